"""The object by brightness: the first step of the automatic mask and of a mask grown from clicks.

A photo of an object has two kinds of pixel, the object's and the background's, and the
background is what reaches the frame: the photographer leaves a margin round the object, so
the background covers most of the image's border while the object touches it little or not at
all. Every rule here follows from that:

- **Which class is the object.** Otsu's threshold splits the pixels into a brighter and a
  darker class; the one covering more than half the frame is the background, so a dark object
  on a white sheet is found as well as a bright one on black (:func:`find_object`).
- **Uneven light on the background.** The background's brightness is taken to vary smoothly
  across the picture: a plane fitted to the frame's pixels (least absolute deviations, so that
  the object where it touches the frame does not pull it) is taken off before the split, where
  it fits the frame better than one level does (a step, such as a lit wall above a table, is
  no slope). On
  scikit-image's ``coins()`` the background darkens from 130 to 40 (of 255) down the picture,
  and without this its bright top edge is "the object".
- **Where the object ends.** From the object's class (seeds) the mask grows through every
  connected pixel that stands out from the background as the frame shows it: brighter (for a
  bright object) than the background's level by more than 3 noise sigmas, more than the
  background's own 95th percentile (a textured cloth or table), and at least 2 % of the way to
  Otsu's threshold. A Lambertian object's rim, where the surface turns away, is dim but still
  object.
- **What is not an object.** A connected part with more than half its outline on the frame is
  background (a bright strip along an edge, a lit corner), not the object.
- **No background at all.** When the two classes are no more distinct than the two halves of
  one Gaussian (Otsu's separability ``eta <= 2 / pi``) and the object's class reaches the frame
  too, nothing says there is a background: the picture is one surface that fills the frame
  (scikit-image's ``moon()``, a microscope field), and the mask is the whole image. A frame
  the object's class never reaches is evidence enough of a background, however the histogram
  looks (a glossy object on black, whose split falls between its highlights and the rest).

:func:`segment_from_seeds` grows the object from pixels the user clicked on ("click the
object"), against a background sampled where the user clicked outside it, or at the frame.

Constants: 3 sigmas, 2 % and the 95th percentile are rules of thumb stated above, not fitted
(the 95th rather than the 99th percentile so that a sphere cut by the frame keeps its rim, a
synthetic case in ``tests/test_masks.py``; on the real photos the two give the same masks
within 0.01 IoU); ``2 / pi`` and one half are the values the rules name. The real photographs
in ``../shared/data/real`` (DiLiGenT, MIT-Berkeley) measure the rules (``tests/test_masks.py``)
and chose no constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi
from skimage.filters import apply_hysteresis_threshold, threshold_otsu

from shadeform._checks import is_number, least_absolute
from shadeform.errors import InputError

__all__ = ["FoundObject", "threshold_object", "LOW_CONFIDENCE"]

#: Below this confidence (:attr:`FoundObject.confidence`) a mask is doubtful and the user is told.
#: Chosen on ``benchmarks/bench_masks.py``'s training backgrounds only (table, paper, wood, cloth;
#: the threshold that best separates the colour masks under 0.9 IoU from the rest), checked on the
#: held-out granite (``benchmarks/results/masks.md``: 0.965; how many it flags is
#: there).
LOW_CONFIDENCE = 0.965
# How far from the background level a pixel must be to be object: this many noise sigmas ...
_NOISE_SIGMAS = 3.0
# ... more than this percentile of the background as the frame shows it (5 % left for dust,
# hot pixels and the object's own dim rim where the frame cuts it: a sphere cut by one side of
# the frame puts 2 % of the frame's pixels in its rim) ...
_BACKGROUND_PERCENTILE = 95.0
# ... and at least this fraction of the way from the background level to the seeds' level.
_LOW_FLOOR = 0.02
# Otsu's separability (between-class over total variance) of one Gaussian cut at its mean:
# two classes no more distinct than that are one population, not object and background.
_ONE_GAUSSIAN = 2.0 / math.pi
# A part with more than this fraction of its outline on the frame is background.
_MOSTLY = 0.5
# Iterations of the reweighted least squares that fit the background plane (L1 converges fast).
_PLANE_ITERATIONS = 20
# 8-connectivity: a diagonal step stays inside one object.
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True, eq=False)
class FoundObject:
    """The automatic object mask and what decided it.

    Attributes
    ----------
    mask : (H, W) bool
        True on the object.
    dark : bool
        Whether the object is darker than its background (found on a light background).
    threshold : float
        The one threshold, in the image's units, nearest to this mask: ``image > threshold``
        (``<`` for a dark object) gives about the same object where the background is even. A
        place to start for a user who wants to move it.
    separation : float
        Otsu's separability of the image (after the background plane is taken off): the
        between-class variance over the total, in ``[0, 1]``; ``2 / pi`` for one Gaussian.
    whole_frame : bool
        True when no background was found (``separation <= 2 / pi`` and the object's class
        reaches the frame): the mask is the whole image.
    confidence : float
        How sure the mask is, in ``[0, 1]``: the highest IoU between the mask and the answer of
        another way of finding it (:func:`shadeform.masks.graphcut.agreement`). Below :data:`LOW_CONFIDENCE`
        the mask is doubtful (:attr:`warning`).
    """

    mask: np.ndarray
    dark: bool
    threshold: float
    separation: float
    whole_frame: bool
    confidence: float = 1.0

    @property
    def doubtful(self) -> bool:
        """Whether the confidence is below :data:`LOW_CONFIDENCE`."""
        return self.confidence < LOW_CONFIDENCE

    @property
    def warning(self) -> str | None:
        """One line for the user when the mask is doubtful, else None."""
        if not self.doubtful:
            return None
        return (
            f"the object's outline is doubtful (confidence {self.confidence:.2f}: ways of finding it "
            "disagree, the background is busy or like the object); check the mask, or give one "
            "(--mask, or click or box the object in the app)"
        )

    @property
    def note(self) -> str:
        """One line in the user's words saying what was found."""
        if self.whole_frame:
            return (
                "no background found (the picture is one surface filling the frame): the mask is "
                "the whole image"
            )
        kind = (
            "a dark object on a lighter background" if self.dark else "a bright object on a darker background"
        )
        return f"{kind}, {int(self.mask.sum()):,} pixels"


def _by_brightness(image: np.ndarray, *, dark, fill_holes: bool, largest: bool) -> FoundObject:
    """The object by brightness alone (the rules of the module's description); confidence 1."""
    brightest, darkest = float(image.max()), float(image.min())
    if brightest <= 0:
        raise InputError(
            "no object found: the image is black; check the exposure and the channel, or give a mask"
        )
    if brightest == darkest:
        raise InputError(
            f"no object found: the image is constant (every pixel is {brightest:g}); "
            "give a mask or a threshold"
        )
    frame = _frame(image.shape)
    plane = _background_plane(image, frame)
    flat = image - plane
    split = threshold_otsu(flat)
    separation = _separation(flat, split)
    if dark is None:
        dark = 2 * np.count_nonzero(flat[frame] > split) > np.count_nonzero(frame)
    # work on "how much the pixel stands out toward the object's side": larger is more object
    sign = -1.0 if dark else 1.0
    toward = sign * flat
    high = sign * split
    if separation <= _ONE_GAUSSIAN and (toward[frame] > high).any():
        return FoundObject(np.ones(image.shape, dtype=bool), False, darkest, separation, True, 1.0)
    background = toward[frame & (toward <= high)]
    if background.size < 2:  # the caller's `dark` puts the frame in the object's class
        background = toward[toward <= high]
    low = min(_low_threshold(background, high), high)
    mask = apply_hysteresis_threshold(toward, low, high)
    if fill_holes:
        mask = ndi.binary_fill_holes(mask)
    mask = _object_parts(mask, frame, largest=largest)
    outline = mask & ~ndi.binary_erosion(mask, border_value=0)
    threshold = float(np.median(plane[outline]) + sign * low)
    return FoundObject(mask, bool(dark), threshold, separation, False, 1.0)


def _grown(image: np.ndarray, seeds_in: np.ndarray, seeds_out: np.ndarray, fill_holes: bool) -> np.ndarray:
    """The object by seeded region growing in brightness (the rules of
    :func:`segment_from_seeds`'s first step)."""
    if seeds_out.any():
        flat, sample = image, image[seeds_out]
    else:
        frame = _frame(image.shape) & ~seeds_in
        if not frame.any():
            raise InputError("the inside clicks cover the whole frame; click outside the object too")
        flat = image - _background_plane(image, frame)
        sample = flat[frame]
    level = float(np.median(sample))
    seed_level = float(np.median(flat[seeds_in]))
    sign = 1.0 if seed_level >= level else -1.0
    tolerance = _low_threshold(sign * (sample - level), sign * (seed_level - level))
    if sign * (seed_level - level) <= tolerance:
        raise InputError(
            f"the clicked pixels look like the background (level {seed_level:.4g} against "
            f"{level:.4g}); click where the object stands out, or click the background too"
        )
    stands_out = (sign * (flat - level) > tolerance) & ~seeds_out | seeds_in
    labels, count = ndi.label(stands_out, structure=_EIGHT)
    chosen = np.zeros(count + 1, dtype=bool)
    chosen[labels[seeds_in]] = True
    chosen[0] = False
    mask = chosen[labels]
    return _filled(mask, seeds_out) if fill_holes else mask


def threshold_object(
    image: np.ndarray,
    threshold: float,
    *,
    dark: bool = False,
    fill_holes: bool = True,
    largest: bool = True,
) -> np.ndarray:
    """The object by one threshold: ``image > threshold``, or ``<`` for a dark object.

    Parameters
    ----------
    image : (H, W) array_like
        Intensities.
    threshold : float
        In the image's units.
    dark : bool, keyword-only
        The object is the pixels below the threshold.
    fill_holes : bool
        Fill holes inside the object.
    largest : bool
        Keep only the largest 8-connected part that is not mostly frame border (a strip or a
        corner of background on the object's side of the threshold); the largest of all when
        every part is.

    Returns
    -------
    (H, W) bool
        True on the object.

    Raises
    ------
    InputError
        If ``image`` is not 2-D or is not finite, ``threshold`` is not a finite number, or no
        pixel is on the object's side of it.
    """
    image = _as_image(image)
    if not is_number(threshold) or not math.isfinite(threshold):
        raise InputError(f"threshold must be a finite number, got {threshold!r}")
    mask = image < threshold if dark else image > threshold
    if not mask.any():
        side, extreme = (
            ("below", f"the darkest is {image.min():g}")
            if dark
            else ("above", f"the brightest is {image.max():g}")
        )
        raise InputError(
            f"no object found: no pixel is {side} threshold {threshold:g} ({extreme}); "
            f"give a {'higher' if dark else 'lower'} threshold"
        )
    if fill_holes:
        mask = ndi.binary_fill_holes(mask)
    if largest:
        mask = _object_parts(mask, _frame(image.shape), largest=True)
    return mask


# --- the pieces --------------------------------------------------------------------------------


def _filled(mask: np.ndarray, open_holes: np.ndarray) -> np.ndarray:
    """``mask`` with its holes filled, but those holding a pixel of ``open_holes``."""
    holes = ndi.binary_fill_holes(mask) & ~mask
    hole_labels, hole_count = ndi.label(holes)
    kept_open = np.zeros(hole_count + 1, dtype=bool)
    kept_open[hole_labels[open_holes]] = True
    return mask | (holes & ~kept_open[hole_labels])


def _as_image(image) -> np.ndarray:
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 2:
        raise InputError(
            f"image must be 2-D (H, W), got shape {image.shape}; pick one channel first "
            "(load_image(..., channel=...))"
        )
    if image.size == 0 or not np.isfinite(image).all():
        raise InputError("image is empty or has NaN or infinite values; give a finite image")
    return image


def _frame(shape: tuple[int, int]) -> np.ndarray:
    """The image's outermost rows and columns."""
    frame = np.zeros(shape, dtype=bool)
    frame[[0, -1], :] = True
    frame[:, [0, -1]] = True
    return frame


def _background_plane(image: np.ndarray, where: np.ndarray) -> np.ndarray:
    """The background's light: the plane ``a + b x + c y`` nearest to ``image[where]`` in least
    absolute deviations, or their median where the plane does not fit them better.

    Iteratively reweighted least squares (weights ``1 / |residual|``): the object's pixels where
    it touches the frame are outliers to it as long as the background holds most of the frame.
    """
    height, width = image.shape
    rows, cols = np.nonzero(where)
    # centred, scaled coordinates keep the normal equations well conditioned
    design = np.column_stack(
        [np.ones(rows.size), (cols - (width - 1) / 2) / width, (rows - (height - 1) / 2) / height]
    )
    values = image[where]
    coefficients = least_absolute(design, values, iterations=_PLANE_ITERATIONS)
    # a plane only where it describes the frame better than one level does: a robust scale
    # (median absolute deviation) of the residuals decides, so that a step (a lit wall above a
    # table, an object across one side) is not taken for a slope
    residuals = values - design @ coefficients
    level = float(np.median(values))
    if np.median(np.abs(residuals - np.median(residuals))) >= np.median(np.abs(values - level)):
        return np.full(image.shape, level)
    x = (np.arange(width) - (width - 1) / 2) / width
    y = (np.arange(height) - (height - 1) / 2) / height
    return coefficients[0] + coefficients[1] * x[None, :] + coefficients[2] * y[:, None]


def _separation(image: np.ndarray, split: float) -> float:
    """Otsu's separability: the between-class variance of the split over the total variance."""
    upper = image > split
    share = np.count_nonzero(upper) / image.size
    total = float(image.var())
    if share in (0.0, 1.0) or total == 0.0:
        return 0.0
    gap = float(image[upper].mean() - image[~upper].mean())
    return share * (1.0 - share) * gap * gap / total


def _low_threshold(background: np.ndarray, seeds: float) -> float:
    """How far toward the object a pixel must be to stand out from ``background`` (values on
    the object's side are larger): the background's level plus the largest of 3 noise sigmas,
    its 95th percentile's distance and 2 % of the way to ``seeds``.

    The noise sigma is a one-sided median absolute deviation, ``1.4826 * (upper quartile -
    median)``: right for Gaussian noise even when it is clipped at black, and unmoved by a few
    object pixels among the background ones.
    """
    level, upper_quartile, top = np.percentile(background, [50, 75, _BACKGROUND_PERCENTILE])
    sigma = 1.4826 * (upper_quartile - level)
    return float(level + max(_NOISE_SIGMAS * sigma, top - level, _LOW_FLOOR * (seeds - level)))


def _object_parts(mask: np.ndarray, frame: np.ndarray, *, largest: bool) -> np.ndarray:
    """The 8-connected parts of ``mask`` that are not mostly frame border (every part, if all
    are), or only the largest of them."""
    labels, count = ndi.label(mask, structure=_EIGHT)
    if count == 0:
        return mask
    outline = mask & ~ndi.binary_erosion(mask, border_value=0)
    on_frame = np.bincount(labels[outline & frame], minlength=count + 1)
    around = np.bincount(labels[outline], minlength=count + 1)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    sizes[0] = 0
    inner = on_frame <= _MOSTLY * around
    inner[0] = False
    if not inner.any():
        inner = sizes > 0
    if largest:
        return labels == np.argmax(np.where(inner, sizes, 0))
    return inner[labels]


def _pixels(points, shape: tuple[int, int], what: str) -> np.ndarray:
    """Clicks as an (N, 2) int array of pixels of an image of ``shape``."""
    array = np.asarray(points, dtype=np.float64).reshape(-1, 2) if len(points) else np.zeros((0, 2))
    if not np.isfinite(array).all() or (array != np.round(array)).any():
        raise InputError(f"{what} clicks must be whole pixel numbers (row, col)")
    array = array.astype(np.int64)
    outside = (array < 0).any(axis=1) | (array[:, 0] >= shape[0]) | (array[:, 1] >= shape[1])
    if outside.any():
        row, col = array[np.argmax(outside)]
        raise InputError(
            f"{what} click ({row}, {col}) is not a pixel of the {shape[1]}x{shape[0]} image "
            "(row, col from 0); click on the image"
        )
    return array


def _disks(pixels: np.ndarray, shape: tuple[int, int], radius: int) -> np.ndarray:
    marked = np.zeros(shape, dtype=bool)
    marked[pixels[:, 0], pixels[:, 1]] = True
    if radius <= 0 or not len(pixels):
        return marked
    offsets = np.arange(-radius, radius + 1)
    disk = np.hypot(offsets[:, None], offsets[None, :]) <= radius
    return ndi.binary_dilation(marked, structure=disk)
