"""The tile tasks and where they run: worker processes or threads here, or a Dask cluster.

Stopping. A run ends at once on Ctrl-C or SIGTERM (which the command line turns into an exit):
the main thread only waits on the tasks, so the interruption reaches it there; worker
processes are terminated (their default SIGTERM ends them where they are), threads are daemon
threads that cannot hold the exit, and a task that finishes after the run was stopped writes
nothing (:data:`STOPPED`). On a cluster the tasks are cancelled; one already running there
finishes its solve and writes nothing into a work folder that is gone. With threads, a numba
kernel holding the interpreter lock delays the main thread until it returns.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from shadeform.errors import InputError
from shadeform.tiled.reading import shading

#: Set when this process's run is stopped: a task of it that finishes then writes nothing.
STOPPED = threading.Event()
_LOCAL = ("processes", "threads", "synchronous")


def solve_tile(source, window, dtype, mask_part, options: dict, target: str) -> dict:
    """One tile: read, solve, save its depth (float32 ``.npy``) atomically; a Dask task.

    Returns the seconds it took, whether it was flat (solved without the pipeline), and the
    reason the pipeline refused its part of the object, if it did (its depth is then NaN)."""
    from shadeform.io.atomic import atomic_write

    start = time.perf_counter()
    values = np.asarray(source[window] if window is not None else source)
    image = shading(values, np.dtype(dtype))
    mask = None if mask_part is None else mask_part.mask(image)
    refused = None
    try:
        depth, flat = tile_depth(image, mask, options)
    except InputError as err:
        depth, flat, refused = np.full(image.shape, np.nan, dtype=np.float32), False, str(err)
    folder = Path(target).parent
    if STOPPED.is_set() or not folder.is_dir():
        return {"seconds": time.perf_counter() - start, "flat": flat, "refused": refused}
    with atomic_write(target) as handle:
        np.save(handle, depth.astype(np.float32))
    return {"seconds": time.perf_counter() - start, "flat": flat, "refused": refused}


def tile_depth(image: np.ndarray, mask: np.ndarray | None, options: dict) -> tuple[np.ndarray, bool]:
    """A tile's depth: the whole-image pipeline on the tile's part of the object (``mask``;
    None: all of the tile), NaN elsewhere.

    A tile whose object is nothing but full brightness (a plate facing the light) is the plane
    facing the light, made without a solve: the pipeline refuses such an image as saturated, a
    guard meant for whole photos. A tile without object, or whose object is black, has no
    shading: its depth is NaN (no data)."""
    from shadeform.light import as_light
    from shadeform.pipeline import SATURATED_FRACTION, reconstruct

    mask = np.ones(image.shape, dtype=bool) if mask is None else mask
    seen = image[mask]
    top = float(seen.max()) if seen.size else 0.0
    if not top > 0:
        return np.full(image.shape, np.nan, dtype=np.float32), False
    at_top = np.count_nonzero(seen >= top * (1 - 1e-6)) / seen.size
    if top >= 0.999 and at_top >= SATURATED_FRACTION:
        if at_top == 1.0:
            light = as_light(options.get("light", (0.0, 0.0, 1.0)))
            rows, cols = np.indices(image.shape, dtype=np.float64)
            # facing the light: dz/dx = -lx / lz, and one row down (y = -r) is dz = +ly / lz
            plane = (-light[0] / light[2]) * cols + (light[1] / light[2]) * rows
            return np.where(mask, plane, np.nan).astype(np.float32), True
        # mostly plate, some shading: a constant factor is invisible to the solvers, which divide
        # by the brightest value, and keeps the pipeline's clipping guard off this tile
        image = image * np.float32(0.99)
    depth = reconstruct(image, mask=mask, **options).depth.astype(np.float32)
    return np.where(mask, depth, np.float32(np.nan)), False


class Runner:
    """Where the tile tasks run, checked (a cluster reached) before any work is made.

    Parameters
    ----------
    scheduler : None, str or distributed.Client
        See :func:`shadeform.tiled.reconstruct`.
    workers : int
        Local workers.
    """

    def __init__(self, scheduler, workers: int):
        self.workers, self.client, self.own = int(workers), None, False
        address = isinstance(scheduler, str) and "://" in scheduler
        if address or (scheduler is not None and not isinstance(scheduler, str)):
            self.kind = "cluster"
            self.client, self.own = _connect(scheduler) if address else (scheduler, False)
        else:
            self.kind = scheduler or ("processes" if workers > 1 else "synchronous")
            if self.kind not in _LOCAL:
                raise InputError(
                    f"unknown scheduler {scheduler!r}; use 'processes', 'threads', 'synchronous' "
                    "or a cluster address like tcp://host:8786"
                )

    def describe(self) -> str:
        if self.kind != "cluster":
            return self.kind
        return f"distributed {getattr(getattr(self.client, 'scheduler', None), 'address', '?')}"

    def close(self) -> None:
        if self.own and self.client is not None:
            self.client.close()
            self.client = None

    def run(self, tasks: list, done: Callable[[int], object]) -> list[dict]:
        """Compute the tile tasks; ``done(count)`` after each. Their results."""
        STOPPED.clear()
        if not tasks:
            return []
        try:
            return self._cluster(tasks, done) if self.kind == "cluster" else self._local(tasks, done)
        except BaseException:
            STOPPED.set()  # threads still solving write nothing
            raise

    def _local(self, tasks: list, done) -> list[dict]:
        import dask
        from dask.callbacks import Callback

        count = [0]

        def finished(key, result, dsk, state, worker_id):
            name = key if isinstance(key, str) else str(key)
            if name.startswith("shadeform-tile-"):
                count[0] += 1
                done(count[0])

        with Callback(posttask=finished):
            if self.kind == "synchronous":
                return list(dask.compute(*tasks, scheduler="synchronous"))
            if self.kind == "threads":
                from multiprocessing.pool import ThreadPool

                pool = ThreadPool(self.workers)  # daemon threads: they cannot hold the exit
                try:
                    return list(dask.compute(*tasks, scheduler="threads", pool=pool))
                finally:
                    pool.terminate()
            import multiprocessing

            from shadeform.batch import _start_worker

            # the batch module's pool: spawned workers that end with this process
            pool = multiprocessing.get_context("spawn").Pool(
                self.workers, initializer=_start_worker, initargs=(os.getpid(),)
            )
            try:
                return list(dask.compute(*tasks, scheduler="processes", pool=pool))
            finally:
                pool.terminate()
                pool.join()

    def _cluster(self, tasks: list, done) -> list[dict]:
        import distributed

        futures = self.client.compute(tasks)
        results = []
        try:
            for count, future in enumerate(distributed.as_completed(futures), start=1):
                results.append(future.result())
                future.release()
                done(count)
        finally:
            self.client.cancel(futures)
        return results


def _connect(address: str):
    try:
        import distributed
    except ImportError:
        raise InputError(
            "running on a Dask cluster needs distributed; install it with pip install 'shadeform[dask]'"
        ) from None
    try:
        return distributed.Client(address, timeout="20s"), True
    except (OSError, TimeoutError, ValueError) as err:
        raise InputError(f"cannot reach the Dask scheduler at {address} ({err}); check the address") from None
