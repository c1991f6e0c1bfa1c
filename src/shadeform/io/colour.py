"""Colour of decoded photos: the sRGB transfer curve both ways, Rec. 601 luma's weights, and
how much of a photo clips at the white level (the rule by which ``channel="auto"`` picks the
channel to solve on).

The readers of :mod:`shadeform.io.images` use them; :func:`srgb_decode` is the one implementation
of the curve (:func:`shadeform.preprocess.srgb_to_linear` checks its input and calls it).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CLIP_MARGIN", "srgb_decode", "srgb_encode"]

#: How many fewer pixels (a fraction of the photo's) one colour channel must clip at the white
#: level than luma does before ``channel="auto"`` solves on it instead of luma; channels within
#: this of the least clipped one count as equals (green is taken first). The few highlight pixels
#: of a glossy object, which clip in every channel alike or almost, leave luma and its lower noise;
#: a colour channel saturated over a part of the object moves the choice. A judgement, not a fit:
#: of the 792 photos in ``../shared/data/real`` it moves 5 (DiLiGenT reading under bluish lights:
#: blue clips on 0.7-0.9 % of the photo, green on 0.2 %) to green.
CLIP_MARGIN = 0.005

# Rec. 601 luma weights (docs/conventions.md).
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)


def _clipped(pixels: np.ndarray) -> dict[str, float]:
    """Fraction of the pixels at the white level, per channel (and in any channel for colour)."""
    count = pixels.shape[0] * pixels.shape[1]
    if pixels.shape[2] == 1:
        return {"gray": int(np.count_nonzero(pixels >= 1.0)) / count}
    fractions = {name: int(np.count_nonzero(pixels[:, :, i] >= 1.0)) / count for i, name in enumerate("rgb")}
    fractions["any"] = int(np.count_nonzero(pixels.max(axis=2) >= 1.0)) / count
    return fractions


def _least_clipped(clipped: dict[str, float]) -> str:
    """The rule of ``channel="auto"`` for a colour photo
    (:func:`shadeform.io.images.read_photo`)."""
    fewest = min(clipped[name] for name in "rgb")
    if clipped["any"] - fewest < CLIP_MARGIN:
        return "luma"
    # green, then red, then blue: the first within the margin of the least clipped
    return next(name for name in "grb" if clipped[name] - fewest < CLIP_MARGIN)


def srgb_decode(values: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear (IEC 61966-2-1), a new array of the same float type.

    The one implementation of the transfer curve (:func:`shadeform.preprocess.srgb_to_linear`
    checks its input and calls this)."""
    number = values.dtype.type  # float32 stays float32
    encoded = ((values + number(0.055)) / number(1.055)) ** number(2.4)
    return np.where(values <= number(0.04045), values / number(12.92), encoded)


def srgb_encode(values: np.ndarray) -> np.ndarray:
    """Linear values in [0, 1] -> sRGB-encoded, the inverse of :func:`srgb_decode` (to show a
    decoded photo as it looked: 8-bit values come back exactly)."""
    number = values.dtype.type
    encoded = number(1.055) * values ** number(1 / 2.4) - number(0.055)
    return np.where(values <= number(0.0031308), values * number(12.92), encoded)
