"""Tests for shadeform.preprocess: object masks and filters that keep the background out."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage as ndi

from shadeform import synth
from shadeform.errors import InputError
from shadeform.preprocess import (
    FILTER_KINDS,
    Filter,
    apply_filter,
    image_detail,
    noise_level,
    object_mask,
    parse_filter,
)

N, R = 256, 100


def lambertian_sphere(n=N, radius=R):
    """Sphere lit from the camera (I = n_z) on a black background; returns image, disk, distance."""
    rows, cols = np.mgrid[0:n, 0:n]
    centre = (n - 1) / 2
    distance = np.hypot(rows - centre, cols - centre)
    disk = distance < radius
    image = np.where(disk, np.sqrt(np.clip(1 - (distance / radius) ** 2, 0, 1)), 0.0)
    return image, disk, distance


def iou(a, b):
    return (a & b).sum() / (a | b).sum()


def disk_mask(n, radius, centre=None):
    rows, cols = np.mgrid[0:n, 0:n]
    c = (n - 1) / 2 if centre is None else centre
    return np.hypot(rows - c, cols - c) < radius


class TestObjectMask:
    def test_smoke(self):
        image, _, _ = lambertian_sphere()
        mask = object_mask(image)
        assert mask.shape == (N, N) and mask.dtype == bool

    @pytest.mark.parametrize("noise", [0.0, 0.01])
    @pytest.mark.parametrize("clip", [False, True])
    def test_sphere_within_one_pixel_rim(self, noise, clip):
        image, disk, distance = lambertian_sphere()
        image = image + np.random.default_rng(7).normal(0, noise, image.shape)
        if clip:
            image = np.clip(image, 0, 1)
        mask = object_mask(image)
        assert iou(mask, disk) > 0.98
        # Wrong pixels only in the ring R - 1 < distance < R + 1, including the dim rim.
        assert mask[distance <= R - 1].all()
        assert not mask[distance >= R + 1].any()

    def test_otsu_alone_would_lose_the_rim(self):
        # The reason for hysteresis: Otsu's threshold cuts deep into a Lambertian sphere.
        from skimage.filters import threshold_otsu

        image, disk, _ = lambertian_sphere()
        assert iou(image > threshold_otsu(image), disk) < 0.95
        assert iou(object_mask(image), disk) > 0.99

    def test_8bit_sphere(self):
        image, disk, _ = lambertian_sphere()
        mask = object_mask(np.round(image * 255) / 255)
        assert iou(mask, disk) > 0.98

    def test_holes_filled(self):
        image, disk, distance = lambertian_sphere()
        image[np.abs(distance - 40) < 3] = 0.0  # a black ring inside the object
        image[120:126, 120:126] = 0.0  # and a black spot in the middle
        assert iou(object_mask(image, fill_holes=False), disk) < 0.97
        mask = object_mask(image)
        assert iou(mask, disk) > 0.99 and mask[122, 122]

    def test_largest_kept(self):
        image = np.zeros((120, 200))
        image[disk_mask(120, 30, centre=60)[:, :120].nonzero()] = 0.8  # big blob at the left
        small = np.zeros((120, 200), dtype=bool)
        small[50:60, 160:170] = True
        image[small] = 0.9  # a small, brighter blob at the right
        mask = object_mask(image)
        assert not mask[small].any()
        assert mask[60, 60] and mask.sum() == (image == 0.8).sum()
        both = object_mask(image, largest=False)
        assert both[small].all() and both[60, 60]

    def test_threshold_given(self):
        image = np.array([[0.0, 0.2, 0.4], [0.6, 0.8, 1.0], [0.1, 0.3, 0.5]])
        expected = image > 0.45
        np.testing.assert_array_equal(
            object_mask(image, threshold=0.45, fill_holes=False, largest=False), expected
        )
        with pytest.raises(InputError, match="no pixel is above threshold 1"):
            object_mask(image, threshold=1.0)
        with pytest.raises(InputError, match="finite number"):
            object_mask(image, threshold=float("nan"))

    def test_black_image(self):
        with pytest.raises(InputError, match="no object found: the image is black") as err:
            object_mask(np.zeros((10, 10)))
        assert "\n" not in str(err.value)

    def test_constant_image(self):
        with pytest.raises(InputError, match="constant"):
            object_mask(np.full((10, 10), 0.4))

    def test_bad_shapes(self):
        with pytest.raises(InputError, match="2-D"):
            object_mask(np.ones((4, 4, 2)))  # grey (H, W) or colour (H, W, 3) only
        image = np.ones((5, 5))
        image[2, 2] = np.nan
        with pytest.raises(InputError, match="NaN"):
            object_mask(image)


class TestParseFilter:
    @pytest.mark.parametrize(
        ("spec", "expected"),
        [
            (None, Filter("none", 0.0)),
            ("none", Filter("none", 0.0)),
            ("gaussian:2", Filter("gaussian", 2.0)),
            (" Gaussian : 1.5 ", Filter("gaussian", 1.5)),
            ("mean:1", Filter("mean", 1.0)),
            ("median:3", Filter("median", 3.0)),
            ("minimum:2", Filter("minimum", 2.0)),
        ],
    )
    def test_values(self, spec, expected):
        assert parse_filter(spec) == expected

    @pytest.mark.parametrize("kind", FILTER_KINDS)
    def test_round_trip(self, kind):
        f = Filter(kind, 0.0 if kind == "none" else 2.0)
        assert parse_filter(str(f)) == f
        assert parse_filter(f) is f

    def test_frozen(self):
        f = Filter("median", 2)
        with pytest.raises(AttributeError):
            f.size = 3

    @pytest.mark.parametrize(
        "spec", ["gauss:2", "gaussian", "median:", "median:two", "mean:1.5", "gaussian:-1", "", 3]
    )
    def test_errors(self, spec):
        with pytest.raises(InputError) as err:
            parse_filter(spec)
        message = str(err.value)
        assert "\n" not in message
        assert any(word in message for word in ("KIND:SIZE", "whole-number", ">= 0"))

    def test_error_lists_kinds(self):
        with pytest.raises(InputError, match="none, gaussian, mean, median, minimum"):
            parse_filter("blur:2")
        with pytest.raises(InputError, match="unknown filter kind"):
            Filter("blur", 1)


class TestApplyFilter:
    SPECS = ["gaussian:1", "gaussian:3", "mean:1", "mean:4", "median:1", "median:3", "minimum:2"]

    def test_smoke(self):
        image = np.random.default_rng(0).random((20, 30)).astype(np.float32)
        out = apply_filter(image, None, "gaussian:1")
        assert out.shape == (20, 30) and out.dtype == np.float64

    @pytest.mark.parametrize("spec", SPECS)
    def test_constant_stays_constant_at_the_edge(self, spec):
        # The bleeding test: a dark background must not darken the object's edge.
        mask = disk_mask(64, 20)
        image = np.where(mask, 0.7, 0.0)
        out = apply_filter(image, mask, spec)
        np.testing.assert_allclose(out[mask], 0.7, rtol=1e-12)
        np.testing.assert_array_equal(out[~mask], 0.0)

    def test_plain_filters_would_bleed(self):
        # Sanity check of the test above: without masking the edge does darken.
        mask = disk_mask(64, 20)
        image = np.where(mask, 0.7, 0.0)
        assert ndi.gaussian_filter(image, 1)[mask].min() < 0.5
        assert ndi.minimum_filter(image, 5)[mask].min() == 0.0

    def test_gaussian_keeps_a_ramp_in_the_interior(self):
        mask = disk_mask(80, 35)
        rows, cols = np.mgrid[0:80, 0:80]
        ramp = 0.2 + 0.004 * cols - 0.003 * rows
        out = apply_filter(np.where(mask, ramp, 0.0), mask, "gaussian:2")
        # Beyond the kernel's reach: its square support has radius 4 sigma = 8.
        interior = ndi.binary_erosion(mask, np.ones((3, 3), bool), iterations=9)
        np.testing.assert_allclose(out[interior], ramp[interior], atol=1e-12)

    def test_mean_by_hand(self):
        image = np.arange(9.0).reshape(3, 3)
        out = apply_filter(image, None, "mean:1")
        assert out[1, 1] == pytest.approx(4.0)
        assert out[0, 0] == pytest.approx((0 + 1 + 3 + 4) / 4)
        assert out[0, 1] == pytest.approx((0 + 1 + 2 + 3 + 4 + 5) / 6)

    def test_median_removes_salt(self):
        image = np.full((30, 30), 0.5)
        salt = np.zeros((30, 30), dtype=bool)
        salt[3::6, 2::5] = True  # isolated pixels
        image[salt] = 1.0
        mask = disk_mask(30, 14)
        out = apply_filter(image, mask, "median:1")
        np.testing.assert_array_equal(out[mask], 0.5)
        np.testing.assert_array_equal(out[~mask], image[~mask])

    def test_minimum_by_hand(self):
        image = np.array([[0.0, 3, 8, 6], [0.0, 9, 7, 5], [0.0, 4, 2, 1]])
        mask = np.ones((3, 4), dtype=bool)
        mask[:, 0] = False  # column 0 is background: it takes the values of column 1
        expected = np.array([[0.0, 3, 3, 5], [0.0, 2, 1, 1], [0.0, 2, 1, 1]])
        np.testing.assert_array_equal(apply_filter(image, mask, "minimum:1"), expected)
        # Whole image, 'nearest' border.
        full = np.array([[5.0, 3, 8], [1, 9, 7], [6, 4, 2]])
        np.testing.assert_array_equal(
            apply_filter(full, None, Filter("minimum", 1)),
            [[1, 1, 3], [1, 1, 2], [1, 1, 2]],
        )

    @pytest.mark.parametrize("spec", [None, "none", "gaussian:0", "median:0"])
    def test_none_is_identity(self, spec):
        image = np.random.default_rng(1).random((9, 11))
        mask = image > 0.3
        out = apply_filter(image, mask, spec)
        np.testing.assert_array_equal(out, image)
        assert out is not image

    @pytest.mark.parametrize("spec", SPECS)
    def test_outside_values_never_leak(self, spec):
        mask = disk_mask(40, 12)
        image = np.where(mask, 0.3, np.nan)  # NaN outside must neither leak in nor be needed
        out = apply_filter(image, mask, spec)
        np.testing.assert_allclose(out[mask], 0.3, rtol=1e-12)
        assert np.isnan(out[~mask]).all()

    def test_errors(self):
        image = np.ones((5, 5))
        with pytest.raises(InputError, match="mask has shape"):
            apply_filter(image, np.ones((4, 5), dtype=bool), "mean:1")
        with pytest.raises(InputError, match="mask is empty"):
            apply_filter(image, np.zeros((5, 5), dtype=bool), "mean:1")
        with pytest.raises(InputError, match="2-D"):
            apply_filter(np.ones((5, 5, 3)), None, "mean:1")
        with pytest.raises(InputError, match="KIND:SIZE"):
            apply_filter(image, None, "blur:1")
        bad = image.copy()
        bad[2, 2] = np.nan
        with pytest.raises(InputError, match="inside the mask"):
            apply_filter(bad, None, "mean:1")

    @pytest.mark.parametrize("size", [9, 1e9, 1e300])
    @pytest.mark.parametrize("kind", ["gaussian", "mean", "median", "minimum"])
    def test_larger_than_the_image(self, kind, size):
        # refused before scipy allocates a kernel of that size (1e9: MemoryError, 1e300: OverflowError)
        with pytest.raises(
            InputError, match=r"larger than the image \(8x5 pixels\); choose a size of at most 8"
        ):
            apply_filter(np.ones((5, 8)), None, Filter(kind, size))
        assert apply_filter(np.ones((5, 8)), None, Filter(kind, 8)).shape == (5, 8)


class TestNoiseLevel:
    @pytest.mark.parametrize("noise", [0.01, 0.03])
    @pytest.mark.parametrize("name", ["sphere", "vase", "bumps"])
    def test_recovers_the_added_noise(self, name, noise):
        # lit off-axis so that no flat part sits at white, where the camera clips half the noise
        scene = synth.scene(name, size=128, noise=noise, light=(0.3, 0.2, 0.93))
        assert noise_level(scene.image, scene.mask) == pytest.approx(noise, rel=0.1)

    def test_smooth_shading_is_nearly_noise_free(self):
        scene = synth.scene("vase", size=256)
        assert noise_level(scene.image, scene.mask) < 0.001  # measured 0.00025: curvature leaks in

    def test_too_thin_an_object(self):
        mask = np.zeros((20, 20), bool)
        mask[5:9, :] = True
        assert noise_level(np.where(mask, 0.5, 0.0), mask) == 0.0


class TestImageDetail:
    @pytest.mark.parametrize("name", ["sphere", "vase", "bumps"])
    def test_noise_alone_leaves_next_to_no_outliers(self, name):
        scene = synth.scene(name, size=128, noise=0.01, light=(0.3, 0.2, 0.93))
        detail = image_detail(scene.image, scene.mask)
        assert detail.noise == noise_level(scene.image, scene.mask)
        assert detail.outliers < 0.003  # Gaussian noise: 6e-5; the bumps' sharp edges add a little

    def test_paint_and_highlights_are_outliers(self):
        scene = synth.scene("sphere", size=128, noise=0.01, light=(0.3, 0.2, 0.93))
        rng = np.random.default_rng(1)
        image = scene.image.copy()
        specks = rng.random(image.shape) < 0.02  # flecks of darker paint, glints
        image[specks] *= rng.choice([0.6, 1.4], size=int(specks.sum()))
        detail = image_detail(image, scene.mask)
        assert detail.outliers > 0.02  # each speck also shows in its 8 neighbours' detail
        assert detail.noise == pytest.approx(0.01, rel=0.3)  # a robust scale: the specks barely move it

    def test_a_flat_object_has_no_detail(self):
        mask = np.zeros((32, 32), bool)
        mask[4:28, 4:28] = True
        detail = image_detail(np.where(mask, 0.5, 0.0), mask)
        assert detail.noise == 0.0 and detail.outliers == 0.0


class TestSrgbToLinear:
    @staticmethod
    def encode(linear):
        """The sRGB encoding (IEC 61966-2-1), written out independently."""
        linear = np.asarray(linear, dtype=np.float64)
        return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)

    def test_known_values(self):
        from shadeform.preprocess import srgb_to_linear

        np.testing.assert_allclose(srgb_to_linear(np.array([0.0, 1.0])), [0.0, 1.0])
        assert srgb_to_linear(np.array(0.5)) == pytest.approx(0.21404, abs=1e-5)
        assert srgb_to_linear(np.array(0.04045)) == pytest.approx(0.0031308, abs=1e-7)

    def test_round_trip_and_shape(self):
        from shadeform.preprocess import srgb_to_linear

        linear = np.linspace(0, 1, 1001)
        np.testing.assert_allclose(srgb_to_linear(self.encode(linear)), linear, atol=1e-12)
        rgb = np.random.default_rng(0).random((4, 5, 3))
        assert srgb_to_linear(rgb).shape == (4, 5, 3)
        assert (np.diff(srgb_to_linear(np.linspace(0, 1, 500))) > 0).all()

    @pytest.mark.parametrize("bad", [np.array([1.5]), np.array([-0.1]), np.array([np.nan])])
    def test_out_of_range(self, bad):
        from shadeform.preprocess import srgb_to_linear

        with pytest.raises(InputError, match=r"\[0, 1\]"):
            srgb_to_linear(bad)


def test_the_detail_s_interior_by_erosion_is_the_distance_transform_s():
    """A kernel against its reference (a private name, deliberately: ``_more_than_two_inside``,
    against scipy's distance transform). image_detail's pixels more than 2 px inside, found by an
    erosion, are those of the exact distance transform, on blobs that touch the image's edge and
    have holes."""
    from scipy import ndimage as ndi

    from shadeform.preprocess import _more_than_two_inside

    rng = np.random.default_rng(3)
    for _ in range(5):
        mask = ndi.gaussian_filter(rng.random((90, 70)), 3) > 0.5
        assert mask.any() and not mask.all()
        assert np.array_equal(_more_than_two_inside(mask), ndi.distance_transform_edt(mask) > 2)
        image = rng.random(mask.shape)
        assert image_detail(image, mask) == image_detail(image, mask, inside=ndi.distance_transform_edt(mask))
