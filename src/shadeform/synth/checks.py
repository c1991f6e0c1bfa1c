"""Argument checks shared by the synthetic scenes, renderings and views: size, light, numbers."""

from __future__ import annotations

import numbers

import numpy as np

from shadeform.errors import InputError

_MIN_SIZE = 16
#: The largest side a synthetic scene is made at (64 Mpx, the loader's pixel limit): checked
#: before anything is allocated.
_MAX_SIZE = 8192


def _check_size(size) -> int:
    if isinstance(size, bool) or not isinstance(size, numbers.Integral) or not _MIN_SIZE <= size <= _MAX_SIZE:
        raise InputError(f"size must be a whole number from {_MIN_SIZE} to {_MAX_SIZE}, got {size!r}")
    return int(size)


def _unit_light(light, *, front: bool = True) -> np.ndarray:
    """``light`` as a unit vector; with ``front``, it must point toward the viewer (z > 0)."""
    try:
        direction = np.asarray(light, dtype=np.float64)
    except (TypeError, ValueError):
        direction = None
    if direction is None or direction.shape != (3,) or not np.isfinite(direction).all():
        raise InputError(f"light must be 3 finite numbers (x, y, z), got {light!r}")
    if front and direction[2] <= 0:
        raise InputError(f"light must point toward the viewer (z > 0), got {tuple(direction.tolist())}")
    norm = np.linalg.norm(direction)
    if norm == 0:
        raise InputError("light must be a nonzero direction, got (0, 0, 0)")
    return direction / norm


def _finite_float(value, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = np.nan
    if isinstance(value, bool) or not np.isfinite(number):
        raise InputError(f"{what} must be a finite number, got {value!r}")
    return number
