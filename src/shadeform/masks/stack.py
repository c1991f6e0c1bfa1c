"""The object of a photo set: its mask found from all the photos at once.

One photo of a set shows the object under one light: its shadowed side is as dark as the
background, a highlight as bright as anything, and the background itself may be lit more than
a dark glaze. The brightest reading of each pixel over the photos (the old default) keeps every
highlight and lights the background too, and filling the mask's holes closes what the object
frames (the gap between a figure's arms and its head, a handle's loop). The set says more:

- **The typical reading.** A pixel's median over the photos is a reading under a light that
  reaches it: the lights of a set ring the camera, so a surface facing the camera is lit in
  most photos, while a cast or attached shadow, or a highlight, is in a minority of them, and
  the median leaves both out. The background, a plane the lights reach like the camera-facing
  surfaces, has its own typical level. An inside that few lights reach (the inside of a bowl,
  a deep hole) is dark in most photos, so its median is dark: no brighter than the background.
  The colours are kept (the median of each channel), for the colour models of the cut.
- **The outline** is found on that picture by :func:`shadeform.masks.find_object` (brightness
  rules, then GrabCut on the colours), holes filled.
- **What the outline encloses that is not object.** The pixels on the background's side of
  the outline's threshold (:attr:`FoundObject.threshold`: no brighter than it, for a bright
  object) that the outline encloses, parts of them that do not reach past it, are the
  background seen through the object (the gap between the arms, a handle's loop) or an inside
  lit in fewer than half the photos, where photometric stereo has too few lights to solve
  anyway: they are left out, whether the cut took them in (its colour models may give the
  lit background's grey to the object) or not. A part that reaches past the outline is the
  object's dim rim running into the background, and stays. Of an enclosed part, what a 3 x 3
  opening removes (a speck or thread of pixels, noise on a dark glaze) stays too. For a dark
  object on a lighter background, what is brighter than the threshold may be a light patch on
  the object as well as the background through it: there only the holes the finder itself
  left (the parts of the brighter side it did not take in) are left out.

Constants: :data:`MAX_PHOTOS` (at most 32 photos, spread evenly over the set, make the median)
is a choice of speed: the median of 96 photos of 0.3 Mpx takes 3.5 s on one core, of 32 about
1.2 s, and on DiLiGenT's seven objects the two give masks within 0.006 IoU of each other. The
median (a half of the photos) is the rule above, not a value fitted. The method was chosen on
the synthetic sets of ``tests/test_masks_stack.py`` (an object with a hole through it and a
deep well, on a lit background) and DiLiGenT's seven objects, which chose between the median,
the mean, the brightest and the 75th / 90th percentile as the picture, and the 3 x 3 opening
(without it, DiLiGenT's reading loses specks of its dark glaze: IoU 0.957 against 0.966); the
MIT-Berkeley objects measure it and chose nothing (``benchmarks/results/stack-masks.md``). The
opening's 3 is the smallest window that tells a speck from a region, in pixels because the
noise it removes is per pixel.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage as ndi

from shadeform.errors import InputError
from shadeform.masks.brightness import _EIGHT, FoundObject
from shadeform.masks.objects import _LUMA, find_object

__all__ = ["find_object_in_set", "typical_picture", "MAX_PHOTOS"]

#: The median picture is taken over at most this many photos, spread evenly over the set.
MAX_PHOTOS = 32


def typical_picture(images) -> np.ndarray:
    """Each pixel's median reading over the photos (each channel's), over at most
    :data:`MAX_PHOTOS` of them spread evenly through the set.

    Parameters
    ----------
    images : (N, H, W) or (N, H, W, C) array_like
        The photos of one still camera, linear.

    Returns
    -------
    (H, W) or (H, W, C) float32

    Raises
    ------
    InputError
        If ``images`` is not 3-D or 4-D, holds no photo, or is not finite.
    """
    stack = np.asarray(images)
    if stack.ndim not in (3, 4) or stack.shape[0] == 0 or stack.size == 0:
        raise InputError(f"a photo set must be (N, H, W) or (N, H, W, C) photos, got shape {stack.shape}")
    count = stack.shape[0]
    if count > MAX_PHOTOS:
        stack = stack[np.linspace(0, count - 1, MAX_PHOTOS).round().astype(np.intp)]
        count = MAX_PHOTOS
    stack = stack.astype(np.float32, copy=False)
    if not np.isfinite(stack).all():
        raise InputError("the photos hold NaN or infinite values; give finite photos")
    half = count // 2
    if count % 2:
        return np.partition(stack, half, axis=0)[half]
    middle = np.partition(stack, [half - 1, half], axis=0)
    return 0.5 * (middle[half - 1] + middle[half])


def find_object_in_set(images) -> FoundObject:
    """Find the object in a photo set from all its photos: the background and the insides
    that few lights reach left out, and how sure the mask is.

    The module's description says how: the outline by :func:`shadeform.masks.find_object` on
    each pixel's median reading over the photos (:func:`typical_picture`), less the parts it
    encloses that lie on the background's side of the outline's threshold (background seen
    through the object, or an inside lit in fewer than half the photos).

    Parameters
    ----------
    images : (N, H, W) or (N, H, W, C) array_like
        The photos of one still camera, linear (e.g. :attr:`shadeform.photoset.PhotoSet.images`).

    Returns
    -------
    FoundObject
        As :func:`shadeform.masks.find_object` finds it on the median picture, less the
        enclosed parts above; ``confidence`` is the outline's (how well another way of finding it agrees).

    Raises
    ------
    InputError
        If ``images`` is not a stack of photos, is not finite, or its median picture is black
        or constant.

    Examples
    --------
    >>> rows, cols = np.mgrid[0:64, 0:64]
    >>> ring = (np.hypot(rows - 32, cols - 32) < 24) & (np.hypot(rows - 32, cols - 32) > 8)
    >>> photos = np.stack([np.where(ring, 0.6 * k, 0.05) for k in (0.5, 0.8, 1.0)])
    >>> found = find_object_in_set(photos)
    >>> bool(found.mask[32, 32]), int(found.mask.sum()), int(ring.sum())  # the hole's tips kept
    (False, 1596, 1592)
    """
    picture = typical_picture(images)
    if not picture.any():
        raise InputError("the photos are black at every pixel in most of them; give photos of the lit object")
    found = find_object(picture, fill_holes=False)
    if found.whole_frame:
        return found
    grey = picture @ _LUMA.astype(np.float32) if picture.ndim == 3 and picture.shape[2] == 3 else picture
    if grey.ndim == 3:
        grey = grey.mean(axis=2)
    outline = ndi.binary_fill_holes(found.mask)
    unlit = grey >= found.threshold if found.dark else grey <= found.threshold
    if found.dark:  # brighter than a dark object is not "unlit": only the holes the finder left
        unlit &= ~found.mask
    # the parts of the background's side that the outline encloses: a part that reaches past
    # it (an object's dim rim, which runs into the background) is not one
    labels, count = ndi.label(unlit)
    if count == 0:
        return replace(found, mask=outline)
    reaches_out = np.zeros(count + 1, dtype=bool)
    reaches_out[labels[~outline]] = True
    enclosed = ~reaches_out
    enclosed[0] = False
    # of those, a speck or a thread of pixels thinner than 3 is noise on the object, not a hole
    opened = enclosed[labels] & ndi.binary_opening(unlit, structure=_EIGHT)
    return replace(found, mask=outline & ~opened)
