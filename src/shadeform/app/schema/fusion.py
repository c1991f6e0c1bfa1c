"""The schema of fusing several views of one object into one closed model
(``shadeform.app.fusion``): the views, the request, the result per view and in all, and a
shipped view set."""

from __future__ import annotations

from typing import Any

from pydantic import AliasChoices, Field, model_validator

from shadeform.app.schema.common import MeshData, _Model, _RequestId
from shadeform.app.schema.reconstruct import ConcaveRegion, ImageInfo, ReconstructParams
from shadeform.app.schema.stereo import StereoParams


class FuseView(_Model):
    """One view of a fusion: a stored photo (or photo set), its turntable angle and how it is
    reconstructed."""

    image_id: str | None = Field(
        default=None, description="The view's stored photo; null when the view is a photo set."
    )
    photo_set_id: str | None = Field(
        default=None,
        description="A stored photo set (``POST /api/photosets``) instead of a photo: several photos of "
        "this view under different lights, solved by photometric stereo as ``/api/stereo`` solves it "
        "(``stereo``; cache included). Its shape needs no hints: it is never solved again for settling, "
        "and ``params`` may not draw concave regions on it.",
    )
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
    stereo: StereoParams = Field(
        default_factory=StereoParams,
        description="A photo-set view's photometric stereo, as ``/api/stereo`` takes it (its ``step`` is "
        "the finest grid of its partial model); unused for a photo.",
    )

    @model_validator(mode="after")
    def _photo_or_set(self) -> FuseView:
        if (self.image_id is None) == (self.photo_set_id is None):
            raise ValueError(
                "a view is one photo (image_id) or one photo set (photo_set_id): give exactly one of them"
            )
        return self


class FuseRequest(_Model):
    """Several views of one object fused into one closed model (or its export)."""

    views: list[FuseView] = Field(min_length=2, max_length=24, description="Two to 24 views.")
    refine_poses: bool = Field(
        default=True,
        # "refine", its old name, still read for one release
        validation_alias=AliasChoices("refine_poses", "refine"),
        description="Correct the poses and depth offsets so that the views agree.",
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
    request_id: _RequestId = 0


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
        description="What ran: ``resolution`` (the voxel edge used), ``refine_poses``, ``settle``, ``cached`` "
        "(whether the fusion was reused).",
    )


class ViewSetInfo(_Model):
    """A view set the server opened: its photos (stored images) and their turntable angles."""

    name: str
    images: list[ImageInfo] = Field(description="One stored image per view, in order.")
    angles: list[float] = Field(description="Each view's turntable angle in degrees.")
