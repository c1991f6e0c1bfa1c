"""The app's print and texture-map routes: a reconstruction as a print-ready solid in millimetres,
and as texture maps.

==============================================  =================================================
``POST /api/relief``                            ``ReliefRequest`` -> ``ReliefResult`` (the solid
                                                for display, with its size, volume, triangles)
``POST /api/relief/export?format=.stl``         ``ReliefRequest`` -> the solid's file (``.stl``,
                                                ``.3mf``, or any format of the registry)
``POST /api/maps``                              ``ReconstructRequest`` -> ``MapsResult`` (small
                                                previews of every map, with their legends)
``POST /api/maps/zip``                          ``ReconstructRequest`` -> a zip of every map at
                                                full resolution as PNG, with a README.txt legend
``POST /api/stereo/relief``, ``.../export``     ``StereoReliefRequest``: the same of a photo
                                                set's photometric stereo
``POST /api/stereo/maps``, ``.../maps/zip``     ``StereoRequest``: the same, with the set's albedo
==============================================  =================================================

As elsewhere, input checking, a library call (:func:`shadeform.relief`, :func:`shadeform.maps`)
and encoding. The reconstruction is the one :func:`shadeform.app.solving.solve` keeps for
``/api/reconstruct`` and ``/api/export`` (a photo set's, the one
:func:`shadeform.app.stereo.solve_set` keeps for ``/api/stereo``): a model that is current is
not solved again. Solids and
maps are kept in the same results cache, so that a download after a preview is not made again.
The maps' files are those of ``shadeform maps`` (:data:`shadeform.cli.maps.LEGEND`, written by
:func:`shadeform.io.maps.save_gray`).
"""

# (no ``from __future__ import annotations``: a route's body type is an argument of
# _add_source_routes, which FastAPI reads from the annotation when the route is added)
import io
import math
import tempfile
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from fastapi import FastAPI, Query, Request
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from shadeform.app.encoding import (
    FILE_RESPONSES,
    download,
    format_suffix,
    mesh_bytes,
    mesh_data,
    png_base64,
    safe_stem,
)
from shadeform.app.schema import (
    MapPreview,
    MapsResult,
    ReconstructRequest,
    ReliefParams,
    ReliefRequest,
    ReliefResult,
    StereoReliefRequest,
    StereoRequest,
)
from shadeform.app.solving import solve
from shadeform.app.stereo import photoset, solve_set
from shadeform.texture import legend

__all__ = ["PREVIEW_SIDE", "add_print_routes", "relief_options"]

#: Longest side of a map's preview, pixels.
PREVIEW_SIDE = 256

#: What the options are called in messages: the Print panel's labels, as a sentence reads them.
_NAMES = {
    "width_mm": "the width",
    "height_mm": "the relief height",
    "base_mm": "the base",
    "outline": "outline",
    "compress": "the compression",
    "invert": "invert",
    "border_mm": "the border",
    "min_wall_mm": "the thinnest wall",
    "max_triangles": "the triangle budget",
}

_ZIP_RESPONSES: dict[int | str, dict] = {
    200: {"content": {"application/zip": {}}, "description": "Every map as a PNG, and a README.txt legend."}
}


@dataclass(frozen=True, eq=False)
class _Source:
    """What a print or the maps are made of: a stored photo's reconstruction or a photo set's
    photometric stereo, with what identifies it (the mesh's step plays no part: a solid and the
    maps are made from the full-resolution depth), its name for files, and how to get it."""

    key: tuple
    name: str
    solved: Callable[[], tuple[Any, bool]]  # () -> (reconstruction, whether it was cached)


def _photo(state, body) -> _Source:
    entry, params = state.image(body.image_id), body.params

    def solved():
        found, cached = solve(state, entry, params)
        return found.reconstruction, cached

    return _Source((entry.image_id, params.model_dump_json(exclude={"step"})), entry.name, solved)


def _photo_set(state, body) -> _Source:
    entry, params = photoset(state, body.photoset_id), body.params

    def solved():
        found, cached = solve_set(state, entry, params)
        return found.reconstruction, cached

    return _Source(
        (entry.photoset_id, params.model_dump_json(exclude={"step"})), entry.stem or entry.name, solved
    )


def add_print_routes(app: FastAPI, state: Any) -> None:
    """Add the print and maps endpoints to an app (before its catch-all route).

    Parameters
    ----------
    app : fastapi.FastAPI
        The app :func:`shadeform.app.server.create_app` builds.
    state : shadeform.app.state.State
        The app's store: its images, its reconstructions, and (in the same cache) the solids and
        maps made of them.
    """
    _add_source_routes(app, state, "/api", "", (ReconstructRequest, ReliefRequest), _photo)
    _add_source_routes(app, state, "/api/stereo", "stereo_", (StereoRequest, StereoReliefRequest), _photo_set)


def _add_source_routes(app: FastAPI, state: Any, prefix: str, name: str, models: tuple, source) -> None:
    """The relief and maps endpoints of one kind of source: a stored photo's (``/api``, bodies
    ``ReconstructRequest`` and ``ReliefRequest``, :func:`_photo`) or a photo set's (``/api/stereo``,
    ``StereoRequest`` and ``StereoReliefRequest``, :func:`_photo_set`); ``name`` goes into each
    route's name after ``post_``."""
    request_model, relief_model = models
    FORMAT = Query(..., description="A suffix from Options.formats: .stl or .3mf for a printer.")

    @app.post(f"{prefix}/relief", response_model=ReliefResult, name=f"post_{name}relief")
    async def post_relief(body: relief_model, request: Request) -> Response:
        options = relief_options(body.relief)  # refused before any solve
        return await state.solve_json(
            request, _relief_result, state, source(state, body), body.request_id, options
        )

    @app.post(
        f"{prefix}/relief/export",
        response_class=Response,
        responses=FILE_RESPONSES,
        name=f"post_{name}relief_export",
    )
    async def post_relief_export(body: relief_model, format: str = FORMAT) -> Response:
        return await _relief_file(state, source(state, body), body.relief, format)

    @app.post(f"{prefix}/maps", response_model=MapsResult, name=f"post_{name}maps")
    async def post_maps(body: request_model, request: Request) -> Response:
        return await state.solve_json(request, _maps_result, state, source(state, body), body.request_id)

    @app.post(
        f"{prefix}/maps/zip", response_class=Response, responses=_ZIP_RESPONSES, name=f"post_{name}maps_zip"
    )
    async def post_maps_zip(body: request_model) -> Response:
        return await _maps_zip(state, source(state, body))


async def _relief_file(state, source: _Source, relief: ReliefParams, format: str) -> Response:
    """The solid's file for a download."""
    from shadeform.io.exporters import available_formats

    suffix = format_suffix(format, available_formats())
    options = relief_options(relief)
    async with state.solve_lock:
        solid, _ = await run_in_threadpool(_relief, state, source, options)
        data = await run_in_threadpool(mesh_bytes, solid, suffix)
    return download(data, f"{safe_stem(source.name)}-relief", suffix)


async def _maps_zip(state, source: _Source) -> Response:
    """Every map at full resolution, zipped, for a download."""
    async with state.solve_lock:
        made, how = await run_in_threadpool(_maps, state, source)
        data = await run_in_threadpool(_zip, made, safe_stem(source.name), how)
    name = f"{safe_stem(source.name)}-maps.zip"
    return Response(
        data, media_type="application/zip", headers={"Content-Disposition": f'attachment; filename="{name}"'}
    )


def relief_options(params: ReliefParams) -> dict:
    """A request's print options checked as :func:`shadeform.relief` checks them (sizes within
    :data:`shadeform.solid.SIZE_RANGE_MM`), named as the Print panel names them.

    Raises
    ------
    InputError
        For the first bad option, in one line.
    """
    from shadeform.solid import check_options

    return check_options(**params.model_dump(), names=_NAMES)


# --- the work ----------------------------------------------------------------------------------


def _relief(state, source: _Source, options: dict) -> tuple[Any, dict[str, Any]]:
    """The solid for these print options, from the cache when known; with the seconds spent and
    whether the reconstruction and the solid were reused."""
    from shadeform import relief

    key = ("relief", *source.key, tuple(sorted(options.items())))
    known = state.results.get(key)
    if known is not None:
        return known, {"timings": {}, "cached": True, "reused": True}
    reconstruction, cached = source.solved()
    timings = {} if cached else {"reconstruct": _solve_seconds(reconstruction)}
    start = time.perf_counter()
    solid = relief(reconstruction, **options)
    timings["relief"] = time.perf_counter() - start
    state.results.put(key, solid, solid.vertices.nbytes + solid.faces.nbytes + solid.normals.nbytes)
    return solid, {"timings": timings, "cached": cached, "reused": False}


def _relief_result(state, source: _Source, request_id: int, options: dict) -> ReliefResult:
    start = time.perf_counter()
    solid, how = _relief(state, source, options)
    timings = how["timings"]
    lap = time.perf_counter()
    encoded = mesh_data(solid)
    timings["encode"] = time.perf_counter() - lap
    timings["total"] = time.perf_counter() - start
    return ReliefResult(
        request_id=request_id,
        mesh=encoded,
        size_mm=tuple(float(v) for v in solid.size_mm),
        volume_mm3=solid.volume_mm3,
        triangle_count=solid.n_faces,
        deviation_mm=float(solid.deviation_mm),
        pixel_mm=float(solid.pixel_mm),
        timings=timings,
        info={"cached": how["cached"], "reused": how["reused"]},
    )


def _maps(state, source: _Source) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Every map of the reconstruction (float32, full resolution), from the cache when known;
    with the seconds spent, whether anything was reused, the height map's range in pixels and
    (a photo set's) the albedo's white."""
    from shadeform import maps
    from shadeform.texture import albedo_map

    key = ("maps", *source.key)
    known = state.results.get(key)
    if known is not None:
        return known[0], {"timings": {}, "cached": True, "reused": True, **known[1]}
    reconstruction, cached = source.solved()
    timings = {} if cached else {"reconstruct": _solve_seconds(reconstruction)}
    start = time.perf_counter()
    # float32 keeps 24 bits, more than the 16-bit files need, at half the cache's memory
    made = {name: values.astype(np.float32) for name, values in maps(reconstruction).items()}
    timings["maps"] = time.perf_counter() - start
    depth = reconstruction.depth[reconstruction.mask]
    measures = {"range": float(np.nanmax(depth) - np.nanmin(depth))}
    if "albedo" in made:
        measures["white"] = albedo_map(reconstruction.albedo, reconstruction.mask)[1]
    state.results.put(key, (made, measures), sum(values.nbytes for values in made.values()))
    return made, {"timings": timings, "cached": cached, "reused": False, **measures}


def _solve_seconds(reconstruction) -> float:
    """The seconds a reconstruction's stages took (its ``info["timings"]``)."""
    return float(sum(reconstruction.info["timings"].values()))


def _legend(made: dict, how: dict) -> dict[str, tuple[int, str]]:
    """The legend of the maps made: a photo set's albedo too."""
    return legend(how["range"], albedo="stereo" if "albedo" in made else None, white=how.get("white"))


def _maps_result(state, source: _Source, request_id: int) -> MapsResult:
    start = time.perf_counter()
    made, how = _maps(state, source)
    timings = how["timings"]
    lap = time.perf_counter()
    previews = [
        MapPreview(name=name, png=png_base64(_shrink(made[name])), bits=bits, legend=text)
        for name, (bits, text) in _legend(made, how).items()
    ]
    timings["encode"] = time.perf_counter() - lap
    timings["total"] = time.perf_counter() - start
    height, width = made["height"].shape
    return MapsResult(
        request_id=request_id,
        width=width,
        height=height,
        maps=previews,
        timings=timings,
        info={"cached": how["cached"], "reused": how["reused"]},
    )


def _shrink(values: np.ndarray) -> np.ndarray:
    """A map at most :data:`PREVIEW_SIDE` on a side: the mean of each ``k`` x ``k`` block (the
    last blocks padded with their edge), so that fine detail shows as its average."""
    from shadeform.app.large import downsample

    return downsample(values, max(1, math.ceil(max(values.shape[:2]) / PREVIEW_SIDE)))


def _zip(made: dict[str, np.ndarray], stem: str, how: dict) -> bytes:
    """Every map as the CLI writes it (``STEM_NAME.png``, its bit depth), and README.txt."""
    from shadeform.io.maps import save_gray

    buffer = io.BytesIO()
    source = "a photo set" if "albedo" in made else "one photo"
    lines = [f"Texture maps made by shadeform from {source} (the same files as `shadeform maps`).", ""]
    with (
        tempfile.TemporaryDirectory(prefix="shadeform-maps-") as folder,
        zipfile.ZipFile(buffer, "w") as archive,
    ):
        for name, (bits, text) in _legend(made, how).items():
            filename = f"{stem}_{name}.png"
            # the file name is ours: a sanitised stem and a map's name
            path = save_gray(made[name], Path(folder) / filename, bitdepth=bits)
            archive.write(path, filename)
            lines.append(f"{filename}  ({bits}-bit PNG): {text}")
        archive.writestr("README.txt", "\n".join(lines) + "\n")
    return buffer.getvalue()
