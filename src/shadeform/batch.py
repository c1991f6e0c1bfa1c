"""Many photos, one model each, reconstructed in parallel with Dask.

An edge of the library, like the CLI: it reads photos and writes files. Each photo is one Dask
task (load, :func:`shadeform.reconstruct`, mesh, export, written atomically); the tasks run in
worker processes (the solvers are numba kernels that hold the interpreter, so threads would
queue). A photo that is a user mistake (unreadable, all black, ...) fails alone: its result
carries the one-line message and the other photos go on.

The workers end with the batch, however it ends: an error or a signal terminates them (and the
batch then removes the temporary files they leave), and a worker whose batch process was killed
outright (``kill -9``) notices within :data:`WATCH_SECONDS` (once a compiled kernel it is
running returns), removes its temporary files and ends itself.

Dask is optional (``pip install 'shadeform[dask]'``); without it :func:`reconstruct_files`
raises an :class:`~shadeform.errors.InputError` naming the extra.
"""

from __future__ import annotations

import os
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from shadeform._deprecated import renamed_keywords
from shadeform.errors import InputError

#: How often a worker checks that its batch process still runs (seconds).
WATCH_SECONDS = 0.5

#: Suffix of the depth and normal maps written beside each mesh.
DEPTH_SUFFIX, NORMALS_SUFFIX = "_depth.tiff", "_normals.png"


@dataclass(frozen=True)
class BatchResult:
    """What became of one photo.

    Attributes
    ----------
    photo : Path
        The input.
    files : tuple of Path
        What was written for it: the mesh first, then the depth and normal maps asked for;
        empty if it failed.
    vertices, faces : int
        Size of the mesh (0 if it failed).
    seconds : float
        Wall time of the task.
    error : str or None
        The one-line message of the user mistake that stopped this photo; None if it worked.
    photo_info : dict or None
        What was decided in reading the photo (:attr:`shadeform.io.images.Photo.info`: bit depth,
        encoding, channel, clipping); None if it could not be read.
    """

    photo: Path
    files: tuple[Path, ...]
    vertices: int
    faces: int
    seconds: float
    error: str | None = None
    photo_info: dict[str, Any] | None = None


@renamed_keywords(method="solver")
def reconstruct_files(
    photos: Sequence[str | os.PathLike],
    out_dir: str | os.PathLike,
    *,
    suffix: str = ".glb",
    step: int = 1,
    channel: str | None = None,
    linear: bool | None = None,
    depth: bool = False,
    normals: bool = False,
    workers: int | None = None,
    max_pixels: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    **options,
) -> list[BatchResult]:
    """Reconstruct every photo with the same options and write one model per photo.

    Parameters
    ----------
    photos : sequence of path-like
        Input photos; their file names (without suffix) name the outputs, so they must differ.
    out_dir : path-like
        Existing folder for the outputs: ``NAME{suffix}``, and with ``depth`` / ``normals``
        ``NAME_depth.tiff`` and ``NAME_normals.png``.
    suffix : str
        Mesh format, one of :func:`shadeform.available_formats`.
    step : int
        Mesh granularity in pixels per vertex.
    channel : {None, "auto", "luma", "r", "g", "b", "max"}
        Image channel (:func:`shadeform.io.images.read_photo`); by default luma, or the least
        clipped colour channel of a photo where one clips on clearly fewer pixels.
    linear : bool or None
        How the photos hold their values (:func:`shadeform.io.images.read_photo`): None decides
        per photo (8-bit files are sRGB and are made linear; 16-bit and float files, and photos in
        a folder holding ``light_intensities.txt``, are linear); True keeps the values, False
        decodes them from sRGB.
    depth, normals : bool
        Also write each photo's depth map and normal map.
    workers : int, optional
        Worker processes; default the CPU count, and never more than the photos or the CPUs
        (:func:`worker_count`). 1 runs the photos one after the other in this process.
    max_pixels : int, optional
        Refuse a photo whose header declares more pixels than this, before decoding it (that
        photo's result carries the message); default
        :data:`shadeform.io.images.MAX_PIXELS`.
    progress : callable, optional
        Called as ``progress(done, total)`` after each photo, in this process.
    **options
        Keyword arguments of :func:`shadeform.reconstruct` (``light``, ``solver``, ``filter``,
        ``integrator``, ``refine``, ``concave``, ...), the same for every photo.

    Returns
    -------
    list of BatchResult
        One per photo, in the order given.

    Raises
    ------
    InputError
        No photos, two photos with the same name, a missing output folder, an unknown mesh
        suffix, ``workers < 1``, ``max_pixels < 1``, an unknown ``channel``, ``solver`` or ``integrator``, a
        ``linear`` that is not a bool or None, a malformed ``filter``, or Dask not installed: all
        before any photo is read. Problems with one photo are reported in its result instead.
    """
    from shadeform._checks import check_choice
    from shadeform.integration import available_integrators
    from shadeform.io.atomic import sweep
    from shadeform.io.exporters import available_formats
    from shadeform.io.images import CHANNELS, MAX_PIXELS
    from shadeform.preprocess import parse_filter
    from shadeform.solvers import available_solvers

    photos = [Path(p) for p in photos]
    out_dir = Path(out_dir)
    if not photos:
        raise InputError("no photos given; list the photos to reconstruct")
    twice = sorted(stem for stem, n in Counter(p.stem for p in photos).items() if n > 1)
    if twice:
        raise InputError(
            f"two photos are named '{twice[0]}', so their models would overwrite each other; rename one"
        )
    if not out_dir.is_dir():
        raise InputError(f"output folder '{out_dir}' does not exist; create it first")
    if suffix.lower() not in available_formats():
        raise InputError(
            f"unknown mesh format suffix '{suffix}'; use one of {', '.join(available_formats())}"
        )
    # the options every photo shares are checked once, not found wrong in every task
    if channel not in (None, "auto"):
        check_choice(channel, ("auto", *CHANNELS), "channel")
    if linear is not None and not isinstance(linear, bool):
        raise InputError(f"linear must be True, False or None (decide per photo), got {linear!r}")
    check_choice(options.get("solver", "auto"), tuple(available_solvers()), "solver")
    if options.get("integrator") is not None:
        check_choice(options["integrator"], tuple(available_integrators()), "integrator")
    parse_filter(options.get("filter"))
    workers = worker_count(workers, len(photos))
    max_pixels = MAX_PIXELS if max_pixels is None else max_pixels
    if not isinstance(max_pixels, int) or isinstance(max_pixels, bool) or max_pixels < 1:
        raise InputError(f"max_pixels must be a whole number >= 1, got {max_pixels!r}")
    try:
        import dask
        from dask.callbacks import Callback
    except ImportError:
        raise InputError(
            "batch processing needs Dask; install it with pip install 'shadeform[dask]'"
        ) from None

    jobs = [
        (
            photo,
            tuple(
                out_dir / f"{photo.stem}{end}"
                for end, wanted in ((suffix, True), (DEPTH_SUFFIX, depth), (NORMALS_SUFFIX, normals))
                if wanted
            ),
        )
        for photo in photos
    ]
    tasks = [
        dask.delayed(_reconstruct_one, pure=False)(photo, files, step, channel, linear, max_pixels, options)
        for photo, files in jobs
    ]
    done = [0]

    def finished(key, result, dsk, state, worker_id):
        done[0] += 1
        if progress is not None:
            progress(min(done[0], len(tasks)), len(tasks))

    with Callback(posttask=finished):
        if workers == 1:
            return list(dask.compute(*tasks, scheduler="synchronous"))
        import multiprocessing

        # a pool of our own, not Dask's default: its workers watch this process, and it can be
        # terminated (an executor's shutdown would wait for the running tasks)
        pool = multiprocessing.get_context("spawn").Pool(
            int(workers), initializer=_start_worker, initargs=(os.getpid(),)
        )
        try:
            results = dask.compute(*tasks, scheduler="processes", pool=pool)
        finally:
            pool.terminate()  # idle after a full run; after an error or a signal, ends the tasks
            pool.join()
            sweep(out_dir, again=True)  # what the ended tasks were writing
    return list(results)


def worker_count(workers: int | None, photos: int) -> int:
    """The worker processes a batch of ``photos`` photos starts: ``workers`` (default one per
    CPU this process may use), but never more than the photos, nor than those CPUs (each task
    runs compiled kernels that keep a core busy: more processes only wait, each holding its
    memory).

    Raises
    ------
    InputError
        ``workers`` not a whole number >= 1.
    """
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    workers = cpus if workers is None else workers
    if (
        isinstance(workers, bool)
        or not isinstance(workers, (int, float))
        or int(workers) != workers
        or workers < 1
    ):
        raise InputError(f"workers must be a whole number >= 1, got {workers!r}")
    return max(1, min(int(workers), photos, cpus))


def _start_worker(batch: int) -> None:
    """A worker's set-up: a thread that ends the worker soon after the batch process ``batch``
    is gone. A SIGTERM (the pool terminated) keeps its default, ending the worker at once: a
    Python handler would run only in the main thread, which may be blocked in the pool's queue
    while the signal lands on another thread (a pool's join then waited forever)."""
    import warnings

    # a worker has no user to speak to (its stderr is the batch's terminal, shared by all): the
    # libraries' warnings stay quiet here, as the command line's edge keeps them in its process
    warnings.simplefilter("ignore")
    threading.Thread(target=_watch, args=(batch,), daemon=True, name="shadeform-watch").start()


def _watch(batch: int) -> None:
    """Wait until this worker's parent is no longer ``batch``, then remove this worker's
    temporaries and end it (from this thread: no signal needs the main thread)."""
    from shadeform.io.atomic import remove_temporaries

    while os.getppid() == batch:
        time.sleep(WATCH_SECONDS)
    remove_temporaries()
    os._exit(1)


def _reconstruct_one(
    photo: Path,
    files: tuple[Path, ...],
    step: int,
    channel: str | None,
    linear: bool | None,
    max_pixels: int,
    options: dict,
) -> BatchResult:
    """One photo: load, reconstruct, mesh, write; a user mistake becomes the result's error."""
    import shadeform
    from shadeform.io.atomic import OutputSet
    from shadeform.io.images import read_photo
    from shadeform.io.maps import save_depth, save_normal_map
    from shadeform.masks import find_object

    start = time.perf_counter()
    read = None
    try:
        with OutputSet() as outputs:  # a photo's files appear together or not at all
            temps = [outputs.temp(path) for path in files]
            read = read_photo(photo, channel=channel, linear=linear, max_pixels=max_pixels)
            found = find_object(read.pixels)  # on the photo's colours, which find it best
            rec = shadeform.reconstruct(read.image, mask=found, **options)
            mesh = shadeform.to_mesh(rec, step=step)
            shadeform.export(mesh, temps[0])
            for path, temp in zip(files[1:], temps[1:]):
                if path.name.endswith(DEPTH_SUFFIX):
                    save_depth(rec.depth, temp)
                else:
                    save_normal_map(rec.normals, temp)
            outputs.commit()
    except InputError as err:
        info = None if read is None else read.info
        return BatchResult(photo, (), 0, 0, time.perf_counter() - start, str(err), info)
    except OSError as err:
        reason = err.strerror or type(err).__name__
        return BatchResult(
            photo,
            (),
            0,
            0,
            time.perf_counter() - start,
            f"cannot read or write the files of '{photo}': {reason}",
        )
    seconds = time.perf_counter() - start
    return BatchResult(photo, files, mesh.n_vertices, mesh.n_faces, seconds, photo_info=read.info)
