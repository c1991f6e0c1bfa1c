"""Least-squares integration of normals over a mask, with one weight per pixel: the solver behind
:mod:`shadeform.integration.poisson`.

The system is ``L z = b`` with ``L = D^T W D``: one unknown per object pixel, one term per
4-neighbour pair of object pixels, weighted by the smaller of the two pixels' weights, and ``b``
the divergence of the slopes ``D^T W s``. ``L`` is singular, with one free offset per connected
part (pixels joined by pairs of positive weight); the solution returned has mean 0 over each part.

:class:`Hierarchy` sets the problem up once per mask and weighting: the operator's pair weights
(float64), the parts, the multigrid levels (:class:`.levels.Levels`); each :meth:`Hierarchy.solve`
then turns normals into the right-hand side, runs :func:`.pcg.pcg` and writes the depth. The
pair-weighted :class:`.pairs.PairHierarchy` shares all but the set-up of the weights.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange

from shadeform.integration._multigrid.cycle import SWEEPS, threads_for
from shadeform.integration._multigrid.layout import CHUNKS, FAST, around, chunk, padded, pair_rows, to_rb
from shadeform.integration._multigrid.levels import Levels, label_parts, pseudo_inverse
from shadeform.integration._multigrid.pcg import pcg

_BIG = np.finfo(np.float64).max


@numba.njit(cache=True)
def weight_range(mask, weights):
    """(whether the weights are finite and >= 0 on the mask, their largest value there)."""
    top = 0.0
    ok = True
    for i in range(mask.shape[0]):
        for j in range(mask.shape[1]):
            if mask[i, j]:
                v = weights[i, j]
                if not (v >= 0.0 and v <= _BIG):
                    ok = False
                elif v > top:
                    top = v
    return ok, top


@numba.njit(cache=True, parallel=True)
def _pixel_pairs(mask, weights, scale, wx, wy):
    """Red-black pair weights: ``scale`` times the smaller of the two pixels' weights where both are
    on the mask, 0 elsewhere."""
    h, w = mask.shape
    wx[:] = 0.0
    wy[:] = 0.0
    for r in prange(h):
        i = r + 1
        for c in range(w):
            if not mask[r, c]:
                continue
            j = c + 1
            if c + 1 < w and mask[r, c + 1]:
                wx[(i + j) & 1, i, j >> 1] = scale * min(weights[r, c], weights[r, c + 1])
            if r + 1 < h and mask[r + 1, c]:
                wy[(i + j) & 1, i, j >> 1] = scale * min(weights[r, c], weights[r + 1, c])


@numba.njit(cache=True, inline="always")
def _finite(v, nan):
    """``np.nan_to_num`` of one value."""
    if v != v:
        return nan
    return min(max(v, -_BIG), _BIG)


@numba.njit(cache=True, parallel=True)
def _slopes_rb(normals, mask, r0, c0, min_nz, zx, zy):
    """Slopes ``dz/dx = -n_x / n_z``, ``dz/dy = -n_y / n_z`` as in
    :func:`shadeform.integration._slopes.slopes` (NaN read as 0, ``n_z`` NaN as 1, ``n_z`` at least
    ``min_nz``) of pixel ``(r0 + i - 1, c0 + j - 1)`` at cell ``(i, j)``; 0 off the mask."""
    h, w = mask.shape
    m = zx.shape[2]
    zx[:, 0, :] = 0.0
    zy[:, 0, :] = 0.0
    zx[:, h + 1 :, :] = 0.0
    zy[:, h + 1 :, :] = 0.0
    for i in prange(1, h + 1):
        for c in range(2):
            s = (i + c) & 1
            for k in range(m):
                j = 2 * k + s
                gx = 0.0
                gy = 0.0
                if 1 <= j <= w and mask[i - 1, j - 1]:
                    n = normals[r0 + i - 1, c0 + j - 1]
                    nz = max(_finite(n[2], 1.0), min_nz)
                    gx = -_finite(n[0], 0.0) / nz
                    gy = -_finite(n[1], 0.0) / nz
                zx[c, i, k] = gx
                zy[c, i, k] = gy


@numba.njit(cache=True, parallel=True, fastmath=FAST)
def _divergence_rb(zx, zy, wx, wy, h, b):
    """``b = D^T W s`` with the trapezoid-rule steps ``s`` of each pair: ``+dz/dx`` to the right,
    ``-dz/dy`` one row down (y is up); ``wx, wy`` the pair weights. Writes every entry."""
    m = b.shape[2]
    for i in prange(1, h + 1):
        for c in range(2):
            s = (i + c) & 1
            gxc, gxo, _, _ = around(zx, c, i)
            gyc, _, gyu, gyd = around(zy, c, i)
            wr, wl, wd, wu = pair_rows(wx, wy, c, i)
            bc = b[c, i]
            for k in range(1, m - 1):
                bc[k] = 0.5 * (
                    wl[k + s - 1] * (gxo[k + s - 1] + gxc[k])
                    - wr[k] * (gxc[k] + gxo[k + s])
                    + wd[k] * (gyc[k] + gyd[k])
                    - wu[k] * (gyu[k] + gyc[k])
                )
            bc[0] = 0.0
            bc[m - 1] = 0.0
            if s == 1:
                bc[0] = 0.5 * (
                    wl[0] * (gxo[0] + gxc[0])
                    - wr[0] * (gxc[0] + gxo[1])
                    + wd[0] * (gyc[0] + gyd[0])
                    - wu[0] * (gyu[0] + gyc[0])
                )
    b[:, 0, :] = 0.0
    b[:, h + 1 :, :] = 0.0


@numba.njit(cache=True, parallel=True)
def _finish(x, mask, labels, n_parts, r0, c0, out):
    """``out[r0 + r, c0 + c]`` = the value of cell ``(r + 1, c + 1)`` less the mean of its part,
    on the mask's pixels."""
    h, w = mask.shape
    blocks = min(CHUNKS, h)
    sums = np.zeros((blocks, n_parts))
    counts = np.zeros((blocks, n_parts))
    for t in prange(blocks):
        first, stop = chunk(h, t, blocks)
        for r in range(first, stop):
            i = r + 1
            for c in range(w):
                lab = labels[r, c]
                if lab >= 0:
                    j = c + 1
                    sums[t, lab] += x[(i + j) & 1, i, j >> 1]
                    counts[t, lab] += 1.0
    mean = sums.sum(axis=0) / np.maximum(counts.sum(axis=0), 1.0)
    for r in prange(h):
        i = r + 1
        for c in range(w):
            if mask[r, c]:
                j = c + 1
                v = x[(i + j) & 1, i, j >> 1]
                lab = labels[r, c]
                if lab >= 0:
                    v -= mean[lab]
                out[r0 + r, c0 + c] = v


class Hierarchy:
    """The operator and multigrid levels for one mask and weighting (set up once, reused for
    every solve).

    Parameters
    ----------
    mask : (h, w) bool
        Object pixels, cropped to their bounding box (C order).
    weights : (h, w) float64
        Finite, non-negative confidence per pixel (C order).
    top : float
        The largest weight on the mask; the weights are scaled by ``1 / top`` (which changes no
        solution) so that float32 holds them whatever their scale.

    Attributes
    ----------
    labels : (h, w) int32
        The connected part of each pixel, ``0 .. n_parts - 1``; -1 for pixels with no pair of
        positive weight.
    n_parts : int
    """

    def __init__(self, mask: np.ndarray, weights: np.ndarray, top: float):
        self.mask = mask
        self.shape = padded(*mask.shape)
        with threads_for(mask.size):
            wx, wy = self._rb_array(), self._rb_array()
            _pixel_pairs(mask, weights, 1.0 / top if top > 0 else 0.0, wx, wy)
            self.labels = np.empty(mask.shape, np.int32)
            self.n_parts = label_parts(mask, weights, self.labels)
            self._set_up(wx, wy, 1.0, pseudo_inverse)

    def _set_up(self, wx: np.ndarray, wy: np.ndarray, scale: float, coarse_inverse) -> None:
        """The operator of red-black pair weights ``wx, wy`` and its levels, which hold ``scale``
        times them (:class:`.levels.Levels`)."""
        self.wx, self.wy = wx, wy
        self.levels = Levels(*self.mask.shape, wx, wy, scale, coarse_inverse)
        self._work = None

    def _rb_array(self) -> np.ndarray:
        """A new float64 red-black array over the padded grid (any content)."""
        return np.empty((2, self.shape[0], self.shape[1] // 2))

    def _to_rb(self, nat: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Natural ``(h, w)`` values into ``out``, or a new float64 red-black array."""
        out = self._rb_array() if out is None else out
        to_rb(np.ascontiguousarray(nat, dtype=np.float64), out)
        return out

    def _workspace(self) -> list[np.ndarray]:
        """Four float64 red-black arrays ``x, r, p, q``, made on first use and kept for the next
        solves (fresh memory costs page faults)."""
        if self._work is None:
            self._work = [np.empty_like(self.wx) for _ in range(4)]
        return self._work

    def _pcg(self, wx, wy, *, tol: float, maxiter: int, warm: bool, from_start: bool = False):
        """:func:`.pcg.pcg` on the workspace (``r`` holding ``b``, with ``warm`` ``x`` holding
        ``x0``) for the operator of red-black pair weights ``wx, wy``."""
        x, r, p, q = self._workspace()
        with threads_for(self.mask.size) as threads:
            it, res = pcg(
                r,
                x,
                p,
                q,
                wx,
                wy,
                self.levels.arrays,
                SWEEPS,
                float(tol),
                int(maxiter),
                threads,
                bool(warm),
                bool(from_start),
            )
        return int(it), float(res)

    def solve(
        self,
        normals: np.ndarray,
        r0: int,
        c0: int,
        min_nz: float,
        out: np.ndarray,
        *,
        tol: float,
        maxiter: int,
    ) -> tuple[int, float]:
        """Integrate the normals: least-squares depth, mean 0 over each part, into ``out``.

        ``normals`` (float64, C order) and ``out`` are whole images; the mask's pixel ``(r, c)``
        is their pixel ``(r0 + r, c0 + c)``. The slopes are those of
        :func:`shadeform.integration._slopes.slopes` with ``MIN_NZ = min_nz``. Writes ``out`` on the
        mask's pixels only. Returns the number of CG iterations and the final relative residual.
        """
        x, r, p, q = self._workspace()
        with threads_for(self.mask.size):
            _slopes_rb(normals, self.mask, r0, c0, min_nz, p, q)  # p, q: slopes, until CG needs them
            _divergence_rb(p, q, self.wx, self.wy, self.mask.shape[0], r)
            it, res = self._pcg(self.wx, self.wy, tol=tol, maxiter=maxiter, warm=False)
            _finish(x, self.mask, self.labels, self.n_parts, r0, c0, out)
        return it, res
