"""VRML 2.0 (VRML97) writer: one Shape with an IndexedFaceSet and per-vertex normals.

The format is ISO/IEC 14772-1:1997. In VRML commas are whitespace, so each row of numbers
ends with ``","`` for readability only.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from shadeform.mesh import Mesh

__all__ = ["write_vrml", "format_rows", "write_rows", "write_vertex_nodes"]

# neutral light grey, the usual default for untextured scans
DIFFUSE_COLOR = (0.8, 0.8, 0.8)

# Normals are supplied, so viewers do not smooth; the angle only matters to tools that drop
# them and recompute (90 degrees: smooth a relief, keep right-angle creases).
CREASE_ANGLE = 1.5708

_CHUNK_ROWS = 1 << 16


def format_rows(array: np.ndarray, row_format: str) -> Iterator[bytes]:
    """ASCII text of a 2-D array, one ``%``-formatted row per line, without a loop per row.

    Rows are formatted in chunks of 65536 with one ``%`` operation each (about three times
    faster than :func:`numpy.savetxt`, which formats row by row), so memory stays bounded.

    Parameters
    ----------
    array : (N, C) array
        Numbers to format.
    row_format : str
        ``%``-format for one row with exactly ``C`` conversions, including its line ending,
        e.g. ``"%.6g %.6g %.6g,\\n"``.

    Yields
    ------
    bytes
        The text of up to 65536 consecutive rows.
    """
    for start in range(0, array.shape[0], _CHUNK_ROWS):
        chunk = array[start : start + _CHUNK_ROWS]
        yield ((row_format * chunk.shape[0]) % tuple(chunk.ravel().tolist())).encode("ascii")


def write_rows(file_obj: BinaryIO, array: np.ndarray, row_format: str) -> None:
    """Write :func:`format_rows` of ``array`` to a binary file."""
    file_obj.writelines(format_rows(array, row_format))


def write_vertex_nodes(
    file_obj: BinaryIO, mesh: Mesh, indent: int, nodes: tuple[str, str, str], after: tuple[bytes, ...] = ()
) -> None:
    """Write the mesh's per-vertex arrays, each as ``node { field [ rows ] }`` (VRML and Inventor).

    Parameters
    ----------
    file_obj : binary file
        Open for writing.
    mesh : Mesh
        Its vertices (field ``point``), normals (``vector``) and uv (``point``; none when
        ``mesh.uv`` is None) are written, ``%.6g`` each.
    indent : int
        Spaces before each node; its field is two more in.
    nodes : tuple of 3 str
        The nodes (with their field name in VRML) of vertices, normals and uv.
    after : tuple of bytes
        Written after the node of the same index (Inventor's bindings); none by default.
    """
    pad = " " * indent
    arrays = [(mesh.vertices, "point", "%.6g %.6g %.6g,\n"), (mesh.normals, "vector", "%.6g %.6g %.6g,\n")]
    if mesh.uv is not None:
        arrays.append((mesh.uv, "point", "%.6g %.6g,\n"))
    for k, (array, field, row_format) in enumerate(arrays):
        file_obj.write(f"{pad}{nodes[k]} {{\n{pad}  {field} [\n".encode("ascii"))
        write_rows(file_obj, array, row_format)
        file_obj.write(f"{pad}  ]\n{pad}}}\n".encode("ascii"))
        if k < len(after):
            file_obj.write(after[k])


def write_vrml(mesh: Mesh, file_obj: BinaryIO) -> None:
    """Write ``mesh`` as a VRML 2.0 file (``.wrl``).

    Parameters
    ----------
    mesh : Mesh
        Triangles with per-vertex normals; ``uv``, when present, becomes a
        ``TextureCoordinate``.
    file_obj : binary file
        Open for writing; UTF-8 (here plain ASCII) text is written to it.

    Notes
    -----
    Layout: ``Shape { appearance Appearance { material Material } geometry IndexedFaceSet }``
    with ``ccw TRUE`` (counter-clockwise front faces, ``docs/conventions.md``), ``solid FALSE``
    (show back faces: an open relief is seen from behind too), ``normalPerVertex TRUE`` and
    ``coordIndex`` with ``-1`` after each triangle. ``normalIndex`` and ``texCoordIndex`` are left
    empty, which by the standard means "use ``coordIndex``". Numbers are written with ``%.6g``.
    """
    head = (
        "#VRML V2.0 utf8\n"
        f"# shadeform mesh: {mesh.n_vertices} vertices, {mesh.n_faces} triangles, units: {mesh.unit}\n"
        "Shape {\n"
        "  appearance Appearance {\n"
        "    material Material {\n"
        f"      diffuseColor {DIFFUSE_COLOR[0]} {DIFFUSE_COLOR[1]} {DIFFUSE_COLOR[2]}\n"
        "    }\n"
        "  }\n"
        "  geometry IndexedFaceSet {\n"
        "    solid FALSE\n"
        "    ccw TRUE\n"
        "    convex TRUE\n"
        f"    creaseAngle {CREASE_ANGLE}\n"
        "    normalPerVertex TRUE\n"
    )
    file_obj.write(head.encode("ascii"))
    write_vertex_nodes(file_obj, mesh, 4, ("coord Coordinate", "normal Normal", "texCoord TextureCoordinate"))
    file_obj.write(b"    coordIndex [\n")
    write_rows(file_obj, mesh.faces, "%d %d %d -1,\n")
    file_obj.write(b"    ]\n  }\n}\n")
