"""Step 3 of the oblique solver: the polish, block-coordinate descent on one energy.

The unknowns are the depth ``z`` and the cone azimuths of the lit pixels (their normals stay on
their shading cones, :mod:`._cone`); the shadowed normals follow by the fill of :mod:`.shadow`.
The energy is that of the marching's chord equations, over 4-neighbour pairs,

    E(z, N) = sum over pairs a, b of  w_ab ((n_a + n_b) . (X_b - X_a))^2
              + smooth * sum over pairs |n_a - n_b|^2   (lit pixels' normals only),

with ``w_ab = 1`` between lit pixels and ``shadow_weight`` where a shadowed pixel takes part.
Normals and depth alternate as unknowns, as in Horn and Brooks' variational scheme [1]_:

* for fixed normals ``E`` is a pair-weighted Poisson problem in ``z``, solved by the project's
  multigrid-preconditioned conjugate gradients
  (:class:`shadeform.integration._multigrid.PairHierarchy`), warm-started from the last depth;
* for fixed ``z`` a red-black colouring makes the lit pixels of one colour independent, each
  minimising a quadratic in ``n`` over its cone, which is a trigonometric polynomial of degree 2
  in ``phi``: a coarse grid of trials, then safeguarded Newton steps (:func:`cone_sweep`).

The shadowed normals are refilled after each sweep. The small ``smooth`` term (the smoothness of
the normal field of Ikeuchi and Horn [2]_) removes the checkerboard that the pair sums cannot
see and favours smooth surfaces over creased ones. The polish only refines within the basin the
marching chose: it decides no convex/concave branch.

The descent runs numba on one thread (:func:`_serial`): its many small warm-started solves lose
more to thread hand-offs than they gain, badly so on a shared machine.

References
----------
.. [1] B. K. P. Horn and M. J. Brooks, "The variational approach to shape from shading",
   CVGIP 33(2), 174-208, 1986 (integrability and normals as alternating unknowns).
.. [2] K. Ikeuchi and B. K. P. Horn, "Numerical shape from shading and occluding boundaries",
   Artificial Intelligence 17, 141-184, 1981 (smoothness of the normal field).
"""

from __future__ import annotations

from contextlib import contextmanager

import numba
import numpy as np

from shadeform.integration._multigrid import PairHierarchy
from shadeform.integration._slopes import MIN_NZ
from shadeform.solvers.oblique._cone import azimuth, azimuth_limits, cone_basis, cone_frame, on_cone

# Set by hand on the synthetic sphere and vase under the light (5, 5, 7) (the scenes of the accuracy
# bars, benchmarks/bench_oblique.py); the speed constants (SWEEP_SAMPLES, REBUILD) by their time at
# 256 and 512 px with the errors at 256 px unchanged.

#: Weight of ``|n_a - n_b|^2`` between lit neighbours in the energy.
SMOOTH = 0.1
#: Weight of the chord equations in which a shadowed pixel takes part.
SHADOW_WEIGHT = 1e-2
#: Descent sweeps at most, and the relative energy change that stops them.
ITERATIONS = 30
STOP = 1e-4
#: CG iterations of a depth block past which the multigrid preconditioner is rebuilt: a build
#: costs about 50 iterations, but letting the count grow costs more over the sweeps.
REBUILD = 10
#: Trial azimuths per pixel before the Newton refinement: the cost on the cone is a
#: trigonometric polynomial of degree 2, with at most two minima, so a coarse grid suffices.
SWEEP_SAMPLES = 24

#: Newton steps from the best trial (quadratic convergence inside its bracket).
_NEWTON_STEPS = 8
#: Relative residuals of the depth blocks: the first (from zero), those between sweeps (loose:
#: warm-started, and the next sweep moves the normals anyway) and the last (to full accuracy).
_FIRST_TOL, _SWEEP_TOL, _LAST_TOL = 1e-6, 1e-3, 1e-8


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
def _sweep_kernel(z, normals, lit, wx, wy, cos_theta, limits, phi, light, e1, e2, smooth, samples, colour):
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
            cone_basis(cos_theta[r, c], light, e1, e2, a0, a1, a2)
            limit = limits[r, c]
            _cone_coefficients(a0, a1, a2, M, g, coef)
            best = _cone_minimum(coef, limit, min(max(phi[r, c], -limit), limit), samples)
            phi[r, c] = best
            cp = np.cos(best)
            sp_ = np.sin(best)
            for i in range(3):
                normals[r, c, i] = a0[i] + a1[i] * cp + a2[i] * sp_


def cone_sweep(z, normals, lit, wx, wy, cos_theta, *, light, smooth=SMOOTH, samples=SWEEP_SAMPLES):
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
        ``I / albedo``.
    light : (3,) float
        Unit vector toward the light.
    smooth : float
        Weight of ``|n_a - n_b|^2`` between lit neighbours.
    samples : int
        Trial azimuths per pixel (>= 3) before the Newton refinement.

    Returns
    -------
    normals : (h, w, 3) float64
        The same array, updated.
    """
    light = np.asarray(light, dtype=np.float64)
    e1, e2 = cone_frame(light)
    limits = azimuth_limits(np.asarray(cos_theta, dtype=np.float64), light)
    phi = np.where(lit, azimuth(np.nan_to_num(normals), light), 0.0)
    for colour in (0, 1):
        _sweep_kernel(
            z,
            normals,
            lit,
            wx,
            wy,
            cos_theta,
            limits,
            phi,
            light,
            e1,
            e2,
            float(smooth),
            int(samples),
            colour,
        )
    return normals


def cone_sweep_reference(z, normals, lit, wx, wy, cos_theta, *, light, smooth=SMOOTH, samples=SWEEP_SAMPLES):
    """Slow version of :func:`cone_sweep`: the same sweep, written out in numpy per pixel.

    Each pixel's quadratic is assembled from its pairs with numpy, and its minimum taken over a
    fine grid of 4096 azimuths (``samples`` is not used); for the tests, on small images.
    """
    light = np.asarray(light, dtype=np.float64)
    limits = azimuth_limits(np.asarray(cos_theta, dtype=np.float64), light)
    height, width = z.shape
    for colour in (0, 1):
        for r in range(height):
            for c in range(width):
                if not lit[r, c] or (r + c) % 2 != colour:
                    continue
                M = np.zeros((3, 3))
                g = np.zeros(3)
                pairs = (
                    (r, c + 1, wx[r, c] if c + 1 < width else 0.0),
                    (r, c - 1, wx[r, c - 1] if c > 0 else 0.0),
                    (r + 1, c, wy[r, c] if r + 1 < height else 0.0),
                    (r - 1, c, wy[r - 1, c] if r > 0 else 0.0),
                )
                for rb, cb, weight in pairs:
                    if weight <= 0:
                        continue
                    chord = np.array([cb - c, r - rb, z[rb, cb] - z[r, c]], dtype=np.float64)
                    M += weight * np.outer(chord, chord)
                    g += weight * (chord * (chord @ normals[rb, cb]) - smooth * normals[rb, cb])
                limit = limits[r, c]
                current = np.clip(azimuth(normals[r, c], light), -limit, limit)
                trial = np.append(np.linspace(-limit, limit, 4096), current)
                candidates = on_cone(np.full(trial.shape, cos_theta[r, c]), trial, light)
                costs = np.einsum("pi,ij,pj->p", candidates, M, candidates) + 2 * candidates @ g
                normals[r, c] = candidates[np.argmin(costs)]
    return normals


@contextmanager
def _serial():
    """Numba's parallel kernels on one thread for the duration (the setting is per thread).

    The descent's depth blocks are many small warm-started solves (a few CG iterations each, about
    10 ms at 256x256 on one core); spread over threads on a shared machine each one waited tens
    of times longer for the others than it computed.
    """
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)


class Descent:
    """The energy of the module docstring on the mask's bounding box, and its two blocks.

    Parameters
    ----------
    mask, lit : (H, W) bool
        The object, and its lit pixels whose normals move (on their cones).
    cos_theta : (H, W) float
        ``I / albedo``.
    light : (3,) float
    shadow_weight, smooth : float
        The energy's weights.
    """

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
        """The chord part of the energy (without the smoothness term) on the box."""
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
        gx = self.wx * (-sx[..., 0] * szx)  # weight times the step dz = -s_x / s_z (right)
        gy = self.wy * (sy[..., 1] * szy)  # weight times the step dz = s_y / s_z (down)
        b = -gx - gy
        b[:, 1:] += gx[:, :-1]
        b[1:] += gy[:-1]
        if self.hierarchy is None:
            self.hierarchy = PairHierarchy(self.mask, px, py)
        z, iterations, _ = self.hierarchy.solve_pairs(
            b, z0, px=px, py=py, tol=tol, maxiter=500, from_start=True
        )
        # the weights have drifted from the preconditioner's: a new one, built when the next
        # solve needs it (none after the last)
        if iterations > REBUILD:
            self.hierarchy = None
        return z

    def sweep(self, z, normals):
        """The normal block: one :func:`cone_sweep`, in place."""
        return cone_sweep(
            z, normals, self.lit, self.wx, self.wy, self.cos_theta, light=self.light, smooth=self.smooth
        )


def polish(descent, fill, normals, light, iterations, stop):
    """Alternate the normal and depth blocks until the energy stalls (numba on one thread).

    Parameters
    ----------
    descent : Descent
    fill : callable
        ``fill(normals, light)``: the shadow's normals refilled (:class:`.shadow.ShadowFill`).
    normals : (H, W, 3) float
        The start, on the whole image; NaN off the object.
    light : (3,) float
    iterations : int
        Sweeps at most.
    stop : float
        The sweeps stop when the energy falls by less than this fraction in one.

    Returns
    -------
    normals : (H, W, 3) float64
        The whole image's.
    z : (h, w) float64
        The depth on the descent's box.
    energies : list of float
        The energy after each sweep, the first before any.
    sweeps : int
        Sweeps done.
    """
    box = descent.box
    with _serial():
        field_ = np.ascontiguousarray(np.nan_to_num(normals[box]))
        z = descent.depth(field_, np.zeros(descent.mask.shape), tol=_FIRST_TOL)
        energies = [descent.energy(z, field_)]
        sweeps = 0
        while sweeps < iterations:
            sweeps += 1
            field_ = descent.sweep(z, field_)
            normals[box] = np.where(descent.mask[..., None], field_, normals[box])
            normals = fill(normals, light)
            field_ = np.ascontiguousarray(np.nan_to_num(normals[box]))
            z = descent.depth(field_, z, tol=_SWEEP_TOL)
            energies.append(descent.energy(z, field_))
            if energies[-2] - energies[-1] <= stop * energies[-2]:
                break
        z = descent.depth(field_, z, tol=_LAST_TOL)
    return normals, z, energies, sweeps
