"""Round features on a flat base: the surface model, its image and Jacobian, and its fit.

A round feature (a bump, a dimple, a crater) is a surface ``z = f(|x - c|)``: its normal at ``x``
leans along the radial direction ``u`` by the profile's slope ``s(r) = -f'(r)``, so with
``tau = L_xy / L_z`` it shades as ``I = k L_z (1 + s tau . u) / sqrt(1 + s^2)``, clipped at 0.
Heights add where features overlap, and so do their gradients. Each slope profile is a cubic
B-spline (:func:`profile_spline`, on :class:`scipy.interpolate.BSpline`). :func:`fit_features`
fits a sum of features and ``tau`` to an image by Levenberg-Marquardt: shape and source together
by minimising the rendering error, after M. J. Brooks and B. K. P. Horn, "Shape and source from
shading", Proc. IJCAI 1985, 932-936. :mod:`shadeform.light.relief` finds the features and reads
the light from the fit.

The fits evaluate the image and its Jacobian thousands of times, so :func:`render_features` runs
a compiled kernel (:mod:`shadeform.light._relief_kernel`), and the Levenberg-Marquardt steps solve
the small normal equations rather than factor the tall Jacobian; the tests hold the kernel to
:func:`_render_features_reference` (vectorised over pixels on scipy's B-spline basis) and the
solver to :func:`scipy.optimize.least_squares`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Cubic B-spline coefficients of each feature's slope profile.
PROFILE_KNOTS = 14
#: A feature's radius, in ring windows of the search that found it.
FEATURE_REACH = 3.5
# Slopes beyond this (84 degrees) are cut back during a fit: no relief is that steep.
_MAX_SLOPE = 10.0
# Cauchy scale (fraction of the base level) of the robust fits, which must not bend the features
# already found to explain the ones not yet modelled (chosen on the synthetic bumps of bench_light).
_ROBUST_SCALE = 0.02


def pixels(image, mask):
    """Object pixels as ``x`` (column), ``y`` (minus row) and intensity, each (n,)."""
    rows, cols = np.nonzero(mask)
    return cols.astype(np.float64), -rows.astype(np.float64), image[rows, cols]


def feature_params(level, across, features) -> np.ndarray:
    """Parameter vector ``(k L_z, tau_x, tau_y, then per feature c_x, c_y, c_1..c_K)``,
    ``K = PROFILE_KNOTS``, from the base level, ``tau`` (2,) and ``(centre, slopes)`` pairs."""
    return np.concatenate([[level, *across]] + [np.r_[c, s] for c, s in features])


def _profile_knots(count: int, spacing: float) -> np.ndarray:
    """Knots of a slope profile of ``count`` coefficients.

    The spline's coefficients are ``c_-1 .. c_{K+4}`` on uniform knots ``spacing`` apart from
    ``-3 * spacing`` (``c_j``'s basis function is centred at ``j * spacing``), with ``c_0 = 0`` and
    ``c_-1 = -c_1`` (odd about the centre, so the top is level and smooth) and ``c_j = 0`` past
    ``K`` (the feature ends at ``(K + 2) * spacing``).
    """
    return spacing * np.arange(-3, count + 7, dtype=np.float64)


def _padded(coefficients) -> np.ndarray:
    """``c_-1 .. c_{K+4}`` from ``c_1 .. c_K`` (see :func:`_profile_knots`)."""
    padded = np.zeros(coefficients.size + 6)
    padded[2 : coefficients.size + 2] = coefficients
    padded[0] = -coefficients[0]
    return padded


def profile_spline(coefficients, spacing: float):
    """The slope profile ``s(r)`` of a round feature as a :class:`scipy.interpolate.BSpline`.

    Parameters
    ----------
    coefficients : (K,) float64
        ``c_1 .. c_K``, the cubic B-spline coefficients on knots ``spacing`` apart; ``c_0 = 0``
        and ``c_-1 = -c_1`` make the profile odd about the centre (a level, smooth top), and the
        profile is 0 from ``(K + 2) * spacing`` on.
    spacing : float
        Knot spacing (pixels).

    Returns
    -------
    scipy.interpolate.BSpline
        ``s(r)`` for ``0 <= r <= (K + 2) * spacing``; ``.derivative()`` gives ``ds/dr``.
    """
    from scipy.interpolate import BSpline

    coefficients = np.asarray(coefficients, dtype=np.float64)
    return BSpline(_profile_knots(coefficients.size, spacing), _padded(coefficients), 3)


def render_features(params, x, y, reaches, *, jacobian: bool = False):
    """Image of round features on a flat base, and its Jacobian (compiled kernel).

    Parameters
    ----------
    params : (3 + F * (2 + K),) float64
        See :func:`feature_params`; slopes are ``-dz/dr`` (positive on a bump's flanks).
    x, y : (n,) float64
        Pixel coordinates (``x`` = column, ``y`` = minus row).
    reaches : sequence of float
        Each feature's radius (F of them).
    jacobian : bool, optional
        Also return the (n, P) derivatives of the image in ``params``.

    Returns
    -------
    (n,) float64, and (n, P) float64 if ``jacobian``
        ``k L_z max(0, (1 - tau . grad z) / sqrt(1 + |grad z|^2))``.
    """
    from shadeform.light._relief_kernel import render_features as kernel

    knots = (params.size - 3) // len(reaches) - 2 if reaches else 0
    image = np.empty(x.size)
    jac = np.zeros((x.size, params.size) if jacobian else (0, 0))
    kernel(
        np.ascontiguousarray(params, dtype=np.float64),
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.asarray(reaches, dtype=np.float64).reshape(-1),
        knots,
        image,
        jac,
        jacobian,
    )
    return (image, jac) if jacobian else image


def _render_features_reference(params, x, y, reaches, *, jacobian=False):
    """:func:`render_features` vectorised over pixels on scipy's B-spline basis (the reference of
    the compiled kernel)."""
    from scipy.interpolate import BSpline

    count = x.size
    level, tx, ty = params[:3]
    knots = (params.size - 3) // len(reaches) - 2 if reaches else 0
    gx = np.zeros(count)
    gy = np.zeros(count)
    parts = []
    for f, reach in enumerate(reaches):
        base = 3 + f * (2 + knots)
        dx, dy = x - params[base], y - params[base + 1]
        radius = np.hypot(dx, dy)
        near = np.nonzero(radius < reach)[0]
        r = np.maximum(radius[near], 1e-12)
        spline = profile_spline(params[base + 2 : base + 2 + knots], reach / (knots + 2))
        slope, rate = spline(r), spline.derivative()(r)
        # d s / d c_1..c_K: the basis functions of c_1..c_K, less c_-1's for c_1
        design = BSpline.design_matrix(r, spline.t, 3).toarray()
        basis = design[:, 2 : knots + 2].copy()
        basis[:, 0] -= design[:, 0]
        ux, uy = dx[near] / r, dy[near] / r
        # grad z = -s(r) u; overlapping features add their heights, so their gradients
        gx[near] -= slope * ux
        gy[near] -= slope * uy
        parts.append((base, near, r, slope, rate, basis, ux, uy))
    root = np.sqrt(1.0 + gx * gx + gy * gy)
    facing = 1.0 - tx * gx - ty * gy
    shade = facing / root
    lit = shade > 0
    image = level * np.where(lit, shade, 0.0)
    if not jacobian:
        return image
    jac = np.zeros((count, params.size))
    jac[:, 0] = np.where(lit, shade, 0.0)
    jac[:, 1] = np.where(lit, -level * gx / root, 0.0)
    jac[:, 2] = np.where(lit, -level * gy / root, 0.0)
    # d image / d grad z
    ex = np.where(lit, level * (-tx / root - facing * gx / root**3), 0.0)
    ey = np.where(lit, level * (-ty / root - facing * gy / root**3), 0.0)
    for base, near, r, slope, rate, basis, ux, uy in parts:
        qx, qy = ex[near], ey[near]
        # d(grad z)/d(centre) = s' u u^T + (s / r)(I - u u^T)
        radial = rate - slope / r
        along = slope / r
        jac[near, base] += qx * (radial * ux * ux + along) + qy * (radial * uy * ux)
        jac[near, base + 1] += qx * (radial * ux * uy) + qy * (radial * uy * uy + along)
        # d(grad z)/d c_j = -B_j(r) u
        jac[near, base + 2 : base + 2 + knots] += basis * -(qx * ux + qy * uy)[:, None]
    return image, jac


def _levenberg_marquardt(model, params, values, *, bounded, scale=None, iterations, tolerance):
    """Levenberg-Marquardt on ``sum(rho(model(p) - values))``, from ``params``.

    ``model(p, jacobian)`` returns the (n,) model, and its (n, P) Jacobian if ``jacobian``;
    ``rho(e) = e^2``, or with a ``scale`` the Cauchy loss ``scale^2 log(1 + e^2 / scale^2)``
    (by reweighted steps). Parameters where ``bounded`` (P,) is true are kept within
    ``+-_MAX_SLOPE``. At most ``iterations`` Jacobians; stops when a step lowers the cost by
    less than ``tolerance`` of it.

    Hand-written rather than :func:`scipy.optimize.least_squares`, which the tests hold it to:
    each step here solves the (P, P) normal equations, where scipy's trust-region step factors the
    whole (n, P) Jacobian by SVD. On the 93 largest joint fits of three bumps estimates of
    bench_light (up to 13,000 pixels x 99 parameters) scipy's ``trf`` took 29.9 s against 7.7 s
    and ended with a cost over 5% higher on 28 (benchmarks/results/light.md, "Tuning notes").
    """

    def loss(error):
        if scale is None:
            return float(error @ error), np.ones(error.size)
        z = (error / scale) ** 2
        return float(scale * scale * np.log1p(z).sum()), 1.0 / (1.0 + z)

    damping = 1e-3
    model_values, jac = model(params, True)
    error = model_values - values
    cost, weight = loss(error)
    for _ in range(iterations):
        root = np.sqrt(weight)
        scaled = jac * root[:, None]
        normal = scaled.T @ scaled
        gradient = scaled.T @ (error * root)
        diagonal = np.diag(normal) + 1e-12 * max(float(normal.diagonal().max()), 1e-300)
        while True:
            try:
                step = np.linalg.solve(normal + damping * np.diag(diagonal), gradient)
            except np.linalg.LinAlgError:
                damping *= 10.0
                continue
            trial = params - step
            trial = np.where(bounded, np.clip(trial, -_MAX_SLOPE, _MAX_SLOPE), trial)
            trial_error = model(trial, False) - values
            trial_cost, trial_weight = loss(trial_error)
            if trial_cost < cost:
                done = cost - trial_cost <= tolerance * cost
                params, error, cost, weight = trial, trial_error, trial_cost, trial_weight
                damping = max(damping / 3.0, 1e-12)
                break
            damping *= 4.0
            if damping > 1e10:
                return params
        if done:
            break
        jac = model(params, True)[1]
    return params


def fit_window(image, mask, centre, reach, level, across, iterations=40):
    """One round feature with its own light, fitted to the object pixels within ``reach`` of
    ``centre`` (x, y) from the image's ``level`` and a first ``across`` (``tau``).

    Returns
    -------
    params : (5 + PROFILE_KNOTS,) float64
        The fit (:func:`feature_params`).
    misfit : float
        Its mean squared residual as a share of the window's energy about ``level``; ``inf`` when
        the window holds too few pixels to fit.
    """
    x, y, values = pixels(image, mask)
    near = np.hypot(x - centre[0], y - centre[1]) <= reach
    x, y, values = x[near], y[near], values[near]
    if values.size < 4 * (PROFILE_KNOTS + 5):
        return feature_params(level, across, [(centre, np.zeros(PROFILE_KNOTS))]), math.inf
    slopes = _slopes_from_rings(
        values, np.hypot(x - centre[0], y - centre[1]), level, reach / (PROFILE_KNOTS + 2)
    )
    params = _levenberg_marquardt(
        lambda p, j: render_features(p, x, y, [reach], jacobian=j),
        feature_params(level, across, [(centre, slopes)]),
        values,
        bounded=np.arange(5 + PROFILE_KNOTS) >= 5,
        iterations=iterations,
        tolerance=1e-7,
    )
    miss = render_features(params, x, y, [reach]) - values
    spread = float(np.mean((values - level) ** 2))
    return params, float(np.mean(miss * miss)) / max(spread, 1e-300)


def _slopes_from_rings(values, radius, level, spacing):
    """First guess of a bump's slope coefficients: each ring's mean brightness read as ``n_z``
    (the light's lean averages out around a ring), ``s = sqrt(1 / n_z^2 - 1)``, at most 1.5."""
    index = np.rint(radius / spacing).astype(np.int64)
    keep = (index >= 1) & (index <= PROFILE_KNOTS)
    sums = np.bincount(index[keep], values[keep], minlength=PROFILE_KNOTS + 1)
    counts = np.bincount(index[keep], minlength=PROFILE_KNOTS + 1)
    mean = np.where(counts > 0, sums / np.maximum(counts, 1), level)[1:] / level
    return np.minimum(np.sqrt(np.maximum(1.0 / np.clip(mean, 0.05, 1.0) ** 2 - 1.0, 0.0)), 1.5)


def window_feature(params, reach, window, sign):
    """A window fit (:func:`fit_window` over ``reach``) as a feature of a joint fit whose ring
    window is ``window``: its centre, and its slope profile (times ``sign``, -1 to read it as a
    dimple under the opposite light) resampled on the joint fit's knots, 0 past ``reach``."""
    spacing = FEATURE_REACH * window / (PROFILE_KNOTS + 2)
    radius = spacing * np.arange(1, PROFILE_KNOTS + 1)
    slope = profile_spline(params[5:], reach / (PROFILE_KNOTS + 2))(np.minimum(radius, reach))
    return params[3:5].copy(), sign * np.where(radius < reach, slope, 0.0)


@dataclass(frozen=True, eq=False)
class Fit:
    """A joint fit of round features.

    Attributes
    ----------
    level : float
        ``k L_z``, the base's intensity.
    across : (2,) float64
        ``tau = L_xy / L_z``.
    features : list of (centre (2,), slopes (PROFILE_KNOTS,))
        Each feature's centre in ``(x, y)`` pixels and its slope coefficients.
    mse : float
        Mean squared residual.
    residual : (n,) float64
        Model minus image at the fitted pixels.
    """

    level: float
    across: np.ndarray
    features: list
    mse: float
    residual: np.ndarray


def fit_features(x, y, values, level, across, features, window, *, robust, iterations=40, tolerance=1e-7):
    """Joint fit of round features and the light, from a first guess.

    Parameters
    ----------
    x, y, values : (n,) float64
        The pixels to fit (:func:`pixels`).
    level : float
        First ``k L_z``.
    across : (2,) float64
        First ``tau``.
    features : list of (centre (2,), slopes (PROFILE_KNOTS,))
        First features, each reaching ``FEATURE_REACH * window``.
    window : float
        Ring window (pixels) of the search that found them.
    robust : bool
        Cauchy loss of scale ``_ROBUST_SCALE * level`` instead of least squares.
    iterations : int, optional
        Most evaluations of the model.
    tolerance : float, optional
        Relative decrease of the cost below which the fit stops.

    Returns
    -------
    Fit
    """
    reaches = [FEATURE_REACH * window] * len(features)
    params = feature_params(level, across, features)
    step = 2 + PROFILE_KNOTS
    # the slopes are bounded; the level, tau and the centres are not
    bounded = (np.arange(params.size) >= 3) & ((np.arange(params.size) - 3) % step >= 2)
    params = _levenberg_marquardt(
        lambda p, j: render_features(p, x, y, reaches, jacobian=j),
        params,
        values,
        bounded=bounded,
        scale=_ROBUST_SCALE * level if robust else None,
        iterations=iterations,
        tolerance=tolerance,
    )
    residual = render_features(params, x, y, reaches) - values
    fitted = [
        (params[3 + f * step : 5 + f * step], params[5 + f * step : 3 + (f + 1) * step])
        for f in range(len(features))
    ]
    return Fit(
        level=float(params[0]),
        across=params[1:3].copy(),
        features=fitted,
        mse=float(np.mean(residual * residual)),
        residual=residual,
    )
