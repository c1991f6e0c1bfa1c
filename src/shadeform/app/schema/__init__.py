"""The app's request and response schema, defined once (pydantic) for the server and the client.

The web client's TypeScript types (``web/src/api.gen.ts``) are generated from these models by
:func:`typescript`; ``python -m shadeform.app.schema`` prints that file, and a test checks that the
committed copy is current. Field meanings and conventions (frames, regions JSON) are those of
``docs/conventions.md``; the server only validates types and ranges here and leaves every other
check to the library, whose :class:`shadeform.InputError` messages reach the user unchanged.

Arrays in :class:`MeshData` travel as base64 text of little-endian ``float32`` (positions,
normals, uvs) and ``uint32`` (indices) so that the client can view them as typed arrays without
parsing numbers.

The models live in one module per panel of the app (:mod:`~shadeform.app.schema.reconstruct`,
:mod:`~shadeform.app.schema.stereo`, :mod:`~shadeform.app.schema.fusion`,
:mod:`~shadeform.app.schema.masks`, :mod:`~shadeform.app.schema.printing`,
:mod:`~shadeform.app.schema.projects`), what they share in :mod:`~shadeform.app.schema.common`,
what the server offers in :mod:`~shadeform.app.schema.options`, and the generator in
:mod:`~shadeform.app.schema.generate`; this package only re-exports them.
"""

from __future__ import annotations

from shadeform.app.schema.common import Channel, ErrorBody, MeshData
from shadeform.app.schema.fusion import FusedView, FuseRequest, FuseResult, FuseView, ViewSetInfo
from shadeform.app.schema.generate import typescript
from shadeform.app.schema.masks import (
    AutoMaskRequest,
    BoxMaskRequest,
    MaskFileRequest,
    MaskResult,
    SeedMaskRequest,
)
from shadeform.app.schema.options import ExampleInfo, FormatInfo, Limits, MethodInfo, OptionInfo, Options
from shadeform.app.schema.printing import (
    MapPreview,
    MapsResult,
    Outline,
    ReliefParams,
    ReliefRequest,
    ReliefResult,
    StereoReliefRequest,
)
from shadeform.app.schema.projects import (
    PROJECT_ID_PATTERN,
    DisplaySettings,
    Project,
    ProjectDocument,
    ProjectImage,
    ProjectInfo,
    ProjectList,
    ProjectPhotoSet,
    ProjectSource,
    ProjectViewEntry,
    ProjectViews,
)
from shadeform.app.schema.reconstruct import (
    Axis,
    ConcaveRegion,
    ConcaveRegions,
    FilterKind,
    FilterParams,
    ImageInfo,
    LightMode,
    LightParams,
    ReconstructParams,
    ReconstructRequest,
    ReconstructResult,
    SolveJob,
)
from shadeform.app.schema.stereo import PhotoSetInfo, StereoLights, StereoParams, StereoRequest, StereoResult

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
    "MethodInfo",
    "OptionInfo",
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
    "StereoReliefRequest",
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
    "PROJECT_ID_PATTERN",
    "typescript",
]
