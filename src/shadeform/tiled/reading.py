"""Reading a huge image window by window: a TIFF through tifffile (never whole), checked first.

Before anything is allocated or any work folder made, the file's header is checked against the
file itself (:func:`shadeform.io.tiffs.check_tiff`): tags of unexpected types, sizes a file of
its size cannot hold, strips or tiles past its end are refused in one line. An uncompressed
TIFF stored in one piece is read through a memory map (a window reads only its rows); any other
through tifffile's Zarr store, which decodes whole strips or tiles: one larger than
:data:`MAX_SEGMENT_BYTES` decoded would be decoded whole for every window, and is refused.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from shadeform.errors import InputError

#: GeoTIFF and GDAL georeferencing tags copied from the input to the depth map: model pixel
#: scale, tie points, transformation, GeoKey directory, its double and ASCII parameters.
GEO_TAGS = (33550, 33922, 34264, 34735, 34736, 34737)
#: Most pixels a tiled input may declare: 2^40, a terapixel (4 TB of float32 depth), beyond
#: any image the tiles could finish; a bound on damaged headers, not on real images.
MAX_TILED_PIXELS = 2**40
#: Largest strip or tile of a compressed TIFF, decoded, in bytes: every window read decodes
#: the strips it touches whole, so one of 256 MiB costs each tile task twice its own memory
#: (about 120 MB for a 512-pixel tile, ``benchmarks/results/tiled.md``).
MAX_SEGMENT_BYTES = 2**28
# Photometric interpretations read as they are: min-is-black gray and RGB.
_PLAIN_PHOTOMETRIC = (1, 2)


class TiffWindows:
    """A TIFF read window by window: a memory map of an uncompressed file stored in one piece,
    else tifffile's Zarr store; what Dask slices lazily.

    Holds the path, not an open file, so it pickles small and every worker process opens the
    file itself (a Zarr store of an open file does not pickle).

    Parameters
    ----------
    path : path-like
        A TIFF or BigTIFF with one 2-D image (gray or ``(H, W, C)`` colour samples, min-is-black
        or RGB).

    Raises
    ------
    InputError
        A missing, unreadable or damaged file, a header the file cannot back (the checks of
        :func:`shadeform.io.tiffs.check_tiff`), an image of another layout, or strips or tiles
        too large to read window by window; all before any pixel is read.
    """

    def __init__(self, path: str | os.PathLike[str]):
        import tifffile

        from shadeform.io.images import ImageTooLargeError
        from shadeform.io.tiffs import check_tiff

        self.path = Path(path)
        try:
            header = check_tiff(self.path, max_pixels=MAX_TILED_PIXELS)
        except ImageTooLargeError:
            raise InputError(
                f"image too large: '{self.path}' declares more than {MAX_TILED_PIXELS:,} pixels, "
                "more than tiles can solve (a damaged file or a decompression bomb); check the file"
            ) from None
        axes, shape = header["axes"], header["shape"]
        if axes == "SYX":
            raise InputError(
                f"'{self.path}' stores its colour planes separately; save it with interleaved "
                "samples (RGB RGB ...) or as gray"
            )
        if header["photometric"] not in _PLAIN_PHOTOMETRIC:
            raise InputError(
                f"'{self.path}' is a TIFF with photometric interpretation {header['photometric']}; "
                "tiles read gray (min-is-black) or RGB: save it as one of those"
            )
        if len(shape) == 3 and shape[2] not in (1, 3, 4):
            raise InputError(
                f"'{self.path}' holds an image of shape {shape}; give one gray or colour image (H, W[, C])"
            )
        try:
            with tifffile.TiffFile(self.path) as tif:
                page = tif.pages.first
                chunks = tuple(int(n) for n in page.chunks)
                self._mapped = bool(page.is_memmappable) and page.compression == 1
                self.tags = {
                    code: (int(page.tags[code].dtype), page.tags[code].count, page.tags[code].value)
                    for code in GEO_TAGS
                    if code in page.tags
                }
        except Exception as err:  # tifffile's own parsing, already checked once: a file changed
            raise InputError(
                f"truncated or damaged TIFF: '{self.path}' cannot be read ({type(err).__name__}); "
                "save or export it again"
            ) from None
        self.shape, self.dtype, self.ndim = shape, np.dtype(header["dtype"]), len(shape)
        segment = int(np.prod(chunks, dtype=np.float64)) * self.dtype.itemsize
        if not self._mapped and segment > MAX_SEGMENT_BYTES:
            raise InputError(
                f"'{self.path}' is stored in strips or tiles of {segment / 2**20:,.0f} MB decoded, "
                "each read whole for every window; save it tiled (e.g. tiles of 512) or "
                "uncompressed to solve it in tiles"
            )
        self._array = None

    def __getstate__(self):
        return {**self.__dict__, "_array": None}

    def __getitem__(self, key) -> np.ndarray:
        if self._array is None:
            import tifffile

            if self._mapped:
                self._array = tifffile.memmap(self.path, mode="r")
            else:
                import zarr

                self._array = zarr.open(tifffile.imread(self.path, aszarr=True), mode="r")
        return np.asarray(self._array[key])


def open_image(path: str | os.PathLike[str]):
    """A TIFF as a lazy Dask array, and its georeferencing tags.

    Parameters
    ----------
    path : path-like
        TIFF, BigTIFF or GeoTIFF.

    Returns
    -------
    image : dask.array.Array
        ``(H, W)`` or ``(H, W, C)``, the file's own type, chunks of 1024 rows and columns; nothing
        is read until it is computed.
    tags : dict
        ``{code: (TIFF datatype, count, value)}`` of the :data:`GEO_TAGS` the file has.

    Raises
    ------
    InputError
        As :class:`TiffWindows`; also if Dask is not installed.
    """
    da = require_dask().array
    windows = TiffWindows(path)
    chunks = (1024, 1024) + windows.shape[2:]
    return da.from_array(windows, chunks=chunks, asarray=False, fancy=False), dict(windows.tags)


def shading(values: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """A window's samples as one linear channel in [0, 1] (``docs/conventions.md``): integers
    by their type's maximum, 8-bit sRGB decoded, colour to luma, alpha dropped."""
    from shadeform.io.images import select_channel
    from shadeform.preprocess import srgb_to_linear

    if np.issubdtype(dtype, np.integer):
        image = values.astype(np.float32) / np.float32(np.iinfo(dtype).max)
        if np.iinfo(dtype).bits <= 8:
            image = srgb_to_linear(image).astype(np.float32)
    else:
        image = values.astype(np.float32)
    if image.ndim == 3:
        image = image[..., 0] if image.shape[2] == 1 else select_channel(image[..., :3], "luma")
    return image


def require_dask():
    """The ``dask`` module, or an InputError naming the extra to install."""
    try:
        import dask
        import dask.array
    except ImportError:
        raise InputError(
            "tiled reconstruction needs Dask; install it with pip install 'shadeform[dask]'"
        ) from None
    return dask
