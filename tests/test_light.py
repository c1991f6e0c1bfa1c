"""Tests for shadeform.light: unit vectors, slant/tilt and their round trips, and the round-feature
fit of a relief behind estimate_light (its helpers against slow references, the compiled kernel
against the scipy-based reference, and reliefs that are not the benchmark's)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.interpolate import BSpline

from helpers.surfaces import normals_of, pixel_xy
from shadeform import synth
from shadeform.errors import InputError
from shadeform.light import as_light, estimate_light, light_from_slant_tilt, parse_light, slant_tilt
from shadeform.light._relief_kernel import _spline_at
from shadeform.light.features import (
    PROFILE_KNOTS,
    _levenberg_marquardt,
    _render_features_reference,
    profile_spline,
    render_features,
)
from shadeform.light.relief import block_mean, ring_scores

S = math.sqrt(0.5)


class TestAsLight:
    def test_smoke(self):
        light = as_light([0, 0, 1])
        assert light.shape == (3,) and light.dtype == np.float64

    @pytest.mark.parametrize(
        ("given", "expected"),
        [
            ([0, 0, 5], [0, 0, 1]),
            ((3, 0, 4), [0.6, 0, 0.8]),
            (np.array([1, 1, 0.5], np.float32), [1 / 1.5, 1 / 1.5, 0.5 / 1.5]),
            ([-2, 2, 1], [-2 / 3, 2 / 3, 1 / 3]),
        ],
    )
    def test_values(self, given, expected):
        light = as_light(given)
        np.testing.assert_allclose(light, expected, atol=1e-15)
        assert np.linalg.norm(light) == pytest.approx(1.0, abs=1e-15)

    def test_does_not_alias_input(self):
        given = np.array([0.0, 0.0, 1.0])
        light = as_light(given)
        light[0] = 9
        assert given[0] == 0

    @pytest.mark.parametrize(
        ("given", "match"),
        [
            ([0, 0, 0], "zero vector"),
            ([0, 0, -1], "z <= 0"),
            ([1, 0, 0], "z <= 0"),
            ([0, np.nan, 1], "NaN or infinite"),
            ([0, 0, np.inf], "NaN or infinite"),
            ([0, 1], "three numbers"),
            ([[0, 0, 1]], "three numbers"),
            ("0,0,1", "three numbers"),
            (None, "three numbers"),
        ],
    )
    def test_errors(self, given, match):
        with pytest.raises(InputError, match=match) as err:
            as_light(given)
        assert "\n" not in str(err.value)


class TestLightFromSlantTilt:
    def test_smoke(self):
        light = light_from_slant_tilt(30, 60)
        assert light.shape == (3,) and np.linalg.norm(light) == pytest.approx(1)

    @pytest.mark.parametrize(
        ("slant", "tilt", "expected"),
        [
            (0, 0, [0, 0, 1]),
            (0, 123, [0, 0, 1]),
            (45, 90, [0, S, S]),
            (45, 0, [S, 0, S]),
            (45, 180, [-S, 0, S]),
            (60, -90, [0, -math.sqrt(3) / 2, 0.5]),
            (30, 45, [0.25 * math.sqrt(2), 0.25 * math.sqrt(2), math.sqrt(3) / 2]),
        ],
    )
    def test_values(self, slant, tilt, expected):
        np.testing.assert_allclose(light_from_slant_tilt(slant, tilt), expected, atol=1e-15)

    def test_tilt_is_periodic(self):
        np.testing.assert_allclose(light_from_slant_tilt(20, 370), light_from_slant_tilt(20, 10), atol=1e-15)

    @pytest.mark.parametrize(
        ("slant", "tilt"), [(90, 0), (120, 0), (-1, 0), (math.nan, 0), (10, math.inf), ("45", 0)]
    )
    def test_errors(self, slant, tilt):
        with pytest.raises(InputError):
            light_from_slant_tilt(slant, tilt)

    def test_slant_90_message(self):
        with pytest.raises(InputError, match=r"\[0, 90\)"):
            light_from_slant_tilt(90, 0)


class TestSlantTilt:
    def test_smoke(self):
        slant, tilt = slant_tilt([0, 0, 1])
        assert (slant, tilt) == (0.0, 0.0)
        assert isinstance(slant, float) and isinstance(tilt, float)

    @pytest.mark.parametrize(
        ("light", "expected"),
        [
            ([0, 1, 1], (45, 90)),
            ([1, 0, 1], (45, 0)),
            ([-1, 0, 1], (45, 180)),
            ([0, -3, math.sqrt(3)], (60, -90)),
            ([0, 0, 7], (0, 0)),
        ],
    )
    def test_values(self, light, expected):
        assert slant_tilt(light) == pytest.approx(expected, abs=1e-12)

    @pytest.mark.parametrize("slant", [0.0, 1e-6, 10.0, 45.0, 89.9])
    @pytest.mark.parametrize("tilt", [-179.0, -90.0, 0.0, 33.0, 180.0])
    def test_round_trip(self, slant, tilt):
        back_slant, back_tilt = slant_tilt(light_from_slant_tilt(slant, tilt))
        assert back_slant == pytest.approx(slant, abs=1e-9)
        if slant > 0:
            assert back_tilt == pytest.approx(tilt, abs=1e-7)

    def test_round_trip_vectors(self):
        rng = np.random.default_rng(3)
        for _ in range(50):
            light = as_light(rng.normal(size=3) * [1, 1, 0] + [0, 0, 0.1 + rng.random()])
            np.testing.assert_allclose(light_from_slant_tilt(*slant_tilt(light)), light, atol=1e-14)

    def test_errors(self):
        with pytest.raises(InputError, match="z <= 0"):
            slant_tilt([0, 0, -1])


class TestParseLight:
    @pytest.mark.parametrize(
        ("text", "expected"),
        [
            ("0,0,1", [0, 0, 1]),
            ("3, 0, 4", [0.6, 0, 0.8]),
            (" -1 ,1, 1.4142135623730951 ", [-0.5, 0.5, S]),
        ],
    )
    def test_values(self, text, expected):
        np.testing.assert_allclose(parse_light(text), expected, atol=1e-15)

    @pytest.mark.parametrize(
        ("text", "match"),
        [
            ("0,0", "three numbers"),
            ("0,0,1,1", "three numbers"),
            ("a,b,c", "not all numbers"),
            ("0 0 1", "three numbers"),
            ("", "three numbers"),
            ("0,0,-1", "z <= 0"),
            ("0,0,0", "zero vector"),
            ("nan,0,1", "NaN"),
        ],
    )
    def test_errors(self, text, match):
        with pytest.raises(InputError, match=match) as err:
            parse_light(text)
        assert "\n" not in str(err.value)

    def test_not_text(self):
        with pytest.raises(InputError, match="bad light"):
            parse_light([0, 0, 1])


# --- the relief fit: round features on a flat base (shadeform.light.features and .relief) ------


def _profile_reference(coefficients, spacing, radius):
    """The slope profile by scipy's B-spline: knots ``spacing`` apart from ``-3 * spacing``,
    coefficients c_-1 .. c_{K+4} with c_-1 = -c_1, c_0 = 0 and zeros past c_K."""
    knots = coefficients.size
    c = np.zeros(knots + 6)
    c[2 : knots + 2] = coefficients
    c[0] = -coefficients[0]
    spline = BSpline(spacing * np.arange(-3, knots + 7), c, 3)
    return spline(radius), spline.derivative()(radius)


def _render_reference(params, x, y, reaches):
    """Pixel by pixel: the gradients of the round features add, then the Lambertian shading."""
    level, tx, ty = params[:3]
    knots = PROFILE_KNOTS
    out = []
    for px, py in zip(x, y):
        gx = gy = 0.0
        for f, reach in enumerate(reaches):
            base = 3 + f * (2 + knots)
            dx, dy = px - params[base], py - params[base + 1]
            r = math.hypot(dx, dy)
            if 0 < r < reach:
                s = _profile_reference(
                    params[base + 2 : base + 2 + knots], reach / (knots + 2), np.array([r])
                )[0][0]
                gx -= s * dx / r
                gy -= s * dy / r
        out.append(level * max(0.0, (1 - tx * gx - ty * gy) / math.sqrt(1 + gx * gx + gy * gy)))
    return np.array(out)


def _random_features(rng, count=2):
    params = [0.9, 0.3, -0.2]
    for _ in range(count):
        params += [*rng.uniform(10, 30, 2) * (1, -1), *rng.uniform(-0.6, 0.6, PROFILE_KNOTS)]
    return np.array(params)


class TestBspline:
    def test_partition_of_unity(self):
        """A compiled kernel against its definition (a private name, deliberately): ``_spline_at``'s
        B-spline weights sum to 1 and their derivatives to 0; with all coefficients 1 (away from the
        mirrored c_-1 and the end) the profile is 1, its slope 0."""
        ones = np.ones(PROFILE_KNOTS)
        for t in np.linspace(0, 7.99, 200):
            assert sum(_spline_at(ones, 0, PROFILE_KNOTS, t)[3]) == pytest.approx(1.0, abs=1e-14)
        for t in np.linspace(2, PROFILE_KNOTS - 1.01, 200):
            value, rate, _, _ = _spline_at(ones, 0, PROFILE_KNOTS, t)
            assert value == pytest.approx(1.0, abs=1e-14)
            assert rate == pytest.approx(0.0, abs=1e-14)

    def test_profile_matches_scipy(self):
        rng = np.random.default_rng(1)
        coefficients = rng.normal(size=PROFILE_KNOTS)
        radius = np.linspace(0, 2.0 * (PROFILE_KNOTS + 2) - 1e-9, 301)
        spline = profile_spline(coefficients, 2.0)
        expected, expected_rate = _profile_reference(coefficients, 2.0, radius)
        np.testing.assert_allclose(spline(radius), expected, atol=1e-12)
        np.testing.assert_allclose(spline.derivative()(radius), expected_rate, atol=1e-12)

    def test_compiled_profile_matches_scipy(self):
        """A compiled kernel against its reference (a private name, deliberately): ``_spline_at``
        gives the profile and its slope of ``_profile_reference`` (scipy's B-spline)."""
        rng = np.random.default_rng(1)
        coefficients = rng.normal(size=PROFILE_KNOTS)
        radius = np.linspace(0, 2.0 * (PROFILE_KNOTS + 2) - 1e-9, 301)
        compiled = np.array([_spline_at(coefficients, 0, PROFILE_KNOTS, r / 2.0)[:2] for r in radius])
        expected, expected_rate = _profile_reference(coefficients, 2.0, radius)
        np.testing.assert_allclose(compiled[:, 0], expected, atol=1e-12)
        np.testing.assert_allclose(compiled[:, 1] / 2.0, expected_rate, atol=1e-12)

    def test_profile_is_level_at_the_top_and_ends(self):
        coefficients = np.ones(PROFILE_KNOTS)
        value = profile_spline(coefficients, 1.5)(np.array([0.0, 1.5 * (PROFILE_KNOTS + 2)]))
        np.testing.assert_allclose(value, 0.0, atol=1e-14)


class TestRenderFeatures:
    def test_matches_the_pixel_by_pixel_reference(self):
        rng = np.random.default_rng(2)
        params = _random_features(rng)
        x, y = rng.uniform(0, 40, 120), -rng.uniform(0, 40, 120)
        np.testing.assert_allclose(
            render_features(params, x, y, [18.0, 14.0]),
            _render_reference(params, x, y, [18.0, 14.0]),
            atol=1e-12,
        )

    def test_compiled_matches_the_vectorised_reference(self):
        """A compiled kernel against its reference (a private name, deliberately):
        ``render_features`` and its Jacobian are those of ``_render_features_reference``."""
        rng = np.random.default_rng(5)
        params = _random_features(rng, count=4)
        x, y = rng.uniform(0, 40, 500), -rng.uniform(0, 40, 500)
        reaches = [18.0, 14.0, 9.0, 22.0]
        image, jac = render_features(params, x, y, reaches, jacobian=True)
        expected_image, expected_jac = _render_features_reference(params, x, y, reaches, jacobian=True)
        np.testing.assert_allclose(image, expected_image, atol=1e-13)
        np.testing.assert_allclose(jac, expected_jac, atol=1e-13)
        np.testing.assert_allclose(render_features(params, x, y, reaches), expected_image, atol=1e-13)

    def test_jacobian_matches_finite_differences(self):
        rng = np.random.default_rng(3)
        params = _random_features(rng)
        x, y = rng.uniform(0, 40, 300), -rng.uniform(0, 40, 300)
        image, jac = render_features(params, x, y, [18.0, 14.0], jacobian=True)
        assert jac.shape == (300, params.size)
        lit = image > 1e-3  # away from the clipping kink
        for i in range(params.size):
            step = np.zeros(params.size)
            step[i] = 1e-6
            numeric = (
                render_features(params + step, x, y, [18.0, 14.0])
                - render_features(params - step, x, y, [18.0, 14.0])
            ) / 2e-6
            np.testing.assert_allclose(jac[lit, i], numeric[lit], atol=1e-7)

    def test_flat_base(self):
        x, y = np.arange(5.0), -np.arange(5.0)
        params = np.r_[0.8, 0.5, 0.1, 2.0, -2.0, np.zeros(PROFILE_KNOTS)]
        np.testing.assert_allclose(render_features(params, x, y, [10.0]), 0.8)


class TestLevenbergMarquardt:
    """The relief fit's solver against scipy's least_squares on the same problem."""

    @pytest.mark.parametrize("scale", [None, 0.02])
    def test_reaches_scipys_minimum(self, scale):
        """A kernel against its reference (a private name, deliberately): ``_levenberg_marquardt``
        reaches the minimum scipy's ``least_squares`` finds, with and without the robust loss."""
        from scipy.optimize import least_squares

        rng = np.random.default_rng(7)
        truth = np.r_[0.9, 0.3, -0.2, 20.0, -20.0, rng.uniform(0.0, 0.6, PROFILE_KNOTS)]
        x, y = pixel_xy((41, 41))
        x, y = x.ravel(), y.ravel()
        values = render_features(truth, x, y, [18.0]) + 0.01 * rng.normal(size=x.size)
        values[::50] += 0.3  # a few outliers, for the robust loss
        start = (
            truth * np.r_[1.0, 0.7, 0.7, 1.0, 1.0, np.full(PROFILE_KNOTS, 0.8)]
            + np.r_[0, 0, 0, 1.5, -1, np.zeros(PROFILE_KNOTS)]
        )
        bounded = np.arange(truth.size) >= 5
        found = _levenberg_marquardt(
            lambda p, j: render_features(p, x, y, [18.0], jacobian=j),
            start,
            values,
            bounded=bounded,
            scale=scale,
            iterations=200,
            tolerance=1e-14,
        )
        expected = least_squares(
            lambda p: render_features(p, x, y, [18.0]) - values,
            start,
            jac=lambda p: render_features(p, x, y, [18.0], jacobian=True)[1],
            loss="linear" if scale is None else "cauchy",
            f_scale=scale or 1.0,
            x_scale="jac",
            ftol=1e-14,
            xtol=1e-14,
            gtol=1e-14,
            max_nfev=2000,
        ).x
        np.testing.assert_allclose(found, expected, atol=1e-6)


class TestRingScores:
    def test_direct_sums(self):
        rng = np.random.default_rng(4)
        deviation = -0.3 * rng.random((24, 26))  # darker than the base, as round features are
        window = 4
        across, score, energy = ring_scores(deviation, window)
        for r0, c0 in [(12, 13), (3, 20), (20, 2)]:
            moment, weight, explained, total = np.zeros(2), 0.0, 0.0, 0.0
            for dr in range(-window - 1, window + 2):
                for dc in range(-window - 1, window + 2):
                    inside = 0 <= r0 + dr < 24 and 0 <= c0 + dc < 26
                    value = deviation[r0 + dr, c0 + dc] if inside else 0.0
                    if math.hypot(dr, dc) < window + 0.5:
                        total += value * value
            for k in range(1, window + 1):
                ring = [
                    (dr, dc)
                    for dr in range(-k - 1, k + 2)
                    for dc in range(-k - 1, k + 2)
                    if abs(math.hypot(dr, dc) - k) < 0.5
                ]
                vals = np.array(
                    [
                        deviation[r0 + dr, c0 + dc] if 0 <= r0 + dr < 24 and 0 <= c0 + dc < 26 else 0.0
                        for dr, dc in ring
                    ]
                )
                angles = np.array([math.atan2(-dr, dc) for dr, dc in ring])
                spread = float((np.cos(angles) ** 2).sum())
                mean = vals.mean()
                harmonic = np.array([(vals * np.cos(angles)).sum(), (vals * np.sin(angles)).sum()]) / spread
                explained += len(ring) * min(mean, 0.0) ** 2
                lean = math.sqrt(1 - min(max(1 + mean, 0.0), 1.0) ** 2)
                moment += spread * lean * harmonic
                weight += spread * lean * lean
            explained += float(moment @ moment) / weight
            assert energy[r0, c0] == pytest.approx(total, rel=1e-9)
            np.testing.assert_allclose(across[r0, c0], moment / weight, rtol=1e-8, atol=1e-12)
            assert score[r0, c0] == pytest.approx(-math.log(max(1 - explained / total, 1e-9)), rel=1e-8)

    def test_reads_the_light_at_a_round_features_centre(self):
        # one smooth cap z = h (1 - r^2 / rho^2)^2, lit from slant 30, tilt 120
        x, y = pixel_xy((61, 61))
        dx, dy = x - 30.0, y + 30.0
        q = np.clip(1 - (dx * dx + dy * dy) / 400.0, 0, None)
        grad = -4 * 8.0 * q / 400.0
        normals = normals_of(grad * dx, grad * dy)
        light = light_from_slant_tilt(30, 120)
        image = synth.render(normals, np.ones((61, 61), bool), light=light)
        across, score, _ = ring_scores(image / light[2] - 1.0, 8)
        np.testing.assert_allclose(across[30, 30], light[:2] / light[2], atol=0.02)
        assert score[30, 30] == score[22:39, 22:39].max()


class TestBlockMean:
    def test_values(self):
        image = np.arange(20.0).reshape(4, 5)
        mask = np.ones((4, 5), bool)
        mask[0, 0] = False
        small, small_mask = block_mean(image, mask, 2)
        np.testing.assert_allclose(small, [[3.0, 5.0], [13.0, 15.0]])
        np.testing.assert_array_equal(small_mask, [[False, True], [True, True]])


def _caps(size, sign=1.0):
    """Two smooth caps and a dimple, z = h (1 - r^2 / rho^2)^2, on a square base: round
    features, but not the gaussians of the synthetic bumps."""
    x, y = pixel_xy((size, size))
    x, y = x - (size - 1) / 2, y + (size - 1) / 2
    zx = np.zeros_like(x)
    zy = np.zeros_like(x)
    for x0, y0, height, rho in [(-0.2, 0.15, 0.12, 0.16), (0.18, -0.1, 0.08, 0.12), (0.15, 0.22, -0.06, 0.1)]:
        dx, dy, rho = x - x0 * size, y - y0 * size, rho * size
        q = np.clip(1 - (dx * dx + dy * dy) / rho**2, 0, None)
        grad = -4 * sign * height * size * q / rho**2
        zx += grad * dx
        zy += grad * dy
    mask = (np.abs(x) < 0.45 * size) & (np.abs(y) < 0.45 * size)
    return normals_of(zx, zy), mask


class TestRoundFeatureRelief:
    """estimate_light on a relief of round features other than the benchmark's gaussians."""

    @pytest.mark.parametrize(("slant", "tilt"), [(10, 30), (35, 200), (60, 300)])
    def test_caps(self, slant, tilt):
        normals, mask = _caps(128)
        light = light_from_slant_tilt(slant, tilt)
        est = estimate_light(synth.render(normals, mask, light=light), mask)
        assert est.evidence == "relief"
        assert est.info["relief_features"] == 3
        assert abs(est.slant - slant) <= 0.5
        assert abs((est.tilt - tilt + 180) % 360 - 180) <= 0.5

    def test_sunk_relief_reads_as_raised_unless_told(self):
        # two dimples and a cap: the raised twin lit from the other side explains it as well
        normals, mask = _caps(128, sign=-1.0)
        image = synth.render(normals, mask, light=light_from_slant_tilt(30, 40))
        convex = estimate_light(image, mask)
        concave = estimate_light(image, mask, convex=False)
        assert abs((convex.tilt - 220 + 180) % 360 - 180) <= 0.5
        assert abs((concave.tilt - 40 + 180) % 360 - 180) <= 0.5
        assert concave.slant == pytest.approx(30, abs=0.5)

    def test_a_ridge_is_not_made_of_round_features(self):
        # a straight ridge with rounded ends: no sum of a few round features explains it, so the
        # fit is not trusted and the spectrum's estimate is given
        x, y = pixel_xy((64, 64))
        x, y = x - 31.5, y + 31.5
        sigma = 4.0
        beyond = np.maximum(np.abs(x) - 16.0, 0.0)
        z = 6.0 * np.exp(-(y * y + beyond * beyond) / (2 * sigma**2))
        normals = normals_of(-z * beyond * np.sign(x) / sigma**2, -z * y / sigma**2)
        mask = (np.abs(x) < 29) & (np.abs(y) < 29)
        image = synth.render(normals, mask, light=light_from_slant_tilt(30, 200))
        est = estimate_light(image, mask)
        assert est.evidence == "relief-spectrum"
        assert "relief_features" not in est.info
