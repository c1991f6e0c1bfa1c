"""The app's photo-set routes: several photos of one still object under moving lights, solved by
photometric stereo, with the maps a relighting viewer needs.

==============================================  =================================================
``POST /api/photosets`` (multipart)             ``photos`` (three or more), optional ``lights``
                                                (the project's file or an RTI ``.lp``),
                                                ``intensities`` and ``mask`` -> ``PhotoSetInfo``
``POST /api/photosets/examples/{name}``         a shipped photo set -> ``PhotoSetInfo``
``GET  /api/photosets/{id}/photos/{i}.png``     photo ``i`` (0-based), 8-bit PNG
``POST /api/stereo``                            ``StereoRequest`` -> ``StereoResult``
``POST /api/stereo/export?format=.glb``         ``StereoRequest`` -> the mesh file
==============================================  =================================================

As for one photo, every endpoint is input checking, a library call
(:func:`shadeform.photometric.reconstruct_stereo`, :func:`shadeform.calibrate_lights`) and
encoding. Uploads are decoded from memory (the light files as text); nothing a client sends is
written to disk. The normals travel as an 8-bit RGB PNG of ``(n + 1) / 2`` and the albedo as an
sRGB-encoded 8-bit PNG: enough for the client to relight the object at any light it is given
(``albedo * max(0, n . l)``), at a quarter of a degree and a 255th of the albedo's range.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from fastapi import APIRouter, FastAPI, File, Query, Request, UploadFile
from fastapi.responses import Response
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
    set_stem,
    shown_photo,
)
from shadeform.app.guard import check_known, size_text
from shadeform.app.mask_files import mask_from_file
from shadeform.app.schema import PhotoSetInfo, StereoParams, StereoRequest, StereoResult
from shadeform.app.store import new_image_id
from shadeform.errors import InputError

__all__ = ["StoredPhotoSet", "add_stereo_routes", "photoset", "solve_set"]

#: Most photos in one set (DiLiGenT has 96; RTI domes 50 to 100).
MAX_PHOTOS = 256


@dataclass(frozen=True, eq=False)
class StoredPhotoSet:
    """A photo set the client opened.

    Attributes
    ----------
    photoset_id, name : str
        The client's name for it, and what to show.
    images : (N, H, W, 3) float32
        The photos, linear.
    names : tuple of str
        The photos' file names.
    lights, intensities : (N, 3) and (N,) or (N, 3) float64, or None
        From the files that came with the photos.
    mask : (H, W) bool or None
        The mask that came with them.
    encoding : {"srgb", "linear"}
        How the files held their values.
    stem : str
        Its downloads' file stem (:func:`shadeform.app.encoding.set_stem`); ``name`` where empty.
    """

    photoset_id: str
    name: str
    images: np.ndarray
    names: tuple[str, ...]
    lights: np.ndarray | None = None
    intensities: np.ndarray | None = None
    mask: np.ndarray | None = None
    encoding: str = "linear"
    stem: str = ""

    @property
    def nbytes(self) -> int:
        return self.images.nbytes


@dataclass(frozen=True, eq=False)
class _SolvedSet:
    """A cached photometric stereo result with what every response about it repeats."""

    reconstruction: Any
    maps: dict[str, Any]


def add_stereo_routes(app: FastAPI, state: Any) -> None:
    """Add the photo-set endpoints to an app (before its catch-all route).

    Parameters
    ----------
    app : fastapi.FastAPI
        The app :func:`shadeform.app.server.create_app` builds.
    state : shadeform.app.state.State
        The app's store: it keeps photo sets beside images, and their results.
    """
    router = APIRouter()
    state.rebuilders["photoset"] = lambda key, recipe, blobs: _replace(_reread_set(state, recipe, blobs), key)
    state.rebuilders["photoset-example"] = lambda key, recipe, blobs: _example_set(key, recipe["name"])

    @router.post("/api/photosets", response_model=PhotoSetInfo, status_code=201)
    def post_photoset(
        photos: list[UploadFile] = File(..., description="Three or more photos, in order."),
        lights: UploadFile | None = File(
            None, description="Light file: x y z per photo, or an RTI .lp file."
        ),
        intensities: UploadFile | None = File(
            None, description="Each light's strength: one number or R G B per photo."
        ),
        mask: UploadFile | None = File(None, description="The object's mask, the photos' size."),
    ) -> Response:
        files = [photos, lights, intensities, mask]
        kept = _contents(photos), *(None if f is None else _contents([f])[0] for f in files[1:])
        entry = _read_set(state, photos, lights, intensities, mask)
        state.images.put(entry.photoset_id, entry, entry.nbytes)
        recipe = {
            "photos": [photo.filename for photo in photos],
            **{name: None if f is None else f.filename for name, f in zip(_EXTRAS, files[1:])},
        }
        blobs = [*kept[0], *(blob for blob in kept[1:] if blob is not None)]
        state.remember(entry.photoset_id, "photoset", recipe, blobs)
        return json_response(_info(entry), status_code=201)

    @router.post("/api/photosets/examples/{name}", response_model=PhotoSetInfo, status_code=201)
    def post_photoset_example(name: str) -> Response:
        from shadeform.examples import PHOTO_SET_EXAMPLES

        check_known(name, PHOTO_SET_EXAMPLES, "photo set")
        entry = _example_set(new_image_id(), name)
        state.images.put(entry.photoset_id, entry, entry.nbytes)
        state.remember(entry.photoset_id, "photoset-example", {"name": name})
        return json_response(_info(entry), status_code=201)

    @router.get(
        "/api/photosets/{photoset_id}/photos/{index}.png", response_class=Response, responses=PNG_RESPONSES
    )
    def get_photoset_photo(photoset_id: str, index: int) -> Response:
        entry = photoset(state, photoset_id)
        if not 0 <= index < len(entry.images):
            raise HTTPException(
                404, f"photo {index} is not in this set: it has photos 0 to {len(entry.images) - 1}"
            )
        photo = shown_photo(entry.images[index], entry.encoding)
        return Response(png(photo), media_type="image/png", headers={"Cache-Control": "no-cache"})

    @router.post("/api/stereo", response_model=StereoResult)
    async def post_stereo(body: StereoRequest, request: Request) -> Response:
        return await state.solve_json(request, _result, state, photoset(state, body.photoset_id), body)

    @router.post("/api/stereo/export", response_class=Response, responses=FILE_RESPONSES)
    async def post_stereo_export(
        body: StereoRequest,
        format: str = Query(..., description="A suffix from Options.formats, e.g. .glb."),
    ) -> Response:
        from shadeform.io.exporters import available_formats

        suffix = format_suffix(format, available_formats())
        entry = photoset(state, body.photoset_id)
        async with state.solve_lock:
            solved, _ = await run_in_threadpool(solve_set, state, entry, body.params)
            data = await run_in_threadpool(mesh_file, solved.reconstruction, body.params.step, suffix)
        return download(data, entry.stem or entry.name, suffix)

    app.include_router(router)


# --- reading -----------------------------------------------------------------------------------


def _read_set(state, photos, lights, intensities, mask) -> StoredPhotoSet:
    """The uploads as a :class:`StoredPhotoSet`; every failure a one-line 4xx."""
    from shadeform.io.images import ImageTooLargeError
    from shadeform.photoset import match_lp, parse_lp, parse_rows, read_photos

    limits = state.limits
    if not 3 <= len(photos) <= MAX_PHOTOS:
        raise HTTPException(
            422, f"photometric stereo needs 3 to {MAX_PHOTOS} photos of one still object, got {len(photos)}"
        )
    names = tuple(display_name(photo.filename) for photo in photos)
    contents = [photo.file.read() for photo in photos]
    for name, data in zip(names, contents):
        if not data:
            raise HTTPException(400, f"photo {name} is empty (0 bytes); choose image files")
    try:
        # the whole set must fit in memory: each photo may have its share of it, checked from
        # the files' headers before anything is decoded
        share = max(1, limits.max_image_bytes // (len(contents) * 3 * 4))
        per_photo = min(limits.max_pixels, share)
        directions = strengths = object_mask = None
        if intensities is not None:
            label = display_name(intensities.filename)
            text = _text(intensities, label, "intensities")
            strengths = parse_rows(text, "intensities", label, len(names), (1, 3))
        # light strengths divide only linear values: a set that has them is radiometrically
        # calibrated whatever its bit depth (as for a folder, shadeform.photoset)
        linear = True if strengths is not None else None
        try:
            images, _, encoding, _, _ = read_photos(
                contents, linear=linear, names=names, max_pixels=per_photo
            )
        except ImageTooLargeError:
            if per_photo == limits.max_pixels:
                raise
            raise HTTPException(
                413,
                f"{len(contents)} photos this large need more than the {size_text(limits.max_image_bytes)} "
                f"this server keeps (at most {per_photo:,} pixels each); open fewer or smaller photos",
            ) from None
        height, width = images.shape[1:3]
        if lights is not None:
            label = display_name(lights.filename)
            text = _text(lights, label, "light")
            if label.lower().endswith(".lp"):
                directions = match_lp(names, *parse_lp(text, label), label)
            else:
                directions = parse_rows(text, "lights", label, len(names), (3,))
        if mask is not None:
            # the server's pixel limit, checked from the header (load_mask's own is far larger)
            data = mask.file.read(limits.max_upload_bytes + 1)
            object_mask = mask_from_file(data, (height, width), limits.max_pixels)
    except ImageTooLargeError as err:
        raise HTTPException(413, str(err)) from None
    except InputError as err:
        raise HTTPException(422, str(err)) from None
    return StoredPhotoSet(
        new_image_id(),
        f"{names[0]} … {names[-1]}",
        images,
        names,
        directions,
        strengths,
        object_mask,
        encoding,
        set_stem([photo.filename for photo in photos]),
    )


def _text(upload: UploadFile, label: str, what: str) -> str:
    data = upload.file.read(1 << 20)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise HTTPException(422, f"{what} file {label} is not text; give a text file of numbers") from None


#: The optional files of a photo set's upload, in the order they are remembered.
_EXTRAS = ("lights", "intensities", "mask")


def _contents(uploads) -> list[bytes]:
    """The bytes of uploaded files, each left rewound for its reader."""
    out = []
    for upload in uploads:
        out.append(upload.file.read())
        upload.file.seek(0)
    return out


def _reread_set(state, recipe: dict, blobs: list[bytes]) -> StoredPhotoSet:
    """A photo set's upload read again from the remembered files (with today's limits)."""
    from io import BytesIO

    from starlette.datastructures import UploadFile as Upload

    count = len(recipe["photos"])
    photos = [Upload(BytesIO(blob), filename=name) for name, blob in zip(recipe["photos"], blobs)]
    rest = iter(blobs[count:])
    extras = [
        None if recipe[name] is None else Upload(BytesIO(next(rest)), filename=recipe[name])
        for name in _EXTRAS
    ]
    return _read_set(state, photos, *extras)


def _example_set(key: str, name: str) -> StoredPhotoSet:
    from shadeform.examples import load_photo_set_example

    images, directions, object_mask = load_photo_set_example(name)
    names = tuple(f"{name.split(':')[-1]}-{i + 1:02d}.png" for i in range(len(images)))
    return StoredPhotoSet(key, name, images, names, directions, None, object_mask)


def _replace(entry: StoredPhotoSet, key: str) -> StoredPhotoSet:
    from dataclasses import replace

    return replace(entry, photoset_id=key)


def photoset(state, photoset_id: str) -> StoredPhotoSet:
    return state.recall_kind(photoset_id, StoredPhotoSet, "photo set", "sets", "open the photos again")


def _info(entry: StoredPhotoSet) -> PhotoSetInfo:
    count, height, width, _ = entry.images.shape
    colour = bool(np.any(entry.images[..., 0] != entry.images[..., 1]))
    lights = "file" if entry.lights is not None else "unknown"
    return PhotoSetInfo(
        photoset_id=entry.photoset_id,
        name=entry.name,
        count=count,
        width=width,
        height=height,
        colour=colour,
        names=list(entry.names),
        lights_file=entry.lights is not None,
        intensities_file=entry.intensities is not None,
        mask=entry.mask is not None,
        suggested=StereoParams(lights=lights),
    )


# --- solving -----------------------------------------------------------------------------------


def solve_set(state, entry: StoredPhotoSet, params: StereoParams) -> tuple[_SolvedSet, bool]:
    """The photometric stereo result for these parameters, from the cache when only ``step``
    changed."""
    from shadeform.integration import available_integrators
    from shadeform.photometric import STEREO_MODELS, reconstruct_stereo

    key = (entry.photoset_id, params.model_dump_json(exclude={"step"}))
    solved = state.results.get(key)
    if solved is not None:
        return solved, True
    if params.model not in STEREO_MODELS:
        raise InputError(
            f"unknown photometric stereo model {params.model!r}; choose one of: "
            f"{', '.join(STEREO_MODELS.names())}"
        )
    if params.integrator not in available_integrators():
        raise InputError(
            f"unknown integrator {params.integrator!r}; choose one of: {', '.join(available_integrators())}"
        )
    lights, strengths, circle = entry.lights, entry.intensities, None
    if params.lights == "file" and lights is None:
        raise InputError(
            "this photo set came without a light file; choose Sphere or Unknown lights, or open the "
            "photos again with their light file"
        )
    if params.lights == "sphere":
        from shadeform.light.sphere import calibrate_lights

        found = calibrate_lights(entry.images, sphere=params.sphere)
        lights, strengths, circle = found.directions, found.strengths, found.sphere
        behind = np.flatnonzero(lights[:, 2] <= 0)
        if behind.size:
            column, row, radius = circle
            raise InputError(
                f"the circle at column {column:.0f}, row {row:.0f} (radius {radius:.0f}) puts light "
                f"{behind[0] + 1} behind the object: it is probably not a shiny sphere; give the "
                "sphere's circle, or choose another source of lights"
            )
    elif params.lights == "unknown":
        lights = None
    rec = reconstruct_stereo(
        entry.images,
        lights,
        entry.mask,
        intensities=strengths,
        model=params.model,
        integrator=params.integrator,
        sphere=circle,
    )
    solved = _SolvedSet(rec, _maps(rec, circle))
    state.results.put(key, solved, rec.normals.nbytes + rec.depth.nbytes + rec.mask.nbytes)
    return solved, False


def _maps(rec, circle) -> dict[str, Any]:
    """What the client shows and relights with, encoded once per solve."""
    from shadeform.io.images import srgb_encode

    mask = rec.mask
    normals = np.where(mask[..., None], (np.nan_to_num(rec.normals) + 1.0) / 2.0, 0.0)
    albedo = rec.albedo if rec.albedo.ndim == 3 else np.repeat(rec.albedo[..., None], 3, axis=2)
    albedo = np.where(mask[..., None], np.nan_to_num(albedo), 0.0)
    white = float(np.percentile(albedo[mask], 99.5)) if mask.any() else 0.0
    shown = srgb_encode(np.clip(albedo / white if white > 0 else albedo, 0.0, 1.0).astype(np.float32))
    depth = rec.depth[mask]
    return {
        "mask_png": png_base64(mask.astype(np.float32)),
        "normals_png": png_base64(normals),
        "albedo_png": png_base64(shown),
        "albedo_white": white,
        "confidence_png": png_base64(np.nan_to_num(rec.confidence)),
        "lights": [tuple(row) for row in rec.info["light_directions"]],
        "sphere": None if circle is None else tuple(float(v) for v in circle),
        "depth_range": (float(np.nanmin(depth)), float(np.nanmax(depth))),
    }


def _result(state, entry: StoredPhotoSet, body: StereoRequest) -> StereoResult:
    from shadeform import to_mesh

    start = time.perf_counter()
    solved, cached = solve_set(state, entry, body.params)
    rec = solved.reconstruction
    timings = {} if cached else dict(rec.info["timings"])
    lap = time.perf_counter()
    mesh = to_mesh(rec, step=body.params.step)
    timings["mesh"] = time.perf_counter() - lap
    timings["total"] = time.perf_counter() - start
    info = {key: value for key, value in rec.info.items() if key != "light_directions"}
    return StereoResult(
        request_id=body.request_id,
        mesh=mesh_data(mesh),
        photos_dropped=list(rec.info["photos_dropped"]),
        photos_rescaled=[(int(i), float(f)) for i, f in rec.info["photos_rescaled"]],
        light=tuple(float(v) for v in rec.light),
        timings=timings,
        info={**plain(info), "cached": cached},
        **solved.maps,
    )
