"""Tests for shadeform.light: unit vectors, slant/tilt and their round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shadeform.errors import InputError
from shadeform.light import as_light, light_from_slant_tilt, parse_light, slant_tilt

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
        np.testing.assert_allclose(
            light_from_slant_tilt(20, 370), light_from_slant_tilt(20, 10), atol=1e-15
        )

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
        [([0, 1, 1], (45, 90)), ([1, 0, 1], (45, 0)), ([-1, 0, 1], (45, 180)),
         ([0, -3, math.sqrt(3)], (60, -90)), ([0, 0, 7], (0, 0))],
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
