"""The app's views routes: photos of one object from several sides, each reconstructed as one
photo is, placed in one frame and fused into one closed model.

==============================================  =================================================
``POST /api/fuse``                              ``FuseRequest`` -> ``FuseResult``
``POST /api/fuse/export?format=.glb``           ``FuseRequest`` -> the fused mesh file
``POST /api/viewsets/examples/{name}``          a shipped view set -> ``ViewSetInfo``
==============================================  =================================================

As for one photo, every endpoint is input checking, library calls (:func:`shadeform.fusion.place`,
:func:`shadeform.fusion.solid`) and encoding. A view is the server's own single-photo solve of
its image with its parameters (``/api/reconstruct``'s, cache included): re-fusing after one
view's mask or regions changed solves only that view again, and the same request twice (an
export after the view) fuses once. With ``settle``, what a photo leaves open (its unsure areas)
is read as concave where the other views' silhouettes say so (:mod:`shadeform.fusion.settle`):
the view is solved again the same way with those areas added to its regions, and the result
lists them per view. Each view's partial model (the reading the fusion kept) comes back moved to
where the fusion placed it (:meth:`shadeform.fusion.Placement.transforms`), on a coarser grid so
that the response stays light.

A view may instead name a stored photo set (``FuseView.photo_set_id``): several photos of that
side under different lights, solved by the photo-set mode's own photometric stereo and cache
(:func:`shadeform.app.stereo.solve_set`), as ``shadeform fuse`` takes a folder per view. Its
shape is unambiguous, so it is never solved again for settling, and concave regions drawn for it
are refused.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from fastapi import APIRouter, FastAPI, Query, Request
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException

from shadeform.app.encoding import (
    FILE_RESPONSES,
    download,
    format_suffix,
    json_response,
    mesh_bytes,
    mesh_data,
    safe_stem,
)
from shadeform.app.guard import check_known
from shadeform.app.schema import ConcaveRegion, FusedView, FuseRequest, FuseResult, ViewSetInfo
from shadeform.app.solving import Solved, solve
from shadeform.app.state import image_info, suggested_params
from shadeform.app.stereo import StoredPhotoSet, photoset, solve_set
from shadeform.errors import InputError

__all__ = ["PART_VERTICES", "add_fusion_routes"]

#: Most vertices across a partial model's longer side: the parts only show where each view went.
PART_VERTICES = 64


@dataclass(frozen=True, eq=False)
class _Fused:
    """A cached fusion: the closed model, each view's reading and where its partial model goes."""

    mesh: Any
    readings: tuple[Any, ...]
    settled: tuple[tuple[dict, ...], ...]
    transforms: tuple[np.ndarray, ...]
    axis: float
    spacing: float
    volume: float
    watertight: bool
    rivals: tuple[tuple[float, ...], ...]
    depth_fixed: bool
    outlines: tuple[float, ...]
    timings: dict[str, float]


def add_fusion_routes(app: FastAPI, state: Any) -> None:
    """Add the views endpoints to an app (before its catch-all route).

    Parameters
    ----------
    app : fastapi.FastAPI
        The app :func:`shadeform.app.server.create_app` builds.
    state : shadeform.app.state.State
        The app's store: its images, its reconstructions (each view's is kept there) and fusions.
    """
    router = APIRouter()
    state.rebuilders["view"] = lambda key, recipe, blobs: _example_views(recipe["name"], key, recipe["index"])
    # example name -> its images' ids and angles (rendered once, while the server keeps the images)
    view_sets: dict[str, tuple[tuple[str, ...], tuple[float, ...]]] = {}

    @router.post("/api/fuse", response_model=FuseResult)
    async def post_fuse(body: FuseRequest, request: Request) -> Response:
        return await state.solve_json(request, _result, state, _entries(state, body), body)

    @router.post("/api/fuse/export", response_class=Response, responses=FILE_RESPONSES)
    async def post_fuse_export(
        body: FuseRequest,
        format: str = Query(..., description="A suffix from Options.formats, e.g. .glb."),
    ) -> Response:
        from shadeform.io.exporters import available_formats

        suffix = format_suffix(format, available_formats())
        entries = _entries(state, body)
        async with state.solve_lock:
            solved = await run_in_threadpool(_solved, state, entries, body)
            fused, _ = await run_in_threadpool(_fuse, state, entries, body, solved)
            data = await run_in_threadpool(mesh_bytes, fused.mesh, suffix)
        return download(data, f"{safe_stem(entries[0].name)}-fused", suffix)

    @router.post("/api/viewsets/examples/{name}", response_model=ViewSetInfo, status_code=201)
    def post_view_set_example(name: str) -> Response:
        from shadeform.examples import VIEW_SET_EXAMPLES

        check_known(name, VIEW_SET_EXAMPLES, "view set")
        ids, angles = view_sets.get(name, ((), ()))
        known = [state.images.get(image_id) for image_id in ids]
        if not known or any(entry is None for entry in known):
            known, angles = _example_views(name)
            for index, entry in enumerate(known):
                state.images.put(entry.image_id, entry, entry.nbytes)
                state.remember(entry.image_id, "view", {"name": name, "index": index})
            view_sets[name] = (tuple(entry.image_id for entry in known), angles)
        info = ViewSetInfo(name=name, images=[image_info(entry) for entry in known], angles=list(angles))
        return json_response(info, status_code=201)

    app.include_router(router)


# --- the work ----------------------------------------------------------------------------------


def _entries(state, body: FuseRequest) -> list:
    """Each view's stored image or photo set; an unknown one is a 404 that says which view, and
    concave regions drawn on a photo set a 422."""
    entries = []
    for i, view in enumerate(body.views):
        try:
            if view.photo_set_id is None:
                entries.append(state.image(view.image_id))
                continue
            entries.append(photoset(state, view.photo_set_id))
        except HTTPException as err:
            raise HTTPException(err.status_code, f"view {i + 1}: {err.detail}") from None
        if view.params.concave.regions:
            raise InputError(
                f"view {i + 1} ({entries[i].name}) is a photo set: its photometric stereo tells convex "
                "from concave itself; drop its concave regions"
            )
    return entries


def _solved(state, entries: list, body: FuseRequest) -> list[tuple[Any, bool]]:
    """Each view's reconstruction, exactly as ``/api/reconstruct`` (a photo) or ``/api/stereo``
    (a photo set) makes it, and caches it."""
    return [_view_solve(state, entries, i, view) for i, view in enumerate(body.views)]


def _view_solve(state, entries: list, i: int, view, params=None) -> tuple[Any, bool]:
    """View ``i`` solved by the server's own solve (and cache) with ``params`` (default: the
    view's), or a photo set's by its photometric stereo; a failure says which view."""
    entry = entries[i]
    try:
        if isinstance(entry, StoredPhotoSet):
            found, cached = solve_set(state, entry, view.stereo)
            maps = found.maps
            return Solved(found.reconstruction, maps["mask_png"], maps["depth_range"]), cached
        return solve(state, entry, view.params if params is None else params)
    except InputError as err:
        raise InputError(f"view {i + 1} ({entry.name}): {err}") from None


def _is_set(view) -> bool:
    return view.photo_set_id is not None


def _resolver(state, entries: list, body: FuseRequest):
    """``resolve(i, regions)`` for :func:`shadeform.fusion.place`: view ``i`` solved again as
    ``/api/reconstruct`` would with ``regions`` added to its own concave regions (and cached, so
    that fusing the same views again tries nothing anew); a photo set's own reading, never solved
    again (as ``shadeform fuse`` does)."""

    def resolve(i: int, regions: list) -> Any:
        view = body.views[i]
        if _is_set(view):
            return _view_solve(state, entries, i, view)[0].reconstruction
        params = view.params
        extra = [ConcaveRegion(polygon=region.polygon.tolist(), axis=region.axis) for region in regions]
        concave = params.concave.model_copy(update={"regions": [*params.concave.regions, *extra]})
        solved, _ = _view_solve(state, entries, i, view, params.model_copy(update={"concave": concave}))
        return solved.reconstruction

    return resolve


def _view_key(view) -> tuple:
    """What a view's reading depends on (its photo or set and settings but ``step``) and its angle."""
    if _is_set(view):
        return ("set", view.photo_set_id, view.stereo.model_dump_json(exclude={"step"}), view.angle)
    return (view.image_id, view.params.model_dump_json(exclude={"step"}), view.angle)


def _step(view) -> int:
    """The finest grid a view's partial model is drawn on."""
    return view.stereo.step if _is_set(view) else view.params.step


def _fuse(state, entries: list, body: FuseRequest, solved: list[tuple[Any, bool]]) -> tuple[_Fused, bool]:
    """The fused model of the solved views (cached per views, angles, parameters but ``step``,
    refine_poses, settle and resolution), and whether it was reused."""
    from shadeform.fusion import place, solid
    from shadeform.fusion.outlines import outline_iou
    from shadeform.mesh import solid_measures

    key = (
        "fuse",
        tuple(_view_key(view) for view in body.views),
        body.refine_poses,
        body.settle,
        body.resolution,
    )
    fused = state.results.get(key)
    if fused is not None:
        return fused, True
    recs = [item.reconstruction for item, _ in solved]
    lap = time.perf_counter()
    placement = place(
        list(zip(recs, [view.angle for view in body.views])),
        resolution=body.resolution,
        refine_poses=body.refine_poses,
        resolve=_resolver(state, entries, body) if body.settle else None,
    )
    placed = time.perf_counter()
    mesh = solid(placement)
    measures = solid_measures(mesh)
    outlines = tuple(outline_iou(mesh, placement))
    fused = _Fused(
        mesh,
        placement.readings,
        placement.concave,
        tuple(placement.transforms()),
        placement.axis,
        placement.grid.spacing,
        measures["volume"],
        measures["watertight"],
        tuple(rival.turns for rival in placement.rivals),
        placement.depth_fixed,
        outlines,
        {"place": placed - lap, "solid": time.perf_counter() - placed},
    )
    state.results.put(key, fused, mesh.vertices.nbytes + mesh.faces.nbytes + mesh.normals.nbytes)
    return fused, False


def _result(state, entries: list, body: FuseRequest) -> FuseResult:
    from shadeform import to_mesh

    start = time.perf_counter()
    solved = _solved(state, entries, body)
    timings = {"reconstruct": time.perf_counter() - start}
    fused, cached = _fuse(state, entries, body, solved)
    if not cached:
        timings.update(fused.timings)
    lap = time.perf_counter()
    parts = []
    for rec, view, transform in zip(fused.readings, body.views, fused.transforms):
        step = max(_step(view), math.ceil(max(rec.mask.shape) / PART_VERTICES))
        parts.append(_moved(to_mesh(rec, step=step), transform))
    timings["parts"] = time.perf_counter() - lap
    lap = time.perf_counter()
    mesh, encoded_parts = mesh_data(fused.mesh), [mesh_data(part) for part in parts]
    timings["encode"] = time.perf_counter() - lap
    timings["total"] = time.perf_counter() - start
    return FuseResult(
        request_id=body.request_id,
        mesh=mesh,
        parts=encoded_parts,
        views=[
            FusedView(
                mask_png=item.mask_png,
                light=tuple(float(v) for v in item.reconstruction.light),
                cached=was_cached,
                settled=[ConcaveRegion(polygon=area["polygon"], axis=area["axis"]) for area in settled],
                transform=transform.tolist(),
                outline_iou=outline,
            )
            for (item, was_cached), settled, transform, outline in zip(
                solved, fused.settled, fused.transforms, fused.outlines
            )
        ],
        axis=fused.axis,
        volume=fused.volume,
        watertight=fused.watertight,
        rivals=[list(turns) for turns in fused.rivals],
        depth_fixed=fused.depth_fixed,
        timings=timings,
        info={
            "resolution": fused.spacing,
            "refine_poses": body.refine_poses,
            "settle": body.settle,
            "cached": cached,
        },
    )


def _moved(mesh, transform: np.ndarray):
    """A mesh moved by a rigid 4x4 transform (its normals turned with it)."""
    from shadeform.mesh import Mesh

    rotation, shift = transform[:3, :3], transform[:3, 3]
    return Mesh(mesh.vertices @ rotation.T + shift, mesh.faces, mesh.normals @ rotation.T, mesh.uv)


def _example_views(name: str, key: str | None = None, index: int | None = None):
    """A view-set example's views as stored images with new ids and their angles; or, given
    ``key`` and ``index``, that one view under that id (made again from the session store)."""
    from shadeform.app.store import StoredImage, new_image_id
    from shadeform.examples import load_view_set_example

    images, masks, angles, settings = load_view_set_example(name)
    suggested = suggested_params(settings)
    stem = name.split(":")[-1]
    views = [
        StoredImage(new_image_id(), f"{stem} {angle:g}°", image[:, :, None], mask, suggested)
        for image, mask, angle in zip(images, masks, angles)
    ]
    if key is None:
        return views, angles
    from dataclasses import replace

    return replace(views[index], image_id=key)
