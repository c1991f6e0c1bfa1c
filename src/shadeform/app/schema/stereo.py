"""The schema of photometric stereo on a photo set (``shadeform.app.stereo``): its parameters,
the request, the set the server holds and the result."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import AliasChoices, Field
from typing_extensions import TypeAliasType

from shadeform.app.schema.common import MeshData, _Model, _RequestId

StereoLights = TypeAliasType("StereoLights", Literal["file", "sphere", "unknown"])


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
    model: str = Field(
        default="bivariate",
        # "method", its old name, still read: projects saved before the rename open
        validation_alias=AliasChoices("model", "method"),
        description="The photometric model: one of ``Options.stereo_models``.",
    )
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
    request_id: _RequestId = 0


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
