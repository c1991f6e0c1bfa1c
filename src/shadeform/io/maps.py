"""Normal maps (16-bit PNG) and depth maps (float TIFF or .npy) in and out.

Normal maps use the OpenGL convention of ``docs/conventions.md``: ``RGB = (n + 1) / 2`` in the
camera frame (x right, y up, z toward the viewer), scaled to 16 bits. Pixels without a normal
are written as black ``(0, 0, 0)``, which no unit normal can produce (it would decode to
``(-1, -1, -1)``), and are read back as NaN.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import png

from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write

__all__ = ["save_normal_map", "load_normal_map", "save_depth", "load_depth", "BACKGROUND_RGB"]

BACKGROUND_RGB = (0, 0, 0)
"""Pixel value written where the normal is NaN (outside the mask)."""

_UNIT_TOLERANCE = 1e-3
_DEPTH_SUFFIXES = (".tif", ".tiff", ".npy")


def _check_png_suffix(path: Path) -> None:
    if path.suffix.lower() != ".png":
        raise InputError(f"normal maps are PNG files; rename '{path.name}' to end in .png")


def save_normal_map(normals: np.ndarray, path: str | os.PathLike[str]) -> Path:
    """Write unit normals as a 16-bit RGB PNG, ``RGB = round((n + 1) / 2 * 65535)``.

    Parameters
    ----------
    normals : (H, W, 3) float
        Unit normals in the camera frame; NaN (any component) where there is no normal.
    path : str or path-like
        A ``.png`` file, written atomically.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        If the shape is wrong, a finite normal is not of unit length (within 1e-3), or the
        suffix is not ``.png``.

    Notes
    -----
    16 bits quantise each component to 3e-5, an angular error below 0.003 degrees. Pixels
    with a NaN component are written as :data:`BACKGROUND_RGB`.
    """
    normals = np.asarray(normals, dtype=np.float64)
    path = Path(path)
    _check_png_suffix(path)
    if normals.ndim != 3 or normals.shape[2] != 3 or 0 in normals.shape:
        raise InputError(f"normals must have shape (H, W, 3), got {normals.shape}")
    missing = np.isnan(normals).any(axis=2)
    present = normals[~missing]
    if not np.isfinite(present).all():
        raise InputError("normals contain inf; give unit vectors, or NaN where there is none")
    lengths = np.linalg.norm(present, axis=1)
    if present.size and np.abs(lengths - 1.0).max() > _UNIT_TOLERANCE:
        raise InputError(
            f"normals must be unit vectors, found lengths "
            f"{lengths.min():.4g}..{lengths.max():.4g}; normalise them first"
        )

    encoded = np.rint((np.clip(normals, -1.0, 1.0) + 1.0) * (65535 / 2.0))
    encoded[missing] = BACKGROUND_RGB
    # PNG stores 16-bit samples big-endian; pack rows ourselves so pypng does no per-pixel work
    packed = encoded.astype(">u2").reshape(normals.shape[0], -1)
    writer = png.Writer(width=normals.shape[1], height=normals.shape[0], greyscale=False, bitdepth=16)
    with atomic_write(path) as file_obj:
        writer.write_packed(file_obj, (row.tobytes() for row in packed))
    return path


def save_gray(image: np.ndarray, path: str | os.PathLike[str], *, bitdepth: int = 16) -> Path:
    """Write a one-channel image in [0, 1] (a photo, a mask), or a colour one, as an 8- or 16-bit
    PNG.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) float
        Values in [0, 1]; outside that range they are clipped. A bool mask gives 0 and full white.
        Three channels give an RGB PNG (a colour albedo).
    path : str or path-like
        A ``.png`` file, written atomically.
    bitdepth : {8, 16}, keyword-only
        Bits per sample.

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    _check_png_suffix(path)
    if bitdepth not in (8, 16):
        raise InputError(f"bitdepth must be 8 or 16, got {bitdepth!r}")
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 2 and image.shape[2:] != (3,):
        raise InputError(f"an image to save must be (H, W) or (H, W, 3), got shape {image.shape}")
    top = 2**bitdepth - 1
    samples = np.rint(np.clip(image, 0.0, 1.0) * top).astype(">u2" if bitdepth == 16 else np.uint8)
    writer = png.Writer(
        width=image.shape[1], height=image.shape[0], greyscale=image.ndim == 2, bitdepth=bitdepth
    )
    with atomic_write(path) as file_obj:
        writer.write_packed(file_obj, (row.tobytes() for row in samples))
    return path


def _read_png(path: Path) -> tuple[np.ndarray, int]:
    """Pixels ``(H, W, planes)`` as unsigned integers and the bit depth."""
    if not path.is_file():
        raise InputError(f"normal map '{path}' does not exist; check the path")
    from imagecodecs import PngError, png_decode  # libpng: fast for 16-bit maps

    try:
        pixels = png_decode(path.read_bytes())
    except (PngError, ValueError):
        raise InputError(f"'{path.name}' is not a readable PNG; give a PNG normal map") from None
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    return pixels, 16 if pixels.dtype == np.uint16 else 8


def load_normal_map(path: str | os.PathLike[str], *, mask: np.ndarray | None = None) -> np.ndarray:
    """Read a normal map PNG (8 or 16 bits, OpenGL convention) into unit normals.

    Parameters
    ----------
    path : str or path-like
        RGB or RGBA PNG with ``RGB = (n + 1) / 2``; alpha is ignored.
    mask : (H, W) bool, optional, keyword-only
        Object pixels; normals outside it become NaN.

    Returns
    -------
    normals : (H, W, 3) float64
        Unit normals, renormalised after decoding; NaN where the pixel is black
        (:data:`BACKGROUND_RGB`), outside ``mask``, or decodes to a zero vector.

    Raises
    ------
    InputError
        If the file is missing, not a PNG, not RGB, or ``mask`` has another shape.
    """
    path = Path(path)
    pixels, bitdepth = _read_png(path)
    if pixels.shape[2] < 3:
        raise InputError(f"'{path.name}' is a grey image; a normal map needs RGB channels")
    rgb = pixels[..., :3]
    normals = rgb * (2.0 / (2**bitdepth - 1)) - 1.0
    lengths = np.linalg.norm(normals, axis=2, keepdims=True)
    empty = (rgb == 0).all(axis=2) | (lengths[..., 0] == 0)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != empty.shape:
            raise InputError(f"mask has shape {mask.shape} but the normal map {empty.shape}; they must match")
        empty |= ~mask
    with np.errstate(invalid="ignore", divide="ignore"):
        normals /= lengths
    normals[empty] = np.nan
    return normals


def _depth_suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in _DEPTH_SUFFIXES:
        raise InputError(f"cannot handle depth file '{path.name}'; use a name ending in .tif, .tiff or .npy")
    return suffix


def save_depth(depth: np.ndarray, path: str | os.PathLike[str]) -> Path:
    """Write a depth map: 32-bit float TIFF (``.tif``, ``.tiff``) or NumPy ``.npy``.

    Parameters
    ----------
    depth : (H, W) float
        Height in pixel units, NaN outside the object (kept as NaN in the file).
    path : str or path-like
        Written atomically; the suffix picks the format.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        If ``depth`` is not 2-D or the suffix is not one of the above.

    Notes
    -----
    TIFF is float32 (what image tools such as GIMP, ImageJ and QGIS read; 24-bit mantissa,
    1e-4 pixel at a depth of 1000); ``.npy`` keeps float64, lossless.
    """
    path = Path(path)
    suffix = _depth_suffix(path)
    depth = np.asarray(depth, dtype=np.float64)
    if depth.ndim != 2 or 0 in depth.shape:
        raise InputError(f"depth must have shape (H, W), got {depth.shape}")
    with atomic_write(path) as file_obj:
        if suffix == ".npy":
            np.save(file_obj, depth, allow_pickle=False)
        else:
            import tifffile  # here, not at import: most commands write no TIFF

            tifffile.imwrite(file_obj, depth.astype(np.float32), photometric="minisblack")
    return path


def load_depth(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a depth map written by :func:`save_depth` (or any 2-D float TIFF / ``.npy``).

    Parameters
    ----------
    path : str or path-like
        ``.tif``, ``.tiff`` or ``.npy``.

    Returns
    -------
    depth : (H, W) float64

    Raises
    ------
    InputError
        If the file is missing, of another format, or not a single 2-D array.
    """
    import tifffile

    path = Path(path)
    suffix = _depth_suffix(path)
    if not path.is_file():
        raise InputError(f"depth file '{path}' does not exist; check the path")
    try:
        if suffix == ".npy":
            depth = np.load(path, allow_pickle=False)
        else:
            depth = tifffile.imread(path)
    except (ValueError, EOFError, tifffile.TiffFileError):
        raise InputError(
            f"'{path.name}' is not a readable depth map; give a file written by save_depth"
        ) from None
    if not isinstance(depth, np.ndarray) or depth.ndim != 2:
        is_array = isinstance(depth, np.ndarray)
        held = f"an array of shape {depth.shape}" if is_array else "several arrays"
        raise InputError(f"'{path.name}' holds {held}; a depth map is one (H, W) array")
    return depth.astype(np.float64)
