"""Eikonal shape from shading for a light at +z: fast marching from the singular points.

With the light behind the camera (``L = (0, 0, 1)``) the image model ``I = k (N . L)`` reads
``c = I / k = n_z = 1 / sqrt(1 + |grad z|^2)``, so the height obeys the eikonal equation

    |grad z| = f,   f = sqrt(1 / c^2 - 1).

The equation fixes how steep the surface is, not which way it goes. Its solutions are built from
the **singular points**, where ``c = 1`` and the surface is level: local maxima, minima and saddles
of ``z`` (Oliensis, 1991). If ``T_a`` is the weighted distance from the singular point ``a``
(``|grad T_a| = f``, ``T_a = 0`` at ``a``; the geodesic distance in the metric ``f``), then for
every pixel ``x`` and every singular point ``a`` of height ``z_a``

    z_a - T_a(x) <= z(x) <= z_a + T_a(x),

with equality on the left when ``x`` lies on a path of steepest descent from ``a`` and on the
right when it lies on a path of steepest ascent from ``a``. Hence (Dupuis & Oliensis, 1994;
Kimmel & Sethian, 2001, march from the minima)

* ``L(x) = max_a (z_a - T_a(x))`` is exact wherever the steepest ascent from ``x`` ends in a
  singular point (every pixel of a convex object: ascent ends at its top);
* ``U(x) = min_a (z_a + T_a(x))`` is exact wherever the steepest descent from ``x`` ends in one
  (every pixel of a bowl: descent ends at its bottom).

The solver

1. finds the singular regions: the bright caps around maxima of ``c`` that reach ``1 - tol``
   and rise at least ``tol`` above the pass to any brighter one (h-maxima), so noise and ripples
   on a level plateau do not split it. Each becomes a source whose pixels within ``tol / 10`` of
   its top start the marching (``T = 0``): a point, a ridge's crest or a plateau. Its **kind**
   comes from the user's concave regions (``docs/conventions.md``): a maximum by default, a
   minimum inside a region concave along both axes (a bowl's bottom), a saddle inside a region
   concave along one axis only (a vase's neck: convex across, concave along it). User sources
   add to or replace the detected ones; every connected part of the mask without a source gets
   its brightest pixel;
2. fixes the sources' heights. The main source (the first user source, else the brightest) is at
   0; then, nearest first, each source ``b`` is bounded by the placed ones, ``|z_b - z_a| <=
   D_ab`` (``D_ab`` is ``T_a`` at ``b``). A maximum is put at the lowest upper bound
   ``min_a (z_a + D_ab)``, a minimum at the highest lower bound ``max_a (z_a - D_ab)``: the bound
   is reached when a path of steepest ascent (descent) joins ``b`` to a placed source, as it does
   between singular points of different kinds, so those go first (a vase's lip is placed from
   its neck, not from its belly). A saddle goes below the maximum or above the minimum that
   links it. Unmarked, all are maxima and each rises as high as the placed ones allow: bumps on
   a plate come out as bumps (and an unmarked dent as one more);
3. takes ``U`` where the source nearest in the metric ``f`` is a minimum and ``L`` everywhere
   else, with ``z = 0`` at each part's main source;
4. returns the normals on each pixel's shading cone (``n_z = c`` exactly) with the tilt of the
   depth's gradient.

**Fast marching** (Sethian, 1996) computes each ``T``: a binary heap accepts pixels in increasing
order of ``T``. Where the surface is not steep (``f <= steep``) a pixel's value solves the
second-order upwind discretisation of ``|grad T| = f`` on the axis stencil and on the diagonal
stencil, keeping the smaller (the multi-stencil scheme of Hassouna & Farag, 2007). Near an
occluding contour ``f`` grows without bound (``z`` behaves like the square root of the distance
to the contour) and any scheme that samples ``f`` at the pixel overshoots; there the value is the
semi-Lagrangian update ``min_y T(y) + |x - y| tan((theta_x + theta_y) / 2)`` over the segments
between accepted neighbours (Tsitsiklis, 1995), with ``theta = arccos c`` interpolated linearly.
The step ``tan`` of the mean angle is the exact rise of a circular arc between the two slopes, so
a sphere's rim is integrated without error along its radius.

Limits. Uniform albedo, the light at +z, no cast shadows. What the singular points and the
user's marks do not decide, no marching can: a surface whose slopes run out through the image
border on both sides (the synthetic saddle, whose image is also that of a dome) needs heights on
that border, and a neck left unmarked is read as a hill top. ``tol`` must exceed what noise does
to the brightest pixels: filter noisy images and raise it (see :data:`TOL`).

``arrival_times`` is the compiled kernel; ``arrival_times_reference`` is a slow, plain-Python
transcription (heapq, every stencil re-evaluated at every step) kept for the tests.

References
----------
.. [1] J. Oliensis, "Uniqueness in shape from shading", IJCV 6(2), 75-104, 1991.
.. [2] P. Dupuis and J. Oliensis, "An optimal control formulation and related numerical methods
   for a problem in shape reconstruction", Ann. Appl. Probab. 4(2), 287-346, 1994.
.. [3] R. Kimmel and J. A. Sethian, "Optimal algorithm for shape from shading and path
   planning", J. Math. Imaging Vis. 14(3), 237-244, 2001.
.. [4] J. A. Sethian, "A fast marching level set method for monotonically advancing fronts",
   PNAS 93(4), 1591-1595, 1996.
.. [5] M. S. Hassouna and A. A. Farag, "Multistencils fast marching methods: a highly accurate
   solution to the eikonal equation on Cartesian domains", IEEE TPAMI 29(9), 1563-1574, 2007.
.. [6] J. N. Tsitsiklis, "Efficient algorithms for globally optimal trajectories", IEEE Trans.
   Automatic Control 40(9), 1528-1538, 1995.
"""

from __future__ import annotations

import heapq
import numbers
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from scipy import ndimage as ndi
from skimage.morphology import local_maxima, reconstruction

from shadeform._checks import StageTimer
from shadeform.errors import InputError

__all__ = [
    "KINDS",
    "SingularPoint",
    "EikonalResult",
    "eikonal_depth",
    "arrival_times",
    "arrival_times_reference",
    "cone_normals",
    "cone_normals_reference",
]

#: Kinds of singular points (sources).
KINDS = ("max", "min", "saddle")

#: Default tolerance on ``c = I / k``: a singular region's top reaches ``1 - tol`` and rises
#: ``tol`` above the pass to any brighter one. Noisy images need more (about 2e-2 at 1% noise
#: after a Gaussian of sigma 2).
TOL = 1e-3
#: Default slope above which the semi-Lagrangian arc update replaces finite differences.
STEEP = 1.5
#: ``c`` is floored here before ``f`` is computed, so a black pixel is a steep wall, not inf.
COS_FLOOR = 1e-3
#: The sources of a singular region are its pixels within this fraction of ``tol`` of its top.
SOURCE_FRACTION = 0.1
#: At most this many detected singular regions are kept (the largest); more mean noise.
MAX_DETECTED = 32

_EIGHT = np.ones((3, 3), dtype=bool)
_SQRT2 = float(np.sqrt(2.0))
_GOLDEN_STEPS = 14  # the bracket shrinks to 0.618**14 ~ 1e-3 of a pixel; the cost is flat there


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class SingularPoint:
    """One source of the fast marching: a singular point (or region) of the surface.

    Attributes
    ----------
    row, col : int
        Its representative pixel: of its source pixels, the one nearest their centroid.
    kind : {"max", "min", "saddle"}
        Local maximum, minimum or saddle of the height.
    height : float
        The height ``z`` it was given, in the result's frame (pixel units).
    pixels : (K, 2) int64
        ``(row, col)`` of the pixels where the marching starts (``T = 0``), read-only.
    origin : {"detected", "user", "brightest"}
        Found as a singular region, given by the user, or the brightest pixel of a part of the
        mask that had no other source.
    """

    row: int
    col: int
    kind: str
    height: float
    pixels: np.ndarray
    origin: str


@dataclass(frozen=True, eq=False)
class EikonalResult:
    """Shape from the eikonal solver.

    Attributes
    ----------
    depth : (H, W) float64
        Height z in pixel units (larger = nearer the viewer), NaN outside the mask; ``z = 0`` at
        the main source of each connected part of the mask.
    normals : (H, W, 3) float64
        Unit normals on the shading cone (``n_z = I / k``) tilted along the depth's steepest
        descent, NaN outside the mask.
    sources : tuple of SingularPoint
        The sources used; the first is the main one.
    k : float
        ``k * albedo``: the brightness of a pixel facing the light.
    info : dict
        ``parts`` (8-connected parts of the mask), ``detected`` (singular regions found; at most
        :data:`MAX_DETECTED` are used), ``tol``, ``steep``, ``smooth`` and ``timings`` (seconds
        per stage).
    """

    depth: np.ndarray
    normals: np.ndarray
    sources: tuple[SingularPoint, ...]
    k: float
    info: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------------------------
# The compiled kernel: binary heap, local updates, marching loop.
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _heap_update(keys, items, where, size, key, item):
    """Insert ``item`` with ``key``, or lower its key if it is queued already.

    A binary min-heap in ``keys``/``items`` of length ``size``; ``where[item]`` is the item's
    position in it, -1 when it is not queued. Returns the new size.
    """
    i = where[item]
    if i < 0:
        i = size
        size += 1
    while i > 0:
        parent = (i - 1) // 2
        if keys[parent] <= key:
            break
        keys[i] = keys[parent]
        items[i] = items[parent]
        where[items[i]] = i
        i = parent
    keys[i] = key
    items[i] = item
    where[item] = i
    return size


@numba.njit(cache=True)
def _heap_pop(keys, items, where, size):
    """Remove the smallest key; return ``(key, item, new size)``."""
    key = keys[0]
    item = items[0]
    where[item] = -1
    size -= 1
    if size == 0:
        return key, item, size
    last_key = keys[size]
    last_item = items[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and keys[child + 1] < keys[child]:
            child += 1
        if keys[child] >= last_key:
            break
        keys[i] = keys[child]
        items[i] = items[child]
        where[items[i]] = i
        i = child
    keys[i] = last_key
    items[i] = last_item
    where[last_item] = i
    return key, item, size


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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
                best = min(best, _arc_triangle(T[ra, ca], T[rd, cd], theta[ra, ca],
                                               theta[rd, cd], thx))
    return best


@numba.njit(cache=True)
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
                best = min(best, _arc_triangle(T[pr, pc], T[rd, cd], theta[pr, pc],
                                               theta[rd, cd], thx))
        return best
    # a diagonal neighbour: its two axis partners
    best = T[pr, pc] + _SQRT2 * np.tan(0.5 * (thx + theta[pr, pc]))
    for k in range(2):
        ra = r + dr if k == 0 else r
        ca = c if k == 0 else c + dc
        if done[ra, ca]:
            best = min(best, _arc_triangle(T[ra, ca], T[pr, pc], theta[ra, ca],
                                           theta[pr, pc], thx))
    return best


@numba.njit(cache=True)
def _march(f, theta, mask, steep, src_index, src_value, src_label, goal, need,
           T, label, done, keys, items, where, reached):
    """Fast marching over ``mask`` from the sources; fills ``T``, ``label``, ``done``.

    Work arrays come from the caller. ``goal`` holds a target id per pixel (-1 for none); the
    first accepted value of each target goes to ``reached`` and marching stops once ``need``
    targets were reached (``need <= 0``: march everything). Returns the targets still missing.
    """
    height, width = mask.shape
    size = 0
    for s in range(src_index.size):
        i = src_index[s]
        r = i // width
        c = i % width
        if src_value[s] < T[r, c]:
            T[r, c] = src_value[s]
            label[r, c] = src_label[s]
            size = _heap_update(keys, items, where, size, src_value[s], i)
    while size > 0:
        key, i, size = _heap_pop(keys, items, where, size)
        r = i // width
        c = i % width
        done[r, c] = True
        g = goal[r, c]
        if need > 0 and g >= 0 and reached[g] == np.inf:
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
                    label[rr, cc] = label[r, c]
                    size = _heap_update(keys, items, where, size, t, rr * width + cc)
    return need


# --------------------------------------------------------------------------------------------
# Arrival times: the kernel's public face, and its slow reference.
# --------------------------------------------------------------------------------------------


def _slope_fields(cos_theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``f = tan(theta)`` and ``theta = arccos(c)`` with ``c`` floored at :data:`COS_FLOOR`."""
    c = np.clip(cos_theta, COS_FLOOR, 1.0)
    return np.sqrt(1.0 / (c * c) - 1.0), np.arccos(c)


def _check_times_input(cos_theta, mask, sources, values, steep):
    cos_theta = np.asarray(cos_theta, dtype=np.float64)
    mask = np.asarray(mask)
    if cos_theta.ndim != 2 or mask.shape != cos_theta.shape:
        raise InputError(f"cos_theta and mask must both be (H, W) of the same shape, got "
                         f"{cos_theta.shape} and {mask.shape}")
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
    steep = _positive(steep, "steep")
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
    values : (K,) float, optional
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
    """
    cos_theta, mask, pixels, values, steep = _check_times_input(cos_theta, mask, sources, values, steep)
    f, theta = _slope_fields(cos_theta)
    index = pixels[:, 0] * mask.shape[1] + pixels[:, 1]
    T, _ = _run_march(f, theta, mask, steep, index, values, np.zeros(len(index), np.int64))
    return T


def arrival_times_reference(cos_theta, mask, sources, *, values=None,
                            steep: float = STEEP) -> np.ndarray:
    """Slow, plain-Python version of :func:`arrival_times` (same arguments and result).

    A :mod:`heapq` queue, and at every acceptance each neighbour's value is recomputed from all of
    its accepted neighbours with the same local rules. Use only on small images.
    """
    cos_theta, mask, pixels, values, steep = _check_times_input(cos_theta, mask, sources, values, steep)
    f, theta = _slope_fields(cos_theta)
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


def _run_march(f, theta, mask, steep, index, values, labels, goal=None, need=0):
    """Allocate the work arrays and run :func:`_march`.

    Returns ``(T, label)``, or ``(T, label, reached)`` when a ``goal`` image of target ids is
    given: ``reached[j]`` is the first accepted value of target ``j`` (inf if not reached); the
    marching stops once ``need`` targets were reached.
    """
    shape = mask.shape
    T = np.full(shape, np.inf)
    label = np.full(shape, -1, dtype=np.int64)
    done = np.zeros(shape, dtype=bool)
    # each pixel is queued at most once at a time
    capacity = int(np.count_nonzero(mask)) + 1
    keys = np.empty(capacity)
    items = np.empty(capacity, dtype=np.int64)
    where = np.full(mask.size, -1, dtype=np.int64)
    targets = np.full(shape, -1, dtype=np.int64) if goal is None else goal
    reached = np.full(max(int(targets.max()) + 1, 1), np.inf)
    _march(f, theta, mask, float(steep), index.astype(np.int64), values.astype(np.float64),
           labels.astype(np.int64), targets, int(need), T, label, done, keys, items, where,
           reached)
    if goal is not None:
        return T, label, reached
    return T, label


# --------------------------------------------------------------------------------------------
# The solver.
# --------------------------------------------------------------------------------------------


@dataclass
class _Node:
    pixels: np.ndarray  # (K, 2) int64
    kind: str
    part: int
    top: float  # brightest c in the node
    size: int  # pixels in its singular region (for choosing the main source)
    origin: str
    region: int = 0  # label of its detected singular region, 0 for none
    height: float = np.nan

    @property
    def representative(self) -> tuple[int, int]:
        centre = self.pixels.mean(axis=0)
        r, c = self.pixels[np.argmin(((self.pixels - centre) ** 2).sum(axis=1))]
        return int(r), int(c)


def eikonal_depth(
    image,
    mask,
    *,
    k: float | None = None,
    sources=None,
    concave=None,
    detect: bool = True,
    tol: float = TOL,
    smooth: float = 0.0,
    steep: float = STEEP,
) -> EikonalResult:
    """Depth and normals from one image lit from the viewer's direction, by fast marching.

    Solves ``|grad z| = sqrt(k^2 / I^2 - 1)`` (light ``(0, 0, 1)``, orthographic camera,
    Lambertian, uniform albedo) from the singular points of the surface; see the module docstring
    for how sources, their kinds and their heights make one surface.

    Parameters
    ----------
    image : (H, W) float
        One channel, >= 0, finite on the mask (filter noisy images first, e.g. with
        :func:`shadeform.preprocess.apply_filter`).
    mask : (H, W) bool
        Object pixels.
    k : float, optional
        ``k * albedo``: the brightness of a pixel facing the light. Default: the brightest object
        pixel (of the smoothed image when ``smooth > 0``).
    sources : sequence, optional
        Singular points the user knows, as ``(row, col)`` or ``(row, col, kind)`` with ``kind`` in
        :data:`KINDS` (default: from ``concave``). The surface is taken as level there. A source
        inside a detected singular region replaces it. The first is the main source: ``z = 0``
        there.
    concave : tuple of two (H, W) bool, or (H, W) bool, optional
        Where the surface is concave: ``(concave_x, concave_y)`` as returned by
        :func:`shadeform.regions.concave_masks`, or one mask meaning concave along both axes.
        A singular point is a minimum where both are set, a saddle where one is, else a maximum.
    detect : bool, optional
        Find singular regions automatically (default). With False only ``sources`` are used (and
        the brightest pixel of every part of the mask without one).
    tol : float, optional
        A singular region is a cap of pixels reaching ``I / k >= 1 - tol`` (slope below
        ``sqrt(2 tol)``) that rises ``tol`` above the pass to any brighter one. Raise it for noisy
        images (2e-2 at 1% noise after a Gaussian of sigma 2); at most :data:`MAX_DETECTED` caps,
        the largest, are kept.
    smooth : float, optional
        Standard deviation in pixels of a Gaussian (inside the mask) applied before singular
        points and ``k`` are found; the marching itself uses ``image`` unchanged. 0: none.
    steep : float, optional
        Slope above which the arc update replaces finite differences (see module docstring).

    Returns
    -------
    EikonalResult
        ``depth`` (H, W), ``normals`` (H, W, 3), ``sources`` (main first), ``k`` and ``info``.

    Raises
    ------
    InputError
        Wrong shapes or types, NaN or negative values in the object, an empty or black object,
        a bad ``k``, ``tol``, ``smooth`` or ``steep``, malformed sources or concave masks.

    References
    ----------
    .. [1] P. Dupuis and J. Oliensis, "An optimal control formulation and related numerical
       methods for a problem in shape reconstruction", Ann. Appl. Probab. 4(2), 1994.
    .. [2] R. Kimmel and J. A. Sethian, "Optimal algorithm for shape from shading and path
       planning", J. Math. Imaging Vis. 14(3), 2001.

    Examples
    --------
    >>> from shadeform import synth, metrics
    >>> s = synth.scene("sphere", size=64)
    >>> res = eikonal_depth(s.image, s.mask)
    >>> bool(metrics.depth_error(res.depth, s.depth, s.mask) < 0.5)
    True
    """
    timer = StageTimer()
    lap = timer.lap

    image, mask = _check_image_mask(image, mask)
    concave_x, concave_y = _check_concave(concave, mask.shape)
    tol = _positive(tol, "tol")
    if tol >= 1:
        raise InputError(f"tol must be below 1 (a tolerance on I / k), got {tol}")
    smooth = _finite(smooth, "smooth")
    if smooth < 0:
        raise InputError(f"smooth must be >= 0 (a Gaussian sigma in pixels), got {smooth}")
    steep = _positive(steep, "steep")
    if not isinstance(detect, (bool, np.bool_)):
        raise InputError(f"detect must be True or False, got {detect!r}")

    seen = _smoothed(image, mask, smooth) if smooth > 0 else image
    if k is None:
        k = float(seen[mask].max())
    else:
        k = _positive(k, "k")
    cos_theta = np.where(mask, np.clip(image / k, 0.0, 1.0), 0.0)
    cos_seen = np.where(mask, np.clip(seen / k, 0.0, 1.0), 0.0)
    f, theta = _slope_fields(cos_theta)
    parts, n_parts = ndi.label(mask, structure=_EIGHT)
    lap("prepare")

    if detect:
        nodes, regions, found = _detect(cos_seen, mask, parts, concave_x, concave_y, tol)
    else:
        nodes, regions, found = [], np.zeros(mask.shape, dtype=np.int64), 0
    nodes = _add_user_sources(nodes, regions, sources, cos_seen, mask, parts, concave_x, concave_y)
    nodes = _cover_parts(nodes, cos_seen, parts, n_parts, concave_x, concave_y)
    main_of_part = _main_sources(nodes, n_parts)
    lap("sources")

    _place_heights(nodes, main_of_part, f, theta, mask, steep)
    lap("heights")

    depth = _surface(nodes, f, theta, mask, steep)
    offset = np.zeros(n_parts + 1)
    for part, main in main_of_part.items():
        offset[part] = depth[nodes[main].representative]
    depth = np.where(mask, depth - offset[parts], np.nan)
    lap("depth")

    normals = cone_normals(depth, mask, cos_theta)
    lap("normals")

    # the main source first: the first user source, else the first part's
    main = 0 if nodes[0].origin == "user" else main_of_part[1]
    points = tuple(_as_point(node) for node in [nodes[main], *nodes[:main], *nodes[main + 1:]])
    info = {"parts": int(n_parts), "detected": int(found), "tol": tol, "steep": steep,
            "smooth": smooth, "timings": timer.timings}
    return EikonalResult(depth=depth, normals=normals, sources=points, k=float(k), info=info)


def cone_normals(depth: np.ndarray, mask: np.ndarray, cos_theta: np.ndarray) -> np.ndarray:
    """Normals with ``n_z = cos_theta`` tilted along the steepest descent of ``depth`` (compiled).

    Parameters
    ----------
    depth : (H, W) float
        Height; read only on ``mask``.
    mask : (H, W) bool
    cos_theta : (H, W) float
        Required ``n_z``, clipped to [0, 1] (``I / k`` for a light at +z).

    Returns
    -------
    normals : (H, W, 3) float64
        Unit normals, NaN outside the mask. The gradient uses central differences where both
        neighbours are on the mask, one-sided ones where only one is; where it vanishes the
        normal is ``(0, 0, 1)``.
    """
    depth = np.asarray(depth, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    cos = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    normals = np.full(mask.shape + (3,), np.nan)
    _cone_normals_kernel(depth, mask, cos, normals)
    return normals


def cone_normals_reference(depth: np.ndarray, mask: np.ndarray, cos_theta: np.ndarray) -> np.ndarray:
    """Plain numpy version of :func:`cone_normals` (same arguments and result), for the tests."""
    mask = np.asarray(mask, dtype=bool)
    z = np.where(mask, depth, 0.0)

    def derivative(axis: int) -> np.ndarray:
        forward = np.zeros_like(z)
        has_forward = np.zeros(mask.shape, dtype=bool)
        lead = [slice(None)] * 2
        trail = [slice(None)] * 2
        lead[axis], trail[axis] = slice(1, None), slice(None, -1)
        lead, trail = tuple(lead), tuple(trail)
        pair = mask[lead] & mask[trail]
        forward[trail] = np.where(pair, z[lead] - z[trail], 0.0)
        has_forward[trail] = pair
        backward = np.zeros_like(z)
        has_backward = np.zeros(mask.shape, dtype=bool)
        backward[lead] = forward[trail]
        has_backward[lead] = pair
        count = has_forward.astype(np.float64) + has_backward
        return (forward + backward) / np.maximum(count, 1.0)

    zx = derivative(1)
    zy = -derivative(0)  # y is up: one row down is -1 in y
    slope = np.hypot(zx, zy)
    cos = np.clip(cos_theta, 0.0, 1.0)
    sin = np.sqrt(1.0 - cos * cos)
    flat = slope == 0
    scale = np.where(flat, 0.0, sin / np.where(flat, 1.0, slope))
    normals = np.stack([-zx * scale, -zy * scale, np.where(flat, 1.0, cos)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[~mask] = np.nan
    return normals


@numba.njit(cache=True)
def _cone_normals_kernel(z, mask, cos, out):
    height, width = mask.shape
    for r in range(height):
        for c in range(width):
            if not mask[r, c]:
                continue
            # d/dx along the row, d/drow down the column: the mean of the one-sided
            # differences that stay on the mask
            gx = 0.0
            n = 0
            if c + 1 < width and mask[r, c + 1]:
                gx += z[r, c + 1] - z[r, c]
                n += 1
            if c > 0 and mask[r, c - 1]:
                gx += z[r, c] - z[r, c - 1]
                n += 1
            if n:
                gx /= n
            grow = 0.0
            n = 0
            if r + 1 < height and mask[r + 1, c]:
                grow += z[r + 1, c] - z[r, c]
                n += 1
            if r > 0 and mask[r - 1, c]:
                grow += z[r, c] - z[r - 1, c]
                n += 1
            if n:
                grow /= n
            gy = -grow  # y is up
            slope = np.sqrt(gx * gx + gy * gy)
            if slope == 0.0:
                out[r, c, 0] = 0.0
                out[r, c, 1] = 0.0
                out[r, c, 2] = 1.0
                continue
            sin = np.sqrt(1.0 - cos[r, c] * cos[r, c])
            nx = -gx / slope * sin
            ny = -gy / slope * sin
            nz = cos[r, c]
            length = np.sqrt(nx * nx + ny * ny + nz * nz)
            out[r, c, 0] = nx / length
            out[r, c, 1] = ny / length
            out[r, c, 2] = nz / length


# --------------------------------------------------------------------------------------------
# Steps of the solver.
# --------------------------------------------------------------------------------------------


def _kind_at(r: int, c: int, concave_x, concave_y) -> str:
    x, y = bool(concave_x[r, c]), bool(concave_y[r, c])
    if x and y:
        return "min"
    if x or y:
        return "saddle"
    return "max"


def _detect(cos_seen, mask, parts, concave_x, concave_y, tol):
    """One node per significant bright cap: ``(nodes, label image of their caps, caps found)``.

    A cap is the connected set of pixels within ``tol`` of a regional maximum of ``c`` that rises
    at least ``tol`` above the pass to any brighter one (an h-maximum, found by morphological
    reconstruction of ``c - tol`` under ``c``), so maxima of noise or ripples on a singular
    plateau merge into one. A cap whose top reaches ``1 - tol`` is singular; its sources are its
    pixels within ``SOURCE_FRACTION * tol`` of the top (a ridge's whole crest, a plateau).
    """
    # Only caps reaching 1 - tol matter, and they lie above 1 - 2 tol: flooring c there and
    # cropping to where it rises above the floor changes none of them, and saves most of the work.
    floor = 1.0 - 2.0 * tol
    bright = mask & (cos_seen > floor)
    regions = np.zeros(mask.shape, dtype=np.int64)
    if not bright.any():
        return [], regions, 0
    rows, cols = np.nonzero(bright)
    box = (slice(max(rows.min() - 1, 0), rows.max() + 2), slice(max(cols.min() - 1, 0), cols.max() + 2))
    c = np.where(bright[box], cos_seen[box], floor)
    domes = reconstruction(c - tol, c, method="dilation", footprint=_EIGHT)
    caps = local_maxima(domes, connectivity=2, allow_borders=True) & bright[box]
    count = ndi.label(caps, structure=_EIGHT, output=regions[box])
    nodes = []
    kept = np.zeros(count + 1, dtype=bool)
    for index, window in enumerate(ndi.find_objects(regions), start=1):
        if window is None:
            continue
        inside = regions[window] == index
        values = cos_seen[window]
        top = float(values[inside].max())
        if top < 1.0 - tol:
            continue
        kept[index] = True
        rows, cols = np.nonzero(inside & (values >= top - SOURCE_FRACTION * tol))
        pixels = np.column_stack([rows + window[0].start, cols + window[1].start]).astype(np.int64)
        node = _Node(pixels=pixels, kind="max", part=int(parts[pixels[0, 0], pixels[0, 1]]),
                     top=top, size=int(inside.sum()), origin="detected", region=index)
        node.kind = _kind_at(*node.representative, concave_x, concave_y)
        nodes.append(node)
    found = len(nodes)
    if found > MAX_DETECTED:
        # Noise: a true singular point has a wide cap, a speck of noise a small one. Dropping a
        # maximum that was not one only removes a source whose bound added nothing.
        nodes = sorted(nodes, key=lambda node: -node.size)[:MAX_DETECTED]
        nodes.sort(key=lambda node: node.region)
        kept[:] = False
        kept[[node.region for node in nodes]] = True
    return nodes, np.where(kept[regions], regions, 0), found


def _add_user_sources(nodes, regions, sources, cos_seen, mask, parts, concave_x,
                      concave_y) -> list[_Node]:
    """User sources first (in their order); each replaces the detected region it falls in."""
    if sources is None:
        return nodes
    if isinstance(sources, (str, bytes)) or not hasattr(sources, "__iter__"):
        raise InputError("sources must be a sequence of (row, col) or (row, col, kind)")
    user = []
    replaced = set()
    for item in sources:
        r, c, kind = _parse_source(item, mask)
        if regions[r, c] > 0:
            replaced.add(int(regions[r, c]))
        user.append(_Node(pixels=np.array([[r, c]], dtype=np.int64),
                          kind=kind or _kind_at(r, c, concave_x, concave_y),
                          part=int(parts[r, c]), top=float(cos_seen[r, c]), size=1, origin="user"))
    return user + [node for node in nodes if node.region not in replaced]


def _parse_source(item, mask) -> tuple[int, int, str | None]:
    try:
        length = len(item)
    except TypeError:
        length = -1
    if length not in (2, 3):
        raise InputError(f"source {item!r} must be (row, col) or (row, col, kind)")
    r, c = item[0], item[1]
    for value in (r, c):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise InputError(f"source {item!r} must have whole-number row and col")
    r, c = int(r), int(c)
    if not (0 <= r < mask.shape[0] and 0 <= c < mask.shape[1]) or not mask[r, c]:
        raise InputError(f"source pixel (row {r}, col {c}) is not on the object; "
                         "pick a pixel inside the mask")
    kind = item[2] if length == 3 else None
    if kind is not None and kind not in KINDS:
        raise InputError(f"source kind must be one of {', '.join(KINDS)} or None, got {kind!r}")
    return r, c, kind


def _cover_parts(nodes, cos_seen, parts, n_parts, concave_x, concave_y) -> list[_Node]:
    """Give every connected part of the mask without a source its brightest pixel."""
    bare = sorted(set(range(1, n_parts + 1)) - {node.part for node in nodes})
    if not bare:
        return nodes
    for part, (r, c) in zip(bare, ndi.maximum_position(cos_seen, parts, bare)):
        r, c = int(r), int(c)
        nodes.append(_Node(pixels=np.array([[r, c]], dtype=np.int64),
                           kind=_kind_at(r, c, concave_x, concave_y), part=part,
                           top=float(cos_seen[r, c]), size=1, origin="brightest"))
    return nodes


def _main_sources(nodes, n_parts) -> dict[int, int]:
    """Per part, the node at z = 0: the first user source, else the brightest (then largest)."""
    main = {}
    for i, node in enumerate(nodes):
        if node.origin == "user" and node.part not in main:
            main[node.part] = i
    for part in range(1, n_parts + 1):
        if part in main:
            continue
        members = [i for i, node in enumerate(nodes) if node.part == part]
        main[part] = max(members, key=lambda i: (nodes[i].top, nodes[i].size, -i))
    return main


def _place_heights(nodes, main_of_part, f, theta, mask, steep) -> None:
    """Heights of all sources from their weighted distances (module docstring, step 2).

    Every placed source ``a`` bounds a new one ``b``: ``|z_b - z_a| <= D_ab``. A maximum takes
    the lowest upper bound, a minimum the highest lower bound; both are reached where a path of
    steepest ascent (descent) joins ``b`` to a placed source, which is why sources linked to a
    placed one of another kind go first. A saddle lies below the maximum or above the minimum
    that links it; one that nothing links takes its nearest neighbour's height.
    """
    for part, main in main_of_part.items():
        members = [i for i, node in enumerate(nodes) if node.part == part]
        nodes[main].height = 0.0
        if len(members) == 1:
            continue
        distance = _pairwise_distances([nodes[i] for i in members], f, theta, mask, steep)
        local = {i: j for j, i in enumerate(members)}

        def d(a: int, b: int) -> float:
            return distance[local[a], local[b]]

        placed = [main]
        waiting = [i for i in members if i != main]
        while waiting:
            linked = [(d(a, b), b, a) for b in waiting for a in placed
                      if nodes[a].kind != nodes[b].kind]
            _, b, nearest = min(linked or [(d(a, b), b, a) for b in waiting for a in placed])
            lower = max(nodes[a].height - d(a, b) for a in placed)
            upper = min(nodes[a].height + d(a, b) for a in placed)
            kind = nodes[b].kind
            if kind == "max":
                nodes[b].height = upper
            elif kind == "min":
                nodes[b].height = lower
            elif not linked:
                nodes[b].height = nodes[nearest].height
            else:
                nodes[b].height = lower if nodes[nearest].kind == "max" else upper
            placed.append(b)
            waiting.remove(b)


def _pairwise_distances(members, f, theta, mask, steep) -> np.ndarray:
    """``D[a, b]``: weighted distance between the sources of nodes a and b (symmetric).

    The marching from node a measures the nodes after it and stops once it has reached them all.
    """
    n = len(members)
    goal = np.full(mask.shape, -1, dtype=np.int64)
    for j, node in enumerate(members):
        goal[node.pixels[:, 0], node.pixels[:, 1]] = j
    width = mask.shape[1]
    distance = np.zeros((n, n))
    for a, node in enumerate(members[:-1]):
        goal[node.pixels[:, 0], node.pixels[:, 1]] = -1  # measured from now on
        index = node.pixels[:, 0] * width + node.pixels[:, 1]
        need = len(np.unique(goal[goal > a]))
        T, _, reached = _run_march(f, theta, mask, steep, index, np.zeros(len(index)),
                                   np.zeros(len(index), np.int64), goal=goal, need=need)
        for b in range(a + 1, n):
            # a node whose pixels all belong to others (a repeated source) is read from T
            pixels = members[b].pixels
            first = reached[b] if b < len(reached) else np.inf
            distance[a, b] = distance[b, a] = min(first, T[pixels[:, 0], pixels[:, 1]].min())
    return distance


def _surface(nodes, f, theta, mask, steep) -> np.ndarray:
    """``L`` (from above) or ``U`` (from below) per pixel, by the kind of the nearest source."""
    width = mask.shape[1]
    index = np.concatenate([n.pixels[:, 0] * width + n.pixels[:, 1] for n in nodes])
    counts = [len(n.pixels) for n in nodes]
    heights = np.repeat([n.height for n in nodes], counts)
    ids = np.repeat(np.arange(len(nodes)), counts)
    is_min = np.array([n.kind == "min" for n in nodes])
    if not is_min.any():
        low, _ = _run_march(f, theta, mask, steep, index, -heights, ids)
        return -low
    up, _ = _run_march(f, theta, mask, steep, index, heights, ids)
    if is_min.all():
        return up
    low, _ = _run_march(f, theta, mask, steep, index, -heights, ids)
    _, nearest = _run_march(f, theta, mask, steep, index, np.zeros(len(index)), ids)
    from_below = mask & is_min[np.maximum(nearest, 0)]
    return np.where(from_below, up, -low)


def _as_point(node: _Node) -> SingularPoint:
    r, c = node.representative
    pixels = node.pixels.copy()
    pixels.flags.writeable = False
    return SingularPoint(row=r, col=c, kind=node.kind, height=float(node.height), pixels=pixels,
                         origin=node.origin)


# --------------------------------------------------------------------------------------------
# Input checks.
# --------------------------------------------------------------------------------------------


def _check_image_mask(image, mask) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(image, np.ndarray):
        raise InputError(f"image must be a numpy array, got {type(image).__name__}")
    if image.ndim != 2:
        raise InputError(f"image must be one channel (H, W), got shape {image.shape}")
    if image.dtype == bool or not (np.issubdtype(image.dtype, np.floating)
                                   or np.issubdtype(image.dtype, np.integer)):
        raise InputError(f"image must hold numbers, got dtype {image.dtype}")
    mask = np.asarray(mask)
    if mask.shape != image.shape:
        raise InputError(f"mask has shape {mask.shape} but the image has {image.shape}; "
                         "give a mask of the image's size")
    mask = mask.astype(bool)
    if not mask.any():
        raise InputError("mask is empty; it must mark the object's pixels")
    image = image.astype(np.float64)
    values = image[mask]
    if not np.isfinite(values).all():
        raise InputError("image has NaN or inf on the object; replace them or mask them out")
    if values.min() < 0:
        raise InputError("image has negative values on the object; intensities must be >= 0")
    if values.max() <= 0:
        raise InputError("the object is black: there is no shading to work with")
    return image, mask


def _check_concave(concave, shape) -> tuple[np.ndarray, np.ndarray]:
    if concave is None:
        empty = np.zeros(shape, dtype=bool)
        return empty, empty
    if isinstance(concave, np.ndarray) and concave.ndim == 2:
        if concave.shape != shape:
            raise InputError(f"concave mask has shape {concave.shape}, the image {shape}")
        both = concave.astype(bool)
        return both, both
    if isinstance(concave, (tuple, list)) and len(concave) == 2:
        pair = [np.asarray(m) for m in concave]
        if any(m.shape != shape for m in pair):
            raise InputError(f"concave masks must both have the image's shape {shape}, got "
                             f"{pair[0].shape} and {pair[1].shape}")
        return pair[0].astype(bool), pair[1].astype(bool)
    raise InputError("concave must be (concave_x, concave_y) from shadeform.regions.concave_masks "
                     "or one (H, W) bool mask (concave along both axes)")


def _smoothed(image, mask, sigma) -> np.ndarray:
    """Gaussian inside the mask by normalised convolution; the background never bleeds in."""
    weight = ndi.gaussian_filter(mask.astype(np.float64), sigma, mode="constant")
    blurred = ndi.gaussian_filter(np.where(mask, image, 0.0), sigma, mode="constant")
    return np.where(mask, blurred / np.maximum(weight, 1e-12), image)


def _finite(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{what} must be a number, got {value!r}")
    value = float(value)
    if not np.isfinite(value):
        raise InputError(f"{what} must be finite, got {value}")
    return value


def _positive(value, what: str) -> float:
    value = _finite(value, what)
    if value <= 0:
        raise InputError(f"{what} must be > 0, got {value}")
    return value
