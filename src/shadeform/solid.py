"""Print-ready reliefs: a depth map as a closed solid in millimetres (STL, 3MF).

:func:`relief` turns a reconstruction (or any depth map) into a watertight, outward-oriented solid
a slicer can print: the recovered surface on top, vertical walls along the object's outline (or
the image frame), a flat base. Its size is given in millimetres: the outline's longest side,
the relief's depth from its lowest to its highest point, the base's thickness.

How the solid is built (all on the pixel grid, so it is closed by construction):

1. The depth is scaled to ``[0, height_mm]``, optionally compressed first (bas-relief,
   :func:`compress_depth`), inverted (engraving) and surrounded by a flat rim (``border_mm``).
2. The top: two triangles per grid cell whose four corners are on the object
   (:func:`shadeform.mesh.cell_triangles`); cells that touch another only at a corner are
   dropped, so every boundary vertex has one edge in and one out (no pinched vertex).
3. The walls: one vertical quad below every boundary edge of the top, down to ``z = 0``; the
   base: the top's cells again at ``z = 0``, wound the other way. Every edge is then shared by
   exactly two triangles, wound consistently, facing out.
4. With a triangle budget, the height field is first sampled every ``k`` pixels so that the
   grid's top has about :data:`OVERSAMPLE` times the
   budget; the top is simplified by quadric edge collapses (Garland & Heckbert 1997, via
   ``fast-simplification``) with its boundary kept, the base is the outline's loops triangulated
   (manifold3d), and the walls join the two along the unchanged boundary. The simplified top is
   accepted only if it still projects onto the plane without a fold or an overlap (every triangle
   turning counter-clockwise, their areas summing to the outline's): then the solid cannot
   intersect itself. Otherwise a coarser grid is tried. ``Relief.deviation_mm`` reports how far
   the printed top lies from the full-resolution relief.

References
----------
.. [1] T. Weyrich, J. Deng, C. Barnes, S. Rusinkiewicz, A. Finkelstein, "Digital bas-relief from
   3D scenes", ACM Transactions on Graphics 26(3), 32, 2007 (SIGGRAPH).
.. [2] J. Kerber, A. Tevs, A. Belyaev, R. Zayer, H.-P. Seidel, "Feature sensitive bas relief
   generation", IEEE Shape Modeling and Applications (SMI), 148-154, 2009.
.. [3] R. Fattal, D. Lischinski, M. Werman, "Gradient domain high dynamic range compression",
   ACM Transactions on Graphics 21(3), 249-256, 2002 (SIGGRAPH).
.. [4] M. Garland, P. S. Heckbert, "Surface simplification using quadric error metrics",
   SIGGRAPH 1997, 209-216.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass

import numpy as np

from shadeform._checks import check_choice, finite, positive, whole, within
from shadeform.errors import InputError
from shadeform.mesh import Mesh, cell_triangles
from shadeform.reconstruction import Reconstruction

__all__ = [
    "MIN_WALL_MM",
    "OUTLINES",
    "OVERSAMPLE",
    "Relief",
    "check_options",
    "compress_depth",
    "grid_step",
    "relief",
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
# relative tolerance of the area checks after simplification: float64 sums of up to ~1e7 areas
_AREA_TOLERANCE = 1e-9
# more grids are tried only if a simplified one is refused; each is 1.5x coarser
_COARSER = 1.5
_MAX_TRIES = 12
# relative residual at which the compressed depth's least-squares solve stops: the relief is
# printed to ~1e-3 of its height, and 1e-6 moved no bump share of tests/test_relief.py in its 4th digit
_COMPRESS_TOLERANCE = 1e-6
# faces per chunk where a whole-mesh temporary would be large (vertex normals)
_CHUNK_FACES = 1 << 20
# (row, column) offsets of a cell's corners: top-left, top-right, bottom-left, bottom-right
_CORNERS = ((0, 0), (0, 1), (1, 0), (1, 1))


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
    print_tools = None if max_triangles is None else _require_print_extra()
    heights, domain = _heights(depth, valid, outline, compress, height_mm, bool(invert))
    floor = height_mm if invert else 0.0
    if border_mm > 0:
        heights, domain = _add_rim(heights, domain, border_mm, width_mm, floor, frame=outline == "frame")
    return _solid(heights, domain, width_mm, height_mm, base_mm, max_triangles, print_tools)


def grid_step(pixels: int, max_triangles: int | None) -> int:
    """Every how many pixels :func:`relief` samples the surface of ``pixels`` pixels for a budget.

    About :data:`OVERSAMPLE` times the budget's triangles on top (two per grid cell) before the
    quadric simplification; 1 (every pixel) without a budget. A depth map solved only on this
    grid (:func:`shadeform.pipeline.reconstruct_on_grid`) gives the solid all it keeps, at
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
        _require_print_extra(load=False)
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


def compress_depth(depth: np.ndarray, mask: np.ndarray, *, compress: float) -> np.ndarray:
    """Bas-relief compression: steep slopes and depth jumps flattened, fine detail kept.

    The depth differences between 4-neighbour pixels are scaled down where the gradient is steep
    and integrated back by least squares (the project's multigrid Poisson solver,
    :class:`shadeform.integration._multigrid.PairHierarchy`), as in the gradient-domain
    bas-relief methods of Weyrich et al. (2007) and Kerber et al. (2009). The attenuation is
    Fattal et al.'s (2002) power law: a pixel whose gradient magnitude ``g`` exceeds ``alpha``
    has its slopes multiplied by ``(g / alpha) ** -compress``; gentler slopes are left as they
    are (not amplified: noise stays noise). ``alpha`` is the mean magnitude over the object (a
    depth jump adds its height spread over the object, not its one-pixel slope), so only slopes
    steeper than the object's typical one shrink, the more the steeper they are: a jump's slope
    ``g`` becomes ``alpha ** c * g ** (1 - c)``, while a small bump whose slopes stay near the
    mean keeps its relief. Each pair of pixels gets the mean of the two pixels' factors. A plane
    is left as it is (every slope is the mean); ``tests/test_relief.py`` and
    ``benchmarks/results/relief.md`` show a jump with bumps: at ``compress=0.5`` the bumps take
    3.6 times the share of the height that linear scaling leaves them.

    Parameters
    ----------
    depth : (H, W) float
        Height, finite on the mask.
    mask : (H, W) bool
        Where the depth is defined.
    compress : float, keyword-only
        Exponent ``c`` in ``[0, 1]``: 0 returns the depth unchanged, 1 clamps every slope above
        ``alpha`` to ``alpha``.

    Returns
    -------
    (H, W) float64
        The compressed height, NaN off the mask. Each connected part keeps its mean scaled by
        the factor the largest part's depth range was compressed by.

    References
    ----------
    Weyrich et al. 2007, Kerber et al. 2009, Fattal et al. 2002: see the module's references.
    """
    from shadeform.integration._multigrid import PairHierarchy

    mask = np.asarray(mask, dtype=bool)
    depth = np.asarray(depth, dtype=np.float64)
    out = np.where(mask, depth, np.nan)
    compress = finite(compress, "compress")
    if not mask.any() or compress == 0:
        return out
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    box = np.s_[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
    m = np.ascontiguousarray(mask[box])
    z = np.where(m, depth[box], 0.0)
    h, w = m.shape
    # pairs (r, c)-(r, c + 1) and (r, c)-(r + 1, c) on the object; differences along them
    across = m[:, :-1] & m[:, 1:]
    down = m[:-1] & m[1:]
    dx = np.where(across, z[:, 1:] - z[:, :-1], 0.0)
    dy = np.where(down, z[1:] - z[:-1], 0.0)
    # the pixel's gradient: the mean of the differences on its sides that exist
    magnitude = _side_mean(dx, across, axis=1) ** 2
    magnitude += _side_mean(dy, down, axis=0) ** 2
    np.sqrt(magnitude, out=magnitude)
    alpha = float(magnitude[m].mean())
    if not alpha > 0:
        return out
    # the attenuation factor of each pixel (in place of its magnitude), each pair the mean of two
    factor = magnitude
    factor /= alpha
    np.maximum(factor, 1.0, out=factor)
    np.power(factor, -compress, out=factor)
    dx *= 0.5 * (factor[:, :-1] + factor[:, 1:])
    dy *= 0.5 * (factor[:-1] + factor[1:])
    del factor, magnitude
    # normal equations of min sum (z_j - z_i - t_ij)^2: L z = D^T t
    b = np.zeros((h, w))
    b[:, :-1] -= dx
    b[:, 1:] += dx
    b[:-1] -= dy
    b[1:] += dy
    del dx, dy
    px = np.zeros((h, w))
    px[:, :-1] = across
    py = np.zeros((h, w))
    py[:-1] = down
    hierarchy = PairHierarchy(m, px, py)
    solved, _, _ = hierarchy.solve_pairs(b, np.zeros((h, w)), tol=_COMPRESS_TOLERANCE, maxiter=500)
    # each part's offset: its mean, scaled as the largest part's range was
    labels = hierarchy.labels
    on = labels >= 0
    counts = np.bincount(labels[on], minlength=hierarchy.n_parts)
    old_mean = np.bincount(labels[on], weights=z[on], minlength=hierarchy.n_parts) / np.maximum(counts, 1)
    new_mean = np.bincount(labels[on], weights=solved[on], minlength=hierarchy.n_parts) / np.maximum(
        counts, 1
    )
    largest = labels == np.argmax(counts)
    old_range = np.ptp(z[largest])
    ratio = np.ptp(solved[largest]) / old_range if old_range > 0 else 1.0
    solved[on] += (old_mean * ratio - new_mean)[labels[on]]
    out[box] = np.where(m, solved, np.nan)
    return out


# --- the steps of relief() -----------------------------------------------------------------


def _side_mean(differences: np.ndarray, exists: np.ndarray, *, axis: int) -> np.ndarray:
    """Per pixel, the mean of the pair differences on its two sides along ``axis`` that exist
    (``differences``, ``exists``: one shorter than the image along ``axis``)."""
    shape = list(differences.shape)
    shape[axis] += 1
    total = np.zeros(shape)
    count = np.zeros(shape)
    first = [slice(None), slice(None)]
    last = [slice(None), slice(None)]
    first[axis] = slice(None, -1)
    last[axis] = slice(1, None)
    for part in (tuple(first), tuple(last)):
        total[part] += differences
        count[part] += exists
    return total / np.maximum(count, 1.0)


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


def _require_print_extra(*, load: bool = True):
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


@dataclass(frozen=True)
class _Grid:
    """The height field sampled every ``step`` pixels: grid rows/cols in pixels, heights (mm),
    the cells kept (four corners on the domain, no pinch) and the vertex number of each point."""

    rows: np.ndarray
    cols: np.ndarray
    heights: np.ndarray
    cells: np.ndarray
    vertex_id: np.ndarray
    used: np.ndarray


def _sample(heights: np.ndarray, domain: np.ndarray, step: int) -> _Grid:
    """Grid points every ``step`` pixels (the last row and column always in), each the height at
    its pixel. (Means over the pixels around each point were tried: on the 12 Mpx vase of
    ``benchmarks/bench_relief.py`` and on DiLiGenT's cat and buddha and MIT's deer they left the
    simplified top as far or farther from the full-resolution relief, twice as far on the vase,
    whose means are biased along the outline.)"""
    h, w = domain.shape
    rows = _grid_lines(h, step)
    cols = _grid_lines(w, step)
    grid = np.ix_(rows, cols)
    values, ok = heights[grid], domain[grid]
    cells = ok[:-1, :-1] & ok[:-1, 1:] & ok[1:, :-1] & ok[1:, 1:]
    _drop_pinches(cells)
    used = np.zeros(ok.shape, dtype=bool)
    n_r, n_c = cells.shape
    for dr in (0, 1):
        for dc in (0, 1):
            used[dr : dr + n_r, dc : dc + n_c] |= cells
    vertex_id = np.cumsum(used.ravel()).reshape(used.shape) - 1
    return _Grid(rows, cols, values, cells, vertex_id, used)


def _grid_lines(n: int, step: int) -> np.ndarray:
    lines = np.arange(0, n, step)
    return lines if lines[-1] == n - 1 else np.append(lines, n - 1)


def _drop_pinches(cells: np.ndarray) -> None:
    """Drop cells, in place, until no two touch at a corner only (2 x 2 blocks of cells with
    exactly a diagonal pair): such a vertex would be shared by two walls, a non-manifold edge."""
    while True:
        a, b = cells[:-1, :-1], cells[:-1, 1:]
        c, d = cells[1:, :-1], cells[1:, 1:]
        diagonal = a & d & ~b & ~c
        anti = b & c & ~a & ~d
        if not (diagonal.any() or anti.any()):
            return
        d[diagonal] = False
        c[anti] = False


def _boundary_edges(grid: _Grid) -> np.ndarray:
    """The top's boundary edges, ``(E, 2)`` vertex numbers, directed with the top on their left
    (the order they have in :func:`shadeform.mesh.cell_triangles`' triangles)."""
    cells = np.pad(grid.cells, 1)
    inner = np.s_[1:-1, 1:-1]
    vid = grid.vertex_id
    n_r, n_c = grid.cells.shape
    tl, tr = vid[:n_r, :n_c], vid[:n_r, 1:]
    bl, br = vid[1:, :n_c], vid[1:, 1:]
    here = cells[inner]
    edges = []
    for gone, start, end in (
        (~cells[:-2, 1:-1], tr, tl),  # no cell above: the top side, right to left
        (~cells[2:, 1:-1], bl, br),  # below: the bottom side, left to right
        (~cells[1:-1, :-2], tl, bl),  # left: down the left side
        (~cells[1:-1, 2:], br, tr),  # right: up the right side
    ):
        pick = here & gone
        edges.append(np.column_stack([start[pick], end[pick]]))
    return np.concatenate(edges)


def _walls(top_edges: np.ndarray, below: np.ndarray) -> np.ndarray:
    """Two triangles per boundary edge ``a -> b`` of the top, down to the base's copies
    ``below[a]``, ``below[b]``, facing out (to the right of ``a -> b``)."""
    a, b = top_edges[:, 0], top_edges[:, 1]
    a_, b_ = below[a], below[b]
    return np.concatenate([np.column_stack([a, a_, b_]), np.column_stack([a, b_, b])])


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
                vertices, faces, _vertex_normals(vertices, faces), deviation_mm=deviation, pixel_mm=pixel_mm
            )
        step = max(step + 1, math.ceil(step * _COARSER))
    raise InputError(
        f"the outline does not fit in {max_triangles:,} triangles; allow more (max_triangles) "
        "or use outline='frame'"
    )


def _grid_solid(grid: _Grid, width_mm, base_mm, max_triangles, print_tools):
    """The solid on ``grid``: vertices (mm), faces, the pixel size (mm), the grid origin
    ``(col, row)`` and whether it was simplified (to ``max_triangles``); None if it does not fit
    or the simplified top fails the checks of :func:`_checked_top`.

    Unsimplified, the base is the top's cells at ``z = 0``. With a budget, the base is the
    outline's loops triangulated (manifold3d's ear clipping: about one triangle per boundary
    vertex) and the top is simplified to what the budget leaves after the base and the walls.
    """
    r_idx, c_idx = np.nonzero(grid.used)
    rows, cols = grid.rows[r_idx], grid.cols[c_idx]
    col0, row1 = cols.min(), rows.max()
    extent = max(cols.max() - col0, row1 - rows.min())
    if extent == 0:
        return None
    pixel_mm = float(width_mm / extent)
    n = len(rows)
    top_v = np.column_stack(
        [(cols - col0) * pixel_mm, (row1 - rows) * pixel_mm, base_mm + grid.heights[grid.used]]
    )
    n_r, n_c = grid.cells.shape
    corner_ids = (grid.vertex_id[dr : dr + n_r, dc : dc + n_c][grid.cells] for dr, dc in _CORNERS)
    top_f = cell_triangles(*corner_ids)
    boundary = _boundary_edges(grid)
    if max_triangles is None or 2 * len(top_f) + 2 * len(boundary) <= max_triangles:
        base_v = top_v.copy()
        base_v[:, 2] = 0.0
        vertices = np.concatenate([top_v, base_v])
        faces = np.concatenate([top_f, top_f[:, ::-1] + n, _walls(boundary, np.arange(n) + n)])
        return _drop_unused(vertices, faces) + (pixel_mm, (col0, row1), False)
    simplify, triangulate = print_tools
    loops = _loops(boundary, n)
    ring = np.concatenate(loops)
    # the base: the loops' points at z = 0, triangulated, facing down
    base_f = triangulate([top_v[loop, :2] for loop in loops])[:, ::-1].astype(np.int64)
    target = max_triangles - len(base_f) - 2 * len(boundary)
    if target < 2:
        return None
    outline_area = float(_projected_areas(top_v, top_f).sum())
    base_v = np.column_stack([top_v[ring, :2], np.zeros(len(ring))])
    if not _covers_once(-_projected_areas(base_v, base_f), outline_area):
        return None  # the triangulator's result folds or overlaps
    if target >= len(top_f):  # the triangulated base alone makes it fit
        points, triangles = top_v, top_f
    else:
        points, triangles = simplify(top_v, top_f, target_count=target, preserve_border=True)
    checked = _checked_top(points, np.asarray(triangles, dtype=np.int64), outline_area, pixel_mm)
    if checked is None:
        return None
    top_points, top_faces, top_edges = checked
    # each kept boundary vertex's copy on the base: the same grid position
    key = _grid_key(base_v, pixel_mm)
    order = np.argsort(key)
    kept = np.unique(top_edges)
    found = order[
        np.minimum(np.searchsorted(key[order], _grid_key(top_points[kept], pixel_mm)), len(order) - 1)
    ]
    if (base_v[found, :2] != top_points[kept, :2]).any() or len(kept) != len(ring):
        return None
    # and the same boundary edges (preserve_border keeps them; checked, not assumed)
    before = _sorted_rows(_grid_key(top_v, pixel_mm)[boundary])
    after = _sorted_rows(_grid_key(top_points, pixel_mm)[top_edges])
    if not np.array_equal(before, after):
        return None
    below = np.full(len(top_points), -1, dtype=np.int64)
    below[kept] = found + len(top_points)
    vertices = np.concatenate([top_points, base_v])
    faces = np.concatenate([top_faces, base_f + len(top_points), _walls(top_edges, below)])
    if len(faces) > max_triangles:
        return None
    return _drop_unused(vertices, faces) + (pixel_mm, (col0, row1), True)


def _loops(edges: np.ndarray, n: int) -> list[np.ndarray]:
    """The boundary's closed loops, each an array of vertex numbers in the edges' direction (every
    vertex has one edge out: the pinches were dropped)."""
    following = np.full(n, -1, dtype=np.int64)
    following[edges[:, 0]] = edges[:, 1]
    seen = np.zeros(n, dtype=bool)
    loops = []
    for start in edges[:, 0]:
        if seen[start]:
            continue
        loop = []
        vertex = start
        while not seen[vertex]:
            seen[vertex] = True
            loop.append(vertex)
            vertex = following[vertex]
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def _drop_unused(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices some face uses, renumbered in their order."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    if used.all():
        return vertices, faces
    number = np.cumsum(used) - 1
    return vertices[used], number[faces]


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


def _projected_areas(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed area of each triangle seen from +z (positive: counter-clockwise)."""
    a, b, c = (points[faces[:, k], :2] for k in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))


def _checked_top(points, faces, outline_area, pixel_mm):
    """The simplified top, checked to be a fold-free height field over the outline it had.

    Returns the vertices, the faces and the boundary edges, or None when a check fails: every
    triangle turns counter-clockwise seen from +z, their areas sum to the outline's (so they
    cover it once: no fold, no overlap) and no directed edge repeats. With its boundary kept
    (checked by the caller), the top is then an embedded disk (with holes) over the outline:
    walls and a flat base below it close a solid that cannot intersect itself.
    """
    if not _covers_once(_projected_areas(points, faces), outline_area):
        return None
    edges = _open_edges(faces, len(points))
    if edges is None:
        return None
    return points, faces, edges


def _covers_once(areas: np.ndarray, outline_area: float) -> bool:
    """Whether triangles of these signed areas (seen from +z) can only tile the outline: all turn
    counter-clockwise and together they have its area."""
    tiny = _AREA_TOLERANCE * outline_area
    return bool(
        areas.min() > tiny * 1e-3 and abs(areas.sum() - outline_area) <= tiny * max(1, len(areas)) ** 0.5
    )


def _sorted_rows(pairs: np.ndarray) -> np.ndarray:
    """``(E, 2)`` integer pairs in lexicographic order (to compare two sets of edges)."""
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _edge_key(edges: np.ndarray, n: int) -> np.ndarray:
    return edges[:, 0].astype(np.int64) * n + edges[:, 1]


def _open_edges(faces: np.ndarray, n: int) -> np.ndarray | None:
    """Directed edges of ``faces`` whose reverse is not an edge (the boundary), ``(E, 2)``; None if
    a directed edge appears twice (two triangles wound against each other across it)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    keys = _edge_key(edges, n)
    ordered = np.sort(keys)
    if (ordered[1:] == ordered[:-1]).any():
        return None
    reverse = _edge_key(edges[:, ::-1], n)
    found = np.searchsorted(ordered, reverse)
    found = np.minimum(found, len(ordered) - 1)
    return edges[ordered[found] != reverse]


def _grid_key(points: np.ndarray, pixel_mm: float) -> np.ndarray:
    """One integer per pixel position ``(x, y) / pixel_mm`` (rounded: exact for grid points)."""
    x = np.rint(points[:, 0] / pixel_mm).astype(np.int64)
    y = np.rint(points[:, 1] / pixel_mm).astype(np.int64)
    return x * (np.int64(1) << 32) + y


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (``+z`` where they cancel), summed a chunk of faces at a
    time so that the temporaries stay small next to the mesh."""
    normals = np.zeros((len(vertices), 3))
    for start in range(0, len(faces), _CHUNK_FACES):
        chunk = faces[start : start + _CHUNK_FACES]
        a = vertices[chunk[:, 0]]
        face_normals = np.cross(vertices[chunk[:, 1]] - a, vertices[chunk[:, 2]] - a)
        # a chunk's faces use a narrow band of vertex numbers (the grid is numbered row by row)
        low, high = int(chunk.min()), int(chunk.max()) + 1
        for corner in range(3):
            for k in range(3):
                normals[low:high, k] += np.bincount(
                    chunk[:, corner] - low, face_normals[:, k], minlength=high - low
                )
    length = np.linalg.norm(normals, axis=1)
    flat = length <= 0
    normals[flat] = (0.0, 0.0, 1.0)
    length[flat] = 1.0
    normals /= length[:, None]
    return normals


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
    from shadeform._relief_distance import (
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
