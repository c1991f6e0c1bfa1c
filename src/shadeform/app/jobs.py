"""Full-resolution solves in the background: a worker process, progress, cancel.

A 12 Mpx photo takes seconds to solve (12 s for the eikonal solver on the 2-core machine), most
of it in one numba kernel that a thread cannot be stopped in: a cancel flag checked between the
pipeline's stages would leave the kernel running for up to 8 s, holding a core and the next
solve. So the full solve runs in a worker process (``spawn``: a fork of a server whose numba
threads are running is unsafe) that cancelling terminates at once; a fresh one is started for the
next job. The worker reports each stage of :func:`shadeform.pipeline.reconstruct` (its
``progress`` hook) through a pipe.

The image goes to the worker, and the result's arrays come back, through shared memory blocks the
server creates and removes (a terminated worker leaves none behind): no copy through the pipe.

One job runs at a time (one worker: two solves would share the cores and both arrive late); a new
job supersedes (cancels) the one running.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import secrets
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing import shared_memory
from typing import Any

import numpy as np

__all__ = ["Job", "SolveJobs", "STAGE_WORDS"]

logger = logging.getLogger(__name__)

#: The solver process's niceness (Unix scheduling priority, 0 to 19: higher gives way more): the
#: conventional one of background work, not tuned.
BACKGROUND_NICENESS = 10

#: What each stage is, in the progress bar's words.
STAGE_WORDS = {
    "queued": "Starting the solver…",
    "mask": "Finding the object",
    "filter": "Filtering",
    "light": "Estimating the light",
    "references": "Finding the references",
    "normals": "Solving for the normals",
    "refine": "Refining the normals",
    "depth": "Integrating the depth",
    "solve": "Solving",
    "combine": "Combining",
    "confidence": "Assessing the result",
    "mesh": "Building the mesh",
    "done": "Done",
    "cancelled": "Cancelled",
    "failed": "Failed",
}

#: Jobs kept for their status and result after they ended.
_KEPT = 8


@dataclass
class Job:
    """One background solve: what the client polls."""

    job_id: str
    request_id: int
    state: str = "running"  # running, done, cancelled, failed
    stage: str = "queued"
    fraction: float = 0.0
    started: float = field(default_factory=time.perf_counter)
    ended: float | None = None
    detail: str | None = None
    result: Any = None  # what finish() made of the reconstruction (the JSON to send)
    cancel_event: threading.Event = field(default_factory=threading.Event)
    thread: threading.Thread | None = None

    @property
    def elapsed(self) -> float:
        return (self.ended or time.perf_counter()) - self.started


def _share(array: np.ndarray, blocks: list) -> tuple[str, tuple, str]:
    """A copy of ``array`` in a new shared memory block (appended to ``blocks``): its spec."""
    block = shared_memory.SharedMemory(create=True, size=max(1, array.nbytes))
    blocks.append(block)
    np.ndarray(array.shape, array.dtype, buffer=block.buf)[...] = array
    return block.name, array.shape, array.dtype.str


def _attach(spec, opened: list) -> np.ndarray:
    """The array of a block made by :func:`_share` (the worker shares the server's resource
    tracker, which holds each block once: the server's unlink is the one that counts)."""
    name, shape, dtype = spec
    block = shared_memory.SharedMemory(name=name)
    opened.append(block)
    return np.ndarray(shape, np.dtype(dtype), buffer=block.buf)


def _worker(conn) -> None:
    """The worker process: solves one job after another until told to stop (None)."""
    # a background solve gives way to what the user is looking at (the browser's page, its render
    # and GPU processes, the server's quick looks) where they want the same cores, and takes the
    # cores they leave: under the solve of a 12 Mpx photo, tasks of 10-16 ms of the page's thread
    # stretched past 50 ms of wall time on the 2-core machine (benchmarks/results/app-large.md)
    with contextlib.suppress(OSError):
        os.nice(BACKGROUND_NICENESS)
    # its stderr is the server's: libraries' warnings are logged, not printed (shadeform.app.quiet)
    import warnings

    from shadeform.app.quiet import log_warning

    warnings.showwarning = log_warning
    # imported while the worker waits for its first job
    from shadeform.errors import InputError
    from shadeform.masks import find_object
    from shadeform.pipeline import reconstruct

    while True:
        try:
            message = conn.recv()
        except EOFError:
            return
        if message is None:
            return
        image_spec, mask_spec, colour_spec, out_specs, settings = message
        opened: list = []
        image = mask = rec = None
        try:
            image = _attach(image_spec, opened)
            mask = None if mask_spec is None else _attach(mask_spec, opened)
            if colour_spec is not None:  # the object found on the photo's colours
                conn.send(("progress", "mask", 0.0))
                mask = find_object(_attach(colour_spec, opened))
            rec = reconstruct(
                image,
                mask=mask,
                progress=lambda stage, done: conn.send(("progress", stage, done)),
                **settings,
            )
            for name in ("normals", "depth", "mask", "confidence"):
                if getattr(rec, name) is not None:
                    _attach(out_specs[name], opened)[...] = getattr(rec, name)
            conn.send(("done", rec.light, rec.albedo, rec.info, rec.confidence is not None))
        except InputError as err:
            conn.send(("failed", str(err)))
        except Exception as err:  # a bug: the server logs it, the client gets one line
            conn.send(("crashed", f"{type(err).__name__}: {err}"))
        finally:
            del image, mask, rec  # no view of a block may outlive it
            for block in opened:
                block.close()


class SolveJobs:
    """The background solves of one app: a worker process kept ready, the jobs by id."""

    def __init__(self) -> None:
        self._context = multiprocessing.get_context("spawn")
        self._lock = threading.Lock()
        self._process = None
        self._conn = None
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._running: Job | None = None

    # --- the worker process -----------------------------------------------------------------

    def warm(self) -> None:
        """Start the worker now (it loads the kernels), so that the first job does not wait."""
        with self._lock:
            self._ensure_worker()

    def _ensure_worker(self) -> None:
        if self._process is not None and self._process.is_alive():
            return
        # the worker shares the server's resource tracker (started first, else it starts its own,
        # which at its exit takes the server's blocks the worker attached to for leaks of its own)
        from multiprocessing import resource_tracker

        resource_tracker.ensure_running()
        parent, child = self._context.Pipe()
        process = self._context.Process(target=_worker, args=(child,), name="shadeform-solver", daemon=True)
        process.start()
        child.close()
        self._process, self._conn = process, parent

    def _stop_worker(self) -> None:
        process, conn = self._process, self._conn
        self._process = self._conn = None
        if process is None:
            return
        process.terminate()
        process.join(timeout=5)
        if process.is_alive():
            process.kill()
            process.join()
        conn.close()

    def close(self) -> None:
        """Cancel what runs and stop the worker."""
        with self._lock:
            running = self._running
        if running is not None:
            self.cancel(running.job_id)
            if running.thread is not None:  # it removes its shared memory blocks
                running.thread.join(timeout=5)
        with self._lock:
            if self._conn is not None:
                with contextlib.suppress(OSError):
                    self._conn.send(None)
            self._stop_worker()

    # --- jobs -------------------------------------------------------------------------------

    def get(self, job_id: str) -> Job | None:
        with self._lock:
            return self._jobs.get(job_id)

    def start(
        self,
        request_id: int,
        image: np.ndarray,
        mask: np.ndarray | None,
        settings: dict[str, Any],
        finish: Callable[[Job, Any], Any],
        *,
        colour: np.ndarray | None = None,
    ) -> Job:
        """Solve ``reconstruct(image, mask=mask, **settings)`` in the worker; ``finish(job, rec)``
        (run in this process, in the job's thread) makes what the job's result is. Without a
        ``mask``, the worker finds the object on ``colour`` (the photo's colours, (H, W, 3)) when
        given, else the pipeline on ``image``."""
        job = Job(secrets.token_hex(8), request_id)
        with self._lock:
            superseded = self._running
        if superseded is not None:
            self.cancel(superseded.job_id, "superseded by a newer solve")
        with self._lock:
            self._jobs[job.job_id] = job
            while len(self._jobs) > _KEPT:
                self._jobs.popitem(last=False)
            self._running = job
        job.thread = threading.Thread(
            target=self._run,
            args=(job, image, mask, colour, settings, finish),
            name="shadeform-job",
            daemon=True,
        )
        job.thread.start()
        return job

    def finished(self, request_id: int, result: Any) -> Job:
        """A job that is done already (its result was known)."""
        job = Job(secrets.token_hex(8), request_id, state="done", stage="done", fraction=1.0, result=result)
        job.ended = job.started
        with self._lock:
            self._jobs[job.job_id] = job
            while len(self._jobs) > _KEPT:
                self._jobs.popitem(last=False)
        return job

    def cancel(self, job_id: str, why: str = "cancelled") -> Job | None:
        """Stop job ``job_id`` (its worker is terminated at once); a no-op for one that ended."""
        with self._lock:
            job = self._jobs.get(job_id)
            if job is None or job.state != "running":
                return job
            job.cancel_event.set()
            job.state, job.detail, job.ended = "cancelled", why, time.perf_counter()
            if self._running is job:
                self._running = None
                self._stop_worker()
        return job

    def _run(self, job: Job, image, mask, colour, settings, finish) -> None:
        from shadeform.reconstruction import Reconstruction

        blocks: list = []
        try:
            with self._lock:
                if job.cancel_event.is_set():
                    return
                self._ensure_worker()
                conn = self._conn
            shape = image.shape
            # the dtypes reconstruct returns (its arrays are copied into these as they are)
            out_specs = {
                "normals": _share(np.empty(shape + (3,), dtype=np.float32), blocks),
                "depth": _share(np.empty(shape), blocks),
                "mask": _share(np.empty(shape, dtype=bool), blocks),
                "confidence": _share(np.empty(shape, dtype=np.float32), blocks),
            }
            image_spec = _share(np.asarray(image, dtype=np.float32), blocks)
            mask_spec = None if mask is None else _share(np.asarray(mask, dtype=bool), blocks)
            colour_spec = None
            if mask is None and colour is not None:
                colour_spec = _share(np.asarray(colour, dtype=np.float32), blocks)
            conn.send((image_spec, mask_spec, colour_spec, out_specs, settings))
            while True:
                message = conn.recv()
                if message[0] != "progress":
                    break
                job.stage, job.fraction = message[1], 0.95 * float(message[2])
            if message[0] != "done":
                job.state, job.detail = "failed", message[1]
                if message[0] == "crashed":
                    logger.error("the background solve failed: %s", message[1])
                return
            opened: list = []
            arrays = {name: np.array(_attach(spec, opened)) for name, spec in out_specs.items()}
            for block in opened:
                block.close()
            light, albedo, info, assessed = message[1:]
            if not assessed:
                arrays["confidence"] = None
            rec = Reconstruction(light=light, albedo=albedo, info=info, **arrays)
            job.stage, job.fraction = "mesh", 0.95
            job.result = finish(job, rec)
            job.state, job.stage, job.fraction = "done", "done", 1.0
        except (EOFError, OSError, BrokenPipeError):
            if not job.cancel_event.is_set():  # the worker died on its own (out of memory?)
                job.state, job.detail = "failed", "the solver process stopped unexpectedly; try again"
        except Exception as err:  # finish() failed: a bug, or the user's input (InputError)
            from shadeform.errors import InputError

            if not isinstance(err, InputError):
                logger.exception("the background solve failed")
            job.state, job.detail = (
                "failed",
                str(err)
                if isinstance(err, InputError)
                else (f"internal error ({type(err).__name__}) in shadeform; please report it"),
            )
        finally:
            for block in blocks:
                block.close()
                block.unlink()
            with self._lock:
                job.ended = job.ended or time.perf_counter()
                if self._running is job:
                    self._running = None
