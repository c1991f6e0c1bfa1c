"""A depth map made into a print-ready solid: :class:`Relief` and :func:`relief`, and the steps
that call the grid solid (:mod:`shadeform.solid.grid`): the depth scaled, a rim added, the finest
grid whose simplification passes, the height fitted and how far the print lies from the relief."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shadeform.errors import InputError
from shadeform.mesh import Mesh, vertex_normals
from shadeform.reconstruction import Reconstruction
from shadeform.solid.compress import compress_depth
from shadeform.solid.grid import _grid_solid, _sample
from shadeform.solid.options import MIN_WALL_MM, check_options, grid_step, require_print_extra

__all__ = ["Relief", "relief"]

# more grids are tried only if a simplified one is refused; each is 1.5x coarser
_COARSER = 1.5
_MAX_TRIES = 12


@dataclass(frozen=True, eq=False)
class Relief(Mesh):
    """A print-ready solid: a closed, outward-oriented :class:`~shadeform.mesh.Mesh` in mm.

    Attributes
    ----------
    vertices, faces, normals, uv, unit
        As for :class:`~shadeform.mesh.Mesh`; ``unit`` is ``"millimeter"``, ``uv`` None. The
        base lies on ``z = 0``, the outline's bounding box starts at ``x = y = 0``.
    deviation_mm : float
        Largest distance, mm, from the relief at full resolution (a point per object pixel under
        the printed top) to the printed top surface: what a triangle budget cost; 0 when every
        pixel is a vertex.
    pixel_mm : float
        Size of one input pixel in the print, mm.
    """

    unit: str = "millimeter"
    deviation_mm: float = 0.0
    pixel_mm: float = 1.0

    @property
    def size_mm(self) -> np.ndarray:
        """``(3,)`` extent along x, y, z in mm (z: base plus relief)."""
        return self.vertices.max(axis=0) - self.vertices.min(axis=0)

    @property
    def volume_mm3(self) -> float:
        """Enclosed volume in mm^3 (divergence theorem; positive when the faces wind outward)."""
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def relief(
    source,
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
) -> Relief:
    """A closed, printable solid of a depth map: the surface on top of walls and a flat base.

    Parameters
    ----------
    source : Reconstruction or (H, W) float array
        A reconstruction (its ``depth`` on its ``mask``) or a depth map in pixel units, larger =
        nearer the viewer, NaN off the object (``docs/conventions.md``).
    width_mm : float, keyword-only
        Longest side of the outline's bounding box (rim included), mm; exact.
    height_mm : float, keyword-only
        Relief depth: from the surface's lowest to its highest point, mm; exact. The solid is
        ``base_mm + height_mm`` tall.
    base_mm : float, keyword-only
        Thickness of the flat base under the surface's lowest point, mm.
    outline : {"mask", "frame"}, keyword-only
        ``"mask"``: the walls follow the object's outline (several parts make several solids;
        holes in the mask are holes through the solid). ``"frame"``: a rectangle, the image
        frame, the background at the surface's lowest level (a plaque).
    compress : float, keyword-only
        Bas-relief compression in ``[0, 1]`` (:func:`compress_depth`): 0 scales the depth
        linearly; larger values flatten steep slopes and depth jumps more while keeping fine
        detail, so detail takes a larger share of ``height_mm``.
    invert : bool, keyword-only
        Engrave instead of emboss: the highest point becomes the lowest (and the rim and the
        frame's background the top).
    border_mm : float, keyword-only
        Width of a flat rim around the outline, mm, at the relief's lowest level (its top when
        ``invert``); 0 for none. Rounded to whole pixels; ``width_mm`` includes it.
    min_wall_mm : float, keyword-only
        The thinnest wall the printer makes, mm; a thinner base is refused.
    max_triangles : int, keyword-only
        Triangle budget, at least 12. Default: no budget (two triangles per pixel on top and on
        the base). Needs the ``print`` extra (``fast-simplification``).

    Returns
    -------
    Relief
        Vertices in mm, base on ``z = 0``, ``x`` along the image's columns, ``y`` up the image;
        every edge shared by exactly two triangles, the faces counter-clockwise seen from
        outside. ``deviation_mm`` says how far a budget moved the surface.

    Raises
    ------
    InputError
        Non-positive sizes, a base thinner than ``min_wall_mm``, a rim as wide as half the
        width, ``compress`` outside ``[0, 1]``, a budget below 12 triangles (or too small for the
        outline), a flat depth map or one without a 2 x 2 block of object pixels, or the
        ``print`` extra missing when a budget is given.

    Notes
    -----
    The top has a vertex at every pixel (every ``k``-th with a budget) where the depth is
    finite; x and y are pixel centres times ``pixel_mm``. Without a budget the solid has about
    four triangles per pixel and the peak memory is about 400 bytes per pixel (traced: 360 for a
    3 Mpx frame; a 12 Mpx frame would take about 4.5 GB): give ``max_triangles`` for large
    photos. With a budget of 200,000 triangles a 12 Mpx depth map takes 1-2 s
    (``benchmarks/results/relief.md``).

    Examples
    --------
    >>> from shadeform import synth
    >>> solid = relief(synth.scene("sphere", size=64).depth, width_mm=50, height_mm=5, base_mm=2)
    >>> [round(float(v), 6) for v in solid.size_mm]
    [50.0, 50.0, 7.0]
    """
    options = check_options(
        width_mm=width_mm,
        height_mm=height_mm,
        base_mm=base_mm,
        outline=outline,
        compress=compress,
        invert=invert,
        border_mm=border_mm,
        min_wall_mm=min_wall_mm,
        max_triangles=max_triangles,
    )
    depth, valid = _source(source)
    width_mm, height_mm, base_mm = options["width_mm"], options["height_mm"], options["base_mm"]
    outline, compress, invert = options["outline"], options["compress"], options["invert"]
    border_mm, max_triangles = options["border_mm"], options["max_triangles"]
    print_tools = None if max_triangles is None else require_print_extra()
    heights, domain = _heights(depth, valid, outline, compress, height_mm, bool(invert))
    floor = height_mm if invert else 0.0
    if border_mm > 0:
        heights, domain = _add_rim(heights, domain, border_mm, width_mm, floor, frame=outline == "frame")
    return _solid(heights, domain, width_mm, height_mm, base_mm, max_triangles, print_tools)


# --- the steps of relief() -----------------------------------------------------------------


def _source(source) -> tuple[np.ndarray, np.ndarray]:
    """Depth (H, W) float64 and where it is defined, from a reconstruction or a depth map."""
    if isinstance(source, Reconstruction):
        depth = np.asarray(source.depth, dtype=np.float64)
        valid = np.asarray(source.mask, dtype=bool)
        if valid.shape != depth.shape:
            raise InputError(
                f"reconstruction depth has shape {depth.shape} but its mask {valid.shape}; they must match"
            )
    elif isinstance(source, np.ndarray):
        if source.ndim != 2 or not np.issubdtype(source.dtype, np.number) or source.dtype == bool:
            raise InputError(
                f"depth must be a 2-D array of numbers (H, W), got shape {source.shape}, dtype {source.dtype}"
            )
        depth = source.astype(np.float64)
        valid = np.ones(depth.shape, dtype=bool)
    else:
        raise InputError(
            f"relief takes a Reconstruction or a depth map (2-D numpy array), got {type(source).__name__}"
        )
    valid = valid & np.isfinite(depth)
    if not (valid[:-1, :-1] & valid[:-1, 1:] & valid[1:, :-1] & valid[1:, 1:]).any():
        raise InputError("the depth map has no 2 x 2 block of object pixels; a relief needs a larger object")
    return depth, valid


def _heights(depth, valid, outline, compress, height_mm, invert) -> tuple[np.ndarray, np.ndarray]:
    """The relief's surface height in mm, ``[0, height_mm]``, NaN off the domain, and the domain."""
    if outline == "frame":
        domain = np.ones(depth.shape, dtype=bool)
        z = np.where(valid, depth, depth[valid].min())  # the background at the object's lowest point
    else:
        domain = valid
        z = np.where(valid, depth, np.nan)
    if compress > 0:
        z = compress_depth(z, domain, compress=compress)
    low, high = float(np.nanmin(z)), float(np.nanmax(z))
    if not high > low:
        raise InputError("the depth map is flat (one height everywhere): there is no relief to print")
    heights = (z - low) * (height_mm / (high - low))
    if invert:
        heights = height_mm - heights
    return heights, domain


def _add_rim(heights, domain, border_mm, width_mm, floor, *, frame) -> tuple[np.ndarray, np.ndarray]:
    """The domain grown by a flat rim of ``border_mm`` (in pixels of the final scale) at ``floor``."""
    import scipy.ndimage as ndi

    rows = np.flatnonzero(domain.any(axis=1))
    cols = np.flatnonzero(domain.any(axis=0))
    extent = max(rows[-1] - rows[0], cols[-1] - cols[0])
    # the rim is b pixels wide when the final scale is width / (extent + 2 b)
    pad = max(1, round(border_mm * extent / (width_mm - 2 * border_mm)))
    heights = np.pad(heights, pad, constant_values=np.nan)
    grown = np.pad(domain, pad, constant_values=False)
    if frame:
        rim = ~grown
    else:
        box = np.s_[rows[0] : rows[-1] + 2 * pad + 1, cols[0] : cols[-1] + 2 * pad + 1]
        rim = np.zeros(grown.shape, dtype=bool)
        rim[box] = (ndi.distance_transform_edt(~grown[box]) <= pad) & ~grown[box]
    heights[rim] = floor
    return heights, grown | rim


def _solid(heights, domain, width_mm, height_mm, base_mm, max_triangles, print_tools) -> Relief:
    """Build the solid; with a budget, on the finest grid whose simplification fits and passes."""
    step = grid_step(int(domain.sum()), max_triangles)
    for _ in range(_MAX_TRIES):
        grid = _sample(heights, domain, step)
        if not grid.cells.any():
            break
        built = _grid_solid(grid, width_mm, base_mm, max_triangles, print_tools)
        if built is not None:
            vertices, faces, pixel_mm, origin, simplified = built
            moved = _fit_height(vertices, base_mm, height_mm)
            if step == 1 and not simplified:
                deviation = moved  # every pixel is a vertex: only the height fit moved any
            else:
                deviation = _deviation(vertices, faces, heights, base_mm, pixel_mm, origin)
            return Relief(
                vertices, faces, vertex_normals(vertices, faces), deviation_mm=deviation, pixel_mm=pixel_mm
            )
        step = max(step + 1, math.ceil(step * _COARSER))
    raise InputError(
        f"the outline does not fit in {max_triangles:,} triangles; allow more (max_triangles) "
        "or use outline='frame'"
    )


def _fit_height(vertices: np.ndarray, base_mm: float, height_mm: float) -> float:
    """Scale the top's heights, in place, to span exactly ``[base_mm, base_mm + height_mm]``
    (sampling and quadric placement move the extremes slightly; a vertical affine map keeps the
    top a height field and every triangle's footprint), the base to ``z = 0``; returns the
    largest change of a top vertex, mm."""
    top = vertices[:, 2] > 0.5 * base_mm
    z = vertices[top, 2]
    low, high = z.min(), z.max()
    fitted = base_mm + (z - low) * (height_mm / (high - low)) if high > low else z
    vertices[top, 2] = fitted
    vertices[~top, 2] = 0.0
    return float(np.abs(fitted - z).max())


def _deviation(vertices, faces, heights, base_mm, pixel_mm, origin) -> float:
    """Largest distance, mm, from the full-resolution relief's points ``(c, r, base_mm +
    heights[r, c])`` (every pixel under the printed top) to the printed top surface.

    Each pixel's distance to the triangle above or below it bounds its distance to the surface
    from above; the nearest triangle is searched only for the pixels with the largest bounds,
    until the largest distance found is at least every bound left. So the result is exact without
    a search at every pixel. (The vertical gap alone would report a cliff's whole height where a
    coarser grid moves it sideways by a fraction of a pixel.)
    """
    col0, row1 = origin
    top = faces[(vertices[faces, 2] > 0.5 * base_mm).all(axis=1)]
    corners = vertices[top]  # (T, 3, 3), in pixel units below: x = column, y = row, z / pixel_mm
    tri = np.empty_like(corners)
    tri[..., 0] = corners[..., 0] / pixel_mm + col0
    tri[..., 1] = row1 - corners[..., 1] / pixel_mm
    tri[..., 2] = (corners[..., 2] - base_mm) / pixel_mm
    from shadeform.solid.distance import (
        BOUND_SHARES,
        BUCKET_PIXELS,
        buckets,
        covering_distances,
        largest_distance,
    )

    surface = np.ascontiguousarray(heights / pixel_mm, dtype=np.float64)
    bounds = np.full(surface.shape, np.nan, dtype=np.float32)
    covering_distances(tri, surface, bounds)
    flat = bounds.ravel()
    where = np.flatnonzero(np.isfinite(flat))
    if where.size == 0:
        return 0.0
    values = flat[where]
    starts, members = buckets(tri, surface.shape, BUCKET_PIXELS)
    found = 0.0
    thresholds = np.quantile(values, [1.0 - share for share in BOUND_SHARES])
    for threshold in thresholds:
        # the pixels whose bound could still beat the largest distance found
        pick = where[values >= max(threshold, found)]
        rows, cols = np.divmod(pick, surface.shape[1])
        found = max(found, largest_distance(rows, cols, surface, tri, starts, members, BUCKET_PIXELS))
        if found >= threshold:
            break
    return float(found * pixel_mm)
