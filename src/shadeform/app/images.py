"""The app's routes for one photo's image: the options, opening a photo (an upload or a shipped
example), and the photo and one channel as PNGs to show.

==========================================  ===================================================
``GET  /api/options``                       solvers, integrators, formats, examples, limits
``POST /api/images`` (multipart ``file``)   store an uploaded photo -> ``ImageInfo``
``POST /api/examples/{name}[?size=N]``      store a shipped example -> ``ImageInfo``
``GET  /api/images/{id}/photo.png``         the photo, 8-bit PNG
``GET  /api/images/{id}/channel.png``       one channel, filtered (``?channel=&filter=``)
==========================================  ===================================================

Uploads are read by :func:`shadeform.app.state.read_upload` (a photo over ``max_pixels`` is
refused with an offer, or taken downsampled with ``?fit=true``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import FastAPI, File, Query, UploadFile
from fastapi.responses import Response
from starlette.exceptions import HTTPException

from shadeform.app.encoding import PNG_RESPONSES, display_name, json_response, png, shown_photo
from shadeform.app.guard import file_too_large
from shadeform.app.large import level_factor
from shadeform.app.schema import ImageInfo, Options
from shadeform.app.solving import channel_of
from shadeform.app.state import app_options, image_info, read_upload
from shadeform.app.store import StoredImage

__all__ = ["add_image_routes"]


def add_image_routes(app: FastAPI, state: Any, initial: StoredImage | None) -> None:
    """Add the options and image endpoints to an app (before its catch-all route).

    Parameters
    ----------
    app : fastapi.FastAPI
        The app :func:`shadeform.app.server.create_app` builds.
    state : shadeform.app.state.State
        The app's store: its images, limits, PNG and mask caches.
    initial : StoredImage or None
        The image given on the command line, listed as ``Options.initial_image``.
    """
    limits = state.limits
    options = app_options(limits, initial)

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
        pixels, photo, factor = read_upload(data, limits, name, fit=fit)
        entry = state.add(name, pixels, photo=photo)
        state.remember(entry.image_id, "upload", {"name": entry.name, "fit": factor}, [data])
        if level_factor(pixels.shape) > 1:
            state.jobs.warm()  # its full solve will run there: load the kernels meanwhile
        return json_response(image_info(entry), status_code=201)

    @app.post("/api/examples/{name}", response_model=ImageInfo, status_code=201)
    def post_example(
        name: str, size: int | None = Query(None, description="Side of a synth: example.")
    ) -> Response:
        entry = state.example(name, size)
        return json_response(image_info(entry), status_code=201)

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
        image, mask, _ = channel_of(state, entry, channel)
        if spec.kind != "none":
            image = apply_filter(image, mask, spec)
        return Response(
            png(_shown(entry, image)), media_type="image/png", headers={"Cache-Control": "no-cache"}
        )


def _shown(entry: StoredImage, image: np.ndarray) -> np.ndarray:
    """Values to show for a stored photo, as a viewer shows it (what is solved on stays linear)."""
    return shown_photo(image, None if entry.photo is None else entry.photo["encoding"])
