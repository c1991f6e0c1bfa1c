"""The schema of the object mask (``shadeform.app.masks``): automatic or by threshold, from the
user's clicks or box, from a file, and the mask the server answers with."""

from __future__ import annotations

from pydantic import Field

from shadeform.app.schema.common import Channel, _Model, _PixelIndex


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
