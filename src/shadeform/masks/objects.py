"""The object found, clicked or boxed: brightness first, then colour models and a graph cut.

:func:`find_object` (the automatic mask), :func:`segment_from_seeds` (clicks on the object and
its background) and :func:`segment_from_box` (a box round it) each find the object by
brightness (:mod:`shadeform.masks.brightness`) and by GrabCut (:mod:`shadeform.masks.graphcut`),
keep the brightness mask where the two agree, and say how sure the answer is (the agreement of
the cuts started in different ways).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import ndimage as ndi

from shadeform._checks import whole
from shadeform.errors import InputError
from shadeform.masks import graphcut as segment
from shadeform.masks.brightness import (
    _EIGHT,
    FoundObject,
    _as_image,
    _by_brightness,
    _disks,
    _filled,
    _frame,
    _grown,
    _object_parts,
    _pixels,
)

__all__ = ["find_object", "segment_from_seeds", "segment_from_box"]

# The brightness mask is kept where the cut agrees with it this well (IoU): its rules keep an
# object's dim rim, finer than the cut's blocks. A choice of margin, not fitted.
_AGREE = 0.95
# Where brightness sees no background, a cut's object smaller than this share of the frame is a
# detail of one surface filling it (scikit-image's moon(): a crater of 1 %), not an object on a
# table (the benchmark's objects fill 15-40 % of theirs). Chosen on moon() alone.
_SPECK = 0.05
_LUMA = np.array([0.299, 0.587, 0.114])


def find_object(
    image: np.ndarray, *, dark: bool | None = None, fill_holes: bool = True, largest: bool = True
) -> FoundObject:
    """Find the object in a photo, on a dark backdrop or a table, paper, wood or cloth, and say
    how sure the mask is.

    First by brightness, the rules of the module's description: the background is the class
    that covers more of the frame, its uneven light is a plane fitted to the frame, the object
    grows from Otsu's class through every connected pixel that stands out from the background,
    parts that are mostly frame border are background, and a picture with neither two distinct
    classes nor a frame free of the object's class is all object. Then by colour models and a
    graph cut (:func:`shadeform.masks.graphcut.cut`: GrabCut started from the frame as background
    and the rest as object, and again from a central ellipse as object), which follows a background that is not darker than the object or
    has a texture of its own. Where the cut agrees with the brightness mask (IoU >= 0.95) the
    brightness mask is kept; otherwise the cut's. ``confidence`` is how well another way
    confirms the answer (:func:`shadeform.masks.graphcut.agreement`).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) array_like
        Intensities, e.g. from :func:`shadeform.load_image`, or linear colours (the cut then
        models colours; brightness is their luma).
    dark : bool, optional, keyword-only
        True for an object darker than its background, False for a brighter one; by default the
        frame decides.
    fill_holes : bool
        Fill holes inside the object (dark spots, specular pits, shadows enclosed by it).
    largest : bool
        Keep only the largest 8-connected part (drops dust and stray reflections); parts that
        are mostly frame border are dropped either way.

    Returns
    -------
    FoundObject

    Raises
    ------
    InputError
        If ``image`` is not 2-D or is not finite, or if it is black or constant.

    References
    ----------
    N. Otsu, "A threshold selection method from gray-level histograms", IEEE Trans. SMC 9(1),
    1979 (the split and its separability ``eta``). J. Canny, "A computational approach to edge
    detection", IEEE TPAMI 8(6), 1986 (hysteresis).

    Examples
    --------
    >>> rows, cols = np.mgrid[0:64, 0:64]
    >>> disk = np.hypot(rows - 32, cols - 32) < 20
    >>> found = find_object(np.where(disk, 0.2, 0.9))  # a dark disk on white paper
    >>> found.dark, bool((found.mask == disk).all())
    (True, True)
    """
    picture = _as_picture(image)
    grey = picture if picture.ndim == 2 else picture @ _LUMA
    found = _by_brightness(grey, dark=dark, fill_holes=fill_holes, largest=largest)
    if dark is not None:  # the user chose by brightness
        return found
    band = segment.frame_band(grey.shape) & (found.whole_frame | ~found.mask)  # a cut-off object stays one
    nothing = np.zeros(grey.shape, dtype=bool)
    starts = [
        segment.Hints(band, nothing, ~band),  # the lowest-energy of the two answers
        segment.Hints(band, nothing, _ellipse(grey.shape, (0, 0, *grey.shape)) & ~band),
    ]

    def tidy(mask):
        mask = ndi.binary_fill_holes(mask) if fill_holes else mask
        return _object_parts(mask, _frame(grey.shape), largest=largest)

    chosen = segment.cut(picture, starts, extra=[found.mask], tidy=tidy)
    if found.whole_frame:  # brightness saw no background: the cut's object, unless it is a speck
        if chosen.mask.mean() < _SPECK:
            return found
        return FoundObject(
            chosen.mask,
            _darker(grey, chosen.mask),
            found.threshold,
            found.separation,
            False,
            segment.agreement(chosen.mask, chosen.answers),
        )
    mask = found.mask if _confirmed(found.mask, chosen) else chosen.mask
    if not mask.any():
        mask = found.mask
    object_darker = _darker(grey, mask) if mask is not found.mask else found.dark
    confidence = segment.agreement(mask, chosen.answers)
    return FoundObject(mask, object_darker, found.threshold, found.separation, False, confidence)


def segment_from_seeds(
    image: np.ndarray,
    inside: Sequence[Sequence[int]] | np.ndarray,
    outside: Sequence[Sequence[int]] | np.ndarray = (),
    *,
    radius: int = 2,
    fill_holes: bool = True,
    return_confidence: bool = False,
) -> np.ndarray | tuple[np.ndarray, float]:
    """The object under the user's clicks: grown from pixels on it, against the background.

    First, seeded region growing in brightness: the background is sampled in disks round the ``outside`` pixels, or
    at the image's frame when there are none (with the frame's plane of uneven light taken off,
    as in :func:`find_object`); a pixel stands out from it when it lies beyond the background's
    level, on the seeds' side, by more than 3 noise sigmas, the background's 95th percentile
    and 2 % of the way to the seeds' level. The object is every such pixel connected to an
    ``inside`` disk; the ``outside`` disks are walls it does not cross, and a hole round an
    outside click stays open. Then GrabCut (:func:`shadeform.masks.graphcut.cut`): the clicks inside
    are object, the frame and the clicks outside background, and the part joined to the inside
    clicks is kept; so an object no brighter or darker than its table, or on a textured cloth,
    is found from its colours and edges. Where the two agree (IoU >= 0.95) the grown mask is
    kept, otherwise the cut's.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) array_like
        Intensities, e.g. from :func:`shadeform.load_image`, or linear colours.
    inside : (N, 2) array_like of int
        Pixels ``(row, col)`` on the object, at least one.
    outside : (M, 2) array_like of int, optional
        Pixels ``(row, col)`` on the background.
    radius : int, keyword-only
        Each click marks a disk of this radius in pixels (0: the pixel alone), so that it
        samples a neighbourhood rather than one noisy value.
    fill_holes : bool
        Fill holes inside the object, except those holding an ``outside`` click.
    return_confidence : bool
        Also return the mask's confidence (as :attr:`FoundObject.confidence`).

    Returns
    -------
    mask : (H, W) bool
        True on the object; always holds the ``inside`` disks.
    confidence : float
        Only with ``return_confidence``.

    Raises
    ------
    InputError
        If ``image`` is not 2-D or is not finite, a click is not a pixel of the image, there is
        no inside click, or the inside clicks look like the background (in brightness, and
        the cut finds nothing more than the clicks there).

    References
    ----------
    R. Adams and L. Bischof, "Seeded region growing", IEEE TPAMI 16(6), 1994.

    Examples
    --------
    >>> image = np.zeros((40, 60))
    >>> image[10:30, 5:25] = 0.8
    >>> image[10:30, 35:55] = 0.6
    >>> mask = segment_from_seeds(image, [(20, 45)])  # click the right-hand square
    >>> int(mask.sum()), bool(mask[20, 15])
    (400, False)
    """
    picture = _as_picture(image)
    grey = picture if picture.ndim == 2 else picture @ _LUMA
    radius = whole(radius, "radius")
    seeds_in = _disks(_pixels(inside, grey.shape, "inside"), grey.shape, radius)
    seeds_out = _disks(_pixels(outside, grey.shape, "outside"), grey.shape, radius)
    if not seeds_in.any():
        raise InputError("no inside click: click at least one pixel on the object")
    seeds_out &= ~seeds_in
    try:
        grown, refusal = _grown(grey, seeds_in, seeds_out, fill_holes), None
    except InputError as err:
        if "inside clicks cover the whole frame" in str(err):
            raise
        grown, refusal = None, err
    background = (segment.frame_band(grey.shape) | seeds_out) & ~seeds_in

    def tidy(mask):
        labels, _ = ndi.label(mask | seeds_in, structure=_EIGHT)
        mask = np.isin(labels, np.unique(labels[seeds_in]))
        return _filled(mask, seeds_out) if fill_holes else mask

    starts = [
        segment.Hints(background, seeds_in, ~background),
        segment.Hints(background, seeds_in, _ellipse(grey.shape, (0, 0, *grey.shape)) & ~background),
    ]
    chosen = segment.cut(picture, starts, extra=[] if grown is None else [grown], tidy=tidy)
    mask = chosen.mask
    if grown is not None and _confirmed(grown, chosen):
        mask = grown
    elif refusal is not None and np.count_nonzero(mask) <= 4 * np.count_nonzero(seeds_in):
        raise refusal
    return (mask, segment.agreement(mask, chosen.answers)) if return_confidence else mask


def segment_from_box(
    image: np.ndarray,
    box: Sequence[int],
    *,
    fill_holes: bool = True,
    return_confidence: bool = False,
) -> np.ndarray | tuple[np.ndarray, float]:
    """The object inside a box the user drew round it.

    GrabCut (:func:`shadeform.masks.graphcut.cut`) with everything outside the box as background and
    the box's inside as probably object, and again from the brightness mask of the box's inside
    (:func:`find_object`'s first step); the largest part is kept. Where the two agree (IoU >=
    0.95) the brightness mask is kept, otherwise the cut's from the box.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) array_like
        Intensities, e.g. from :func:`shadeform.load_image`, or linear colours.
    box : (4,) int
        ``(top, left, bottom, right)`` in pixels, bottom and right exclusive; cut to the image.
    fill_holes : bool
        Fill holes inside the object.
    return_confidence : bool
        Also return the mask's confidence (as :attr:`FoundObject.confidence`).

    Returns
    -------
    mask : (H, W) bool
        True on the object, only inside the box.
    confidence : float
        Only with ``return_confidence``.

    Raises
    ------
    InputError
        If ``image`` is not 2-D (or colour) or is not finite, or the box is not four whole
        numbers holding at least 3 x 3 pixels of the image.

    Examples
    --------
    >>> image = np.full((60, 80), 0.5)
    >>> image[20:40, 30:50] = 0.9
    >>> mask = segment_from_box(image, (15, 25, 45, 55))
    >>> int(mask.sum()), bool(mask[30, 40])
    (400, True)
    """
    picture = _as_picture(image)
    grey = picture if picture.ndim == 2 else picture @ _LUMA
    top, left, bottom, right = _box(box, grey.shape)
    inside = np.zeros(grey.shape, dtype=bool)
    inside[top:bottom, left:right] = True
    background = ~inside if (~inside).any() else segment.frame_band(grey.shape)
    nothing = np.zeros(grey.shape, dtype=bool)
    starts = [segment.Hints(background, nothing, inside & ~background)]
    extra = []
    crop = grey[top:bottom, left:right]
    if np.ptp(crop) > 0 and crop.max() > 0:
        found = _by_brightness(crop, dark=None, fill_holes=fill_holes, largest=True)
        if not found.whole_frame:
            bright = nothing.copy()
            bright[top:bottom, left:right] = found.mask
            extra.append(bright)
    starts.append(segment.Hints(background, nothing, _ellipse(grey.shape, (top, left, bottom, right))))

    def tidy(mask):
        mask = ndi.binary_fill_holes(mask) if fill_holes else mask
        return _object_parts(mask & inside, ~inside | _frame(grey.shape), largest=True)

    chosen = segment.cut(picture, starts, extra=extra, tidy=tidy)
    mask = chosen.mask
    if extra and _confirmed(extra[0], chosen):
        mask = extra[0]
    return (mask, segment.agreement(mask, chosen.answers)) if return_confidence else mask


# --- the pieces --------------------------------------------------------------------------------


def _box(box, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """A drawn box ``(top, left, bottom, right)`` checked and cut to the image."""
    values = np.asarray(box, dtype=np.float64).ravel() if np.ndim(box) else np.zeros(0)
    if values.size != 4 or not np.isfinite(values).all() or (values != np.round(values)).any():
        raise InputError("box must be four whole pixel numbers (top, left, bottom, right)")
    top, left = max(0, int(values[0])), max(0, int(values[1]))
    bottom, right = min(shape[0], int(values[2])), min(shape[1], int(values[3]))
    if bottom - top < 3 or right - left < 3:
        raise InputError(
            f"box ({', '.join(str(int(v)) for v in values)}) holds less than 3x3 pixels of the "
            f"{shape[1]}x{shape[0]} image (top, left, bottom, right from 0); draw it round the object"
        )
    return top, left, bottom, right


def _ellipse(shape: tuple[int, int], box: tuple[int, int, int, int]) -> np.ndarray:
    """An ellipse centred in the box, reaching 63 % of the way to its sides (``0.1`` is the
    square of 0.32 of a side): a second start for the cut, unlike the first."""
    top, left, bottom, right = box
    rows, cols = np.ogrid[: shape[0], : shape[1]]
    across = ((rows + 0.5 - top) / (bottom - top) - 0.5) ** 2 + (
        (cols + 0.5 - left) / (right - left) - 0.5
    ) ** 2
    return across < 0.1


def _as_picture(image) -> np.ndarray:
    """A grey (H, W) or colour (H, W, 3) picture as float64, checked."""
    picture = np.asarray(image, dtype=np.float64)
    if picture.ndim == 3 and picture.shape[2] == 1:
        picture = picture[..., 0]
    if picture.ndim == 3 and picture.shape[2] == 3:
        if picture.size == 0 or not np.isfinite(picture).all():
            raise InputError("image is empty or has NaN or infinite values; give a finite image")
        return picture
    return _as_image(picture)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return segment.iou(a, b)


def _confirmed(mask: np.ndarray, chosen: segment.Cut) -> bool:
    """Whether a cut the answer was chosen from finds ``mask`` too (IoU >= 0.95): any start's cut
    on the colours (the frame start's may confirm a brightness mask that the ellipse start,
    lower in energy, cuts short: a phone's dark handset on a lab backdrop), the first on grey."""
    return max((_iou(mask, answer) for answer in chosen.candidates), default=0.0) >= _AGREE


def _darker(image: np.ndarray, mask: np.ndarray) -> bool:
    """Whether the object is darker than the rest of the image (by their medians)."""
    return bool(mask.any() and (~mask).any() and np.median(image[mask]) < np.median(image[~mask]))
