"""Light directions: unit vectors toward a distant light, and slant and tilt in degrees.

Frame and angles as in ``docs/conventions.md``: x right, y up, z toward the viewer; ``(0, 0, 1)``
is a light behind the camera. Slant is the angle from +z, tilt the angle in the image plane from
+x toward +y, so ``L = (sin s cos t, sin s sin t, cos s)``. Every solver takes a light the camera
can see lit surfaces under (``z > 0``); these functions check a light once, at the boundary, and
convert between the two ways of giving it. They import only numpy: the pipeline imports them at
its own import time.
"""

from __future__ import annotations

import math

import numpy as np

from shadeform._checks import finite
from shadeform.errors import InputError

__all__ = ["as_light", "light_from_slant_tilt", "slant_tilt", "parse_light"]


def as_light(light) -> np.ndarray:
    """Check a light direction and scale it to unit length.

    Parameters
    ----------
    light : (3,) array_like
        ``(x, y, z)`` toward the light, any non-zero length, with ``z > 0``.

    Returns
    -------
    (3,) float64
        The unit vector.

    Raises
    ------
    InputError
        If ``light`` is not three finite numbers, is zero, or has ``z <= 0`` (a light at or behind
        the object's horizon lights nothing the camera sees, or only at grazing angles).

    Examples
    --------
    >>> as_light([0, 0, 2])
    array([0., 0., 1.])
    """
    try:
        vector = np.array(light, dtype=np.float64)
    except (TypeError, ValueError):
        vector = None
    if vector is None or vector.shape != (3,):
        raise InputError(
            f"light must be three numbers (x, y, z) toward the light, got {light!r}; "
            "e.g. (0, 0, 1) for a light behind the camera"
        )
    if not np.isfinite(vector).all():
        raise InputError(f"light has NaN or infinite components: {light!r}; give finite numbers")
    largest = float(np.abs(vector).max())
    if largest == 0:
        raise InputError("light is the zero vector; give a direction toward the light, e.g. (0, 0, 1)")
    if vector[2] <= 0:
        raise InputError(
            f"light {tuple(float(v) for v in vector)} has z <= 0: it is at or behind the object's "
            "horizon and lights nothing the camera sees; give a light with z > 0"
        )
    vector = vector / largest  # first to the unit cube: the squares of 1e300 or 1e-300 stay finite
    return vector / math.sqrt(float(vector @ vector))


def light_from_slant_tilt(slant: float, tilt: float) -> np.ndarray:
    """Light direction from slant and tilt in degrees.

    Parameters
    ----------
    slant : float
        Angle from the viewing direction +z, in degrees, ``0 <= slant < 90``.
    tilt : float
        Angle in the image plane from +x toward +y (up), in degrees; any value.

    Returns
    -------
    (3,) float64
        ``(sin s cos t, sin s sin t, cos s)``.

    Raises
    ------
    InputError
        If an angle is not a finite number or ``slant`` is outside ``[0, 90)``.

    Examples
    --------
    >>> light_from_slant_tilt(45, 90).round(4)
    array([0.    , 0.7071, 0.7071])
    """
    slant = finite(slant, "slant (degrees)")
    tilt = finite(tilt, "tilt (degrees)")
    if not 0 <= slant < 90:
        raise InputError(
            f"slant must be in [0, 90) degrees, got {slant:g}; at 90 or more the light is at or "
            "behind the object's horizon and lights nothing the camera sees"
        )
    s, t = math.radians(slant), math.radians(tilt)
    return np.array([math.sin(s) * math.cos(t), math.sin(s) * math.sin(t), math.cos(s)])


def slant_tilt(light) -> tuple[float, float]:
    """Slant and tilt in degrees of a light direction; the inverse of :func:`light_from_slant_tilt`.

    Parameters
    ----------
    light : (3,) array_like
        Toward the light, any length, ``z > 0`` (see :func:`as_light`).

    Returns
    -------
    slant : float
        Degrees from +z, in ``[0, 90)``.
    tilt : float
        Degrees from +x toward +y, in ``(-180, 180]``; 0 when ``slant`` is 0.

    Raises
    ------
    InputError
        As :func:`as_light`.

    Examples
    --------
    >>> slant_tilt([0, 1, 1])
    (45.0, 90.0)
    """
    x, y, z = as_light(light)
    # atan2 keeps full precision near slant 0, where acos(z) does not.
    slant = math.degrees(math.atan2(math.hypot(x, y), z))
    tilt = math.degrees(math.atan2(y, x)) if (x or y) else 0.0
    return slant, tilt


def parse_light(text: str) -> np.ndarray:
    """Read a light direction written ``"X,Y,Z"``, as on the command line.

    Parameters
    ----------
    text : str
        Three numbers separated by commas, spaces allowed, e.g. ``"0.3, 0.2, 1"``.

    Returns
    -------
    (3,) float64
        The unit vector (see :func:`as_light`).

    Raises
    ------
    InputError
        If the text is not three numbers, or the direction is not a valid light.
    """
    usage = "give three numbers X,Y,Z toward the light, e.g. '0,0,1'"
    if not isinstance(text, str):
        raise InputError(f"bad light {text!r}: {usage}")
    parts = text.split(",")
    if len(parts) != 3:
        raise InputError(f"bad light {text!r}: {usage}")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        raise InputError(f"bad light {text!r}: not all numbers; {usage}") from None
    return as_light(values)
