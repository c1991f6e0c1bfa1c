"""Multigrid-preconditioned conjugate gradients for the masked, weighted 5-point graph Laplacian.

The system is ``L z = b`` with ``L = D^T W D``: one unknown per object pixel, one equation term per
4-neighbour pair of object pixels, each pair weighted by ``W``. ``L`` is singular, with one free
offset per connected part (parts joined by pairs of positive weight).

Layout
------
Every level is a dense ``(h + 2, w + 2)`` grid (the bounding box of the mask plus a one-cell border
of zeros, so no kernel needs a bounds check). ``wx[i, j]`` is the weight of the pair
``(i, j)-(i, j + 1)``, ``wy[i, j]`` of ``(i, j)-(i + 1, j)``, 0 where a pair is missing; a cell
with no pair of positive weight is *inactive* (``inv_diag == 0``) and stays at 0. All levels live
in one flat buffer per quantity, level ``l`` at ``offsets[l]``, so that the whole solve runs in a
single compiled call.

Coarsening
----------
Cell-centred: coarse cell ``(I, J)`` is the 2x2 block of fine cells ``(2I-1 .. 2I, 2J-1 .. 2J)``.
Prolongation is piecewise constant, restriction its transpose (sum over the block). The Galerkin
product ``P^T L P`` is again a 5-point graph Laplacian whose pair weights are the sums of the fine
pairs crossing between two blocks; it is used at half that weight, the classical over-correction
that makes the piecewise-constant coarse-grid correction as large as the smooth error it stands for
(Braess 1995; for the Laplacian the halved operator is exactly the rediscretisation on the coarse
grid). Blocks that are not joined by any fine pair are not joined on the coarse grid either, so
holes and separate parts keep apart until the blocks themselves touch.

Cycle
-----
A symmetric V(2, 2) cycle: red-black Gauss-Seidel (red then black before the coarse correction,
black then red after), the coarsest grid (at most ``_COARSEST`` cells) solved exactly with a
precomputed pseudo-inverse. The cycle is a symmetric positive (semi-)definite operator for any
positive semi-definite coarse operator, so it is a valid preconditioner for conjugate gradients,
which guarantee the accuracy: the iteration stops when ``|b - L z| <= tol |b|``.

References
----------
.. [1] D. Braess, "Towards algebraic multigrid for elliptic problems of second order",
   Computing 55, 1995.
.. [2] U. Trottenberg, C. Oosterlee, A. Schueller, "Multigrid", Academic Press 2001
   (cell-centred grids, red-black smoothing).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange

#: Stop coarsening once a grid has at most this many cells (its system is solved densely).
_COARSEST = 256
#: Levels with fewer cells than this run on one thread (a parallel launch costs more there).
_PARALLEL_MIN = 1 << 15
#: Coarse pair weight = this times the sum of the fine pairs crossing between the two blocks.
_COARSE_SCALE = 0.5
#: Gauss-Seidel sweeps (red + black) before and after each coarse-grid correction.
_SWEEPS = 2


# ---------------------------------------------------------------------------------------------
# Row kernels. Each works on one grid row; the level drivers below run them over all rows, in
# parallel (prange) on big grids and serially on small ones.
# ---------------------------------------------------------------------------------------------

@numba.njit(cache=True, inline="always")
def _gs_row(z, b, wx, wy, inv_diag, i, color, first):
    """One Gauss-Seidel half-sweep over the cells of row ``i`` with ``(i + j) % 2 == color``.

    With ``first`` the grid is taken as all zero (the cycle's initial guess) without reading it.
    """
    w = z.shape[1] - 2
    for j in range(1 + ((i + 1 + color) & 1), w + 1, 2):
        d = inv_diag[i, j]
        if first:
            z[i, j] = b[i, j] * d
        else:
            z[i, j] = (b[i, j] + wx[i, j] * z[i, j + 1] + wx[i, j - 1] * z[i, j - 1]
                       + wy[i, j] * z[i + 1, j] + wy[i - 1, j] * z[i - 1, j]) * d


@numba.njit(cache=True, inline="always")
def _apply_at(z, wx, wy, i, j):
    """``(L z)[i, j]``."""
    c = z[i, j]
    return (wx[i, j] * (c - z[i, j + 1]) + wx[i, j - 1] * (c - z[i, j - 1])
            + wy[i, j] * (c - z[i + 1, j]) + wy[i - 1, j] * (c - z[i - 1, j]))


@numba.njit(cache=True, inline="always")
def _restrict_row(z, b, wx, wy, inv_diag, bc, ci):
    """Coarse row ``ci`` of the restricted residual: the sum of ``b - L z`` over each block."""
    wc = bc.shape[1] - 2
    for cj in range(1, wc + 1):
        s = 0.0
        for i in range(2 * ci - 1, 2 * ci + 1):
            for j in range(2 * cj - 1, 2 * cj + 1):
                if inv_diag[i, j] != 0.0:  # inactive cells (and the border) hold no residual
                    s += b[i, j] - _apply_at(z, wx, wy, i, j)
        bc[ci, cj] = s


@numba.njit(cache=True, inline="always")
def _prolong_row(z, zc, inv_diag, i):
    """Add the coarse correction to the active cells of fine row ``i``."""
    w = z.shape[1] - 2
    ci = (i + 1) >> 1
    for j in range(1, w + 1):
        if inv_diag[i, j] != 0.0:
            z[i, j] += zc[ci, (j + 1) >> 1]


# ---------------------------------------------------------------------------------------------
# Level drivers
# ---------------------------------------------------------------------------------------------

@numba.njit(cache=True, parallel=True)
def _gs_par(z, b, wx, wy, inv_diag, color, first):
    for i in prange(1, z.shape[0] - 1):
        _gs_row(z, b, wx, wy, inv_diag, i, color, first)


@numba.njit(cache=True)
def _gs_ser(z, b, wx, wy, inv_diag, color, first):
    for i in range(1, z.shape[0] - 1):
        _gs_row(z, b, wx, wy, inv_diag, i, color, first)


@numba.njit(cache=True, parallel=True)
def _restrict_par(z, b, wx, wy, inv_diag, bc):
    for ci in prange(1, bc.shape[0] - 1):
        _restrict_row(z, b, wx, wy, inv_diag, bc, ci)


@numba.njit(cache=True)
def _restrict_ser(z, b, wx, wy, inv_diag, bc):
    for ci in range(1, bc.shape[0] - 1):
        _restrict_row(z, b, wx, wy, inv_diag, bc, ci)


@numba.njit(cache=True, parallel=True)
def _prolong_par(z, zc, inv_diag):
    for i in prange(1, z.shape[0] - 1):
        _prolong_row(z, zc, inv_diag, i)


@numba.njit(cache=True)
def _prolong_ser(z, zc, inv_diag):
    for i in range(1, z.shape[0] - 1):
        _prolong_row(z, zc, inv_diag, i)


@numba.njit(cache=True)
def _smooth(z, b, wx, wy, inv_diag, parallel, colors, first):
    for k in range(colors.shape[0]):
        if parallel:
            _gs_par(z, b, wx, wy, inv_diag, colors[k], first and k == 0)
        else:
            _gs_ser(z, b, wx, wy, inv_diag, colors[k], first and k == 0)


@numba.njit(cache=True)
def _level(buf, offsets, shapes, lev):
    """Level ``lev``'s 2-D view of a flat per-level buffer."""
    return buf[offsets[lev]:offsets[lev + 1]].reshape(shapes[lev, 0], shapes[lev, 1])


@numba.njit(cache=True)
def _vcycle(r, zf, wx_all, wy_all, inv_all, z_all, b_all, offsets, shapes, coarse_cells,
            coarse_pinv, sweeps):
    """``zf = B r``: one symmetric V-cycle with zero initial guess on the fine-level residual."""
    n_levels = shapes.shape[0]
    pre = np.empty(2 * sweeps, np.int64)
    post = np.empty(2 * sweeps, np.int64)
    for k in range(sweeps):
        pre[2 * k], pre[2 * k + 1] = 0, 1
        post[2 * k], post[2 * k + 1] = 1, 0
    # down: smooth, restrict the residual
    for lev in range(n_levels - 1):
        wx = _level(wx_all, offsets, shapes, lev)
        wy = _level(wy_all, offsets, shapes, lev)
        inv = _level(inv_all, offsets, shapes, lev)
        z = zf if lev == 0 else _level(z_all, offsets, shapes, lev)
        b = r if lev == 0 else _level(b_all, offsets, shapes, lev)
        bc = _level(b_all, offsets, shapes, lev + 1)
        parallel = z.size >= _PARALLEL_MIN
        _smooth(z, b, wx, wy, inv, parallel, pre, True)
        if parallel:
            _restrict_par(z, b, wx, wy, inv, bc)
        else:
            _restrict_ser(z, b, wx, wy, inv, bc)
    # coarsest: exact (pseudo-inverse) solve on its active cells
    last = n_levels - 1
    zc = z_all[offsets[last]:offsets[last + 1]]
    bc = b_all[offsets[last]:offsets[last + 1]]
    m = coarse_cells.shape[0]
    for a in range(m):
        s = 0.0
        for k in range(m):
            s += coarse_pinv[a, k] * bc[coarse_cells[k]]
        zc[coarse_cells[a]] = s
    # up: correct, smooth
    for lev in range(n_levels - 2, -1, -1):
        wx = _level(wx_all, offsets, shapes, lev)
        wy = _level(wy_all, offsets, shapes, lev)
        inv = _level(inv_all, offsets, shapes, lev)
        z = zf if lev == 0 else _level(z_all, offsets, shapes, lev)
        b = r if lev == 0 else _level(b_all, offsets, shapes, lev)
        zc2 = _level(z_all, offsets, shapes, lev + 1)
        parallel = z.size >= _PARALLEL_MIN
        if parallel:
            _prolong_par(z, zc2, inv)
        else:
            _prolong_ser(z, zc2, inv)
        _smooth(z, b, wx, wy, inv, parallel, post, False)


# ---------------------------------------------------------------------------------------------
# Fine-level vector kernels for conjugate gradients (fused, parallel)
# ---------------------------------------------------------------------------------------------

@numba.njit(cache=True, parallel=True)
def _apply_dot(p, wx, wy, inv_diag, q):
    """``q = L p`` on the active cells; returns ``p . q``."""
    s = 0.0
    for i in prange(1, p.shape[0] - 1):
        t = 0.0
        for j in range(1, p.shape[1] - 1):
            v = 0.0
            if inv_diag[i, j] != 0.0:
                v = _apply_at(p, wx, wy, i, j)
            q[i, j] = v
            t += v * p[i, j]
        s += t
    return s


@numba.njit(cache=True, parallel=True)
def _update_xr(x, r, p, q, alpha):
    """``x += alpha p``, ``r -= alpha q``; returns ``r . r``."""
    s = 0.0
    for i in prange(1, x.shape[0] - 1):
        t = 0.0
        for j in range(1, x.shape[1] - 1):
            x[i, j] += alpha * p[i, j]
            v = r[i, j] - alpha * q[i, j]
            r[i, j] = v
            t += v * v
        s += t
    return s


@numba.njit(cache=True, parallel=True)
def _dot(a, b):
    s = 0.0
    for i in prange(1, a.shape[0] - 1):
        t = 0.0
        for j in range(1, a.shape[1] - 1):
            t += a[i, j] * b[i, j]
        s += t
    return s


@numba.njit(cache=True, parallel=True)
def _update_p(p, z, beta):
    for i in prange(1, p.shape[0] - 1):
        for j in range(1, p.shape[1] - 1):
            p[i, j] = z[i, j] + beta * p[i, j]


@numba.njit(cache=True)
def _pcg(b, x, wx_all, wy_all, inv_all, z_all, b_all, offsets, shapes, coarse_cells, coarse_pinv,
         sweeps, tol, maxiter):
    """Preconditioned CG from ``x = 0``; returns (iterations, final relative residual)."""
    wx = _level(wx_all, offsets, shapes, 0)
    wy = _level(wy_all, offsets, shapes, 0)
    inv = _level(inv_all, offsets, shapes, 0)
    x[:] = 0.0
    bb = _dot(b, b)
    if bb == 0.0:
        return 0, 0.0
    r = b.copy()
    z = np.zeros_like(b)
    p = np.zeros_like(b)
    q = np.zeros_like(b)
    _vcycle(r, z, wx_all, wy_all, inv_all, z_all, b_all, offsets, shapes, coarse_cells,
            coarse_pinv, sweeps)
    p[:] = z
    rz = _dot(r, z)
    rr = bb
    it = 0
    while it < maxiter:
        it += 1
        pq = _apply_dot(p, wx, wy, inv, q)
        if pq <= 0.0:
            break
        alpha = rz / pq
        rr = _update_xr(x, r, p, q, alpha)
        if rr <= tol * tol * bb:
            break
        _vcycle(r, z, wx_all, wy_all, inv_all, z_all, b_all, offsets, shapes, coarse_cells,
                coarse_pinv, sweeps)
        rz_new = _dot(r, z)
        if rz_new <= 0.0:
            break
        _update_p(p, z, rz_new / rz)
        rz = rz_new
    return it, np.sqrt(rr / bb)


# ---------------------------------------------------------------------------------------------
# Set-up kernels
# ---------------------------------------------------------------------------------------------

@numba.njit(cache=True)
def _fine_pairs(mask, weights, wx, wy):
    """Pair weights on the padded fine grid: the smaller of the two pixels' weights."""
    h, w = mask.shape
    for i in range(h):
        for j in range(w):
            if not mask[i, j]:
                continue
            if j + 1 < w and mask[i, j + 1]:
                wx[i + 1, j + 1] = min(weights[i, j], weights[i, j + 1])
            if i + 1 < h and mask[i + 1, j]:
                wy[i + 1, j + 1] = min(weights[i, j], weights[i + 1, j])


@numba.njit(cache=True)
def _inverse_diagonal(wx, wy, inv_diag):
    for i in range(1, wx.shape[0] - 1):
        for j in range(1, wx.shape[1] - 1):
            d = wx[i, j] + wx[i, j - 1] + wy[i, j] + wy[i - 1, j]
            inv_diag[i, j] = 1.0 / d if d > 0.0 else 0.0


@numba.njit(cache=True)
def _coarsen(wx, wy, wxc, wyc, scale):
    """Coarse pair weights: ``scale`` times the sum of the fine pairs crossing between blocks."""
    hc, wc = wxc.shape[0] - 2, wxc.shape[1] - 2
    for ci in range(1, hc + 1):
        i = 2 * ci
        for cj in range(1, wc + 1):
            j = 2 * cj
            if cj < wc:
                wxc[ci, cj] = scale * (wx[i - 1, j] + wx[i, j])
            if ci < hc:
                wyc[ci, cj] = scale * (wy[i, j - 1] + wy[i, j])


@numba.njit(cache=True)
def _find(parent, a):
    root = a
    while parent[root] != root:
        root = parent[root]
    while parent[a] != root:  # path compression
        nxt = parent[a]
        parent[a] = root
        a = nxt
    return root


@numba.njit(cache=True)
def _label_parts(wx, wy, inv_diag, labels):
    """Connected parts joined by pairs of positive weight; returns their count.

    ``labels`` (padded grid, int64) gets 0..n-1 on active cells and -1 elsewhere.
    """
    hp, wp = wx.shape
    parent = np.arange(hp * wp)
    for i in range(1, hp - 1):
        for j in range(1, wp - 1):
            a = i * wp + j
            if wx[i, j] > 0.0:
                ra, rb = _find(parent, a), _find(parent, a + 1)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
            if wy[i, j] > 0.0:
                ra, rb = _find(parent, a), _find(parent, a + wp)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    n = 0
    root_label = np.full(hp * wp, -1, np.int64)
    for i in range(hp):
        for j in range(wp):
            if inv_diag[i, j] == 0.0:
                labels[i, j] = -1
                continue
            root = _find(parent, i * wp + j)
            if root_label[root] < 0:
                root_label[root] = n
                n += 1
            labels[i, j] = root_label[root]
    return n


@numba.njit(cache=True)
def _remove_part_means(x, labels, n_parts):
    sums = np.zeros(n_parts)
    counts = np.zeros(n_parts)
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            k = labels[i, j]
            if k >= 0:
                sums[k] += x[i, j]
                counts[k] += 1.0
    for k in range(n_parts):
        sums[k] /= counts[k]
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            k = labels[i, j]
            if k >= 0:
                x[i, j] -= sums[k]


@numba.njit(cache=True)
def _coarsest_matrix(wx, wy, inv_diag, cells):
    """Dense Laplacian of the coarsest grid restricted to its active cells (flat indices)."""
    wp = wx.shape[1]
    m = cells.shape[0]
    where = np.full(wx.size, -1, np.int64)
    for a in range(m):
        where[cells[a]] = a
    A = np.zeros((m, m))
    for a in range(m):
        i, j = cells[a] // wp, cells[a] % wp
        for di, dj, wt in ((0, 1, wx[i, j]), (0, -1, wx[i, j - 1]),
                           (1, 0, wy[i, j]), (-1, 0, wy[i - 1, j])):
            if wt > 0.0:
                k = where[(i + di) * wp + j + dj]
                A[a, a] += wt
                A[a, k] -= wt
    return A


class Hierarchy:
    """The multigrid levels for one mask and weighting (set up once, reused for every solve).

    Parameters
    ----------
    mask : (h, w) bool
        Object pixels, already cropped to their bounding box.
    weights : (h, w) float64
        Non-negative, finite confidence per pixel.
    """

    def __init__(self, mask: np.ndarray, weights: np.ndarray):
        h, w = mask.shape
        shapes = [(h + 2, w + 2)]
        while shapes[-1][0] * shapes[-1][1] > _COARSEST and max(shapes[-1]) > 3:
            hp, wp = shapes[-1]
            shapes.append(((hp - 1) // 2 + 2, (wp - 1) // 2 + 2))
        self.shapes = np.array(shapes, dtype=np.int64)
        sizes = self.shapes[:, 0] * self.shapes[:, 1]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        total = int(self.offsets[-1])
        self.wx = np.zeros(total)
        self.wy = np.zeros(total)
        self.inv_diag = np.zeros(total)
        self.z_work = np.zeros(total)
        self.b_work = np.zeros(total)

        def view(buf, lev):
            return buf[self.offsets[lev]:self.offsets[lev + 1]].reshape(shapes[lev])

        _fine_pairs(mask, weights, view(self.wx, 0), view(self.wy, 0))
        for lev in range(len(shapes)):
            if lev > 0:
                _coarsen(view(self.wx, lev - 1), view(self.wy, lev - 1),
                         view(self.wx, lev), view(self.wy, lev), _COARSE_SCALE)
            _inverse_diagonal(view(self.wx, lev), view(self.wy, lev), view(self.inv_diag, lev))
        self.labels = np.empty(shapes[0], dtype=np.int64)
        self.n_parts = _label_parts(view(self.wx, 0), view(self.wy, 0), view(self.inv_diag, 0),
                                    self.labels)
        last = len(shapes) - 1
        self.coarse_cells = np.flatnonzero(view(self.inv_diag, last)).astype(np.int64)
        A = _coarsest_matrix(view(self.wx, last), view(self.wy, last), view(self.inv_diag, last),
                             self.coarse_cells)
        self.coarse_pinv = _pseudo_inverse(A)
        self.fine_shape = shapes[0]

    def fine_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The fine grid's pair weights ``(wx, wy)`` (padded views)."""
        n = self.offsets[1]
        return self.wx[:n].reshape(self.fine_shape), self.wy[:n].reshape(self.fine_shape)

    def solve(self, b: np.ndarray, *, tol: float, maxiter: int = 500) -> tuple[np.ndarray, int, float]:
        """Least-squares solution of ``L x = b`` (padded fine grid), mean 0 over each part.

        Returns the solution, the number of CG iterations and the final relative residual.
        """
        x = np.zeros(self.fine_shape)
        it, res = _pcg(b, x, self.wx, self.wy, self.inv_diag, self.z_work, self.b_work,
                       self.offsets, self.shapes, self.coarse_cells, self.coarse_pinv, _SWEEPS,
                       float(tol), int(maxiter))
        _remove_part_means(x, self.labels, self.n_parts)
        return x, int(it), float(res)


def _pseudo_inverse(A: np.ndarray) -> np.ndarray:
    """Moore-Penrose inverse of a small symmetric positive semi-definite matrix."""
    if A.shape[0] == 0:
        return np.zeros((0, 0))
    vals, vecs = np.linalg.eigh(A)
    keep = vals > 1e-10 * max(vals[-1], 0.0)
    if not keep.any():
        return np.zeros_like(A)
    return (vecs[:, keep] / vals[keep]) @ vecs[:, keep].T
