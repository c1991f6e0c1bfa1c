"""Tests for shadeform.masks: the automatic object mask and the mask grown from clicks.

The real photographs (``../shared/data/real``: DiLiGenT's cropped photos on black, MIT-Berkeley's
16-bit photos) measure the rules against their ground-truth masks; no constant was chosen on
them. Without that folder those tests skip, saying so.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage as ndi
from skimage import data

from helpers import SHARED_DATA
from shadeform import load_image
from shadeform.errors import InputError
from shadeform.examples import EXAMPLES, load_example
from shadeform.masks import FoundObject, find_object, segment_from_seeds, threshold_object
from shadeform.preprocess import object_mask

REAL = SHARED_DATA / "real"
DILIGENT = REAL / "diligent"
MIT = REAL / "mit-berkeley"


def iou(a, b) -> float:
    return float((a & b).sum() / (a | b).sum())


def frame_pixels(mask) -> int:
    return int(mask[0].sum() + mask[-1].sum() + mask[1:-1, 0].sum() + mask[1:-1, -1].sum())


def sphere(shape=(160, 200), centre=(80, 100), radius=50, albedo=0.9):
    """A Lambertian sphere lit from the camera: its image (0 off it) and its disk."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    distance = np.hypot(rows - centre[0], cols - centre[1])
    disk = distance < radius
    shading = np.sqrt(np.clip(1 - (distance / radius) ** 2, 0, 1))
    return np.where(disk, albedo * shading, 0.0), disk


class TestFindObject:
    def test_smoke(self):
        image, disk = sphere()
        found = find_object(image)
        assert isinstance(found, FoundObject)
        assert found.mask.shape == image.shape and found.mask.dtype == bool
        assert not found.dark and not found.whole_frame
        assert iou(found.mask, disk) > 0.98
        assert "\n" not in found.note and "bright object" in found.note

    def test_coins_finds_a_coin_not_the_background(self):
        # scikit-image's coins(): a background that darkens from 130 to 40 (of 255) down the
        # picture; its bright top edge used to be taken for the object
        image = data.coins() / 255.0
        found = find_object(image)
        mask = found.mask
        assert frame_pixels(mask) == 0
        assert 1_000 < mask.sum() < 6_000  # one coin: 40 to 80 pixels across
        rows, cols = np.nonzero(mask)
        radius = (np.ptp(rows) + np.ptp(cols) + 2) / 4
        assert mask.sum() > 0.85 * math.pi * radius**2  # round
        ring = ndi.binary_dilation(mask, iterations=6) & ~ndi.binary_dilation(mask, iterations=2)
        assert image[mask].mean() > image[ring].mean() + 0.2  # brighter than what surrounds it
        np.testing.assert_array_equal(object_mask(image), mask)

    def test_moon_is_one_surface(self):
        # scikit-image's moon(): the lunar surface fills the frame; its crater shadows are not
        # an object on a background
        found = find_object(data.moon() / 255.0)
        assert found.whole_frame and found.mask.all()
        assert object_mask(data.moon() / 255.0).all()
        assert found.separation <= 2 / math.pi
        assert "whole image" in found.note

    @pytest.mark.parametrize("name", [name for name in EXAMPLES if name.startswith("synth:")])
    @pytest.mark.parametrize("size", [64, 256])
    def test_synthetic_examples_match_their_true_masks(self, name, size):
        image, info = load_example(name, size=size)
        assert iou(find_object(image).mask, info["mask"]) > 0.985

    def test_coin_example(self):
        image, _ = load_example("coin")
        mask = find_object(image).mask
        assert frame_pixels(mask) == 0
        assert 0.4 < mask.mean() < 0.65  # the coin fills about half of the crop
        rows, cols = np.nonzero(mask)
        assert abs(rows.mean() - image.shape[0] / 2) < 6 and abs(cols.mean() - image.shape[1] / 2) < 6

    def test_dark_object_on_white_paper(self):
        image, disk = sphere()
        paper = np.where(disk, 0.3 * image / 0.9, 0.95)
        found = find_object(paper)
        assert found.dark
        assert iou(found.mask, disk) > 0.98
        np.testing.assert_array_equal(object_mask(paper), found.mask)

    def test_background_lit_unevenly(self):
        # a background ramp from 0.5 (top) to 0.05 (bottom): its top is brighter than the
        # object's dim rim, but the plane fitted to the frame takes the ramp off
        image, disk = sphere(centre=(100, 100), radius=45)
        ramp = np.linspace(0.5, 0.05, image.shape[0])[:, None] * np.ones(image.shape)
        photo = np.where(disk, ramp + image, ramp)
        assert iou(find_object(photo).mask, disk) > 0.97

    def test_strip_along_the_frame_is_background(self):
        image, disk = sphere(radius=30)
        image[:12, :] = 0.8  # a lit strip along the top edge, larger than the object
        found = find_object(image)
        assert not found.mask[:12].any()
        assert iou(found.mask, disk) > 0.97

    def test_object_touching_the_frame_is_kept(self):
        # a bust cut by the bottom edge: most of its outline is still off the frame
        image, disk = sphere(shape=(120, 200), centre=(110, 100), radius=60)
        found = find_object(image)
        assert iou(found.mask, disk) > 0.97

    def test_noise_on_black(self):
        image, disk = sphere()
        noisy = np.clip(image + np.random.default_rng(3).normal(0, 0.01, image.shape), 0, 1)
        assert iou(find_object(noisy).mask, disk) > 0.97

    def test_dark_given(self):
        image, disk = sphere()
        paper = np.where(disk, 0.3 * image / 0.9, 0.95)
        assert iou(find_object(image, dark=False).mask, disk) > 0.98
        assert iou(find_object(paper, dark=True).mask, disk) > 0.98
        assert find_object(paper, dark=False).mask.all()  # the paper, and the disk as its hole

    def test_threshold_reproduces_the_mask(self):
        image, disk = sphere()
        for photo in (image, np.where(disk, 0.3 * image / 0.9, 0.95)):
            found = find_object(photo)
            again = threshold_object(photo, found.threshold, dark=found.dark)
            assert iou(again, found.mask) > 0.97

    def test_largest_and_fill_holes(self):
        image, disk = sphere(radius=40)
        image[75:85, 95:105] = 0.0  # a black spot inside
        image[5:15, 170:180] = 0.9  # a small bright blob
        assert find_object(image).mask[80, 100]
        assert not find_object(image, fill_holes=False).mask[80, 100]
        both = find_object(image, largest=False).mask
        assert both[10, 175] and not find_object(image).mask[10, 175]

    def test_errors(self):
        with pytest.raises(InputError, match="black"):
            find_object(np.zeros((8, 8)))
        with pytest.raises(InputError, match="constant"):
            find_object(np.full((8, 8), 0.5))
        with pytest.raises(InputError, match="2-D"):
            find_object(np.ones((4, 4, 2)))


class TestThresholdObject:
    def test_values(self):
        image = np.array([[0.0, 0.2, 0.4], [0.6, 0.8, 1.0], [0.1, 0.3, 0.5]])
        np.testing.assert_array_equal(
            threshold_object(image, 0.45, fill_holes=False, largest=False), image > 0.45
        )
        np.testing.assert_array_equal(
            threshold_object(image, 0.45, dark=True, fill_holes=False, largest=False), image < 0.45
        )

    def test_largest_skips_a_strip_of_background(self):
        image, disk = sphere(radius=30)
        image[:12, :] = 0.8
        mask = threshold_object(image, 0.05)
        assert not mask[:12].any() and mask[80, 100]

    def test_errors(self):
        image = np.linspace(0, 1, 16).reshape(4, 4)
        with pytest.raises(InputError, match="no pixel is above threshold 1"):
            threshold_object(image, 1.0)
        with pytest.raises(InputError, match="no pixel is below threshold 0"):
            threshold_object(image, 0.0, dark=True)
        with pytest.raises(InputError, match="finite number"):
            threshold_object(image, float("inf"))


class TestSegmentFromSeeds:
    @staticmethod
    def two_spheres():
        left, left_disk = sphere(shape=(120, 260), centre=(60, 65), radius=45, albedo=0.9)
        right, right_disk = sphere(shape=(120, 260), centre=(60, 190), radius=50, albedo=0.5)
        return left + right, left_disk, right_disk

    def test_click_picks_the_object_under_it(self):
        image, left, right = self.two_spheres()
        # the smaller, brighter one: the automatic mask takes the larger
        assert iou(find_object(image).mask, right) > 0.97
        assert iou(segment_from_seeds(image, [(60, 65)]), left) > 0.97
        assert iou(segment_from_seeds(image, [(60, 190)]), right) > 0.97
        both = segment_from_seeds(image, [(60, 65), (60, 190)])
        assert iou(both, left | right) > 0.97

    def test_noisy_textured_background(self):
        image, disk = sphere()
        rng = np.random.default_rng(5)
        background = ndi.gaussian_filter(rng.normal(0.2, 0.05, image.shape), 2)
        photo = np.where(disk, 0.25 + image * 0.7, background)
        assert iou(segment_from_seeds(photo, [(80, 100)]), disk) > 0.97

    def test_dark_object(self):
        image, disk = sphere()
        paper = np.where(disk, 0.3 * image / 0.9, 0.95)
        assert iou(segment_from_seeds(paper, [(80, 100)]), disk) > 0.98

    def test_outside_clicks_are_walls_and_keep_holes_open(self):
        image = np.zeros((60, 100))
        image[10:50, 10:90] = 0.8
        image[25:35, 45:55] = 0.0  # a hole
        filled = segment_from_seeds(image, [(20, 20)])
        assert filled[30, 50] and filled.sum() == 40 * 80
        kept = segment_from_seeds(image, [(20, 20)], [(30, 50)], radius=1)
        assert not kept[25:35, 45:55].any() and kept.sum() == 40 * 80 - 100

    def test_an_outside_click_on_a_bridge_cuts_it(self):
        image = np.zeros((60, 120))
        image[10:50, 10:50] = 0.8
        image[10:50, 70:110] = 0.8
        image[28:33, 50:70] = 0.3  # a dim bridge between two squares
        both = segment_from_seeds(image, [(30, 30)])
        assert both[30, 90] and both[30, 60]
        left = segment_from_seeds(image, [(30, 30)], [(30, 60)])
        assert left[30, 30] and not left[30, 90] and not left[30, 60]

    def test_inside_clicks_always_belong(self):
        image, disk = sphere()
        mask = segment_from_seeds(image, [(80, 100)], radius=3)
        assert mask[77:84, 97:104].all()

    def test_errors(self):
        image, _ = sphere()
        with pytest.raises(InputError, match="look like the background"):
            segment_from_seeds(image, [(5, 5)])
        with pytest.raises(InputError, match=r"inside click \(200, 5\) is not a pixel of the 200x160 image"):
            segment_from_seeds(image, [(200, 5)])
        with pytest.raises(InputError, match="whole pixel"):
            segment_from_seeds(image, [(2.5, 5)])
        with pytest.raises(InputError, match="no inside click"):
            segment_from_seeds(image, [])
        with pytest.raises(InputError, match="radius"):
            segment_from_seeds(image, [(80, 100)], radius=-1)


# ------------------------------------------------------------------------------ real photos

# IoU with the ground-truth mask of the DiLiGenT photo lit nearest the camera, measured when
# the rules were written (ball 0.981, bear 0.992, buddha 0.937, cat 0.981, cow 0.967, pot1 0.885,
# reading 0.207); each bar leaves a margin. buddha's and ball's ground truth leaves out the
# pedestal and the stand the photos show; pot1's shadowed underside lies at the background's
# noise level. reading is a black glazed figure on a dark grey backdrop: most of it is darker
# than the backdrop, its book and face brighter, and a one-sided rule takes only the bright
# parts (the app's mask tool is the way there).
DILIGENT_BARS = {
    "ball": 0.95,
    "bear": 0.97,
    "buddha": 0.90,
    "cat": 0.95,
    "cow": 0.92,
    "pot1": 0.85,
    "reading": 0.15,
}


def need(folder):
    if not folder.is_dir():
        pytest.skip(f"real photos not found at {folder}")


@pytest.mark.parametrize("name", sorted(DILIGENT_BARS))
def test_diligent_frontal_photo(name):
    folder = DILIGENT / name
    need(folder)
    lights = np.loadtxt(folder / "light_directions.txt")
    photo = folder / f"{int(np.argmax(lights[:, 2])) + 1:03d}.png"
    truth = load_image(folder / "mask.png") > 0
    mask = object_mask(load_image(photo))
    assert iou(mask, truth) >= DILIGENT_BARS[name]
    assert (mask & truth).sum() >= 0.9 * mask.sum()  # what it takes is object


# measured: 1.000 on 10 objects, panther 0.982, phone 0.999 (light01); 0.98 or more on all ten
# photos of every object
@pytest.mark.parametrize(
    "name",
    [
        "apple",
        "box",
        "cup1",
        "deer",
        "dinosaur",
        "frog1",
        "panther",
        "paper1",
        "pear",
        "phone",
        "raccoon",
        "sun",
    ],
)
def test_mit_berkeley(name):
    folder = MIT / name
    need(folder)
    truth = load_image(folder / "mask.png") > 0
    image = load_image(folder / "light01.png")
    assert iou(object_mask(image), truth) >= 0.97
    # one click on the object's deepest pixel grows the same object
    click = np.unravel_index(np.argmax(ndi.distance_transform_edt(truth)), truth.shape)
    assert iou(segment_from_seeds(image, [click]), truth) >= 0.97
