"""The tiled run: check everything, find the object, solve the tiles, join them, write."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shadeform._deprecated import renamed_keywords
from shadeform.errors import InputError
from shadeform.tiled.join import Tiling, _disagreement, _offsets
from shadeform.tiled.objects import object_mask
from shadeform.tiled.output import _mesh_step, _write, _write_mesh
from shadeform.tiled.reading import TiffWindows, require_dask
from shadeform.tiled.tasks import Runner, solve_tile

#: Tile side in pixels by default: a 512-pixel tile with its default halo (768 pixels a side,
#: 0.6 Mpx) solves in a few seconds and about 120 MB (``benchmarks/results/tiled.md``).
DEFAULT_TILE = 512
#: Smallest tile side accepted; tiles are multiples of 16 (the TIFF tile size must be).
MIN_TILE = 32
#: Triangles of the mesh by default (``mesh=``).
DEFAULT_TRIANGLES = 1_000_000
#: A seam (the tiles' largest disagreement after the join) above this fraction of the depth's
#: range is more than the solvers' own error and is reported (``info["seam_warning"]``): their
#: median depth error on the synthetic scenes is 0.03-3.6 % of the depth range with the light
#: at +z, noise 0 to 3 % (``benchmarks/results/methods.md``); 5 % is above all of those.
SEAM_FRACTION = 0.05
#: Version of the work folder's layout; a folder of another version is refused.
_LAYOUT = 2
#: The options a tile passes to :func:`shadeform.pipeline.reconstruct`.
_OPTIONS = ("light", "solver", "filter", "integrator", "refine")
#: Bytes of disk a tile's depth takes per pixel of its window in the work folder (float32).
_TILE_BYTES = 4
#: Progress callback: ``progress(stage, done, total)``, stage one of "mask", "tiles", "join", "write".
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
        ``mask`` (how the object was found: a line in words), ``flat_tiles`` (tiles at full
        brightness everywhere, made flat without a solve), ``unsolved_tiles`` and
        ``unsolved_reason`` (tiles whose part of the object the pipeline refused: NaN there),
        ``depth_range`` (1st to 99th percentile, pixels), ``seam_warning`` (one line in words
        when the seam is above :data:`SEAM_FRACTION` of the depth's range, else None) and
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


@renamed_keywords(method="solver")
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
    mask=None,
    progress: Progress | None = None,
    **options,
) -> TiledResult:
    """Reconstruct a huge image tile by tile (see :mod:`shadeform.tiled` for how).

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
        The depth map, a tiled BigTIFF (``.tif`` / ``.tiff``), float32, NaN off the object and
        where no tile had data, the input's GeoTIFF tags kept. Without it the depth is returned
        in memory.
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
        Keep the work folder after the run, whether it succeeds, fails or is stopped (Ctrl-C,
        SIGTERM), so that a rerun solves only the missing tiles. Without it the folder is
        removed in every case, unless it held this run's tiles before (a resumed run).
    workers : int, keyword-only
        Local worker processes (default: the CPU count).
    mask : None, "whole", (H, W) array or path-like, keyword-only
        The object. None: found on a coarse overview of the whole image
        (:mod:`shadeform.tiled.objects`), as a photo solved whole finds it; a picture that is
        one surface filling the frame is all object. ``"whole"``: every pixel is the object (a
        relief). An array or a mask image of the image's size: non-zero pixels are the object
        (a TIFF is read window by window). Off the object the depth is NaN.
    progress : callable, keyword-only
        ``progress(stage, done, total)`` in this process: stage "mask" while the object is
        found, "tiles" after each tile, then "join" and "write" (bands of tiles).
    **options
        ``light``, ``solver``, ``filter``, ``integrator``, ``refine`` of
        :func:`shadeform.reconstruct`, the same for every tile. The light is a direction (not
        "estimate": a tile's estimate would differ from its neighbour's).

    Returns
    -------
    TiledResult

    Raises
    ------
    InputError
        An unreadable or untrustworthy input (checked from its header before anything is read
        or made), bad sizes or options, an output suffix that is not a TIFF, a work folder
        holding another run's tiles, too little disk for the tiles, no object found, Dask (or
        distributed, for a cluster) not installed. All are raised before the work folder is
        made.

    Examples
    --------
    >>> from shadeform import synth
    >>> scene = synth.bump_relief((128, 128), spacing=64)
    >>> result = reconstruct(scene.image, tile=64, overlap=32, scheduler="synchronous", mask="whole")
    >>> result.tiles, result.depth.shape
    (4, (128, 128))
    """
    timings: dict[str, float] = {}
    start = time.perf_counter()
    # everything the caller gave is checked before anything is read, made or started
    options = _check_options(options)
    tile = _check_tile(tile)
    overlap = _check_overlap(overlap, tile)
    out = _check_out(out)
    mesh = _check_mesh(mesh, max_triangles)
    workers = _check_workers(workers)
    if work is not None:
        work = _check_work(Path(work))
    dask = require_dask()
    reader, dtype, shape, tags = _source(source)
    height, width = shape
    grid = Tiling(height, width, tile, overlap)
    runner = Runner(scheduler, workers)
    try:
        if progress:
            progress("mask", 0, 1)
        objects = object_mask(mask, reader, dtype, shape)
        timings["mask"] = time.perf_counter() - start
        if progress:
            progress("mask", 1, 1)
        temporary = work is None and out is None
        _check_disk(grid, work or (out.parent if out is not None else Path(tempfile.gettempdir())), out)
        if work is None:
            work = Path(tempfile.mkdtemp(prefix="shadeform-tiles-")) if temporary else Path(f"{out}.tiles")
        manifest = {
            "layout": _LAYOUT,
            "shape": [height, width],
            "tile": tile,
            "overlap": overlap,
            "options": _jsonable(options),
            "source": _identity(source),
            "mask": objects.identity(),
        }
        resumed = _prepare_work(work, manifest)
        try:
            result = _solve(
                grid, reader, dtype, objects, options, work, runner, out, mesh, tags, max_triangles,
                progress, timings, dask,
            )  # fmt: skip
        except BaseException:
            if temporary or not (keep_work or resumed):
                shutil.rmtree(work, ignore_errors=True)
            raise
    finally:
        runner.close()
    if temporary or not keep_work:
        shutil.rmtree(work, ignore_errors=True)
    timings["total"] = time.perf_counter() - start
    depth, solved, skipped, seam, seam_rms, info = result
    return TiledResult(
        depth=depth,
        path=out,
        mesh=mesh,
        shape=(height, width),
        tiles=grid.rows * grid.cols,
        solved=solved,
        skipped=skipped,
        seam=seam,
        seam_rms=seam_rms,
        info={
            "tile": tile,
            "overlap": overlap,
            "scheduler": runner.describe(),
            "workers": workers,
            "mask": objects.note,
            **info,
            "timings": timings,
        },
    )


def _solve(
    grid,
    reader,
    dtype,
    objects,
    options,
    work,
    runner,
    out,
    mesh,
    tags,
    max_triangles,
    progress,
    timings,
    dask,
):
    """The tiles, their join and the writing, in a work folder made for them."""
    names = {(i, j): work / f"r{i:05d}_c{j:05d}.npy" for i in range(grid.rows) for j in range(grid.cols)}
    pending = [key for key, path in names.items() if not path.exists()]
    skipped = len(names) - len(pending)
    if progress:
        progress("tiles", skipped, len(names))
    lap = time.perf_counter()
    tasks = []
    for i, j in pending:
        window = grid.window(i, j)
        if isinstance(reader, TiffWindows):
            part, window_arg = reader, window
        else:
            part, window_arg = reader[window], None  # only the window travels to the worker
        tasks.append(
            dask.delayed(solve_tile, pure=False)(
                part,
                window_arg,
                dtype,
                objects.part(window),
                options,
                str(names[i, j]),
                dask_key_name=f"shadeform-tile-{i}-{j}",
            )  # fmt: skip
        )
    results = runner.run(tasks, lambda done: progress and progress("tiles", skipped + done, len(names)))
    unsolved = [r["refused"] for r in results if r["refused"]]
    timings["tiles"] = time.perf_counter() - lap

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
    depth, samples, extent = _write(grid, names, offsets, out, tags, step, progress)
    timings["write"] = time.perf_counter() - lap
    if mesh is not None:
        lap = time.perf_counter()
        _write_mesh(samples, step, max_triangles, mesh)
        timings["mesh"] = time.perf_counter() - lap
    info = {
        "offsets": {f"{i},{j}": float(v) for (i, j), v in offsets.items()},
        "flat_tiles": sum(bool(r["flat"]) for r in results),
        "unsolved_tiles": len(unsolved),
        "unsolved_reason": unsolved[0] if unsolved else None,
        "depth_range": extent,
        "seam_warning": seam_warning(seam, extent),
    }
    return depth, len(pending), skipped, seam, seam_rms, info


def seam_warning(seam: float, extent: float) -> str | None:
    """One line in words when the tiles' largest disagreement is above the solvers' own error
    (:data:`SEAM_FRACTION` of the depth's range), else None."""
    if not extent > 0 or not seam > SEAM_FRACTION * extent:
        return None
    return (
        f"the tiles disagree by up to {seam:.3g} px of height where they overlap, {seam / extent:.0%} "
        f"of the depth's range of {extent:.3g} px (the solvers' own error is under "
        f"{SEAM_FRACTION:.0%}): the depth is unreliable across tile borders; try larger tiles, a "
        "larger overlap, or solve it whole"
    )


def _check_options(options: dict) -> dict:
    from shadeform._checks import check_choice
    from shadeform.integration import available_integrators
    from shadeform.light import as_light
    from shadeform.preprocess import parse_filter
    from shadeform.solvers import available_solvers

    unknown = sorted(set(options) - set(_OPTIONS))
    if unknown:
        raise InputError(
            f"tiled reconstruction does not take {', '.join(unknown)}; it takes "
            f"{', '.join(_OPTIONS)} and mask"
        )
    light = options.get("light", (0.0, 0.0, 1.0))
    if isinstance(light, str):
        raise InputError(
            "tiled reconstruction needs the light as a direction (x, y, z); estimate it on a "
            "downsampled copy of the image first"
        )
    options = dict(options)
    options["light"] = tuple(float(v) for v in as_light(light))
    check_choice(options.get("solver", "auto"), tuple(available_solvers()), "solver")
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


def _check_overlap(overlap, tile: int) -> int:
    overlap = tile // 4 // 2 * 2 if overlap is None else overlap
    if isinstance(overlap, bool) or not isinstance(overlap, (int, np.integer)) or not 4 <= overlap <= tile:
        raise InputError(f"overlap must be a whole number from 4 to the tile size {tile}, got {overlap!r}")
    if overlap % 2:
        raise InputError(f"overlap must be even (half of it is the blend band), got {overlap}")
    return int(overlap)


def _check_workers(workers) -> int:
    workers = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise InputError(f"workers must be a whole number >= 1, got {workers!r}")
    return int(workers)


def _check_work(work: Path) -> Path:
    if work.exists() and not work.is_dir():
        raise InputError(f"work folder '{work}' is a file; remove it or choose another work folder")
    if not work.exists() and not work.parent.is_dir():
        raise InputError(f"folder '{work.parent}' does not exist; create it first")
    return work


def _check_disk(grid: Tiling, folder: Path, out: Path | None) -> None:
    """Refuse a run whose tiles (float32 over each tile's window) and depth map (float32,
    compressed, counted whole) cannot fit on the disk they go to."""
    # the windows are a product of row spans and column spans
    rows = sum(e1 - e0 for _, _, e0, e1 in (grid.span(i, grid.height) for i in range(grid.rows)))
    cols = sum(e1 - e0 for _, _, e0, e1 in (grid.span(j, grid.width) for j in range(grid.cols)))
    needed = rows * cols * _TILE_BYTES
    if out is not None:
        needed += grid.height * grid.width * _TILE_BYTES
    probe = folder if folder.is_dir() else folder.parent
    try:
        free = shutil.disk_usage(probe).free
    except OSError:
        return  # no answer from the file system: the writes will say what is wrong
    if needed > free:
        raise InputError(
            f"not enough disk: the tiles and depth map of this {grid.width}x{grid.height} image need "
            f"about {needed / 1e9:,.1f} GB and '{probe}' has {free / 1e9:,.1f} GB free; free some "
            "space or write the depth elsewhere"
        )


def _prepare_work(work: Path, manifest: dict) -> bool:
    """Create the work folder with its manifest, or check that an existing one is this run's.
    Whether it was (an earlier run's tiles are resumed)."""
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
            return True
        if any(work.iterdir()):
            raise InputError(f"work folder '{work}' is not empty; choose an empty or new folder")
    else:
        if not work.parent.is_dir():
            raise InputError(f"folder '{work.parent}' does not exist; create it first")
        work.mkdir()
    with atomic_write(record, mode="w") as handle:
        json.dump(manifest, handle)
    return False
