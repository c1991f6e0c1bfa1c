"""The app's request and response schema, defined once (pydantic) for the server and the client.

The web client's TypeScript types (``web/src/api.gen.ts``) are generated from these models by
:func:`typescript`; ``python -m shadeform.app.schema`` prints that file, and a test checks that the
committed copy is current. Field meanings and conventions (frames, regions JSON) are those of
``docs/conventions.md``; the server only validates types and ranges here and leaves every other
check to the library, whose :class:`shadeform.InputError` messages reach the user unchanged.

Arrays in :class:`MeshData` travel as base64 text of little-endian ``float32`` (positions,
normals, uvs) and ``uint32`` (indices) so that the client can view them as typed arrays without
parsing numbers.
"""

from __future__ import annotations

import json
import sys
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic.json_schema import models_json_schema
from typing_extensions import TypeAliasType

__all__ = [
    "Channel",
    "FilterKind",
    "LightMode",
    "Axis",
    "FilterParams",
    "LightParams",
    "ConcaveRegion",
    "ConcaveRegions",
    "ReconstructParams",
    "ReconstructRequest",
    "FormatInfo",
    "ExampleInfo",
    "Limits",
    "ImageInfo",
    "Options",
    "MeshData",
    "ReconstructResult",
    "SolveJob",
    "StereoLights",
    "StereoParams",
    "StereoRequest",
    "PhotoSetInfo",
    "StereoResult",
    "FuseView",
    "FuseRequest",
    "FusedView",
    "FuseResult",
    "ViewSetInfo",
    "AutoMaskRequest",
    "SeedMaskRequest",
    "BoxMaskRequest",
    "MaskFileRequest",
    "MaskResult",
    "Outline",
    "ReliefParams",
    "ReliefRequest",
    "ReliefResult",
    "MapPreview",
    "MapsResult",
    "ProjectSource",
    "ProjectImage",
    "DisplaySettings",
    "ProjectPhotoSet",
    "ProjectViewEntry",
    "ProjectViews",
    "ProjectDocument",
    "ProjectInfo",
    "ProjectList",
    "Project",
    "ErrorBody",
    "typescript",
]

Channel = TypeAliasType("Channel", Literal["luma", "r", "g", "b", "max"])
FilterKind = TypeAliasType("FilterKind", Literal["none", "gaussian", "mean", "median", "minimum"])
LightMode = TypeAliasType("LightMode", Literal["z", "slant_tilt", "estimate"])
Axis = TypeAliasType("Axis", Literal["x", "y", "both"])
StereoLights = TypeAliasType("StereoLights", Literal["file", "sphere", "unknown"])

# a pixel row or column a client sends: no image is 2**31 pixels wide, and a larger number would
# wrap around in numpy's int64 and be reported as another pixel
_PixelIndex = Annotated[int, Field(ge=-(2**31), lt=2**31)]


class _Model(BaseModel):
    # requests with unknown fields are refused (a typo must not be silently ignored); in the
    # generated types a field with a default is still required: the server always sends it
    model_config = ConfigDict(extra="forbid", json_schema_serialization_defaults_required=True)


class FilterParams(_Model):
    """Smoothing before the solve (:func:`shadeform.preprocess.parse_filter`)."""

    kind: FilterKind = "none"
    size: float = Field(
        default=0.0,
        ge=0,
        description="Gaussian sigma, or the window radius (whole number) of mean, median and minimum.",
    )


class LightParams(_Model):
    """Where the light is: +z, slant/tilt in degrees (``docs/conventions.md``), or estimated."""

    mode: LightMode = "z"
    slant: float = 0.0
    tilt: float = 0.0


class ConcaveRegion(_Model):
    """One concave region: polygon ``[[x, y], ...]`` (x = column, y = row, input pixels)."""

    polygon: list[tuple[float, float]]
    axis: Axis


class ConcaveRegions(_Model):
    """The CLI's regions JSON, exactly: ``{"regions": [...]}``."""

    regions: list[ConcaveRegion] = Field(default_factory=list)


class ReconstructParams(_Model):
    """Everything the user sets for one reconstruction."""

    channel: Channel = "luma"
    filter: FilterParams = Field(default_factory=FilterParams)
    light: LightParams = Field(default_factory=LightParams)
    method: str = Field(
        default="auto", description='One of ``Options.methods``; "auto" is the best measured for the light.'
    )
    integrator: str | None = Field(
        default=None,
        description="One of ``Options.integrators``, or null for the method's own.",
    )
    refine: int = Field(
        default=3,
        ge=0,
        le=100,
        description="Integrability refinement iterations (propagation only).",
    )
    step: int = Field(
        default=2,
        ge=1,
        description="Mesh granularity: pixels per vertex. Changing only this re-meshes without a new solve.",
    )
    references: list[tuple[_PixelIndex, _PixelIndex]] = Field(
        default_factory=list,
        description="Reference pixels ``[row, col]`` chosen by the user; the automatic ones are added.",
    )
    concave: ConcaveRegions = Field(default_factory=ConcaveRegions)
    mask: str | None = Field(
        default=None,
        description="The user's object mask: base64 of an image file (PNG) of the image's size, non-zero "
        "= object (``shadeform.load_mask``'s rule); null for the automatic one. Every solve and export "
        "uses it.",
    )


class ReconstructRequest(_Model):
    """A reconstruction (or export) of a stored image with these parameters."""

    image_id: str
    params: ReconstructParams = Field(default_factory=ReconstructParams)
    request_id: int = Field(
        default=0,
        description="Chosen by the client, echoed in the result: a response older than the newest is stale.",
    )
    preview: bool = Field(
        default=False,
        description="Answer at once with a quick look solved at the mesh's grid (or a coarser one within the "
        "solver's pixel budget), unless the full result is already known or the grid is the "
        "image's own; the result's ``preview`` says which came.",
    )


class MethodInfo(_Model):
    """A solver or integrator the library offers (its registry: :func:`shadeform.solvers.available_methods`,
    :func:`shadeform.integration.available_integrators`)."""

    name: str
    description: str = Field(description="One line in the user's words.")


class FormatInfo(_Model):
    """A mesh format the export endpoint writes (:func:`shadeform.available_formats`)."""

    suffix: str
    description: str


class ExampleInfo(_Model):
    """A shipped example (:data:`shadeform.examples.EXAMPLES`)."""

    name: str
    title: str


class Limits(_Model):
    """What an upload may be."""

    max_upload_bytes: int
    max_pixels: int
    large_pixels: int = Field(
        description="Images with more pixels get their quick look on a downsampled copy and their full "
        "solve in the background (``/api/solves``: progress, cancel).",
    )
    fit_factor: int = Field(
        description="A photo over ``max_pixels`` but at most this many times it may be opened downsampled "
        "to fit (``POST /api/images?fit=true``).",
    )


class ImageInfo(_Model):
    """A stored image; ``image_id`` names it in every later request."""

    image_id: str
    name: str
    width: int
    height: int
    channels: int = Field(description="1 for a gray file, 3 for colour.")
    suggested: ReconstructParams | None = Field(
        default=None,
        description="Settings the image is best reconstructed with (the examples have them), else null.",
    )


class Options(_Model):
    """What the library offers, the upload limits and the default parameters."""

    methods: list[MethodInfo] = Field(description='"auto" first, then every registered solver.')
    integrators: list[MethodInfo]
    channels: list[str]
    filters: list[str]
    formats: list[FormatInfo]
    examples: list[ExampleInfo]
    stereo_methods: list[MethodInfo] = Field(description="Photometric stereo's methods, the default first.")
    photo_set_examples: list[ExampleInfo]
    stereo_defaults: StereoParams
    relief_defaults: ReliefParams = Field(default_factory=lambda: ReliefParams())
    view_set_examples: list[ExampleInfo] = Field(
        description="Shipped view sets: one object photographed from several sides, to fuse."
    )
    limits: Limits
    defaults: ReconstructParams
    initial_image: ImageInfo | None = Field(
        default=None,
        description="The image the server was started with (``shadeform app IMAGE``), else null.",
    )


class MeshData(_Model):
    """A triangle mesh in the convention of ``docs/conventions.md`` ("Meshes"), as base64."""

    vertex_count: int
    triangle_count: int
    positions: str = Field(
        description="float32 little-endian, 3 per vertex: (x, y, z) = (col, -row, depth)",
    )
    normals: str = Field(description="float32 little-endian, 3 per vertex, unit length")
    uvs: str = Field(
        description="float32 little-endian, 2 per vertex: u = (col + 0.5) / W, v = 1 - (row + 0.5) / H; "
        "empty for a mesh without texture coordinates (a fused model)",
    )
    indices: str = Field(
        description="uint32 little-endian, 3 per triangle, counter-clockwise seen from +z",
    )


class ReconstructResult(_Model):
    """One reconstruction: the mesh, and what the library used and found."""

    request_id: int
    preview: bool = Field(
        description="True for a quick look solved at the mesh's grid or a coarser one: the full result is "
        "still to come.",
    )
    mesh: MeshData
    mask_png: str = Field(
        description="The object mask as a base64 8-bit grey PNG (255 = object), the image's size; empty "
        "in a quick look of a large photo (``info.level``): the full result brings it.",
    )
    light: tuple[float, float, float] = Field(
        description="Unit vector toward the light that was used (given or estimated).",
    )
    references: list[tuple[int, int]] = Field(
        description="Reference pixels used, ``[row, col]``: the user's, then the automatic ones.",
    )
    depth_range: tuple[float, float] = Field(
        description="Smallest and largest depth on the object, pixel units.",
    )
    timings: dict[str, float] = Field(
        description="Seconds per stage: the library's stages, then mesh, encode, total.",
    )
    info: dict[str, Any] = Field(
        description="What ran (the library's ``Reconstruction.info`` plus ``cached``: whether the solve was reused).",
    )


class SolveJob(_Model):
    """A full-resolution solve running in the background (``/api/solves``)."""

    job_id: str
    request_id: int = Field(description="The request's ``request_id``, echoed.")
    state: Literal["running", "done", "cancelled", "failed"]
    stage: str = Field(
        description="The stage done last (``timings``' names), ``queued``, ``mesh`` or ``done``."
    )
    stage_text: str = Field(description="What the solve is doing, in the user's words.")
    fraction: float = Field(description="Rough share of the work done, 0 to 1.")
    elapsed: float = Field(description="Seconds since it started (to its end, once ended).")
    detail: str | None = Field(
        description="Why it ended without a result: the error, or what cancelled it; else null."
    )


class StereoParams(_Model):
    """Everything the user sets for photometric stereo on a photo set."""

    lights: StereoLights = Field(
        default="file",
        description='Where the lights come from: "file" (the set\'s light file), "sphere" (a shiny sphere '
        'in the photos) or "unknown" (read from the photos alone).',
    )
    sphere: tuple[float, float, float] | None = Field(
        default=None,
        description="The sphere's circle ``[column, row, radius]`` in pixels; null to find it (lights "
        '"sphere" only).',
    )
    method: str = Field(default="bivariate", description="One of ``Options.stereo_methods``.")
    integrator: str = Field(default="poisson", description="One of ``Options.integrators``.")
    step: int = Field(
        default=2,
        ge=1,
        description="Mesh granularity: pixels per vertex. Changing only this re-meshes without a new solve.",
    )


class StereoRequest(_Model):
    """Photometric stereo (or its export) on a stored photo set with these parameters."""

    photoset_id: str
    params: StereoParams = Field(default_factory=StereoParams)
    request_id: int = Field(
        default=0,
        description="Chosen by the client, echoed in the result: a response older than the newest is stale.",
    )


class PhotoSetInfo(_Model):
    """A photo set the server holds (several photos of one still object, lights moving)."""

    photoset_id: str
    name: str
    count: int = Field(description="How many photos.")
    width: int
    height: int
    colour: bool = Field(description="Whether the photos have colour.")
    names: list[str] = Field(description="The photos' file names, in the set's order.")
    lights_file: bool = Field(description="Whether a light file came with the photos.")
    intensities_file: bool = Field(description="Whether a file of the lights' strengths came with them.")
    mask: bool = Field(description="Whether a mask came with them.")
    suggested: StereoParams = Field(description="Settings to start from.")


class StereoResult(_Model):
    """Photometric stereo's result: the mesh, the maps to view and relight, what was found."""

    request_id: int
    mesh: MeshData
    mask_png: str = Field(description="The object mask as a base64 8-bit grey PNG (255 = object).")
    normals_png: str = Field(
        description="Normals as a base64 8-bit RGB PNG, ``(n + 1) / 2`` per channel (x right, y up, z toward "
        "the viewer), black off the object.",
    )
    albedo_png: str = Field(
        description="Albedo as a base64 8-bit RGB PNG, sRGB-encoded, white = ``albedo_white``.",
    )
    albedo_white: float = Field(description="The linear albedo shown as white (its 99.5th percentile).")
    confidence_png: str = Field(
        description="Each normal's confidence in [0, 1] as a base64 8-bit grey PNG.",
    )
    lights: list[tuple[float, float, float]] = Field(
        description="The unit direction toward each photo's light that was used (given, from the sphere or "
        "read from the photos).",
    )
    sphere: tuple[float, float, float] | None = Field(
        description="The sphere's circle ``[column, row, radius]`` the lights were read from, if they were.",
    )
    photos_dropped: list[int] = Field(description="Photos (0-based) left out: they contradict the others.")
    photos_rescaled: list[tuple[int, float]] = Field(
        description="Photos whose light was brighter (factor > 1) or dimmer than said, and the factor.",
    )
    light: tuple[float, float, float] = Field(description="The lights' mean direction (to shade the model).")
    depth_range: tuple[float, float] = Field(
        description="Smallest and largest depth on the object, pixel units.",
    )
    timings: dict[str, float] = Field(description="Seconds per stage.")
    info: dict[str, Any] = Field(
        description="What ran (the library's ``Reconstruction.info`` plus ``cached``).",
    )


class FuseView(_Model):
    """One view of a fusion: a stored photo, its turntable angle and how it is reconstructed."""

    image_id: str
    angle: float = Field(
        allow_inf_nan=False,
        description="Turntable angle in degrees: the object turned by it about the camera's vertical "
        'axis, right-handed about +y (``docs/conventions.md``, "Turntable views").',
    )
    params: ReconstructParams = Field(
        default_factory=ReconstructParams,
        description="The view's reconstruction, exactly as ``/api/reconstruct`` makes it (its ``step`` "
        "is the finest grid of its partial model).",
    )


class FuseRequest(_Model):
    """Several views of one object fused into one closed model (or its export)."""

    views: list[FuseView] = Field(min_length=2, max_length=24, description="Two to 24 views.")
    refine: bool = Field(
        default=True, description="Correct the poses and depth offsets so that the views agree."
    )
    settle: bool = Field(
        default=True,
        description="Read each view's unsure areas (what its photo leaves open: ``info['unsure']``) as "
        "concave where the other views' silhouettes say so (``shadeform.fusion.settle``).",
    )
    resolution: float | None = Field(
        default=None,
        ge=0.25,
        le=64,
        allow_inf_nan=False,
        description="Voxel edge in pixels; null: 1, or coarser for a big object (the library's default).",
    )
    request_id: int = Field(
        default=0,
        description="Chosen by the client, echoed in the result: a response older than the newest is stale.",
    )


class FusedView(_Model):
    """What one view of a fusion was reconstructed with."""

    mask_png: str = Field(description="The view's object mask as a base64 8-bit grey PNG (255 = object).")
    light: tuple[float, float, float] = Field(description="Unit vector toward the light that was used.")
    cached: bool = Field(description="Whether its reconstruction was reused, not solved for this request.")
    settled: list[ConcaveRegion] = Field(
        description="Unsure areas of the view's photo that the other views showed to be concave: its "
        "partial model and the fused one read them so (add them to the view's regions to keep them).",
    )
    transform: list[list[float]] = Field(
        description="The 4x4 matrix (rows) that took the view's own mesh (``(col, -row, depth)``) to its "
        "partial model in the object frame: its refined pose and depth offset.",
    )
    outline_iou: float = Field(
        default=1.0,
        description="How well the fused model keeps the view's outline: the IoU of its projection into the "
        "view with the view's mask (``shadeform.fusion.outlines.outline_iou``); below 0.95 parts the view "
        "shows are missing or the model reaches past them.",
    )


class FuseResult(_Model):
    """The fused model, and each view's partial model where the fusion placed it."""

    request_id: int
    mesh: MeshData = Field(
        description="The fused model: closed, outward-facing, in the object frame (the frame of the view "
        "at angle 0, x = 0 on the turntable axis), pixel units; no texture coordinates.",
    )
    parts: list[MeshData] = Field(
        description="Each view's own mesh (on a coarser grid, to stay light), moved into the object frame "
        "where the fusion placed it; in the views' order.",
    )
    views: list[FusedView] = Field(description="Per view, in order.")
    axis: float = Field(description="The turntable axis's column in the photos (the object frame's x = 0).")
    volume: float = Field(description="The fused model's volume, cubic pixels.")
    watertight: bool = Field(
        description="Whether the fused model is closed (every edge shared by two faces)."
    )
    rivals: list[list[float]] = Field(
        default_factory=list,
        description="Other placements the photos fit about as well as the fused model's "
        "(``shadeform.fusion.Rival``): per placement, per view the degrees it is turned from where the "
        "model has it (0: not turned). Not empty: the photos do not decide, and the model may be wrong.",
    )
    depth_fixed: bool = Field(
        default=True,
        description="Whether the views fix the object's depth (``shadeform.fusion.Placement.depth_fixed``): "
        "false when they all look along one line (from opposite sides only), and the model's thickness rests on each photo's shading alone.",
    )
    timings: dict[str, float] = Field(
        description="Seconds per stage: reconstruct (the views solved anew), place, solid, parts, encode, "
        "total.",
    )
    info: dict[str, Any] = Field(
        description="What ran: ``resolution`` (the voxel edge used), ``refine``, ``settle``, ``cached`` "
        "(whether the fusion was reused).",
    )


class ViewSetInfo(_Model):
    """A view set the server opened: its photos (stored images) and their turntable angles."""

    name: str
    images: list[ImageInfo] = Field(description="One stored image per view, in order.")
    angles: list[float] = Field(description="Each view's turntable angle in degrees.")


class AutoMaskRequest(_Model):
    """The automatic object mask of a stored image, or the one of a threshold
    (:func:`shadeform.preprocess.object_mask`)."""

    channel: Channel = "luma"
    threshold: float | None = Field(
        default=None,
        description="Object = pixels above it (below it with ``dark``), the largest part that is not "
        "mostly frame border, holes filled; null for the automatic mask.",
    )
    dark: bool | None = Field(
        default=None,
        description="The object is darker than its background; null: decided from the image (with a "
        "threshold: false).",
    )


class SeedMaskRequest(_Model):
    """The object under the user's clicks (:func:`shadeform.masks.segment_from_seeds`)."""

    channel: Channel = "luma"
    inside: list[tuple[_PixelIndex, _PixelIndex]] = Field(
        min_length=1, max_length=1000, description="Pixels ``[row, col]`` on the object."
    )
    outside: list[tuple[_PixelIndex, _PixelIndex]] = Field(
        default_factory=list, max_length=1000, description="Pixels ``[row, col]`` on the background."
    )
    radius: int = Field(default=2, ge=0, le=64, description="Each click marks a disk of this radius, pixels.")


class MaskFileRequest(_Model):
    """A mask file the user loads, to be checked against the image and made the app's PNG."""

    data: str = Field(description="base64 of the file's bytes (PNG, TIFF, BMP, ...); non-zero = object.")


class MaskResult(_Model):
    """An object mask made or checked by the server."""

    mask_png: str = Field(description="The mask as a base64 8-bit grey PNG (255 = object), the image's size.")
    pixels: int = Field(description="How many pixels are object.")
    threshold: float | None = Field(
        description="The threshold nearest to this mask (a place to start a threshold slider), in the "
        "channel's units; null when it did not come from one.",
    )
    dark: bool = Field(description="Whether the object is darker than its background.")
    note: str = Field(description="One line in the user's words saying what was found.")
    confidence: float | None = Field(
        default=None,
        description="How sure the mask is, 0 to 1 (the agreement of the ways of finding it); null for a "
        "threshold's or a file's mask. Below ``shadeform.masks.LOW_CONFIDENCE`` the note says it is doubtful.",
    )


class BoxMaskRequest(_Model):
    """The object inside a box the user drew (:func:`shadeform.masks.segment_from_box`)."""

    channel: Channel = "luma"
    box: tuple[_PixelIndex, _PixelIndex, _PixelIndex, _PixelIndex] = Field(
        description="``[top, left, bottom, right]`` in pixels, bottom and right exclusive."
    )


# --- printing and texture maps (shadeform.app.printing) -----------------------------------------

Outline = TypeAliasType("Outline", Literal["mask", "frame"])


class ReliefParams(_Model):
    """A print's options (:func:`shadeform.relief`); the server checks them
    (:func:`shadeform.solid.check_options`) and says what is wrong in one line."""

    width_mm: float = Field(default=100.0, description="Longest side of the outline, mm (exact).")
    height_mm: float = Field(default=5.0, description="Relief depth, lowest to highest point, mm.")
    base_mm: float = Field(default=2.0, description="Flat base under the relief's lowest point, mm.")
    outline: Outline = Field(default="mask", description="Walls along the object's outline, or the frame.")
    compress: float = Field(default=0.0, description="Bas-relief compression in [0, 1]; 0 scales linearly.")
    invert: bool = Field(default=False, description="Engrave instead of emboss.")
    border_mm: float = Field(default=0.0, description="A flat rim around the outline, mm; 0 for none.")
    min_wall_mm: float = Field(default=0.8, description="The thinnest wall the printer makes, mm.")
    max_triangles: int | None = Field(
        default=200_000, description="Triangle budget (at least 12); null: two triangles per pixel."
    )


class ReliefRequest(_Model):
    """A print-ready solid of a stored image's reconstruction with these parameters."""

    image_id: str
    params: ReconstructParams = Field(default_factory=ReconstructParams)
    relief: ReliefParams = Field(default_factory=ReliefParams)
    request_id: int = Field(default=0, description="Chosen by the client, echoed in the result.")


class ReliefResult(_Model):
    """The solid, in millimetres, and its measures."""

    request_id: int
    mesh: MeshData = Field(
        description="The closed solid, mm: x along the image's columns, y up the image, base on z = 0; "
        "no texture coordinates.",
    )
    size_mm: tuple[float, float, float] = Field(description="Extent along x, y, z, mm (z: base plus relief).")
    volume_mm3: float
    triangle_count: int
    deviation_mm: float = Field(description="Farthest the printed top is from the full-resolution relief.")
    pixel_mm: float = Field(description="One image pixel in the print, mm.")
    timings: dict[str, float] = Field(description="Seconds: reconstruct (if solved), relief, encode, total.")
    info: dict[str, Any] = Field(description="``cached``: the model was reused; ``reused``: the solid too.")


class MapPreview(_Model):
    """One texture map, small, with what its file holds."""

    name: str = Field(description="normal_opengl, normal_directx, height, ambient_occlusion or curvature.")
    png: str = Field(description="A preview: base64 8-bit PNG, at most 256 pixels on a side.")
    bits: int = Field(description="Bits per sample of the map's file in the zip.")
    legend: str = Field(description="What the map's values mean.")


class MapsResult(_Model):
    """Previews of every texture map of a reconstruction (:func:`shadeform.maps`)."""

    request_id: int
    width: int = Field(description="The maps' full width in pixels (the image's).")
    height: int
    maps: list[MapPreview]
    timings: dict[str, float] = Field(description="Seconds: reconstruct (if solved), maps, encode, total.")
    info: dict[str, Any] = Field(description="``cached``: the model was reused; ``reused``: the maps too.")


# --- projects: the user's work on one photo, a photo set or views, kept by the server ------------

#: A project's id: chosen by the client, so that it can save before the server answers.
PROJECT_ID_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"

_Name = Annotated[str, Field(max_length=1000)]


class ProjectSource(_Model):
    """Where a project's photo came from, to open it again: a shipped example (by name), an upload,
    the image the server was started with, or photo ``index`` of a shipped view set."""

    kind: Literal["example", "upload", "initial", "viewset"]
    name: _Name
    type: str | None = Field(default=None, max_length=200, description="An upload's MIME type.")
    index: int | None = Field(default=None, ge=0, lt=1000, description="The photo's place in its view set.")


class ProjectImage(_Model):
    """A project's photo: a project file carries its bytes; the server's projects name the image in
    the server's session store instead (``info.image_id``), which keeps the bytes."""

    name: _Name
    type: str = Field(default="", max_length=200, description="The file's MIME type.")
    data: str | None = Field(default=None, description="base64 of the image file (project files).")
    example: str | None = Field(default=None, max_length=200, description="A shipped example's name.")
    source: ProjectSource | None = None
    info: ImageInfo | None = Field(
        default=None, description="The image as the server stored it (its id in the session store)."
    )


class DisplaySettings(_Model):
    """How the client shows the model and the image (the project file's ``view``)."""

    wireframe: bool = False
    normalColours: bool = False
    texture: bool = False
    maskOverlay: bool = True
    lightArrow: bool = True


class ProjectPhotoSet(_Model):
    """A photo set in a project: the set the server stored and the user's settings."""

    info: PhotoSetInfo
    params: StereoParams


class ProjectViewEntry(_Model):
    """One view in a project: its stored photo, where the photo came from, angle and settings."""

    image: ImageInfo
    source: ProjectSource
    angle: float = Field(allow_inf_nan=False)
    params: ReconstructParams


class ProjectViews(_Model):
    """The views in a project (several sides of one object, fused) and the fusion's settings."""

    views: list[ProjectViewEntry] = Field(min_length=1, max_length=24)
    refine: bool = True
    settle: bool = True
    resolution: float | None = Field(default=None, ge=0.25, le=64, allow_inf_nan=False)
    showParts: bool = True
    editing: int | None = Field(
        default=None, ge=0, lt=24, description="The view being edited in single-photo mode, if one is."
    )


class ProjectDocument(_Model):
    """A project as the client's project file holds it: one photo (``image`` and ``params``), a
    photo set (``photo_set``) or views (``views``), with the display settings."""

    format: Literal["shadeform-project"]
    version: int = Field(ge=1, le=1, description="1: the only version so far.")
    name: str | None = Field(
        default=None, max_length=200, description="Shown in Open recent; null: what the project is of."
    )
    image: ProjectImage | None = None
    params: ReconstructParams | None = None
    view: DisplaySettings = Field(default_factory=DisplaySettings)
    photo_set: ProjectPhotoSet | None = None
    views: ProjectViews | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> ProjectDocument:
        held = [key for key in ("image", "photo_set", "views") if getattr(self, key) is not None]
        if len(held) != 1:
            raise ValueError(
                "a project holds exactly one of image (with params), photo_set or views; "
                f"this one holds {' and '.join(held) or 'none of them'}"
            )
        if self.image is not None and self.params is None:
            raise ValueError("a project with an image needs its params")
        return self


class ProjectInfo(_Model):
    """A project the server keeps, as Open recent lists it."""

    id: str
    name: str
    image: str = Field(description="What the project is of: the photo's name, the photo set's, the views'.")
    kind: Literal["photo", "photo_set", "views"]
    created: float = Field(description="Seconds since the epoch.")
    updated: float = Field(description="Seconds since the epoch, when it was last saved.")


class ProjectList(_Model):
    """The projects the server keeps, the most recently updated first."""

    projects: list[ProjectInfo]


class Project(ProjectInfo):
    """A project the server keeps, with its document."""

    document: ProjectDocument


class ErrorBody(_Model):
    """Every error response: one line saying what was wrong and what to do."""

    detail: str


#: Models written to the TypeScript file, in this order.
_EXPORTED = (
    FilterParams,
    LightParams,
    ConcaveRegion,
    ConcaveRegions,
    ReconstructParams,
    ReconstructRequest,
    MethodInfo,
    FormatInfo,
    ExampleInfo,
    Limits,
    ImageInfo,
    Options,
    MeshData,
    ReconstructResult,
    SolveJob,
    StereoParams,
    StereoRequest,
    PhotoSetInfo,
    StereoResult,
    FuseView,
    FuseRequest,
    FusedView,
    FuseResult,
    ViewSetInfo,
    AutoMaskRequest,
    SeedMaskRequest,
    BoxMaskRequest,
    MaskFileRequest,
    MaskResult,
    ReliefParams,
    ReliefRequest,
    ReliefResult,
    MapPreview,
    MapsResult,
    ProjectSource,
    ProjectImage,
    DisplaySettings,
    ProjectPhotoSet,
    ProjectViewEntry,
    ProjectViews,
    ProjectDocument,
    ProjectInfo,
    ProjectList,
    Project,
    ErrorBody,
)


def typescript() -> str:
    """The TypeScript declarations of the schema: the text of ``web/src/api.gen.ts``.

    Built from pydantic's JSON schema (serialization mode, so every field the server sends is
    required): objects become interfaces, string enums union types of literals, fixed-length
    arrays tuples.

    Returns
    -------
    str
        The whole file, ending with a newline.
    """
    _, schema = models_json_schema([(model, "serialization") for model in _EXPORTED])
    definitions = schema["$defs"]
    # aliases (Channel, ...) first, then the models in _EXPORTED order
    order = [name for name in definitions if "properties" not in definitions[name]]
    order += [model.__name__ for model in _EXPORTED]
    lines = [
        "// Generated from shadeform.app.schema by `python -m shadeform.app.schema`; do not edit.",
        "// A test (tests/test_app_api.py) fails when this file and the schema disagree.",
        "",
    ]
    for name in order:
        definition = definitions[name]
        if "properties" not in definition:
            lines += [f"export type {name} = {_ts_type(definition)};", ""]
            continue
        doc = definition.get("description")
        if doc:
            lines.append(f"/** {' '.join(doc.split())} */")
        lines.append(f"export interface {name} {{")
        required = set(definition.get("required", ()))
        for field, spec in definition["properties"].items():
            if spec.get("description"):
                lines.append(f"  /** {spec['description']} */")
            optional = "" if field in required else "?"
            lines.append(f"  {field}{optional}: {_ts_type(spec)};")
        lines += ["}", ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def _ts_type(spec: dict) -> str:
    """A TypeScript type expression for one JSON-schema node."""
    if "$ref" in spec:
        return spec["$ref"].rsplit("/", 1)[-1]
    if "enum" in spec:
        return " | ".join(json.dumps(value) for value in spec["enum"])
    if "const" in spec:
        return json.dumps(spec["const"])
    if "anyOf" in spec:
        return " | ".join(_ts_type(option) for option in spec["anyOf"])
    kind = spec.get("type")
    if kind == "array":
        if "prefixItems" in spec:
            return "[" + ", ".join(_ts_type(item) for item in spec["prefixItems"]) + "]"
        item = _ts_type(spec.get("items", {}))
        return f"({item})[]" if " | " in item else f"{item}[]"
    if kind == "object":
        values = spec.get("additionalProperties", True)
        return f"Record<string, {'unknown' if values is True else _ts_type(values)}>"
    return {
        "string": "string",
        "number": "number",
        "integer": "number",
        "boolean": "boolean",
        "null": "null",
    }.get(kind, "unknown")


if __name__ == "__main__":
    sys.stdout.write(typescript())
