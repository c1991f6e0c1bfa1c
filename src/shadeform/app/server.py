"""The app's HTTP server: a thin FastAPI shell over the library, and the built web client.

Every endpoint is input checking, a library call and encoding; no algorithm lives here. The API
(all under ``/api``, JSON unless said; types in :mod:`shadeform.app.schema`):

==========================================  ===================================================
``GET  /api/options``                       methods, integrators, formats, examples, limits
``POST /api/images`` (multipart ``file``)   store an uploaded photo -> ``ImageInfo``
``POST /api/examples/{name}[?size=N]``      store a shipped example -> ``ImageInfo``
``GET  /api/images/{id}/photo.png``         the photo, 8-bit PNG
``GET  /api/images/{id}/channel.png``       one channel, filtered (``?channel=&filter=``)
``POST /api/reconstruct``                   ``ReconstructRequest`` -> ``ReconstructResult``
``POST /api/solves``                        ``ReconstructRequest`` -> ``SolveJob``: the full solve
                                            in the background (large photos: progress, cancel)
``GET  /api/solves/{id}[/result]``          its progress; its ``ReconstructResult`` once done
``DELETE /api/solves/{id}``                 cancel it
``POST /api/export?format=.wrl``            ``ReconstructRequest`` -> the mesh file
``POST /api/images/{id}/mask/...``          masks: :mod:`shadeform.app.masks`
``/api/photosets``, ``/api/stereo``         photo sets: :mod:`shadeform.app.stereo`
``/api/fuse``, ``/api/viewsets``            several views fused: :mod:`shadeform.app.fusion`
``/api/projects``                           the users' projects: :mod:`shadeform.app.projects`
``/api/relief``, ``/api/maps``              prints and texture maps: :mod:`shadeform.app.printing`
==========================================  ===================================================

Large photos (more than :data:`shadeform.app.large.LARGE_PIXELS`) get their quick look on a
downsampled copy and their full solve in a worker process (:mod:`shadeform.app.large`,
:mod:`shadeform.app.jobs`); a photo over ``max_pixels`` is refused with an offer
(``X-Shadeform-Fit`` headers) and taken downsampled to fit with ``POST /api/images?fit=true``.

Errors are always ``{"detail": "<one line: what was wrong and what to do>"}``: a library
:class:`~shadeform.InputError` is 422 (413 for an image with too many pixels), an unknown image
id 404, malformed requests 4xx; nothing else of an exception (no traceback) reaches the client.

Safety: the server binds to loopback unless told otherwise (``shadeform app --allow-remote``);
requests whose ``Host`` names another machine or port are refused (DNS rebinding), as are requests
from any page but the app's own: an ``Origin`` other than exactly the scheme, host and port the
request came to (another site, another port of this machine, ``null`` for a sandboxed page or a
local file), or a browser's ``Sec-Fetch-Site: cross-site``. Request bodies are capped before
they are read, images by pixels from their header before they are decoded; uploads are decoded
from memory, never from a path a client sent; downloads are named by the server (a registry
suffix and a sanitised stem). The limits, the guard and the error handlers live in
:mod:`shadeform.app.guard`.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from fastapi import FastAPI, File, Query, Request, UploadFile
from fastapi.responses import FileResponse, HTMLResponse, Response
from fastapi.routing import APIRoute
from fastapi.staticfiles import StaticFiles
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException

from shadeform.app.encoding import (
    FILE_RESPONSES,
    PNG_RESPONSES,
    display_name,
    download,
    format_suffix,
    json_response,
    mesh_data,
    mesh_file,
    plain,
    png,
    png_base64,
    shown_photo,
)
from shadeform.app.fusion import add_fusion_routes
from shadeform.app.guard import ERROR_RESPONSES, AppLimits, Guard, add_error_handlers, file_too_large
from shadeform.app.jobs import STAGE_WORDS, SolveJobs
from shadeform.app.large import FIT_FACTOR, LARGE_PIXELS, TILED_COMMAND, downsample, fit_factor, level_factor
from shadeform.app.masks import add_mask_routes, user_mask
from shadeform.app.printing import add_print_routes
from shadeform.app.projects import add_project_routes
from shadeform.app.quiet import warnings_logged
from shadeform.app.schema import (
    ExampleInfo,
    FilterParams,
    FormatInfo,
    ImageInfo,
    LightParams,
    Limits,
    MethodInfo,
    Options,
    ReconstructParams,
    ReconstructRequest,
    ReconstructResult,
    SolveJob,
)
from shadeform.app.sessions import SessionStore
from shadeform.app.stereo import add_stereo_routes
from shadeform.app.store import LRU, StoredImage, new_image_id
from shadeform.errors import InputError

__all__ = ["AppLimits", "LOOPBACK_HOSTS", "STATIC_DIR", "create_app", "warm_up"]

logger = logging.getLogger(__name__)

#: Where ``make web`` (and the package build) put the built client.
STATIC_DIR = Path(__file__).with_name("static")

#: The default ``allowed_hosts``: host names that mean this machine (at the server's port), and
#: the Vite dev server's address (``npm run dev`` forwards ``/api`` with its page's ``Host``).
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1", "localhost:5173")

_NO_CLIENT_PAGE = (
    "<!doctype html><title>shadeform</title><p>The web client is not built: run "
    "<code>make web</code> in the shadeform source folder, then reload this page.</p>"
)


def create_app(
    *,
    initial_image: str | Path | None = None,
    limits: AppLimits = AppLimits(),
    allowed_hosts: Sequence[str] | None = LOOPBACK_HOSTS,
    warm: bool = False,
    static_dir: Path | None = None,
    sessions: str | Path | None = None,
) -> FastAPI:
    """Build the app's ASGI application.

    Parameters
    ----------
    initial_image : str or Path, optional, keyword-only
        Opened at once and listed as ``Options.initial_image``: a :class:`~pathlib.Path` to an
        image file (the command line's own argument, never a client's), or the name of a shipped
        example (``"coin"``, ``"synth:bowl"``, ...).
    limits : AppLimits
        Upload and memory limits.
    allowed_hosts : sequence of str or None
        Host names a request's ``Host`` may name at the server's port, and forwarders' ``host:port``;
        None allows any (``--allow-remote``). Either way an ``Origin`` must be the app's own.
    warm : bool
        Compile (or load from numba's cache) the solvers' kernels in a background thread at
        start-up, so that the first reconstruction does not wait for them.
    static_dir : Path, optional
        The built client; :data:`STATIC_DIR` by default. Looked up per request, so a client
        built while the server runs is served without a restart.
    sessions : str or Path, optional
        An SQLite file that keeps what the clients opened (:class:`shadeform.app.sessions.
        SessionStore`), so that their sessions outlive a restart of the server; ``shadeform
        app`` gives one in the user's data folder. None: memory only.

    Returns
    -------
    FastAPI

    Raises
    ------
    InputError
        If ``initial_image`` cannot be read or is not an example.
    """
    static_dir = STATIC_DIR if static_dir is None else Path(static_dir)
    state = _State(
        limits, None if sessions is None else SessionStore(sessions, max_bytes=limits.max_stored_bytes)
    )
    initial = _store_initial(state, initial_image) if initial_image is not None else None

    app = FastAPI(
        title="shadeform",
        docs_url=None,
        redoc_url=None,
        openapi_url="/api/openapi.json",
        lifespan=_lifespan(warm, state),
        responses=ERROR_RESPONSES,
    )
    add_error_handlers(app)
    app.add_middleware(Guard, allowed_hosts=allowed_hosts, limits=limits)

    options = _options(limits, initial)

    @app.get("/api/options", response_model=Options)
    def get_options() -> Response:
        return json_response(options)

    @app.post("/api/images", response_model=ImageInfo, status_code=201)
    def post_image(
        file: UploadFile = File(..., description="The image file."),
        fit: bool = Query(
            False,
            description="Downsample a photo over the pixel limit to fit it (up to FIT_FACTOR times the "
            "limit): the offer a refusal's X-Shadeform-Fit headers describe.",
        ),
    ) -> Response:
        data = file.file.read(limits.max_upload_bytes + 1)
        if len(data) > limits.max_upload_bytes:
            raise HTTPException(413, file_too_large(limits))
        if not data:
            raise HTTPException(400, "the uploaded file is empty (0 bytes); choose an image file")
        name = display_name(file.filename)
        pixels, photo, factor = _read_upload(data, limits, name, fit=fit)
        entry = state.add(name, pixels, photo=photo)
        state.remember(entry.image_id, "upload", {"name": entry.name, "fit": factor}, [data])
        if level_factor(pixels.shape) > 1:
            state.jobs.warm()  # its full solve will run there: load the kernels meanwhile
        return json_response(_image_info(entry), status_code=201)

    @app.post("/api/examples/{name}", response_model=ImageInfo, status_code=201)
    def post_example(
        name: str, size: int | None = Query(None, description="Side of a synth: example.")
    ) -> Response:
        entry = state.example(name, size)
        return json_response(_image_info(entry), status_code=201)

    @app.get("/api/images/{image_id}/photo.png", response_class=Response, responses=PNG_RESPONSES)
    def get_photo(image_id: str) -> Response:
        entry = state.image(image_id)
        encoded = state.pngs.get((image_id, "photo"))
        if encoded is None:
            encoded = png(
                _shown(entry, entry.pixels[:, :, 0] if entry.pixels.shape[2] == 1 else entry.pixels)
            )
            state.pngs.put((image_id, "photo"), encoded, len(encoded))
        return Response(encoded, media_type="image/png", headers={"Cache-Control": "no-cache"})

    @app.get("/api/images/{image_id}/channel.png", response_class=Response, responses=PNG_RESPONSES)
    def get_channel(
        image_id: str,
        channel: str = Query("luma", description="luma, r, g, b or max."),
        filter: str = Query("none", description="none, or KIND:SIZE (e.g. gaussian:2, median:1)."),
    ) -> Response:
        from shadeform.preprocess import apply_filter, parse_filter

        entry = state.image(image_id)
        spec = parse_filter(filter)
        image, mask, _ = _channel(state, entry, channel)
        if spec.kind != "none":
            image = apply_filter(image, mask, spec)
        return Response(
            png(_shown(entry, image)), media_type="image/png", headers={"Cache-Control": "no-cache"}
        )

    @app.post("/api/reconstruct", response_model=ReconstructResult)
    async def post_reconstruct(body: ReconstructRequest, request: Request) -> Response:
        return await state.solve_json(request, _reconstruct_result, state, state.image(body.image_id), body)

    @app.post("/api/solves", response_model=SolveJob, status_code=202)
    def post_solve(body: ReconstructRequest) -> Response:
        return json_response(_job_info(_start_job(state, state.image(body.image_id), body)), status_code=202)

    @app.get("/api/solves/{job_id}", response_model=SolveJob)
    def get_solve(job_id: str) -> Response:
        return json_response(_job_info(_job(state, job_id)))

    @app.get("/api/solves/{job_id}/result", response_model=ReconstructResult)
    def get_solve_result(job_id: str) -> Response:
        job = _job(state, job_id)
        if job.state == "done":
            return Response(job.result, media_type="application/json")
        if job.state == "failed":
            raise HTTPException(422, job.detail)
        if job.state == "cancelled":
            raise HTTPException(409, f"the solve was {job.detail}; start a new one")
        raise HTTPException(409, "the solve is still running; ask for its progress until it is done")

    @app.delete("/api/solves/{job_id}", response_model=SolveJob)
    def delete_solve(job_id: str) -> Response:
        _job(state, job_id)
        return json_response(_job_info(state.jobs.cancel(job_id)))

    @app.post("/api/export", response_class=Response, responses=FILE_RESPONSES)
    async def post_export(
        body: ReconstructRequest,
        format: str = Query(..., description="A suffix from Options.formats, e.g. .wrl."),
    ) -> Response:
        from shadeform.io.exporters import available_formats

        suffix = format_suffix(format, available_formats())
        entry = state.image(body.image_id)
        async with state.solve_lock:
            data = await run_in_threadpool(_export_bytes, state, entry, body.params, suffix)
        return download(data, entry.name, suffix)

    add_mask_routes(app, state)
    add_stereo_routes(app, state)
    add_fusion_routes(app, state)
    add_project_routes(app, state)
    add_print_routes(app, state)

    @app.api_route("/", methods=["GET", "HEAD"], include_in_schema=False)
    def index() -> Response:
        page = static_dir / "index.html"
        if page.is_file():
            return FileResponse(page, headers={"Cache-Control": "no-cache"})
        return HTMLResponse(_NO_CLIENT_PAGE)

    # the client's scripts, styles and pictures; looked up per request (the client may be built
    # while the server runs); StaticFiles refuses any path that resolves outside the folder
    client_files = StaticFiles(directory=static_dir, check_dir=False)

    @app.api_route(
        "/{path:path}", methods=["GET", "HEAD", "POST", "PUT", "PATCH", "DELETE"], include_in_schema=False
    )
    async def static_file(path: str, request: Request) -> Response:
        # reached by every request no other route took, whatever its method
        if path == "api" or path.startswith("api/"):
            if any(
                route.path_regex.match("/" + path)
                for route in app.router.routes
                if isinstance(route, APIRoute) and route is not static_route
            ):
                raise HTTPException(405)
            raise HTTPException(404, "no such API endpoint; the endpoints are listed in /api/openapi.json")
        if request.method not in ("GET", "HEAD"):
            raise HTTPException(405)
        return await client_files.get_response(path, request.scope)

    static_route = app.router.routes[-1]
    return app


# --- state -------------------------------------------------------------------------------------


class _State:
    """What one app holds: images, recent reconstructions, encoded PNGs, the solver lock, and
    (with a session store) how to make again what its clients opened."""

    def __init__(self, limits: AppLimits, sessions: SessionStore | None = None) -> None:
        self.limits = limits
        self.sessions = sessions
        # kind of a remembered entry -> (key, recipe, blobs) -> the entry, made again
        self.rebuilders: dict[str, Any] = {"upload": self._rebuild_upload, "example": self._rebuild_example}
        self.images = LRU(max_items=limits.max_images, max_bytes=limits.max_image_bytes)
        self.results = LRU(max_items=limits.max_results, max_bytes=limits.max_result_bytes)
        self.pngs = LRU(max_items=2 * limits.max_images, max_bytes=limits.max_image_bytes // 4)
        self.masks = LRU(max_items=2 * limits.max_images, max_bytes=limits.max_image_bytes // 4)
        self._examples: dict[tuple[str, int | None], str] = {}
        # full solves of large photos, in a worker process (started with the first large photo)
        self.jobs = SolveJobs()
        # one solve at a time: two would only share the cores and both arrive late
        self.solve_lock = asyncio.Lock()

    async def solve_json(self, request: Request, work, *args) -> Response:
        """``work(*args)`` (a solve returning a pydantic model) run in a worker thread, one solve
        at a time, as a JSON response; a client that gave up while it waited (a newer request
        superseded it) gets 204 and no solve."""
        async with self.solve_lock:
            if await request.is_disconnected():
                return Response(status_code=204)
            result = await run_in_threadpool(work, *args)
        return Response(result.model_dump_json(), media_type="application/json")

    def add(
        self, name: str, pixels: np.ndarray, *, mask=None, suggested=None, pinned=False, photo=None
    ) -> StoredImage:
        entry = StoredImage(new_image_id(), name, pixels, mask, suggested, photo)
        self.images.put(entry.image_id, entry, entry.nbytes, pinned=pinned)
        return entry

    def remember(self, key: str, kind: str, recipe: dict, blobs=()) -> None:
        """Keep how to make entry ``key`` again (a no-op without a session store). A store that
        cannot be written (a full disk) only costs the entry its life after a restart."""
        if self.sessions is None:
            return
        try:
            self.sessions.put(key, kind, recipe, blobs)
        except sqlite3.Error as err:
            logger.warning("could not keep %s in the session store %s: %s", key, self.sessions.path, err)

    def recall(self, key: str):
        """The entry ``key`` from memory, else made again from the session store and kept in
        memory; None if neither has it (or it can no longer be made: a lowered limit)."""
        entry = self.images.get(key)
        if entry is not None or self.sessions is None:
            return entry
        try:
            found = self.sessions.get(key)
        except sqlite3.Error:
            return None
        if found is None or found[0] not in self.rebuilders:
            return None
        kind, recipe, blobs = found
        try:
            entry = self.rebuilders[kind](key, recipe, blobs)
        except (InputError, HTTPException):
            return None
        self.images.put(key, entry, entry.nbytes)
        return entry

    def _rebuild_upload(self, key: str, recipe: dict, blobs: list[bytes]) -> StoredImage:
        pixels, photo, _ = _read_upload(blobs[0], self.limits, recipe["name"], fit=recipe.get("fit", 1) > 1)
        return StoredImage(key, recipe["name"], pixels, photo=photo)

    def _rebuild_example(self, key: str, recipe: dict, blobs: list[bytes]) -> StoredImage:
        from dataclasses import replace

        return replace(self._example_entry(recipe["name"], recipe["size"]), image_id=key)

    def image(self, image_id: str) -> StoredImage:
        entry = self.recall(image_id)
        if not isinstance(entry, StoredImage):
            shown = image_id if len(image_id) <= 40 else image_id[:37] + "..."
            raise HTTPException(
                404,
                f"unknown image id {shown!r}: the server does not have it (it was "
                "restarted or forgot older images); reload the page or open the image again",
            )
        return entry

    def example(self, name: str, size: int | None, *, pinned: bool = False) -> StoredImage:
        from shadeform.examples import EXAMPLES

        if name not in EXAMPLES:
            shown = name if len(name) <= 40 else name[:37] + "..."
            raise HTTPException(404, f"unknown example {shown!r}; choose one of: {', '.join(EXAMPLES)}")
        if size is not None and size * size > self.limits.max_pixels:
            raise HTTPException(
                413,
                f"size {size} gives {size * size:,} pixels, more than the limit of "
                f"{self.limits.max_pixels:,}; choose a smaller size",
            )
        known = self._examples.get((name, size))
        if known is not None and self.images.get(known) is not None:
            return self.images.get(known)
        entry = self._example_entry(name, size)
        self.images.put(entry.image_id, entry, entry.nbytes, pinned=pinned)
        self._examples[(name, size)] = entry.image_id
        self.remember(entry.image_id, "example", {"name": name, "size": size})
        return entry

    def _example_entry(self, name: str, size: int | None) -> StoredImage:
        from shadeform.examples import load_example

        image, info = load_example(name, size=size)
        return StoredImage(new_image_id(), name, image[:, :, None], info["mask"], _suggested(info))


def _read_as(photo) -> dict[str, Any]:
    """How a photo file was read (:attr:`shadeform.io.images.Photo.info`), less the channel:
    the app picks that per request."""
    return {key: value for key, value in photo.info.items() if not key.startswith("channel")}


def _shown(entry: StoredImage, image: np.ndarray) -> np.ndarray:
    """Values to show for a stored photo, as a viewer shows it (what is solved on stays linear)."""
    return shown_photo(image, None if entry.photo is None else entry.photo["encoding"])


def _store_initial(state: _State, source: str | Path) -> StoredImage:
    """The image given on the command line: a file (a Path) or an example name (a str)."""
    if isinstance(source, Path):
        from shadeform.io.images import read_photo

        photo = read_photo(source, max_pixels=state.limits.max_pixels)
        entry = state.add(display_name(source.name), photo.pixels, pinned=True, photo=_read_as(photo))
        state.remember(entry.image_id, "upload", {"name": entry.name}, [source.read_bytes()])
        return entry
    try:
        return state.example(source, None, pinned=True)
    except HTTPException as err:
        raise InputError(err.detail) from None


def _read_upload(data: bytes, limits: AppLimits, name: str, *, fit: bool) -> tuple[np.ndarray, dict, int]:
    """An upload's pixels, how it was read, and the block side it was downsampled by (1: not).

    A photo over ``max_pixels`` is refused (413) with the offer in the app's words and in
    headers (``X-Shadeform-Fit``: the block side, or ``none`` beyond :data:`FIT_FACTOR` times the
    limit; ``X-Shadeform-Size``: its ``WxH``); with ``fit`` it is decoded and downsampled to fit.
    """
    from shadeform.io.images import ImageTooLargeError, naming, read_photo

    try:
        # 8-bit uploads are sRGB and are made linear; 16-bit and float ones are linear
        photo = read_photo(data, max_pixels=limits.max_pixels * (FIT_FACTOR if fit else 1))
    except ImageTooLargeError as err:
        size = _declared_size(data, err)
        if size is None:
            raise HTTPException(413, naming(str(err), name)) from None
        width, height = size
        factor = fit_factor(width, height, limits.max_pixels)

        def mpx(pixels: int) -> str:
            return f" ({pixels / 1e6:.1f} Mpx)" if pixels >= 1e6 else ""

        tiled = TILED_COMMAND.replace("PHOTO", name if name.isprintable() and " " not in name else "PHOTO")
        what = (
            f"{name} is too large for the app: {width}x{height} = {width * height:,} pixels"
            f"{mpx(width * height)}, more than its limit of {limits.max_pixels:,}{mpx(limits.max_pixels)}"
        )
        if factor is None:
            detail = (
                f"{what}, and more than {FIT_FACTOR} times it: reconstruct it with `{tiled}` on the command "
                "line (it works in tiles)"
            )
        else:
            detail = (
                f"{what}; open it downsampled to {-(-width // factor)}x{-(-height // factor)}, or reconstruct "
                f"it at full resolution with `{tiled}` on the command line"
            )
        headers = {
            "X-Shadeform-Fit": "none" if factor is None else str(factor),
            "X-Shadeform-Size": f"{width}x{height}",
        }
        raise HTTPException(413, detail, headers=headers) from None
    except InputError as err:  # named as the user's file, not as bytes
        raise HTTPException(415, naming(str(err), name)) from None
    pixels = photo.pixels
    height, width = pixels.shape[:2]
    factor = fit_factor(width, height, limits.max_pixels) if fit else 1
    if factor is None:  # pragma: no cover - read_photo refused it above
        raise HTTPException(413, f"{name} is too large to downsample here")
    if factor > 1:
        pixels = downsample(pixels, factor)
    return pixels, {**_read_as(photo), **({"downsampled": factor} if factor > 1 else {})}, factor


def _declared_size(data: bytes, err: Exception) -> tuple[int, int] | None:
    """The width and height a file's header declares (the loader's refusal names them; else
    Pillow reads the header), or None."""
    import io
    import re

    from PIL import Image

    declared = re.search(rb"declares (\d+)x(\d+) = ", str(err).encode())
    if declared:
        return int(declared[1]), int(declared[2])
    try:
        with Image.open(io.BytesIO(data)) as image:
            return image.size
    except Exception:  # not a format Pillow reads, or damaged: the loader's message stays
        return None


def _lifespan(warm: bool, state: _State):
    from contextlib import asynccontextmanager

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        if warm:
            threading.Thread(target=warm_up, name="shadeform-warm-up", daemon=True).start()
        try:
            with warnings_logged():  # libraries' warnings kept off the console
                yield
        finally:
            state.jobs.close()

    return lifespan


def warm_up() -> None:
    """Run every method and integrator once on a tiny scene: compiles (or loads) numba kernels."""
    from shadeform import reconstruct, synth, to_mesh
    from shadeform.integration import available_integrators
    from shadeform.solvers import available_methods

    scene = synth.scene("sphere", size=24)
    # float32: what uploads are (the kernels are specialised per dtype); float64: the examples
    for image in (scene.image.astype(np.float32), scene.image):
        for method in available_methods():
            for integrator in (None, *available_integrators()):
                to_mesh(reconstruct(image, mask=scene.mask, method=method, integrator=integrator), step=2)
    # a shape with areas the photo cannot settle: the confidence's outlines (their first use took 1 s)
    vase = synth.scene("vase", size=64)
    reconstruct(vase.image.astype(np.float32), mask=vase.mask)


# --- the work ----------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Solved:
    """A cached reconstruction with what every response about it repeats."""

    reconstruction: Any
    mask_png: str
    depth_range: tuple[float, float]
    #: the block side of the pyramid level it was solved on (1: the photo itself)
    level: int = 1


def _solve(
    state: _State, entry: StoredImage, params: ReconstructParams, *, preview: bool = False
) -> tuple[_Solved, bool]:
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
    image, mask, mask_png = _channel(state, entry, params.channel)
    if params.mask is not None:  # the user's mask
        mask, mask_png = user_mask(state, params.mask, image.shape)
    settings["mask"] = mask
    light = settings["light"]
    spacing = preview_step(mask, params.step, method=params.method, light=light) if preview else 1
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
    solved = _Solved(rec, mask_png, (float(np.nanmin(depth)), float(np.nanmax(depth))))
    nbytes = rec.normals.nbytes + rec.depth.nbytes + rec.mask.nbytes
    state.results.put(key, solved, nbytes)
    return solved, False


def _full_key(entry: StoredImage, params: ReconstructParams) -> tuple:
    """The cache key of a full-resolution reconstruction (``step`` only re-meshes it)."""
    return (entry.image_id, params.model_dump_json(exclude={"step"}))


def _settings(params: ReconstructParams, factor: int = 1) -> dict[str, Any]:
    """:func:`shadeform.pipeline.reconstruct`'s options for ``params`` (all but the mask); with
    ``factor`` > 1 for the pyramid level of that block side: filter sizes, references and regions
    in its pixels (a reference is checked against the level's mask by :func:`_level_references`)."""
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
        size = params.filter.size
        # a window radius that is not whole stays as it is: the library says what is wrong with it
        if factor > 1 and (params.filter.kind == "gaussian" or size == round(size)):
            size = size / factor if params.filter.kind == "gaussian" else float(round(size / factor))
        spec = Filter(params.filter.kind, size) if size > 0 else None
    regions = params.concave.model_dump()
    for region in regions["regions"]:
        region["polygon"] = [[x / factor, y / factor] for x, y in region["polygon"]]
    return dict(
        light=light,
        method=params.method,
        filter=spec,
        references=[tuple(ref) for ref in params.references],
        concave=regions if regions["regions"] else None,
        integrator=params.integrator,
        refine=params.refine,
    )


def _solve_level(
    state: _State, entry: StoredImage, params: ReconstructParams, full_key: tuple
) -> tuple[_Solved, bool]:
    """The quick look of a large photo: solved on its pyramid level (:func:`shadeform.app.large.
    level`) at the solver's preview grid there, whatever the photo's size."""
    from shadeform.app.large import level
    from shadeform.coarse import preview_step, reconstruct_preview
    from shadeform.io.images import select_channel

    factor = level_factor(entry.pixels.shape)
    settings = _settings(params, factor)
    known = state.masks.get(("level", entry.image_id, params.channel, factor))
    if known is None:
        from shadeform.masks import find_object

        image, mask = level(select_channel(entry.pixels, params.channel), entry.mask, factor)
        if mask is None:  # found on the level's colours, as the full photo's (_channel)
            mask = find_object(downsample(entry.pixels, factor)).mask
        known = (image, mask)
        state.masks.put(("level", entry.image_id, params.channel, factor), known, known[0].nbytes)
    image, mask = known
    if params.mask is not None:  # the user's mask, at the level
        full, _ = user_mask(state, params.mask, entry.pixels.shape[:2])
        mask = downsample(full.astype(np.float32), factor) >= 0.5
        if not mask.any():  # thinner than a block: the blocks it touches
            mask = downsample(full.astype(np.float32), factor) > 0
    settings["references"] = _level_references(settings["references"], mask, factor)
    spacing = preview_step(mask, 1, method=params.method, light=settings["light"])
    key = (*full_key, "level", factor, spacing)
    if (solved := state.results.get(key)) is not None:
        return solved, True
    rec = reconstruct_preview(image, step=spacing, mask=mask, **settings)
    depth = rec.depth[rec.mask & np.isfinite(rec.depth)] * factor
    solved = _Solved(rec, "", (float(np.min(depth)), float(np.max(depth))), level=factor)
    state.results.put(key, solved, rec.normals.nbytes + rec.depth.nbytes + rec.mask.nbytes)
    return solved, False


def _level_references(references: list, mask: np.ndarray, factor: int) -> list:
    """The user's references ``(row, col[, normal])`` in the level's pixels, on its object (the
    nearest object pixel where a block fell off it)."""
    moved = []
    for ref in references:
        row, col = (
            min(int(ref[0]) // factor, mask.shape[0] - 1),
            min(int(ref[1]) // factor, mask.shape[1] - 1),
        )
        if row < 0 or col < 0:
            moved.append(ref)  # off the image: reconstruct says so
            continue
        if not mask[row, col]:
            rows, cols = np.nonzero(mask)
            nearest = np.argmin((rows - row) ** 2 + (cols - col) ** 2)
            row, col = int(rows[nearest]), int(cols[nearest])
        moved.append((row, col, *ref[2:]))
    return moved


def _channel(state: _State, entry: StoredImage, channel: str) -> tuple[np.ndarray, np.ndarray, str]:
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


def _mask_warning(state: _State, entry: StoredImage) -> str | None:
    """The automatic mask's one-line warning when it is doubtful (kept with it by :func:`_channel`)."""
    known = state.masks.get(("mask", entry.image_id))
    return known[2] if known is not None else None


def _reconstruct_result(state: _State, entry: StoredImage, body: ReconstructRequest) -> ReconstructResult:
    start = time.perf_counter()
    solved, cached = _solve(state, entry, body.params, preview=body.preview)
    return _result(entry, body, solved, cached, start)


def _result(entry: StoredImage, body: ReconstructRequest, solved: _Solved, cached: bool, start: float):
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


def _start_job(state: _State, entry: StoredImage, body: ReconstructRequest):
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
        solved = _Solved(rec, mask_png, (float(np.nanmin(depth)), float(np.nanmax(depth))))
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


def _job(state: _State, job_id: str):
    job = state.jobs.get(job_id)
    if job is None:
        shown = job_id if len(job_id) <= 40 else job_id[:37] + "..."
        raise HTTPException(
            404, f"unknown solve {shown!r}: it ended long ago or the server restarted; solve again"
        )
    return job


def _job_info(job) -> SolveJob:
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


def _export_bytes(state: _State, entry: StoredImage, params: ReconstructParams, suffix: str) -> bytes:
    solved, _ = _solve(state, entry, params)
    return mesh_file(solved.reconstruction, params.step, suffix)


# --- the parameters ----------------------------------------------------------------------------


def _suggested(info: dict[str, Any]) -> dict[str, Any]:
    """An example's settings (:func:`shadeform.examples.load_example`) as ReconstructParams."""
    from shadeform.light import slant_tilt
    from shadeform.preprocess import parse_filter

    light = None if isinstance(info["light"], str) else np.asarray(info["light"], dtype=np.float64)
    if light is None:
        light_params = LightParams(mode=info["light"])
    elif np.allclose(light, (0.0, 0.0, 1.0)):
        light_params = LightParams()
    else:
        slant, tilt = slant_tilt(light)
        light_params = LightParams(mode="slant_tilt", slant=slant, tilt=tilt)
    spec = parse_filter(info["filter"])
    return ReconstructParams(
        filter=FilterParams(kind=spec.kind, size=spec.size),
        light=light_params,
        step=int(info["step"]),
        method=info["method"],
    ).model_dump()


def _image_info(entry: StoredImage) -> ImageInfo:
    height, width, channels = entry.pixels.shape
    suggested = None if entry.suggested is None else ReconstructParams(**entry.suggested)
    return ImageInfo(
        image_id=entry.image_id,
        name=entry.name,
        width=width,
        height=height,
        channels=channels,
        suggested=suggested,
    )


def _options(limits: AppLimits, initial: StoredImage | None) -> Options:
    from shadeform.app.schema import StereoParams
    from shadeform.examples import EXAMPLES, PHOTO_SET_EXAMPLES, VIEW_SET_EXAMPLES
    from shadeform.integration import available_integrators
    from shadeform.io.exporters import available_formats
    from shadeform.io.images import CHANNELS
    from shadeform.photometric import available_methods as stereo_methods
    from shadeform.preprocess import FILTER_KINDS
    from shadeform.solvers import available_methods

    return Options(
        methods=[MethodInfo(name=name, description=text) for name, text in available_methods().items()],
        integrators=[
            MethodInfo(name=name, description=text) for name, text in available_integrators().items()
        ],
        channels=list(CHANNELS),
        filters=list(FILTER_KINDS),
        formats=[FormatInfo(suffix=s, description=d) for s, d in available_formats().items()],
        examples=[ExampleInfo(name=name, title=title) for name, title in EXAMPLES.items()],
        stereo_methods=[MethodInfo(name=name, description=text) for name, text in stereo_methods().items()],
        photo_set_examples=[
            ExampleInfo(name=name, title=title) for name, title in PHOTO_SET_EXAMPLES.items()
        ],
        stereo_defaults=StereoParams(),
        view_set_examples=[ExampleInfo(name=name, title=title) for name, title in VIEW_SET_EXAMPLES.items()],
        limits=Limits(
            max_upload_bytes=limits.max_upload_bytes,
            max_pixels=limits.max_pixels,
            large_pixels=LARGE_PIXELS,
            fit_factor=FIT_FACTOR,
        ),
        defaults=ReconstructParams(),
        initial_image=None if initial is None else _image_info(initial),
    )
