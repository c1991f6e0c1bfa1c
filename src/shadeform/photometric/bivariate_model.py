"""The bivariate reflectance model (:mod:`shadeform.photometric.bivariate`'s description): its
constants, and its slow, plain-numpy references (the basis, the non-negative fit at one normal,
the Gauss-Newton step and the re-weighted search) that the compiled kernels
(:mod:`.bivariate_kernels`) are tested against.
"""

from __future__ import annotations

import numpy as np

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
