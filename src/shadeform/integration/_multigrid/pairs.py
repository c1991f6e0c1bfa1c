"""Pair-weighted least squares: each 4-neighbour pair its own weight, a given right-hand side and a
warm start, for iteratively reweighted least squares (:mod:`shadeform.integration.bilateral`) and
the oblique-light solver (:mod:`shadeform.solvers.oblique`).

The multigrid levels are built once from one set of pair weights and may precondition operators
with other weights over the same mask: a preconditioner built for nearby weights stays a valid
symmetric positive definite one, only the iteration count depends on how close the weights are.
"""

from __future__ import annotations

import numpy as np

from shadeform.integration._multigrid.hierarchy import Hierarchy
from shadeform.integration._multigrid.layout import from_rb, padded
from shadeform.integration._multigrid.levels import graph_pseudo_inverse, label_parts


class PairHierarchy(Hierarchy):
    """A :class:`.hierarchy.Hierarchy` whose operator has one weight per 4-neighbour pair.

    Parameters
    ----------
    mask : (h, w) bool
        Object pixels, cropped to their bounding box (C order).
    px, py : (h, w) float64
        ``px[r, c]`` weights the pair ``(r, c)-(r, c + 1)``, ``py[r, c]`` the pair
        ``(r, c)-(r + 1, c)``; finite, >= 0, and 0 where either pixel is off the mask (or the
        partner is outside the box).

    Notes
    -----
    The parts (:attr:`labels`, :attr:`n_parts`) are the 4-connected parts of the mask, whatever the
    weights. The multigrid levels (the preconditioner) come from ``px, py``; :meth:`solve_pairs`
    can apply conjugate gradients to an operator with other pair weights over the same mask.
    """

    def __init__(self, mask: np.ndarray, px: np.ndarray, py: np.ndarray):
        self.mask = mask
        self.shape = padded(*mask.shape)
        top = float(max(px.max(initial=0.0), py.max(initial=0.0)))
        self.labels = np.empty(mask.shape, np.int32)
        self.n_parts = label_parts(mask, mask.astype(np.float64), self.labels)
        self._set_up(self._to_rb(px), self._to_rb(py), 1.0 / top if top > 0 else 0.0, graph_pseudo_inverse)

    def solve_pairs(
        self,
        b: np.ndarray,
        x0: np.ndarray,
        *,
        px: np.ndarray | None = None,
        py: np.ndarray | None = None,
        tol: float,
        maxiter: int,
        from_start: bool = False,
    ) -> tuple[np.ndarray, int, float]:
        """Solve ``L x = b`` by multigrid-preconditioned CG from ``x0``.

        Parameters
        ----------
        b, x0 : (h, w) float64
            Right-hand side (0 off the mask, summing to 0 over each connected part) and initial
            guess, natural layout over the box.
        px, py : (h, w) float64, optional
            Pair weights of the operator (same layout as the constructor's); default the
            constructor's own.
        tol : float
            Relative residual ``|b - L x| / |b|`` at which to stop.
        maxiter : int
        from_start : bool
            Measure ``tol`` against the initial residual ``|b - L x0|`` (whichever of the two is
            smaller) instead of ``|b|``: a warm start then still gains ``tol``.

        Returns
        -------
        x : (h, w) float64
            The solution (its offset per part is whatever CG left; 0 off the mask).
        iterations : int
        residual : float
        """
        x, r, _, _ = self._workspace()
        wx, wy = (self.wx, self.wy) if px is None else (self._to_rb(px), self._to_rb(py))
        self._to_rb(b, r)
        self._to_rb(x0, x)
        it, res = self._pcg(wx, wy, tol=tol, maxiter=maxiter, warm=True, from_start=from_start)
        out = np.empty(self.mask.shape)
        from_rb(x, out)
        out[~self.mask] = 0.0
        return out, it, res
