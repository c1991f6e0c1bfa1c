"""The schema of printing and texture maps (``shadeform.app.printing``): a relief's options,
request and solid, and the maps' previews."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field
from typing_extensions import TypeAliasType

from shadeform.app.schema.common import MeshData, _Model
from shadeform.app.schema.reconstruct import ReconstructParams
from shadeform.app.schema.stereo import StereoParams

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


class StereoReliefRequest(_Model):
    """A print-ready solid of a stored photo set's photometric stereo with these parameters."""

    photoset_id: str
    params: StereoParams = Field(default_factory=StereoParams)
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

    name: str = Field(
        description="normal_opengl, normal_directx, height, ambient_occlusion, curvature, or a photo set's albedo."
    )
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
