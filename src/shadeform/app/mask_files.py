"""The masks clients send, read and checked: the user's mask that every solve and export uses
(``ReconstructParams.mask``, base64 of an image file, decoded once per mask and kept), and a mask
file (the mask route's, a photo set's). Used by :mod:`shadeform.app.masks` (the mask routes),
:mod:`shadeform.app.solving` and :mod:`shadeform.app.stereo`.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
from typing import Any

import numpy as np

from shadeform.app.encoding import png_base64
from shadeform.errors import InputError

__all__ = ["decode_mask", "mask_from_file", "user_mask"]


def user_mask(state: Any, text: str, shape: tuple[int, ...]) -> tuple[np.ndarray, str]:
    """The user's mask (``ReconstructParams.mask``) for a solve, checked, and as the app's PNG.

    Parameters
    ----------
    state : shadeform.app.state.State
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
        mask = decode_mask(text, shape, state.limits.max_pixels)
        known = (mask, png_base64(mask.astype(np.float32)))
        state.masks.put(key, known, mask.nbytes)
    mask, png = known
    _check_shape(mask, shape)
    return mask, png


def decode_mask(text: str, shape: tuple[int, ...], max_pixels: int) -> np.ndarray:
    """A mask a client sent as base64 of an image file, read by :func:`mask_from_file`.

    Raises
    ------
    InputError
        If the text is not base64, or as :func:`mask_from_file`.
    """
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


def _check_shape(mask: np.ndarray, shape: tuple[int, ...]) -> None:
    height, width = (int(n) for n in tuple(shape)[:2])
    if mask.shape != (height, width):
        raise InputError(
            f"mask is {mask.shape[1]}x{mask.shape[0]} but the image is {width}x{height} "
            "(width x height); give a mask of the image's size"
        )
