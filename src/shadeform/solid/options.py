"""A relief's options: the sizes in millimetres, the outline, the triangle budget and the grid it
samples, checked once before any work (:func:`check_options`); the ``print`` extra a budget needs."""

from __future__ import annotations

import importlib.util
import math

from shadeform._checks import check_choice, finite, positive, whole, within
from shadeform.errors import InputError

__all__ = [
    "MIN_TRIANGLES",
    "MIN_WALL_MM",
    "OUTLINES",
    "OVERSAMPLE",
    "SIZE_RANGE_MM",
    "check_options",
    "grid_step",
    "require_print_extra",
]

#: What the solid's sides follow: the object's outline (its mask) or the whole image frame.
OUTLINES = ("mask", "frame")

#: Default thinnest wall, mm: two perimeters of a 0.4 mm nozzle, the usual minimum of desktop
#: filament printers (their slicers' defaults), not measured here. Resin printers go thinner.
MIN_WALL_MM = 0.8

#: The range of each size (width, height, base), mm: 10 m is beyond any printer (and STL's and
#: 3MF's float32 coordinates keep steps under 0.002 mm there); below a micrometre no printer
#: resolves anything.
SIZE_RANGE_MM = (1e-3, 1e4)

#: The fewest triangles a budget may allow: a box.
MIN_TRIANGLES = 12

#: With a triangle budget, the height field is sampled on a grid whose top has about this many
#: times the budget's triangles before the quadric simplification chooses where they go. Chosen
#: on ``benchmarks/bench_relief.py`` (the synthetic 4000 x 3000 vase's outline, 200,000
#: triangles; ``results/relief.md``): 2 took 0.7 s and left the surface within 0.031 mm, 4 took
#: 1.4 s and 0.019 mm, 8 (there the full-resolution grid) 5.5 s and 0.012 mm.
OVERSAMPLE = 4

_PRINT_EXTRA = "pip install 'shadeform[print]'"


def grid_step(pixels: int, max_triangles: int | None) -> int:
    """Every how many pixels :func:`relief` samples the surface of ``pixels`` pixels for a budget.

    About :data:`OVERSAMPLE` times the budget's triangles on top (two per grid cell) before the
    quadric simplification; 1 (every pixel) without a budget. A depth map solved only on this
    grid (:func:`shadeform.coarse.reconstruct_on_grid`) gives the solid all it keeps, at
    ``step**2`` times less work.

    Parameters
    ----------
    pixels : int
        The relief's pixels: the object's (``outline="mask"``) or the image's (``"frame"``).
    max_triangles : int or None
        The triangle budget; None for none.

    Returns
    -------
    int
        The grid spacing in pixels, ``>= 1``.

    Examples
    --------
    >>> grid_step(2_800_000, 200_000), grid_step(12_000_000, 200_000), grid_step(10**6, None)
    (2, 5, 1)
    """
    if max_triangles is None:
        return 1
    return max(1, math.floor(math.sqrt(2 * pixels / (OVERSAMPLE * max_triangles))))


def check_options(
    *,
    width_mm: float,
    height_mm: float,
    base_mm: float,
    outline: str = "mask",
    compress: float = 0.0,
    invert: bool = False,
    border_mm: float = 0.0,
    min_wall_mm: float = MIN_WALL_MM,
    max_triangles: int | None = None,
    names: dict[str, str] | None = None,
) -> dict:
    """:func:`relief`'s options checked, as a dict of the same names (floats, a bool, an int or
    None), so that a caller (the CLI) can refuse a bad request before any work.

    Parameters
    ----------
    width_mm, height_mm, base_mm, outline, compress, invert, border_mm, min_wall_mm, max_triangles
        As for :func:`relief`.
    names : dict of str to str, optional
        What to call an option in the messages, e.g. ``{"width_mm": "--width"}`` (the CLI's flags);
        by default its name here.

    Raises
    ------
    InputError
        As :func:`relief` does for its options, including the ``print`` extra missing when
        ``max_triangles`` is given.
    """
    names = {key: (names or {}).get(key, key) for key in _OPTION_NAMES}
    width_mm, height_mm, base_mm = (
        within(positive(value, names[key]), names[key], *SIZE_RANGE_MM, unit="mm")
        for value, key in ((width_mm, "width_mm"), (height_mm, "height_mm"), (base_mm, "base_mm"))
    )
    min_wall_mm = positive(min_wall_mm, names["min_wall_mm"])
    if base_mm < min_wall_mm:
        raise InputError(
            f"a base of {base_mm:g} mm ({names['base_mm']}) is thinner than the thinnest wall allowed, "
            f"{min_wall_mm:g} mm; make the base at least that thick, or lower {names['min_wall_mm']} "
            "for a printer that makes thinner walls"
        )
    outline = check_choice(outline, OUTLINES, names["outline"])
    compress = finite(compress, names["compress"])
    if not 0.0 <= compress <= 1.0:
        raise InputError(f"{names['compress']} must be in [0, 1] (0: linear scaling), got {compress:g}")
    border_mm = finite(border_mm, names["border_mm"])
    if border_mm < 0 or 2 * border_mm >= width_mm:
        raise InputError(
            f"{names['border_mm']} must be >= 0 and less than half of the width ({width_mm:g} mm), "
            f"got {border_mm:g}"
        )
    if max_triangles is not None:
        max_triangles = whole(max_triangles, names["max_triangles"], minimum=MIN_TRIANGLES)
        require_print_extra(load=False)
    return dict(
        width_mm=width_mm,
        height_mm=height_mm,
        base_mm=base_mm,
        outline=outline,
        compress=compress,
        invert=bool(invert),
        border_mm=border_mm,
        min_wall_mm=min_wall_mm,
        max_triangles=max_triangles,
    )


_OPTION_NAMES = (
    "width_mm",
    "height_mm",
    "base_mm",
    "outline",
    "compress",
    "border_mm",
    "min_wall_mm",
    "max_triangles",
)


def require_print_extra(*, load: bool = True):
    """``(fast_simplification.simplify, manifold3d.triangulate)``, or an error naming the extra;
    with ``load=False`` only whether both are installed is checked, and None returned."""
    if not load:
        for module in ("fast_simplification", "manifold3d"):
            if importlib.util.find_spec(module) is None:
                raise InputError(
                    f"a triangle budget needs {module.replace('_', '-')}, which is not installed; "
                    f"install the print extra: {_PRINT_EXTRA}"
                )
        return None
    try:
        from fast_simplification import simplify
        from manifold3d import triangulate
    except ImportError as err:
        raise InputError(
            f"a triangle budget needs {err.name or 'fast-simplification and manifold3d'}, which is not "
            f"installed; install the print extra: {_PRINT_EXTRA}"
        ) from None
    return simplify, triangulate
