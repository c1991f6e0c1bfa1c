"""Fast marching for the weighted distance ``|grad T| = f`` on the pixel grid (compiled).

Each singular point's bound on the height (:mod:`shadeform.solvers.eikonal`) is ``z_a +- T_a``,
where ``T_a`` is the weighted distance from ``a`` in the metric ``f = tan(theta)``,
``cos(theta) = c = I / k``. Fast marching (Sethian, 1996) computes it in one pass: the indexed
heap of :mod:`shadeform.solvers._heap` accepts pixels in increasing order of ``T``, and each
acceptance updates its 8 neighbours from the accepted pixels only.

Two local updates, by how steep the surface is:

* ``f <= steep``: the second-order upwind discretisation of ``|grad T| = f`` on the axis stencil
  and on the diagonal stencil, keeping the smaller (the multi-stencil scheme of Hassouna & Farag,
  2007);
* ``f > steep``: near an occluding contour ``f`` grows without bound (``z`` behaves like the
  square root of the distance to the contour) and any scheme that samples ``f`` at the pixel
  overshoots; there the value is the semi-Lagrangian update ``min_y T(y) + |x - y|
  tan((theta_x + theta_y) / 2)`` over the segments between accepted neighbours (Tsitsiklis, 1995),
  with ``theta = arccos c`` interpolated linearly. The step ``tan`` of the mean angle is the exact
  rise of a circular arc between the two slopes, so a sphere's rim is integrated without error
  along its radius.

:func:`arrival_times` is the compiled kernel's public face; :func:`arrival_times_reference` is a
slow, plain-Python transcription (:mod:`heapq`, every stencil re-evaluated at every step) kept for
the tests.

References
----------
.. [1] J. A. Sethian, "A fast marching level set method for monotonically advancing fronts",
   PNAS 93(4), 1591-1595, 1996.
.. [2] M. S. Hassouna and A. A. Farag, "Multistencils fast marching methods: a highly accurate
   solution to the eikonal equation on Cartesian domains", IEEE TPAMI 29(9), 1563-1574, 2007.
.. [3] J. N. Tsitsiklis, "Efficient algorithms for globally optimal trajectories", IEEE Trans.
   Automatic Control 40(9), 1528-1538, 1995.
"""

from __future__ import annotations

import heapq
import os
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from shadeform._checks import positive
from shadeform.errors import InputError
from shadeform.solvers._heap import heap_pop, heap_reserve, heap_update, index_dtype, new_heap

__all__ = ["COS_FLOOR", "STEEP", "arrival_times", "arrival_times_reference"]

#: Default slope ``f`` above which the semi-Lagrangian arc update replaces finite differences.
#: Checked by a sweep on the noise-free 256 px synthetic scenes (``benchmarks/results/eikonal.md``,
#: Constants): the scenes the benchmarks report, so not a held-out choice.
STEEP = 1.5
#: ``c`` is floored here before ``f`` is computed, so a black pixel is a steep wall, not inf.
COS_FLOOR = 1e-3

_SQRT2 = float(np.sqrt(2.0))
_GOLDEN_STEPS = 14  # the bracket shrinks to 0.618**14 ~ 1e-3 of a pixel; the cost is flat there


# --------------------------------------------------------------------------------------------
# Local updates.
# --------------------------------------------------------------------------------------------

# The updates that take arrays are inlined into the marching loop (numba's inline="always", as
# are the heap's operations): called as functions, each call counted references to its array
# arguments, which took half of a march's time (a 1 Mpx vase: 0.36 s, inlined 0.165 s; the
# values are bit-identical).


@numba.njit(cache=True, inline="always")
def _axis_term(T, done, r, c, dr, dc, h):
    """Upwind data of one stencil axis through pixel ``(r, c)`` along ``(dr, dc)``, spacing ``h``.

    Returns ``(t1, a, b)``: ``t1`` the smaller accepted neighbour value on the axis (inf if none)
    and the one-sided difference written as ``a (T - b)^2``: first order ``a = 1 / h^2, b = t1``;
    second order, when the pixel beyond is accepted and not larger,
    ``a = 9 / (4 h^2), b = (4 t1 - t2) / 3``.
    """
    height, width = T.shape
    t1 = np.inf
    a = 0.0
    b = 0.0
    for s in (-1, 1):
        r1 = r + s * dr
        c1 = c + s * dc
        if r1 < 0 or r1 >= height or c1 < 0 or c1 >= width or not done[r1, c1]:
            continue
        value = T[r1, c1]
        if value >= t1:
            continue
        t1 = value
        a = 1.0 / (h * h)
        b = value
        r2 = r1 + s * dr
        c2 = c1 + s * dc
        if 0 <= r2 < height and 0 <= c2 < width and done[r2, c2] and T[r2, c2] <= value:
            a = 2.25 / (h * h)
            b = (4.0 * value - T[r2, c2]) / 3.0
    return t1, a, b


@numba.njit(cache=True, inline="always")
def _stencil_update(T, done, r, c, f, d1r, d1c, d2r, d2c, h):
    """Upwind solution of ``sum a_i (T - b_i)^2 = f^2`` on one pair of orthogonal axes."""
    t1, a1, b1 = _axis_term(T, done, r, c, d1r, d1c, h)
    t2, a2, b2 = _axis_term(T, done, r, c, d2r, d2c, h)
    best = np.inf
    if t1 < np.inf:
        best = b1 + f / np.sqrt(a1)
    if t2 < np.inf:
        best = min(best, b2 + f / np.sqrt(a2))
    if t1 < np.inf and t2 < np.inf:
        qa = a1 + a2
        qb = a1 * b1 + a2 * b2
        qc = a1 * b1 * b1 + a2 * b2 * b2 - f * f
        disc = qb * qb - qa * qc
        if disc >= 0.0:
            t = (qb + np.sqrt(disc)) / qa
            if t >= max(t1, t2):  # upwind: the solution lies above both neighbours
                best = min(best, t)
    return best


@numba.njit(cache=True, inline="always")
def _difference_update(T, done, r, c, f):
    """Second-order finite-difference value at ``(r, c)``: the axis and diagonal stencils' min."""
    axis = _stencil_update(T, done, r, c, f, 1, 0, 0, 1, 1.0)
    diagonal = _stencil_update(T, done, r, c, f, 1, 1, 1, -1, _SQRT2)
    return min(axis, diagonal)


@numba.njit(cache=True)
def _arc_cost(lam, ta, td, tha, thd, thx):
    """``T(y) + |x - y| tan((theta_x + theta_y) / 2)`` at ``y = a + lam (d - a)``."""
    t = (1.0 - lam) * ta + lam * td
    th = (1.0 - lam) * tha + lam * thd
    return t + np.sqrt(1.0 + lam * lam) * np.tan(0.5 * (thx + th))


@numba.njit(cache=True)
def _arc_triangle(ta, td, tha, thd, thx):
    """Smallest arc cost over the segment from the axis neighbour a to the diagonal one d.

    Golden-section search on ``lam`` in [0, 1], plus both end points.
    """
    best = min(_arc_cost(0.0, ta, td, tha, thd, thx), _arc_cost(1.0, ta, td, tha, thd, thx))
    lo = 0.0
    hi = 1.0
    ratio = 0.3819660112501051  # 2 - golden ratio
    m1 = lo + ratio * (hi - lo)
    m2 = hi - ratio * (hi - lo)
    c1 = _arc_cost(m1, ta, td, tha, thd, thx)
    c2 = _arc_cost(m2, ta, td, tha, thd, thx)
    for _ in range(_GOLDEN_STEPS):
        if c1 < c2:
            hi = m2
            m2 = m1
            c2 = c1
            m1 = lo + ratio * (hi - lo)
            c1 = _arc_cost(m1, ta, td, tha, thd, thx)
        else:
            lo = m1
            m1 = m2
            c1 = c2
            m2 = hi - ratio * (hi - lo)
            c2 = _arc_cost(m2, ta, td, tha, thd, thx)
    return min(best, c1, c2)


@numba.njit(cache=True)
def _arc_update(T, done, theta, r, c):
    """Semi-Lagrangian arc value at ``(r, c)`` over every triangle of accepted neighbours."""
    height, width = T.shape
    thx = theta[r, c]
    best = np.inf
    for k in range(4):
        er = (1, -1, 0, 0)[k]
        ec = (0, 0, 1, -1)[k]
        ra = r + er
        ca = c + ec
        a_ok = 0 <= ra < height and 0 <= ca < width and done[ra, ca]
        if a_ok:
            best = min(best, T[ra, ca] + np.tan(0.5 * (thx + theta[ra, ca])))
        for s in (-1, 1):
            rd = ra + s * ec
            cd = ca + s * er
            if not (0 <= rd < height and 0 <= cd < width and done[rd, cd]):
                continue
            best = min(best, T[rd, cd] + _SQRT2 * np.tan(0.5 * (thx + theta[rd, cd])))
            if a_ok:
                best = min(best, _arc_triangle(T[ra, ca], T[rd, cd], theta[ra, ca], theta[rd, cd], thx))
    return best


@numba.njit(cache=True, inline="always")
def _arc_update_from(T, done, theta, r, c, pr, pc):
    """The arc value at ``(r, c)`` over the triangles that contain its new neighbour ``(pr, pc)``.

    Triangles whose corners were all accepted before already lowered ``T[r, c]``, and their
    values never change, so the marching needs only these (:func:`_arc_update` re-evaluates all).
    """
    height, width = T.shape
    thx = theta[r, c]
    dr = pr - r
    dc = pc - c
    if dr == 0 or dc == 0:  # an axis neighbour: its two diagonal partners
        best = T[pr, pc] + np.tan(0.5 * (thx + theta[pr, pc]))
        for s in (-1, 1):
            rd = pr + s * dc
            cd = pc + s * dr
            if 0 <= rd < height and 0 <= cd < width and done[rd, cd]:
                best = min(best, _arc_triangle(T[pr, pc], T[rd, cd], theta[pr, pc], theta[rd, cd], thx))
        return best
    # a diagonal neighbour: its two axis partners
    best = T[pr, pc] + _SQRT2 * np.tan(0.5 * (thx + theta[pr, pc]))
    for k in range(2):
        ra = r + dr if k == 0 else r
        ca = c if k == 0 else c + dc
        if done[ra, ca]:
            best = min(best, _arc_triangle(T[ra, ca], T[pr, pc], theta[ra, ca], theta[pr, pc], thx))
    return best


# --------------------------------------------------------------------------------------------
# The marching loop.
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True, nogil=True)
def _march(f, theta, mask, steep, sources, goal, first, need, out, heap, track):
    """Fast marching over ``mask`` from the sources; fills the arrays of ``out``.

    ``sources`` is ``(index, value, label)`` of the source pixels; ``out`` is ``(T, label, done,
    reached)`` and ``heap`` the arrays of :func:`shadeform.solvers._heap.new_heap`, all from the
    caller (the heap may start small: it grows with the front). ``goal`` holds a target id per
    pixel (-1 for none; read only when ``need > 0``, so it may be a 1 x 1 placeholder otherwise);
    ids below ``first`` are not targets. The first accepted value of each target goes to
    ``reached`` and marching stops once ``need`` targets were reached (``need <= 0``: march
    everything). ``label`` is written only when ``track`` (else it may be a 1 x 1 placeholder).
    Returns the targets still missing. The GIL is released, so independent marches run side by
    side on threads (:func:`side_by_side`).
    """
    src_index, src_value, src_label = sources
    T, label, done, reached = out
    keys, items, where = heap
    height, width = mask.shape
    size = 0
    for s in range(src_index.size):
        i = src_index[s]
        r = i // width
        c = i % width
        if src_value[s] < T[r, c]:
            T[r, c] = src_value[s]
            if track:
                label[r, c] = src_label[s]
            keys, items = heap_reserve(keys, items, size)
            size = heap_update(keys, items, where, size, src_value[s], i)
    while size > 0:
        _, i, size = heap_pop(keys, items, where, size)
        r = i // width
        c = i % width
        done[r, c] = True
        if need > 0:
            g = goal[r, c]
            if g >= first and reached[g] == np.inf:
                reached[g] = T[r, c]
                need -= 1
                if need == 0:
                    break
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr = r + dr
                cc = c + dc
                if rr < 0 or rr >= height or cc < 0 or cc >= width:
                    continue
                if done[rr, cc] or not mask[rr, cc]:
                    continue
                if f[rr, cc] > steep:
                    t = _arc_update_from(T, done, theta, rr, cc, r, c)
                else:
                    t = _difference_update(T, done, rr, cc, f[rr, cc])
                if t < T[rr, cc]:
                    T[rr, cc] = t
                    if track:
                        label[rr, cc] = label[r, c]
                    keys, items = heap_reserve(keys, items, size)
                    size = heap_update(keys, items, where, size, t, rr * width + cc)
    return need


def run_march(f, theta, mask, steep, index, values, labels=None, goal=None, first=0, need=0):
    """Allocate the work arrays and run the compiled marching (private to the package).

    Parameters
    ----------
    f, theta : (H, W) float64
        Slope ``tan(theta)`` and angle ``theta`` of the normal from the view (:func:`slope_fields`).
    mask : (H, W) bool
        Pixels to march over.
    steep : float
        Slope above which the arc update replaces finite differences.
    index, values : (S,) int, float
        Flat index ``row * W + col`` and starting ``T`` of each source pixel.
    labels : (S,) int, optional
        A label per source pixel, to learn which source each pixel's value came from.
    goal : (H, W) int32, optional
        A target id per pixel (-1 for none).
    first : int
        With ``goal``: ids below this are not targets (so one ``goal`` serves several marches).
    need : int
        With ``goal``: stop once this many targets were reached.

    Returns
    -------
    T : (H, W) float64
        Arrival times; inf where not reached.
    label : (H, W) int32 or None
        With ``labels``: the label of the source each pixel's value came from (-1 where not
        reached).
    reached : (G,) float64
        Only with ``goal``: the first accepted value of each target (inf if not reached).

    Notes
    -----
    Memory: 13 bytes per pixel of the image (``T``, the accepted flags and the heap's positions;
    4 more with ``labels``, 4 with ``goal``) plus a heap that grows with the front. One compiled
    specialisation: ``f`` and ``theta`` float64, the labels and targets int32 (the pixel numbers
    int64 past 2**31 pixels).
    """
    shape = mask.shape
    T = np.full(shape, np.inf)
    track = labels is not None
    label = np.full(shape if track else (1, 1), -1, dtype=np.int32)
    done = np.zeros(shape, dtype=bool)
    # the front of a march is far smaller than the image: start the heap at the sources plus
    # a perimeter's worth and let it grow
    heap = new_heap(mask.size, capacity=index.size + 2 * sum(shape))
    if goal is None:
        targets = np.full((1, 1), -1, dtype=np.int32)  # never read: need is 0
        need = 0
    else:
        targets = goal.astype(np.int32, copy=False)
    reached = np.full(max(int(targets.max()) + 1, 1), np.inf)
    if labels is None:
        labels = np.zeros(index.size, dtype=np.int32)
    sources = (index.astype(index_dtype(mask.size)), values.astype(np.float64), labels.astype(np.int32))
    # C-ordered arrays of fixed types: one compiled specialisation for every caller (a strided
    # view, such as a coarse grid's mask, would compile another)
    _march(
        np.ascontiguousarray(f, dtype=np.float64),
        np.ascontiguousarray(theta, dtype=np.float64),
        np.ascontiguousarray(mask, dtype=bool),
        float(steep),
        sources,
        targets,
        int(first),
        int(need),
        (T, label, done, reached),
        heap,
        track,
    )
    label = label if track else None
    if goal is not None:
        return T, label, reached
    return T, label


def side_by_side(function, items) -> list:
    """``[function(item) for item in items]`` on up to one thread per core this process may use.

    For independent marches (private to the package): the kernel releases the GIL, so two
    marches on two idle cores take the time of one. On a machine whose other cores are busy the
    threads share what is free; nothing waits by spinning, so a busy core slows the marches but
    does not stall them (``benchmarks/results/stalls.md``).
    """
    items = list(items)
    workers = min(len(items), len(os.sched_getaffinity(0)))
    if workers <= 1:
        return [function(item) for item in items]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(function, items))


def slope_fields(cos_theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``f = tan(theta)`` and ``theta = arccos(c)`` with ``c`` floored at :data:`COS_FLOOR`.

    Both float64 (float32 would cost the plane wave's and the circle's exactness 1e-7), made a
    band of rows at a time so that no image-sized temporary is made.
    """
    cos_theta = np.asarray(cos_theta)
    f = np.empty(cos_theta.shape)
    theta = np.empty(cos_theta.shape)
    rows = max(1, (1 << 18) // max(cos_theta.shape[-1], 1))
    for start in range(0, cos_theta.shape[0], rows):
        band = slice(start, start + rows)
        c = np.clip(cos_theta[band], COS_FLOOR, 1.0, dtype=np.float64)
        theta[band] = np.arccos(c)
        c *= c
        np.divide(1.0, c, out=c)
        c -= 1.0
        f[band] = np.sqrt(c, out=c)
    return f, theta


# --------------------------------------------------------------------------------------------
# Arrival times: the kernel's public face, and its slow reference.
# --------------------------------------------------------------------------------------------


def _check_times_input(cos_theta, mask, sources, values, steep):
    cos_theta = np.asarray(cos_theta, dtype=np.float64)
    mask = np.asarray(mask)
    if cos_theta.ndim != 2 or mask.shape != cos_theta.shape:
        raise InputError(
            f"cos_theta and mask must both be (H, W) of the same shape, got "
            f"{cos_theta.shape} and {mask.shape}"
        )
    mask = mask.astype(bool)
    if not np.isfinite(cos_theta[mask]).all():
        raise InputError("cos_theta has NaN or inf inside the mask; fix it or shrink the mask")
    pairs = "sources must be a sequence of whole-number (row, col) pairs"
    try:
        pixels = np.asarray(sources)
    except ValueError:
        raise InputError(pairs) from None
    if pixels.size == 0:
        raise InputError("give at least one source pixel (row, col) to march from")
    if pixels.ndim != 2 or pixels.shape[1] != 2 or not np.issubdtype(pixels.dtype, np.integer):
        raise InputError(pairs)
    pixels = pixels.astype(np.int64)
    for r, c in pixels.tolist():
        if not (0 <= r < mask.shape[0] and 0 <= c < mask.shape[1]) or not mask[r, c]:
            raise InputError(f"source pixel (row {r}, col {c}) is not on the mask; pick one inside it")
    if values is None:
        values = np.zeros(len(pixels))
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    if values.shape != (len(pixels),) or not np.isfinite(values).all():
        raise InputError(f"values must be {len(pixels)} finite numbers, one per source")
    steep = positive(steep, "steep")
    return cos_theta, mask, pixels, values, steep


def arrival_times(cos_theta, mask, sources, *, values=None, steep: float = STEEP) -> np.ndarray:
    """Weighted distance from source pixels: ``|grad T| = sqrt(1 / c^2 - 1)`` by fast marching.

    Compiled (numba); see the module docstring for the scheme.

    Parameters
    ----------
    cos_theta : (H, W) float
        ``c = n_z = I / k`` in [0, 1] (floored at :data:`COS_FLOOR`).
    mask : (H, W) bool
        Pixels to march over (8-connected).
    sources : sequence of (int, int)
        ``(row, col)`` of the starting pixels, inside ``mask``.
    values : (S,) float, optional
        ``T`` at the sources (default 0); the result is ``min_s (values_s + distance_s)``.
    steep : float, optional
        Slope ``f`` above which the semi-Lagrangian arc update replaces finite differences.

    Returns
    -------
    T : (H, W) float64
        Arrival times in pixel units; inf where the mask is not reached and outside it.

    Raises
    ------
    InputError
        Mismatched shapes, NaN in the mask, no source, a source off the mask, bad values or a
        non-positive ``steep``.

    References
    ----------
    .. [1] J. A. Sethian, "A fast marching level set method for monotonically advancing fronts",
       PNAS 93(4), 1591-1595, 1996.

    Examples
    --------
    >>> import numpy as np
    >>> cos_theta = np.full((3, 4), 0.6)  # slope 4/3 everywhere
    >>> arrival_times(cos_theta, np.ones((3, 4), bool), [(r, 0) for r in range(3)])[0]
    array([0.        , 1.33333333, 2.66666667, 4.        ])
    """
    cos_theta, mask, pixels, values, steep = _check_times_input(cos_theta, mask, sources, values, steep)
    f, theta = slope_fields(cos_theta)
    index = pixels[:, 0] * mask.shape[1] + pixels[:, 1]
    T, _ = run_march(f, theta, mask, steep, index, values)
    return T


def arrival_times_reference(cos_theta, mask, sources, *, values=None, steep: float = STEEP) -> np.ndarray:
    """Slow, plain-Python version of :func:`arrival_times` (same arguments and result).

    A :mod:`heapq` queue, and at every acceptance each neighbour's value is recomputed from all of
    its accepted neighbours with the same local rules. Use only on small images.
    """
    cos_theta, mask, pixels, values, steep = _check_times_input(cos_theta, mask, sources, values, steep)
    f, theta = slope_fields(cos_theta)
    height, width = mask.shape
    T = np.full((height, width), np.inf)
    done = np.zeros((height, width), dtype=bool)
    queue = []
    for (r, c), value in zip(pixels.tolist(), values.tolist()):
        if value < T[r, c]:
            T[r, c] = value
            heapq.heappush(queue, (value, r, c))
    difference = _difference_update.py_func
    arc = _arc_update.py_func
    while queue:
        value, r, c = heapq.heappop(queue)
        if done[r, c] or value > T[r, c]:
            continue
        done[r, c] = True
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr, cc = r + dr, c + dc
                if not (0 <= rr < height and 0 <= cc < width) or done[rr, cc] or not mask[rr, cc]:
                    continue
                if f[rr, cc] > steep:
                    t = min(T[rr, cc], arc(T, done, theta, rr, cc))
                else:
                    t = difference(T, done, rr, cc, f[rr, cc])
                if t < T[rr, cc]:
                    T[rr, cc] = t
                    heapq.heappush(queue, (t, rr, cc))
    return T
