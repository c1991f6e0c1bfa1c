"""TIFF headers checked before decoding: the whole-image loader's checks of a TIFF's first page
(:mod:`shadeform.io.decoding`), and :func:`check_tiff` for readers that take a huge TIFF window
by window (:mod:`shadeform.tiled`) and never hold it whole.

The checks run on the first page's tags and the file's size (its content in memory, or its size
on disk): tags of the wrong type or count, sizes, bit depths, layouts and codecs that cannot be
read, pixel data that a file of its size cannot hold (for codecs whose expansion is bounded),
strips or tiles missing or pointing past the file's end.
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

import numpy as np

from shadeform.errors import InputError
from shadeform.io.headers import _TIFF_RATIOS, _check_dimensions, _check_holds
from shadeform.io.sources import _decoding, _Source, _unsupported

__all__ = ["check_tiff"]

# tifffile logs each oddity of a damaged file as a warning, and where nothing configured logging,
# Python prints them all on stderr around our one-line error. A handler that drops them ends that
# fallback; records still reach the handlers of an application that configured logging.
logging.getLogger("tifffile").addHandler(logging.NullHandler())

# TIFF photometric interpretations the TIFF decoder understands; YCbCr only JPEG-compressed,
# which the codec decodes to RGB.
_MINISWHITE, _MINISBLACK, _RGB, _PALETTE, _YCBCR = 0, 1, 2, 3, 6


def check_tiff(path: str | os.PathLike[str], *, max_pixels: int) -> dict:
    """Check a TIFF's first page from its header and the file's size, before any pixel is read.

    Parameters
    ----------
    path : path-like
        A TIFF or BigTIFF file.
    max_pixels : int, keyword-only
        Most pixels the page may declare.

    Returns
    -------
    dict
        The page's header as checked: ``axes`` (``"YX"``, ``"YXS"`` or ``"SYX"``), ``shape``
        (whole numbers), ``dtype``, ``bits``, ``photometric``, ``codec``, ``tile``, ``offsets``
        and ``counts`` of its strips or tiles.

    Raises
    ------
    InputError
        A missing or unreadable file, a folder or device, or a header that cannot be trusted
        (:class:`shadeform.io.images.ImageTooLargeError` for more than ``max_pixels``).
    """
    import tifffile

    path = Path(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        raise InputError(f"file not found: '{path}'; check the path") from None
    except (OSError, ValueError) as err:
        raise InputError(f"cannot read '{path}': {err}; check the path") from None
    if not stat.S_ISREG(info.st_mode):
        raise InputError(f"not a file: '{path}' is a folder or a device; give an image file")
    source = _Source(b"", path, size=info.st_size)
    with _decoding(source, "TIFF"):
        tif = tifffile.TiffFile(path)
    try:
        with _decoding(source, "TIFF"):
            page = tif.pages.first
        return _check_tiff_page(source, page, max_pixels)
    finally:
        tif.close()


def _tiff_header(source: _Source, page) -> dict:
    """What the checks and the decoding need of a TIFF page's tags."""
    with _decoding(source, "TIFF"):
        tag = page.tags.get(274)  # Orientation
        return {
            "axes": page.axes,
            "shape": page.shape,
            "dtype": page.dtype,
            "bits": page.bitspersample,
            "photometric": page.photometric,
            "codec": page.compression,
            "tile": (page.tilelength, page.tilewidth),
            "colormap": page.colormap,
            "orientation": tag.value if tag is not None else 1,
            "offsets": page.dataoffsets,
            "counts": page.databytecounts,
        }


def _check_tiff_page(source: _Source, page, max_pixels: int) -> dict:
    """Every check of a TIFF page before its pixels are decoded; its checked header."""
    header = _tiff_header(source, page)
    _check_tiff_header(source, header, max_pixels)
    with _decoding(source, "TIFF"):
        # Not before the checks: tifffile's chunk layout trusts the tile tags.
        segments = int(np.prod(page.chunked))
    _check_tiff_segments(source, header, segments)
    return header


def _whole(source: _Source, value, what: str) -> int:
    """A TIFF tag's value as one whole number (a tag may hold several, or none)."""
    if isinstance(value, (tuple, list)) and len(value) == 1:
        value = value[0]
    if not isinstance(value, (int, np.integer)):
        raise InputError(
            f"truncated or damaged TIFF: '{source}' has {value!r} as its {what}; save or export it again"
        )
    return int(value)


def _check_tiff_header(source: _Source, header: dict, max_pixels: int) -> None:
    """Refuse from the first page's tags what cannot be read, or would cost more than the file
    could hold, before decoding it."""
    axes, shape = header["axes"], header["shape"]
    if not isinstance(axes, str) or axes not in ("YX", "YXS", "SYX") or len(shape) != len(axes):
        raise _unsupported(
            source, f"is a TIFF with axes {axes} of shape {shape}", "give a single 2-D image (gray or colour)"
        )
    shape = header["shape"] = tuple(_whole(source, n, "image size") for n in shape)
    height, width = shape[axes.index("Y")], shape[axes.index("X")]
    _check_dimensions(source, width, height, max_pixels)
    planes = shape[axes.index("S")] if "S" in axes else 1
    photometric = header["photometric"] = _whole(source, header["photometric"], "photometric interpretation")
    codec = _whole(source, header["codec"], "compression")
    bits = header["bits"] = _whole(source, header["bits"], "bits per sample")
    dtype = header["dtype"]
    if planes > 4:
        raise _unsupported(
            source, f"has {planes} samples per pixel", "save it as gray or RGB (with alpha at most)"
        )
    if not isinstance(dtype, np.dtype) or dtype.kind not in "buf" or not 1 <= bits <= 64:
        raise _unsupported(
            source,
            f"holds {bits}-bit samples of type {dtype}",
            "save it as 8- or 16-bit unsigned or as float",
        )
    if photometric not in (_MINISWHITE, _MINISBLACK, _RGB, _PALETTE) and not (
        photometric == _YCBCR and codec == 7
    ):
        raise _unsupported(
            source, f"is a TIFF with photometric interpretation {photometric}", "save it as RGB or grayscale"
        )
    from tifffile import TIFF

    if codec not in TIFF.DECOMPRESSORS:
        raise _unsupported(
            source, f"is a TIFF compressed with codec {codec}", "save it uncompressed or with deflate"
        )
    colormap = header["colormap"]
    if photometric == _PALETTE and (
        dtype.kind != "u"
        or not isinstance(colormap, np.ndarray)
        or colormap.ndim != 2
        or colormap.shape[0] != 3
        or planes != 1
    ):
        raise InputError(
            f"truncated or damaged TIFF: '{source}' is indexed but has no usable colour map; save or export it again"
        )
    tile_height, tile_width = (_whole(source, n, "tile size") for n in header["tile"])
    if tile_height * tile_width > max(4 * width * height, 2**20):
        raise InputError(
            f"truncated or damaged TIFF: '{source}' declares tiles of {tile_width}x{tile_height} "
            f"pixels for a {width}x{height} image; save or export it again"
        )
    ratio = _TIFF_RATIOS.get(codec)
    if ratio is not None:
        packed = (width * planes * bits + 7) // 8 * height
        _check_holds(source, "TIFF", width, height, packed // ratio)


def _check_tiff_segments(source: _Source, header: dict, segments: int) -> None:
    """Every strip or tile the picture needs must be in the file: tifffile would fill a missing
    one with zeros and return part of a picture."""
    offsets, counts = header["offsets"], header["counts"]
    size = source.length
    whole = all(isinstance(n, (int, np.integer)) for n in (*offsets, *counts))
    if (
        not whole
        or len(offsets) < segments
        or len(counts) < segments
        or any(
            count <= 0 or offset + count > size
            for offset, count in zip(offsets[:segments], counts[:segments])
        )
    ):
        raise InputError(
            f"truncated or damaged TIFF: '{source}' lacks some of the {segments} strips or tiles "
            "its pixels need, or they point past its end; save or export it again"
        )
