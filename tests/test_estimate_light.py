"""Tests for shadeform.light.estimate_light: the light and k * albedo from one image.

The bars of issue 3 (slant within 3 degrees, tilt within 5 degrees where the slant is at least 10,
noise-free synthetic scenes, slants 0-60) are the first class and the relief class. Where one image
cannot tell the light (a cylinder lit along its axis, a bowl, a saddle) the tests pin down the
documented answer instead. The bars of issue 11 follow: the automatic mask (slant within 3 degrees
at slants 0, 20, 40 and 60 on the sphere, the ellipsoid and the bumps), highlights and clipping,
the confidence, degenerate masks refused, and the real photos of ``../shared/data/real`` (light
error median <= 8 degrees and worst <= 30 over the frontal photo of each object, and a few objects
with bars of their own).
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
AUTO_SLANTS = (0, 20, 40, 60)
ALL_TILTS = tuple(range(0, 360, 45))


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

    def test_unknown_cue(self, scene):
        with pytest.raises(
            InputError, match="unknown light estimation cue 'pentland'; choose one of: contour, round"
        ):
            estimate_light(scene.image, scene.mask, cue="pentland")

    def test_the_old_keyword_method_warns_and_gives_the_same_estimate(self, scene):
        new = estimate_light(scene.image, scene.mask, cue="round")
        with pytest.warns(DeprecationWarning, match="cue="):
            old = estimate_light(scene.image, scene.mask, method="round")
        assert old.evidence == new.evidence == "round"
        np.testing.assert_array_equal(old.light, new.light)
        assert (old.albedo, old.confidence) == (new.albedo, new.confidence)
        with pytest.raises(TypeError, match="both method= and cue="):
            estimate_light(scene.image, scene.mask, cue="round", method="contour")

    def test_estimation_methods_is_a_deprecated_alias(self):
        import shadeform.light as light
        from shadeform.light import estimate

        for module in (light, estimate):
            with pytest.warns(DeprecationWarning, match="ESTIMATION_CUES"):
                assert module.ESTIMATION_METHODS == module.ESTIMATION_CUES == ("contour", "round")

    def test_convex_must_be_a_bool(self, scene):
        with pytest.raises(InputError, match="convex"):
            estimate_light(scene.image, scene.mask, convex="yes")

    def test_messages_are_one_line(self, scene):
        with pytest.raises(InputError) as info:
            estimate_light(np.zeros_like(scene.image), scene.mask)
        assert "\n" not in str(info.value)


@pytest.fixture(scope="module")
def ball_errors():
    """Angular errors (degrees) of ``cue="round"`` on every 16th DiLiGenT ball photo."""
    from shadeform.io.images import load_image_rgb, load_mask

    names = (DILIGENT_BALL / "filenames.txt").read_text().split()
    directions = np.loadtxt(DILIGENT_BALL / "light_directions.txt")
    intensities = np.loadtxt(DILIGENT_BALL / "light_intensities.txt")
    mask = load_mask(DILIGENT_BALL / "mask.png")
    found = []
    for i in range(0, len(names), 16):
        gray = (load_image_rgb(DILIGENT_BALL / names[i]) / intensities[i]).mean(axis=2)
        est = estimate_light(gray, mask, cue="round")
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


def _angle(a, b) -> float:
    return math.degrees(math.acos(min(1.0, max(-1.0, float(np.dot(a, b))))))


class TestAutomaticMask:
    """The bar of issue 11: with the automatic mask (``mask=None``), which stops where the shading
    fades out, the slant within 3 degrees on the sphere, the ellipsoid and the bumps at slants 0,
    20, 40 and 60 (all eight tilts on the round scenes; four on the slower bumps, at 128)."""

    @pytest.mark.parametrize("slant", AUTO_SLANTS)
    @pytest.mark.parametrize("name", ["sphere", "ellipsoid"])
    def test_bar(self, name, slant):
        errors = []
        for tilt in (0,) if slant == 0 else ALL_TILTS:
            scene = synth.scene(name, size=256, light=light_from_slant_tilt(slant, tilt))
            est = estimate_light(scene.image)
            errors.append(abs(est.slant - slant))
            if slant >= 20:
                assert _tilt_error(est.tilt, tilt) <= TILT_BAR
        assert max(errors) <= SLANT_BAR

    @pytest.mark.parametrize("slant", AUTO_SLANTS)
    def test_bumps(self, slant):
        for tilt in (0,) if slant == 0 else (0, 90, 135, 270):
            scene = synth.scene("bumps", size=128, light=light_from_slant_tilt(slant, tilt))
            est = estimate_light(scene.image)
            assert abs(est.slant - slant) <= SLANT_BAR

    @pytest.mark.parametrize("slant", [40, 60])
    def test_the_shadow_edge_is_not_the_outline(self, slant):
        """The mask stops at the attached shadow's edge: the top of the mask is then off the top
        of the object, and the brightest point fixes k instead."""
        scene = synth.scene("sphere", size=256, light=light_from_slant_tilt(slant, 135))
        auto = estimate_light(scene.image)
        drawn = estimate_light(scene.image, scene.mask)
        assert auto.evidence == "limb-brightest"
        assert auto.info["shadow_edge"] > 0 and auto.info["shadowed_outline"] == 0
        assert drawn.evidence == "limb"
        assert drawn.info["shadowed_outline"] > 0 and drawn.info["shadow_edge"] == 0


class TestHighlightsAndClipping:
    """A Blinn-Phong highlight (clipped by the camera, as photos clip it) and a top clipped by
    over-exposure: the top and the brightest level are read past them."""

    @staticmethod
    def _errors(slants, mask_given, **render):
        found = []
        for slant in slants:
            for tilt in (0, 135, 270):
                scene = synth.scene("sphere", size=256, light=light_from_slant_tilt(slant, tilt))
                image = synth.render(scene.normals, scene.mask, light=scene.light, **render)
                est = estimate_light(image, scene.mask if mask_given else None)
                found.append((_angle(est.light, scene.light), est.confidence))
        return np.array(found)

    @pytest.mark.parametrize("mask_given", [True, False])
    def test_narrow_highlight(self, mask_given):
        errors = self._errors((20, 40, 60), mask_given, albedo=0.6, specular=0.3, shininess=300)
        assert errors[:, 0].max() <= SLANT_BAR

    def test_clipped_highlight(self):
        # the highlight clipped at 1 (a plateau) and its flanks: measured 1.8 with the mask drawn
        # on the outline, 6.4 with the automatic mask (where the brightest level fixes k)
        drawn = self._errors((20, 40, 60), True, albedo=0.6, specular=1.0, shininess=200)
        auto = self._errors((20, 40, 60), False, albedo=0.6, specular=1.0, shininess=200)
        assert drawn[:, 0].max() <= SLANT_BAR
        assert auto[:, 0].max() <= 8.0

    def test_clipped_top(self):
        drawn = self._errors((20, 40, 60), True, albedo=1.15)
        auto = self._errors((20, 40), False, albedo=1.15)
        assert drawn[:, 0].max() <= SLANT_BAR
        assert auto[:, 0].max() <= SLANT_BAR

    def test_clipped_top_lowers_the_confidence_where_it_misleads(self):
        # at slant 60 the automatic mask leaves the brightest level alone to fix k, and it is
        # clipped: 8 degrees off, and the confidence says so
        errors = self._errors((60,), False, albedo=1.15)
        assert errors[errors[:, 0] > 5.0, 1].max() < 0.5


class TestConfidence:
    def test_range_and_spread(self):
        scene = synth.scene("sphere", size=128, light=light_from_slant_tilt(30, 45))
        est = estimate_light(scene.image, scene.mask)
        assert isinstance(est.confidence, float) and 0.0 <= est.confidence <= 1.0
        assert est.confidence >= 0.9
        assert est.info["spread"] >= 0.0

    def test_matches_its_definition(self):
        from shadeform.light import CONFIDENCE_ANGLE

        scene = synth.scene("ellipsoid", size=128, light=light_from_slant_tilt(45, 200), noise=0.02)
        est = estimate_light(scene.image, scene.mask)
        expected = 1.0 - math.exp(-((CONFIDENCE_ANGLE / est.info["spread"]) ** 2))
        assert est.confidence == pytest.approx(expected)

    @pytest.mark.parametrize(("slant", "tilt"), [(30, 90), (45, 270)])
    def test_low_where_the_image_cannot_tell(self, slant, tilt):
        """A cylinder lit along its axis: the slant is only bounded by the brightest point."""
        est = _estimate("cylinder", slant, tilt)
        assert est.evidence == "limb-peak"
        assert est.confidence <= 0.2

    @pytest.mark.parametrize("name", ["sphere", "bumps"])
    def test_high_on_clean_scenes(self, name):
        est = _estimate(name, 40, 135, size=128)
        assert est.confidence >= 0.9

    def test_recorded_by_the_pipeline(self):
        from shadeform import reconstruct

        scene = synth.scene("sphere", size=64, light=light_from_slant_tilt(20, 60))
        rec = reconstruct(scene.image, mask=scene.mask, light="estimate")
        recorded = rec.info["light_estimate"]["confidence"]
        assert recorded == pytest.approx(estimate_light(scene.image, scene.mask).confidence)


class TestDegenerateMasks:
    """Masks that hold no outline or no inside are refused with one line saying what to do."""

    @pytest.fixture()
    def scene(self):
        return synth.scene("sphere", size=128, light=light_from_slant_tilt(30, 45))

    @pytest.mark.parametrize("width", [1, 2, 4])
    def test_strip(self, scene, width):
        mask = np.zeros_like(scene.mask)
        mask[60 : 60 + width, 10:120] = True
        with pytest.raises(InputError, match="pixels across") as info:
            estimate_light(scene.image, mask)
        assert "\n" not in str(info.value)

    def test_a_five_pixel_band_is_read(self, scene):
        mask = scene.mask.copy()
        mask[:, :] = False
        mask[40:45, 10:120] = True
        assert 0.0 <= estimate_light(scene.image, mask).confidence <= 1.0

    def test_outline_only(self, scene):
        from scipy import ndimage as ndi

        ring = scene.mask & ~ndi.binary_erosion(scene.mask, iterations=2)
        with pytest.raises(InputError, match="filled mask"):
            estimate_light(scene.image, ring)

    def test_background_mask(self, scene):
        """The mask is the background round the object: it touches the frame all round."""
        image = scene.image + 0.3 * ~scene.mask
        with pytest.raises(InputError, match="all four sides") as info:
            estimate_light(image, ~scene.mask)
        assert "\n" not in str(info.value)

    def test_frame_filled_by_an_object_that_is_no_relief(self, scene):
        with pytest.raises(InputError, match="all four sides"):
            estimate_light(scene.image, np.ones_like(scene.mask))


@pytest.fixture(scope="module")
def real_cases(real_data):
    """The frontal photo of each real object, with the estimate from its mask and from the
    automatic one: ``[(case, given, automatic)]``."""
    found = []
    for case in real_data.cases():
        found.append((case, estimate_light(case.image, case.mask), estimate_light(case.image)))
    return found


# one worker makes the estimates for all of the class's tests (they take 16 s)
@pytest.mark.xdist_group("real-light-estimates")
class TestRealPhotos:
    """The frontal photo of the six DiLiGenT and twelve MIT-Berkeley objects (``real_data``)."""

    def test_bar(self, real_cases, real_data):
        errors = np.array([real_data.light_error(given.light, case) for case, given, _ in real_cases])
        assert len(errors) == 18
        assert np.median(errors) <= 8.0
        assert errors.max() <= 30.0

    def test_bar_with_the_automatic_mask(self, real_cases, real_data):
        errors = np.array([real_data.light_error(auto.light, case) for case, _, auto in real_cases])
        assert np.median(errors) <= 8.0
        assert errors.max() <= 30.0

    @pytest.mark.parametrize(
        ("name", "bar"),
        # measured: cat 0.9, bear 3.1, reading 4.0 (slant 89 before issue 11), deer 0.6, pear 2.6
        [("cat", 3.0), ("bear", 5.0), ("reading", 8.0), ("deer", 3.0), ("pear", 5.0)],
    )
    def test_objects(self, real_cases, real_data, name, bar):
        case, given, _ = next(found for found in real_cases if found[0].name == name)
        assert real_data.light_error(given.light, case) <= bar

    def test_no_grazing_light_on_a_frontal_photo(self, real_cases):
        """Every light of these photos is within 17 degrees of the viewer; dark paint at the top
        (``reading``) or highlights must not send the estimate to the horizon."""
        for _, given, auto in real_cases:
            assert given.slant < 45.0 and auto.slant < 45.0

    def test_confidence_is_lowest_where_the_error_is_largest(self, real_cases, real_data):
        errors = np.array([real_data.light_error(given.light, case) for case, given, _ in real_cases])
        confidence = np.array([given.confidence for _, given, _ in real_cases])
        assert confidence[errors > 15.0].max() < np.median(confidence)

    @pytest.mark.parametrize(
        ("name", "bar", "confidence"),
        # measured: deer 3.4, cup1 12.2, frog1 35.4 (confidence 0.14), panther 4.3 (0.99); before
        # the outline's loose light was weighed against the brightest point: 72.6, 62.1, 88.5
        # (confidence 0.94, 0.28, 1.0) and 4.3
        [
            ("deer", 6.0, None),
            ("cup1", 15.0, None),
            ("frog1", 40.0, (0.0, 0.2)),
            ("panther", 6.0, (0.9, 1.0)),
        ],
    )
    def test_painted_raw_photo(self, real_data, name, bar, confidence):
        """The raw MIT-Berkeley photos keep their paint: a dark-painted top under a white foot
        read from the brightest point is a grazing light. Where the outline's own light is too
        loose to answer alone, the surer of the two is kept, and the confidence says how sure."""
        case = real_data.mit(name, raw=True)
        estimate = estimate_light(case.image, case.mask)
        assert real_data.light_error(estimate.light, case) <= bar
        if confidence is not None:
            assert confidence[0] <= estimate.confidence <= confidence[1]
