"""The app's HTTP server: a thin FastAPI shell over the library, and the built web client.

Every endpoint is input checking, a library call and encoding; no algorithm lives here. The API
(all under ``/api``, JSON unless said; types in :mod:`shadeform.app.schema`):

==========================================  ===================================================
``/api/options``, ``/api/images``,          the options, opening a photo, the photo and one
``/api/examples``                           channel as PNGs: :mod:`shadeform.app.images`
``/api/reconstruct``, ``/api/solves``,      one photo's model, its full solve in the background
``/api/export``                             (large photos), its file: :mod:`shadeform.app.reconstruct`
``POST /api/images/{id}/mask/...``          masks: :mod:`shadeform.app.masks`
``/api/photosets``, ``/api/stereo``         photo sets: :mod:`shadeform.app.stereo`
``/api/fuse``, ``/api/viewsets``            several views fused: :mod:`shadeform.app.fusion`
``/api/projects``                           the users' projects: :mod:`shadeform.app.projects`
``/api/relief``, ``/api/maps``              prints and texture maps: :mod:`shadeform.app.printing`
==========================================  ===================================================

Each module named lists its routes in full. The routes live in modules by concern, over one
:class:`shadeform.app.state.State` per app and the solves of :mod:`shadeform.app.solving`; this
module builds the app and adds them in order.

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

import threading
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from fastapi import FastAPI, Request
from fastapi.responses import FileResponse, HTMLResponse, Response
from fastapi.routing import APIRoute
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException

from shadeform.app.fusion import add_fusion_routes
from shadeform.app.guard import ERROR_RESPONSES, AppLimits, Guard, add_error_handlers
from shadeform.app.images import add_image_routes
from shadeform.app.masks import add_mask_routes
from shadeform.app.printing import add_print_routes
from shadeform.app.projects import add_project_routes
from shadeform.app.quiet import warnings_logged
from shadeform.app.reconstruct import add_reconstruct_routes
from shadeform.app.sessions import SessionStore
from shadeform.app.state import State, store_initial
from shadeform.app.stereo import add_stereo_routes

__all__ = ["AppLimits", "LOOPBACK_HOSTS", "STATIC_DIR", "create_app", "warm_up"]

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
    state = State(
        limits, None if sessions is None else SessionStore(sessions, max_bytes=limits.max_stored_bytes)
    )
    initial = store_initial(state, initial_image) if initial_image is not None else None

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
    # in this order: the API's routes first, the catch-all for the client's files last
    add_image_routes(app, state, initial)
    add_reconstruct_routes(app, state)
    add_mask_routes(app, state)
    add_stereo_routes(app, state)
    add_fusion_routes(app, state)
    add_project_routes(app, state)
    add_print_routes(app, state)
    _add_client_routes(app, static_dir)
    return app


def _add_client_routes(app: FastAPI, static_dir: Path) -> None:
    """The built client's page and files, and the catch-all that tells an unknown API path (404)
    from a wrong method on a known one (405); added after every API route."""

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


def _lifespan(warm: bool, state: State):
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
    """Run every solver and integrator once on a tiny scene: compiles (or loads) numba kernels."""
    from shadeform import reconstruct, synth, to_mesh
    from shadeform.integration import available_integrators
    from shadeform.solvers import available_solvers

    scene = synth.scene("sphere", size=24)
    # float32: what uploads are (the kernels are specialised per dtype); float64: the examples
    for image in (scene.image.astype(np.float32), scene.image):
        for solver in available_solvers():
            for integrator in (None, *available_integrators()):
                to_mesh(reconstruct(image, mask=scene.mask, solver=solver, integrator=integrator), step=2)
    # a shape with areas the photo cannot settle: the confidence's outlines (their first use took 1 s)
    vase = synth.scene("vase", size=64)
    reconstruct(vase.image.astype(np.float32), mask=vase.mask)
