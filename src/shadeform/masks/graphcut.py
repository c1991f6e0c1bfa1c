"""The object on a real background: colour models and a graph cut (GrabCut), and how sure it is.

A table, a sheet of paper, wood or cloth is not darker than every object on it, and it has a
texture of its own: a brightness threshold then takes part of the background with the object,
or part of the object with the background. GrabCut (Rother, Kolmogorov and Blake 2004) instead
learns two colour models, Gaussian mixtures of the background's colours (from the pixels known
to be background: the frame, a box's outside, the clicks outside) and of the object's, and cuts
the picture where the labels best fit both models and the cut runs along edges (a minimum cut
of a graph whose links between neighbours are weak across an edge); it alternates between the
models and the cut. OpenCV's ``cv2.grabCut`` is the implementation used here.

GrabCut is a local search: where it ends depends on where it starts. :func:`cut` runs it from
several starts (:class:`Hints`: the frame as background and everything else as probably object;
or a central ellipse as probably object) and, on a colour photo, on its colours as well as its
grey, and answers with the start that ends at the **lowest energy** (:func:`energy`, the sum
GrabCut minimises: how badly each pixel's colour fits its side's model, plus the cost of the
outline where it does not run along an edge), as one keeps the best of several restarts of any
local minimiser. On a plaid cloth the frame start lets the cloth's colours into the object's
model and stops in a worse minimum than the ellipse start; on an object that reaches the
frame's corners the ellipse start is the worse one. On a grey picture the energy does not judge:
its three equal channels make every colour model flat across them, the densities then rest on
OpenCV's fix for a flat model, and on a dark lab photo the start that gives the object's shadows
to the black backdrop ends lowest (DiLiGenT's reading: IoU 0.12 against the frame start's 0.92);
there the frame start answers. The **confidence** of an answer (:func:`agreement`) is how well another, independent way
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

__all__ = ["Hints", "Cut", "agreement", "cut", "energy", "iou", "WORK_PIXELS", "frame_band"]

#: The cut works on the picture scaled down to at most this many pixels.
WORK_PIXELS = 90_000
#: Model-and-cut rounds of each GrabCut run.
ITERATIONS = 5
#: Share of the picture's shorter side taken as the frame's band of background.
FRAME_BAND = 0.02
#: Weight of the outline's cost against the colour models' (Rother et al. 2004, and OpenCV's).
GAMMA = 50.0

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
        The object at full size: the answer of the start that ended at the lowest
        :func:`energy` (on the colours, for a colour picture).
    confidence : float
        ``mask``'s :func:`agreement` with the other answers, in ``[0, 1]`` (1 when there is no
        other).
    answers : list of (H, W) bool
        Every start's answer, at full size, ``mask`` among them.
    candidates : list of (H, W) bool
        The answers ``mask`` was chosen from: each start's on the colours of a colour picture,
        the first start's on a grey one.
    """

    mask: np.ndarray
    confidence: float
    answers: list
    candidates: list


def frame_band(shape: tuple[int, int]) -> np.ndarray:
    """The picture's outer band, :data:`FRAME_BAND` of its shorter side wide (at least 1 pixel)."""
    width = max(1, int(round(FRAME_BAND * min(shape))))
    band = np.ones(shape, dtype=bool)
    band[width:-width, width:-width] = False
    return band


def cut(image: np.ndarray, starts: list[Hints], *, extra: list[np.ndarray] = (), tidy=None) -> Cut:
    """The object by GrabCut from each start, on the grey and (for a colour picture) the colour
    features: the answer that ends at the lowest :func:`energy` on the colours (on a grey
    picture, the first start's), and its agreement with the others as its confidence.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) float array
        Linear intensities or colours, >= 0.
    starts : list of Hints
        Where each run starts. The starts share their sure pixels (``background`` and
        ``objects``) and differ in ``probable`` only, so that their energies compare.
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
        return Cut(answers[0], 1.0, answers, [])
    primary, lowest, candidates = None, np.inf, []
    for hints in starts:
        labels = _labels(hints, step, pictures[0].shape[:2])
        if not (labels % 2 == 1).any() or not (labels % 2 == 0).any():
            continue  # nothing to model on one side: no cut
        for index, picture in enumerate(pictures):
            ended, models = _grabcut(picture, labels)
            answer = _upsample(ended % 2 == 1, step, shape) | hints.objects
            answers.append(tidy(answer) if tidy is not None else answer)
            if index > 0 or (image.ndim == 2 and candidates):
                continue  # on the grey alone the energy does not judge (module notes): the first
            candidates.append(answers[-1])
            reached = energy(picture, ended, *models) if image.ndim == 3 else 0.0
            if reached < lowest:
                primary, lowest = answers[-1], reached
    if primary is None:  # no start could cut: the other method's answer
        primary = answers[0]
    return Cut(primary, agreement(primary, answers), answers, candidates)


def energy(picture: np.ndarray, labels: np.ndarray, background_model, object_model) -> float:
    """GrabCut's energy of a labelling: what its cut minimises for the given colour models.

    ``E = sum_p -log p_side(p)(z_p) + sum_{p~q, sides differ} GAMMA / dist(p, q) *
    exp(-beta |z_p - z_q|^2)`` over 8-neighbours, ``beta = 1 / (2 <|z_p - z_q|^2>)``; each
    model is a mixture of five Gaussians, and each density lacks its constant ``(2 pi)^(-3/2)``,
    as in OpenCV's implementation (whose final cut is the minimum of this sum for its models).

    Parameters
    ----------
    picture : (H, W, 3) uint8
        The features the cut ran on.
    labels : (H, W) uint8
        OpenCV's labels (odd: object).
    background_model, object_model : (1, 65) float64
        OpenCV's mixtures: 5 weights, 5 means (3 each), 5 covariances (9 each).

    Returns
    -------
    float

    References
    ----------
    C. Rother, V. Kolmogorov and A. Blake, "GrabCut: interactive foreground extraction using
    iterated graph cuts", ACM TOG 23(3), 2004.
    """
    colours = picture.reshape(-1, 3).astype(np.float64)
    inside = (labels % 2 == 1).reshape(-1)
    data = float(_mixture_cost(colours[inside], object_model).sum())
    data += float(_mixture_cost(colours[~inside], background_model).sum())
    z = picture.astype(np.float64)
    pairs = [_neighbours(z, labels % 2 == 1, dy, dx) for dy, dx in ((0, 1), (1, 1), (1, 0), (1, -1))]
    squared = np.concatenate([d2.ravel() for d2, _ in pairs])
    mean = float(squared.mean()) if squared.size else 0.0
    beta = 1.0 / (2.0 * mean) if mean > 0 else 0.0
    outline = 0.0
    for (d2, across), weight in zip(pairs, (1.0, 2**-0.5, 1.0, 2**-0.5), strict=True):
        outline += GAMMA * weight * float(np.exp(-beta * d2[across]).sum())  # diagonals: 1 / sqrt 2
    return data + outline


def _neighbours(z: np.ndarray, inside: np.ndarray, dy: int, dx: int):
    """Squared colour differences of each pixel and its neighbour at ``(dy, dx)`` (``dy >= 0``),
    and where the labels differ across that link."""
    height, width = inside.shape
    cols = slice(max(0, -dx), width - max(0, dx))
    moved = slice(max(0, dx), width + min(0, dx))
    here, there = (slice(0, height - dy), cols), (slice(dy, height), moved)
    return ((z[here] - z[there]) ** 2).sum(axis=-1), inside[here] != inside[there]


def _mixture_cost(colours: np.ndarray, model: np.ndarray) -> np.ndarray:
    """``-log`` of an OpenCV GrabCut mixture's density (without its constant) at each colour."""
    model = np.asarray(model, dtype=np.float64).reshape(-1)
    weights, means, covariances = model[:5], model[5:20].reshape(5, 3), model[20:65].reshape(5, 3, 3)
    density = np.zeros(len(colours))
    for weight, mean, covariance in zip(weights, means, covariances, strict=True):
        if weight <= 0:
            continue
        if np.linalg.det(covariance) <= np.finfo(np.float64).eps:  # OpenCV's fix for a flat one
            covariance = covariance + 0.01 * np.eye(3)
        offset = colours - mean
        spread = np.einsum("ni,ij,nj->n", offset, np.linalg.inv(covariance), offset)
        density += weight / np.sqrt(np.linalg.det(covariance)) * np.exp(-0.5 * spread)
    return -np.log(np.maximum(density, np.finfo(np.float64).tiny))


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


def _grabcut(picture: np.ndarray, labels: np.ndarray):
    """OpenCV's GrabCut from ``labels``: the labels it ends with and its two colour models."""
    import cv2

    labels = labels.copy()
    background_model = np.zeros((1, 65), np.float64)
    object_model = np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)  # its k-means starts from OpenCV's global generator: the same answer every time
    cv2.grabCut(picture, labels, None, background_model, object_model, ITERATIONS, cv2.GC_INIT_WITH_MASK)
    return labels, (background_model, object_model)


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
