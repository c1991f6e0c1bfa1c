"""What every panel's schema shares: the base model (unknown fields refused), the image channel,
a pixel index, a request's number, the mesh as base64 arrays and the error body."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field
from typing_extensions import TypeAliasType

Channel = TypeAliasType("Channel", Literal["luma", "r", "g", "b", "max"])

# a pixel row or column a client sends: no image is 2**31 pixels wide, and a larger number would
# wrap around in numpy's int64 and be reported as another pixel
_PixelIndex = Annotated[int, Field(ge=-(2**31), lt=2**31)]

# a request's number, which its result echoes (the requests of a panel that solves: a photo, a
# photo set, the views)
_RequestId = Annotated[
    int,
    Field(
        description="Chosen by the client, echoed in the result: a response older than the newest is stale."
    ),
]


class _Model(BaseModel):
    # requests with unknown fields are refused (a typo must not be silently ignored); in the
    # generated types a field with a default is still required: the server always sends it
    model_config = ConfigDict(extra="forbid", json_schema_serialization_defaults_required=True)


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


class ErrorBody(_Model):
    """Every error response: one line saying what was wrong and what to do."""

    detail: str
