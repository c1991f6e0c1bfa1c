"""The one registry of mesh exporters: file suffix -> writer.

:func:`available_formats` is built from the registry, and the tests loop over it, so a format
added with :func:`register` is listed and round-trip tested without further changes.

VRML 2.0 and Open Inventor 2.1 are written by the project (:mod:`shadeform.io.vrml`,
:mod:`shadeform.io.inventor`); OBJ, PLY, STL and glTF binary go through trimesh, imported only
when one of them is written.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write
from shadeform.io.inventor import write_inventor
from shadeform.io.vrml import write_vrml
from shadeform.mesh import Mesh

__all__ = ["Writer", "register", "available_formats", "export"]

Writer = Callable[[Mesh, BinaryIO], None]
"""A writer takes a mesh and a binary file open for writing, writes the whole file, returns None."""

_WRITERS: dict[str, Writer] = {}
_DESCRIPTIONS: dict[str, str] = {}


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
    _WRITERS[suffix] = writer
    _DESCRIPTIONS[suffix] = description


def available_formats() -> dict[str, str]:
    """Formats :func:`export` can write.

    Returns
    -------
    dict of str to str
        Suffix (lower case, with the dot) to a one-line description, in registration order.
    """
    return dict(_DESCRIPTIONS)


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
    writer = _WRITERS.get(suffix)
    if writer is None:
        known = ", ".join(_WRITERS)
        given = f"suffix '{path.suffix}'" if path.suffix else "no suffix"
        raise InputError(f"cannot export '{path.name}': {given}; use one of {known}")
    with atomic_write(path, mode="wb") as file_obj:
        writer(mesh, file_obj)
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
    # no uv: trimesh would reference a material file that export() does not write
    text = _trimesh(mesh, with_uv=False).export(file_type="obj", include_normals=True)
    file_obj.write(text.encode("utf-8"))


def _write_ply(mesh: Mesh, file_obj: BinaryIO) -> None:
    data = _trimesh(mesh, with_uv=False).export(file_type="ply", encoding="binary", vertex_normal=True)
    file_obj.write(data)


def _write_stl(mesh: Mesh, file_obj: BinaryIO) -> None:
    # STL stores one normal per face (from the winding) and no shared vertices
    file_obj.write(_trimesh(mesh, with_uv=False).export(file_type="stl"))


def _write_glb(mesh: Mesh, file_obj: BinaryIO) -> None:
    data = _trimesh(mesh, with_uv=True).export(file_type="glb", include_normals=True)
    file_obj.write(data)


register(".wrl", write_vrml, description="VRML 2.0 (VRML97), per-vertex normals, texture coords")
register(".iv", write_inventor, description="Open Inventor 2.1 ASCII, per-vertex normals, texture coords")
register(".obj", _write_obj, description="Wavefront OBJ, per-vertex normals")
register(".ply", _write_ply, description="PLY (binary), per-vertex normals")
register(".stl", _write_stl, description="STL (binary), face normals only")
register(".glb", _write_glb, description="glTF 2.0 binary, per-vertex normals, texture coords")
