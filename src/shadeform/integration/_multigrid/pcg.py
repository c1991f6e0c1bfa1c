"""Conjugate gradients for a weighted graph Laplacian on the padded grid, preconditioned by one
multigrid V-cycle (:func:`.cycle.vcycle`) per iteration.

The operator ``L`` is given by its pair weights ``wx, wy`` (float64, red-black layout, see
:mod:`.layout`): ``(L z)_a = sum over pairs (a, b) of w_ab (z_a - z_b)``. The pixel-weighted
problem (:class:`.hierarchy.Hierarchy`) builds these once from its pixel weights, the
pair-weighted one (:class:`.pairs.PairHierarchy`) takes them as given, so both run this one
iteration. ``L`` and all vectors of the iteration are float64, which is what makes the stopping
test ``|b - L x| <= tol |b|`` a guarantee; only the preconditioner runs in float32.

Why a hand-written CG rather than a library: set-up and solve are 20-35 times faster. On the disk of
``benchmarks/bench_poisson.py`` (1024^2, 609 084 pixels, uniform weights, ``|b - L x| <= 1e-8 |b|``,
2 cores) set-up and first solve take 0.13 s here, against 4.7 s for ``scipy.sparse.linalg.cg``
preconditioned by a V-cycle of pyamg's smoothed aggregation (17 iterations) and 2.5 s with pyamg's
Ruge-Stueben AMG (8 iterations); each further solve 0.09 s against 2.2 s and 1.0 s. pyamg runs on
one core; on one thread this solver takes 0.2 s. Figures and both weightings:
``benchmarks/results/poisson.md``.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange

from shadeform.integration._multigrid.cycle import vcycle
from shadeform.integration._multigrid.layout import CHUNKS, FAST, around, chunk, copy_flat, pair_rows

#: Below ``1e-12`` relative residual (squared: ``1e-24``) CG only adds round-off noise.
_FLOOR = 1e-24


@numba.njit(cache=True, parallel=True, fastmath=FAST)
def apply_dot(p, wx, wy, h, q):
    """``q = L p`` for the pair weights ``wx, wy`` (``wx[c, i, k]`` joins cell ``(i, j)`` to its
    right neighbour, ``wy[c, i, k]`` to the one below); returns ``p . q``. Writes every entry of
    rows ``1..h``."""
    m = p.shape[2]
    total = 0.0
    for i in prange(1, h + 1):
        t = 0.0
        for c in range(2):
            s = (i + c) & 1
            pc, po, pu, pd = around(p, c, i)
            wr, wl, wd, wu = pair_rows(wx, wy, c, i)
            qc = q[c, i]
            for k in range(1, m - 1):
                v = (
                    wr[k] * (pc[k] - po[k + s])
                    + wl[k + s - 1] * (pc[k] - po[k + s - 1])
                    + wd[k] * (pc[k] - pd[k])
                    + wu[k] * (pc[k] - pu[k])
                )
                qc[k] = v
                t += v * pc[k]
            qc[0] = 0.0
            qc[m - 1] = 0.0
            if s == 1:
                v = (
                    wr[0] * (pc[0] - po[1])
                    + wl[0] * (pc[0] - po[0])
                    + wd[0] * (pc[0] - pd[0])
                    + wu[0] * (pc[0] - pu[0])
                )
                qc[0] = v
                t += v * pc[0]
        total += t
    return total


@numba.njit(cache=True, parallel=True, fastmath=FAST)
def _update_xr(x, r, p, q, alpha):
    """``x += alpha p``, ``r -= alpha q`` (flat arrays); returns ``r . r``."""
    n = x.shape[0]
    total = 0.0
    for t in prange(CHUNKS):
        s = 0.0
        a0, a1 = chunk(n, t, CHUNKS)
        for a in range(a0, a1):
            x[a] += alpha * p[a]
            v = r[a] - alpha * q[a]
            r[a] = v
            s += v * v
        total += s
    return total


@numba.njit(cache=True, inline="always", fastmath=FAST)
def _partial_dot(a, b, i0, i1):
    s = 0.0
    for i in range(i0, i1):
        s += a[i] * b[i]
    return s


@numba.njit(cache=True, parallel=True, fastmath=FAST)
def _dot(a, b):
    """``a . b`` (flat arrays)."""
    total = 0.0
    for t in prange(CHUNKS):
        i0, i1 = chunk(a.shape[0], t, CHUNKS)
        total += _partial_dot(a, b, i0, i1)
    return total


@numba.njit(cache=True, parallel=True, fastmath=FAST)
def _update_p(p, z, beta):
    """``p = z + beta p`` (flat arrays)."""
    n = p.shape[0]
    for t in prange(CHUNKS):
        a0, a1 = chunk(n, t, CHUNKS)
        for a in range(a0, a1):
            p[a] = z[a] + beta * p[a]


@numba.njit(cache=True)
def pcg(r, x, p, q, wx, wy, levels, sweeps, tol, maxiter, threads, warm, from_start):
    """Preconditioned CG for ``L x = b``, all vectors in red-black layout; returns (iterations,
    final ``|b - L x| / |b|``).

    ``r`` holds ``b`` on entry and the residual on return; ``p, q`` are work arrays (any content).
    ``wx, wy`` (float64 pair weights) define ``L``; ``levels`` (:attr:`.levels.Levels.arrays`)
    only precondition. With ``warm`` the iteration starts
    from the ``x`` given, else from 0. The iteration stops at ``|b - L x| <= tol |b|``, or with
    ``from_start`` at ``|b - L x| <= tol min(|b|, |b - L x0|)`` (a warm start still gains ``tol``),
    and not below round-off (``1e-12 |b|``).
    """
    _, _, _, z_all, _, offsets, dims, _, _ = levels
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
    q[:, 0, :] = 0.0  # rows apply_dot does not write
    q[:, h + 1 :, :] = 0.0
    rr = bb
    if warm:
        apply_dot(x, wx, wy, h, q)
        for a in range(n):
            rf[a] -= qf[a]
        rr = _dot(rf, rf)
    else:
        xf[:] = 0.0
    goal = tol * tol * (min(rr, bb) if from_start else bb)
    goal = max(goal, _FLOOR * bb)
    if rr <= goal:
        return 0, np.sqrt(rr / bb)
    zf = z_all[offsets[0] : offsets[1]]  # where the V-cycle leaves its output
    vcycle(r, levels, sweeps, threads)
    rz = _dot(rf, zf)
    copy_flat(zf, pf)
    it = 0
    while it < maxiter:
        it += 1
        pq = apply_dot(p, wx, wy, h, q)
        if not pq > 0.0:
            break
        rr = _update_xr(xf, rf, pf, qf, rz / pq)
        if rr <= goal:
            break
        vcycle(r, levels, sweeps, threads)
        rz_new = _dot(rf, zf)
        if not rz_new > 0.0:
            break
        _update_p(pf, zf, rz_new / rz)
        rz = rz_new
    return it, np.sqrt(rr / bb)
