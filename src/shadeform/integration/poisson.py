"""Depth by (weighted) least squares over the mask: the discrete Poisson equation.

Finds the depth whose forward differences between neighbouring object pixels best match the
trapezoid-rule steps of the given slopes, in the least-squares sense, with optional per-pixel
confidence weights (Horn & Brooks 1986; the masked formulation of e.g. Queau, Durou & Aujol 2018).
The normal equations are a weighted graph Laplacian over the mask, ``D^T W D z = D^T W s``, with one
free offset per connected part. They are solved by conjugate gradients preconditioned with a
geometric multigrid V-cycle on the mask's bounding box (:mod:`shadeform.integration._multigrid`),
compiled with numba; :func:`poisson_integrator_reference` solves the same system with a sparse
direct factorisation and is the slow, obviously correct check.

References
----------
.. [1] Y. Queau, J.-D. Durou, J.-F. Aujol, "Normal integration: a survey", JMIV 60, 2018.
"""

from __future__ import annotations

import numpy as np

from shadeform.errors import InputError
from shadeform.integration._multigrid import Hierarchy, weight_range
from shadeform.integration._slopes import MIN_NZ, slopes

#: Conjugate-gradient iterations at most (the multigrid preconditioner needs about 10).
MAX_ITERATIONS = 500


def _check_weights(mask: np.ndarray, weights: np.ndarray | None) -> tuple[np.ndarray, float]:
    """The weights as float64 (uniform if None) and their largest value on the mask."""
    if weights is None:
        return np.ones(mask.shape), 1.0
    w = np.ascontiguousarray(weights, dtype=np.float64)
    if w.shape != mask.shape:
        raise InputError(f"weights must have the mask's shape {mask.shape}, got {w.shape}")
    ok, top = weight_range(mask, w)
    if not ok:
        raise InputError("weights must be finite and non-negative on the mask")
    return w, top


def _bounding_box(mask: np.ndarray) -> tuple[slice, slice]:
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


def poisson_integrator(mask: np.ndarray, *, weights: np.ndarray | None = None, tol: float = 1e-8):
    """Set up the least-squares system for one mask and weighting; return ``solve(normals)``.

    The multigrid hierarchy is built here, once, so callers that integrate several fields over the
    same mask and weights (iterative refinement) pay for it once.

    Parameters
    ----------
    mask : (H, W) bool
    weights : (H, W) float, optional
        Confidence per pixel, finite and >= 0 (a pair of pixels gets the smaller of the two);
        default uniform.
    tol : float
        Relative residual ``|b - A z| / |b|`` at which conjugate gradients stop.

    Returns
    -------
    solve : callable
        ``solve(normals) -> depth`` with normals (H, W, 3) and depth (H, W) float64, NaN outside
        the mask, mean 0 over each connected part (pixels joined by pairs of positive weight; a
        pixel with no such pair is a part of its own, at 0). After a call, ``solve.info`` holds
        the iteration count and final relative residual.
    """
    mask = np.ascontiguousarray(mask, dtype=bool)
    if mask.ndim != 2:
        raise InputError(f"mask must be (H, W), got shape {mask.shape}")
    pixel_weights, top = _check_weights(mask, weights)
    shape = mask.shape
    info = {}
    if not mask.any():

        def solve_empty(normals: np.ndarray) -> np.ndarray:
            return np.full(shape, np.nan)

        solve_empty.info = info
        return solve_empty
    box = _bounding_box(mask)
    r0, c0 = box[0].start, box[1].start
    hierarchy = Hierarchy(np.ascontiguousarray(mask[box]), np.ascontiguousarray(pixel_weights[box]), top)

    def solve(normals: np.ndarray) -> np.ndarray:
        normals = np.ascontiguousarray(normals, dtype=np.float64)
        if normals.shape != (*shape, 3):
            raise InputError(f"normals must be {(*shape, 3)} to match the mask, got {normals.shape}")
        depth = np.full(shape, np.nan)
        iterations, residual = hierarchy.solve(
            normals, r0, c0, MIN_NZ, depth, tol=tol, maxiter=MAX_ITERATIONS
        )
        info.update(iterations=iterations, residual=residual)
        return depth

    solve.info = info
    return solve


def integrate_poisson(
    normals: np.ndarray,
    mask: np.ndarray,
    *,
    weights: np.ndarray | None = None,
    origin: tuple[int, int] | None = None,
    tol: float = 1e-8,
) -> np.ndarray:
    """Least-squares depth from normals over an arbitrary mask.

    Parameters
    ----------
    normals : (H, W, 3) float
        Unit normals, finite on the mask.
    mask : (H, W) bool
    weights : (H, W) float, optional
        Confidence per pixel, finite and >= 0 (a pair of pixels gets the smaller of the two);
        default uniform.
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


# ---------------------------------------------------------------------------------------------
# Reference: the same least-squares problem, assembled as sparse matrices and solved directly
# ---------------------------------------------------------------------------------------------


def difference_system(mask, weights):
    """Difference operator over every 4-neighbour pair of object pixels.

    Also the pairs of neighbours the photo solver's smoothness runs over
    (:mod:`shadeform.solvers.photo`).

    Parameters
    ----------
    mask : (H, W) bool
        The object.
    weights : (H, W) float
        Per-pixel weights.

    Returns
    -------
    pairs : tuple of 4 (M,) int arrays
        ``(rh, ch, rv, cv)``: the pixels whose partner is to the right, resp. below.
    D : (M, n) scipy.sparse.csr_matrix
        ``(D z)[e] = z[partner] - z[pixel]`` over the ``n`` object pixels in row-major order.
    weights : (M,) float64
        Each pair's weight: the smaller of its two pixels' weights.
    """
    import scipy.sparse as sp

    index = np.full(mask.shape, -1, dtype=np.int64)
    n = int(mask.sum())
    index[mask] = np.arange(n)
    rh, ch = np.nonzero(mask[:, :-1] & mask[:, 1:])
    rv, cv = np.nonzero(mask[:-1, :] & mask[1:, :])
    a = np.concatenate([index[rh, ch], index[rv, cv]])
    b = np.concatenate([index[rh, ch + 1], index[rv + 1, cv]])
    wts = np.concatenate(
        [np.minimum(weights[rh, ch], weights[rh, ch + 1]), np.minimum(weights[rv, cv], weights[rv + 1, cv])]
    )
    m = len(a)
    eq = np.arange(m)
    D = sp.csr_matrix((np.r_[-np.ones(m), np.ones(m)], (np.r_[eq, eq], np.r_[a, b])), shape=(m, n))
    return (rh, ch, rv, cv), D, wts


def _steps(zx, zy, pairs):
    """Trapezoid-rule depth steps along each pair: +x to the right, -y one row down."""
    rh, ch, rv, cv = pairs
    return np.concatenate([0.5 * (zx[rh, ch] + zx[rh, ch + 1]), -0.5 * (zy[rv, cv] + zy[rv + 1, cv])])


def poisson_integrator_reference(mask: np.ndarray, *, weights: np.ndarray | None = None):
    """Same problem and result as :func:`poisson_integrator`, solved exactly (slow).

    Assembles ``A = D^T W D`` as a sparse matrix, pins one pixel of every connected part (pixels
    joined by pairs of positive weight) to make it non-singular, factorises it (SuperLU) and
    removes each part's mean from the solution. Exact up to round-off; for checking the fast
    solver (the factorisation takes about 20 s for 600k pixels).
    """
    import scipy.sparse as sp
    import scipy.sparse.csgraph as csgraph
    import scipy.sparse.linalg as spla

    mask = np.ascontiguousarray(mask, dtype=bool)
    w, _ = _check_weights(mask, weights)
    pairs, D, wts = difference_system(mask, w)
    n = D.shape[1]
    A = (D.T @ sp.diags(wts) @ D).tocsr()
    A.eliminate_zeros()  # pairs of weight 0 join nothing
    n_parts, labels = csgraph.connected_components(A, directed=False)
    pinned = np.zeros(n, dtype=bool)
    pinned[np.unique(labels, return_index=True)[1]] = True  # the first pixel of each part
    free = ~pinned
    A_free = A[free][:, free].tocsc()
    factor = spla.splu(A_free) if A_free.shape[0] else None

    def solve(normals: np.ndarray) -> np.ndarray:
        zx, zy = slopes(np.asarray(normals, dtype=np.float64), mask)
        b = D.T @ (wts * _steps(zx, zy, pairs))
        z = np.zeros(n)
        if factor is not None:
            z[free] = factor.solve(b[free])
        z -= (np.bincount(labels, weights=z, minlength=n_parts) / np.bincount(labels, minlength=n_parts))[
            labels
        ]
        depth = np.full(mask.shape, np.nan)
        depth[mask] = z
        return depth

    solve.info = {}
    return solve
