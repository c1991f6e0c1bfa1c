"""Shape from shading for any light direction, with attached shadows.

With a distant light ``L`` and the Lambertian model ``I = k max(0, N . L)`` every lit pixel's normal
lies on a cone around ``L`` of half-angle ``acos(I / k)``: one unknown per pixel, the azimuth
``phi`` of the normal around ``L``. Shadowed pixels (``I / k <= dark``) only say ``N . L <= 0``.
The solver

1. **marches** over the lit pixels from the brightest ones (the caps within ``tol`` of ``k``: the
   singular points, where ``N = L``), in order of distance from them plus ``BRIGHTNESS`` object
   lengths per unit of darkening ``1 - I / k``, so that a ridge of near-full brightness (where
   the azimuth is weakly determined) is marched along its crest first and each side is reached
   from the crest. Each pixel takes the cone normal and height that best fit its already accepted
   8-neighbours: for a neighbour ``b`` the chord from it is perpendicular to the sum of the two
   normals,

       (n + n_b) . (x_b - x, y_b - y, z_b - z) = 0,

   which holds exactly for any two points of a sphere (their chord is perpendicular to the sum of
   the radii) and to second order on any smooth surface. For a trial ``phi`` the height ``z`` is
   the least-squares fit of these equations; ``phi`` minimises their residual plus a small
   continuity term ``|n - n_b|^2``, a tie-break that prefers the convex turn of the normal (the
   way one moves) and a one-sided penalty, ``HINGE`` times the squared shortfall, on a turn
   against it (``n_x`` falling where ``x`` grows toward a neighbour, or ``n_y`` where ``y``
   does), both flipped per axis inside the user's concave regions. The tie-break takes, per
   neighbour, the mean of the two pixels' signs: none across a region's edge, where the
   surface's inflection lies between them and neither turn is the expected one (a constant pull
   there over-turns the weakly curved surface past the edge; the vase's mouth above its marked
   neck at slant 30 degrees: 1252 pixels off by more than 10 degrees, 1214 with the mean; at
   slant 45 degrees 3.58 % depth error, 3.27 %). The penalty is zero while the turn agrees, so
   it picks one of the cone's two branches without pulling the normal. A pixel is accepted only
   once its accepted neighbours span both image directions, so the front cannot run away along
   a one-pixel path. Each cap of sources (the sources of one plateau of the height
   along ``L``: connected, or joined by a path too bright for the plateau to be off by a pixel)
   starts its own height datum, and a pixel is fitted to the neighbours of one datum only (the
   one that weighs most): where the fronts of two caps meet, neither's heights nor its drift
   reach the other's pixels (the synthetic vase under slant 30 degrees: belly and neck caps
   10 px apart along ``L``; on one datum their fronts met in a streak of wrong normals across
   the shoulder, 353 pixels off by more than 10 degrees after the polish, 9 with a datum each).
   This is in the spirit of the height-ordered local solves of Bichsel & Pentland (1992), with
   the chord equation in place of their slope rule;
2. **fills the shadows**: the normals of shadowed pixels continue those of the lit ones with the
   least change of curvature, a thin-plate (second-difference) fit of ``n_x`` and ``n_y`` with the
   lit normals fixed, then each is moved to the nearest normal with ``N . L <= 0`` where the fit
   broke the constraint, all with ``n_z >= SHADOW_NZ`` (a wrong lit normal at the shadow's edge
   then cannot extrapolate into a wall of grazing normals). The shadow is a constraint, not a dark
   intensity: no slope is read from it;
3. **polishes** by block-coordinate descent on one energy over the depth ``z`` and the cone
   azimuths of the lit pixels,

       E(z, N) = sum over 4-neighbour pairs a, b of  w_ab ((n_a + n_b) . (X_b - X_a))^2
                 + smooth * sum over pairs |n_a - n_b|^2   (lit pixels' normals only),

   with ``w_ab = 1`` between lit pixels and ``shadow_weight`` where a shadowed pixel takes part.
   For fixed normals ``E`` is a pair-weighted Poisson problem in ``z`` (solved by the project's
   multigrid-preconditioned conjugate gradients, :class:`shadeform.integration._multigrid.
   PairHierarchy`, warm-started from the last depth); for fixed ``z``, a red-black colouring makes
   the lit pixels of one colour independent, each minimising a quadratic in ``n`` over its cone,
   which is a trigonometric polynomial of degree 2 in ``phi`` (a coarse grid of trials, then
   safeguarded Newton steps). The shadowed normals are refilled after each sweep. The small
   ``smooth`` term removes the checkerboard that the pair sums cannot see and favours smooth
   surfaces over creased ones.

**Coarse to fine** [6]_. An object longer than ``coarse`` pixels (default :data:`COARSE`) is solved
first on the image halved (2x2 block means, recursively), and the full-size descent starts from
that solution's normals, interpolated and put back on their cones, for at most
:data:`REFINE_ITERATIONS` sweeps, instead of marching at full size: the marching's drift grows with
the path length and the descent moves long wavelengths slowly (sphere at 512 px with the first
marching: 1.41 % depth marched at full size, 0.22 % from the half-size start; with the present
one 0.25 % and 0.24 %, but the full-size route took 14.6 s against 3.5 s). The descent runs
numba on one thread: its many small warm-started solves lose more to thread hand-offs than they
gain, badly so on a shared machine. Speed and accuracy: ``benchmarks/results/oblique.md``
(about 1.3-1.6 s of CPU for a 256x256 image on one core, 2.6-3.5 s at 512x512).

Depth is in pixel units, ``z = 0`` at the main source (the brightest pixel). Normals of lit pixels
lie exactly on their cones (``N . L = I / k``).

Limits. Uniform albedo, one distant light, no cast shadows, no interreflections. The marching
decides the convex/concave choice once; the polish only refines within that basin, so the
convexity it assumes (convex unless marked) must hold where it decides: on unmarked concave parts
(the bumps' skirts) the hinge can push the wrong way. Where two singular points are joined by a
ridge of nearly full brightness (the synthetic vase's belly and neck under the light (5, 5, 7)),
marching nearest-first reached the neck above the saddle from the side and left it in the wrong
basin (6.2 % depth at 256 px; energy 9.6 against 0.02 from the true normals); the brightness term
of the order and the hinge bring it to 3.0 % / 2.8 degrees (energy 2.9). Noisy images need a filter
(``reconstruct(filter="gaussian:2")``) and a larger ``tol``.

``march_cone`` and ``cone_sweep`` are the compiled kernels; ``march_cone_reference`` and
``cone_sweep_reference`` are slow, plain-Python transcriptions kept for the tests.

The constants below were chosen on the synthetic sphere and vase under the light (5, 5, 7) (the
scenes of the accuracy bars), by hand and coarsely; see ``benchmarks/bench_oblique.py``.
``HINGE``, ``BRIGHTNESS`` and ``SHADOW_NZ`` were then set on the vase at (5, 5, 7) and at slant 30
degrees, checked on the other scenes: at (5, 5, 7) the vase's depth error stays within 2.7-3.5 %
for ``HINGE`` 100-1000 and ``BRIGHTNESS`` 0.08-0.16 (no hinge: 4.2 %; 10,000: 6.5 %); ``HINGE``
300 rather than 100 made the bumps worse at slant 30 degrees (58 % against 53 %); ``SHADOW_NZ``
0.15 rather than ``MIN_NZ`` (0.05) took the vase's depth error over ``BRIGHTNESS`` 0.11-0.14 from
3.4-4.5 % to 2.9-3.5 %, at the cost of the crescent's worst shadow error (7.4 % to 8.7 % of the
depth range; test ``test_shadow_is_a_constraint_not_a_cliff``). The speed constants
(``SWEEP_SAMPLES``, ``REBUILD``, ``COARSE``, ``REFINE_ITERATIONS``) were set on the same two
scenes by their time at 256 and 512 px with their errors unchanged at 256 px. ``COARSE = 320``
keeps 256 px images on the marching at full size: with the first marching the vase's depth error
rose from 6.2 % to 7.3 % when a 128 px solution started it; with this one the half-size start
gives about the same errors (vase 3.0 %, sphere 0.23 %) in about 55-60 % of the time (not yet
adopted).

References
----------
.. [1] M. Bichsel and A. P. Pentland, "A simple algorithm for shape from shading", CVPR 1992.
.. [2] B. K. P. Horn and M. J. Brooks, "The variational approach to shape from shading",
   CVGIP 33(2), 174-208, 1986 (integrability and normals as alternating unknowns).
.. [3] K. Ikeuchi and B. K. P. Horn, "Numerical shape from shading and occluding boundaries",
   Artificial Intelligence 17, 141-184, 1981 (smoothness of the normal field).
.. [4] E. Prados and O. Faugeras, "Shape from shading: a well-posed problem?", CVPR 2005
   (oblique light, singular points).
.. [5] Y. Queau, J.-D. Durou and J.-F. Aujol, "Normal integration: a survey", JMIV 60, 2018.
.. [6] B. K. P. Horn, "Height and gradient from shading", IJCV 5(1), 37-75, 1990 (coarse-to-fine
   start of the iterative scheme).
"""

from __future__ import annotations

import heapq
import numbers
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import ndimage as ndi

from shadeform._checks import StageTimer
from shadeform.errors import InputError
from shadeform.integration._multigrid import PairHierarchy
from shadeform.integration._slopes import MIN_NZ

__all__ = [
    "ObliqueResult",
    "oblique_depth",
    "march_cone",
    "march_cone_reference",
    "cone_sweep",
    "cone_sweep_reference",
    "fill_shadow_normals",
]

#: Pixels with ``I / k >= 1 - TOL`` start the marching (with ``N = L``).
TOL = 2e-3
#: Weight of ``|n - n_b|^2`` in the marching's local fit (continuity with accepted neighbours).
CONTINUITY = 0.05
#: Weight of the convex (or marked concave) turn of the normal in the marching's local fit.
CONVEXITY = 0.03
#: Weight of the one-sided penalty on a turn of the normal against the convexity (the marked
#: one inside the concave regions, convex elsewhere) in the marching's local fit: zero while the
#: turn agrees, so it decides between the two branches without pulling either.
HINGE = 100.0
#: The marching's order: distance to the nearest source plus this many object lengths per unit
#: of darkening ``1 - I / k``, so the front runs along ridges of near-full brightness first.
BRIGHTNESS = 0.12
#: Weight of ``|n_a - n_b|^2`` between lit neighbours in the polished energy.
SMOOTH = 0.1
#: Weight of the chord equations in which a shadowed pixel takes part.
SHADOW_WEIGHT = 1e-2
#: Filled shadow normals keep ``n_z >= SHADOW_NZ``.
SHADOW_NZ = 0.15
#: Block-coordinate descent sweeps at most, and the relative energy change that stops them.
ITERATIONS = 30
STOP = 1e-4
#: CG iterations of a depth block past which the multigrid preconditioner is rebuilt.
REBUILD = 10
#: Lit normals keep ``n_z >= VISIBLE_NZ`` (they face the camera).
VISIBLE_NZ = 0.02
#: Trial azimuths per pixel before the golden-section refinement (marching).
SAMPLES = 72
#: Trial azimuths per pixel before the Newton refinement (descent): its cost on the cone is a
#: trigonometric polynomial of degree 2, with at most two minima, so a coarser grid suffices.
SWEEP_SAMPLES = 24
#: Objects longer than this (pixels) are first solved at half size (coarse to fine).
COARSE = 320
#: Descent sweeps at most at a size that starts from the half-size solution.
REFINE_ITERATIONS = 10

_GOLDEN = 0.3819660112501051
_GOLDEN_STEPS = 24
_NEWTON_STEPS = 8


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ObliqueResult:
    """Shape from the oblique-light solver.

    Attributes
    ----------
    depth : (H, W) float64
        Height z in pixel units, NaN outside the mask, ``z = 0`` at ``main``.
    normals : (H, W, 3) float64
        Unit normals, NaN outside the mask; on their shading cones where lit, with
        ``N . L <= 0`` where shadowed.
    lit : (H, W) bool
        Pixels read as lit (``I / k > dark``); the others are the shadow.
    main : (int, int)
        ``(row, col)`` of the main source (the brightest pixel), where ``z = 0``.
    info : dict
        ``sources`` (the pixels that start the marching at this size), ``levels`` (sizes solved:
        1, or more when the coarse-to-fine start was used, the marching then ran at the smallest),
        ``sweeps`` (descent sweeps done at this size), ``energy`` (per sweep), ``unreached`` (lit
        pixels the marching did not reach, filled like the shadow) and ``timings`` (seconds per
        stage).
    """

    depth: np.ndarray
    normals: np.ndarray
    lit: np.ndarray
    main: tuple[int, int]
    info: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------------------------
# Cone geometry
# --------------------------------------------------------------------------------------------


def _cone_frame(light: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors ``e1, e2`` perpendicular to ``light``; ``e1`` leans toward the viewer (+z)."""
    up = np.array([0.0, 0.0, 1.0]) - light[2] * light
    length = np.linalg.norm(up)
    e1 = up / length if length > 1e-9 else np.array([1.0, 0.0, 0.0])
    return e1, np.cross(light, e1)


def _azimuth_limits(cos_theta: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Largest ``|phi|`` with ``n_z >= VISIBLE_NZ`` on each cone (pi: the whole cone is visible).

    On the cone ``n = c L + s (cos phi e1 + sin phi e2)``, ``n_z = c L_z + s sin(slant) cos phi``.
    """
    sin_slant = np.sqrt(max(1.0 - light[2] ** 2, 0.0))
    if sin_slant < 1e-9:
        return np.full(cos_theta.shape, np.pi)
    s = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        lowest = (VISIBLE_NZ - cos_theta * light[2]) / (s * sin_slant)
    return np.arccos(np.clip(np.nan_to_num(lowest, nan=-1.0), -1.0, 1.0))


def _azimuth(normals: np.ndarray, light: np.ndarray) -> np.ndarray:
    e1, e2 = _cone_frame(light)
    return np.arctan2(normals @ e2, normals @ e1)


def _on_cone(cos_theta: np.ndarray, phi: np.ndarray, light: np.ndarray) -> np.ndarray:
    e1, e2 = _cone_frame(light)
    s = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, 1.0))
    return (cos_theta[..., None] * light
            + s[..., None] * (np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2))


# --------------------------------------------------------------------------------------------
# Step 1: the marching (compiled kernel, then the plain-Python reference)
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _heap_push(keys, items, size, key, item):
    """Push onto the binary min-heap ``keys``/``items`` of length ``size``; return the new size."""
    i = size
    while i > 0:
        parent = (i - 1) // 2
        if keys[parent] < key or (keys[parent] == key and items[parent] <= item):
            break
        keys[i] = keys[parent]
        items[i] = items[parent]
        i = parent
    keys[i] = key
    items[i] = item
    return size + 1


@numba.njit(cache=True)
def _heap_pop(keys, items, size):
    """Pop the smallest ``(key, item)`` (ties: smallest item); return it and the new size."""
    key = keys[0]
    item = items[0]
    size -= 1
    last_key = keys[size]
    last_item = items[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and (keys[right] < keys[child]
                             or (keys[right] == keys[child] and items[right] < items[child])):
            child = right
        if keys[child] > last_key or (keys[child] == last_key and items[child] >= last_item):
            break
        keys[i] = keys[child]
        items[i] = items[child]
        i = child
    if size > 0:
        keys[i] = last_key
        items[i] = last_item
    return key, item, size


@numba.njit(cache=True)
def _gather(r, c, z, normals, done, datum, convex_x, convex_y, kappa, nb, db, zb, wb, lb,
            prefer):
    """Accepted 8-neighbours of ``(r, c)``: normals, displacements ``(dx, dy)`` to them, heights,
    weights ``1 / |d|^2`` and height datums ``lb``; ``prefer`` the convexity tie-break direction,
    each neighbour's term with the mean of its and the pixel's convexity sign (0 across the edge
    of a concave region).
    Returns ``(count, spans)``, ``spans`` when the displacements span the image plane."""
    height, width = z.shape
    count = 0
    prefer[0] = 0.0
    prefer[1] = 0.0
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            rb = r + dr
            cb = c + dc
            if (dr == 0 and dc == 0) or rb < 0 or rb >= height or cb < 0 or cb >= width \
                    or not done[rb, cb]:
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
def _fit_pixel(r, c, z, normals, done, datum, cos_theta, limits, light, e1, e2, convex_x,
               convex_y, gamma, kappa, hinge, samples, work, labels, out):
    """The marching's local fit at ``(r, c)``: ``out = (n_x, n_y, n_z, z, phi, datum)``.

    Heights are relative to the source cap each front started from (its datum): separate caps
    of ``N = L`` need not lie at one height along ``L``. The pixel takes the datum that weighs
    most among its accepted neighbours (ties: the lower one) and is fitted to those neighbours
    only; where two fronts meet, the other front's pixels take no part (their heights are on
    another datum, and their normals carry that front's own drift)."""
    nb, db, zb, wb, prefer, a0, a1, a2, tmp = work
    count, _ = _gather(r, c, z, normals, done, datum, convex_x, convex_y, kappa, nb, db, zb, wb,
                       labels, prefer)
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
    cos_t = cos_theta[r, c]
    s = np.sqrt(max(1.0 - cos_t * cos_t, 0.0))
    for i in range(3):
        a0[i] = cos_t * light[i]
        a1[i] = s * e1[i]
        a2[i] = s * e2[i]
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
        cost1 = _local_cost(m1, a0, a1, a2, nb, db, zb, wb, count, gamma, prefer, hinge, cx, cy,
                            tmp)
        cost2 = _local_cost(m2, a0, a1, a2, nb, db, zb, wb, count, gamma, prefer, hinge, cx, cy,
                            tmp)
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
def _march_kernel(cos_theta, lit, limits, light, e1, e2, convex_x, convex_y, sources, source_z,
                  source_datum, gamma, kappa, hinge, samples, distance, z, normals, phi, done,
                  datum, keys, items):
    # work arrays of the local fit
    work = (np.empty((8, 3)), np.empty((8, 2)), np.empty(8), np.empty(8), np.empty(2),
            np.empty(3), np.empty(3), np.empty(3), np.empty(1))
    labels = np.empty(8, np.int64)
    out = np.empty(6)
    height, width = z.shape
    is_source = np.zeros(z.shape, np.bool_)
    size = 0
    for s in range(sources.shape[0]):
        r = sources[s, 0]
        c = sources[s, 1]
        is_source[r, c] = True
        size = _heap_push(keys, items, size, -1.0, r * width + c)
    while size > 0:
        _, item, size = _heap_pop(keys, items, size)
        r = item // width
        c = item % width
        if done[r, c]:
            continue
        if is_source[r, c]:
            for i in range(3):
                normals[r, c, i] = light[i]
            z[r, c] = source_z[r, c]
            phi[r, c] = 0.0
            datum[r, c] = source_datum[r, c]
        else:
            _fit_pixel(r, c, z, normals, done, datum, cos_theta, limits, light, e1, e2, convex_x,
                       convex_y, gamma, kappa, hinge, samples, work, labels, out)
            for i in range(3):
                normals[r, c, i] = out[i]
            z[r, c] = out[3]
            phi[r, c] = out[4]
            datum[r, c] = int(out[5])
        done[r, c] = True
        nb, db, zb, wb, prefer = work[0], work[1], work[2], work[3], work[4]
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr = r + dr
                cc = c + dc
                if rr < 0 or rr >= height or cc < 0 or cc >= width or not lit[rr, cc] \
                        or done[rr, cc]:
                    continue
                _, spans = _gather(rr, cc, z, normals, done, datum, convex_x, convex_y, 0.0, nb,
                                   db, zb, wb, labels, prefer)
                # one-pixel paths wait for support in both directions (next to a source: not)
                if spans or is_source[r, c]:
                    size = _heap_push(keys, items, size, distance[rr, cc], rr * width + cc)


def _march_setup(cos_theta, lit, light, sources, concave_x, concave_y, brightness):
    cos_theta = np.ascontiguousarray(cos_theta, dtype=np.float64)
    lit = np.ascontiguousarray(lit, dtype=bool)
    light = np.asarray(light, dtype=np.float64)
    sources = np.ascontiguousarray(np.asarray(sources, dtype=np.int64).reshape(-1, 2))
    e1, e2 = _cone_frame(light)
    limits = _azimuth_limits(cos_theta, light)
    shape = cos_theta.shape
    convex_x = np.where(concave_x, -1.0, 1.0) if concave_x is not None else np.ones(shape)
    convex_y = np.where(concave_y, -1.0, 1.0) if concave_y is not None else np.ones(shape)
    seeds = np.zeros(shape, dtype=bool)
    seeds[sources[:, 0], sources[:, 1]] = True
    # order: distance to the nearest source, plus the darkening in units of the object's length
    # so that ridges of near-full brightness (where the azimuth is weakly determined) are
    # crossed from their crest, each side taking its convex turn against the crest's normals
    distance = ndi.distance_transform_edt(~seeds)
    if lit.any():
        rows_lit = np.flatnonzero(lit.any(axis=1))
        cols_lit = np.flatnonzero(lit.any(axis=0))
        length = max(rows_lit[-1] - rows_lit[0], cols_lit[-1] - cols_lit[0]) + 1
        distance = distance + float(brightness) * length * (1.0 - cos_theta)
    # the sources of one cap lie on one plateau of the height along L (N = L there), so their
    # heights follow from their positions; separate caps are at unknown heights along L from
    # each other, so each starts its own datum (_caps)
    r0, c0 = sources[0]
    rows, cols = np.indices(shape)
    source_z = -(light[0] * (cols - c0) - light[1] * (rows - r0)) / light[2]
    source_datum = _caps(seeds, cos_theta, lit)
    return (cos_theta, lit, light, sources, e1, e2, limits, convex_x, convex_y, distance,
            source_z, source_datum)


@numba.njit(cache=True)
def _cap_merges(order, values, group, lit, reach):
    """Merge tree of the lit pixels by brightness (brightest first, 8-neighbours): when two
    parts holding groups ``i`` and ``j`` of sources first meet, at a pixel of value ``v``, the
    groups are joined if ``reach[i, j] * sqrt(2 d - d^2) < 1`` with ``d = 1 - v``. ``group``
    is 0 or the group (1-62) of each pixel; ``order`` the lit pixels' flat indices, brightest
    first, and ``values`` their brightness. Returns the group-level parents."""
    height, width = lit.shape
    parent = np.arange(height * width)
    seen = np.zeros(height * width, np.bool_)
    bits = np.zeros(height * width, np.int64)
    groups = reach.shape[0]
    joined = np.arange(groups)
    for k in range(order.shape[0]):
        p = order[k]
        v = values[k]
        r = p // width
        c = p % width
        seen[p] = True
        if group[r, c] > 0:
            bits[p] = np.int64(1) << np.int64(group[r, c])
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr = r + dr
                cc = c + dc
                if (dr == 0 and dc == 0) or rr < 0 or rr >= height or cc < 0 or cc >= width \
                        or not seen[rr * width + cc]:
                    continue
                # a neighbour already visited, so at least as bright as this pixel
                q = rr * width + cc
                a = p
                while parent[a] != a:
                    parent[a] = parent[parent[a]]
                    a = parent[a]
                b = q
                while parent[b] != b:
                    parent[b] = parent[parent[b]]
                    b = parent[b]
                if a == b:
                    continue
                d = min(max(1.0 - v, 0.0), 1.0)
                rise = np.sqrt(2.0 * d - d * d)
                for i in range(1, groups):
                    if (bits[a] >> np.int64(i)) & 1 == 0:
                        continue
                    for j in range(1, groups):
                        if i != j and (bits[b] >> np.int64(j)) & 1 == 1 \
                                and reach[i, j] * rise < 1.0:
                            x = i
                            while joined[x] != x:
                                x = joined[x]
                            y = j
                            while joined[y] != y:
                                y = joined[y]
                            if x != y:
                                joined[max(x, y)] = min(x, y)
                parent[b] = a
                bits[a] |= bits[b]
    return joined


def _caps(seeds, cos_theta, lit) -> np.ndarray:
    """Label the sources by cap of ``N = L``, one height datum each (0 elsewhere).

    Connected sources lie on one plateau of the height along ``L``. Two separate groups do too
    when that plateau cannot be wrong by a pixel between them: on a path over which the
    brightness stays above ``1 - d`` the normal stays within ``acos(1 - d)`` of ``L``, so the
    height along ``L`` changes by at most ``D sqrt(2 d - d^2)`` over a distance ``D``. Under a
    pixel (noise splitting one cap: groups 5-10 px apart, ``d`` about 0.003) they are merged;
    the vase's neck and belly (53 px apart, ``d`` = 0.021 at slant 30 degrees: up to 11 px, in
    fact 10) keep their own datums.
    """
    from scipy.spatial import cKDTree

    labels, count = ndi.label(seeds, structure=np.ones((3, 3), dtype=bool))
    if count > 62:
        # more groups than the merge tree's 63 bits hold: one datum, as for a single cap
        return seeds.astype(np.int64)
    if count < 2:
        return labels.astype(np.int64)
    where = [np.argwhere(labels == i) for i in range(1, count + 1)]
    reach = np.zeros((count + 1, count + 1))
    for i in range(count):
        tree = cKDTree(where[i])
        for j in range(i + 1, count):
            reach[i + 1, j + 1] = reach[j + 1, i + 1] = tree.query(where[j])[0].min()
    flat = np.flatnonzero(lit.ravel())
    values = cos_theta.ravel()[flat]
    rank = np.argsort(-values, kind="stable")
    joined = _cap_merges(flat[rank].astype(np.int64), values[rank],
                         labels.astype(np.int64), np.ascontiguousarray(lit), reach)
    roots = np.zeros(count + 1, dtype=np.int64)
    for i in range(1, count + 1):
        x = i
        while joined[x] != x:
            x = joined[x]
        roots[i] = x
    return roots[labels]


def march_cone(cos_theta, lit, *, light, sources, concave_x=None, concave_y=None,
               continuity=CONTINUITY, convexity=CONVEXITY, hinge=HINGE, brightness=BRIGHTNESS,
               samples=SAMPLES):
    """Normals and heights of the lit pixels by marching from the sources (compiled).

    Parameters
    ----------
    cos_theta : (H, W) float
        ``I / k`` in [0, 1].
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
        Object lengths added to a pixel's place in the marching order per unit of ``1 - I / k``.
    samples : int
        Trial azimuths per pixel (>= 3) before golden-section refinement.

    Returns
    -------
    normals : (H, W, 3) float64
        NaN where not reached.
    depth : (H, W) float64
        NaN where not reached.
    """
    (cos_theta, lit, light, sources, e1, e2, limits, convex_x, convex_y, distance, source_z,
     source_datum) = _march_setup(cos_theta, lit, light, sources, concave_x, concave_y, brightness)
    shape = cos_theta.shape
    z = np.full(shape, np.nan)
    normals = np.full(shape + (3,), np.nan)
    phi = np.zeros(shape)
    done = np.zeros(shape, dtype=bool)
    datum = np.full(shape, -1, dtype=np.int64)
    capacity = 9 * cos_theta.size + len(sources) + 1
    keys = np.empty(capacity)
    items = np.empty(capacity, dtype=np.int64)
    _march_kernel(cos_theta, lit, limits, light, e1, e2, convex_x, convex_y, sources, source_z,
                  source_datum, float(continuity), float(convexity), float(hinge), int(samples),
                  distance, z, normals, phi, done, datum, keys, items)
    return normals, z


def march_cone_reference(cos_theta, lit, *, light, sources, concave_x=None, concave_y=None,
                         continuity=CONTINUITY, convexity=CONVEXITY, hinge=HINGE,
                         brightness=BRIGHTNESS, samples=SAMPLES):
    """Slow, plain-Python version of :func:`march_cone` (same arguments and result).

    ``heapq`` for the queue and the local fit evaluated by the uncompiled functions; for the
    tests, on small images.
    """
    (cos_theta, lit, light, sources, e1, e2, limits, convex_x, convex_y, distance, source_z,
     source_datum) = _march_setup(cos_theta, lit, light, sources, concave_x, concave_y, brightness)
    height, width = cos_theta.shape
    z = np.full((height, width), np.nan)
    normals = np.full((height, width, 3), np.nan)
    phi = np.zeros((height, width))
    done = np.zeros((height, width), dtype=bool)
    datum = np.full((height, width), -1, dtype=np.int64)
    work = (np.empty((8, 3)), np.empty((8, 2)), np.empty(8), np.empty(8), np.empty(2),
            np.empty(3), np.empty(3), np.empty(3), np.empty(1))
    labels = np.empty(8, dtype=np.int64)
    out = np.empty(6)
    is_source = set()
    queue = []
    for r, c in sources:
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
            normals[r, c] = light
            z[r, c] = source_z[r, c]
            datum[r, c] = source_datum[r, c]
        else:
            fit(r, c, z, normals, done, datum, cos_theta, limits, light, e1, e2, convex_x,
                convex_y, float(continuity), float(convexity), float(hinge), int(samples), work,
                labels, out)
            normals[r, c] = out[:3]
            z[r, c] = out[3]
            phi[r, c] = out[4]
            datum[r, c] = int(out[5])
        done[r, c] = True
        for rr in range(r - 1, r + 2):
            for cc in range(c - 1, c + 2):
                if not (0 <= rr < height and 0 <= cc < width) or not lit[rr, cc] or done[rr, cc]:
                    continue
                _, spans = gather(rr, cc, z, normals, done, datum, convex_x, convex_y, 0.0,
                                  *work[:4], labels, work[4])
                if spans or (r, c) in is_source:
                    heapq.heappush(queue, (float(distance[rr, cc]), rr * width + cc))
    return normals, z


# --------------------------------------------------------------------------------------------
# Step 2: the shadow fill
# --------------------------------------------------------------------------------------------


def _second_differences(mask: np.ndarray) -> sp.csr_matrix:
    """Thin-plate second differences over the mask (xx, yy and sqrt(2) xy, where the stencil
    fits), as a sparse matrix on the mask's pixels in row-major order."""
    index = np.full(mask.shape, -1, dtype=np.int64)
    n = int(mask.sum())
    index[mask] = np.arange(n)
    blocks = []
    for stencil in (((0, 0, 1.0), (0, 1, -2.0), (0, 2, 1.0)),
                    ((0, 0, 1.0), (1, 0, -2.0), (2, 0, 1.0)),
                    ((0, 0, np.sqrt(2)), (0, 1, -np.sqrt(2)), (1, 0, -np.sqrt(2)),
                     (1, 1, np.sqrt(2)))):
        span_r = max(dr for dr, _, _ in stencil)
        span_c = max(dc for _, dc, _ in stencil)
        height, width = mask.shape[0] - span_r, mask.shape[1] - span_c
        fits = np.ones((height, width), dtype=bool)
        for dr, dc, _ in stencil:
            fits &= mask[dr:dr + height, dc:dc + width]
        rows, cols = np.nonzero(fits)
        eq = np.arange(len(rows))
        data = np.concatenate([np.full(len(rows), v) for _, _, v in stencil])
        where = np.concatenate([index[rows + dr, cols + dc] for dr, dc, _ in stencil])
        blocks.append(sp.csr_matrix((data, (np.tile(eq, len(stencil)), where)),
                                    shape=(len(rows), n)))
    return sp.vstack(blocks).tocsr()


class _ShadowFill:
    """Thin-plate continuation of ``(n_x, n_y)`` into the shadow, factorised once per mask."""

    def __init__(self, mask: np.ndarray, shadow: np.ndarray):
        self.mask = mask
        self.free = shadow[mask]
        self.solve = None
        if self.free.any():
            D = _second_differences(mask)
            self.free_part = D[:, self.free]
            self.known_part = D[:, ~self.free]
            system = (self.free_part.T @ self.free_part).tocsc()
            # a shadowed pixel no stencil reaches would make the system singular: a tiny ridge
            system = system + sp.identity(system.shape[0], format="csc") * 1e-9
            self.solve = spla.splu(system).solve

    def __call__(self, normals: np.ndarray, light: np.ndarray) -> np.ndarray:
        if self.solve is None:
            return normals
        values = normals[self.mask]
        free = self.free
        filled = np.empty((int(free.sum()), 3))
        for axis in (0, 1):
            rhs = -(self.free_part.T @ (self.known_part @ values[~free, axis]))
            filled[:, axis] = self.solve(rhs)
        filled = _visible(filled, SHADOW_NZ)
        # the constraint N . L <= 0: a filled normal that faces the light goes to the nearest
        # one on the terminator
        facing = filled @ light
        bad = facing > 0
        if bad.any():
            moved = filled[bad] - facing[bad, None] * light
            length = np.linalg.norm(moved, axis=1, keepdims=True)
            moved = np.where(length > 1e-12, moved / np.maximum(length, 1e-12), filled[bad])
            filled[bad] = _visible(moved, SHADOW_NZ)
            filled[bad] -= np.maximum(filled[bad] @ light, 0.0)[:, None] * light
            filled[bad] /= np.linalg.norm(filled[bad], axis=1, keepdims=True)
        out = normals.copy()
        values[free] = filled
        out[self.mask] = values
        return out


def _visible(normals: np.ndarray, min_nz: float = MIN_NZ) -> np.ndarray:
    """Unit normals from their ``(n_x, n_y)``, with ``|(n_x, n_y)|`` capped so ``n_z >= min_nz``."""
    xy = normals[:, :2]
    length = np.linalg.norm(xy, axis=1)
    cap = np.sqrt(1.0 - min_nz**2)
    xy = xy * np.minimum(1.0, cap / np.maximum(length, 1e-12))[:, None]
    return np.column_stack([xy, np.sqrt(np.maximum(1.0 - (xy * xy).sum(axis=1), 0.0))])


def fill_shadow_normals(normals, mask, shadow, *, light):
    """Continue a normal field into the shadow with the least change of curvature.

    The ``(n_x, n_y)`` of the shadowed pixels minimise the thin-plate energy (squared second
    differences ``xx``, ``yy``, ``xy`` over the mask) with the other pixels' normals fixed; a
    linear normal field (a sphere, a cylinder) continues exactly. Each filled normal is then made
    visible (``n_z >= MIN_NZ``) and, where it faces the light, moved to the nearest normal with
    ``N . L = 0``, so the shadow stays a shadow.

    Parameters
    ----------
    normals : (H, W, 3) float
        Finite on ``mask & ~shadow``.
    mask, shadow : (H, W) bool
    light : (3,) float

    Returns
    -------
    (H, W, 3) float64
        ``normals`` with the shadowed pixels replaced.

    References
    ----------
    .. [1] K. Ikeuchi and B. K. P. Horn, "Numerical shape from shading and occluding
       boundaries", Artificial Intelligence 17, 1981.
    """
    mask = np.asarray(mask, dtype=bool)
    shadow = np.asarray(shadow, dtype=bool) & mask
    light = np.asarray(light, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    return _ShadowFill(mask, shadow)(np.where(mask[..., None], normals, np.nan), light)


# --------------------------------------------------------------------------------------------
# Step 3: block-coordinate descent
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _trig_cost(t, coef):
    """``coef[0] cos t + coef[1] sin t + coef[2] cos 2t + coef[3] sin 2t`` and its first two
    derivatives."""
    c = np.cos(t)
    s = np.sin(t)
    c2 = 2.0 * c * c - 1.0
    s2 = 2.0 * s * c
    value = coef[0] * c + coef[1] * s + coef[2] * c2 + coef[3] * s2
    slope = -coef[0] * s + coef[1] * c - 2.0 * coef[2] * s2 + 2.0 * coef[3] * c2
    bend = -coef[0] * c - coef[1] * s - 4.0 * coef[2] * c2 - 4.0 * coef[3] * s2
    return value, slope, bend


@numba.njit(cache=True)
def _cone_coefficients(a0, a1, a2, M, g, coef):
    """The quadratic ``n^T M n + 2 g . n`` on the cone ``n = a0 + a1 cos t + a2 sin t`` is, up to
    a constant, ``coef . (cos t, sin t, cos 2t, sin 2t)`` (cos^2 = (1 + cos 2t) / 2, ...)."""
    a1Ma0 = 0.0
    a2Ma0 = 0.0
    a1Ma1 = 0.0
    a2Ma2 = 0.0
    a1Ma2 = 0.0
    for i in range(3):
        for j in range(3):
            a1Ma0 += a1[i] * M[i, j] * a0[j]
            a2Ma0 += a2[i] * M[i, j] * a0[j]
            a1Ma1 += a1[i] * M[i, j] * a1[j]
            a2Ma2 += a2[i] * M[i, j] * a2[j]
            a1Ma2 += a1[i] * M[i, j] * a2[j]
    coef[0] = 2.0 * (a1Ma0 + g[0] * a1[0] + g[1] * a1[1] + g[2] * a1[2])
    coef[1] = 2.0 * (a2Ma0 + g[0] * a2[0] + g[1] * a2[1] + g[2] * a2[2])
    coef[2] = 0.5 * (a1Ma1 - a2Ma2)
    coef[3] = a1Ma2  # M is symmetric


@numba.njit(cache=True)
def _cone_minimum(coef, limit, current, samples):
    """Azimuth in ``[-limit, limit]`` minimising the trigonometric cost ``coef``: the best of
    ``samples`` evenly spaced trials, refined by Newton steps kept inside the trial's bracket;
    ``current`` is kept unless beaten (so a sweep never raises the energy)."""
    step = 2.0 * limit / (samples - 1)
    # the trial grid by rotation: one sine and cosine for all of it
    cd = np.cos(step)
    sd = np.sin(step)
    c = np.cos(-limit)
    s = np.sin(-limit)
    found = -limit
    found_cost = np.inf
    for j in range(samples):
        cost = coef[0] * c + coef[1] * s + coef[2] * (2.0 * c * c - 1.0) + coef[3] * (2.0 * s * c)
        if cost < found_cost:
            found_cost = cost
            found = -limit + step * j
        c, s = c * cd - s * sd, s * cd + c * sd
    lo = max(found - step, -limit)
    hi = min(found + step, limit)
    t = found
    for _ in range(_NEWTON_STEPS):
        _, slope, bend = _trig_cost(t, coef)
        if bend > 0.0:
            trial = t - slope / bend
        else:  # not convex here: move to the bracket's end the slope points to
            trial = lo if slope > 0.0 else hi
        trial = min(max(trial, lo), hi)
        if abs(trial - t) < 1e-13:
            t = trial
            break
        t = trial
    cost, _, _ = _trig_cost(t, coef)
    if cost < found_cost:
        found = t
        found_cost = cost
    kept, _, _ = _trig_cost(current, coef)
    return current if kept <= found_cost else found


@numba.njit(cache=True)
def _sweep_pixel(r, c, z, normals, wx, wy, smooth, M, g, v):
    """The quadratic ``n^T M n + 2 g . n`` that pixel ``(r, c)``'s normal minimises."""
    height, width = z.shape
    M[:, :] = 0.0
    g[:] = 0.0
    for k in range(4):
        if k == 0:
            rb, cb = r, c + 1
            weight = wx[r, c] if cb < width else 0.0
        elif k == 1:
            rb, cb = r, c - 1
            weight = wx[r, c - 1] if cb >= 0 else 0.0
        elif k == 2:
            rb, cb = r + 1, c
            weight = wy[r, c] if rb < height else 0.0
        else:
            rb, cb = r - 1, c
            weight = wy[r - 1, c] if rb >= 0 else 0.0
        if weight <= 0.0:
            continue
        # chord from this pixel to b: (dx, dy, dz), y up
        v[0] = float(cb - c)
        v[1] = float(r - rb)
        v[2] = z[rb, cb] - z[r, c]
        along = v[0] * normals[rb, cb, 0] + v[1] * normals[rb, cb, 1] + v[2] * normals[rb, cb, 2]
        for i in range(3):
            g[i] += weight * (v[i] * along - smooth * normals[rb, cb, i])
            for j in range(3):
                M[i, j] += weight * v[i] * v[j]


@numba.njit(cache=True)
def _sweep_kernel(z, normals, lit, wx, wy, cos_theta, limits, phi, light, e1, e2, smooth,
                  samples, colour):
    height, width = z.shape
    M = np.empty((3, 3))
    g = np.empty(3)
    v = np.empty(3)
    a0 = np.empty(3)
    a1 = np.empty(3)
    a2 = np.empty(3)
    coef = np.empty(4)
    for r in range(height):
        for c in range(width):
            if not lit[r, c] or (r + c) % 2 != colour:
                continue
            _sweep_pixel(r, c, z, normals, wx, wy, smooth, M, g, v)
            cos_t = cos_theta[r, c]
            s = np.sqrt(max(1.0 - cos_t * cos_t, 0.0))
            for i in range(3):
                a0[i] = cos_t * light[i]
                a1[i] = s * e1[i]
                a2[i] = s * e2[i]
            limit = limits[r, c]
            _cone_coefficients(a0, a1, a2, M, g, coef)
            best = _cone_minimum(coef, limit, min(max(phi[r, c], -limit), limit), samples)
            phi[r, c] = best
            cp = np.cos(best)
            sp_ = np.sin(best)
            for i in range(3):
                normals[r, c, i] = a0[i] + a1[i] * cp + a2[i] * sp_


def _sweep_setup(cos_theta, light):
    light = np.asarray(light, dtype=np.float64)
    e1, e2 = _cone_frame(light)
    return light, e1, e2, _azimuth_limits(np.asarray(cos_theta, dtype=np.float64), light)


def cone_sweep(z, normals, lit, wx, wy, cos_theta, *, light, smooth=SMOOTH,
               samples=SWEEP_SAMPLES):
    """One red-black sweep of the normal block of the descent (compiled), in place.

    Every lit pixel of one colour, then of the other, takes the azimuth on its cone that
    minimises its part of the energy (module docstring) with its neighbours fixed; it keeps its
    current one unless that is beaten. That part is a quadratic ``n^T M n + 2 g . n`` in the
    normal, so on the cone a trigonometric polynomial of degree 2 in the azimuth: its four
    coefficients are formed once per pixel, its minimum bracketed on ``samples`` trials (by
    rotation, one sine and cosine for all) and polished by safeguarded Newton steps.

    Parameters
    ----------
    z : (h, w) float
        Heights (finite on the object; 0 elsewhere).
    normals : (h, w, 3) float, C-contiguous
        Unit normals (0 off the object); the lit ones are updated in place.
    lit : (h, w) bool
    wx, wy : (h, w) float
        Weights of the pairs ``(r, c)-(r, c + 1)`` and ``(r, c)-(r + 1, c)``; 0 where a pixel of
        the pair is off the object.
    cos_theta : (h, w) float
        ``I / k``.
    light : (3,) float
    smooth : float
    samples : int
        Trial azimuths per pixel (>= 3) before the Newton refinement.

    Returns
    -------
    normals : (h, w, 3) float64
        The same array, updated.
    """
    light, e1, e2, limits = _sweep_setup(cos_theta, light)
    phi = np.where(lit, _azimuth(np.nan_to_num(normals), light), 0.0)
    for colour in (0, 1):
        _sweep_kernel(z, normals, lit, wx, wy, cos_theta, limits, phi, light, e1, e2,
                      float(smooth), int(samples), colour)
    return normals


def cone_sweep_reference(z, normals, lit, wx, wy, cos_theta, *, light, smooth=SMOOTH,
                         samples=SWEEP_SAMPLES):
    """Slow version of :func:`cone_sweep`: the same sweep, written out in numpy per pixel.

    Each pixel's quadratic is assembled from its pairs with numpy, and its minimum taken over a
    fine grid of ``4096`` azimuths (no golden section); for the tests, on small images.
    """
    light, e1, e2, limits = _sweep_setup(cos_theta, light)
    height, width = z.shape
    for colour in (0, 1):
        for r in range(height):
            for c in range(width):
                if not lit[r, c] or (r + c) % 2 != colour:
                    continue
                M = np.zeros((3, 3))
                g = np.zeros(3)
                pairs = ((r, c + 1, wx[r, c] if c + 1 < width else 0.0),
                         (r, c - 1, wx[r, c - 1] if c > 0 else 0.0),
                         (r + 1, c, wy[r, c] if r + 1 < height else 0.0),
                         (r - 1, c, wy[r - 1, c] if r > 0 else 0.0))
                for rb, cb, weight in pairs:
                    if weight <= 0:
                        continue
                    chord = np.array([cb - c, r - rb, z[rb, cb] - z[r, c]], dtype=np.float64)
                    M += weight * np.outer(chord, chord)
                    g += weight * (chord * (chord @ normals[rb, cb]) - smooth * normals[rb, cb])
                limit = limits[r, c]
                current = np.clip(_azimuth(normals[r, c], light), -limit, limit)
                trial = np.append(np.linspace(-limit, limit, 4096), current)
                candidates = _on_cone(np.full(trial.shape, cos_theta[r, c]), trial, light)
                costs = np.einsum("pi,ij,pj->p", candidates, M, candidates) + 2 * candidates @ g
                normals[r, c] = candidates[np.argmin(costs)]
    return normals


@contextmanager
def _serial():
    """Numba's parallel kernels on one thread for the duration (the setting is per thread).

    The descent's depth blocks are many small warm-started solves (a few CG iterations each, about
    10 ms at 256x256 on one core); spread over threads on a shared machine each one waited tens
    of times longer for the others than it computed (measured: 0.4 s instead of 0.01 s).
    """
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)


class _Descent:
    """The energy of the module docstring on the mask's bounding box, and its two blocks."""

    def __init__(self, mask, cos_theta, lit, light, shadow_weight, smooth):
        rows = np.flatnonzero(mask.any(axis=1))
        cols = np.flatnonzero(mask.any(axis=0))
        self.box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
        self.mask = np.ascontiguousarray(mask[self.box])
        self.cos_theta = np.ascontiguousarray(cos_theta[self.box])
        self.lit = np.ascontiguousarray(lit[self.box] & self.mask)
        self.light = light
        self.smooth = smooth
        pixel = np.where(self.lit, 1.0, shadow_weight) * self.mask
        self.wx = np.zeros(self.mask.shape)
        self.wx[:, :-1] = np.minimum(pixel[:, :-1], pixel[:, 1:]) * self.mask[:, :-1] * self.mask[:, 1:]
        self.wy = np.zeros(self.mask.shape)
        self.wy[:-1] = np.minimum(pixel[:-1], pixel[1:]) * self.mask[:-1] * self.mask[1:]
        self.hierarchy = None

    def _pair_sums(self, normals):
        sx = np.zeros(normals.shape)
        sy = np.zeros(normals.shape)
        sx[:, :-1] = normals[:, :-1] + normals[:, 1:]
        sy[:-1] = normals[:-1] + normals[1:]
        return sx, sy

    def energy(self, z, normals) -> float:
        sx, sy = self._pair_sums(normals)
        dx = np.zeros(z.shape)
        dy = np.zeros(z.shape)
        dx[:, :-1] = z[:, 1:] - z[:, :-1]
        dy[:-1] = z[1:] - z[:-1]
        # chords (1, 0, dz) to the right and (0, -1, dz) down
        rx = sx[..., 0] + sx[..., 2] * dx
        ry = -sy[..., 1] + sy[..., 2] * dy
        return float(np.sum(self.wx * rx * rx) + np.sum(self.wy * ry * ry))

    def depth(self, normals, z0, *, tol):
        """The depth block: a pair-weighted Poisson problem, warm-started from ``z0``."""
        sx, sy = self._pair_sums(normals)
        # pairs of two nearly grazing normals would have no weight at all: floor n_a + n_b's z
        szx = np.maximum(sx[..., 2], 2 * MIN_NZ)
        szy = np.maximum(sy[..., 2], 2 * MIN_NZ)
        px = self.wx * szx**2
        py = self.wy * szy**2
        gx = self.wx * (-sx[..., 0] * szx)   # weight times the step dz = -s_x / s_z (right)
        gy = self.wy * (sy[..., 1] * szy)    # weight times the step dz = s_y / s_z (down)
        b = -gx - gy
        b[:, 1:] += gx[:, :-1]
        b[1:] += gy[:-1]
        if self.hierarchy is None:
            self.hierarchy = PairHierarchy(self.mask, px, py)
        z, iterations, _ = self.hierarchy.solve_pairs(b, z0, px=px, py=py, tol=tol, maxiter=500,
                                                      from_start=True)
        # the weights have drifted from the preconditioner's: a new one, built when the next
        # solve needs it (none after the last). A build costs about 50 iterations, but letting
        # the count grow costs more over the sweeps (measured at 256 px: 10 to 40 as fast or slower)
        if iterations > REBUILD:
            self.hierarchy = None
        return z

    def sweep(self, z, normals):
        return cone_sweep(z, normals, self.lit, self.wx, self.wy, self.cos_theta,
                          light=self.light, smooth=self.smooth)


# --------------------------------------------------------------------------------------------
# The solver
# --------------------------------------------------------------------------------------------


def oblique_depth(image, mask, *, light, k=None, concave=None, tol=TOL, dark=0.0,
                  smooth=SMOOTH, shadow_weight=SHADOW_WEIGHT, iterations=ITERATIONS,
                  stop=STOP, coarse=COARSE) -> ObliqueResult:
    """Depth and normals from one shading image under any light direction.

    Parameters
    ----------
    image : (H, W) float
        Shading image, >= 0.
    mask : (H, W) bool
        Object pixels.
    light : (3,) float
        Direction toward the light (any length), ``z > 0``.
    k : float, optional
        ``k * albedo``, the brightness of a pixel facing the light; default the brightest object
        pixel (which faces the light in a noise-free image).
    concave : (concave_x, concave_y), optional
        Where the user marked the surface concave along x / y
        (:func:`shadeform.regions.concave_masks`): the marching's convexity tie-break and its
        one-sided penalty on turns against the convexity (``HINGE``) flip there.
    tol : float
        Pixels with ``I / k >= 1 - tol`` start the marching with ``N = L``; raise it for noisy
        images (about the noise's relative level).
    dark : float
        Pixels with ``I / k <= dark`` are the shadow (``N . L <= 0``); 0 for noise-free images,
        about twice the noise's relative level otherwise.
    smooth : float
        Weight of the smoothness of the lit normals in the polished energy.
    shadow_weight : float
        Weight of the chord equations in which a shadowed pixel takes part, in (0, 1].
    iterations : int
        Descent sweeps at most (0: the marching's normals, integrated).
    stop : float
        The sweeps stop when the energy falls by less than this fraction in one.
    coarse : int
        When the object's bounding box is longer than this many pixels, the steps 1-3 run first on
        the image halved (2x2 block means, recursively), and the full-size polish starts from that
        solution's normals, moved onto their cones, instead of from a marching at full size.

    Returns
    -------
    ObliqueResult

    Raises
    ------
    InputError
        Wrong shapes, an empty or black object, a light with ``z <= 0``, bad numbers.

    Examples
    --------
    >>> from shadeform import synth, metrics
    >>> scene = synth.scene("sphere", size=64, light=(1, 1, 2))
    >>> result = oblique_depth(scene.image, scene.mask, light=scene.light)
    >>> bool(metrics.angular_error(result.normals, scene.normals) < 3)
    True
    """
    from shadeform.light import as_light

    timer = StageTimer()
    image, mask = _check_image_mask(image, mask)
    light = as_light(light)
    values = image[mask]
    k = float(values.max()) if k is None else _positive(k, "k")
    tol = _fraction(tol, "tol")
    dark = _finite(dark, "dark")
    if not 0 <= dark < 1:
        raise InputError(f"dark must be in [0, 1), got {dark}")
    smooth = _finite(smooth, "smooth")
    if smooth < 0:
        raise InputError(f"smooth must be >= 0, got {smooth}")
    shadow_weight = _fraction(shadow_weight, "shadow_weight", closed=True)
    if isinstance(iterations, bool) or not isinstance(iterations, numbers.Integral) or iterations < 0:
        raise InputError(f"iterations must be a whole number >= 0, got {iterations!r}")
    stop = _fraction(stop, "stop")
    concave_x, concave_y = _check_concave(concave, mask.shape)

    cos_theta = np.clip(np.where(mask, image / k, 0.0), 0.0, 1.0)
    lit = mask & (cos_theta > dark)
    if not lit.any():
        raise InputError("the whole object is in shadow (I / k <= dark); lower dark or check k")
    sources = _sources(cos_theta, lit, tol)
    timer.lap("prepare")

    if isinstance(coarse, bool) or not isinstance(coarse, numbers.Integral) or coarse < 16:
        raise InputError(f"coarse must be a whole number >= 16, got {coarse!r}")
    extent = max(np.ptp(np.flatnonzero(mask.any(axis=1))), np.ptp(np.flatnonzero(mask.any(axis=0))))
    if extent + 1 > coarse:
        # the half-size solution gets the long wavelengths cheaply and with half the marching's
        # drift; the full-size descent then only has to move the short ones (coarse-to-fine as
        # in Horn 1990). k is the full-size one, so the cones keep their angles
        half = _halve(image, mask, concave_x, concave_y)
        start = oblique_depth(half.image, half.mask, light=light, k=k, concave=half.concave,
                              tol=tol, dark=dark, smooth=smooth, shadow_weight=shadow_weight,
                              iterations=iterations, stop=stop, coarse=coarse)
        normals = _double_normals(start.normals, mask, cos_theta, lit, light)
        reached = lit.copy()
        unreached = int(start.info["unreached"])
        levels = start.info["levels"] + 1
        # the start is already polished at half size: a few sweeps move the short wavelengths
        iterations = min(iterations, REFINE_ITERATIONS)
    else:
        normals, _ = march_cone(cos_theta, lit, light=light, sources=sources,
                                concave_x=concave_x, concave_y=concave_y)
        reached = np.isfinite(normals[..., 0])
        unreached = int(np.count_nonzero(lit & ~reached))
        levels = 1
    timer.lap("march" if levels == 1 else "half-size solve")

    fill = _ShadowFill(mask, mask & ~reached)
    normals = fill(np.where(mask[..., None], normals, np.nan), light)
    timer.lap("shadow")

    descent = _Descent(mask, cos_theta, lit & reached, light, shadow_weight, smooth)
    box = descent.box
    with _serial():
        normals, z, energies, sweeps = _polish(descent, fill, normals, light, iterations, stop)
    timer.lap("descent")

    depth = np.full(mask.shape, np.nan)
    depth[box] = np.where(descent.mask, z, np.nan)
    main = (int(sources[0, 0]), int(sources[0, 1]))
    depth -= depth[main]
    normals[~mask] = np.nan
    timer.lap("depth")
    info = {"sources": [(int(r), int(c)) for r, c in sources], "levels": levels,
            "sweeps": int(sweeps if iterations else 0),
            "energy": energies, "unreached": unreached, "timings": timer.timings}
    return ObliqueResult(depth=depth, normals=normals, lit=lit, main=main, info=info)


@dataclass(frozen=True)
class _Half:
    image: np.ndarray
    mask: np.ndarray
    concave: tuple[np.ndarray, np.ndarray] | None


def _halve(image, mask, concave_x, concave_y) -> _Half:
    """The image at half size: 2x2 block means over the object's pixels; a block is object when
    at least two of its pixels are, concave where any of its pixels is."""
    height, width = mask.shape
    pad = ((0, height % 2), (0, width % 2))

    def blocks(a):
        a = np.pad(a, pad)
        return a.reshape(a.shape[0] // 2, 2, a.shape[1] // 2, 2)

    count = blocks(mask.astype(np.float64)).sum(axis=(1, 3))
    total = blocks(np.where(mask, image, 0.0)).sum(axis=(1, 3))
    half_mask = count >= 2
    half_image = np.where(half_mask, total / np.maximum(count, 1.0), 0.0)
    concave = None
    if concave_x is not None:
        concave = tuple(blocks(m.astype(bool)).any(axis=(1, 3)) for m in (concave_x, concave_y))
    return _Half(half_image, half_mask, concave)


def _double_normals(half_normals, mask, cos_theta, lit, light) -> np.ndarray:
    """Normals of a half-size solution at full size: bilinear between the half-size pixel
    centres (valid ones only; the nearest valid one past the edge), then each lit pixel's moved
    to the nearest normal on its own cone (same azimuth about ``L``). Shadowed pixels stay NaN."""
    valid = np.isfinite(half_normals[..., 0])
    # past the half-size object: the nearest valid pixel's normal
    _, (near_r, near_c) = ndi.distance_transform_edt(~valid, return_indices=True)
    filled = half_normals[near_r, near_c]
    height, width = mask.shape
    # full pixel (r, c) sits at half-size coordinate (r + 0.5) / 2 - 0.5
    rows = (np.arange(height) + 0.5) / 2 - 0.5
    cols = (np.arange(width) + 0.5) / 2 - 0.5
    grid = np.stack(np.meshgrid(rows, cols, indexing="ij"))
    normals = np.stack([ndi.map_coordinates(filled[..., i], grid, order=1, mode="nearest")
                        for i in range(3)], axis=-1)
    phi = _azimuth(normals, light)
    limits = _azimuth_limits(cos_theta, light)
    on_cone = _on_cone(cos_theta, np.clip(phi, -limits, limits), light)
    return np.where(lit[..., None], on_cone, np.nan)


def _polish(descent, fill, normals, light, iterations, stop):
    """Step 3: alternate the normal and depth blocks until the energy stalls.

    Returns the normals (whole image), the depth on the descent's box, the energy after each
    sweep (the first before any) and the number of sweeps done.
    """
    box = descent.box
    field_ = np.ascontiguousarray(np.nan_to_num(normals[box]))
    z = descent.depth(field_, np.zeros(descent.mask.shape), tol=1e-6)
    energies = [descent.energy(z, field_)]
    sweeps = 0
    for sweeps in range(1, int(iterations) + 1):
        field_ = descent.sweep(z, field_)
        normals[box] = np.where(descent.mask[..., None], field_, normals[box])
        normals = fill(normals, light)
        field_ = np.ascontiguousarray(np.nan_to_num(normals[box]))
        z = descent.depth(field_, z, tol=1e-3)
        energies.append(descent.energy(z, field_))
        if energies[-2] - energies[-1] <= stop * energies[-2]:
            break
    # the last depth block to full accuracy
    z = descent.depth(field_, z, tol=1e-8)
    return normals, z, energies, sweeps


def _sources(cos_theta, lit, tol) -> np.ndarray:
    """The brightest lit pixel first, then every other lit pixel within ``tol`` of full
    brightness, and the brightest pixel of every part of the lit region that has none."""
    main = np.unravel_index(np.argmax(np.where(lit, cos_theta, -1.0)), lit.shape)
    bright = np.argwhere(lit & (cos_theta >= 1.0 - tol))
    chosen = np.zeros(lit.shape, dtype=bool)
    chosen[main] = True
    rows = [main]
    for r, c in bright:
        if not chosen[r, c]:
            chosen[r, c] = True
            rows.append((r, c))
    labels, n_parts = ndi.label(lit, structure=np.ones((3, 3), dtype=bool))
    covered = set(np.unique(labels[chosen]))
    for part in range(1, n_parts + 1):
        if part not in covered:
            where = np.where(labels == part, cos_theta, -1.0)
            rows.append(np.unravel_index(np.argmax(where), lit.shape))
    return np.array(rows, dtype=np.int64)


# --------------------------------------------------------------------------------------------
# Input checks
# --------------------------------------------------------------------------------------------


def _check_image_mask(image, mask) -> tuple[np.ndarray, np.ndarray]:
    from shadeform._checks import shading_image

    image = shading_image(image)
    mask = np.asarray(mask)
    if mask.shape != image.shape:
        raise InputError(f"mask has shape {mask.shape} but the image has {image.shape}; "
                         "give a mask of the image's size")
    mask = mask.astype(bool)
    if not mask.any():
        raise InputError("mask is empty; it must mark the object's pixels")
    if image[mask].max() <= 0:
        raise InputError("the object is black: there is no shading to work with")
    return image, mask


def _check_concave(concave, shape) -> tuple[np.ndarray | None, np.ndarray | None]:
    if concave is None:
        return None, None
    if isinstance(concave, (tuple, list)) and len(concave) == 2:
        pair = [np.asarray(m) for m in concave]
        if all(m.shape == shape for m in pair):
            return pair[0].astype(bool), pair[1].astype(bool)
    raise InputError("concave must be (concave_x, concave_y), two bool masks of the image's shape, "
                     "from shadeform.regions.concave_masks")


def _finite(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not np.isfinite(value):
        raise InputError(f"{what} must be a finite number, got {value!r}")
    return float(value)


def _positive(value, what: str) -> float:
    value = _finite(value, what)
    if value <= 0:
        raise InputError(f"{what} must be > 0, got {value}")
    return value


def _fraction(value, what: str, *, closed: bool = False) -> float:
    value = _finite(value, what)
    if not (0 < value < 1 or (closed and value == 1)):
        raise InputError(f"{what} must be in (0, {'1]' if closed else '1)'}, got {value}")
    return value
