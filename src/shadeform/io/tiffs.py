"""A TIFF's header checked against its file without reading the file: for readers that take a
huge TIFF window by window (:mod:`shadeform.tiled`) and never hold it whole.

The checks are the whole-image loader's (:mod:`shadeform.io.images`), run on the first page's
tags and the file's size on disk instead of its content in memory: tags of the wrong type or
count, sizes, bit depths, layouts and codecs that cannot be read, pixel data that a file of
its size cannot hold (for codecs whose expansion is bounded), strips or tiles missing or
pointing past the file's end.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from shadeform.errors import InputError
from shadeform.io.images import _check_tiff_page, _decoding, _Source

__all__ = ["check_tiff"]


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
