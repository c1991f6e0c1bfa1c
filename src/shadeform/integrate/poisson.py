"""Depth by (weighted) least squares over the mask: the discrete Poisson equation.

Finds the depth whose forward differences between neighbouring object pixels best match the
trapezoid-rule steps of the given slopes, in the least-squares sense, with optional per-pixel
confidence weights (Horn & Brooks 1986; the masked formulation of e.g. Queau, Durou & Aujol 2018).
The normal equations are a graph Laplacian over the mask, solved by algebraic multigrid
(pyamg) as a preconditioner for conjugate gradients.

References
----------
.. [1] Y. Queau, J.-D. Durou, J.-F. Aujol, "Normal integration: a survey", JMIV 60, 2018.
"""

from __future__ import annotations

import numpy as np
import pyamg
import scipy.sparse as sp

from shadeform.integrate._slopes import slopes


def _difference_system(mask, weights):
    """Difference operator over every 4-neighbour pair of object pixels.

    Returns the pairs ``(r, c, horizontal)`` (pixel and whether its partner is to the right or
    below), the sparse operator ``D`` with ``(D z)[e] = z[partner] - z[pixel]``, and the pair
    weights (the smaller of the two pixels' weights).
    """
    index = np.full(mask.shape, -1, dtype=np.int64)
    n = int(mask.sum())
    index[mask] = np.arange(n)
    rh, ch = np.nonzero(mask[:, :-1] & mask[:, 1:])
    rv, cv = np.nonzero(mask[:-1, :] & mask[1:, :])
    a = np.concatenate([index[rh, ch], index[rv, cv]])
    b = np.concatenate([index[rh, ch + 1], index[rv + 1, cv]])
    wts = np.concatenate([np.minimum(weights[rh, ch], weights[rh, ch + 1]),
                          np.minimum(weights[rv, cv], weights[rv + 1, cv])])
    m = len(a)
    eq = np.arange(m)
    D = sp.csr_matrix((np.r_[-np.ones(m), np.ones(m)], (np.r_[eq, eq], np.r_[a, b])), shape=(m, n))
    return (rh, ch, rv, cv), D, wts


def _steps(zx, zy, pairs):
    """Trapezoid-rule depth steps along each pair: +x to the right, -y one row down."""
    rh, ch, rv, cv = pairs
    return np.concatenate([0.5 * (zx[rh, ch] + zx[rh, ch + 1]),
                           -0.5 * (zy[rv, cv] + zy[rv + 1, cv])])


def poisson_integrator(mask: np.ndarray, *, weights: np.ndarray | None = None, tol: float = 1e-8):
    """Set up the least-squares system for one mask and weighting; return ``solve(normals)``.

    Building the multigrid hierarchy is most of the cost, so callers that integrate several
    fields over the same mask (iterative refinement) set it up once.

    Parameters
    ----------
    mask : (H, W) bool
    weights : (H, W) float, optional
        Confidence per pixel (a pair of pixels gets the smaller of the two); default uniform.
    tol : float
        Relative residual at which conjugate gradients stop.

    Returns
    -------
    solve : callable
        ``solve(normals) -> depth`` with normals (H, W, 3) and depth (H, W) float64, NaN outside
        the mask, mean 0 over each connected part.
    """
    mask = np.asarray(mask, dtype=bool)
    w = np.ones(mask.shape) if weights is None else np.asarray(weights, dtype=np.float64)
    pairs, D, wts = _difference_system(mask, w)
    A = (D.T @ sp.diags(wts) @ D).tocsr()
    # the Laplacian is singular (free offset per connected part): a tiny ridge term fixes it
    # without visibly pulling the solution toward 0
    A = A + sp.identity(A.shape[0], format="csr") * (1e-9 * A.diagonal().mean())
    amg = pyamg.smoothed_aggregation_solver(A, symmetry="symmetric", max_coarse=500)

    def solve(normals: np.ndarray) -> np.ndarray:
        zx, zy = slopes(normals, mask)
        rhs = _steps(zx, zy, pairs)
        z = amg.solve(D.T @ (wts * rhs), tol=tol, accel="cg", maxiter=200)
        depth = np.full(mask.shape, np.nan)
        depth[mask] = z
        return depth

    return solve


def integrate_poisson(normals: np.ndarray, mask: np.ndarray, *, weights: np.ndarray | None = None,
                      origin: tuple[int, int] | None = None, tol: float = 1e-8) -> np.ndarray:
    """Least-squares depth from normals over an arbitrary mask.

    Parameters
    ----------
    normals : (H, W, 3) float
        Unit normals, finite on the mask.
    mask : (H, W) bool
    weights : (H, W) float, optional
        Confidence per pixel (a pair of pixels gets the smaller of the two); default uniform.
    origin : (int, int), optional
        (row, col) where ``z = 0``; by default the mean depth of each connected part is 0.
    tol : float
        Relative residual at which conjugate gradients stop.

    Returns
    -------
    depth : (H, W) float64
        Height in pixel units, NaN outside the mask.
    """
    depth = poisson_integrator(mask, weights=weights, tol=tol)(normals)
    if origin is not None:
        depth -= depth[tuple(origin)]
    return depth
