"""Concave regions: where the user says the surface curves away from the viewer.

The 2002 method assumes a convex surface; inside a user-drawn polygon the convexity choice is
flipped for one image axis or both. The file format (``docs/conventions.md``) is JSON with
coordinates in pixels of the input image, ``x`` = column and ``y`` = row::

    {"regions": [{"polygon": [[x, y], [x, y], [x, y]], "axis": "x" | "y" | "both"}]}

``axis`` names the image direction in which the surface is concave: a bowl is ``"both"``, a
horizontal trough is ``"y"``.
"""

from __future__ import annotations

import json
import numbers
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from skimage.draw import polygon2mask

from shadeform._checks import regular_file
from shadeform.errors import InputError

AXES = ("x", "y", "both")

#: The largest coordinate a region's point may have, in pixels. A polygon may reach past the frame
#: (it is clipped there), but no photo has a side near 1e10 pixels (the loader's default limit is
#: 6.7e7 pixels in all): a point beyond is a typing mistake, not a region, and float64 arithmetic
#: on the polygon keeps the pixel grid only for coordinates far below 1e16.
MAX_COORDINATE = 1e10

_FORMAT = '{"regions": [{"polygon": [[x, y], ...], "axis": "x" | "y" | "both"}]}'


@dataclass(frozen=True, eq=False)
class Region:
    """One concave region.

    Attributes
    ----------
    polygon : (N, 2) float64
        Vertices ``(x, y)`` = (column, row) in pixels of the input image, N >= 3, read-only.
    axis : {"x", "y", "both"}
        Image direction(s) in which the surface is concave inside the polygon.
    """

    polygon: np.ndarray
    axis: str

    def __post_init__(self):
        polygon = np.array(self.polygon, dtype=np.float64)
        if polygon.ndim != 2 or polygon.shape[1] != 2 or polygon.shape[0] < 3:
            raise InputError(f"polygon must have shape (N, 2) with N >= 3, got {polygon.shape}")
        if not np.isfinite(polygon).all():
            raise InputError("polygon coordinates must be finite numbers")
        if self.axis not in AXES:
            raise InputError(f"axis must be 'x', 'y' or 'both', got {self.axis!r}")
        polygon.flags.writeable = False
        object.__setattr__(self, "polygon", polygon)


def parse_regions(source) -> tuple[Region, ...]:
    """Read concave regions from parsed JSON, a JSON string or a ``.json`` file.

    Parameters
    ----------
    source : dict, str or pathlib.Path
        The document already parsed, its text, or the path of a file holding it. A ``str`` is
        always JSON text; pass a :class:`pathlib.Path` to read a file.

    Returns
    -------
    tuple of Region
        In file order; empty if the list is empty.

    Raises
    ------
    InputError
        A missing or unreadable file, invalid JSON (with line and column), or a document not
        of the form in ``docs/conventions.md``; the message names the region (counted from 1)
        and the point at fault.

    Examples
    --------
    >>> (r,) = parse_regions('{"regions": [{"polygon": [[0, 0], [9, 0], [9, 9]], "axis": "x"}]}')
    >>> r.axis, r.polygon.shape
    ('x', (3, 2))
    """
    where = "regions JSON"
    if isinstance(source, Path):
        where = f"regions file {str(source)!r}"
        try:
            text = regular_file(source, "regions file").read_text(encoding="utf-8")
        except FileNotFoundError:
            raise InputError(f"{where} not found; check the path") from None
        except IsADirectoryError:
            raise InputError(f"{where} is a folder; pass the .json file inside it") from None
        except UnicodeDecodeError:
            raise InputError(f"{where} is not UTF-8 text; save it as UTF-8 JSON") from None
        except OSError as err:
            raise InputError(f"cannot read {where}: {err.strerror}") from None
        document = loads_json(text, where)
    elif isinstance(source, str):
        where = "regions text"
        if not source.lstrip().startswith(("{", "[")):
            where += " (a str is JSON text; pass a pathlib.Path to read a file)"
        document = loads_json(source, where)
    elif isinstance(source, dict):
        document = source
    else:
        raise InputError(
            f"regions must be a dict, a JSON string or a pathlib.Path, got {type(source).__name__}"
        )

    if not isinstance(document, dict):
        raise InputError(f"{where} must be an object, got {_kind(document)}; expected {_FORMAT}")
    if "regions" not in document:
        raise InputError(f"{where} has no 'regions' key; expected {_FORMAT}")
    entries = document["regions"]
    if not isinstance(entries, list):
        raise InputError(f"'regions' in {where} must be a list, got {_kind(entries)}")
    return tuple(_region(entry, i) for i, entry in enumerate(entries, start=1))


def as_regions(concave) -> tuple[Region, ...]:
    """Concave regions from any form a user gives them: what ``concave=`` means everywhere.

    Parameters
    ----------
    concave : dict, str, path, sequence of Region, or None
        Parsed JSON or JSON text in the format of ``docs/conventions.md``, a path to a ``.json``
        file (see :func:`parse_regions`), regions already made, or None for none.

    Returns
    -------
    tuple of Region
    """
    if concave is None:
        return ()
    if isinstance(concave, (dict, str, Path)):
        return parse_regions(concave)
    try:
        regions = tuple(concave)
    except TypeError:
        regions = None
    if regions is None or not all(isinstance(region, Region) for region in regions):
        raise InputError("concave must be a regions dict, JSON text, a .json path or a sequence of Region")
    return regions


def regions_to_json(regions) -> dict:
    """The JSON document of ``regions``; ``parse_regions`` reads it back unchanged.

    Parameters
    ----------
    regions : iterable of Region

    Returns
    -------
    dict
        ``{"regions": [{"polygon": [[x, y], ...], "axis": ...}, ...]}`` with float
        coordinates, ready for :func:`json.dumps`.
    """
    return {
        "regions": [
            {"polygon": [[float(x), float(y)] for x, y in r.polygon], "axis": r.axis} for r in regions
        ]
    }


def concave_masks(regions, shape) -> tuple[np.ndarray, np.ndarray]:
    """Rasterise concave regions into one mask per image axis.

    A pixel belongs to a polygon when its centre ``(x = column, y = row)`` lies inside it or on
    its boundary. Parts of polygons outside the image are clipped.

    Parameters
    ----------
    regions : iterable of Region
        From :func:`parse_regions`.
    shape : tuple of int
        Image shape; ``(H, W)`` or ``(H, W, C)``, only the first two are used.

    Returns
    -------
    concave_x : (H, W) bool
        Pixels in a region with axis ``"x"`` or ``"both"``.
    concave_y : (H, W) bool
        Pixels in a region with axis ``"y"`` or ``"both"``.
    """
    if len(shape) < 2 or any(not isinstance(n, numbers.Integral) or n < 1 for n in shape[:2]):
        raise InputError(f"shape must start with two positive integers (H, W), got {shape!r}")
    height, width = int(shape[0]), int(shape[1])
    concave_x = np.zeros((height, width), dtype=bool)
    concave_y = np.zeros((height, width), dtype=bool)
    for region in regions:
        # polygon2mask takes (row, column) vertices.
        inside = polygon2mask((height, width), region.polygon[:, ::-1])
        if region.axis in ("x", "both"):
            concave_x |= inside
        if region.axis in ("y", "both"):
            concave_y |= inside
    return concave_x, concave_y


def outline_polygon(inside: np.ndarray, *, tolerance: float = 1.0) -> np.ndarray:
    """The outer outline of a pixel area as a region's polygon: the inverse of :func:`concave_masks`.

    Parameters
    ----------
    inside : (H, W) bool
        The area's pixels (one connected area; the largest outline is taken).
    tolerance : float, keyword-only
        Douglas-Peucker tolerance of the simplification, in pixels.

    Returns
    -------
    (N, 2) float64
        Vertices ``(x, y)`` = (column, row), N >= 3, the first not repeated at the end.
    """
    from scipy import ndimage as ndi
    from skimage.measure import find_contours

    rows, cols = ndi.find_objects(inside.astype(np.int8))[0]
    # a pixel of margin closes the contour where the area meets the image frame
    padded = np.pad(inside[rows, cols], 1).astype(np.float64)
    contour = max(find_contours(padded, 0.5), key=len)
    simple = _simplified(contour, tolerance)[:-1]  # closed: last repeats first
    if len(simple) < 3:
        simple = contour[:-1]
    offset = np.array([rows.start - 1, cols.start - 1], dtype=np.float64)
    return (simple + offset)[:, ::-1].copy()


def loads_json(text: str, where: str):
    """``json.loads(text)``, with a one-line :class:`InputError` naming ``where`` for text that is
    not JSON or nests too deeply (the decoder recurses once per level)."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(
            f"{where} is not valid JSON: {err.msg} at line {err.lineno}, column {err.colno}"
        ) from None
    except RecursionError:
        raise InputError(f"{where} nests lists or objects too deeply; give a flat JSON document") from None
    except ValueError:  # a whole number of more digits than Python converts (sys.get_int_max_str_digits)
        raise InputError(f"{where} holds a number with thousands of digits; give ordinary numbers") from None


def _region(entry, index: int) -> Region:
    """Validate one entry of the ``regions`` list, naming it in every message."""
    at = f"in region {index}"
    if not isinstance(entry, dict):
        raise InputError(f"each region must be an object with 'polygon' and 'axis'; {at}")
    if "polygon" not in entry:
        raise InputError(f"missing 'polygon' {at}; give a list of [x, y] points")
    if "axis" not in entry:
        raise InputError(f"missing 'axis' {at}; use 'x', 'y' or 'both'")
    axis = entry["axis"]
    if not isinstance(axis, str) or axis not in AXES:
        raise InputError(f"axis must be 'x', 'y' or 'both', got {axis!r} {at}")
    points = entry["polygon"]
    if not isinstance(points, (list, tuple)):
        raise InputError(f"'polygon' must be a list of [x, y] points, got {_kind(points)} {at}")
    if len(points) < 3:
        raise InputError(f"polygon needs at least 3 points, got {len(points)} {at}")
    vertices = np.empty((len(points), 2), dtype=np.float64)
    for k, point in enumerate(points, start=1):
        if not isinstance(point, (list, tuple)) or len(point) != 2:
            raise InputError(f"point {k} must be [x, y], got {_short(point)} {at}")
        for j, value in enumerate(point):
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise InputError(f"point {k} has a non-numeric coordinate {_short(value)} {at}")
            far = (
                f"point {k} has the coordinate {_short(value)} {at}; give pixel coordinates within "
                f"{MAX_COORDINATE:.0e} of the image"
            )
            try:
                vertices[k - 1, j] = value
            except OverflowError:  # a whole number beyond any float
                raise InputError(far) from None
            if not np.isfinite(vertices[k - 1, j]):
                raise InputError(f"point {k} has a non-finite coordinate {_short(value)} {at}")
            if abs(vertices[k - 1, j]) > MAX_COORDINATE:
                raise InputError(far)
    return Region(polygon=vertices, axis=axis)


def _kind(value) -> str:
    names = {dict: "an object", list: "a list", str: "a string", type(None): "null"}
    return names.get(type(value), type(value).__name__)


def _short(value) -> str:
    """A short JSON-like rendering of a bad value for a one-line message."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _simplified(points, tolerance):
    """The vertices of the polyline ``points`` (N, 2) that Douglas-Peucker keeps at ``tolerance``.

    Each chord keeps its farthest point (the first of equals) when that lies more than
    ``tolerance`` from it, and both halves are simplified again. A point that projects strictly
    inside the chord is measured to the chord's line, any other (a closed chord's, whose ends are
    one point) to the nearer end. The result is :func:`skimage.measure.approximate_polygon`'s
    (the tests compare them), without that module's import of scipy.signal: a third of a second
    at start-up.
    """
    keep = np.zeros(len(points), dtype=bool)
    keep[[0, -1]] = True
    chords = [(0, len(points) - 1)]
    while chords:
        start, end = chords.pop()
        if end - start < 2:
            continue
        (r0, c0), (r1, c1) = points[start], points[end]
        dr, dc = r1 - r0, c1 - c0
        angle = -np.arctan2(dr, dc)
        rows, cols = points[start + 1 : end, 0], points[start + 1 : end, 1]
        to_start = np.sqrt((cols - c0) ** 2 + (rows - r0) ** 2)
        to_end = np.sqrt((cols - c1) ** 2 + (rows - r1) ** 2)
        distance = np.minimum(to_start, to_end)
        within = ((rows - r0) * dr + (cols - c0) * dc > 0) & (-(rows - r1) * dr - (cols - c1) * dc > 0)
        line = c0 * np.sin(angle) + r0 * np.cos(angle)
        distance[within] = np.abs(rows[within] * np.cos(angle) + cols[within] * np.sin(angle) - line)
        if (distance > tolerance).any():
            split = start + 1 + int(np.argmax(distance))
            keep[split] = True
            chords += [(split, end), (start, split)]
    return points[keep]
