"""What one app holds, and the photos it is given: its session state (:class:`State`: images,
caches, the solve lock, background jobs, the session store), uploads read and checked, the image
given on the command line, and the schema's descriptions of images, examples and options.

Shared by the app's route modules (:mod:`shadeform.app.server` builds one :class:`State` per app
and hands it to each); the solves on it are in :mod:`shadeform.app.solving`.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
from fastapi import Request
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException

from shadeform.app.encoding import display_name
from shadeform.app.guard import AppLimits, check_known, shorten
from shadeform.app.jobs import SolveJobs
from shadeform.app.large import FIT_FACTOR, LARGE_PIXELS, TILED_COMMAND, downsample, fit_factor
from shadeform.app.schema import (
    ExampleInfo,
    FilterParams,
    FormatInfo,
    ImageInfo,
    LightParams,
    Limits,
    MethodInfo,
    OptionInfo,
    Options,
    ReconstructParams,
)
from shadeform.app.sessions import SessionStore
from shadeform.app.store import LRU, StoredImage, new_image_id
from shadeform.errors import InputError

__all__ = ["State", "app_options", "image_info", "read_upload", "store_initial", "suggested_params"]

logger = logging.getLogger(__name__)


class State:
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
        pixels, photo, _ = read_upload(blobs[0], self.limits, recipe["name"], fit=recipe.get("fit", 1) > 1)
        return StoredImage(key, recipe["name"], pixels, photo=photo)

    def _rebuild_example(self, key: str, recipe: dict, blobs: list[bytes]) -> StoredImage:
        from dataclasses import replace

        return replace(self._example_entry(recipe["name"], recipe["size"]), image_id=key)

    def image(self, image_id: str) -> StoredImage:
        return self.recall_kind(
            image_id, StoredImage, "image id", "images", "reload the page or open the image again"
        )

    def recall_kind(self, key: str, kind: type, what: str, forgot: str, advice: str):
        """:meth:`recall` of an entry that must be a ``kind``; else a 404 that says what it is
        (``what``), what the server forgets (``forgot``) and what to do (``advice``)."""
        entry = self.recall(key)
        if not isinstance(entry, kind):
            raise HTTPException(
                404,
                f"unknown {what} {shorten(key)!r}: the server does not have it (it was "
                f"restarted or forgot older {forgot}); {advice}",
            )
        return entry

    def example(self, name: str, size: int | None, *, pinned: bool = False) -> StoredImage:
        from shadeform.examples import EXAMPLES

        check_known(name, EXAMPLES, "example")
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
        return StoredImage(new_image_id(), name, image[:, :, None], info["mask"], suggested_params(info))


def _read_as(photo) -> dict[str, Any]:
    """How a photo file was read (:attr:`shadeform.io.images.Photo.info`), less the channel:
    the app picks that per request."""
    return {key: value for key, value in photo.info.items() if not key.startswith("channel")}


def store_initial(state: State, source: str | Path) -> StoredImage:
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


def read_upload(data: bytes, limits: AppLimits, name: str, *, fit: bool) -> tuple[np.ndarray, dict, int]:
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


# --- the parameters ----------------------------------------------------------------------------


def suggested_params(info: dict[str, Any]) -> dict[str, Any]:
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
        solver=info["solver"],
    ).model_dump()


def image_info(entry: StoredImage) -> ImageInfo:
    """A stored image as the client's :class:`~shadeform.app.schema.ImageInfo`."""
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


def method_infos(registry) -> list[MethodInfo]:
    """Every entry of a :class:`shadeform.registry.Registry` with its options, in registration order."""
    return [
        MethodInfo(
            name=name,
            description=text,
            options=[OptionInfo(**option.describe()) for option in registry.options(name)],
        )
        for name, text in registry.descriptions().items()
    ]


def app_options(limits: AppLimits, initial: StoredImage | None) -> Options:
    """What ``/api/options`` lists: solvers, integrators, formats, examples, limits, defaults."""
    from shadeform.app.schema import StereoParams
    from shadeform.examples import EXAMPLES, PHOTO_SET_EXAMPLES, VIEW_SET_EXAMPLES
    from shadeform.integration import INTEGRATORS
    from shadeform.io.exporters import available_formats
    from shadeform.io.images import CHANNELS
    from shadeform.photometric import STEREO_MODELS
    from shadeform.preprocess import FILTER_KINDS
    from shadeform.solvers import AUTO, SOLVERS, available_solvers

    return Options(
        solvers=[MethodInfo(name=AUTO, description=available_solvers()[AUTO]), *method_infos(SOLVERS)],
        integrators=method_infos(INTEGRATORS),
        channels=list(CHANNELS),
        filters=list(FILTER_KINDS),
        formats=[FormatInfo(suffix=s, description=d) for s, d in available_formats().items()],
        examples=[ExampleInfo(name=name, title=title) for name, title in EXAMPLES.items()],
        stereo_models=method_infos(STEREO_MODELS),
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
        initial_image=None if initial is None else image_info(initial),
    )
