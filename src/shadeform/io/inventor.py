"""Open Inventor 2.1 ASCII writer: one Separator with an IndexedFaceSet and per-vertex normals.

The 2002 ModelBuilder exported this format; ``ivview``, ``ivcat``, Coin3D and FreeCAD read it.
"""

from __future__ import annotations

from typing import BinaryIO

from shadeform.io.vrml import DIFFUSE_COLOR, format_rows, write_vertex_nodes
from shadeform.mesh import Mesh

__all__ = ["write_inventor"]

# Normals are given per vertex, so the crease angle only matters to viewers that recompute them.
CREASE_ANGLE = 1.5708
# the nodes whose values are bound per vertex through the face set's indices
_BOUND = ("Normal", "TextureCoordinate")


def write_inventor(mesh: Mesh, file_obj: BinaryIO) -> None:
    """Write ``mesh`` as an Open Inventor 2.1 ASCII file (``.iv``).

    Parameters
    ----------
    mesh : Mesh
        Triangles with per-vertex normals; ``uv``, when present, becomes a
        ``TextureCoordinate2`` bound per vertex.
    file_obj : binary file
        Open for writing; ASCII text is written to it.

    Notes
    -----
    Layout: ``Separator { ShapeHints Material Coordinate3 Normal NormalBinding
    [TextureCoordinate2 TextureCoordinateBinding] IndexedFaceSet }``. ``ShapeHints`` declares
    ``COUNTERCLOCKWISE`` vertex ordering (``docs/conventions.md``) and ``UNKNOWN_SHAPE_TYPE``
    (an open surface: light both sides). ``normalIndex`` (and ``textureCoordIndex``) repeat
    ``coordIndex`` explicitly, since old readers differ on what an empty index means.
    Multiple-value fields separate values with commas, as ``ivcat`` writes them. Numbers are
    written with ``%.6g``.
    """
    has_uv = mesh.uv is not None
    head = (
        "#Inventor V2.1 ascii\n\n"
        f"# shadeform mesh: {mesh.n_vertices} vertices, {mesh.n_faces} triangles, units: {mesh.unit}\n"
        "Separator {\n"
        "  ShapeHints {\n"
        "    vertexOrdering COUNTERCLOCKWISE\n"
        "    shapeType UNKNOWN_SHAPE_TYPE\n"
        "    faceType CONVEX\n"
        f"    creaseAngle {CREASE_ANGLE}\n"
        "  }\n"
        "  Material {\n"
        f"    diffuseColor {DIFFUSE_COLOR[0]} {DIFFUSE_COLOR[1]} {DIFFUSE_COLOR[2]}\n"
        "  }\n"
    )
    file_obj.write(head.encode("ascii"))
    write_vertex_nodes(
        file_obj,
        mesh,
        2,
        ("Coordinate3", "Normal", "TextureCoordinate2"),
        after=(
            b"",
            *(f"  {name}Binding {{\n    value PER_VERTEX_INDEXED\n  }}\n".encode() for name in _BOUND),
        ),
    )

    # format the indices once, write them two or three times
    index_parts = list(format_rows(mesh.faces, "%d, %d, %d, -1,\n"))
    file_obj.write(b"  IndexedFaceSet {\n    coordIndex [\n")
    file_obj.writelines(index_parts)
    file_obj.write(b"    ]\n    normalIndex [\n")
    file_obj.writelines(index_parts)
    if has_uv:
        file_obj.write(b"    ]\n    textureCoordIndex [\n")
        file_obj.writelines(index_parts)
    file_obj.write(b"    ]\n  }\n}\n")
