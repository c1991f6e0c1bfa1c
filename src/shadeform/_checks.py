"""Checks and small tools shared by the library's public functions (private)."""

from __future__ import annotations

import time

import numpy as np

from shadeform.errors import InputError


def is_number(value) -> bool:
    """A real number (Python or numpy), not a bool."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def shading_image(image) -> np.ndarray:
    """A user's one-channel intensity image as float64 (H, W), checked.

    Integer arrays are scaled by their type's maximum; NaN, infinities and negative values are
    refused with a one-line :class:`InputError`.
    """
    if not isinstance(image, np.ndarray):
        raise InputError(f"image must be a numpy array, got {type(image).__name__}; "
                         "load it with shadeform.load_image")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.ndim != 2:
        raise InputError(
            f"image must be one channel (H, W), got shape {image.shape}; "
            "pick a channel with shadeform.load_image(path, channel='luma')"
        )
    if np.issubdtype(image.dtype, np.integer):
        image = image / np.iinfo(image.dtype).max
    elif image.dtype == bool or not np.issubdtype(image.dtype, np.floating):
        raise InputError(f"image must hold numbers, got dtype {image.dtype}")
    image = image.astype(np.float64)
    if not np.isfinite(image).all():
        raise InputError("image contains NaN or infinite values; replace them (e.g. by 0) or mask them out")
    if image.size and image.min() < 0:
        raise InputError("image has negative values; intensities must be >= 0")
    return image


class StageTimer:
    """Wall time per named stage: ``lap("stage")`` adds the time since the previous lap."""

    def __init__(self) -> None:
        self.timings: dict[str, float] = {}
        self._clock = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.timings[stage] = self.timings.get(stage, 0.0) + now - self._clock
        self._clock = now
