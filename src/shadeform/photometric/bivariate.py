"""Photometric stereo with a low-frequency reflectance model: shadows, gloss and non-Lambertian
falloff, fitted per pixel.

Real paints and glazes are not Lambertian: their brightness falls off with ``n . l`` more steeply
or more gently than the cosine, and gloss adds a lobe round the mirror direction, broad on a
metallic paint (DiLiGenT's ``cow``) and sharp on a glaze (``ball``). A Lambertian fit reads both as
shape, however carefully it leaves highlights out. Here each pixel's readings are explained by

    I_j = a (c_j - c_j^2 / 2) + b c_j^2 / 2  +  c_j sum_m s_m h_j^(4^m)
          (c_j = max(0, n . l_j), h_j = n . h_j, m = 1 .. LOBES)

with every coefficient non-negative: the diffuse part is then exactly a quadratic in ``c``
through 0 that does not decrease toward the light (Lambert's cosine and the lowest-order
correction of its falloff), and the gloss only adds light, in lobes round the half vector
``h_j = (l_j + v) / |l_j + v|`` (``v = +z``) each four times narrower than the last (half-widths
of about 34, 17 and 8 degrees: the narrowest near the spacing of a dense light dome). For a
given normal the coefficients are a five-unknown non-negative least squares (Lawson and
Hanson's active set on the normal equations); the normal is the one whose fit leaves the least
weighted residual, found from the robust Lambertian normal by Gauss-Newton steps in its tangent
plane, each from the model linearised in the normal and the non-zero coefficients together (the
variable-projection step of Golub and Pereyra) and halved until the fit improves. Readings the model cannot explain
(cast shadows on a lit surface, interreflections, a highlight sharper than the narrowest lobe)
are weighted down by Tukey's biweight of the residual over the median absolute deviation of the
lit readings' residuals (the textbook 4.685 scale), re-weighted :data:`ROUNDS` times. Readings
the normal puts in shadow count as predicted dark.

The same model checks the given lights for a slant error common to all of them (a chrome sphere
read slightly too large or small), which a Lambertian fit cannot see: :func:`slant_scale`.

This is a classical bivariate reflectance fit in the family the DiLiGenT benchmark ranks best
among non-learned methods (Shi et al. 2014, Ikehata and Aizawa 2014); the basis here is its own.
Measured on the seven real DiLiGenT objects: ``benchmarks/results/stereo.md``. The basis was
compared on ``ball``, ``cow`` and ``cat`` before the sign constraints (powers 1-3 of ``c`` with
three lobes, two to four lobes with one power): one power loses the ball's falloff (16-bit ball
2.01 against 1.74 degrees), three let the normal trade with the falloff (cow 13.5 against 8.7).
The constraints then took the seven objects' mean from 8.41 to 7.74 degrees (cow 9.34 -> 7.95,
pot1 8.77 -> 7.84; the ball alone lost, 8-bit crop 2.07 -> 2.45, 16-bit 1.75 -> 1.79).

References
----------
.. [1] B. Shi, P. Tan, Y. Matsushita, K. Ikeuchi, "Bi-polynomial modeling of low-frequency
   reflectances", IEEE TPAMI 36(6), 2014.
.. [2] S. Ikehata, K. Aizawa, "Photometric stereo using constrained bivariate regression for
   general isotropic surfaces", CVPR 2014.
.. [3] B. Shi et al., "A benchmark dataset and evaluation for non-Lambertian and uncalibrated
   photometric stereo", IEEE TPAMI 41(2), 2019.
.. [4] P. N. Belhumeur, D. J. Kriegman, A. L. Yuille, "The bas-relief ambiguity", IJCV 35(1),
   1999.
.. [5] G. Golub, V. Pereyra, "Separable nonlinear least squares: the variable projection method
   and its applications", Inverse Problems 19(2), 2003.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange

from shadeform.photometric import lambertian

#: Terms of the diffuse part: ``c - c^2 / 2`` and ``c^2 / 2`` with non-negative weights, which
#: spans exactly the quadratics in ``c`` through 0 that do not decrease on [0, 1].
POWERS = 2
#: Lobes round the half vector, with exponents 4, 16, 64.
LOBES = 3
#: Tukey's biweight scale in units of the residuals' robust sigma (95 % efficiency for Gaussian
#: noise: the textbook value).
TUKEY = 4.685
#: A small ridge on the lobes' coefficients (the basis is dimensionless), so that a pixel whose
#: readings barely reach a lobe still has a solvable fit; not swept.
RIDGE = 0.01
#: Lit readings a pixel needs per unknown of the model (its coefficients and the normal's two
#: angles) for the model to be fitted; with fewer (a set of a few photos) the robust Lambertian
#: normal is kept. A rule of thumb, not swept.
READINGS_PER_UNKNOWN = 3
#: Re-weightings of the residuals, each followed by at most :data:`STEPS` Gauss-Newton steps of
#: the normal. A step longer than :data:`TURN` radians is shortened to it (the linearisation does
#: not see lights coming into or out of shadow), one that does not improve the fit is halved up to
#: :data:`HALVINGS` times, and the search stops at a step under :data:`STOP` radians (0.0006
#: degrees, far below any error measured). Limits of the search, not swept: a pixel takes 3-4
#: steps a round on the DiLiGenT objects.
ROUNDS = 2
STEPS = 12
TURN = 0.2
HALVINGS = 6
STOP = 1e-5
#: The lights' slant refinement (:func:`slant_scale`) searches scales of ``tan(slant)`` within
#: this factor either way: a calibration off by more is not a small error to refine. A bound on
#: the search, not swept; a minimum on it means the photos cannot tell, and the given lights stay.
SLANT_BOUND = 1.25
#: Degrees: the lights' slants must spread by this much (standard deviation) for a common slant
#: error to be looked for. With every light at one slant the error is only a uniform change of
#: strength, which the albedo absorbs: the photos say nothing about it, and the search would read
#: the noise (a ring of 12 lights at 45 degrees gave 0.85). Half the spread of DiLiGenT's dome
#: (9.7); not swept.
SLANT_SPREAD = 5.0
#: Standard deviations by which the pixels a refined slant explains better must outnumber half
#: of them (one-sided p = 0.0005): the usual significance of a sign test.
SIGN_TEST = 3.29
#: The search stops when the bracket of ``log`` scale is narrower than this (a 1 % slant scale).
SLANT_TOLERANCE = 0.01


def fit(lights, readings, *, min_shading, highlight_cos, iterations):
    """Per pixel ``g = f(1) n`` (P, 3), ``f(1)`` the diffuse brightness facing the light, and
    the readings the final fit counted (N, P): lit and not weighted out. Pixels the robust
    Lambertian start cannot solve stay NaN; those with too few lit readings for the model
    (:data:`READINGS_PER_UNKNOWN`) keep the start.

    Parameters
    ----------
    lights : (N, 3) float64
        Unit directions toward the lights.
    readings : (N, P) float64
        Each pixel's readings, divided by the lights' strengths.
    min_shading, highlight_cos, iterations
        The robust Lambertian start's options (:func:`shadeform.photometric.lambertian.robust`).
    """
    g, usable = lambertian.robust(
        lights, readings, min_shading=min_shading, highlight_cos=highlight_cos, iterations=iterations
    )
    solved = np.isfinite(g[:, 0]) & (np.linalg.norm(g, axis=1) > 0)
    start = np.zeros_like(g)
    start[solved] = g[solved] / np.linalg.norm(g[solved], axis=1, keepdims=True)
    lit = (lights @ start.T > 0) & (readings > 0)
    modelled = solved & (lit.sum(axis=0) >= READINGS_PER_UNKNOWN * (POWERS + LOBES + 2))
    normals, brightness, weights = _refine(
        start[modelled], np.ascontiguousarray(readings[:, modelled]), lights, lambertian.half_vectors(lights)
    )
    result = g.copy()  # where the model is not fitted: the robust Lambertian g
    # a fit whose diffuse part is not positive keeps the Lambertian albedo
    albedo = np.where(brightness > 0, brightness, np.linalg.norm(g[modelled], axis=1))
    result[modelled] = normals * albedo[:, None]
    usable[:, modelled] = (weights > 0) & (lights @ normals.T > 0)
    return result, usable


def _basis(n, light, half):
    """The model's basis at normal ``n`` (3,) for one reading: (POWERS + LOBES,), zero where the
    light does not reach (slow reference of :func:`_basis_kernel`)."""
    c = float(n @ light)
    if c <= 0:
        return np.zeros(POWERS + LOBES)
    h = max(0.0, float(n @ half))
    return np.r_[c - c * c / 2, c * c / 2, [c * h ** (4 ** (m + 1)) for m in range(LOBES)]]


def model_fit_reference(n, lights, values, weights):
    """The weighted, non-negative least-squares fit of the model at normal ``n``: its weighted
    residual sum (unlit readings count as predicted dark) and the coefficients (POWERS + LOBES,),
    all >= 0. Plain numpy and SciPy's bounded least squares, one reading at a time: the compiled
    kernel is tested against it."""
    from scipy.optimize import lsq_linear

    half = lambertian.half_vectors(lights)
    basis = np.array([_basis(n, light, h) for light, h in zip(lights, half)])
    lit = basis.any(axis=1)
    ridge = np.r_[[1e-12] * POWERS, [RIDGE + 1e-12] * LOBES]
    root = np.sqrt(weights * lit)
    # the ridge as extra rows: the same objective as the kernel's normal equations
    system = np.vstack([root[:, None] * basis, np.diag(np.sqrt(ridge))])
    target = np.r_[root * values, np.zeros(POWERS + LOBES)]
    # bounded-variable least squares: coefficients held at a bound are exactly zero there
    coefficients = lsq_linear(system, target, bounds=(0.0, np.inf), method="bvls", tol=1e-14).x
    residual = np.sum(weights * values * values) - np.sum(weights * lit * values * values)
    residual += np.sum((system @ coefficients - target) ** 2)
    return residual, coefficients


def search_reference(n, lights, values):
    """:func:`_search_pixel` in plain numpy over :func:`model_fit_reference` (slow, obviously
    correct: the compiled search is tested against it): the unit normal (3,), ``f(1)`` and the
    final weights (N,) from the unit start ``n``."""
    n = np.asarray(n, dtype=np.float64)
    half = lambertian.half_vectors(lights)
    weights = np.ones(len(values))
    for _ in range(ROUNDS):
        _, coefficients = model_fit_reference(n, lights, values, weights)
        basis = np.array([_basis(n, light, h) for light, h in zip(lights, half)])
        residuals = np.abs(values - basis @ coefficients)
        lit = basis.any(axis=1)
        u = residuals / (TUKEY * 1.4826 * np.median(residuals[lit] if lit.any() else residuals) + 1e-12)
        weights = np.where(u < 1.0, (1.0 - u * u) ** 2, 0.0)
        best, coefficients = model_fit_reference(n, lights, values, weights)
        for _ in range(STEPS):
            tangents = np.array(_tangents_reference(n))
            step = _step_reference(n, lights, values, weights, coefficients, tangents)
            length = np.linalg.norm(step)
            if length > TURN:
                step, length = step * TURN / length, TURN
            for _ in range(HALVINGS):
                m = n + step @ tangents
                m /= np.linalg.norm(m)
                cost, fitted = model_fit_reference(m, lights, values, weights)
                if cost < best:
                    best, n, coefficients = cost, m, fitted
                    break
                step, length = step / 2, length / 2
            else:
                break
            if length < STOP:
                break
    coefficients = model_fit_reference(n, lights, values, weights)[1]
    return n, float(coefficients[0] / 2 + coefficients[1] / 2), weights


def slope_reference(n, light, half, coefficients):
    """The gradient (3,) of the model's prediction ``basis(n) @ coefficients`` for one reading
    with respect to ``n`` (zero where the light does not reach): the derivative of each basis
    term of :func:`_basis`, written out."""
    c = float(n @ light)
    if c <= 0:
        return np.zeros(3)
    h = max(0.0, float(n @ half))
    exponents = 4.0 ** np.arange(1, LOBES + 1)
    along_light = coefficients[0] * (1 - c) + coefficients[1] * c + coefficients[POWERS:] @ h**exponents
    along_half = c * coefficients[POWERS:] @ (exponents * h ** (exponents - 1)) if h > 0 else 0.0
    return along_light * light + along_half * half


def _step_reference(n, lights, values, weights, coefficients, tangents):
    """The Gauss-Newton step (2,) of the normal along ``tangents`` (2, 3): the weighted least
    squares of the model linearised in the normal and the non-zero coefficients together, with
    the lobes' ridge (:func:`_search_pixel`'s step, by ``numpy.linalg.lstsq``)."""
    half = lambertian.half_vectors(lights)
    basis = np.array([_basis(n, light, h) for light, h in zip(lights, half)])
    slopes = np.array([slope_reference(n, light, h, coefficients) for light, h in zip(lights, half)])
    lit = basis.any(axis=1)
    free = coefficients > 0  # coefficients at zero stay there
    root = np.sqrt(weights * lit)
    ridge = np.sqrt(np.r_[[1e-12] * POWERS, [RIDGE + 1e-12] * LOBES][free])
    system = np.vstack(
        [
            root[:, None] * np.hstack([basis[:, free], slopes @ tangents.T]),
            np.hstack([np.diag(ridge), np.zeros((ridge.size, 2))]),
            np.hstack([np.zeros((2, free.sum())), np.sqrt(1e-12) * np.eye(2)]),
        ]
    )
    target = np.r_[root * (values - basis @ coefficients), -ridge * coefficients[free], 0.0, 0.0]
    return np.linalg.lstsq(system, target, rcond=None)[0][-2:]


def _tangents_reference(n):
    """Two unit vectors spanning the plane perpendicular to the unit ``n``."""
    first = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    first /= np.linalg.norm(first)
    return first, np.cross(n, first)


@numba.njit(cache=True, inline="always")
def _basis_kernel(n0, n1, n2, lights, half, j, basis):
    c = n0 * lights[j, 0] + n1 * lights[j, 1] + n2 * lights[j, 2]
    if c <= 0.0:
        return False
    h = max(0.0, n0 * half[j, 0] + n1 * half[j, 1] + n2 * half[j, 2])
    basis[0] = c - 0.5 * c * c
    basis[1] = 0.5 * c * c
    for m in range(LOBES):
        h = h * h
        h = h * h  # h^(4^(m+1))
        basis[POWERS + m] = c * h
    return True


@numba.njit(cache=True)
def _model_fit(n0, n1, n2, lights, half, values, weights, work):
    """The kernel of :func:`model_fit_reference`: the weighted residual sum; the coefficients in
    ``work[3, :size]`` (``work`` is (6, size^2) scratch space: the system, its right-hand side,
    one reading's basis, the coefficients, and the active set's own)."""
    size = POWERS + LOBES
    system = work[0, : size * size].reshape(size, size)
    moment, basis, coefficients = work[1, :size], work[2, :size], work[3, :size]
    system[:, :] = 0.0
    moment[:] = 0.0
    total = 0.0
    for j in range(values.size):
        w = weights[j]
        if w == 0.0:
            continue
        total += w * values[j] * values[j]
        if not _basis_kernel(n0, n1, n2, lights, half, j, basis):
            continue
        for a in range(size):
            moment[a] += w * values[j] * basis[a]
            wa = w * basis[a]
            for b in range(a + 1):
                system[a, b] += wa * basis[b]
    for a in range(size):
        system[a, a] += (RIDGE if a >= POWERS else 0.0) + 1e-12
        for b in range(a):
            system[b, a] = system[a, b]
    _nonnegative_solve(
        system, moment, coefficients, basis, work[4, : size * size].reshape(size, size), work[5, :size]
    )
    # sum w I^2 - 2 x . b + x . A x
    residual = total
    for a in range(size):
        residual -= 2.0 * coefficients[a] * moment[a]
        for b in range(size):
            residual += coefficients[a] * system[a, b] * coefficients[b]
    return residual


@numba.njit(cache=True)
def _nonnegative_solve(system, rhs, x, scratch, sub, z):
    """``x >= 0`` minimising ``x . A x / 2 - b . x`` for a small symmetric positive definite ``A``
    (``system``, kept) by Lawson and Hanson's active set; ``scratch`` (size,), ``sub`` (size,
    size) and ``z`` (size,) are work space."""
    size = rhs.size
    passive = np.zeros(size, dtype=np.bool_)
    x[:] = 0.0
    for _ in range(3 * size):
        # the most promising variable held at zero: the largest gradient b - A x
        best, enter = 1e-14, -1
        for a in range(size):
            if passive[a]:
                continue
            gradient = rhs[a]
            for b in range(size):
                gradient -= system[a, b] * x[b]
            if gradient > best:
                best, enter = gradient, a
        if enter < 0:
            return
        passive[enter] = True
        for _inner in range(size):
            # the unconstrained minimum over the passive variables
            k = 0
            for a in range(size):
                if passive[a]:
                    scratch[k] = rhs[a]
                    m = 0
                    for b in range(size):
                        if passive[b]:
                            sub[k, m] = system[a, b]
                            m += 1
                    k += 1
            _cholesky_solve(sub[:k, :k], scratch[:k], z[:k])
            step, k = 1.0, 0
            for a in range(size):
                if passive[a]:
                    if z[k] <= 0.0:
                        step = min(step, x[a] / (x[a] - z[k]))
                    k += 1
            k = 0
            for a in range(size):
                if passive[a]:
                    x[a] += step * (z[k] - x[a])
                    k += 1
            if step >= 1.0:
                break
            for a in range(size):  # variables the step brought to zero leave
                if passive[a] and x[a] <= 1e-15:
                    passive[a] = False
                    x[a] = 0.0


@numba.njit(cache=True)
def _cholesky_solve(system, rhs, out):
    """Solve ``system @ out = rhs`` for a small symmetric positive definite ``system`` given by its
    lower triangle (overwritten by its Cholesky factor)."""
    size = rhs.size
    for i in range(size):
        for j in range(i + 1):
            s = system[i, j]
            for k in range(j):
                s -= system[i, k] * system[j, k]
            if i == j:
                system[i, i] = np.sqrt(max(s, 1e-300))
            else:
                system[i, j] = s / system[j, j]
    for i in range(size):
        s = rhs[i]
        for k in range(i):
            s -= system[i, k] * out[k]
        out[i] = s / system[i, i]
    for i in range(size - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, size):
            s -= system[k, i] * out[k]
        out[i] = s / system[i, i]


@numba.njit(cache=True)
def _tangents(n0, n1, n2):
    """Two unit vectors spanning the plane perpendicular to the unit ``n``."""
    if abs(n0) < 0.9:  # n x (1, 0, 0)
        a0, a1, a2 = 0.0, n2, -n1
    else:  # n x (0, 1, 0)
        a0, a1, a2 = -n2, 0.0, n0
    length = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0, a1, a2 = a0 / length, a1 / length, a2 / length
    return a0, a1, a2, n1 * a2 - n2 * a1, n2 * a0 - n0 * a2, n0 * a1 - n1 * a0


@numba.njit(cache=True)
def _search_pixel(n, lights, half, values, weights, residuals, lit, work):
    """One pixel's re-weighted Gauss-Newton search from the unit normal ``n`` (3,), in place;
    returns ``f(1)``. ``weights`` ends as the final round's; ``work`` is (10, :data:`_WORK`)."""
    size = POWERS + LOBES
    basis, coefficients, kept = work[2, :size], work[3, :size], work[6, :size]
    weights[:] = 1.0
    n0, n1, n2 = n[0], n[1], n[2]
    for _round in range(ROUNDS):
        # Tukey's weights of the current fit's residuals
        _model_fit(n0, n1, n2, lights, half, values, weights, work)
        count = 0  # the residuals' scale from the readings the normal says are lit
        for j in range(values.size):
            predicted = 0.0
            if _basis_kernel(n0, n1, n2, lights, half, j, basis):
                for a in range(size):
                    predicted += coefficients[a] * basis[a]
                lit[count] = abs(values[j] - predicted)
                count += 1
            residuals[j] = abs(values[j] - predicted)
        scale = TUKEY * 1.4826 * (np.median(lit[:count]) if count else np.median(residuals)) + 1e-12
        for j in range(values.size):
            u = residuals[j] / scale
            weights[j] = (1.0 - u * u) ** 2 if u < 1.0 else 0.0
        best = _model_fit(n0, n1, n2, lights, half, values, weights, work)
        kept[:] = coefficients
        for _step in range(STEPS):
            t0, t1, t2, s0, s1, s2 = _tangents(n0, n1, n2)
            du, dv = _step_kernel(
                n0, n1, n2, t0, t1, t2, s0, s1, s2, lights, half, values, weights, kept, work
            )
            length = np.sqrt(du * du + dv * dv)
            if length > TURN:
                du, dv, length = du * TURN / length, dv * TURN / length, TURN
            improved = False
            for _halving in range(HALVINGS):
                m0, m1, m2 = n0 + du * t0 + dv * s0, n1 + du * t1 + dv * s1, n2 + du * t2 + dv * s2
                norm = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
                m0, m1, m2 = m0 / norm, m1 / norm, m2 / norm
                cost = _model_fit(m0, m1, m2, lights, half, values, weights, work)
                if cost < best:
                    best, n0, n1, n2, improved = cost, m0, m1, m2, True
                    kept[:] = coefficients
                    break
                du, dv, length = 0.5 * du, 0.5 * dv, 0.5 * length
            if not improved or length < STOP:
                break
    _model_fit(n0, n1, n2, lights, half, values, weights, work)
    n[0], n[1], n[2] = n0, n1, n2
    return 0.5 * (coefficients[0] + coefficients[1])  # f(1)


@numba.njit(cache=True)
def _step_kernel(n0, n1, n2, t0, t1, t2, s0, s1, s2, lights, half, values, weights, coefficients, work):
    """The kernel of :func:`_step_reference`: the Gauss-Newton step ``(du, dv)`` of the unit
    normal along the tangents ``t`` and ``s``, from the weighted normal equations of the model
    linearised in the normal and its non-zero ``coefficients`` together; ``work`` rows 7-9 are
    its scratch space."""
    size = POWERS + LOBES
    dim = size + 2
    system = work[7, : dim * dim].reshape(dim, dim)
    rhs, column, solution = work[8, :dim], work[9, :dim], work[9, dim : 2 * dim]
    system[:, :] = 0.0
    rhs[:] = 0.0
    for j in range(values.size):
        w = weights[j]
        if w == 0.0 or not _basis_kernel(n0, n1, n2, lights, half, j, column):
            continue
        c = n0 * lights[j, 0] + n1 * lights[j, 1] + n2 * lights[j, 2]
        h = max(0.0, n0 * half[j, 0] + n1 * half[j, 1] + n2 * half[j, 2])
        # the prediction's gradient in n: a multiple of the light plus one of the half vector
        along_light = coefficients[0] * (1.0 - c) + coefficients[1] * c
        along_half, exponent = 0.0, 1.0
        for m in range(LOBES):
            exponent *= 4.0
            along_light += coefficients[POWERS + m] * column[POWERS + m] / c  # h^e
            if h > 0.0:
                along_half += coefficients[POWERS + m] * exponent * column[POWERS + m] / h  # c e h^(e-1)
        g0 = along_light * lights[j, 0] + along_half * half[j, 0]
        g1 = along_light * lights[j, 1] + along_half * half[j, 1]
        g2 = along_light * lights[j, 2] + along_half * half[j, 2]
        column[size] = g0 * t0 + g1 * t1 + g2 * t2
        column[size + 1] = g0 * s0 + g1 * s1 + g2 * s2
        residual = values[j]
        for a in range(size):
            residual -= coefficients[a] * column[a]
        for a in range(dim):
            if a < size and coefficients[a] <= 0.0:
                continue  # coefficients at zero stay there
            rhs[a] += w * residual * column[a]
            wa = w * column[a]
            for b in range(a + 1):
                if b >= size or coefficients[b] > 0.0:
                    system[a, b] += wa * column[b]
    for a in range(size):
        if coefficients[a] <= 0.0:  # a fixed coefficient: its row says "no change"
            system[a, a], rhs[a] = 1.0, 0.0
        else:
            ridge = (RIDGE if a >= POWERS else 0.0) + 1e-12
            system[a, a] += ridge
            rhs[a] -= ridge * coefficients[a]
    system[size, size] += 1e-12
    system[size + 1, size + 1] += 1e-12
    _cholesky_solve(system, rhs, solution)
    return solution[size], solution[size + 1]


#: Scratch space per row of a pixel's ``work`` (the Gauss-Newton system's entries).
_WORK = (POWERS + LOBES + 2) ** 2


#: Pixels a thread takes at once in :func:`_refine_kernel`.
_BLOCK = 256


@numba.njit(cache=True, parallel=True)
def _refine_kernel(normals, readings, lights, half, brightness, weights):
    """:func:`_search_pixel` over the pixels (columns of ``readings``), each independent of the
    others (the result does not depend on the number of threads)."""
    count, pixels = readings.shape
    blocks = (pixels + _BLOCK - 1) // _BLOCK
    for block in prange(blocks):
        # scratch space once per block of pixels, not once per pixel
        work = np.empty((10, _WORK))
        residuals, lit, values, column = np.empty(count), np.empty(count), np.empty(count), np.empty(count)
        n = np.empty(3)
        for p in range(block * _BLOCK, min(pixels, (block + 1) * _BLOCK)):
            values[:] = readings[:, p]
            n[:] = normals[p]
            brightness[p] = _search_pixel(n, lights, half, values, column, residuals, lit, work)
            normals[p] = n
            weights[:, p] = column


def _refine(start, readings, lights, half):
    """Normals (P, 3), ``f(1)`` (P,) and final weights (N, P) from unit ``start`` normals."""
    normals = np.ascontiguousarray(start, dtype=np.float64).copy()
    brightness = np.empty(len(normals))
    weights = np.empty(readings.shape)
    _refine_kernel(
        normals, readings, np.ascontiguousarray(lights, dtype=np.float64), half, brightness, weights
    )
    return normals, brightness, weights


def slant_scale(lights, readings, start):
    """The scale of the lights' ``tan(slant)`` that the model explains the readings best with: 1
    where the photos cannot tell.

    A chrome sphere whose outline is read a little too large or small gives every light's slant
    too small or large by nearly one factor; so does a dome whose lamps sit higher or lower than
    its drawing says. A Lambertian surface cannot reveal it: the normals tilt to match (the
    depth scale of the bas-relief ambiguity, ``g -> diag(s, s, 1) g``). Gloss and the falloff
    can: a highlight sits where the normal meets a half vector, which tilts the other way. So
    the scale is the one whose per-pixel fits (:func:`_refine`, from the Lambertian ``start``
    turned by the ambiguity) leave the least median residual, a golden-section search on its
    logarithm within :data:`SLANT_BOUND`; a pixel lit too rarely for the model
    (:data:`READINGS_PER_UNKNOWN`) is judged by the Lambertian fit the fit itself keeps there
    (where the lights' strengths are known, a wrong slant leaves it a residual too). It gives 1 where the photos cannot tell: lights all at
    nearly one slant (:data:`SLANT_SPREAD`), a minimum on the bound, or a scale that explains
    no more pixels better than chance would (a sign test, :data:`SIGN_TEST`).

    Parameters
    ----------
    lights : (N, 3) float64
        The given unit lights.
    readings : (N, P) float64
        A sample of the object's readings, divided by the lights' strengths.
    start : (P, 3) float64
        The robust Lambertian ``g`` of those pixels with the given lights (finite, non-zero).

    References
    ----------
    .. [1] P. N. Belhumeur, D. J. Kriegman, A. L. Yuille, "The bas-relief ambiguity", IJCV 35(1),
       1999.
    .. [2] O. Drbohlav, R. Sara, "Specularities reduce ambiguity of uncalibrated photometric
       stereo", ECCV 2002.
    """
    if np.std(np.degrees(np.arccos(np.clip(lights[:, 2], -1.0, 1.0)))) < SLANT_SPREAD:
        return 1.0
    albedo = np.linalg.norm(start, axis=1)
    # each pixel judged by the model the fit gives it (:func:`fit`): this one where it is lit
    # often enough, the Lambertian one where it is lit in more photos than g has unknowns
    lit = (lights @ (start / albedo[:, None]).T > 0) & (readings > 0)
    count = lit.sum(axis=0)
    modelled = count >= READINGS_PER_UNKNOWN * (POWERS + LOBES + 2)
    plain = ~modelled & (count > 3)
    if np.count_nonzero(modelled | plain) <= SIGN_TEST**2:
        return 1.0  # too few for the sign test below ever to pass
    albedo = np.concatenate([albedo[modelled], albedo[plain]])
    model_start = start[modelled]
    model_readings = np.ascontiguousarray(readings[:, modelled], dtype=np.float64)
    plain_readings, plain_lit = readings[:, plain], lit[:, plain].astype(np.float64)

    def costs(log_scale):
        scale = np.exp(log_scale)
        tilted = lambertian.scaled_lights(lights, scale)
        normals = model_start / np.array([scale, scale, 1.0])  # the ambiguity's normals for these lights
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        half = lambertian.half_vectors(tilted)
        normals, _, _ = _refine(normals, model_readings, tilted, half)
        g = np.nan_to_num(lambertian.fit(tilted, plain_readings, plain_lit)[0])
        residuals = plain_readings - np.maximum(tilted @ g.T, 0.0)  # every reading, unlit as dark
        both = np.concatenate([_costs(normals, model_readings, tilted, half), np.sum(residuals**2, axis=0)])
        return both / albedo**2

    def loss(log_scale):
        return float(np.median(costs(log_scale)))

    low, high = -np.log(SLANT_BOUND), np.log(SLANT_BOUND)
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = high - golden * (high - low), low + golden * (high - low)
    loss_a, loss_b = loss(a), loss(b)
    while high - low > SLANT_TOLERANCE:
        if loss_a < loss_b:
            high, b, loss_b = b, a, loss_a
            a = high - golden * (high - low)
            loss_a = loss(a)
        else:
            low, a, loss_a = a, b, loss_b
            b = low + golden * (high - low)
            loss_b = loss(b)
    found = (low + high) / 2.0
    if np.log(SLANT_BOUND) - abs(found) < SLANT_TOLERANCE:
        return 1.0
    # a sign test: more pixels must be explained better than chance would give (one-sided
    # p = 0.0005), or the scale found only rode the noise along the ambiguity
    better = np.count_nonzero(costs(found) < costs(0.0) * (1.0 - 1e-9))
    if better <= albedo.size / 2 + SIGN_TEST * np.sqrt(albedo.size) / 2:
        return 1.0
    return float(np.exp(found))


@numba.njit(cache=True, parallel=True)
def _costs(normals, readings, lights, half):
    """Per pixel (columns of ``readings``), the model's unweighted residual sum at its unit normal
    (P,): every reading counted, unlit ones as predicted dark."""
    count, pixels = readings.shape
    size = POWERS + LOBES
    out = np.empty(pixels)
    blocks = (pixels + _BLOCK - 1) // _BLOCK
    for block in prange(blocks):
        work = np.empty((6, size * size))
        values, weights = np.empty(count), np.ones(count)
        for p in range(block * _BLOCK, min(pixels, (block + 1) * _BLOCK)):
            values[:] = readings[:, p]
            out[p] = _model_fit(
                normals[p, 0], normals[p, 1], normals[p, 2], lights, half, values, weights, work
            )
    return out
