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
==============================================  =================================================

As elsewhere, input checking, a library call (:func:`shadeform.relief`, :func:`shadeform.maps`)
and encoding. The reconstruction is the one :func:`shadeform.app.solving.solve` keeps for
``/api/reconstruct`` and ``/api/export``: a model that is current is not solved again. Solids and
maps are kept in the same results cache, so that a download after a preview is not made again.
The maps' files are those of ``shadeform maps`` (:data:`shadeform.cli.maps.LEGEND`, written by
:func:`shadeform.io.maps.save_gray`).
"""

from __future__ import annotations

import io
import math
import tempfile
import time
import zipfile
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
    ReconstructParams,
    ReconstructRequest,
    ReliefParams,
    ReliefRequest,
    ReliefResult,
)
from shadeform.app.solving import solve
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

    @app.post("/api/relief", response_model=ReliefResult)
    async def post_relief(body: ReliefRequest, request: Request) -> Response:
        options = relief_options(body.relief)  # refused before any solve
        return await state.solve_json(
            request, _relief_result, state, state.image(body.image_id), body, options
        )

    @app.post("/api/relief/export", response_class=Response, responses=FILE_RESPONSES)
    async def post_relief_export(
        body: ReliefRequest,
        format: str = Query(..., description="A suffix from Options.formats: .stl or .3mf for a printer."),
    ) -> Response:
        from shadeform.io.exporters import available_formats

        suffix = format_suffix(format, available_formats())
        options = relief_options(body.relief)
        entry = state.image(body.image_id)
        async with state.solve_lock:
            solid, _ = await run_in_threadpool(_relief, state, entry, body.params, options)
            data = await run_in_threadpool(mesh_bytes, solid, suffix)
        return download(data, f"{safe_stem(entry.name)}-relief", suffix)

    @app.post("/api/maps", response_model=MapsResult)
    async def post_maps(body: ReconstructRequest, request: Request) -> Response:
        return await state.solve_json(request, _maps_result, state, state.image(body.image_id), body)

    @app.post("/api/maps/zip", response_class=Response, responses=_ZIP_RESPONSES)
    async def post_maps_zip(body: ReconstructRequest) -> Response:
        entry = state.image(body.image_id)
        async with state.solve_lock:
            made, how = await run_in_threadpool(_maps, state, entry, body.params)
            data = await run_in_threadpool(_zip, made, safe_stem(entry.name), how["range"])
        name = f"{safe_stem(entry.name)}-maps.zip"
        return Response(
            data,
            media_type="application/zip",
            headers={"Content-Disposition": f'attachment; filename="{name}"'},
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


def _key(kind: str, entry, params: ReconstructParams, *extra) -> tuple:
    # the mesh's step plays no part: a solid and the maps are made from the full-resolution depth
    return (kind, entry.image_id, params.model_dump_json(exclude={"step"}), *extra)


def _relief(state, entry, params: ReconstructParams, options: dict) -> tuple[Any, dict[str, Any]]:
    """The solid for these parameters and print options, from the cache when known; with the
    seconds spent and whether the reconstruction and the solid were reused."""
    from shadeform import relief

    key = _key("relief", entry, params, tuple(sorted(options.items())))
    known = state.results.get(key)
    if known is not None:
        return known, {"timings": {}, "cached": True, "reused": True}
    solved, cached = solve(state, entry, params)
    timings = {} if cached else {"reconstruct": _solve_seconds(solved.reconstruction)}
    start = time.perf_counter()
    solid = relief(solved.reconstruction, **options)
    timings["relief"] = time.perf_counter() - start
    state.results.put(key, solid, solid.vertices.nbytes + solid.faces.nbytes + solid.normals.nbytes)
    return solid, {"timings": timings, "cached": cached, "reused": False}


def _relief_result(state, entry, body: ReliefRequest, options: dict) -> ReliefResult:
    start = time.perf_counter()
    solid, how = _relief(state, entry, body.params, options)
    timings = how["timings"]
    lap = time.perf_counter()
    encoded = mesh_data(solid)
    timings["encode"] = time.perf_counter() - lap
    timings["total"] = time.perf_counter() - start
    return ReliefResult(
        request_id=body.request_id,
        mesh=encoded,
        size_mm=tuple(float(v) for v in solid.size_mm),
        volume_mm3=solid.volume_mm3,
        triangle_count=solid.n_faces,
        deviation_mm=float(solid.deviation_mm),
        pixel_mm=float(solid.pixel_mm),
        timings=timings,
        info={"cached": how["cached"], "reused": how["reused"]},
    )


def _maps(state, entry, params: ReconstructParams) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Every map of the reconstruction (float32, full resolution), from the cache when known;
    with the seconds spent, whether anything was reused, and the height map's range in pixels."""
    from shadeform import maps

    key = _key("maps", entry, params)
    known = state.results.get(key)
    if known is not None:
        return known[0], {"timings": {}, "cached": True, "reused": True, "range": known[1]}
    solved, cached = solve(state, entry, params)
    timings = {} if cached else {"reconstruct": _solve_seconds(solved.reconstruction)}
    start = time.perf_counter()
    # float32 keeps 24 bits, more than the 16-bit files need, at half the cache's memory
    made = {name: values.astype(np.float32) for name, values in maps(solved.reconstruction).items()}
    timings["maps"] = time.perf_counter() - start
    low, high = solved.depth_range
    state.results.put(key, (made, high - low), sum(values.nbytes for values in made.values()))
    return made, {"timings": timings, "cached": cached, "reused": False, "range": high - low}


def _solve_seconds(reconstruction) -> float:
    """The seconds a reconstruction's stages took (its ``info["timings"]``)."""
    return float(sum(reconstruction.info["timings"].values()))


def _maps_result(state, entry, body: ReconstructRequest) -> MapsResult:
    start = time.perf_counter()
    made, how = _maps(state, entry, body.params)
    timings = how["timings"]
    lap = time.perf_counter()
    previews = [
        MapPreview(name=name, png=png_base64(_shrink(made[name])), bits=bits, legend=text)
        for name, (bits, text) in legend(how["range"]).items()
    ]
    timings["encode"] = time.perf_counter() - lap
    timings["total"] = time.perf_counter() - start
    height, width = made["height"].shape
    return MapsResult(
        request_id=body.request_id,
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


def _zip(made: dict[str, np.ndarray], stem: str, relief_px: float) -> bytes:
    """Every map as the CLI writes it (``STEM_NAME.png``, its bit depth), and README.txt."""
    from shadeform.io.maps import save_gray

    buffer = io.BytesIO()
    lines = ["Texture maps made by shadeform from one photo (the same files as `shadeform maps`).", ""]
    with (
        tempfile.TemporaryDirectory(prefix="shadeform-maps-") as folder,
        zipfile.ZipFile(buffer, "w") as archive,
    ):
        for name, (bits, text) in legend(relief_px).items():
            filename = f"{stem}_{name}.png"
            # the file name is ours: a sanitised stem and a map's name
            path = save_gray(made[name], Path(folder) / filename, bitdepth=bits)
            archive.write(path, filename)
            lines.append(f"{filename}  ({bits}-bit PNG): {text}")
        archive.writestr("README.txt", "\n".join(lines) + "\n")
    return buffer.getvalue()
