"""One multigrid V-cycle, the preconditioner of the conjugate gradients (:mod:`.pcg`).

Coarsening is cell-centred: coarse cell ``(I, J)`` is the 2x2 block of fine cells
``(2I-1 .. 2I, 2J-1 .. 2J)`` (the coarse operators are built by :mod:`.levels`). Prolongation is
piecewise constant, restriction its transpose (the sum over the block).

The cycle is a symmetric V(2, 2): red-black Gauss-Seidel, red then black before the coarse-grid
correction, black then red after; the coarsest grid solved exactly with a precomputed
pseudo-inverse. Such a cycle is a symmetric positive (semi-)definite operator, so a valid
preconditioner for conjugate gradients. It runs in float32 (half the memory traffic of float64):
only the preconditioner is rounded so, never the operator CG solves.

The kernels work on rows of the red-black layout (:mod:`.layout`); the level drivers run them over
all rows, in parallel on big grids and serially on small ones. A parallel Gauss-Seidel sweep cuts
the rows into one block per thread; each block sweeps its rows in one pass (colour ``lead`` on row
``i``, the other colour on row ``i - 1``) and the rows where blocks meet are finished afterwards.

References
----------
.. [1] U. Trottenberg, C. Oosterlee, A. Schueller, "Multigrid", Academic Press 2001
   (cell-centred grids, red-black smoothing and ordering).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numba
import numpy as np
from numba import prange

from shadeform.integration._multigrid.layout import FAST, around, chunk, copy_flat, level, pair_rows

#: Red-black Gauss-Seidel sweeps before and after each coarse-grid correction (the V(2, 2) cycle).
#: Re-checked on the bench's 256^2 and 1024^2 disks, 1 thread (``benchmarks/results/poisson.md``):
#: 1 sweep needs 1.5x the iterations and is slower; 3 save up to two iterations, at about equal time.
SWEEPS = 2
#: Levels with fewer cells than this run on one thread (a parallel launch costs more there).
#: Chosen for 2 cores when the solver was written; on which data was not recorded.
PARALLEL_MIN = 1 << 15
#: A parallel sweep gives each thread a block of at least this many rows (not a tuned value).
_BLOCK_ROWS = 8

# ---------------------------------------------------------------------------------------------
# Row kernels (red-black layout). The level drivers run them over all rows: in parallel on big
# grids, serially on small ones.
# ---------------------------------------------------------------------------------------------


@numba.njit(cache=True, fastmath=FAST)
def _gs_row(z, b, wx, wy, inv, i, c, first):
    """Gauss-Seidel on the cells of colour ``c`` in row ``i``; with ``first`` the other colour is
    taken as 0 (the cycle's zero initial guess) without reading it.

    Runs over ``k = 1 .. m-2`` (a fixed range, so that the loop vectorises; the cells there beyond
    the interior are border cells, which stay 0), plus ``k = 0`` when that is column 1.
    """
    s = (i + c) & 1
    m = z.shape[2]
    zc = z[c, i]
    bc = b[c, i]
    iv = inv[c, i]
    if first:
        for k in range(1, m - 1):
            zc[k] = bc[k] * iv[k]
        if s == 1:
            zc[0] = bc[0] * iv[0]
        return
    _, zo, zu, zd = around(z, c, i)
    wr, wl, wd, wu = pair_rows(wx, wy, c, i)
    for k in range(1, m - 1):
        zc[k] = (
            bc[k] + wr[k] * zo[k + s] + wl[k + s - 1] * zo[k + s - 1] + wd[k] * zd[k] + wu[k] * zu[k]
        ) * iv[k]
    if s == 1:
        zc[0] = (bc[0] + wr[0] * zo[1] + wl[0] * zo[0] + wd[0] * zd[0] + wu[0] * zu[0]) * iv[0]


@numba.njit(cache=True, fastmath=FAST)
def _residual_row(z, b, wx, wy, i, c, out):
    """``out[k] = (b - L z)`` at the cells of colour ``c`` in row ``i`` (0 on border cells)."""
    s = (i + c) & 1
    m = z.shape[2]
    bc = b[c, i]
    zc, zo, zu, zd = around(z, c, i)
    wr, wl, wd, wu = pair_rows(wx, wy, c, i)
    for k in range(1, m - 1):
        out[k] = bc[k] - (
            (wr[k] + wl[k + s - 1] + wd[k] + wu[k]) * zc[k]
            - wr[k] * zo[k + s]
            - wl[k + s - 1] * zo[k + s - 1]
            - wd[k] * zd[k]
            - wu[k] * zu[k]
        )
    out[m - 1] = 0.0
    out[0] = 0.0
    if s == 1:
        out[0] = bc[0] - (
            (wr[0] + wl[0] + wd[0] + wu[0]) * zc[0]
            - wr[0] * zo[1]
            - wl[0] * zo[0]
            - wd[0] * zd[0]
            - wu[0] * zu[0]
        )


@numba.njit(cache=True)
def _sweep_block(z, b, wx, wy, inv, i0, i1, lead, first):
    """Rows ``i0 .. i1-1`` of a red-black sweep in one pass: colour ``lead`` (0 red, 1 black) on
    row ``i``, then the other colour on row ``i - 1``, whose ``lead`` neighbours are final by
    then. The forward sweep leads with red, its adjoint with black. The second colour on the
    block's first and last rows needs the neighbouring blocks: :func:`_sweep_edges` does those
    afterwards."""
    for i in range(i0, i1):
        _gs_row(z, b, wx, wy, inv, i, lead, first)
        if i - 1 > i0:
            _gs_row(z, b, wx, wy, inv, i - 1, 1 - lead, False)


@numba.njit(cache=True)
def _sweep_edges(z, b, wx, wy, inv, i0, i1, lead):
    if i1 > i0:
        _gs_row(z, b, wx, wy, inv, i0, 1 - lead, False)
    if i1 - 1 > i0:
        _gs_row(z, b, wx, wy, inv, i1 - 1, 1 - lead, False)


@numba.njit(cache=True)
def _restrict_row(z, b, wx, wy, h, bc, ci, wc, ra, rb):
    """Coarse row ``ci`` of the restricted residual (the sum of ``b - L z`` over each block).

    Called after a sweep that ends with black, so the black residual is 0: only the red cells of
    each block, ``(2ci-1, 2cj-1)`` (``k = cj - 1``) and ``(2ci, 2cj)`` (``k = cj``), are summed.
    """
    _residual_row(z, b, wx, wy, 2 * ci - 1, 0, ra)
    if 2 * ci <= h:
        _residual_row(z, b, wx, wy, 2 * ci, 0, rb)
    else:
        rb[:] = 0.0
    for cc in range(2):
        s = (ci + cc) & 1
        row = bc[cc, ci]
        for k in range(1 - s, (wc - s) // 2 + 1):
            cj = 2 * k + s
            row[k] = ra[cj - 1] + rb[cj]


@numba.njit(cache=True, fastmath=FAST)
def _prolong_rows(z, zc, h, ci, tmp):
    """Add the coarse correction of coarse row ``ci`` to the red cells of fine rows ``2ci-1`` and
    ``2ci``. Black is relaxed next, which overwrites it without reading it; the red sweep after
    that overwrites the red inactive and border cells touched here (with 0) before anything reads
    them with a non-zero weight."""
    for cc in range(2):
        s = (ci + cc) & 1
        src = zc[cc, ci]
        for k in range(src.shape[0]):
            tmp[2 * k + s] = src[k]
    for i in range(2 * ci - 1, min(2 * ci, h) + 1):
        s = i & 1
        zr = z[0, i]
        for k in range(1, zr.shape[0] - 1):
            zr[k] += tmp[k + s]  # red cell (i, 2k + s) lies in coarse column k + s
        if s == 1:
            zr[0] += tmp[1]


# ---------------------------------------------------------------------------------------------
# Level drivers
# ---------------------------------------------------------------------------------------------


@numba.njit(cache=True, parallel=True)
def _sweep_par(z, b, wx, wy, inv, h, back, first, blocks):
    lead = 1 if back else 0
    first = first and not back
    for t in prange(blocks):
        i0, i1 = chunk(h, t, blocks)
        _sweep_block(z, b, wx, wy, inv, i0 + 1, i1 + 1, lead, first)
    for t in range(blocks):
        i0, i1 = chunk(h, t, blocks)
        _sweep_edges(z, b, wx, wy, inv, i0 + 1, i1 + 1, lead)


@numba.njit(cache=True)
def _sweep_ser(z, b, wx, wy, inv, h, back, first):
    lead = 1 if back else 0
    _sweep_block(z, b, wx, wy, inv, 1, h + 1, lead, first and not back)
    _sweep_edges(z, b, wx, wy, inv, 1, h + 1, lead)


@numba.njit(cache=True, parallel=True)
def _restrict_par(z, b, wx, wy, h, bc, hc, wc):
    for ci in prange(1, hc + 1):
        ra = np.empty(z.shape[2], z.dtype)
        rb = np.empty(z.shape[2], z.dtype)
        _restrict_row(z, b, wx, wy, h, bc, ci, wc, ra, rb)


@numba.njit(cache=True)
def _restrict_ser(z, b, wx, wy, h, bc, hc, wc):
    ra = np.empty(z.shape[2], z.dtype)
    rb = np.empty(z.shape[2], z.dtype)
    for ci in range(1, hc + 1):
        _restrict_row(z, b, wx, wy, h, bc, ci, wc, ra, rb)


@numba.njit(cache=True, parallel=True)
def _prolong_par(z, zc, h, hc):
    for ci in prange(1, hc + 1):
        tmp = np.empty(2 * zc.shape[2], zc.dtype)
        _prolong_rows(z, zc, h, ci, tmp)


@numba.njit(cache=True)
def _prolong_ser(z, zc, h, hc):
    tmp = np.empty(2 * zc.shape[2], zc.dtype)
    for ci in range(1, hc + 1):
        _prolong_rows(z, zc, h, ci, tmp)


@numba.njit(cache=True)
def _views(wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, lev):
    """Level ``lev``'s pair weights, inverse diagonal, values and right-hand side."""
    return (
        level(wx_all, offsets, dims, lev),
        level(wy_all, offsets, dims, lev),
        level(inv_all, offsets, dims, lev),
        level(z_all, offsets, dims, lev),
        level(b_all, offsets, dims, lev),
    )


@numba.njit(cache=True)
def _row_blocks(dims, lev, threads):
    """(whether level ``lev`` runs in parallel, the number of row blocks of its sweeps)."""
    parallel = threads > 1 and dims[lev, 2] * dims[lev, 3] >= PARALLEL_MIN
    return parallel, min(threads, dims[lev, 0] // _BLOCK_ROWS) if parallel else 1


@numba.njit(cache=True)
def _smooth(z, b, wx, wy, inv, h, sweeps, back, blocks):
    """``sweeps`` red-black sweeps: red first from a zero initial guess, or with ``back`` the
    adjoint, black first."""
    for k in range(sweeps):
        if blocks > 1:
            _sweep_par(z, b, wx, wy, inv, h, back, k == 0, blocks)
        else:
            _sweep_ser(z, b, wx, wy, inv, h, back, k == 0)


@numba.njit(cache=True)
def vcycle(r, levels, sweeps, threads):
    """``z_all[level 0] = B r``: one symmetric V-cycle from a zero initial guess.

    ``r`` is the fine residual (float64, red-black layout); ``levels`` is
    :attr:`.levels.Levels.arrays`, ``z_all`` its work buffer of values. Before each coarse-grid
    correction: ``sweeps`` red-black sweeps, red first; after it the adjoint, black first.
    """
    wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, coarse_cells, coarse_pinv = levels
    n_levels = dims.shape[0]
    copy_flat(r.reshape(r.size), b_all[offsets[0] : offsets[1]])  # float32 from here on
    # down: smooth, restrict the residual
    for lev in range(n_levels - 1):
        wx, wy, inv, z, b = _views(wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, lev)
        h = dims[lev, 0]
        parallel, blocks = _row_blocks(dims, lev, threads)
        _smooth(z, b, wx, wy, inv, h, sweeps, False, blocks)
        bc = level(b_all, offsets, dims, lev + 1)
        if parallel:
            _restrict_par(z, b, wx, wy, h, bc, dims[lev + 1, 0], dims[lev + 1, 1])
        else:
            _restrict_ser(z, b, wx, wy, h, bc, dims[lev + 1, 0], dims[lev + 1, 1])
    # coarsest: exact (pseudo-inverse) solve on its active cells
    last = n_levels - 1
    zl = z_all[offsets[last] : offsets[last + 1]]
    bl = b_all[offsets[last] : offsets[last + 1]]
    m = coarse_cells.shape[0]
    for a in range(m):
        s = 0.0
        for k in range(m):
            s += coarse_pinv[a, k] * bl[coarse_cells[k]]
        zl[coarse_cells[a]] = s
    # up: correct, smooth
    for lev in range(n_levels - 2, -1, -1):
        wx, wy, inv, z, b = _views(wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, lev)
        h = dims[lev, 0]
        parallel, blocks = _row_blocks(dims, lev, threads)
        zc = level(z_all, offsets, dims, lev + 1)
        if parallel:
            _prolong_par(z, zc, h, dims[lev + 1, 0])
        else:
            _prolong_ser(z, zc, h, dims[lev + 1, 0])
        _smooth(z, b, wx, wy, inv, h, sweeps, True, blocks)


@contextmanager
def threads_for(cells: int) -> Iterator[int]:
    """Run the kernels called inside on one thread when the grid has fewer than
    :data:`PARALLEL_MIN` cells, on all of numba's threads otherwise; yields the count.

    A small grid gains nothing from a parallel launch, and on a loaded machine every launch
    waits for its slowest thread: the 2002 method's small Poisson solves had runs 2-6x their
    median with another program on a core (``benchmarks/results/stalls.md``)."""
    threads = numba.get_num_threads()
    if cells >= PARALLEL_MIN or threads == 1:
        yield threads
        return
    numba.set_num_threads(1)
    try:
        yield 1
    finally:
        numba.set_num_threads(threads)
