"""Multigrid-preconditioned conjugate gradients for the masked, weighted 5-point graph Laplacian.

The system is ``L z = b`` with ``L = D^T W D``: one unknown per object pixel, one term per
4-neighbour pair of object pixels, weighted by the smaller of the two pixels' weights. ``L`` is
singular, with one free offset per connected part (pixels joined by pairs of positive weight); the
solution returned has mean 0 over each part.

Grids
-----
Every level is a dense grid over the mask's bounding box, with a border of inactive cells so that
no kernel needs a bounds check: interior rows ``1..h``, columns ``1..w``, padded to ``hp = h + 2``
rows and ``wp = 2 (w // 2 + 2)`` columns. On the multigrid levels ``wx[i, j]`` is the weight of
the pair ``(i, j)-(i, j + 1)`` and ``wy[i, j]`` of ``(i, j)-(i + 1, j)``, 0 where a pair is
missing; a cell with no pair of positive weight is *inactive*: ``inv_diag`` is 0 there and its
value stays 0. The fine operator itself is stored as the pixels' weights (0 off the mask), the
pair weights taken on the fly as the smaller of two: half the memory traffic of two pair arrays.

Every grid is kept in *red-black order*: an array ``a[c, i, k]`` of shape ``(2, hp, wp / 2)``
holds the cells of colour ``c = (i + j) % 2``, cell ``(i, j)`` at ``k = j // 2``. A cell's four
neighbours all have the other colour; in that array they sit at ``[i, k + s - 1]`` (left),
``[i, k + s]`` (right), ``[i - 1, k]`` and ``[i + 1, k]`` (up, down), with ``s = (i + c) % 2``.
Every loop of a Gauss-Seidel half-sweep is then contiguous, which the compiler vectorises (about
seven times faster than striding over one colour of the natural layout). Loops run over the fixed
range ``k = 1 .. m-2`` (``m = wp / 2``; a variable start defeats the vectoriser), which covers the
interior but for column 1, done on its own, and otherwise only border cells, which stay 0.

Coarsening
----------
Cell-centred: coarse cell ``(I, J)`` is the 2x2 block of fine cells ``(2I-1 .. 2I, 2J-1 .. 2J)``.
Prolongation is piecewise constant, restriction its transpose (sum over the block). The Galerkin
product ``P^T L P`` is again a 5-point graph Laplacian, whose pair weights are the sums of the fine
pairs crossing between two blocks; it is used at half that weight, the classical over-correction
that makes a piecewise-constant correction as large as the smooth error it stands for (Braess
1995; for uniform weights the halved operator is exactly the Laplacian rediscretised on the coarse
grid, and 0.5 is a sharp optimum: 0.46 or 0.55 need half as many iterations again). Blocks not
joined by any fine pair are not joined on the coarse grid either, so holes and separate parts
stay apart until the blocks themselves touch.

Cycle and accuracy
------------------
A symmetric V(2, 2) cycle: red-black Gauss-Seidel (red then black before the coarse-grid
correction, black then red after), the coarsest grid (at most ``_COARSEST`` cells) solved exactly
with a precomputed pseudo-inverse. Such a cycle is a symmetric positive (semi-)definite operator,
a valid preconditioner for conjugate gradients, which guarantee the accuracy: the iteration stops
when ``|b - L z| <= tol |b|``, with ``L`` and all vectors of the iteration in float64. Only the
preconditioner runs in float32 (half the memory traffic); its rounding costs no iterations.

References
----------
.. [1] D. Braess, "Towards algebraic multigrid for elliptic problems of second order",
   Computing 55, 1995.
.. [2] U. Trottenberg, C. Oosterlee, A. Schueller, "Multigrid", Academic Press 2001
   (cell-centred grids, red-black smoothing and ordering).
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
#: Pair weights (relative to the largest) below this are left out of the float32 preconditioner.
_TINY = 1e-30
#: Red-black Gauss-Seidel sweeps before and after each coarse-grid correction.
_SWEEPS = 2
#: Row blocks of the flat vector kernels.
_CHUNKS = 64

_FAST = {"contract", "reassoc", "nsz", "arcp"}


@numba.njit(cache=True)
def _split(nat, out):
    """Natural ``(hp, wp)`` grid -> red-black ``(2, hp, wp / 2)``."""
    for c in range(2):
        for i in range(nat.shape[0]):
            s = (i + c) & 1
            for k in range(out.shape[2]):
                out[c, i, k] = nat[i, 2 * k + s]


# ---------------------------------------------------------------------------------------------
# Row kernels (red-black layout). The level drivers run them over all rows: in parallel on big
# grids, serially on small ones.
# ---------------------------------------------------------------------------------------------

@numba.njit(cache=True, fastmath=_FAST)
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
    o = 1 - c
    zo = z[o, i]
    zu = z[o, i - 1]
    zd = z[o, i + 1]
    wxc = wx[c, i]
    wxo = wx[o, i]
    wyc = wy[c, i]
    wyu = wy[o, i - 1]
    for k in range(1, m - 1):
        zc[k] = (bc[k] + wxc[k] * zo[k + s] + wxo[k + s - 1] * zo[k + s - 1]
                 + wyc[k] * zd[k] + wyu[k] * zu[k]) * iv[k]
    if s == 1:
        zc[0] = (bc[0] + wxc[0] * zo[1] + wxo[0] * zo[0] + wyc[0] * zd[0] + wyu[0] * zu[0]) * iv[0]


@numba.njit(cache=True, fastmath=_FAST)
def _residual_row(z, b, wx, wy, i, c, out):
    """``out[k] = (b - L z)`` at the cells of colour ``c`` in row ``i`` (0 on border cells)."""
    s = (i + c) & 1
    m = z.shape[2]
    o = 1 - c
    zc = z[c, i]
    bc = b[c, i]
    zo = z[o, i]
    zu = z[o, i - 1]
    zd = z[o, i + 1]
    wxc = wx[c, i]
    wxo = wx[o, i]
    wyc = wy[c, i]
    wyu = wy[o, i - 1]
    for k in range(1, m - 1):
        out[k] = bc[k] - ((wxc[k] + wxo[k + s - 1] + wyc[k] + wyu[k]) * zc[k]
                          - wxc[k] * zo[k + s] - wxo[k + s - 1] * zo[k + s - 1]
                          - wyc[k] * zd[k] - wyu[k] * zu[k])
    out[m - 1] = 0.0
    out[0] = 0.0
    if s == 1:
        out[0] = bc[0] - ((wxc[0] + wxo[0] + wyc[0] + wyu[0]) * zc[0] - wxc[0] * zo[1]
                          - wxo[0] * zo[0] - wyc[0] * zd[0] - wyu[0] * zu[0])


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


@numba.njit(cache=True, fastmath=_FAST)
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

@numba.njit(cache=True, inline="always")
def _block(n, k, blocks):
    return 1 + (n * k) // blocks, 1 + (n * (k + 1)) // blocks


@numba.njit(cache=True, parallel=True)
def _sweep_par(z, b, wx, wy, inv, h, back, first, blocks):
    lead = 1 if back else 0
    first = first and not back
    for t in prange(blocks):
        i0, i1 = _block(h, t, blocks)
        _sweep_block(z, b, wx, wy, inv, i0, i1, lead, first)
    for t in range(blocks):
        i0, i1 = _block(h, t, blocks)
        _sweep_edges(z, b, wx, wy, inv, i0, i1, lead)


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
def _level(buf, offsets, dims, lev):
    """Level ``lev``'s red-black view ``(2, hp, wp / 2)`` of a flat per-level buffer."""
    return buf[offsets[lev]:offsets[lev + 1]].reshape(2, dims[lev, 2], dims[lev, 3] // 2)


@numba.njit(cache=True)
def _vcycle(r, wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, coarse_cells, coarse_pinv,
            sweeps, threads):
    """``z_all[level 0] = B r``: one symmetric V-cycle from a zero initial guess.

    ``r`` is the fine residual (float64, red-black layout). Before each coarse-grid correction:
    ``sweeps`` red-black sweeps, red first; after it the adjoint, black first.
    """
    n_levels = dims.shape[0]
    _copy_flat(r.reshape(r.size), b_all[offsets[0]:offsets[1]])  # float32 from here on
    # down: smooth, restrict the residual
    for lev in range(n_levels - 1):
        h = dims[lev, 0]
        wx = _level(wx_all, offsets, dims, lev)
        wy = _level(wy_all, offsets, dims, lev)
        inv = _level(inv_all, offsets, dims, lev)
        z = _level(z_all, offsets, dims, lev)
        b = _level(b_all, offsets, dims, lev)
        bc = _level(b_all, offsets, dims, lev + 1)
        parallel = threads > 1 and dims[lev, 2] * dims[lev, 3] >= _PARALLEL_MIN
        blocks = min(threads, h // 8) if parallel else 1
        for k in range(sweeps):
            if blocks > 1:
                _sweep_par(z, b, wx, wy, inv, h, False, k == 0, blocks)
            else:
                _sweep_ser(z, b, wx, wy, inv, h, False, k == 0)
        if parallel:
            _restrict_par(z, b, wx, wy, h, bc, dims[lev + 1, 0], dims[lev + 1, 1])
        else:
            _restrict_ser(z, b, wx, wy, h, bc, dims[lev + 1, 0], dims[lev + 1, 1])
    # coarsest: exact (pseudo-inverse) solve on its active cells
    last = n_levels - 1
    zl = z_all[offsets[last]:offsets[last + 1]]
    bl = b_all[offsets[last]:offsets[last + 1]]
    m = coarse_cells.shape[0]
    for a in range(m):
        s = 0.0
        for k in range(m):
            s += coarse_pinv[a, k] * bl[coarse_cells[k]]
        zl[coarse_cells[a]] = s
    # up: correct, smooth
    for lev in range(n_levels - 2, -1, -1):
        h = dims[lev, 0]
        wx = _level(wx_all, offsets, dims, lev)
        wy = _level(wy_all, offsets, dims, lev)
        inv = _level(inv_all, offsets, dims, lev)
        z = _level(z_all, offsets, dims, lev)
        b = _level(b_all, offsets, dims, lev)
        zc = _level(z_all, offsets, dims, lev + 1)
        parallel = threads > 1 and dims[lev, 2] * dims[lev, 3] >= _PARALLEL_MIN
        blocks = min(threads, h // 8) if parallel else 1
        if parallel:
            _prolong_par(z, zc, h, dims[lev + 1, 0])
        else:
            _prolong_ser(z, zc, h, dims[lev + 1, 0])
        for k in range(sweeps):
            if blocks > 1:
                _sweep_par(z, b, wx, wy, inv, h, True, False, blocks)
            else:
                _sweep_ser(z, b, wx, wy, inv, h, True, False)


# ---------------------------------------------------------------------------------------------
# Conjugate gradients (float64, red-black layout, fused vector kernels)
# ---------------------------------------------------------------------------------------------

@numba.njit(cache=True, parallel=True, fastmath=_FAST)
def _apply_dot(p, wpix, h, q):
    """``q = L p`` (the pair weights are the smaller of the two pixel weights); returns ``p . q``.
    Writes every entry of rows ``1..h``."""
    m = p.shape[2]
    total = 0.0
    for i in prange(1, h + 1):
        t = 0.0
        for c in range(2):
            s = (i + c) & 1
            o = 1 - c
            pc = p[c, i]
            po = p[o, i]
            pu = p[o, i - 1]
            pd = p[o, i + 1]
            wc = wpix[c, i]
            wo = wpix[o, i]
            wu = wpix[o, i - 1]
            wd = wpix[o, i + 1]
            qc = q[c, i]
            for k in range(1, m - 1):
                v = (min(wc[k], wo[k + s]) * (pc[k] - po[k + s])
                     + min(wc[k], wo[k + s - 1]) * (pc[k] - po[k + s - 1])
                     + min(wc[k], wd[k]) * (pc[k] - pd[k]) + min(wc[k], wu[k]) * (pc[k] - pu[k]))
                qc[k] = v
                t += v * pc[k]
            qc[0] = 0.0
            qc[m - 1] = 0.0
            if s == 1:
                v = (min(wc[0], wo[1]) * (pc[0] - po[1]) + min(wc[0], wo[0]) * (pc[0] - po[0])
                     + min(wc[0], wd[0]) * (pc[0] - pd[0]) + min(wc[0], wu[0]) * (pc[0] - pu[0]))
                qc[0] = v
                t += v * pc[0]
        total += t
    return total


@numba.njit(cache=True, parallel=True, fastmath=_FAST)
def _update_xr(x, r, p, q, alpha):
    """``x += alpha p``, ``r -= alpha q`` (flat arrays); returns ``r . r``."""
    n = x.shape[0]
    total = 0.0
    for t in prange(_CHUNKS):
        s = 0.0
        for a in range(n * t // _CHUNKS, n * (t + 1) // _CHUNKS):
            x[a] += alpha * p[a]
            v = r[a] - alpha * q[a]
            r[a] = v
            s += v * v
        total += s
    return total


@numba.njit(cache=True, parallel=True, fastmath=_FAST)
def _dot(a, b):
    """``a . b`` (flat arrays)."""
    n = a.shape[0]
    total = 0.0
    for t in prange(_CHUNKS):
        s = 0.0
        for i in range(n * t // _CHUNKS, n * (t + 1) // _CHUNKS):
            s += a[i] * b[i]
        total += s
    return total


@numba.njit(cache=True, parallel=True)
def _copy_flat(src, dst):
    """``dst = src`` (flat arrays, with a cast)."""
    n = src.shape[0]
    for t in prange(_CHUNKS):
        for i in range(n * t // _CHUNKS, n * (t + 1) // _CHUNKS):
            dst[i] = src[i]


@numba.njit(cache=True, parallel=True, fastmath=_FAST)
def _update_p(p, z, beta):
    """``p = z + beta p`` (flat arrays)."""
    n = p.shape[0]
    for t in prange(_CHUNKS):
        for a in range(n * t // _CHUNKS, n * (t + 1) // _CHUNKS):
            p[a] = z[a] + beta * p[a]


@numba.njit(cache=True)
def _pcg(r, x, p, q, wpix, wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, coarse_cells,
         coarse_pinv, sweeps, tol, maxiter, threads):
    """Preconditioned CG from ``x = 0``, all in red-black layout; returns (iterations, final
    relative residual).

    ``r`` holds the right-hand side on entry and the residual on return; ``p, q`` are work
    arrays (any content). ``wpix`` (float64 pixel weights) defines the operator; the multigrid
    levels (float32) only precondition.
    """
    h = dims[0, 0]
    n = r.size
    xf = x.reshape(n)
    rf = r.reshape(n)
    pf = p.reshape(n)
    qf = q.reshape(n)
    xf[:] = 0.0
    bb = _dot(rf, rf)
    if bb == 0.0:
        return 0, 0.0
    q[:, 0, :] = 0.0  # rows _apply_dot does not write
    q[:, h + 1:, :] = 0.0
    zf = z_all[offsets[0]:offsets[1]]
    _vcycle(r, wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, coarse_cells, coarse_pinv,
            sweeps, threads)
    rz = _dot(rf, zf)
    _copy_flat(zf, pf)
    rr = bb
    it = 0
    while it < maxiter:
        it += 1
        pq = _apply_dot(p, wpix, h, q)
        if not pq > 0.0:
            break
        rr = _update_xr(xf, rf, pf, qf, rz / pq)
        if rr <= tol * tol * bb:
            break
        _vcycle(r, wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, coarse_cells,
                coarse_pinv, sweeps, threads)
        rz_new = _dot(rf, zf)
        if not rz_new > 0.0:
            break
        _update_p(pf, zf, rz_new / rz)
        rz = rz_new
    return it, np.sqrt(rr / bb)


# ---------------------------------------------------------------------------------------------
# Right-hand side from normals, result to image (red-black layout)
# ---------------------------------------------------------------------------------------------

_BIG = np.finfo(np.float64).max


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
    zx[:, h + 1:, :] = 0.0
    zy[:, h + 1:, :] = 0.0
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


@numba.njit(cache=True, parallel=True, fastmath=_FAST)
def _divergence_rb(zx, zy, wpix, h, b):
    """``b = D^T W s`` with the trapezoid-rule steps ``s`` of each pair: ``+dz/dx`` to the right,
    ``-dz/dy`` one row down (y is up). Writes every entry."""
    m = b.shape[2]
    for i in prange(1, h + 1):
        for c in range(2):
            s = (i + c) & 1
            o = 1 - c
            xc = zx[c, i]
            xo = zx[o, i]
            yc = zy[c, i]
            yu = zy[o, i - 1]
            yd = zy[o, i + 1]
            wc = wpix[c, i]
            wo = wpix[o, i]
            wu = wpix[o, i - 1]
            wd = wpix[o, i + 1]
            bc = b[c, i]
            for k in range(1, m - 1):
                bc[k] = 0.5 * (min(wc[k], wo[k + s - 1]) * (xo[k + s - 1] + xc[k])
                               - min(wc[k], wo[k + s]) * (xc[k] + xo[k + s])
                               + min(wc[k], wd[k]) * (yc[k] + yd[k])
                               - min(wc[k], wu[k]) * (yu[k] + yc[k]))
            bc[0] = 0.0
            bc[m - 1] = 0.0
            if s == 1:
                bc[0] = 0.5 * (min(wc[0], wo[0]) * (xo[0] + xc[0])
                               - min(wc[0], wo[1]) * (xc[0] + xo[1])
                               + min(wc[0], wd[0]) * (yc[0] + yd[0])
                               - min(wc[0], wu[0]) * (yu[0] + yc[0]))
    b[:, 0, :] = 0.0
    b[:, h + 1:, :] = 0.0


@numba.njit(cache=True, parallel=True)
def _finish(x, mask, labels, n_parts, r0, c0, out):
    """``out[r0 + r, c0 + c]`` = the value of cell ``(r + 1, c + 1)`` less the mean of its part,
    on the mask's pixels."""
    h, w = mask.shape
    blocks = min(_CHUNKS, h)
    sums = np.zeros((blocks, n_parts))
    counts = np.zeros((blocks, n_parts))
    for t in prange(blocks):
        for r in range(h * t // blocks, h * (t + 1) // blocks):
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


# ---------------------------------------------------------------------------------------------
# Set-up kernels
# ---------------------------------------------------------------------------------------------

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


@numba.njit(cache=True)
def _pixel_weights(mask, weights, scale, out):
    """Red-black pixel weights ``scale * weights`` on the mask, 0 elsewhere."""
    h, w = mask.shape
    out[:] = 0.0
    for i in range(1, h + 1):
        for j in range(1, w + 1):
            if mask[i - 1, j - 1]:
                out[(i + j) & 1, i, j >> 1] = scale * weights[i - 1, j - 1]


@numba.njit(cache=True)
def _fine_pairs(mask, weights, scale, wx, wy):
    """Natural float32 pair weights: ``scale`` times the smaller of the two pixels' weights, 0
    below ``_TINY``."""
    h, w = mask.shape
    for i in range(h):
        for j in range(w):
            if not mask[i, j]:
                continue
            if j + 1 < w and mask[i, j + 1]:
                v = scale * min(weights[i, j], weights[i, j + 1])
                if v >= _TINY:
                    wx[i + 1, j + 1] = v
            if i + 1 < h and mask[i + 1, j]:
                v = scale * min(weights[i, j], weights[i + 1, j])
                if v >= _TINY:
                    wy[i + 1, j + 1] = v


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
def _label_parts(mask, weights, labels):
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
            if lab >= 0 and ((j + 1 < w and labels[i, j + 1] >= 0)
                             or (i + 1 < h and labels[i + 1, j] >= 0)):
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
        for di, dj, wt in ((0, 1, wx[i, j]), (0, -1, wx[i, j - 1]),
                           (1, 0, wy[i, j]), (-1, 0, wy[i - 1, j])):
            if wt > 0.0:
                k = where[(i + di) * wp + j + dj]
                A[a, a] += wt
                A[a, k] -= wt
    return A


def _padded(h: int, w: int) -> tuple[int, int]:
    """Padded grid shape: a border of at least one cell, an even number of columns, and in
    red-black order ``k = 1 .. m-2`` (``m = wp / 2``) reaching the last interior column."""
    return h + 2, 2 * (w // 2 + 2)


def _pseudo_inverse(A: np.ndarray) -> np.ndarray:
    """Moore-Penrose inverse of a small symmetric positive semi-definite matrix."""
    if A.shape[0] == 0:
        return np.zeros((0, 0))
    vals, vecs = np.linalg.eigh(A)
    keep = vals > 1e-10 * max(vals[-1], 0.0)
    if not keep.any():
        return np.zeros_like(A)
    return (vecs[:, keep] / vals[keep]) @ vecs[:, keep].T


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
    """

    def __init__(self, mask: np.ndarray, weights: np.ndarray, top: float):
        h, w = mask.shape
        self.mask = mask
        self.shape = _padded(h, w)
        scale = 1.0 / top if top > 0 else 0.0
        rb_shape = (2, self.shape[0], self.shape[1] // 2)
        self.wpix = np.empty(rb_shape)
        _pixel_weights(mask, weights, scale, self.wpix)
        self.labels = np.empty((h, w), np.int32)
        self.n_parts = _label_parts(mask, weights, self.labels)
        self._build_levels(lambda wx, wy: _fine_pairs(mask, weights, scale, wx, wy), _pseudo_inverse)
        self._work = None

    def _build_levels(self, fill_fine_pairs, coarse_inverse) -> None:
        """Multigrid levels from the finest pair weights (``fill_fine_pairs(wx, wy)`` writes them)
        and ``coarse_inverse`` for the dense solve on the coarsest grid."""
        h, w = self.mask.shape
        # multigrid levels: natural layout (float32) first
        dims = [(h, w, *self.shape)]
        while dims[-1][2] * dims[-1][3] > _COARSEST and max(dims[-1][:2]) > 1:
            hc, wc = (dims[-1][0] + 1) // 2, (dims[-1][1] + 1) // 2
            dims.append((hc, wc, *_padded(hc, wc)))
        self.dims = np.array(dims, dtype=np.int64)
        wx = [np.zeros(d[2:], np.float32) for d in dims]
        wy = [np.zeros(d[2:], np.float32) for d in dims]
        fill_fine_pairs(wx[0], wy[0])
        for lev in range(1, len(dims)):
            _coarsen(wx[lev - 1], wy[lev - 1], wx[lev], wy[lev], dims[lev][0], dims[lev][1],
                     _COARSE_SCALE)
        # ... then red-black, all levels in one flat buffer per quantity
        sizes = self.dims[:, 2] * self.dims[:, 3]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        total = int(self.offsets[-1])
        self.mg_wx = np.empty(total, np.float32)
        self.mg_wy = np.empty(total, np.float32)
        self.mg_inv = np.empty(total, np.float32)
        self.z_work = np.zeros(total, np.float32)
        self.b_work = np.zeros(total, np.float32)
        for lev, d in enumerate(dims):
            inv = np.zeros(d[2:], np.float32)
            _inverse_diagonal(wx[lev], wy[lev], inv)
            for nat, buf in ((wx[lev], self.mg_wx), (wy[lev], self.mg_wy), (inv, self.mg_inv)):
                _split(nat, _level(buf, self.offsets, self.dims, lev))
        # coarsest grid: dense pseudo-inverse over its active cells
        cells = np.flatnonzero(inv).astype(np.int64)
        self.coarse_pinv = coarse_inverse(_coarsest_matrix(wx[-1], wy[-1], cells))
        i, j = np.divmod(cells, dims[-1][3])
        self.coarse_cells = ((((i + j) % 2) * dims[-1][2] + i) * (dims[-1][3] // 2)
                             + j // 2).astype(np.int64)

    def _workspace(self) -> list[np.ndarray]:
        """Four float64 red-black arrays, made on first use and kept for the next solves (fresh
        memory costs page faults)."""
        if self._work is None:
            self._work = [np.empty_like(self.wpix) for _ in range(4)]
        return self._work

    def solve(self, normals: np.ndarray, r0: int, c0: int, min_nz: float, out: np.ndarray, *,
              tol: float, maxiter: int) -> tuple[int, float]:
        """Integrate the normals: least-squares depth, mean 0 over each part, into ``out``.

        ``normals`` (float64, C order) and ``out`` are whole images; the mask's pixel ``(r, c)``
        is their pixel ``(r0 + r, c0 + c)``. The slopes are those of
        :func:`shadeform.integration._slopes.slopes` with ``MIN_NZ = min_nz``. Writes ``out`` on the
        mask's pixels only. Returns the number of CG iterations and the final relative residual.
        """
        x, r, p, q = self._workspace()
        _slopes_rb(normals, self.mask, r0, c0, min_nz, p, q)  # p, q: slopes, until CG needs them
        _divergence_rb(p, q, self.wpix, self.dims[0, 0], r)
        it, res = _pcg(r, x, p, q, self.wpix, self.mg_wx, self.mg_wy, self.mg_inv, self.z_work,
                       self.b_work, self.offsets, self.dims, self.coarse_cells, self.coarse_pinv,
                       _SWEEPS, float(tol), int(maxiter), numba.get_num_threads())
        _finish(x, self.mask, self.labels, self.n_parts, r0, c0, out)
        return int(it), float(res)


# ---------------------------------------------------------------------------------------------
# Explicit pair weights (each 4-neighbour pair its own weight), a given right-hand side, and a
# warm start: for iteratively reweighted least squares (shadeform.integration.bilateral)
# ---------------------------------------------------------------------------------------------

@numba.njit(cache=True, parallel=True, fastmath=_FAST)
def _apply_dot_pairs(p, px, py, h, q):
    """``q = L p`` with explicit pair weights: ``px[c, i, k]`` joins cell ``(i, j)`` to its right
    neighbour, ``py[c, i, k]`` to the one below (red-black layout, 0 where a pair is missing);
    returns ``p . q``. Writes every entry of rows ``1..h``."""
    m = p.shape[2]
    total = 0.0
    for i in prange(1, h + 1):
        t = 0.0
        for c in range(2):
            s = (i + c) & 1
            o = 1 - c
            pc = p[c, i]
            po = p[o, i]
            pu = p[o, i - 1]
            pd = p[o, i + 1]
            xc = px[c, i]
            xo = px[o, i]
            yc = py[c, i]
            yu = py[o, i - 1]
            qc = q[c, i]
            for k in range(1, m - 1):
                v = (xc[k] * (pc[k] - po[k + s]) + xo[k + s - 1] * (pc[k] - po[k + s - 1])
                     + yc[k] * (pc[k] - pd[k]) + yu[k] * (pc[k] - pu[k]))
                qc[k] = v
                t += v * pc[k]
            qc[0] = 0.0
            qc[m - 1] = 0.0
            if s == 1:
                v = (xc[0] * (pc[0] - po[1]) + xo[0] * (pc[0] - po[0])
                     + yc[0] * (pc[0] - pd[0]) + yu[0] * (pc[0] - pu[0]))
                qc[0] = v
                t += v * pc[0]
        total += t
    return total


@numba.njit(cache=True)
def _pcg_pairs(r, x, p, q, px, py, wx_all, wy_all, inv_all, z_all, b_all, offsets, dims,
               coarse_cells, coarse_pinv, sweeps, tol, maxiter, threads, from_start):
    """Preconditioned CG for the operator of pair weights ``px, py`` from the initial guess in
    ``x`` (red-black layout); stops at ``|b - L x| <= tol |b|``, or with ``from_start`` at
    ``|b - L x| <= tol |b - L x0|`` (a reduction of the initial residual, for warm starts).
    ``r`` holds ``b`` on entry and the residual on return. Returns (iterations, final
    ``|b - L x| / |b|``)."""
    h = dims[0, 0]
    n = r.size
    xf = x.reshape(n)
    rf = r.reshape(n)
    pf = p.reshape(n)
    qf = q.reshape(n)
    bb = _dot(rf, rf)
    if bb == 0.0:
        xf[:] = 0.0
        return 0, 0.0
    q[:, 0, :] = 0.0
    q[:, h + 1:, :] = 0.0
    _apply_dot_pairs(x, px, py, h, q)
    for a in range(n):
        rf[a] -= qf[a]
    rr = _dot(rf, rf)
    goal = tol * tol * (min(rr, bb) if from_start else bb)
    goal = max(goal, 1e-24 * bb)  # below round-off CG only adds noise
    if rr <= goal:
        return 0, np.sqrt(rr / bb)
    zf = z_all[offsets[0]:offsets[1]]
    _vcycle(r, wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, coarse_cells, coarse_pinv,
            sweeps, threads)
    rz = _dot(rf, zf)
    _copy_flat(zf, pf)
    it = 0
    while it < maxiter:
        it += 1
        pq = _apply_dot_pairs(p, px, py, h, q)
        if not pq > 0.0:
            break
        rr = _update_xr(xf, rf, pf, qf, rz / pq)
        if rr <= goal:
            break
        _vcycle(r, wx_all, wy_all, inv_all, z_all, b_all, offsets, dims, coarse_cells,
                coarse_pinv, sweeps, threads)
        rz_new = _dot(rf, zf)
        if not rz_new > 0.0:
            break
        _update_p(pf, zf, rz_new / rz)
        rz = rz_new
    return it, np.sqrt(rr / bb)


@numba.njit(cache=True)
def _to_rb(nat, out):
    """Natural ``(h, w)`` values -> red-black cells ``(i, j) = (r + 1, c + 1)``, 0 elsewhere."""
    h, w = nat.shape
    out[:] = 0.0
    for r in range(h):
        i = r + 1
        for c in range(w):
            j = c + 1
            out[(i + j) & 1, i, j >> 1] = nat[r, c]


@numba.njit(cache=True)
def _from_rb(rb, out):
    """Red-black cells -> natural ``(h, w)`` values (inverse of :func:`_to_rb`)."""
    h, w = out.shape
    for r in range(h):
        i = r + 1
        for c in range(w):
            j = c + 1
            out[r, c] = rb[(i + j) & 1, i, j >> 1]


@numba.njit(cache=True)
def _fine_pairs_explicit(px, py, scale, wx, wy):
    """Natural float32 fine-level pair weights from explicit ``(h, w)`` pair weights."""
    h, w = px.shape
    for i in range(h):
        for j in range(w):
            v = scale * px[i, j]
            wx[i + 1, j + 1] = v if v >= _TINY else 0.0
            v = scale * py[i, j]
            wy[i + 1, j + 1] = v if v >= _TINY else 0.0


def _graph_pseudo_inverse(A: np.ndarray) -> np.ndarray:
    """Moore-Penrose inverse of a small graph Laplacian, without an eigendecomposition.

    The null space of a graph Laplacian is spanned by the indicator vectors ``e_c`` of its
    connected parts, so ``A + sum_c e_c e_c^T / |c|`` is non-singular and its inverse is
    ``A^+ + sum_c e_c e_c^T / |c|`` (``e_c / sqrt|c|`` orthonormal). One LU solve: far cheaper
    than :func:`_pseudo_inverse` where the machine's BLAS threads are contended.
    """
    import scipy.sparse.csgraph as csgraph

    m = A.shape[0]
    if m == 0:
        return np.zeros((0, 0))
    n_parts, labels = csgraph.connected_components(A != 0, directed=False)
    E = np.zeros((m, n_parts))
    E[np.arange(m), labels] = 1.0
    J = (E / E.sum(axis=0)) @ E.T
    return np.linalg.inv(A + J) - J


class PairHierarchy(Hierarchy):
    """A :class:`Hierarchy` whose operator has one weight per 4-neighbour pair.

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
    The multigrid levels (the preconditioner) come from ``px, py``; :meth:`solve_pairs` can apply
    conjugate gradients to an operator with other pair weights over the same mask, so that a
    preconditioner built for nearby weights is reused (it stays a valid SPD preconditioner; only
    the iteration count depends on how close the weights are).
    """

    def __init__(self, mask: np.ndarray, px: np.ndarray, py: np.ndarray):
        h, w = mask.shape
        self.mask = mask
        self.shape = _padded(h, w)
        top = float(max(px.max(initial=0.0), py.max(initial=0.0)))
        scale = 1.0 / top if top > 0 else 0.0
        rb_shape = (2, self.shape[0], self.shape[1] // 2)
        self.wpix = np.zeros(rb_shape)
        self.labels = np.empty((h, w), np.int32)
        self.n_parts = _label_parts(mask, mask.astype(np.float64), self.labels)
        self._build_levels(lambda wx, wy: _fine_pairs_explicit(px, py, scale, wx, wy),
                           _graph_pseudo_inverse)
        self._work = None
        self.px = np.empty(rb_shape)
        self.py = np.empty(rb_shape)
        _to_rb(px, self.px)
        _to_rb(py, self.py)

    def solve_pairs(self, b: np.ndarray, x0: np.ndarray, *, px: np.ndarray | None = None,
                    py: np.ndarray | None = None, tol: float, maxiter: int,
                    from_start: bool = False) -> tuple[np.ndarray, int, float]:
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
        x, r, p, q = self._workspace()
        if px is None:
            opx, opy = self.px, self.py
        else:
            opx, opy = np.empty_like(self.px), np.empty_like(self.py)
            _to_rb(np.ascontiguousarray(px, dtype=np.float64), opx)
            _to_rb(np.ascontiguousarray(py, dtype=np.float64), opy)
        _to_rb(np.ascontiguousarray(b, dtype=np.float64), r)
        _to_rb(np.ascontiguousarray(x0, dtype=np.float64), x)
        it, res = _pcg_pairs(r, x, p, q, opx, opy, self.mg_wx, self.mg_wy, self.mg_inv,
                             self.z_work, self.b_work, self.offsets, self.dims, self.coarse_cells,
                             self.coarse_pinv, _SWEEPS, float(tol), int(maxiter),
                             numba.get_num_threads(), bool(from_start))
        out = np.empty(self.mask.shape)
        _from_rb(x, out)
        out[~self.mask] = 0.0
        return out, int(it), float(res)
