"""Tests for shadeform.light.estimate_light: the light and k * albedo from one image.

The bars of issue 3 (slant within 3 degrees, tilt within 5 degrees where the slant is at least 10,
noise-free synthetic scenes, slants 0-60) are the first class and the relief class. Where one image
cannot tell the light (a cylinder lit along its axis, a bowl, a saddle) the tests pin down the
documented answer instead.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from shadeform import synth
from shadeform.errors import InputError
from shadeform.light import LightEstimate, estimate_light, light_from_slant_tilt, slant_tilt

SLANT_BAR = 3.0
TILT_BAR = 5.0
SLANTS = (10, 20, 30, 45, 60)
TILTS = (0, 135, 270)
DILIGENT_BALL = Path(__file__).resolve().parents[2] / "shared" / "data" / "diligent-ball"


def _tilt_error(estimated: float, true: float) -> float:
    return abs((estimated - true + 180.0) % 360.0 - 180.0)


def _estimate(name, slant, tilt, *, noise=0.0, size=256, **kwargs):
    scene = synth.scene(name, size=size, light=light_from_slant_tilt(slant, tilt), noise=noise)
    return estimate_light(scene.image, scene.mask, **kwargs)


def _lights(slants=SLANTS, tilts=TILTS):
    return [(0, 0)] + [(s, t) for s in slants for t in tilts]


class TestOccludingContour:
    """Objects bounded by occluding contours: the bar, on every light."""

    @pytest.mark.parametrize("name", ["sphere", "ellipsoid", "vase"])
    @pytest.mark.parametrize(("slant", "tilt"), _lights())
    def test_bar(self, name, slant, tilt):
        est = _estimate(name, slant, tilt)
        assert abs(est.slant - slant) <= SLANT_BAR
        if slant >= 10:
            assert _tilt_error(est.tilt, tilt) <= TILT_BAR
        assert est.evidence == "limb"

    @pytest.mark.parametrize(("slant", "tilt"), _lights(tilts=(0, 180)))
    def test_cylinder_lit_across_its_axis(self, slant, tilt):
        est = _estimate("cylinder", slant, tilt)
        assert abs(est.slant - slant) <= SLANT_BAR
        if slant >= 10:
            assert _tilt_error(est.tilt, tilt) <= TILT_BAR

    @pytest.mark.parametrize(("slant", "tilt"), [(30, 60), (45, 135), (60, 210)])
    def test_cylinder_lit_along_its_axis_gives_the_least_slanted_light(self, slant, tilt):
        # I = k (n . L) with n in the x-z plane: (k, L_y) trade off exactly, so only the light's
        # projection on that plane is seen; the estimate is that projection (L_y = 0)
        x, _, z = light_from_slant_tilt(slant, tilt)
        seen_slant, seen_tilt = slant_tilt((x, 0.0, z))
        est = _estimate("cylinder", slant, tilt)
        assert abs(est.slant - seen_slant) <= SLANT_BAR
        assert _tilt_error(est.tilt, seen_tilt) <= TILT_BAR


class TestTiltedRim:
    """A bowl and a saddle: the edge is a rim of one slant, not an occluding contour."""

    @pytest.mark.parametrize(("slant", "tilt"), _lights(tilts=(60, 210)))
    def test_bowl_meets_the_bar_when_told_it_is_concave(self, slant, tilt):
        est = _estimate("bowl", slant, tilt, convex=False)
        assert abs(est.slant - slant) <= SLANT_BAR
        if slant >= 10:
            assert _tilt_error(est.tilt, tilt) <= TILT_BAR
        assert est.evidence == "rim"

    @pytest.mark.parametrize("slant", [10, 45])
    def test_bowl_looks_like_a_dome_lit_from_the_other_side(self, slant):
        est = _estimate("bowl", slant, 60)
        assert _tilt_error(est.tilt, 60 + 180) <= TILT_BAR

    @pytest.mark.parametrize(("slant", "tilt"), _lights(tilts=(30, 250)))
    def test_saddle_slant_and_mirrored_tilt(self, slant, tilt):
        # z = (x^2 - y^2) / 2s under tilt t gives the image of a dome under tilt 180 - t
        est = _estimate("saddle", slant, tilt)
        assert abs(est.slant - slant) <= SLANT_BAR
        if slant >= 10:
            assert _tilt_error(est.tilt, 180 - tilt) <= TILT_BAR


class TestRelief:
    """Bumps and a dent on a flat base facing the camera: round features fitted with the light."""

    @pytest.mark.parametrize(("slant", "tilt"), _lights())
    def test_bar(self, slant, tilt):
        est = _estimate("bumps", slant, tilt, size=128)
        assert est.evidence == "relief"
        assert abs(est.slant - slant) <= SLANT_BAR
        if slant >= 10:
            assert _tilt_error(est.tilt, tilt) <= TILT_BAR
        assert est.albedo == pytest.approx(1.0, abs=0.02)


class TestNoise:
    """2% Gaussian noise (seed 0): not a bar, a guard on the reported numbers."""

    @pytest.mark.parametrize("name", ["sphere", "ellipsoid", "vase", "bumps"])
    @pytest.mark.parametrize("slant", [10, 60])
    def test_scenes(self, name, slant):
        est = _estimate(name, slant, 135, noise=0.02)
        assert abs(est.slant - slant) <= 4.0
        assert _tilt_error(est.tilt, 135) <= 6.0
        assert est.albedo == pytest.approx(1.0, abs=0.08)


class TestResult:
    def test_shape(self):
        est = _estimate("sphere", 30, 45)
        assert isinstance(est, LightEstimate)
        assert dataclasses.is_dataclass(est)
        assert est.light.shape == (3,) and est.light.dtype == np.float64
        assert np.linalg.norm(est.light) == pytest.approx(1.0)
        assert est.light[2] > 0
        assert isinstance(est.albedo, float) and isinstance(est.slant, float)
        assert isinstance(est.tilt, float) and isinstance(est.info, dict)
        assert -180 < est.tilt <= 180

    def test_frozen_and_read_only(self):
        est = _estimate("sphere", 30, 45)
        with pytest.raises(dataclasses.FrozenInstanceError):
            est.slant = 0.0
        with pytest.raises(ValueError):
            est.light[0] = 1.0

    def test_slant_tilt_match_the_vector(self):
        est = _estimate("ellipsoid", 45, -120)
        slant, tilt = slant_tilt(est.light)
        assert slant == pytest.approx(est.slant, abs=1e-9)
        assert tilt == pytest.approx(est.tilt, abs=1e-9)

    def test_frontal_light_has_zero_tilt(self):
        est = _estimate("sphere", 0, 0)
        assert est.slant < 1.0
        if est.slant == 0:
            assert est.tilt == 0.0

    @pytest.mark.parametrize("scale", [0.25, 1.0, 40.0])
    def test_albedo_follows_the_image_scale(self, scale):
        scene = synth.scene("sphere", light=light_from_slant_tilt(30, 45))
        est = estimate_light(scene.image * scale, scene.mask)
        assert est.albedo == pytest.approx(scale, rel=0.02)
        assert est.slant == pytest.approx(30, abs=SLANT_BAR)

    def test_integer_images_are_scaled(self):
        scene = synth.scene("sphere", light=light_from_slant_tilt(30, 45))
        est = estimate_light(np.round(scene.image * 65535).astype(np.uint16), scene.mask)
        assert est.albedo == pytest.approx(1.0, rel=0.02)

    def test_concave_turns_the_tilt(self):
        scene = synth.scene("sphere", light=light_from_slant_tilt(30, 45))
        convex = estimate_light(scene.image, scene.mask)
        concave = estimate_light(scene.image, scene.mask, convex=False)
        assert concave.slant == pytest.approx(convex.slant)
        assert _tilt_error(concave.tilt, convex.tilt + 180) < 1e-9

    def test_object_cut_by_the_frame(self):
        scene = synth.scene("sphere", light=light_from_slant_tilt(30, 120))
        est = estimate_light(scene.image[:, :150], scene.mask[:, :150])
        assert abs(est.slant - 30) <= SLANT_BAR
        assert _tilt_error(est.tilt, 120) <= TILT_BAR

    def test_relief_filling_the_frame(self):
        scene = synth.scene("bumps", light=light_from_slant_tilt(45, 30))
        image = np.where(scene.mask, scene.image, np.median(scene.image[scene.mask]))
        est = estimate_light(image, np.ones(image.shape, dtype=bool))
        assert est.evidence == "relief"
        assert abs(est.slant - 45) <= SLANT_BAR
        assert _tilt_error(est.tilt, 30) <= TILT_BAR


class TestBadInput:
    @pytest.fixture()
    def scene(self):
        return synth.scene("sphere", size=64, light=light_from_slant_tilt(30, 45))

    def test_empty_mask(self, scene):
        with pytest.raises(InputError, match="empty"):
            estimate_light(scene.image, np.zeros_like(scene.mask))

    def test_black_image(self, scene):
        with pytest.raises(InputError, match="black"):
            estimate_light(np.zeros_like(scene.image), scene.mask)

    @pytest.mark.parametrize(
        ("image", "mask", "message"),
        [
            (np.ones((64, 64, 3)), np.ones((64, 64), bool), "one channel"),
            (np.ones((64, 64)), np.ones((32, 64), bool), "shape"),
            (np.full((64, 64), np.nan), np.ones((64, 64), bool), "NaN"),
            (-np.ones((64, 64)), np.ones((64, 64), bool), "negative"),
            (np.ones((64, 64), dtype=bool), np.ones((64, 64), bool), "numbers"),
        ],
    )
    def test_malformed(self, image, mask, message):
        with pytest.raises(InputError, match=message):
            estimate_light(image, mask)

    def test_tiny_object(self, scene):
        mask = np.zeros_like(scene.mask)
        mask[30:35, 30:35] = True
        with pytest.raises(InputError, match="pixels"):
            estimate_light(scene.image, mask)

    def test_object_filling_the_frame_without_a_base(self):
        ramp = np.add.outer(np.linspace(0.2, 0.8, 64), np.linspace(0.0, 0.1, 64))
        with pytest.raises(InputError, match="frame"):
            estimate_light(ramp, np.ones(ramp.shape, dtype=bool))

    def test_unknown_method(self, scene):
        with pytest.raises(InputError, match="contour, round"):
            estimate_light(scene.image, scene.mask, method="pentland")

    def test_convex_must_be_a_bool(self, scene):
        with pytest.raises(InputError, match="convex"):
            estimate_light(scene.image, scene.mask, convex="yes")

    def test_messages_are_one_line(self, scene):
        with pytest.raises(InputError) as info:
            estimate_light(np.zeros_like(scene.image), scene.mask)
        assert "\n" not in str(info.value)


@pytest.fixture(scope="module")
def ball_errors():
    """Angular errors (degrees) of ``method="round"`` on every 16th DiLiGenT ball photo."""
    from shadeform.io.images import load_image_rgb, load_mask

    names = (DILIGENT_BALL / "filenames.txt").read_text().split()
    directions = np.loadtxt(DILIGENT_BALL / "light_directions.txt")
    intensities = np.loadtxt(DILIGENT_BALL / "light_intensities.txt")
    mask = load_mask(DILIGENT_BALL / "mask.png")
    found = []
    for i in range(0, len(names), 16):
        gray = (load_image_rgb(DILIGENT_BALL / names[i]) / intensities[i]).mean(axis=2)
        est = estimate_light(gray, mask, method="round")
        truth = directions[i] / np.linalg.norm(directions[i])
        found.append(math.degrees(math.acos(min(1.0, float(est.light @ truth)))))
    return np.array(found)


@pytest.mark.skipif(not DILIGENT_BALL.is_dir(), reason=f"DiLiGenT ball images not found at {DILIGENT_BALL}")
def test_diligent_ball_round_method(ball_errors):
    """Real photos of a glossy ball under calibrated lights, each channel divided by its light's
    intensity; the contour method's slant is biased low there (the paint darkens toward the
    contour), the round one is not."""
    assert ball_errors.mean() <= 2.0
    assert ball_errors.max() <= 4.0
