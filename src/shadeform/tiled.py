"""Images too large to solve whole: the same stages over overlapping tiles, on Dask.

Planetary and microscopy images run to hundreds of megapixels; the whole-image pipeline needs
about 200 bytes per pixel and its eikonal solver's cost grows with the number of singular points
times the pixels. :func:`reconstruct` cuts the image into tiles of ``tile`` pixels, each solved
with a halo of ``overlap`` pixels on every side by :func:`shadeform.pipeline.reconstruct` (any
method, light or filter), and joins them:

1. **Tiles** (the expensive part, one Dask task each): every tile reads its own window of the
   input (a TIFF is read lazily through tifffile's Zarr store, never whole), is solved, and its
   depth is saved to the work folder (``<out>.tiles/``) as one ``.npy`` file, written atomically:
   a file there is a finished tile, so a rerun after an interruption solves only the missing
   ones (:attr:`TiledResult.skipped`).
2. **Coarse global solve**: each tile's depth is known up to an offset (``z = 0`` at its own
   reference pixel). One unknown per tile, the offset, is found by least squares from the
   median height difference of every pair of overlapping tiles (neighbours and diagonals), with
   ``z = 0`` at the reference pixel of the first tile. This is the coarse level of a two-level
   solve: a system with one unknown per tile instead of one per pixel.
3. **Blend and write**: the output is written band by band (one row of tiles): each pixel is
   the mean of the aligned tiles covering it, weighted by a smooth step that falls from 1 to 0
   across a band of ``overlap`` pixels centred on the tile border. The weights sum to one, so the
   depth is continuous across borders; the outer half of each halo is never used (the solvers'
   border effects stay there). Depth goes to a tiled BigTIFF (float32, with the input's
   GeoTIFF tags), and optionally a mesh sampled on a grid and decimated to ``max_triangles``.

Why tie the tiles through their overlaps rather than through a shape-from-shading solve of a
downsampled image (the first design): averaging an image does not average the shape it shows,
so such a solve is biased where detail is near its grid's size (on
:func:`shadeform.synth.bump_relief` of spacing 128 at 4096 x 4096, solved at 1/16 scale, the
heights come out 30 % low: a depth range of 9.5 px for 13.6), and aligning the tiles to it
imports that bias; and the eikonal solver's cost, about 1.6 us per pixel for each singular
point, makes a 1 Mpx coarse solve of a relief with thousands of bumps cost about an hour of
one core (2700 bumps), one task that no worker can share. The tiles' overlaps see the same pixels at full resolution, so their disagreement there
is exactly the seam to remove; :attr:`TiledResult.seam` reports what is left of it.

Why explicit tiles rather than ``dask.array.map_overlap``: ``map_overlap`` trims each block's
halo and returns disjoint blocks, so overlaps can be neither compared (for the offsets) nor
blended, and a block's result cannot be kept on disk for a rerun.

Schedulers. The eikonal solver's numba kernels hold the interpreter lock (compiled without
``nogil``), so threads queue behind one another: by default the tiles run in worker processes
(``benchmarks/results/tiled.md`` has the measured threads-versus-processes ratio). A Dask
distributed cluster (an address ``"tcp://host:8786"`` or a ``distributed.Client``) runs the
same tasks; its workers read the input and write the tiles by path, so the input and the work
folder must be on storage they all reach.

Memory. The main process holds one band of the output (``tile x width`` float32, twice) and, if
a mesh is asked for, its grid; each worker one tile with its halo through the whole-image
pipeline (about 200 bytes per pixel: 120 MB for a 512-pixel tile with a 128-pixel halo).

Limits. The whole frame is the object (a relief: no mask, no background). Each tile is solved
on its own, so what a tile cannot see it cannot know: with the light at +z every slope must
rise to a singular point (a fully lit top) within the tile's halo, so the halo must be at least
as wide as the widest feature's flank (the default, a quarter of the tile, is 128 pixels), and a
tile that holds no fully lit pixel takes its own brightest pixel as facing the light, as a whole
image would. Features wider than a tile come out only as well as a tile sees them.
Dask (and ``distributed`` for a cluster) are optional: ``pip install 'shadeform[dask]'``.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import struct
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shadeform.errors import InputError

#: Tile side in pixels by default: a 512-pixel tile with its default halo (768 pixels a side,
#: 0.6 Mpx) solves in a few seconds and about 120 MB (``benchmarks/results/tiled.md``).
DEFAULT_TILE = 512
#: Smallest tile side accepted; tiles are multiples of 16 (the TIFF tile size must be).
MIN_TILE = 32
#: GeoTIFF and GDAL georeferencing tags copied from the input to the depth map: model pixel
#: scale, tie points, transformation, GeoKey directory, its double and ASCII parameters.
GEO_TAGS = (33550, 33922, 34264, 34735, 34736, 34737)
#: Triangles of the mesh by default (``mesh=``).
DEFAULT_TRIANGLES = 1_000_000
#: Side of the output's TIFF tiles: the largest of these dividing ``tile``.
_TIFF_TILES = (512, 256, 128, 64, 32, 16)
#: Version of the work folder's layout; a folder of another version is refused.
_LAYOUT = 1
#: The options a tile passes to :func:`shadeform.pipeline.reconstruct`.
_OPTIONS = ("light", "method", "filter", "integrator", "refine")
#: Progress callback: ``progress(stage, done, total)``, stage one of "tiles", "join", "write".
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True, eq=False)
class TiledResult:
    """What a tiled reconstruction made.

    Attributes
    ----------
    depth : (H, W) float32 or None
        The depth map in memory when no ``out`` path was given, else None (read ``path``).
    path : Path or None
        The tiled BigTIFF written (``out``).
    mesh : Path or None
        The mesh written (``mesh``).
    shape : (int, int)
        Rows and columns.
    tiles : int
        Tiles in all.
    solved, skipped : int
        Tiles solved by this run, and tiles found finished in the work folder by an earlier one.
    seam : float
        Largest difference, in pixels of height, between two overlapping tiles after the
        offsets, over the bands where they are blended (a seam if they were butted together).
    seam_rms : float
        Root mean square of that difference over all blend bands.
    info : dict
        ``tile``, ``overlap``, ``scheduler``, ``workers``, ``offsets`` (per tile, pixels),
        ``flat_tiles`` (tiles at full brightness everywhere, made flat without a solve) and
        ``timings`` (seconds per stage).
    """

    depth: np.ndarray | None
    path: Path | None
    mesh: Path | None
    shape: tuple[int, int]
    tiles: int
    solved: int
    skipped: int
    seam: float
    seam_rms: float
    info: dict[str, Any] = field(default_factory=dict)


# --- reading -----------------------------------------------------------------------------------


class TiffWindows:
    """A TIFF read window by window through tifffile's Zarr store: what Dask slices lazily.

    Holds the path, not an open file, so it pickles small and every worker process opens the
    file itself (a Zarr store of an open file does not pickle).

    Parameters
    ----------
    path : path-like
        A TIFF or BigTIFF with one 2-D image (gray) or ``(H, W, C)`` colour samples.
    """

    def __init__(self, path: str | os.PathLike[str]):
        import tifffile

        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"cannot read '{self.path}': no such file; check the path")
        try:
            with tifffile.TiffFile(self.path) as tif:
                page = tif.pages.first
                shape, dtype = tuple(page.shape), page.dtype
                self.tags = {
                    code: (int(page.tags[code].dtype), page.tags[code].count, page.tags[code].value)
                    for code in GEO_TAGS
                    if code in page.tags
                }
        except (tifffile.TiffFileError, OSError, ValueError, KeyError, IndexError, struct.error):
            raise InputError(
                f"truncated or damaged TIFF: '{self.path}' cannot be read; save or export it again "
                "(tiled reconstruction reads TIFF and BigTIFF)"
            ) from None
        if len(shape) not in (2, 3) or (len(shape) == 3 and shape[2] not in (1, 3, 4)) or dtype is None:
            raise InputError(
                f"'{self.path}' holds an image of shape {shape}; give one gray or colour image (H, W[, C])"
            )
        self.shape, self.dtype, self.ndim = shape, np.dtype(dtype), len(shape)
        self._array = None

    def __getstate__(self):
        return {**self.__dict__, "_array": None}

    def __getitem__(self, key) -> np.ndarray:
        if self._array is None:
            import tifffile
            import zarr

            self._array = zarr.open(tifffile.imread(self.path, aszarr=True), mode="r")
        return np.asarray(self._array[key])


def open_image(path: str | os.PathLike[str]):
    """A TIFF as a lazy Dask array, and its georeferencing tags.

    Parameters
    ----------
    path : path-like
        TIFF, BigTIFF or GeoTIFF.

    Returns
    -------
    image : dask.array.Array
        ``(H, W)`` or ``(H, W, C)``, the file's own type, chunks of 1024 rows and columns; nothing
        is read until it is computed.
    tags : dict
        ``{code: (TIFF datatype, count, value)}`` of the :data:`GEO_TAGS` the file has.
    """
    da = _dask().array
    windows = TiffWindows(path)
    chunks = (1024, 1024) + windows.shape[2:]
    return da.from_array(windows, chunks=chunks, asarray=False, fancy=False), dict(windows.tags)


def _shading(values: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """A window's samples as one linear channel in [0, 1] (``docs/conventions.md``): integers
    by their type's maximum, 8-bit sRGB decoded, colour to luma."""
    from shadeform.io.images import _srgb_decode, select_channel

    if np.issubdtype(dtype, np.integer):
        image = values.astype(np.float32) / np.float32(np.iinfo(dtype).max)
        if np.iinfo(dtype).bits <= 8:
            image = _srgb_decode(image).astype(np.float32)
    else:
        image = values.astype(np.float32)
    if image.ndim == 3:
        image = image[..., 0] if image.shape[2] == 1 else select_channel(image[..., :3], "luma")
    return image


# --- the tiles ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Grid:
    """Tile ``(i, j)``: core rows ``[i t, (i + 1) t)``, halo ``o`` each side, clipped to the image."""

    height: int
    width: int
    tile: int
    overlap: int

    @property
    def rows(self) -> int:
        return math.ceil(self.height / self.tile)

    @property
    def cols(self) -> int:
        return math.ceil(self.width / self.tile)

    def span(self, k: int, size: int) -> tuple[int, int, int, int]:
        """Core ``[k0, k1)`` and extended ``[e0, e1)`` of tile ``k`` along an axis of ``size``."""
        k0, k1 = k * self.tile, min((k + 1) * self.tile, size)
        return k0, k1, max(k0 - self.overlap, 0), min(k1 + self.overlap, size)

    def window(self, i: int, j: int) -> tuple[slice, slice]:
        _, _, r0, r1 = self.span(i, self.height)
        _, _, c0, c1 = self.span(j, self.width)
        return slice(r0, r1), slice(c0, c1)

    def weight(self, k: int, size: int) -> np.ndarray:
        """1-D blend weight over tile ``k``'s extended span: 1 in the core, a smooth step
        ``3u^2 - 2u^3`` across ``overlap`` pixels centred on each border with a neighbour, 0
        beyond. Two neighbours' steps are mirror images, so the weights sum to one."""
        k0, k1, e0, e1 = self.span(k, size)
        x = np.arange(e0, e1, dtype=np.float64) + 0.5
        w = np.ones(e1 - e0)
        half = self.overlap / 2.0
        if k0 > 0:
            w *= _smoothstep((x - (k0 - half)) / self.overlap)
        if k1 < size:
            w *= 1.0 - _smoothstep((x - (k1 - half)) / self.overlap)
        return w

    def used(self, k: int, size: int) -> tuple[int, int]:
        """Where tile ``k``'s weight is not zero: its core widened by half the overlap."""
        k0, k1, _, _ = self.span(k, size)
        half = self.overlap // 2
        return max(k0 - half, 0), min(k1 + half, size)


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _solve_tile(source, window, dtype, options: dict, target: str) -> dict:
    """One tile: read, solve, save its depth (float32 ``.npy``) atomically; a Dask task."""
    from shadeform.io.atomic import atomic_write

    start = time.perf_counter()
    values = np.asarray(source[window] if window is not None else source)
    depth, flat = _tile_depth(_shading(values, np.dtype(dtype)), options)
    with atomic_write(target) as handle:
        np.save(handle, depth.astype(np.float32))
    return {"seconds": time.perf_counter() - start, "flat": flat}


def _tile_depth(image: np.ndarray, options: dict) -> tuple[np.ndarray, bool]:
    """A tile's depth: the whole-image pipeline on the tile, all of it object.

    A tile of nothing but full brightness (a plate facing the light) is the plane facing the
    light, made without a solve: the pipeline refuses such an image as saturated, a guard meant
    for whole photos. A black tile has no shading: its depth is NaN (no data)."""
    from shadeform.light import as_light
    from shadeform.pipeline import SATURATED_FRACTION, reconstruct

    top = float(image.max()) if image.size else 0.0
    if not top > 0:
        return np.full(image.shape, np.nan, dtype=np.float32), False
    at_top = np.count_nonzero(image >= top * (1 - 1e-6)) / image.size
    if top >= 0.999 and at_top >= SATURATED_FRACTION:
        if at_top == 1.0:
            light = as_light(options.get("light", (0.0, 0.0, 1.0)))
            rows, cols = np.indices(image.shape, dtype=np.float64)
            # facing the light: dz/dx = -lx / lz, and one row down (y = -r) is dz = +ly / lz
            return (-light[0] / light[2]) * cols + (light[1] / light[2]) * rows, True
        # mostly plate, some shading: a constant factor is invisible to the solvers, which divide
        # by the brightest value, and keeps the pipeline's clipping guard off this tile
        image = image * np.float32(0.99)
    mask = np.ones(image.shape, dtype=bool)
    return reconstruct(image, mask=mask, **options).depth.astype(np.float32), False


# --- the run -----------------------------------------------------------------------------------


def reconstruct(
    source,
    *,
    tile: int = DEFAULT_TILE,
    overlap: int | None = None,
    scheduler=None,
    out: str | os.PathLike[str] | None = None,
    mesh: str | os.PathLike[str] | None = None,
    max_triangles: int = DEFAULT_TRIANGLES,
    work: str | os.PathLike[str] | None = None,
    keep_work: bool = False,
    workers: int | None = None,
    progress: Progress | None = None,
    **options,
) -> TiledResult:
    """Reconstruct a huge image tile by tile (see the module's description for how).

    Parameters
    ----------
    source : path-like, (H, W) array or dask array
        A TIFF, BigTIFF or GeoTIFF (read lazily, window by window), or the image itself: numpy
        or Dask, ``(H, W)`` or ``(H, W, C)``; integers are scaled by their type's maximum and
        8-bit values decoded from sRGB, floats taken as linear values in [0, 1].
    tile : int, keyword-only
        Tile side in pixels, a multiple of 16, at least :data:`MIN_TILE`.
    overlap : int, keyword-only
        Halo on each side of a tile, in pixels, even, at least 4 and at most ``tile``; by default
        a quarter of ``tile`` rounded to even. Half of it is the band where neighbours are
        blended, half a margin never used. It must exceed the widest feature's flank.
    scheduler : None, str or distributed.Client, keyword-only
        None: worker processes on this machine (``workers`` of them; one runs in this process);
        ``"processes"``, ``"threads"`` or ``"synchronous"``: that local Dask scheduler; an
        address like ``"tcp://host:8786"`` or a ``distributed.Client``: that cluster.
    out : path-like, keyword-only
        The depth map, a tiled BigTIFF (``.tif`` / ``.tiff``), float32, NaN where no tile had
        data, the input's GeoTIFF tags kept. Without it the depth is returned in memory.
    mesh : path-like, keyword-only
        Also write a mesh (suffix: a format of :func:`shadeform.available_formats`): the depth on
        a grid with about ``4 * max_triangles`` triangles, decimated to ``max_triangles``
        (fast-simplification, ``pip install 'shadeform[print]'``). Vertices are in pixels of the
        input (``docs/conventions.md``).
    max_triangles : int, keyword-only
        Triangle budget of the mesh.
    work : path-like, keyword-only
        Folder for the finished tiles; by default ``<out>.tiles`` beside ``out`` (a temporary
        folder without ``out``). A rerun with the same folder skips the tiles found there.
    keep_work : bool, keyword-only
        Keep the work folder after a successful run (it is always kept after a failure).
    workers : int, keyword-only
        Local worker processes (default: the CPU count).
    progress : callable, keyword-only
        ``progress(stage, done, total)`` in this process: stage "tiles" after each tile, then
        "join" and "write" (bands of tiles).
    **options
        ``light``, ``method``, ``filter``, ``integrator``, ``refine`` of
        :func:`shadeform.reconstruct`, the same for every tile. The light is a direction (not
        "estimate": a tile's estimate would differ from its neighbour's).

    Returns
    -------
    TiledResult

    Raises
    ------
    InputError
        An unreadable input, bad sizes or options, an output suffix that is not a TIFF, a work
        folder holding another run's tiles, Dask (or distributed, for a cluster) not installed;
        a tile's own input error, with the tile's place.

    Examples
    --------
    >>> from shadeform import synth
    >>> scene = synth.bump_relief((128, 128), spacing=64)
    >>> result = reconstruct(scene.image, tile=64, overlap=32, scheduler="synchronous")
    >>> result.tiles, result.depth.shape
    (4, (128, 128))
    """
    timings: dict[str, float] = {}
    start = time.perf_counter()
    options = _check_options(options)
    reader, dtype, shape, tags = _source(source)
    height, width = shape
    tile = _check_tile(tile)
    overlap = tile // 4 // 2 * 2 if overlap is None else overlap
    if isinstance(overlap, bool) or not isinstance(overlap, (int, np.integer)) or not 4 <= overlap <= tile:
        raise InputError(f"overlap must be a whole number from 4 to the tile size {tile}, got {overlap!r}")
    if overlap % 2:
        raise InputError(f"overlap must be even (half of it is the blend band), got {overlap}")
    grid = _Grid(height, width, tile, int(overlap))
    out = _check_out(out)
    mesh = _check_mesh(mesh, max_triangles)
    workers = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise InputError(f"workers must be a whole number >= 1, got {workers!r}")
    dask = _dask()

    temporary = work is None and out is None
    if work is None:
        work = Path(tempfile.mkdtemp(prefix="shadeform-tiles-")) if temporary else Path(f"{out}.tiles")
    work = Path(work)
    manifest = {
        "layout": _LAYOUT,
        "shape": [height, width],
        "tile": tile,
        "overlap": int(overlap),
        "options": _jsonable(options),
        "source": _identity(source),
    }
    _prepare_work(work, manifest)

    names = {(i, j): work / f"r{i:05d}_c{j:05d}.npy" for i in range(grid.rows) for j in range(grid.cols)}
    pending = [key for key, path in names.items() if not path.exists()]
    skipped = len(names) - len(pending)
    if progress:
        progress("tiles", skipped, len(names))
    tasks = []
    for i, j in pending:
        window = grid.window(i, j)
        if isinstance(reader, np.ndarray):
            part, window_arg = reader[window], None  # only the window travels to the worker
        elif hasattr(reader, "dask"):
            part, window_arg = reader[window], None
        else:
            part, window_arg = reader, window
        tasks.append(
            dask.delayed(_solve_tile, pure=False)(
                part, window_arg, dtype, options, str(names[i, j]), dask_key_name=f"shadeform-tile-{i}-{j}"
            )
        )
    flat = _run(
        tasks, scheduler, workers, lambda done: progress and progress("tiles", skipped + done, len(names))
    )
    timings["tiles"] = time.perf_counter() - start

    lap = time.perf_counter()
    if progress:
        progress("join", 0, 1)
    offsets = _offsets(grid, names)
    seam, seam_rms = _disagreement(grid, names, offsets)
    timings["join"] = time.perf_counter() - lap
    if progress:
        progress("join", 1, 1)

    lap = time.perf_counter()
    step = _mesh_step(grid, max_triangles) if mesh is not None else None
    depth, samples = _write(grid, names, offsets, out, tags, step, progress)
    timings["write"] = time.perf_counter() - lap
    if mesh is not None:
        lap = time.perf_counter()
        _write_mesh(samples, step, max_triangles, mesh)
        timings["mesh"] = time.perf_counter() - lap
    if temporary or not keep_work:
        shutil.rmtree(work, ignore_errors=True)
    timings["total"] = time.perf_counter() - start
    return TiledResult(
        depth=depth,
        path=out,
        mesh=mesh,
        shape=(height, width),
        tiles=len(names),
        solved=len(pending),
        skipped=skipped,
        seam=seam,
        seam_rms=seam_rms,
        info={
            "tile": tile,
            "overlap": int(overlap),
            "scheduler": _describe(scheduler, workers),
            "workers": int(workers),
            "offsets": {f"{i},{j}": float(v) for (i, j), v in offsets.items()},
            "flat_tiles": int(flat),
            "timings": timings,
        },
    )


def _dask():
    try:
        import dask
        import dask.array
    except ImportError:
        raise InputError(
            "tiled reconstruction needs Dask; install it with pip install 'shadeform[dask]'"
        ) from None
    return dask


def _check_options(options: dict) -> dict:
    from shadeform._checks import check_choice
    from shadeform.integration import available_integrators
    from shadeform.light import as_light
    from shadeform.preprocess import parse_filter
    from shadeform.solvers import available_methods

    unknown = sorted(set(options) - set(_OPTIONS))
    if unknown:
        raise InputError(
            f"tiled reconstruction does not take {', '.join(unknown)}: the whole frame is the object; "
            f"it takes {', '.join(_OPTIONS)}"
        )
    light = options.get("light", (0.0, 0.0, 1.0))
    if isinstance(light, str):
        raise InputError(
            "tiled reconstruction needs the light as a direction (x, y, z); estimate it on a "
            "downsampled copy of the image first"
        )
    options = dict(options)
    options["light"] = tuple(float(v) for v in as_light(light))
    check_choice(options.get("method", "auto"), tuple(available_methods()), "method")
    if options.get("integrator") is not None:
        check_choice(options["integrator"], tuple(available_integrators()), "integrator")
    if options.get("filter") is not None:
        parse_filter(options["filter"])
    return options


def _source(source):
    """``(reader, dtype, (H, W), tags)``: a :class:`TiffWindows` for a path, else the array."""
    if isinstance(source, (str, os.PathLike)):
        reader = TiffWindows(source)
        return reader, reader.dtype, reader.shape[:2], reader.tags
    if hasattr(source, "dask") and hasattr(source, "chunks"):
        array = source
    else:
        try:
            array = np.asarray(source)
        except (TypeError, ValueError):
            array = None
        if array is None or array.dtype == object:
            raise InputError(
                f"cannot read an image from {type(source).__name__}; give a TIFF path or an array"
            )
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (1, 3, 4)):
        raise InputError(f"image has shape {tuple(array.shape)}; give one gray or colour image (H, W[, C])")
    if not (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)):
        raise InputError(f"image has values of type {array.dtype}; give numbers")
    if min(array.shape[:2]) < 3:
        raise InputError(f"image is {array.shape[1]}x{array.shape[0]} pixels; it needs at least 3x3")
    return array, array.dtype, tuple(int(v) for v in array.shape[:2]), {}


def _check_tile(tile) -> int:
    if isinstance(tile, bool) or not isinstance(tile, (int, np.integer)) or tile < MIN_TILE or tile % 16:
        raise InputError(f"tile must be a multiple of 16 pixels, at least {MIN_TILE}, got {tile!r}")
    return int(tile)


def _check_out(out) -> Path | None:
    if out is None:
        return None
    out = Path(out)
    if out.suffix.lower() not in (".tif", ".tiff"):
        raise InputError(f"the tiled depth map is a BigTIFF: name it .tif or .tiff, not '{out.name}'")
    if not out.parent.is_dir():
        raise InputError(f"output folder '{out.parent}' does not exist; create it first")
    return out


def _check_mesh(mesh, max_triangles) -> Path | None:
    from shadeform.io.exporters import available_formats

    if (
        isinstance(max_triangles, bool)
        or not isinstance(max_triangles, (int, np.integer))
        or max_triangles < 2
    ):
        raise InputError(f"max_triangles must be a whole number >= 2, got {max_triangles!r}")
    if mesh is None:
        return None
    mesh = Path(mesh)
    if mesh.suffix.lower() not in available_formats():
        raise InputError(
            f"unknown mesh format suffix '{mesh.suffix}'; use one of {', '.join(available_formats())}"
        )
    if not mesh.parent.is_dir():
        raise InputError(f"output folder '{mesh.parent}' does not exist; create it first")
    return mesh


def _jsonable(options: dict) -> dict:
    return {
        key: (list(value) if isinstance(value, tuple) else value) for key, value in sorted(options.items())
    }


def _identity(source) -> dict:
    """What names the input in the work folder's manifest: a file's path, size and time."""
    if isinstance(source, (str, os.PathLike)):
        stat = Path(source).stat()
        return {"path": str(Path(source).resolve()), "bytes": stat.st_size, "mtime_ns": stat.st_mtime_ns}
    return {"array": [list(np.shape(source)), str(source.dtype)]}


def _prepare_work(work: Path, manifest: dict) -> None:
    """Create the work folder with its manifest, or check that an existing one is this run's."""
    from shadeform.io.atomic import atomic_write

    record = work / "manifest.json"
    if work.exists():
        if not work.is_dir():
            raise InputError(f"work folder '{work}' is a file; remove it or choose another work folder")
        if record.exists():
            try:
                found = json.loads(record.read_text())
            except (OSError, ValueError):
                found = None
            if found != json.loads(json.dumps(manifest)):
                raise InputError(
                    f"work folder '{work}' holds the tiles of another run (other input, tile size or "
                    "options); delete it or choose another work folder"
                )
            return
        if any(work.iterdir()):
            raise InputError(f"work folder '{work}' is not empty; choose an empty or new folder")
    else:
        if not work.parent.is_dir():
            raise InputError(f"folder '{work.parent}' does not exist; create it first")
        work.mkdir()
    with atomic_write(record, mode="w") as handle:
        json.dump(manifest, handle)


def _run(tasks: list, scheduler, workers: int, done: Callable[[int], Any]) -> int:
    """Compute the tile tasks; ``done(count)`` after each. Returns how many tiles were flat."""
    if not tasks:
        return 0
    address = isinstance(scheduler, str) and "://" in scheduler
    if address or (scheduler is not None and not isinstance(scheduler, str)):
        return _run_cluster(tasks, scheduler, done)
    import dask
    from dask.callbacks import Callback

    count = [0]

    def finished(key, result, dsk, state, worker_id):
        name = key if isinstance(key, str) else str(key)
        if name.startswith("shadeform-tile-"):
            count[0] += 1
            done(count[0])

    kind = scheduler or ("processes" if workers > 1 else "synchronous")
    if kind not in ("processes", "threads", "synchronous"):
        raise InputError(
            f"unknown scheduler {scheduler!r}; use 'processes', 'threads', 'synchronous' or a cluster "
            "address like tcp://host:8786"
        )
    with Callback(posttask=finished):
        if kind == "processes":
            import multiprocessing

            from shadeform.batch import _start_worker

            # the batch module's pool: spawned workers that end with this process
            pool = multiprocessing.get_context("spawn").Pool(
                int(workers), initializer=_start_worker, initargs=(os.getpid(),)
            )
            try:
                results = dask.compute(*tasks, scheduler="processes", pool=pool)
            finally:
                pool.terminate()
                pool.join()
        elif kind == "threads":
            results = dask.compute(*tasks, scheduler="threads", num_workers=int(workers))
        else:
            results = dask.compute(*tasks, scheduler="synchronous")
    return sum(bool(r["flat"]) for r in results)


def _run_cluster(tasks: list, scheduler, done: Callable[[int], Any]) -> int:
    try:
        import distributed
    except ImportError:
        raise InputError(
            "running on a Dask cluster needs distributed; install it with pip install 'shadeform[dask]'"
        ) from None
    own = isinstance(scheduler, str)
    if own:
        try:
            client = distributed.Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as err:
            raise InputError(
                f"cannot reach the Dask scheduler at {scheduler} ({err}); check the address"
            ) from None
    else:
        client = scheduler
    futures = client.compute(tasks)
    flat = 0
    try:
        for count, future in enumerate(distributed.as_completed(futures), start=1):
            flat += bool(future.result()["flat"])
            future.release()
            done(count)
    finally:
        client.cancel(futures)
        if own:
            client.close()
    return flat


def _describe(scheduler, workers) -> str:
    if scheduler is None:
        return "processes" if workers > 1 else "synchronous"
    if isinstance(scheduler, str):
        return scheduler
    return f"distributed {getattr(getattr(scheduler, 'scheduler', None), 'address', '?')}"


# --- joining -----------------------------------------------------------------------------------


def _load(path: Path) -> np.ndarray:
    return np.load(path, mmap_mode="r")


def _pairs(grid: _Grid):
    """Overlapping tile pairs ``((i, j), (i2, j2), rows, cols)``: neighbours and diagonals, with
    the slices (image coordinates) where both tiles' weights are not zero."""
    for i in range(grid.rows):
        for j in range(grid.cols):
            for di, dj in ((0, 1), (1, -1), (1, 0), (1, 1)):
                i2, j2 = i + di, j + dj
                if not (0 <= i2 < grid.rows and 0 <= j2 < grid.cols):
                    continue
                a0, a1 = grid.used(i, grid.height)
                b0, b1 = grid.used(i2, grid.height)
                c0, c1 = grid.used(j, grid.width)
                d0, d1 = grid.used(j2, grid.width)
                rows = (max(a0, b0), min(a1, b1))
                cols = (max(c0, d0), min(c1, d1))
                if rows[1] > rows[0] and cols[1] > cols[0]:
                    yield (i, j), (i2, j2), rows, cols


def _part(grid: _Grid, names, key, rows, cols) -> np.ndarray:
    """Tile ``key``'s depth over image rows ``[rows)`` and columns ``[cols)``."""
    i, j = key
    window = grid.window(i, j)
    r0, c0 = window[0].start, window[1].start
    return np.asarray(
        _load(names[key])[rows[0] - r0 : rows[1] - r0, cols[0] - c0 : cols[1] - c0], dtype=np.float64
    )


def _offsets(grid: _Grid, names) -> dict:
    """Each tile's offset: least squares over the median differences of overlapping tiles, zero
    for the first tile with data of every connected group of tiles."""
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse.linalg import spsolve

    keys = list(names)
    index = {key: n for n, key in enumerate(keys)}
    rows, cols, weights, values = [], [], [], []
    for a, b, r, c in _pairs(grid):
        diff = _part(grid, names, a, r, c) - _part(grid, names, b, r, c)
        diff = diff[np.isfinite(diff)]
        if diff.size == 0:
            continue
        rows.append(index[a])
        cols.append(index[b])
        weights.append(float(diff.size))
        values.append(float(np.median(diff)))  # robust to a feature one tile reads wrongly
    n = len(keys)
    offsets = np.zeros(n)
    if rows:
        # normal equations of sum w (x_a - x_b + d)^2: a weighted graph Laplacian
        rows_, cols_, w, d = map(np.asarray, (rows, cols, weights, values))
        adjacency = sparse.coo_matrix((w, (rows_, cols_)), shape=(n, n)).tocsr()
        adjacency = adjacency + adjacency.T
        laplacian = sparse.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency
        rhs = np.zeros(n)
        np.add.at(rhs, rows_, -w * d)
        np.add.at(rhs, cols_, w * d)
        _, group = connected_components(adjacency, directed=False)
        pinned = np.zeros(n, dtype=bool)
        for g in np.unique(group):
            pinned[np.flatnonzero(group == g)[0]] = True
        free = ~pinned
        if free.any():
            system = laplacian[free][:, free].tocsc()
            offsets[free] = spsolve(system, rhs[free])
    return {key: float(offsets[index[key]]) for key in keys}


def _disagreement(grid: _Grid, names, offsets) -> tuple[float, float]:
    """Largest and root-mean-square height difference of overlapping tiles after the offsets."""
    largest, squares, count = 0.0, 0.0, 0
    for a, b, r, c in _pairs(grid):
        diff = (_part(grid, names, a, r, c) + offsets[a]) - (_part(grid, names, b, r, c) + offsets[b])
        diff = diff[np.isfinite(diff)]
        if diff.size:
            largest = max(largest, float(np.abs(diff).max()))
            squares += float(np.sum(diff * diff))
            count += diff.size
    return largest, (math.sqrt(squares / count) if count else 0.0)


def _band(grid: _Grid, names, offsets, i: int) -> np.ndarray:
    """Core rows of tile row ``i``, all columns: the aligned tiles blended."""
    k0, k1, _, _ = grid.span(i, grid.height)
    total = np.zeros((k1 - k0, grid.width), dtype=np.float32)
    weight = np.zeros((k1 - k0, grid.width), dtype=np.float32)
    for a in range(max(i - 1, 0), min(i + 2, grid.rows)):
        u0, u1 = grid.used(a, grid.height)
        r0, r1 = max(u0, k0), min(u1, k1)
        if r1 <= r0:
            continue
        _, _, e0, _ = grid.span(a, grid.height)
        w_rows = grid.weight(a, grid.height)[r0 - e0 : r1 - e0]
        for b in range(grid.cols):
            c0, c1 = grid.used(b, grid.width)
            _, _, f0, _ = grid.span(b, grid.width)
            w_cols = grid.weight(b, grid.width)[c0 - f0 : c1 - f0]
            part = _part(grid, names, (a, b), (r0, r1), (c0, c1)) + offsets[(a, b)]
            w = np.outer(w_rows, w_cols)
            w[~np.isfinite(part)] = 0.0
            total[r0 - k0 : r1 - k0, c0:c1] += (w * np.nan_to_num(part)).astype(np.float32)
            weight[r0 - k0 : r1 - k0, c0:c1] += w.astype(np.float32)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 0, total / weight, np.float32(np.nan)).astype(np.float32)


def _write(grid: _Grid, names, offsets, out: Path | None, tags: dict, step: int | None, progress):
    """Blend band by band into ``out`` (a tiled BigTIFF) or an array; also the mesh's samples
    (every ``step``-th row and column), if ``step``."""
    samples: list[np.ndarray] = []
    bands = grid.rows

    def sample(band: np.ndarray, i: int) -> None:
        if step is not None:
            k0 = i * grid.tile
            first = (-k0) % step
            samples.append(np.array(band[first::step, ::step]))
        if progress:
            progress("write", i + 1, bands)

    if out is None:
        depth = np.empty((grid.height, grid.width), dtype=np.float32)
        for i in range(bands):
            k0, k1, _, _ = grid.span(i, grid.height)
            depth[k0:k1] = _band(grid, names, offsets, i)
            sample(depth[k0:k1], i)
        return depth, _stack(samples)

    import tifffile

    from shadeform.io.atomic import atomic_write

    side = next(s for s in _TIFF_TILES if grid.tile % s == 0)

    def tiff_tiles():
        for i in range(bands):
            band = _band(grid, names, offsets, i)
            sample(band, i)
            for r in range(0, band.shape[0], side):
                for c in range(0, grid.width, side):
                    block = np.full((side, side), np.nan, dtype=np.float32)
                    part = band[r : r + side, c : c + side]
                    block[: part.shape[0], : part.shape[1]] = part
                    yield block

    extratags = [(code, dtype, count, value, True) for code, (dtype, count, value) in sorted(tags.items())]
    with atomic_write(out) as handle:
        tifffile.imwrite(
            handle,
            data=tiff_tiles(),
            shape=(grid.height, grid.width),
            dtype=np.float32,
            tile=(side, side),
            bigtiff=True,
            compression="zlib",
            predictor=3,
            extratags=extratags,
            metadata=None,
        )
    return None, _stack(samples)


def _stack(samples: list[np.ndarray]) -> np.ndarray | None:
    return np.concatenate(samples, axis=0) if samples else None


# --- mesh --------------------------------------------------------------------------------------


def _mesh_step(grid: _Grid, max_triangles: int) -> int:
    """Grid spacing giving about ``OVERSAMPLE * max_triangles`` triangles (two per cell)."""
    from shadeform.solid import OVERSAMPLE

    cells = OVERSAMPLE * max_triangles / 2
    return max(1, math.ceil(math.sqrt(grid.height * grid.width / cells)))


def _write_mesh(samples: np.ndarray, step: int, max_triangles: int, path: Path) -> None:
    """The depth samples (every ``step``-th pixel) as a grid mesh, decimated to the budget."""
    from shadeform.io.exporters import export
    from shadeform.mesh import Mesh, cell_triangles
    from shadeform.solid import _require_print_extra, _vertex_normals

    valid = np.isfinite(samples)
    ids = np.full(samples.shape, -1, dtype=np.int64)
    ids[valid] = np.arange(np.count_nonzero(valid))
    rows, cols = np.nonzero(valid)
    vertices = np.column_stack([cols * step, -rows * step, samples[valid]]).astype(np.float64)
    tl, tr, bl, br = ids[:-1, :-1], ids[:-1, 1:], ids[1:, :-1], ids[1:, 1:]
    cells = (tl >= 0) & (tr >= 0) & (bl >= 0) & (br >= 0)
    faces = cell_triangles(tl[cells], tr[cells], bl[cells], br[cells])
    if len(faces) == 0:
        raise InputError("the depth map has no 2x2 block of data on the mesh grid; there is no mesh to make")
    if len(faces) > max_triangles:
        simplify, _ = _require_print_extra()
        vertices, faces = simplify(
            vertices.astype(np.float32),
            faces.astype(np.int64),
            target_count=max_triangles,
            preserve_border=True,
        )
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
    export(Mesh(vertices, faces, _vertex_normals(vertices, faces)), path)
