"""The multigrid levels of one operator, set up once and reused for every solve.

From the finest pair weights (:mod:`.layout`) each coarser level is built by cell-centred 2x2
coarsening until a grid has at most :data:`COARSEST` cells. The Galerkin product ``P^T L P`` of a
5-point graph Laplacian with piecewise-constant prolongation ``P`` is again a 5-point graph
Laplacian, whose pair weights are the sums of the fine pairs crossing between two blocks; it is
used at half that weight (:data:`COARSE_SCALE`), the classical over-correction that makes a
piecewise-constant correction as large as the smooth error it stands for [1]_ (for uniform weights
the halved operator is exactly the Laplacian rediscretised on the coarse grid). Blocks not joined
by any fine pair are not joined on the coarse grid either, so holes and separate parts stay apart
until the blocks themselves touch. A cell with no pair of positive weight is *inactive*: its
inverse diagonal is 0 and its value stays 0.

The coarsest grid is solved exactly with a dense pseudo-inverse over its active cells. The levels
are float32: they only precondition (:mod:`.pcg`).

Also here: the connected parts of an operator (its null space: one free offset per part).

References
----------
.. [1] D. Braess, "Towards algebraic multigrid for elliptic problems of second order",
   Computing 55, 1995.
"""

from __future__ import annotations

import functools

import numba
import numpy as np
from numba import prange

from shadeform.integration._multigrid.layout import level, padded, split

#: Stop coarsening once a grid has at most this many cells (its system is solved densely).
#: Re-checked on the bench's 256^2 and 1024^2 disks, 1 thread (``benchmarks/results/poisson.md``):
#: 64 is as fast, 1024 adds 100-150 ms of dense pseudo-inverse to the set-up.
COARSEST = 256
#: Coarse pair weight = this times the sum of the fine pairs crossing between the two blocks.
#: 0.5 is the classical value; CG iteration counts on the bench's 256^2 and 1024^2 disks confirm it
#: as a sharp optimum: 0.46 or 0.55 need 1.5x as many (``benchmarks/results/poisson.md``).
COARSE_SCALE = 0.5
#: Pair weights (relative to the largest) below this are left out of the float32 levels, whose
#: normal range ends near 1e-38 (not a tuned value).
TINY = 1e-30


@numba.njit(cache=True, parallel=True)
def _fine_pairs(wx_rb, wy_rb, scale, wx, wy):
    """Natural float32 finest-level pair weights from red-black ones: ``scale`` times them, 0
    below :data:`TINY`."""
    for i in prange(wx.shape[0]):
        for j in range(wx.shape[1]):
            v = scale * wx_rb[(i + j) & 1, i, j >> 1]
            wx[i, j] = v if v >= TINY else 0.0
            v = scale * wy_rb[(i + j) & 1, i, j >> 1]
            wy[i, j] = v if v >= TINY else 0.0


@numba.njit(cache=True)
def _inverse_diagonal(wx, wy, inv_diag):
    for i in range(1, wx.shape[0] - 1):
        for j in range(1, wx.shape[1] - 1):
            d = np.float64(wx[i, j]) + wx[i, j - 1] + wy[i, j] + wy[i - 1, j]
            inv_diag[i, j] = 1.0 / d if d > 0.0 else 0.0


@numba.njit(cache=True)
def _coarsen(wx, wy, wxc, wyc, hc, wc, scale):
    """Coarse pair weights: ``scale`` times the sum of the fine pairs crossing between blocks."""
    for ci in range(1, hc + 1):
        i = 2 * ci
        for cj in range(1, wc + 1):
            j = 2 * cj
            if cj < wc:
                wxc[ci, cj] = scale * (wx[i - 1, j] + wx[i, j])
            if ci < hc:
                wyc[ci, cj] = scale * (wy[i, j - 1] + wy[i, j])


@numba.njit(cache=True)
def _coarsest_matrix(wx, wy, cells):
    """Dense Laplacian of a (natural-layout) grid restricted to the given flat cell indices."""
    wp = wx.shape[1]
    m = cells.shape[0]
    where = np.full(wx.size, -1, np.int64)
    for a in range(m):
        where[cells[a]] = a
    A = np.zeros((m, m))
    for a in range(m):
        i, j = cells[a] // wp, cells[a] % wp
        for di, dj, wt in ((0, 1, wx[i, j]), (0, -1, wx[i, j - 1]), (1, 0, wy[i, j]), (-1, 0, wy[i - 1, j])):
            if wt > 0.0:
                k = where[(i + di) * wp + j + dj]
                A[a, a] += wt
                A[a, k] -= wt
    return A


def pseudo_inverse(A: np.ndarray) -> np.ndarray:
    """Moore-Penrose inverse of a small symmetric positive semi-definite matrix (eigenvalues below
    ``1e-10`` of the largest count as 0)."""
    if A.shape[0] == 0:
        return np.zeros((0, 0))
    with _one_blas_thread():
        vals, vecs = np.linalg.eigh(A)
        keep = vals > 1e-10 * max(vals[-1], 0.0)
        if not keep.any():
            return np.zeros_like(A)
        return (vecs[:, keep] / vals[keep]) @ vecs[:, keep].T


def graph_pseudo_inverse(A: np.ndarray) -> np.ndarray:
    """Moore-Penrose inverse of a small graph Laplacian, without an eigendecomposition.

    The null space of a graph Laplacian is spanned by the indicator vectors ``e_c`` of its
    connected parts, so ``A + sum_c e_c e_c^T / |c|`` is non-singular and its inverse is
    ``A^+ + sum_c e_c e_c^T / |c|`` (``e_c / sqrt|c|`` orthonormal): one LU solve instead of
    :func:`pseudo_inverse`'s eigendecomposition.
    """
    import scipy.sparse.csgraph as csgraph

    m = A.shape[0]
    if m == 0:
        return np.zeros((0, 0))
    n_parts, labels = csgraph.connected_components(A != 0, directed=False)
    E = np.zeros((m, n_parts))
    E[np.arange(m), labels] = 1.0
    with _one_blas_thread():
        J = (E / E.sum(axis=0)) @ E.T
        return np.linalg.inv(A + J) - J


def _one_blas_thread():
    """The coarsest grid's matrix is small: BLAS threads give little there, and OpenBLAS's, which
    spin after their work, made every solve on a machine with a busy core up to 2.5x slower now
    and then (``benchmarks/results/stalls.md``: the propagation solver's refinement)."""
    return _blas_libraries().limit(limits=1, user_api="blas")


@functools.cache
def _blas_libraries():
    """The process's thread pools, found once (``threadpool_limits`` looks for them at each call:
    0.8 ms, against 0.01 ms for a limit on the ones found)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


class Levels:
    """The multigrid levels (float32, red-black layout) of an operator.

    Parameters
    ----------
    h, w : int
        The grid's interior (the mask's bounding box).
    wx, wy : (2, hp, wp / 2) float64
        The operator's pair weights, red-black (:mod:`.layout`); finite, >= 0.
    scale : float
        The levels hold ``scale * wx``, ``scale * wy``: a scale that brings the largest weight to
        about 1 keeps every weight in float32's range.
    coarse_inverse : callable
        Pseudo-inverse of the coarsest grid's dense Laplacian (:func:`pseudo_inverse` or
        :func:`graph_pseudo_inverse`).

    Attributes
    ----------
    arrays : tuple
        ``(wx, wy, inv_diag, z_work, b_work, offsets, dims, coarse_cells, coarse_pinv)``, the
        arguments of :func:`.cycle.vcycle` and :func:`.pcg.pcg`: per quantity one flat buffer of
        all levels, level ``l`` at ``offsets[l]:offsets[l + 1]``; ``dims[l] = (h, w, hp, wp)``.
    """

    def __init__(self, h: int, w: int, wx_rb: np.ndarray, wy_rb: np.ndarray, scale: float, coarse_inverse):
        # natural layout (float32) first
        dims = [(h, w, *padded(h, w))]
        while dims[-1][2] * dims[-1][3] > COARSEST and max(dims[-1][:2]) > 1:
            hc, wc = (dims[-1][0] + 1) // 2, (dims[-1][1] + 1) // 2
            dims.append((hc, wc, *padded(hc, wc)))
        dims_arr = np.array(dims, dtype=np.int64)
        wx = [np.zeros(d[2:], np.float32) for d in dims]
        wy = [np.zeros(d[2:], np.float32) for d in dims]
        _fine_pairs(wx_rb, wy_rb, scale, wx[0], wy[0])
        for lev in range(1, len(dims)):
            _coarsen(wx[lev - 1], wy[lev - 1], wx[lev], wy[lev], dims[lev][0], dims[lev][1], COARSE_SCALE)
        # ... then red-black, all levels in one flat buffer per quantity
        sizes = dims_arr[:, 2] * dims_arr[:, 3]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        total = int(offsets[-1])
        mg_wx, mg_wy, mg_inv = (np.empty(total, np.float32) for _ in range(3))
        for lev, d in enumerate(dims):
            inv = np.zeros(d[2:], np.float32)
            _inverse_diagonal(wx[lev], wy[lev], inv)
            for nat, buf in ((wx[lev], mg_wx), (wy[lev], mg_wy), (inv, mg_inv)):
                split(nat, level(buf, offsets, dims_arr, lev))
        # coarsest grid: dense pseudo-inverse over its active cells (`inv` is the last level's)
        cells = np.flatnonzero(inv).astype(np.int64)
        coarse_pinv = coarse_inverse(_coarsest_matrix(wx[-1], wy[-1], cells))
        i, j = np.divmod(cells, dims[-1][3])
        coarse_cells = ((((i + j) % 2) * dims[-1][2] + i) * (dims[-1][3] // 2) + j // 2).astype(np.int64)
        z_work, b_work = np.zeros(total, np.float32), np.zeros(total, np.float32)
        self.arrays = (mg_wx, mg_wy, mg_inv, z_work, b_work, offsets, dims_arr, coarse_cells, coarse_pinv)


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
def label_parts(mask, weights, labels):
    """Connected parts: pixels joined by pairs of positive weight (4-connected pixels of the mask
    with a positive weight); returns their count.

    ``labels`` (h, w) gets 0..n-1 on pixels with a pair of positive weight and -1 elsewhere. Two
    passes: provisional labels from the left and upper neighbours, with their equivalences in a
    union-find forest; then each label's root, numbered in order.
    """
    h, w = mask.shape
    parent = np.empty(h * w, np.int32)
    n = 0
    for i in range(h):
        for j in range(w):
            if not (mask[i, j] and weights[i, j] > 0.0):
                labels[i, j] = -1
                continue
            left = labels[i, j - 1] if j > 0 else -1
            up = labels[i - 1, j] if i > 0 else -1
            if left >= 0:
                lab = left
                if up >= 0 and up != left:
                    ra, rb = _find(parent, left), _find(parent, up)
                    if ra != rb:
                        parent[max(ra, rb)] = min(ra, rb)
            elif up >= 0:
                lab = up
            else:
                lab = n  # a new part, or a pixel on its own (told apart below)
                parent[n] = n
                n += 1
            labels[i, j] = lab
    # pixels with no pair: -1; the rest: their root (the smallest label of the part), in order
    alone = np.ones(n, np.bool_)
    for i in range(h):
        for j in range(w):
            lab = labels[i, j]
            if lab >= 0 and ((j + 1 < w and labels[i, j + 1] >= 0) or (i + 1 < h and labels[i + 1, j] >= 0)):
                alone[_find(parent, lab)] = False
    final = np.empty(n, np.int32)
    count = 0
    for a in range(n):
        root = _find(parent, a)
        if root == a:
            if alone[a]:
                final[a] = -1
            else:
                final[a] = count
                count += 1
        else:
            final[a] = final[root]
    for i in range(h):
        for j in range(w):
            if labels[i, j] >= 0:
                labels[i, j] = final[labels[i, j]]
    return count
