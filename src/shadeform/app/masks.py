"""The app's mask routes: the automatic mask or a threshold's, the object under clicks, a loaded
mask file checked; and the user's mask that every solve and export then uses.

==============================================  =================================================
``POST /api/images/{id}/mask/auto``             ``AutoMaskRequest`` -> ``MaskResult``
``POST /api/images/{id}/mask/seeds``            ``SeedMaskRequest`` -> ``MaskResult``
``POST /api/images/{id}/mask/box``              ``BoxMaskRequest`` -> ``MaskResult``
``POST /api/images/{id}/mask/file``             ``MaskFileRequest`` -> ``MaskResult``
==============================================  =================================================

A mask travels as base64 of a PNG, 255 (any non-zero value) on the object, the image's size: in
every :class:`~shadeform.app.schema.MaskResult` (with its confidence, and a doubtful mask's
warning in its note), and from the client in
``ReconstructParams.mask``, which :func:`~shadeform.app.mask_files.user_mask` reads for the solve
(decoded once per mask and kept). Brush, polygon, invert and fill holes are edits the client makes on its own copy.
Errors are the library's one-line :class:`~shadeform.InputError` messages (422): a mask of
another size, an empty one, a file that is not an image.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import APIRouter, FastAPI
from fastapi.responses import Response

from shadeform.app.encoding import png_base64
from shadeform.app.guard import ERROR_RESPONSES
from shadeform.app.mask_files import decode_mask, mask_from_file, user_mask
from shadeform.app.schema import AutoMaskRequest, BoxMaskRequest, MaskFileRequest, MaskResult, SeedMaskRequest
from shadeform.app.solving import channel_of

__all__ = ["add_mask_routes", "mask_from_file", "user_mask"]


def add_mask_routes(app: FastAPI, state: Any) -> None:
    """Add the mask endpoints to an app (before its catch-all route for the client's files, so
    that they are its own routes: a wrong method on one is then a 405, not a 404).

    Parameters
    ----------
    app : fastapi.FastAPI
        The app :func:`shadeform.app.server.create_app` builds.
    state : shadeform.app.state.State
        The app's store: its images (``state.image(id)``), limits and mask cache.
    """
    router = APIRouter(prefix="/api/images/{image_id}/mask", responses=ERROR_RESPONSES)

    @router.post("/auto", response_model=MaskResult)
    def post_auto(image_id: str, body: AutoMaskRequest) -> Response:
        from shadeform.masks import find_object, threshold_object

        entry = state.image(image_id)
        image, automatic, _ = channel_of(state, entry, body.channel)
        if body.threshold is not None:
            dark = bool(body.dark)
            mask = threshold_object(image, body.threshold, dark=dark)
            side = "below" if dark else "above"
            note = f"pixels {side} {body.threshold:.4g}, the largest part, holes filled"
            return _result(mask, threshold=body.threshold, dark=dark, note=note)
        if entry.mask is not None and body.dark is None:
            return _result(automatic, threshold=None, dark=False, note="the example's true mask")
        found = find_object(entry.pixels if body.dark is None else image, dark=body.dark)  # colours
        note = found.note if found.warning is None else f"{found.note}; {found.warning}"
        return _result(
            found.mask, threshold=found.threshold, dark=found.dark, note=note, confidence=found.confidence
        )

    @router.post("/seeds", response_model=MaskResult)
    def post_seeds(image_id: str, body: SeedMaskRequest) -> Response:
        from shadeform.masks import segment_from_seeds

        entry = state.image(image_id)
        image, _, _ = channel_of(state, entry, body.channel)
        mask, confidence = segment_from_seeds(  # cut on the photo's colours
            entry.pixels, body.inside, body.outside, radius=body.radius, return_confidence=True
        )
        inside, outside = len(body.inside), len(body.outside)
        note = f"grown from {inside} click{'s' * (inside != 1)} on the object"
        if outside:
            note += f" and {outside} on the background"
        return _result(mask, threshold=None, dark=_darker(image, mask), note=note, confidence=confidence)

    @router.post("/box", response_model=MaskResult)
    def post_box(image_id: str, body: BoxMaskRequest) -> Response:
        from shadeform.masks import segment_from_box

        entry = state.image(image_id)
        image, _, _ = channel_of(state, entry, body.channel)
        mask, confidence = segment_from_box(entry.pixels, body.box, return_confidence=True)
        note = "found inside the box drawn round the object"
        return _result(mask, threshold=None, dark=_darker(image, mask), note=note, confidence=confidence)

    @router.post("/file", response_model=MaskResult)
    def post_file(image_id: str, body: MaskFileRequest) -> Response:
        entry = state.image(image_id)
        mask = decode_mask(body.data, entry.pixels.shape[:2], state.limits.max_pixels)
        return _result(mask, threshold=None, dark=False, note="loaded from a file")

    # the app's own routes (FastAPI's include_router would nest them out of the 405 check)
    for route in router.routes:
        app.router.routes.append(route)


def _darker(image: np.ndarray, mask: np.ndarray) -> bool:
    """Whether the object is darker than the rest of the image (by their medians)."""
    return bool(mask.any() and (~mask).any() and np.median(image[mask]) < np.median(image[~mask]))


def _result(
    mask: np.ndarray, *, threshold: float | None, dark: bool, note: str, confidence: float | None = None
) -> Response:
    from shadeform.masks import LOW_CONFIDENCE

    if confidence is not None and confidence < LOW_CONFIDENCE and "doubtful" not in note:
        note += f"; doubtful (confidence {confidence:.2f}): check the mask, or add clicks"
    result = MaskResult(
        mask_png=png_base64(mask.astype(np.float32)),
        pixels=int(np.count_nonzero(mask)),
        threshold=None if threshold is None else float(threshold),
        dark=bool(dark),
        note=note,
        confidence=None if confidence is None else float(confidence),
    )
    return Response(result.model_dump_json(), media_type="application/json")
