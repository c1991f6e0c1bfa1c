"""The app's solves of one photo: the reconstruction for a request's parameters (cached, a quick
look on a large photo's pyramid level), the image and automatic mask a solve uses, the result as
the client's JSON, background solves of large photos, and an export's mesh file.

Shared by the app's route modules (:mod:`shadeform.app.reconstruct` for one photo, and the
prints, maps and fused views, which reuse a current model rather than solve it again).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from starlette.exceptions import HTTPException

from shadeform.app.encoding import mesh_bytes, mesh_data, mesh_file, plain, png_base64
from shadeform.app.guard import shorten
from shadeform.app.jobs import STAGE_WORDS
from shadeform.app.large import downsample, level_factor
from shadeform.app.mask_files import user_mask
from shadeform.app.schema import ReconstructParams, ReconstructRequest, ReconstructResult, SolveJob
from shadeform.app.state import State
from shadeform.app.store import StoredImage

__all__ = [
    "Solved",
    "channel_of",
    "export_bytes",
    "find_job",
    "job_info",
    "reconstruct_result",
    "solve",
    "start_job",
]


@dataclass(frozen=True, eq=False)
class Solved:
    """A cached reconstruction with what every response about it repeats."""

    reconstruction: Any
    mask_png: str
    depth_range: tuple[float, float]
    #: the block side of the pyramid level it was solved on (1: the photo itself)
    level: int = 1


def solve(
    state: State, entry: StoredImage, params: ReconstructParams, *, preview: bool = False
) -> tuple[Solved, bool]:
    """The reconstruction for these parameters, from the cache when only ``step`` changed.

    With ``preview`` the full result if it is cached, else the quick look at the mesh's grid,
    or a coarser one within the solver's pixel budget
    (:func:`shadeform.coarse.preview_step`, :func:`shadeform.coarse.reconstruct_preview`);
    the returned reconstruction's ``info`` has ``preview_step`` when it is the quick one.
    """
    from shadeform.coarse import preview_step, reconstruct_preview
    from shadeform.pipeline import reconstruct

    full_key = _full_key(entry, params)
    solved = state.results.get(full_key)
    if solved is not None:
        return solved, True
    if preview and level_factor(entry.pixels.shape) > 1:
        return _solve_level(state, entry, params, full_key)
    settings = _settings(params)
    image, mask, mask_png = channel_of(state, entry, params.channel)
    if params.mask is not None:  # the user's mask
        mask, mask_png = user_mask(state, params.mask, image.shape)
    settings["mask"] = mask
    light = settings["light"]
    spacing = preview_step(mask, params.step, solver=params.solver, light=light) if preview else 1
    key = (*full_key, "preview", spacing) if spacing > 1 else full_key
    if spacing > 1 and (solved := state.results.get(key)) is not None:
        return solved, True
    rec = (
        reconstruct_preview(image, step=spacing, **settings)
        if spacing > 1
        else reconstruct(image, **settings)
    )
    if params.mask is None and (warning := _mask_warning(state, entry)):
        rec.info["mask_warning"] = warning  # as the CLI says it: the pipeline was given this mask
    depth = rec.depth[rec.mask]
    solved = Solved(rec, mask_png, (float(np.nanmin(depth)), float(np.nanmax(depth))))
    nbytes = rec.normals.nbytes + rec.depth.nbytes + rec.mask.nbytes
    state.results.put(key, solved, nbytes)
    return solved, False


def _full_key(entry: StoredImage, params: ReconstructParams) -> tuple:
    """The cache key of a full-resolution reconstruction (``step`` only re-meshes it)."""
    return (entry.image_id, params.model_dump_json(exclude={"step"}))


def _settings(params: ReconstructParams) -> dict[str, Any]:
    """:func:`shadeform.pipeline.reconstruct`'s options for ``params`` (all but the mask), in the
    photo's pixels."""
    from shadeform.light import light_from_slant_tilt
    from shadeform.preprocess import Filter

    if params.light.mode == "estimate":
        light: Any = "estimate"
    elif params.light.mode == "slant_tilt":
        light = light_from_slant_tilt(params.light.slant, params.light.tilt)
    else:
        light = (0.0, 0.0, 1.0)
    spec = None
    if params.filter.kind != "none":
        spec = Filter(params.filter.kind, params.filter.size) if params.filter.size > 0 else None
    regions = params.concave.model_dump()
    return dict(
        light=light,
        solver=params.solver,
        filter=spec,
        references=[tuple(ref) for ref in params.references],
        concave=regions if regions["regions"] else None,
        integrator=params.integrator,
        refine=params.refine,
    )


def _solve_level(
    state: State, entry: StoredImage, params: ReconstructParams, full_key: tuple
) -> tuple[Solved, bool]:
    """The quick look of a large photo: solved on its pyramid level (:func:`shadeform.app.large.
    level`) at the solver's preview grid there, whatever the photo's size."""
    from shadeform.app.large import level
    from shadeform.coarse import preview_step, reconstruct_on_level
    from shadeform.io.images import select_channel

    factor = level_factor(entry.pixels.shape)
    settings = _settings(params)
    known = state.masks.get(("level", entry.image_id, params.channel, factor))
    if known is None:
        from shadeform.masks import find_object

        image, mask = level(select_channel(entry.pixels, params.channel), entry.mask, factor)
        if mask is None:  # found on the level's colours, as the full photo's (channel_of)
            mask = find_object(downsample(entry.pixels, factor)).mask
        known = (image, mask)
        state.masks.put(("level", entry.image_id, params.channel, factor), known, known[0].nbytes)
    image, mask = known
    if params.mask is not None:  # the user's mask, at the level
        full, _ = user_mask(state, params.mask, entry.pixels.shape[:2])
        mask = downsample(full.astype(np.float32), factor) >= 0.5
        if not mask.any():  # thinner than a block: the blocks it touches
            mask = downsample(full.astype(np.float32), factor) > 0
    spacing = preview_step(mask, 1, solver=params.solver, light=settings["light"])
    key = (*full_key, "level", factor, spacing)
    if (solved := state.results.get(key)) is not None:
        return solved, True
    rec = reconstruct_on_level(image, factor=factor, step=spacing, mask=mask, **settings)
    depth = rec.depth[rec.mask & np.isfinite(rec.depth)] * factor
    solved = Solved(rec, "", (float(np.min(depth)), float(np.max(depth))), level=factor)
    state.results.put(key, solved, rec.normals.nbytes + rec.depth.nbytes + rec.mask.nbytes)
    return solved, False


def channel_of(state: State, entry: StoredImage, channel: str) -> tuple[np.ndarray, np.ndarray, str]:
    """One channel of a stored image, its object mask and the mask as base64 PNG, the mask kept
    per image: it is found on the photo's colours, whatever the channel and other parameters."""
    from shadeform.io.images import select_channel
    from shadeform.masks import find_object

    image = select_channel(entry.pixels, channel)
    key = ("mask", entry.image_id)
    known = state.masks.get(key)
    if known is None:
        warning = None
        if entry.mask is not None:
            mask = entry.mask
        else:
            found = find_object(entry.pixels)
            mask, warning = found.mask, found.warning
        known = (mask, png_base64(mask.astype(np.float32)), warning)
        state.masks.put(key, known, mask.nbytes)
    return image, *known[:2]


def _mask_warning(state: State, entry: StoredImage) -> str | None:
    """The automatic mask's one-line warning when it is doubtful (kept with it by :func:`channel_of`)."""
    known = state.masks.get(("mask", entry.image_id))
    return known[2] if known is not None else None


def reconstruct_result(state: State, entry: StoredImage, body: ReconstructRequest) -> ReconstructResult:
    """``/api/reconstruct``'s answer: :func:`solve` (a quick look if asked for) as the client's result."""
    start = time.perf_counter()
    solved, cached = solve(state, entry, body.params, preview=body.preview)
    return _result(entry, body, solved, cached, start)


def _result(entry: StoredImage, body: ReconstructRequest, solved: Solved, cached: bool, start: float):
    """A reconstruction as the client's result: its mesh sized for the screen, in the photo's
    pixels (a pyramid level's scaled back), with what ran."""
    from shadeform import to_mesh
    from shadeform.app.large import scale_mesh, scale_pixel, view_step

    rec = solved.reconstruction
    factor = solved.level
    timings = {} if cached else dict(rec.info["timings"])
    lap = time.perf_counter()
    # a quick look may be on a coarser grid than asked for (the solver's pixel budget); a full
    # result's mesh has at most VIEW_VERTICES vertices (the exports keep the step asked for)
    step = rec.info.get("preview_step") or view_step(int(np.count_nonzero(rec.mask)), body.params.step)
    mesh = scale_mesh(to_mesh(rec, step=step), factor)
    timings["mesh"] = time.perf_counter() - lap
    lap = time.perf_counter()
    encoded = mesh_data(mesh)
    timings["encode"] = time.perf_counter() - lap
    timings["total"] = time.perf_counter() - start
    info = plain(rec.info)
    references = [scale_pixel(ref, factor) for ref in rec.info["references"]]
    if factor > 1:
        info["level"] = factor  # solved on the photo downsampled by this factor
        info["references"] = references
        info["unsure"] = [
            {
                **area,
                "polygon": [[x * factor, y * factor] for x, y in area["polygon"]],
                "centre": [area["centre"][0] * factor, area["centre"][1] * factor],
            }
            for area in info.get("unsure", [])
        ]
    if step * factor != body.params.step:
        info["view_step"] = step * factor  # the mesh shown: pixels per vertex
    return ReconstructResult(
        request_id=body.request_id,
        preview="preview_step" in rec.info or factor > 1,
        mesh=encoded,
        mask_png=solved.mask_png,
        light=tuple(float(v) for v in rec.light),
        references=references,
        depth_range=solved.depth_range,
        timings=timings,
        info={**info, "cached": cached, **({"photo": entry.photo} if entry.photo else {})},
    )


# --- background solves -------------------------------------------------------------------------


def start_job(state: State, entry: StoredImage, body: ReconstructRequest):
    """The full solve of ``body`` as a background job (:class:`shadeform.app.jobs.SolveJobs`);
    already done when the result is cached."""
    from shadeform.io.images import select_channel

    start = time.perf_counter()
    params = body.params
    full_key = _full_key(entry, params)
    settings = _settings(params)
    image = select_channel(entry.pixels, params.channel)
    # the automatic mask is found in the worker (1.6 s at 12 Mpx), unless it is known already
    known = state.masks.get(("mask", entry.image_id))
    mask, mask_png = known[:2] if known is not None else (entry.mask, None)
    if params.mask is not None:
        mask, mask_png = user_mask(state, params.mask, image.shape)

    def finish(job, rec) -> str:
        nonlocal mask_png
        if mask_png is None:  # found by the pipeline, which said whether it is doubtful
            mask_png = png_base64(rec.mask.astype(np.float32))
            known = (rec.mask, mask_png, rec.info.get("mask_warning"))
            state.masks.put(("mask", entry.image_id), known, rec.mask.nbytes)
        elif params.mask is None and (warning := _mask_warning(state, entry)):
            rec.info["mask_warning"] = warning
        depth = rec.depth[rec.mask]
        solved = Solved(rec, mask_png, (float(np.nanmin(depth)), float(np.nanmax(depth))))
        state.results.put(full_key, solved, rec.normals.nbytes + rec.depth.nbytes + rec.mask.nbytes)
        return _result(entry, body, solved, False, start).model_dump_json()

    cached = state.results.get(full_key)
    if cached is not None:
        job = state.jobs.finished(
            body.request_id, _result(entry, body, cached, True, start).model_dump_json()
        )
        return job
    colour = entry.pixels if mask is None else None  # the worker finds the object on it
    return state.jobs.start(body.request_id, image, mask, settings, finish, colour=colour)


def find_job(state: State, job_id: str):
    """The background solve ``job_id``; an unknown one is a 404 that says what to do."""
    job = state.jobs.get(job_id)
    if job is None:
        raise HTTPException(
            404, f"unknown solve {shorten(job_id)!r}: it ended long ago or the server restarted; solve again"
        )
    return job


def job_info(job) -> SolveJob:
    """A background solve's progress as the client's :class:`~shadeform.app.schema.SolveJob`."""
    return SolveJob(
        job_id=job.job_id,
        request_id=job.request_id,
        state=job.state,
        stage=job.stage,
        stage_text=STAGE_WORDS.get(job.stage, job.stage.capitalize()),
        fraction=round(job.fraction, 4),
        elapsed=round(job.elapsed, 3),
        detail=job.detail,
    )


def export_bytes(
    state: State, entry: StoredImage, params: ReconstructParams, suffix: str, *, closed: bool = False
) -> bytes:
    """The model for ``params`` as a mesh file of the registry's format ``suffix``; ``closed``:
    the closed model of :func:`shadeform.fusion.close` (its back the front mirrored, a guess; the
    voxel edge ``params.step`` pixels, as ``shadeform reconstruct --closed --step``)."""
    solved, _ = solve(state, entry, params)
    if closed:
        from shadeform.fusion import close

        model = close(solved.reconstruction, resolution=params.step if params.step > 1 else None)
        return mesh_bytes(model, suffix)
    return mesh_file(solved.reconstruction, params.step, suffix)
