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
``ReconstructParams.mask``, which :func:`user_mask` reads for the solve (decoded once per mask
and kept). Brush, polygon, invert and fill holes are edits the client makes on its own copy.
Errors are the library's one-line :class:`~shadeform.InputError` messages (422): a mask of
another size, an empty one, a file that is not an image.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
from typing import Any

import numpy as np
from fastapi import APIRouter, FastAPI
from fastapi.responses import Response

from shadeform.app.encoding import png_base64
from shadeform.app.guard import ERROR_RESPONSES
from shadeform.app.schema import AutoMaskRequest, BoxMaskRequest, MaskFileRequest, MaskResult, SeedMaskRequest
from shadeform.errors import InputError

__all__ = ["add_mask_routes", "mask_from_file", "user_mask"]


def add_mask_routes(app: FastAPI, state: Any) -> None:
    """Add the mask endpoints to an app (before its catch-all route for the client's files, so
    that they are its own routes: a wrong method on one is then a 405, not a 404).

    Parameters
    ----------
    app : fastapi.FastAPI
        The app :func:`shadeform.app.server.create_app` builds.
    state : shadeform.app.server._State
        The app's store: its images (``state.image(id)``), limits and mask cache.
    """
    router = APIRouter(prefix="/api/images/{image_id}/mask", responses=ERROR_RESPONSES)

    @router.post("/auto", response_model=MaskResult)
    def post_auto(image_id: str, body: AutoMaskRequest) -> Response:
        from shadeform.masks import find_object, threshold_object

        entry = state.image(image_id)
        image, automatic, _ = _channel(state, entry, body.channel)
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
        image, _, _ = _channel(state, entry, body.channel)
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
        image, _, _ = _channel(state, entry, body.channel)
        mask, confidence = segment_from_box(entry.pixels, body.box, return_confidence=True)
        note = "found inside the box drawn round the object"
        return _result(mask, threshold=None, dark=_darker(image, mask), note=note, confidence=confidence)

    @router.post("/file", response_model=MaskResult)
    def post_file(image_id: str, body: MaskFileRequest) -> Response:
        entry = state.image(image_id)
        mask = _decode(body.data, entry.pixels.shape[:2], state.limits.max_pixels)
        return _result(mask, threshold=None, dark=False, note="loaded from a file")

    # the app's own routes (FastAPI's include_router would nest them out of the 405 check)
    for route in router.routes:
        app.router.routes.append(route)


def user_mask(state: Any, text: str, shape: tuple[int, ...]) -> tuple[np.ndarray, str]:
    """The user's mask (``ReconstructParams.mask``) for a solve, checked, and as the app's PNG.

    Parameters
    ----------
    state : shadeform.app.server._State
        Holds the decoded masks (``state.masks``), keyed by the text's hash.
    text : str
        base64 of an image file, non-zero = object.
    shape : tuple of int
        The image's ``(H, W)``.

    Returns
    -------
    mask : (H, W) bool
    png : str
        base64 of the mask as an 8-bit grey PNG, 255 on the object.

    Raises
    ------
    InputError
        If the text is not base64 of an image file, or the mask has another size or is empty.
    """
    key = ("user mask", hashlib.sha256(text.encode("ascii", "replace")).hexdigest())
    known = state.masks.get(key)
    if known is None:
        mask = _decode(text, shape, state.limits.max_pixels)
        known = (mask, png_base64(mask.astype(np.float32)))
        state.masks.put(key, known, mask.nbytes)
    mask, png = known
    _check_shape(mask, shape)
    return mask, png


def _channel(state: Any, entry: Any, channel: str) -> tuple[np.ndarray, np.ndarray, str]:
    # the very image and automatic mask a solve uses (the server keeps them per channel)
    from shadeform.app.server import _channel as channel_of

    return channel_of(state, entry, channel)


def _decode(text: str, shape: tuple[int, ...], max_pixels: int) -> np.ndarray:
    try:
        data = base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError):
        raise InputError(
            "mask is not base64 text of an image file; send the file's bytes in base64"
        ) from None
    return mask_from_file(data, shape, max_pixels)


def mask_from_file(data: bytes, shape: tuple[int, ...], max_pixels: int) -> np.ndarray:
    """A mask file a client sent, read from memory and checked.

    Parameters
    ----------
    data : bytes
        The file's content (PNG, TIFF, BMP, ...); non-zero in any channel = object.
    shape : tuple of int
        The image's ``(H, W)``: the mask must have it.
    max_pixels : int
        The server's pixel limit, checked from the file's header before anything is decoded.

    Returns
    -------
    (H, W) bool

    Raises
    ------
    InputError
        If the file is empty or not an image, has another size or no non-zero pixel;
        :class:`~shadeform.io.images.ImageTooLargeError` if its header declares more than
        ``max_pixels``.
    """
    from shadeform.io.images import load_pixels

    if not data:
        raise InputError("mask is an empty file; send a PNG of the image's size")
    try:
        pixels = load_pixels(data, max_pixels=max_pixels)
    except InputError as err:
        raise type(err)(f"mask: {err}") from None
    mask = (pixels > 0).any(axis=2)
    _check_shape(mask, shape)
    if not mask.any():
        raise InputError(
            "mask is empty (no non-zero pixel); paint the object in a non-zero colour, or use the "
            "automatic mask"
        )
    return mask


def _darker(image: np.ndarray, mask: np.ndarray) -> bool:
    """Whether the object is darker than the rest of the image (by their medians)."""
    return bool(mask.any() and (~mask).any() and np.median(image[mask]) < np.median(image[~mask]))


def _check_shape(mask: np.ndarray, shape: tuple[int, ...]) -> None:
    height, width = (int(n) for n in tuple(shape)[:2])
    if mask.shape != (height, width):
        raise InputError(
            f"mask is {mask.shape[1]}x{mask.shape[0]} but the image is {width}x{height} "
            "(width x height); give a mask of the image's size"
        )


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
