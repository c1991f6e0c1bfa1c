"""How the app's results travel: JSON responses, base64 arrays and PNGs, meshes, downloads, and
the names shown or given to files. Shared by the server's routes for one photo and for photo sets."""

from __future__ import annotations

import base64
import io
import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from fastapi.responses import Response
from starlette.exceptions import HTTPException

from shadeform.app.schema import MeshData

__all__ = [
    "MEDIA_TYPES",
    "PNG_RESPONSES",
    "FILE_RESPONSES",
    "json_response",
    "base64_array",
    "png",
    "png_base64",
    "plain",
    "mesh_data",
    "mesh_file",
    "mesh_bytes",
    "download",
    "format_suffix",
    "display_name",
    "safe_stem",
]

#: Media types of the exported formats; anything else is sent as bytes.
MEDIA_TYPES = {
    ".wrl": "model/vrml",
    ".obj": "model/obj",
    ".stl": "model/stl",
    ".3mf": "model/3mf",
    ".glb": "model/gltf-binary",
}


#: OpenAPI ``responses`` of a route that answers a PNG.
PNG_RESPONSES: dict[int | str, dict] = {200: {"content": {"image/png": {}}, "description": "An 8-bit PNG."}}

#: OpenAPI ``responses`` of a route that answers a mesh file (:func:`download`).
FILE_RESPONSES: dict[int | str, dict] = {
    200: {
        "content": {media: {} for media in (*MEDIA_TYPES.values(), "application/octet-stream")},
        "description": "The mesh file, as a download.",
    }
}


def json_response(model, status_code: int = 200) -> Response:
    return Response(model.model_dump_json(), status_code=status_code, media_type="application/json")


def base64_array(array: np.ndarray, dtype: str) -> str:
    """An array's values as base64 of the packed little-endian ``dtype`` (a typed array's bytes)."""
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def png(image: np.ndarray) -> bytes:
    """An (H, W) or (H, W, 3) image in [0, 1] as an 8-bit PNG (fast compression: it is local)."""
    from PIL import Image

    samples = np.rint(np.clip(image, 0.0, 1.0) * 255).astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(samples).save(buffer, format="PNG", compress_level=1)
    return buffer.getvalue()


def png_base64(image: np.ndarray) -> str:
    """:func:`png` as base64 text, for a JSON field."""
    return base64.b64encode(png(image)).decode("ascii")


def plain(value: Any) -> Any:
    """JSON types only (numpy scalars and arrays, tuples -> numbers and lists)."""
    if isinstance(value, dict):
        return {str(key): plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [plain(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def mesh_data(mesh) -> MeshData:
    """A :class:`shadeform.mesh.Mesh` as the client's typed arrays (``uvs`` empty for a mesh
    without texture coordinates)."""
    return MeshData(
        vertex_count=mesh.n_vertices,
        triangle_count=mesh.n_faces,
        positions=base64_array(mesh.vertices, "<f4"),
        normals=base64_array(mesh.normals, "<f4"),
        uvs="" if mesh.uv is None else base64_array(mesh.uv, "<f4"),
        indices=base64_array(mesh.faces, "<u4"),
    )


def mesh_file(reconstruction, step: int, suffix: str) -> bytes:
    """A reconstruction's mesh, at ``step`` pixels per vertex, as a file of the registry's format."""
    from shadeform import to_mesh

    return mesh_bytes(to_mesh(reconstruction, step=step), suffix)


def mesh_bytes(mesh, suffix: str) -> bytes:
    """A :class:`shadeform.mesh.Mesh` as a file of the registry's format (``suffix``)."""
    from shadeform import export

    with tempfile.TemporaryDirectory(prefix="shadeform-export-") as folder:
        # the file name is ours: a fixed stem and a suffix from the registry
        path = export(mesh, Path(folder) / f"model{suffix}")
        return path.read_bytes()


def download(data: bytes, name: str, suffix: str) -> Response:
    """A mesh file as a download named after ``name`` (sanitised) with the format's suffix."""
    return Response(
        data,
        media_type=MEDIA_TYPES.get(suffix, "application/octet-stream"),
        headers={"Content-Disposition": f'attachment; filename="{safe_stem(name) + suffix}"'},
    )


def format_suffix(text: str, formats: dict[str, str]) -> str:
    """The registry's suffix a client named (``glb``, ``.GLB``...); 422 for another."""
    suffix = text.strip().lower()
    suffix = suffix if suffix.startswith(".") else "." + suffix
    if suffix not in formats:
        shown = text if len(text) <= 20 else text[:17] + "..."
        raise HTTPException(422, f"unknown export format {shown!r}; choose one of: {', '.join(formats)}")
    return suffix


def display_name(filename: str | None) -> str:
    """A file name to show: no folders, no control characters, at most 100 characters."""
    name = re.split(r"[/\\]", filename or "")[-1]
    name = "".join(ch for ch in name if ch.isprintable()).strip()
    return name[:100] or "image"


def safe_stem(name: str) -> str:
    """A download's file stem: letters, digits, ``-`` and ``_`` only, never empty."""
    stem = name.rsplit(".", 1)[0] if "." in name.lstrip(".") else name
    stem = re.sub(r"[^A-Za-z0-9_-]+", "_", stem).strip("_")
    return stem[:60] or "model"
