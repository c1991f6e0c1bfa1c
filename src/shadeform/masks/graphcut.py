"""The object on a real background: colour models and a graph cut (GrabCut), and how sure it is.

A table, a sheet of paper, wood or cloth is not darker than every object on it, and it has a
texture of its own: a brightness threshold then takes part of the background with the object,
or part of the object with the background. GrabCut (Rother, Kolmogorov and Blake 2004) instead
learns two colour models, Gaussian mixtures of the background's colours (from the pixels known
to be background: the frame, a box's outside, the clicks outside) and of the object's, and cuts
the picture where the labels best fit both models and the cut runs along edges (a minimum cut
of a graph whose links between neighbours are weak across an edge); it alternates between the
models and the cut. OpenCV's ``cv2.grabCut`` is the implementation used here.

Each cut starts from a few hints, and :func:`cut` runs it from several (:class:`Hints`): the
frame as background and everything else as probably object; or the brightness mask of
:mod:`shadeform.masks.brightness` as probably object; and, on a colour photo, on its colours as well as its
grey. The **confidence** of an answer (:func:`agreement`) is how well another, independent way
of finding the object confirms it: the highest IoU between it and any other answer (another
start's cut, the brightness mask). Two ways that find the same outline are unlikely to be wrong
the same way; an answer that nothing else finds is doubtful. On a plain dark lab backdrop the
brightness mask and the cut agree (confidence near 1); on a busy cloth they part ways.

The cut runs on the picture scaled down to at most :data:`WORK_PIXELS` pixels (a mean over
blocks) and the mask is brought back to full size; the cut's detail is then a block of pixels.

Constants: ``WORK_PIXELS`` (the speed a user waits for: about half a second a cut on 2 cores) and
the 2 % frame band are choices of speed and margin; ``ITERATIONS`` is OpenCV's documented usage
(a few iterations converge). None was fitted to a data set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

__all__ = ["Hints", "Cut", "agreement", "cut", "iou", "WORK_PIXELS", "frame_band"]

#: The cut works on the picture scaled down to at most this many pixels.
WORK_PIXELS = 90_000
#: Model-and-cut rounds of each GrabCut run.
ITERATIONS = 5
#: Share of the picture's shorter side taken as the frame's band of background.
FRAME_BAND = 0.02

# OpenCV's labels (cv2.GC_BGD, GC_FGD, GC_PR_BGD, GC_PR_FGD), named here so that the module
# loads OpenCV only when it cuts
_BACKGROUND, _OBJECT, _PROBABLY_BACKGROUND, _PROBABLY_OBJECT = 0, 1, 2, 3
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True, eq=False)
class Hints:
    """What is known before the cut, each (H, W) bool at the picture's full size.

    Attributes
    ----------
    background : (H, W) bool
        Surely background (the frame's band, outside a box, disks round clicks outside).
    objects : (H, W) bool
        Surely object (disks round clicks on it); may be empty.
    probable : (H, W) bool
        Probably object; everything else not sure is probably background.
    """

    background: np.ndarray
    objects: np.ndarray
    probable: np.ndarray


@dataclass(frozen=True, eq=False)
class Cut:
    """The cut chosen among the starts, and how sure it is.

    Attributes
    ----------
    mask : (H, W) bool
        The object at full size: the first start's answer (on the colours, for a colour picture).
    confidence : float
        ``mask``'s :func:`agreement` with the other answers, in ``[0, 1]`` (1 when there is no
        other).
    answers : list of (H, W) bool
        Every start's answer, at full size, ``mask`` among them.
    """

    mask: np.ndarray
    confidence: float
    answers: list


def frame_band(shape: tuple[int, int]) -> np.ndarray:
    """The picture's outer band, :data:`FRAME_BAND` of its shorter side wide (at least 1 pixel)."""
    width = max(1, int(round(FRAME_BAND * min(shape))))
    band = np.ones(shape, dtype=bool)
    band[width:-width, width:-width] = False
    return band


def cut(image: np.ndarray, starts: list[Hints], *, extra: list[np.ndarray] = (), tidy=None) -> Cut:
    """The object by GrabCut from each start, on the grey and (for a colour picture) the colour
    features: the first start's answer, and its agreement with the others as its confidence.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) float array
        Linear intensities or colours, >= 0.
    starts : list of Hints
        Where each run starts.
    extra : list of (H, W) bool
        Answers of other methods (e.g. the brightness mask), kept first in ``Cut.answers``.
    tidy : callable, optional
        Applied to each cut's answer at full size (fill holes, keep the part clicked).

    Returns
    -------
    Cut
    """
    shape = image.shape[:2]
    step = max(1, int(np.ceil(np.sqrt(image.shape[0] * image.shape[1] / WORK_PIXELS))))
    pictures = [_features(image, step)]
    if image.ndim == 3:
        pictures.append(_features(image @ np.array([0.299, 0.587, 0.114]), step))
    answers = [np.asarray(mask, dtype=bool) for mask in extra]
    if not starts:
        return Cut(answers[0], 1.0, answers)
    for hints in starts:
        labels = _labels(hints, step, pictures[0].shape[:2])
        if not (labels % 2 == 1).any() or not (labels % 2 == 0).any():
            continue  # nothing to model on one side: no cut
        for picture in pictures:
            answer = _upsample(_grabcut(picture, labels), step, shape) | hints.objects
            answers.append(tidy(answer) if tidy is not None else answer)
    primary = answers[len(extra)] if len(answers) > len(extra) else answers[0]
    return Cut(primary, agreement(primary, answers), answers)


def agreement(mask: np.ndarray, answers: list[np.ndarray]) -> float:
    """How well another answer confirms ``mask``: the highest IoU between it and any of
    ``answers`` other than itself (the same array), in ``[0, 1]``; 1 when there is no other."""
    others = [answer for answer in answers if answer is not mask]
    return max(iou(mask, answer) for answer in others) if others else 1.0


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two masks (1 when both are empty)."""
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 1.0


def _features(image: np.ndarray, step: int) -> np.ndarray:
    """The picture as GrabCut takes it: 8-bit, 3 channels, perceptually spaced (sRGB's curve,
    so that dark tones are not crushed together), exposed to its 99.5th percentile, scaled down
    by a mean over ``step`` x ``step`` blocks."""
    from shadeform.io.images import srgb_encode

    image = np.asarray(image, dtype=np.float64)
    if step > 1:
        height, width = (image.shape[0] // step) * step, (image.shape[1] // step) * step
        image = image[:height, :width]
        image = image.reshape(height // step, step, width // step, step, *image.shape[2:]).mean(axis=(1, 3))
    top = max(float(np.percentile(image, 99.5)), 1e-12)
    encoded = srgb_encode(np.clip(image / top, 0.0, 1.0))
    if encoded.ndim == 2:
        encoded = np.repeat(encoded[..., None], 3, axis=2)
    return np.ascontiguousarray(np.round(encoded * 255), dtype=np.uint8)


def _labels(hints: Hints, step: int, shape: tuple[int, int]) -> np.ndarray:
    """The hints as OpenCV's labels on the scaled picture (a block is sure where any of its
    pixels is sure background, or else any is sure object; probable by majority)."""

    def blocks(mask, how):
        mask = mask[: shape[0] * step, : shape[1] * step]
        return getattr(mask.reshape(shape[0], step, shape[1], step), how)(axis=(1, 3))

    labels = np.full(shape, _PROBABLY_BACKGROUND, dtype=np.uint8)
    labels[blocks(hints.probable.astype(np.float64), "mean") >= 0.5] = _PROBABLY_OBJECT
    labels[blocks(hints.objects, "any")] = _OBJECT
    labels[blocks(hints.background, "any")] = _BACKGROUND
    return labels


def _grabcut(picture: np.ndarray, labels: np.ndarray) -> np.ndarray:
    import cv2

    labels = labels.copy()
    background_model = np.zeros((1, 65), np.float64)
    object_model = np.zeros((1, 65), np.float64)
    cv2.grabCut(picture, labels, None, background_model, object_model, ITERATIONS, cv2.GC_INIT_WITH_MASK)
    return (labels == _OBJECT) | (labels == _PROBABLY_OBJECT)


def _upsample(mask: np.ndarray, step: int, shape: tuple[int, int]) -> np.ndarray:
    """A mask of the scaled picture at full size: smoothed by a bilinear zoom, cut at one half
    (rows and columns past the last whole block copy its edge)."""
    if step == 1:
        return mask[: shape[0], : shape[1]].copy()
    grown = ndi.zoom(mask.astype(np.float32), step, order=1, mode="nearest", grid_mode=True)
    full = np.zeros(shape, dtype=np.float32)
    full[: grown.shape[0], : grown.shape[1]] = grown[: shape[0], : shape[1]]
    if grown.shape[0] < shape[0]:
        full[grown.shape[0] :] = full[grown.shape[0] - 1]
    if grown.shape[1] < shape[1]:
        full[:, grown.shape[1] :] = full[:, grown.shape[1] - 1 : grown.shape[1]]
    return full >= 0.5
