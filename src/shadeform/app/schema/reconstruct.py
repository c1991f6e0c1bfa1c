"""The schema of one photo's reconstruction: its parameters (filter, light, concave regions), the
request, the stored image, the result and the background solve of a large photo."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import AliasChoices, Field
from typing_extensions import TypeAliasType

from shadeform.app.schema.common import Channel, MeshData, _Model, _PixelIndex, _RequestId

FilterKind = TypeAliasType("FilterKind", Literal["none", "gaussian", "mean", "median", "minimum"])
LightMode = TypeAliasType("LightMode", Literal["z", "slant_tilt", "estimate"])
Axis = TypeAliasType("Axis", Literal["x", "y", "both"])


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
    solver: str = Field(
        default="auto",
        # "method": its name in projects saved before the rename
        validation_alias=AliasChoices("solver", "method"),
        description='One of ``Options.solvers``; "auto" is the best measured for the light.',
    )
    integrator: str | None = Field(
        default=None,
        description="One of ``Options.integrators``, or null for the solver's own.",
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
    request_id: _RequestId = 0
    preview: bool = Field(
        default=False,
        description="Answer at once with a quick look solved at the mesh's grid (or a coarser one within the "
        "solver's pixel budget), unless the full result is already known or the grid is the "
        "image's own; the result's ``preview`` says which came.",
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
