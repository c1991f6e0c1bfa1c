"""The one registry of mesh exporters: file suffix -> writer.

:func:`available_formats` is built from the registry, and the tests loop over it, so a format
added with :func:`register` is listed and round-trip tested without further changes.

VRML 2.0 and Open Inventor 2.1 are written by the project (:mod:`shadeform.io.vrml`,
:mod:`shadeform.io.inventor`), and so are 3MF (:func:`write_3mf`) and glTF binary (streamed, without
trimesh's import or its in-memory copies); OBJ, PLY and STL go through trimesh, imported only when
one of them is written.

Every file states its unit (:attr:`shadeform.mesh.Mesh.unit`: pixels for reconstructions,
millimetres for print-ready solids; ``docs/conventions.md``): 3MF in its ``unit`` attribute, glTF in
``asset.extras.unit``, STL in its 80-byte header, OBJ, PLY, VRML and Open Inventor in a comment.
The coordinates are written as they are, never rescaled.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write
from shadeform.io.inventor import write_inventor
from shadeform.io.vrml import format_rows, write_vrml
from shadeform.mesh import Mesh
from shadeform.registry import Option, Registry

__all__ = ["EXPORTERS", "Exporter", "Writer", "register", "available_formats", "export", "write_3mf"]

Writer = Callable[[Mesh, BinaryIO], None]
"""A writer takes a mesh and a binary file open for writing, writes the whole file, returns None."""


@dataclass(frozen=True)
class Exporter:
    """One mesh format of the registry.

    Attributes
    ----------
    name : str
        Its file suffix, lower case with the dot (``".wrl"``).
    writer : callable ``(mesh, file_obj) -> None``
        See :func:`register`.
    description : str
        One line shown to users.
    options : tuple of Option
        Options of its own (:class:`shadeform.registry.Option`); none of the built-in formats has any.
    """

    name: str
    writer: Writer
    description: str
    options: tuple[Option, ...] = ()


#: The registered formats by suffix, in registration order.
EXPORTERS: Registry[Exporter] = Registry("mesh format suffix", Exporter)


def _normalise_suffix(suffix: str) -> str:
    suffix = suffix.lower()
    return suffix if suffix.startswith(".") else "." + suffix


def register(suffix: str, writer: Writer, *, description: str) -> None:
    """Add (or replace) the writer for a file suffix.

    Parameters
    ----------
    suffix : str
        File suffix such as ``".wrl"``; case-insensitive, the dot is optional.
    writer : callable ``(mesh, file_obj) -> None``
        Writes the whole file to a binary file object open for writing. It must not close the
        file nor seek before where it started.
    description : str, keyword-only
        One line shown to users, e.g. ``"VRML 2.0 (VRML97)"``.
    """
    suffix = _normalise_suffix(suffix)
    if len(suffix) < 2 or not suffix[1:].isalnum():
        raise ValueError(f"exporter suffix must be a dot and letters or digits, got {suffix!r}")
    EXPORTERS.register(Exporter(suffix, writer, description))


def available_formats() -> dict[str, str]:
    """Formats :func:`export` can write.

    Returns
    -------
    dict of str to str
        Suffix (lower case, with the dot) to a one-line description, in registration order.
    """
    return EXPORTERS.descriptions()


def export(mesh: Mesh, path: str | os.PathLike[str]) -> Path:
    """Write ``mesh`` to ``path`` in the format given by its suffix.

    The file is written atomically (:func:`shadeform.io.atomic.atomic_write`): on any error no
    partial file is left and an existing file at ``path`` is untouched.

    Parameters
    ----------
    mesh : Mesh
        The mesh to write.
    path : str or path-like
        Target file; its suffix (case-insensitive) picks the format, see
        :func:`available_formats`.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        If the suffix is not a known format or the folder does not exist.
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"export expects a shadeform Mesh, got {type(mesh).__name__}")
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in EXPORTERS:
        known = ", ".join(EXPORTERS.names())
        given = f"suffix '{path.suffix}'" if path.suffix else "no suffix"
        raise InputError(f"cannot export '{path.name}': {given}; use one of {known}")
    with atomic_write(path, mode="wb") as file_obj:
        EXPORTERS.get(suffix).writer(mesh, file_obj)
    return path


def _trimesh(mesh: Mesh, *, with_uv: bool):
    import trimesh  # heavy; only paid when a trimesh format is written

    visual = trimesh.visual.TextureVisuals(uv=mesh.uv) if with_uv and mesh.uv is not None else None
    return trimesh.Trimesh(
        vertices=mesh.vertices,
        faces=mesh.faces,
        vertex_normals=mesh.normals,
        visual=visual,
        process=False,  # keep our vertex order and count: no merging, no reordering
    )


def _write_obj(mesh: Mesh, file_obj: BinaryIO) -> None:
    """Wavefront OBJ: ``v`` and ``vn`` lines, then ``f a//a b//b c//c`` (no uv: it would need a
    material file). Written row by row (numpy's savetxt), not as trimesh does, one string
    formatted in a single call: for a 330,000-vertex mesh that call held the interpreter for
    6.5 s, so a Ctrl-C or a kill waited that long, and it kept the whole text in memory twice."""
    import numpy as np

    file_obj.write(f"# units: {mesh.unit}\n".encode("ascii"))
    np.savetxt(file_obj, mesh.vertices, fmt="v %.8g %.8g %.8g")
    np.savetxt(file_obj, mesh.normals, fmt="vn %.8g %.8g %.8g")
    np.savetxt(file_obj, np.repeat(mesh.faces + 1, 2, axis=1), fmt="f %d//%d %d//%d %d//%d")


def _write_ply(mesh: Mesh, file_obj: BinaryIO) -> None:
    data = _trimesh(mesh, with_uv=False).export(file_type="ply", encoding="binary", vertex_normal=True)
    # a header comment after the format line (the header is ASCII up to end_header)
    after_format = data.index(b"\n", data.index(b"\nformat ") + 1) + 1
    file_obj.write(
        data[:after_format] + f"comment units: {mesh.unit}\n".encode("ascii") + data[after_format:]
    )


def _write_stl(mesh: Mesh, file_obj: BinaryIO) -> None:
    # STL stores one normal per face (from the winding) and no shared vertices; its 80-byte
    # header is free text (not starting with "solid", which would read as ASCII STL)
    data = _trimesh(mesh, with_uv=False).export(file_type="stl")
    header = f"shadeform mesh, units: {mesh.unit}".encode("ascii").ljust(80, b" ")
    file_obj.write(header + data[80:])


def _write_glb(mesh: Mesh, file_obj: BinaryIO) -> None:
    """glTF 2.0 binary (GLB), written by the project: one triangle primitive with ``POSITION``,
    ``NORMAL`` and ``TEXCOORD_0`` (float32; glTF's texture ``v`` runs down the image, so ``1 - v``
    is stored) and ``uint32`` indices, one grey matte material, the unit in ``asset.extras``.

    The arrays are streamed into the file one at a time, so the memory is one float32 copy of one
    array at most (trimesh built the whole file in memory, twice).

    References
    ----------
    .. [1] The Khronos Group, "glTF 2.0 Specification", 2021 (GLB container, accessors).
    """
    import json

    import numpy as np

    if mesh.n_vertices >= 2**32:
        raise InputError(f"a glTF mesh holds fewer than 2**32 vertices; this one has {mesh.n_vertices:,}")
    parts = [
        (lambda: mesh.faces.astype(np.uint32).ravel(), 5125, "SCALAR", 3 * mesh.n_faces, 34963),
        (lambda: mesh.vertices.astype(np.float32), 5126, "VEC3", mesh.n_vertices, 34962),
        (lambda: mesh.normals.astype(np.float32), 5126, "VEC3", mesh.n_vertices, 34962),
    ]
    if mesh.uv is not None:
        parts.append((lambda: _gltf_uv(mesh.uv), 5126, "VEC2", mesh.n_vertices, 34962))
    views, accessors, offset = [], [], 0
    for index, (_, component, kind, count, target) in enumerate(parts):
        length = 4 * count * {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[kind]
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": length, "target": target})
        accessors.append({"bufferView": index, "componentType": component, "count": count, "type": kind})
        offset += length  # every element is 4 bytes: each view stays 4-byte aligned
    # glTF requires the positions' bounds, of the float32 values as stored
    positions = mesh.vertices.astype(np.float32)
    if mesh.n_vertices:
        accessors[1]["min"] = positions.min(axis=0).tolist()
        accessors[1]["max"] = positions.max(axis=0).tolist()
    del positions
    attributes = {"POSITION": 1, "NORMAL": 2}
    if mesh.uv is not None:
        attributes["TEXCOORD_0"] = 3
    tree = {
        "asset": {"version": "2.0", "generator": "shadeform", "extras": {"unit": mesh.unit}},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": 0, "mode": 4, "material": 0}]}],
        "materials": [
            {
                "pbrMetallicRoughness": {
                    "baseColorFactor": [0.4, 0.4, 0.4, 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.9,
                }
            }
        ],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": offset}],
    }
    text = json.dumps(tree, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)  # chunks are 4-byte aligned; JSON pads with spaces
    total = 12 + 8 + len(text) + 8 + offset
    if total >= 2**32:
        raise InputError("the mesh is too large for one glTF binary file (4 GiB); use a larger --step")
    file_obj.write(b"glTF" + (2).to_bytes(4, "little") + total.to_bytes(4, "little"))
    file_obj.write(len(text).to_bytes(4, "little") + b"JSON" + text)
    file_obj.write(offset.to_bytes(4, "little") + b"BIN\x00")
    for make, *_ in parts:
        file_obj.write(memoryview(np.ascontiguousarray(make())).cast("B"))


def _gltf_uv(uv):
    """Texture coordinates in glTF's frame: ``v`` down from the top of the image, float32."""
    import numpy as np

    out = uv.astype(np.float32)
    np.subtract(1.0, out[:, 1], out=out[:, 1])
    return out


#: 3MF's own length units (the core specification's ``ST_Unit``).
UNITS_3MF = ("micron", "millimeter", "centimeter", "inch", "foot", "meter")

_3MF_CONTENT_TYPES = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">\n'
    ' <Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>\n'
    ' <Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>\n'
    "</Types>\n"
)
_3MF_RELATIONSHIPS = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">\n'
    ' <Relationship Target="/3D/3dmodel.model" Id="rel0" '
    'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/>\n'
    "</Relationships>\n"
)
# zip entries past 2 GiB need the zip64 extension, which must be chosen before writing one
_ZIP64_FROM = 1 << 31


def _zip_entry(name: str) -> zipfile.ZipInfo:
    """A compressed zip entry with a fixed date, so that one mesh always makes the same bytes."""
    entry = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    entry.compress_type = zipfile.ZIP_DEFLATED
    return entry


def write_3mf(mesh: Mesh, file_obj: BinaryIO) -> None:
    """Write ``mesh`` as a 3MF package (3D Manufacturing Format, core specification 1.x).

    Parameters
    ----------
    mesh : Mesh
        Triangles; normals and ``uv`` are not stored (3MF has no place for them in its core).
    file_obj : binary file
        Open for writing; a zip archive is written to it.

    Notes
    -----
    The package holds ``[Content_Types].xml``, ``_rels/.rels`` and ``3D/3dmodel.model`` (dated
    1980-01-01, so the bytes depend on the mesh alone): one
    object of type ``model`` with the vertices (``%.9g``) and triangles in the mesh's order,
    and one build item. The model's ``unit`` is the mesh's (``"millimeter"`` for a relief); a mesh
    in pixels is written with ``unit="millimeter"``, one pixel to one millimetre, and says so in
    its ``Description`` metadata. Slicers expect a ``model`` object to be closed: a reconstruction's
    open sheet is flagged by them; :func:`shadeform.relief` makes closed ones.

    References
    ----------
    .. [1] 3MF Consortium, "3MF Core Specification", version 1.3, 2022.
    """
    unit = mesh.unit if mesh.unit in UNITS_3MF else "millimeter"
    note = (
        ""
        if unit == mesh.unit
        else f' <metadata name="Description">coordinates in {mesh.unit}s, written as millimetres '
        f"(one {mesh.unit} to one millimetre)</metadata>\n"
    )
    head = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<model unit="{unit}" xml:lang="en-US" '
        'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">\n'
        ' <metadata name="Application">shadeform</metadata>\n'
        f"{note}"
        " <resources>\n"
        '  <object id="1" type="model">\n'
        "   <mesh>\n"
        "    <vertices>\n"
    )
    middle = "    </vertices>\n    <triangles>\n"
    tail = '    </triangles>\n   </mesh>\n  </object>\n </resources>\n <build>\n  <item objectid="1"/>\n </build>\n</model>\n'
    # about 60 bytes per vertex line and 45 per triangle line: an upper bound of the text's size
    large = 60 * mesh.n_vertices + 45 * mesh.n_faces > _ZIP64_FROM
    with zipfile.ZipFile(file_obj, mode="w", compression=zipfile.ZIP_DEFLATED, compresslevel=5) as package:
        package.writestr(_zip_entry("[Content_Types].xml"), _3MF_CONTENT_TYPES)
        package.writestr(_zip_entry("_rels/.rels"), _3MF_RELATIONSHIPS)
        with package.open(_zip_entry("3D/3dmodel.model"), mode="w", force_zip64=large) as model:
            model.write(head.encode("ascii"))
            model.writelines(format_rows(mesh.vertices, '     <vertex x="%.9g" y="%.9g" z="%.9g"/>\n'))
            model.write(middle.encode("ascii"))
            model.writelines(format_rows(mesh.faces, '     <triangle v1="%d" v2="%d" v3="%d"/>\n'))
            model.write(tail.encode("ascii"))


register(".wrl", write_vrml, description="VRML 2.0 (VRML97), per-vertex normals, texture coords")
register(".iv", write_inventor, description="Open Inventor 2.1 ASCII, per-vertex normals, texture coords")
register(".obj", _write_obj, description="Wavefront OBJ, per-vertex normals")
register(".ply", _write_ply, description="PLY (binary), per-vertex normals")
register(".stl", _write_stl, description="STL (binary), face normals only")
register(".glb", _write_glb, description="glTF 2.0 binary, per-vertex normals, texture coords")
register(".3mf", write_3mf, description="3MF (3D Manufacturing Format), the unit in the file, no normals")
