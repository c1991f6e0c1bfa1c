"""Step 1 of the oblique solver: cone marching from the brightest caps.

Every lit pixel's normal lies on its shading cone (:mod:`._cone`): one unknown, the azimuth
``phi``. The marching fixes the lit pixels one at a time, from the sources (the caps of
``N = L``, :mod:`.caps`) outward, each with the cone normal and height that best fit its already
accepted 8-neighbours. For a neighbour ``b`` the chord from it is perpendicular to the sum of the
two normals,

    (n + n_b) . (x_b - x, y_b - y, z_b - z) = 0,

which holds exactly for any two points of a sphere (their chord is perpendicular to the sum of the
radii) and to second order on any smooth surface. For a trial ``phi`` the height ``z`` is the
least-squares fit of these equations; ``phi`` minimises their residual plus

* a small continuity term ``|n - n_b|^2`` (weight :data:`CONTINUITY`);
* a tie-break that prefers the convex turn of the normal, the way one moves (weight
  :data:`CONVEXITY`), flipped per axis inside the user's concave regions. Each neighbour's term
  takes the mean of the two pixels' signs: none across a region's edge, where the surface's
  inflection lies between them and neither turn is the expected one (a constant pull there
  over-turns the weakly curved surface past the edge);
* a one-sided penalty, :data:`HINGE` times the squared shortfall, on a turn against the convexity
  (``n_x`` falling where ``x`` grows toward a neighbour, or ``n_y`` where ``y`` does), flipped
  likewise. It is zero while the turn agrees, so it picks one of the cone's two branches without
  pulling the normal.

Order. Pixels are taken by distance from the nearest source plus :data:`BRIGHTNESS` object lengths
per unit of darkening ``1 - I / albedo``, so that a ridge of near-full brightness (where the
azimuth is weakly determined) is marched along its crest first and each side is reached from the
crest, taking its convex turn against the crest's normals; nearest-first alone reached the
vase's neck from the side and left it in the wrong branch. A pixel is queued only once its
accepted neighbours span both image directions, so the front cannot run away along a one-pixel
path. The queue is the project's indexed heap (:mod:`shadeform.solvers._heap`), keyed by that
order; ties pop the smaller flat index first.

Datums. Each cap of sources starts its own height datum (:func:`.caps.cap_datums`) and a pixel is
fitted to the neighbours of one datum only, the one that weighs most among its accepted
neighbours: where the fronts of two caps meet, neither's heights nor its drift reach the other's
pixels.

This is in the spirit of the height-ordered local solves of Bichsel and Pentland [1]_, with the
chord equation in place of their slope rule. :func:`march_cone` is the compiled kernel;
:func:`march_cone_reference` a plain-Python transcription (``heapq`` and the uncompiled local fit)
kept for the tests.

References
----------
.. [1] M. Bichsel and A. P. Pentland, "A simple algorithm for shape from shading", CVPR 1992.
"""

from __future__ import annotations

import heapq
import inspect

import numba
import numpy as np
from scipy import ndimage as ndi

from shadeform.solvers._heap import heap_pop, heap_update, new_heap
from shadeform.solvers.oblique._cone import azimuth_limits, cone_basis, cone_frame
from shadeform.solvers.oblique.caps import cap_datums

# The constants below were set by hand, coarsely, on the synthetic sphere and vase under the light
# (5, 5, 7) (the scenes of the accuracy bars, benchmarks/bench_oblique.py); HINGE and BRIGHTNESS
# then on the vase at (5, 5, 7) and at slant 30 degrees, checked on the other scenes (the
# measurements: benchmarks/results/oblique.md, "Tuning history").

#: Weight of ``|n - n_b|^2`` in the local fit (continuity with accepted neighbours).
CONTINUITY = 0.05
#: Weight of the convex (or marked concave) turn of the normal in the local fit.
CONVEXITY = 0.03
#: Weight of the one-sided penalty on a turn of the normal against the convexity (the marked one
#: inside the concave regions, convex elsewhere) in the local fit.
HINGE = 100.0
#: The order: distance to the nearest source plus this many object lengths per unit of darkening
#: ``1 - I / albedo``.
BRIGHTNESS = 0.12
#: Trial azimuths per pixel before the golden-section refinement.
SAMPLES = 72

_GOLDEN = 0.3819660112501051  # (3 - sqrt(5)) / 2
#: Golden-section steps: they shrink the bracket of two trial spacings by 0.618^24, about 1e-5.
_GOLDEN_STEPS = 24


# The local fit's functions are inlined into the marching loop (numba's inline="always", as are
# the heap's operations): a compiled call counts references to each array argument, and the
# cost alone is called about 70 times a pixel (kernel 10-20 % faster, median of 9 scene runs:
# benchmarks/results/inline.md; the values are bit-identical).


@numba.njit(cache=True)
def _fit_work():
    """Work arrays of the local fit: ``nb, db, zb, wb, prefer, a0, a1, a2, tmp`` (8 neighbours)."""
    return (
        np.empty((8, 3)),
        np.empty((8, 2)),
        np.empty(8),
        np.empty(8),
        np.empty(2),
        np.empty(3),
        np.empty(3),
        np.empty(3),
        np.empty(1),
    )


@numba.njit(cache=True, inline="always")
def _gather(r, c, state, convex, kappa, work, lb):
    """Accepted 8-neighbours of ``(r, c)`` into ``work`` (:func:`_fit_work`): normals ``nb``,
    displacements ``db = (dx, dy)`` to them, heights ``zb``, weights ``wb = 1 / |d|^2``, and their
    height datums into ``lb``; ``prefer`` the convexity tie-break direction, each neighbour's term
    with the mean of its and the pixel's convexity sign (0 across the edge of a concave region).
    ``state = (z, normals, done, datum)``, ``convex = (convex_x, convex_y)`` (+1 or -1).
    Returns ``(count, spans)``, ``spans`` when the displacements span the image plane."""
    z, normals, done, datum = state
    convex_x, convex_y = convex
    nb, db, zb, wb, prefer = work[0], work[1], work[2], work[3], work[4]
    height, width = z.shape
    count = 0
    prefer[0] = 0.0
    prefer[1] = 0.0
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            rb = r + dr
            cb = c + dc
            if (dr == 0 and dc == 0) or rb < 0 or rb >= height or cb < 0 or cb >= width or not done[rb, cb]:
                continue
            dx = float(dc)
            dy = float(-dr)  # y is up
            weight = 1.0 / (dx * dx + dy * dy)
            nb[count, 0] = normals[rb, cb, 0]
            nb[count, 1] = normals[rb, cb, 1]
            nb[count, 2] = normals[rb, cb, 2]
            db[count, 0] = dx
            db[count, 1] = dy
            zb[count] = z[rb, cb]
            wb[count] = weight
            lb[count] = datum[rb, cb]
            # convex: the normal turns the way one moves (from b to here, -d); concave flips it,
            # and a pair across a concave region's edge (the inflection between them) has no
            # preferred turn
            prefer[0] -= kappa * weight * 0.5 * (convex_x[r, c] + convex_x[rb, cb]) * dx
            prefer[1] -= kappa * weight * 0.5 * (convex_y[r, c] + convex_y[rb, cb]) * dy
            count += 1
    spans = False
    for i in range(count):
        for j in range(i + 1, count):
            if db[i, 0] * db[j, 1] != db[i, 1] * db[j, 0]:
                spans = True
    return count, spans


@numba.njit(cache=True, inline="always")
def _local_cost(phi, a0, a1, a2, nb, db, zb, wb, count, gamma, prefer, hinge, cx, cy, out_z):
    """Cost of azimuth ``phi`` in the local fit; its best height goes to ``out_z[0]``.

    ``cx, cy`` are +1 (convex) or -1 (concave) along x and y at the pixel: a neighbour ``b`` at
    ``d`` should have ``cx d_x (n_b,x - n_x) >= 0`` and ``cy d_y (n_b,y - n_y) >= 0``; each
    shortfall costs ``hinge`` times its square."""
    cp = np.cos(phi)
    sp_ = np.sin(phi)
    n0 = a0[0] + a1[0] * cp + a2[0] * sp_
    n1 = a0[1] + a1[1] * cp + a2[1] * sp_
    n2 = a0[2] + a1[2] * cp + a2[2] * sp_
    num = 0.0
    den = 0.0
    for j in range(count):
        s0 = n0 + nb[j, 0]
        s1 = n1 + nb[j, 1]
        s2 = n2 + nb[j, 2]
        num += wb[j] * s2 * (s0 * db[j, 0] + s1 * db[j, 1] + s2 * zb[j])
        den += wb[j] * s2 * s2
    z = num / den if den > 1e-12 else 0.0
    cost = -(n0 * prefer[0] + n1 * prefer[1])
    for j in range(count):
        s0 = n0 + nb[j, 0]
        s1 = n1 + nb[j, 1]
        s2 = n2 + nb[j, 2]
        residual = s0 * db[j, 0] + s1 * db[j, 1] + s2 * (zb[j] - z)
        m0 = n0 - nb[j, 0]
        m1 = n1 - nb[j, 1]
        m2 = n2 - nb[j, 2]
        cost += wb[j] * (residual * residual + gamma * (m0 * m0 + m1 * m1 + m2 * m2))
        turn_x = min(cx * db[j, 0] * (nb[j, 0] - n0), 0.0)
        turn_y = min(cy * db[j, 1] * (nb[j, 1] - n1), 0.0)
        cost += hinge * wb[j] * (turn_x * turn_x + turn_y * turn_y)
    out_z[0] = z
    return cost


@numba.njit(cache=True, inline="always")
def _fit_pixel(r, c, state, cone, convex, weights, samples, work, labels, out):
    """The marching's local fit at ``(r, c)``: ``out = (n_x, n_y, n_z, z, phi, datum)``.

    Heights are relative to the source cap each front started from (its datum): separate caps
    of ``N = L`` need not lie at one height along ``L``. The pixel takes the datum that weighs
    most among its accepted neighbours (ties: the lower one) and is fitted to those neighbours
    only; where two fronts meet, the other front's pixels take no part (their heights are on
    another datum, and their normals carry that front's own drift).

    ``state = (z, normals, done, datum)`` of the marching, ``cone = (cos_theta, limits, light,
    e1, e2)``, ``convex = (convex_x, convex_y)``, ``weights = (continuity, convexity, hinge)``."""
    nb, db, zb, wb, prefer, a0, a1, a2, tmp = work
    cos_theta, limits, light, e1, e2 = cone
    convex_x, convex_y = convex
    gamma, kappa, hinge = weights
    count, _ = _gather(r, c, state, convex, kappa, work, labels)
    chosen = -1
    chosen_weight = -1.0
    for i in range(count):
        total = 0.0
        for j in range(count):
            if labels[j] == labels[i]:
                total += wb[j]
        if total > chosen_weight or (total == chosen_weight and labels[i] < chosen):
            chosen = labels[i]
            chosen_weight = total
    prefer[0] = 0.0
    prefer[1] = 0.0
    for j in range(count):
        if labels[j] != chosen:
            wb[j] = 0.0
        rb = r - int(db[j, 1])
        cb = c + int(db[j, 0])
        prefer[0] -= kappa * wb[j] * 0.5 * (convex_x[r, c] + convex_x[rb, cb]) * db[j, 0]
        prefer[1] -= kappa * wb[j] * 0.5 * (convex_y[r, c] + convex_y[rb, cb]) * db[j, 1]
    cx = convex_x[r, c]
    cy = convex_y[r, c]
    cone_basis(cos_theta[r, c], light, e1, e2, a0, a1, a2)
    limit = limits[r, c]
    best = 0.0
    best_cost = np.inf
    best_z = 0.0
    for j in range(samples):
        t = -limit + 2.0 * limit * j / (samples - 1)
        cost = _local_cost(t, a0, a1, a2, nb, db, zb, wb, count, gamma, prefer, hinge, cx, cy, tmp)
        if cost < best_cost:
            best_cost = cost
            best = t
            best_z = tmp[0]
    step = 2.0 * limit / (samples - 1)
    lo = max(best - step, -limit)
    hi = min(best + step, limit)
    for _ in range(_GOLDEN_STEPS):
        m1 = lo + _GOLDEN * (hi - lo)
        m2 = hi - _GOLDEN * (hi - lo)
        cost1 = _local_cost(m1, a0, a1, a2, nb, db, zb, wb, count, gamma, prefer, hinge, cx, cy, tmp)
        cost2 = _local_cost(m2, a0, a1, a2, nb, db, zb, wb, count, gamma, prefer, hinge, cx, cy, tmp)
        if cost1 < cost2:
            hi = m2
        else:
            lo = m1
    t = 0.5 * (lo + hi)
    cost = _local_cost(t, a0, a1, a2, nb, db, zb, wb, count, gamma, prefer, hinge, cx, cy, tmp)
    if cost < best_cost:
        best = t
        best_z = tmp[0]
    cp = np.cos(best)
    sp_ = np.sin(best)
    for i in range(3):
        out[i] = a0[i] + a1[i] * cp + a2[i] * sp_
    out[3] = best_z
    out[4] = best
    out[5] = chosen


@numba.njit(cache=True)
def _march_kernel(
    state, cone, convex, weights, samples, lit, sources, source_z, source_datum, distance, heap
):
    z, normals, done, datum = state
    light = cone[2]
    keys, items, where = heap
    work = _fit_work()
    labels = np.empty(8, np.int64)
    out = np.empty(6)
    height, width = z.shape
    is_source = np.zeros(z.shape, np.bool_)
    size = 0
    for s in range(sources.shape[0]):
        r = sources[s, 0]
        c = sources[s, 1]
        is_source[r, c] = True
        size = heap_update(keys, items, where, size, -1.0, r * width + c)
    # each pixel is queued once, with its fixed key distance[r, c], and never again once done
    while size > 0:
        _, item, size = heap_pop(keys, items, where, size)
        r = item // width
        c = item % width
        if is_source[r, c]:
            for i in range(3):
                normals[r, c, i] = light[i]
            z[r, c] = source_z[r, c]
            datum[r, c] = source_datum[r, c]
        else:
            _fit_pixel(r, c, state, cone, convex, weights, samples, work, labels, out)
            for i in range(3):
                normals[r, c, i] = out[i]
            z[r, c] = out[3]
            datum[r, c] = int(out[5])
        done[r, c] = True
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr = r + dr
                cc = c + dc
                if rr < 0 or rr >= height or cc < 0 or cc >= width or not lit[rr, cc] or done[rr, cc]:
                    continue
                _, spans = _gather(rr, cc, state, convex, 0.0, work, labels)
                # one-pixel paths wait for support in both directions (next to a source: not)
                if spans or is_source[r, c]:
                    size = heap_update(keys, items, where, size, distance[rr, cc], rr * width + cc)


class _Marching:
    """What both versions of the marching start from, and the arrays they fill."""

    def __init__(self, cos_theta, lit, light, sources, concave_x, concave_y, brightness):
        self.cos_theta = np.ascontiguousarray(cos_theta, dtype=np.float64)
        self.lit = np.ascontiguousarray(lit, dtype=bool)
        self.light = np.asarray(light, dtype=np.float64)
        self.sources = np.ascontiguousarray(np.asarray(sources, dtype=np.int64).reshape(-1, 2))
        self.e1, self.e2 = cone_frame(self.light)
        self.limits = azimuth_limits(self.cos_theta, self.light)
        shape = self.cos_theta.shape
        self.convex_x = np.where(concave_x, -1.0, 1.0) if concave_x is not None else np.ones(shape)
        self.convex_y = np.where(concave_y, -1.0, 1.0) if concave_y is not None else np.ones(shape)
        seeds = np.zeros(shape, dtype=bool)
        seeds[self.sources[:, 0], self.sources[:, 1]] = True
        # the order: distance to the nearest source, plus the darkening in units of the object's
        # length (module docstring)
        self.distance = ndi.distance_transform_edt(~seeds)
        if self.lit.any():
            rows_lit = np.flatnonzero(self.lit.any(axis=1))
            cols_lit = np.flatnonzero(self.lit.any(axis=0))
            length = max(rows_lit[-1] - rows_lit[0], cols_lit[-1] - cols_lit[0]) + 1
            self.distance = self.distance + float(brightness) * length * (1.0 - self.cos_theta)
        # the sources of one cap lie on one plateau of the height along L (N = L there), so their
        # heights follow from their positions; each cap has its own datum
        r0, c0 = self.sources[0]
        rows, cols = np.indices(shape)
        light = self.light
        self.source_z = -(light[0] * (cols - c0) - light[1] * (rows - r0)) / light[2]
        self.source_datum = cap_datums(seeds, self.cos_theta, self.lit)
        # the results: NaN where not reached
        self.z = np.full(shape, np.nan)
        self.normals = np.full(shape + (3,), np.nan)
        self.done = np.zeros(shape, dtype=bool)
        self.datum = np.full(shape, -1, dtype=np.int64)
        # the bundles the kernels take
        self.state = (self.z, self.normals, self.done, self.datum)
        self.cone = (self.cos_theta, self.limits, self.light, self.e1, self.e2)
        self.convex = (self.convex_x, self.convex_y)


def march_cone(
    cos_theta,
    lit,
    *,
    light,
    sources,
    concave_x=None,
    concave_y=None,
    continuity=CONTINUITY,
    convexity=CONVEXITY,
    hinge=HINGE,
    brightness=BRIGHTNESS,
    samples=SAMPLES,
):
    """Normals and heights of the lit pixels by marching from the sources (compiled).

    Parameters
    ----------
    cos_theta : (H, W) float
        ``I / albedo`` in [0, 1].
    lit : (H, W) bool
        Pixels to solve; the marching stays on them.
    light : (3,) float
        Unit vector toward the light, ``light[2] > 0``.
    sources : (S, 2) int
        ``(row, col)`` of the pixels that start with ``N = L``; the first has ``z = 0``.
    concave_x, concave_y : (H, W) bool, optional
        The user's concave regions per axis: the convexity tie-break and hinge flip there.
    continuity, convexity : float
        Weights of ``|n - n_b|^2`` and of the convex turn in the local fit.
    hinge : float
        Weight of the one-sided penalty on a turn against the convexity in the local fit.
    brightness : float
        Object lengths added to a pixel's place in the marching order per unit of
        ``1 - I / albedo``.
    samples : int
        Trial azimuths per pixel (>= 3) before golden-section refinement.

    Returns
    -------
    normals : (H, W, 3) float64
        NaN where not reached.
    depth : (H, W) float64
        NaN where not reached.
    """
    m = _Marching(cos_theta, lit, light, sources, concave_x, concave_y, brightness)
    weights = (float(continuity), float(convexity), float(hinge))
    _march_kernel(
        m.state,
        m.cone,
        m.convex,
        weights,
        int(samples),
        m.lit,
        m.sources,
        m.source_z,
        m.source_datum,
        m.distance,
        new_heap(m.cos_theta.size),
    )
    return m.normals, m.z


def march_cone_reference(cos_theta, lit, **options):
    """Slow, plain-Python version of :func:`march_cone`: the same arguments and result.

    ``heapq`` for the queue (a pixel pushed by each neighbour that supports it, skipped when
    popped again) and the local fit evaluated by the uncompiled functions; for the tests, on
    small images.
    """
    given = inspect.signature(march_cone).bind(cos_theta, lit, **options)
    given.apply_defaults()
    a = given.arguments
    m = _Marching(cos_theta, lit, a["light"], a["sources"], a["concave_x"], a["concave_y"], a["brightness"])
    weights = (float(a["continuity"]), float(a["convexity"]), float(a["hinge"]))
    samples = int(a["samples"])
    height, width = m.cos_theta.shape
    z, normals, done, datum = m.z, m.normals, m.done, m.datum
    work = _fit_work.py_func()
    labels = np.empty(8, dtype=np.int64)
    out = np.empty(6)
    is_source = set()
    queue = []
    for r, c in m.sources:
        is_source.add((int(r), int(c)))
        heapq.heappush(queue, (-1.0, int(r) * width + int(c)))
    fit = _fit_pixel.py_func
    gather = _gather.py_func
    while queue:
        _, item = heapq.heappop(queue)
        r, c = divmod(item, width)
        if done[r, c]:
            continue
        if (r, c) in is_source:
            normals[r, c] = m.light
            z[r, c] = m.source_z[r, c]
            datum[r, c] = m.source_datum[r, c]
        else:
            fit(r, c, m.state, m.cone, m.convex, weights, samples, work, labels, out)
            normals[r, c] = out[:3]
            z[r, c] = out[3]
            datum[r, c] = int(out[5])
        done[r, c] = True
        for rr in range(r - 1, r + 2):
            for cc in range(c - 1, c + 2):
                if not (0 <= rr < height and 0 <= cc < width) or not m.lit[rr, cc] or done[rr, cc]:
                    continue
                _, spans = gather(rr, cc, m.state, m.convex, 0.0, work, labels)
                if spans or (r, c) in is_source:
                    heapq.heappush(queue, (float(m.distance[rr, cc]), rr * width + cc))
    return normals, z
