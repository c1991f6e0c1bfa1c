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
    "shown_photo",
    "plain",
    "mesh_data",
    "mesh_file",
    "mesh_bytes",
    "download",
    "format_suffix",
    "display_name",
    "safe_stem",
    "set_stem",
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


def shown_photo(image: np.ndarray, encoding: str | None) -> np.ndarray:
    """The values to show of a photo read as linear ``image``, as a picture viewer shows it.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) float array
        Linear values in [0, 1], as solved on (left unchanged).
    encoding : {"srgb", "linear"} or None
        How the file held its values (``Photo.info["encoding"]``). ``"srgb"`` (8-bit files):
        encoded again, so it looks as the file did (8-bit values come back exactly);
        ``"linear"`` (16-bit and float files, calibrated sets): sRGB-encoded for the screen as
        a raw or HDR viewer shows linear data, not as dark as its numbers read as sRGB would be;
        None (a synthetic example, no file): as is.

    Returns
    -------
    ndarray
        Display values in [0, 1] (:func:`png` makes them 8 bits).
    """
    if encoding not in ("srgb", "linear"):
        return image
    from shadeform.io.images import srgb_encode

    return srgb_encode(np.clip(image, 0.0, 1.0).astype(np.float32))


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
    return _sanitised(stem) or "model"


def _sanitised(text: str) -> str:
    """``text`` with every run of other characters than letters, digits, ``-`` and ``_`` made one
    ``_``, none at the ends, at most 60 characters (may be empty)."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", text).strip("_")[:60].strip("_")


def set_stem(filenames: list[str | None]) -> str:
    """A photo set's download stem, from its photos' file names as uploaded.

    The folder they came from where the names carry one (``catPNG/001.png`` -> ``catPNG``),
    else the part of their names they share, its running numbers left out (``cat_001.png``,
    ``cat_002.png`` -> ``cat``; ``light01_x.png``, ``light02_x.png`` -> ``light_x``), else
    the first photo's stem (DiLiGenT's ``001.png`` ... ``096.png`` -> ``001``); sanitised as
    :func:`safe_stem`, never empty.
    """
    import os.path

    parts = [re.split(r"[/\\]", name or "") for name in filenames]
    folders = {tuple(part[:-1]) for part in parts}
    if len(folders) == 1:
        folder = next(iter(folders))
        if folder and (named := _sanitised(folder[-1])):
            return named
    stems = [name.rsplit(".", 1)[0] if "." in name.lstrip(".") else name for *_, name in parts]
    head = os.path.commonprefix(stems)
    tail = os.path.commonprefix([stem[len(head) :][::-1] for stem in stems])[::-1]
    # the running number's leading digits are in the shared head ("cat_00" of cat_001, cat_002)
    shared = _sanitised(re.sub(r"[\d\W_]+$", "", head) + re.sub(r"^[\d]+", "", tail))
    if len(stems) > 1 and shared:
        return shared
    return safe_stem(stems[0]) if stems else "model"
