"""Compiled kernel of the relief fit: the image of round features on a flat base and its Jacobian.

:func:`shadeform.light.features.render_features` calls it; the fits of
:mod:`shadeform.light.relief` evaluate it thousands of times per estimate. One pixel at a time, it
evaluates each feature's slope profile (a uniform cubic B-spline) only at the four coefficients
that count there and writes the Jacobian's few nonzero columns directly. Its reference is
:func:`shadeform.light.features._render_features_reference`, the same model vectorised over pixels
on :class:`scipy.interpolate.BSpline` and its design matrix; the tests hold the two to 1e-13.
It stays hand-written because it is measurably faster than that reference: on the fits of
bench_light's bumps (180 to 13,000 pixels, 1 to 7 features; 2 cores, one BLAS thread) the image
alone 6-30x, the image and its Jacobian 3-20x, and two whole bumps estimates took 1.4 s with the
kernel against 4.8 s with the reference in its place (benchmarks/results/light.md, "Tuning notes").
"""

from __future__ import annotations

import math

import numba


@numba.njit(cache=True, inline="always")
def _spline_at(coefficients, base, knots, t):
    """Slope ``s`` and ``ds/dt`` of the B-spline of ``coefficients[base:base + knots]`` at
    ``t >= 0`` (knot units), with ``c_0 = 0``, ``c_-1 = -c_1`` and zeros past ``c_K``."""
    first = math.floor(t)
    u = t - first
    u2 = u * u
    u3 = u2 * u
    weights = ((1 - u) ** 3 / 6, (3 * u3 - 6 * u2 + 4) / 6, (-3 * u3 + 3 * u2 + 3 * u + 1) / 6, u3 / 6)
    slopes = (-((1 - u) ** 2) / 2, (3 * u2 - 4 * u) / 2, (-3 * u2 + 2 * u + 1) / 2, u2 / 2)
    value = 0.0
    rate = 0.0
    for k in range(4):
        j = first - 1 + k  # coefficient index, -1 .. K + 4
        if j == -1:
            c = -coefficients[base]
        elif 1 <= j <= knots:
            c = coefficients[base + j - 1]
        else:
            continue
        value += c * weights[k]
        rate += c * slopes[k]
    return value, rate, first, weights


@numba.njit(cache=True, inline="always")
def _feature_at(params, base, knots, reach, px, py):
    """Pixel ``(px, py)`` against the feature whose parameters start at ``base``: whether it is
    within ``reach``, its distance ``r`` (at least 1e-12) and unit direction ``(ux, uy)`` from the
    centre, the knot spacing, and the profile there (:func:`_spline_at`)."""
    dx = px - params[base]
    dy = py - params[base + 1]
    radius = math.hypot(dx, dy)
    r = max(radius, 1e-12)
    spacing = reach / (knots + 2)
    s, ds, first, weights = _spline_at(params, base + 2, knots, r / spacing)
    return radius < reach, r, dx / r, dy / r, spacing, s, ds, first, weights


@numba.njit(cache=True)
def render_features(params, x, y, reaches, knots, image, jac, want_jacobian):
    """Fill ``image`` (n,) and, if ``want_jacobian``, ``jac`` (n, P) (zeroed by the caller):
    ``k L_z max(0, (1 - tau . grad z) / sqrt(1 + |grad z|^2))`` with ``grad z`` the sum of the
    features' ``-s(r) u``; parameters as :func:`shadeform.light.features.feature_params`."""
    level = params[0]
    tx = params[1]
    ty = params[2]
    stride = 2 + knots
    for i in range(x.size):
        gx = 0.0
        gy = 0.0
        for f in range(reaches.size):
            near, _, ux, uy, _, s, _, _, _ = _feature_at(
                params, 3 + f * stride, knots, reaches[f], x[i], y[i]
            )
            if near:
                gx -= s * ux
                gy -= s * uy
        root = math.sqrt(1.0 + gx * gx + gy * gy)
        facing = 1.0 - tx * gx - ty * gy
        shade = facing / root
        if shade <= 0:
            image[i] = 0.0
            continue
        image[i] = level * shade
        if not want_jacobian:
            continue
        jac[i, 0] = shade
        jac[i, 1] = -level * gx / root
        jac[i, 2] = -level * gy / root
        # d image / d grad z
        ex = level * (-tx / root - facing * gx / root**3)
        ey = level * (-ty / root - facing * gy / root**3)
        for f in range(reaches.size):
            base = 3 + f * stride
            near, r, ux, uy, spacing, s, ds, first, weights = _feature_at(
                params, base, knots, reaches[f], x[i], y[i]
            )
            if not near:
                continue
            # d(grad z)/d(centre) = s' u u^T + (s / r)(I - u u^T)
            radial = ds / spacing - s / r
            along = s / r
            jac[i, base] = ex * (radial * ux * ux + along) + ey * (radial * uy * ux)
            jac[i, base + 1] = ex * (radial * ux * uy) + ey * (radial * uy * uy + along)
            # d(grad z)/d c_j = -B_j(r) u; c_-1 is -c_1
            outward = -(ex * ux + ey * uy)
            for k in range(4):
                j = first - 1 + k
                if j == -1:
                    jac[i, base + 2] -= weights[k] * outward
                elif 1 <= j <= knots:
                    jac[i, base + 1 + j] += weights[k] * outward
