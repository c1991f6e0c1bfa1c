"""Checks and small tools shared by the library's public functions (private)."""

from __future__ import annotations

import stat
import time
import warnings
from pathlib import Path

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
        raise InputError(
            f"image must be a numpy array, got {type(image).__name__}; load it with shadeform.load_image"
        )
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
    image = image.astype(np.float64, copy=False)  # no copy of a float64 image: callers only read it
    if not np.isfinite(image).all():
        raise InputError("image contains NaN or infinite values; replace them (e.g. by 0) or mask them out")
    if image.size and image.min() < 0:
        raise InputError("image has negative values; intensities must be >= 0")
    return image


def least_absolute(design: np.ndarray, values: np.ndarray, *, iterations: int) -> np.ndarray:
    """Coefficients ``c`` (k,) of ``design @ c`` nearest to ``values`` (n,) in least absolute
    deviations: iteratively reweighted least squares (weights ``1 / |residual|``), so that a
    minority of outlying values does not pull the fit. ``design`` is (n, k)."""
    scale = max(float(np.ptp(values)), 1e-12)
    weights = np.ones(values.size)
    for _ in range(iterations):
        root = np.sqrt(weights)
        coefficients = np.linalg.lstsq(design * root[:, None], values * root, rcond=None)[0]
        weights = 1.0 / np.maximum(np.abs(values - design @ coefficients), 1e-6 * scale)
    return coefficients


class StageTimer:
    """Wall time per named stage: ``lap("stage")`` adds the time since the previous lap."""

    def __init__(self) -> None:
        self.timings: dict[str, float] = {}
        self._clock = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.timings[stage] = self.timings.get(stage, 0.0) + now - self._clock
        self._clock = now


def check_mask(mask, shape, *, of: str = "the image") -> np.ndarray:
    """A user's object mask as a bool array of ``shape``, not empty.

    Parameters
    ----------
    mask : array_like
        Anything numpy reads as an array; nonzero marks the object.
    shape : tuple of int
        The shape it must have.
    of : str, keyword-only
        What ``shape`` belongs to, in the user's words, for the message.
    """
    mask = np.asarray(mask)
    if mask.shape != tuple(shape):
        raise InputError(
            f"mask has shape {mask.shape} but {of} has {tuple(shape)}; give a mask of the same size"
        )
    mask = mask.astype(bool)
    if not mask.any():
        raise InputError("mask is empty; it must mark the object's pixels")
    return mask


def check_choice(value, choices, what: str):
    """``value`` if it is one of ``choices``, else an ``unknown WHAT`` error that lists them."""
    if isinstance(value, str) and value in choices:
        return value
    raise InputError(f"unknown {what} {value!r}; choose one of: {', '.join(map(str, choices))}")


def finite(value, what: str) -> float:
    """A real number (not a bool), finite, as a float."""
    if not is_number(value) or not np.isfinite(value):
        raise InputError(f"{what} must be a finite number, got {value!r}")
    return float(value)


def positive(value, what: str) -> float:
    """A finite number > 0, as a float."""
    value = finite(value, what)
    if value <= 0:
        raise InputError(f"{what} must be > 0, got {value}")
    return value


def within(value, what: str, low: float, high: float, *, unit: str = "") -> float:
    """A finite number from ``low`` to ``high`` (``unit`` names its unit in the message)."""
    value = finite(value, what)
    if not low <= value <= high:
        raise InputError(f"{what} must be from {low:g} to {high:g} {unit}, got {value:g}".replace("  ", " "))
    return value


def fraction(value, what: str, *, closed: bool = False) -> float:
    """A number in (0, 1), or (0, 1] when ``closed``."""
    value = finite(value, what)
    if not (0 < value < 1 or (closed and value == 1)):
        raise InputError(f"{what} must be in (0, {'1]' if closed else '1)'}, got {value}")
    return value


def whole(value, what: str, *, minimum: int = 0) -> int:
    """A whole number (Python or numpy integer, not a bool) >= ``minimum``, as an int."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{what} must be a whole number >= {minimum}, got {value!r}")
    return int(value)


def regular_file(path: Path, what: str) -> Path:
    """``path``, unless it names a folder, a pipe or a device (reading one could block forever or
    never end): then a one-line :class:`InputError` naming ``what``. A path that cannot be
    looked at passes: the caller's own read says what is wrong with it."""
    try:
        mode = Path(path).stat().st_mode
    except (OSError, ValueError):
        return path
    if stat.S_ISDIR(mode):
        raise InputError(f"{what} '{path}' is a folder; give a file")
    if not stat.S_ISREG(mode):
        raise InputError(f"{what} '{path}' is a pipe or a device, not a file; give a file")
    return path


def renamed(value, old_value, *, name: str, old: str, where: str, default=None):
    """A keyword's value where it was renamed and the old name still works for one release:
    ``value`` (given as ``name``), or ``old_value`` with a :class:`DeprecationWarning` where the
    caller gave the old keyword ``old`` (``old_value`` not None) to ``where`` (a function's name).

    Raises
    ------
    InputError
        If both keywords were given with different values (``value`` not its ``default``).
    """
    if old_value is None:
        return value
    warnings.warn(
        f"{where}({old}=...) is deprecated; use {name}= (the old keyword goes in the next release)",
        DeprecationWarning,
        stacklevel=3,
    )
    if value != default and value != old_value:
        raise InputError(f"give {name} only: {old} is its old name ({where})")
    return old_value
