"""The one decoder: a file, told by its first bytes (never its name), to its samples, and
samples to float pixels.

Every failure while reading a file is an InputError that names it. The checks run in order,
each before anything it guards against is allocated: the file's size
(:mod:`shadeform.io.sources`), then the size, bit depth and layout its header declares
(``max_pixels``), then whether its data could hold that many pixels at all (a 2 KB JPEG cannot
hold 9000x9000: it is damaged or a bomb; :mod:`shadeform.io.headers`, :mod:`shadeform.io.tiffs`),
and only then decoding. Decoding itself writes the float pixels block by block through a lookup
table, so that it never holds more than the file's samples, their float copy and a few small
blocks.
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass, replace
from os import PathLike

import numpy as np
from PIL import Image

from shadeform.errors import InputError
from shadeform.io.colour import srgb_decode
from shadeform.io.headers import (
    _PNG_SIGNATURE,
    TIFF_MAGICS,
    _check_dimensions,
    _check_holds,
    _check_layout,
    _check_pillow_data,
    _check_png,
    _not_an_image,
)
from shadeform.io.sources import _damaged, _decoding, _read_source, _Source, _unsupported
from shadeform.io.tiffs import _MINISWHITE, _PALETTE, _check_tiff_page

_EXIF_ORIENTATION = 0x0112

#: Pillow's formats read here, tried in this order (PNG and TIFF have their own paths, above
#: them); every other format Pillow knows is refused unread. The name each has in messages.
_PILLOW_FORMATS = {"JPEG": "JPEG", "BMP": "BMP", "GIF": "GIF", "WEBP": "WebP", "PPM": "PNM"}

# Rows converted to float per block (bounding the index and float temporaries).
_BLOCK_SAMPLES = 2**20

# Pillow pixel modes: kept as they are, or converted to gray or RGB first (palette through the
# palette, CMYK and YCbCr to RGB, alpha dropped). Other modes are refused from the header.
_PILLOW_KEEP = {"L", "RGB", "I;16", "I;16L", "I;16B", "I;16N"}
_PILLOW_CONVERT = {
    "LA": "L",
    "La": "L",
    "P": "RGB",
    "PA": "RGB",
    "RGBA": "RGB",
    "RGBa": "RGB",
    "RGBX": "RGB",
    "CMYK": "RGB",
    "YCbCr": "RGB",
}


@dataclass(frozen=True, eq=False)
class _Samples:
    """A decoded picture before it becomes float: ``values`` (H, W, C), C in {1, 3}, unsigned
    integers up to ``top`` (``top`` reads as 1.0), or floats already in [0, 1] (``top`` None); or
    (H, W) indices into ``palette`` (N, 3) colours up to ``top``. ``invert``: 0 is white (TIFF)."""

    values: np.ndarray
    bits: int
    top: int | None
    orientation: int = 1
    invert: bool = False
    palette: np.ndarray | None = None


def _decode(path: str | PathLike | bytes, max_pixels: int) -> tuple[_Samples, _Source]:
    """File -> its samples (see :class:`_Samples`) and the checked source it was read from."""
    whole = isinstance(max_pixels, (int, np.integer)) and not isinstance(max_pixels, bool)
    if not whole or max_pixels < 1:
        raise InputError(f"max_pixels must be a positive whole number, got {max_pixels!r}")
    source = _read_source(path, int(max_pixels))
    if source.data.startswith(_PNG_SIGNATURE):
        samples = _decode_png(source, max_pixels)
    elif source.data[:4] in TIFF_MAGICS:
        samples = _decode_tiff(source, max_pixels)
    else:
        samples = _decode_pillow(source, max_pixels)
    return samples, source


# --- from samples to float pixels -------------------------------------------------------------


def _unit(samples: _Samples, *, srgb: bool) -> np.ndarray:
    """Samples -> (H, W, C) float32 in [0, 1], upright, decoded from sRGB if ``srgb``.

    Integer samples go through a table of every value's result (computed with the same float32
    operations as value by value), filled in blocks of rows: no float or index temporary larger
    than a block is ever made."""
    values = samples.values
    if samples.palette is not None:
        table = _unit_table(samples.palette, samples.top, False, srgb)  # (N, 3) colours
        upright = _orient(values, samples.orientation)
        out = np.empty((*upright.shape, 3), np.float32)
    else:
        upright = _orient(values, samples.orientation)
        out = np.empty(upright.shape, np.float32)
        table = None if samples.top is None else _table_for(samples, srgb)
    step = max(1, _BLOCK_SAMPLES // max(1, upright[0].size))
    for start in range(0, upright.shape[0], step):
        block = upright[start : start + step]
        if table is not None:
            np.take(
                table,
                block.view(np.uint8) if block.dtype == bool else block,
                axis=0,
                out=out[start : start + step],
            )
        elif samples.top is None:  # floats, already in [0, 1]
            out[start : start + step] = srgb_decode(block) if srgb else block
        else:  # 32-bit integers: too many values for a table
            unit = np.minimum(block.astype(np.float32) / np.float32(samples.top), np.float32(1.0))
            if samples.invert:
                unit = np.float32(1.0) - unit
            out[start : start + step] = srgb_decode(unit) if srgb else unit
    return out


def _table_for(samples: _Samples, srgb: bool) -> np.ndarray | None:
    """The lookup table of integer samples, or None where their type has too many values."""
    kind, size = samples.values.dtype.kind, samples.values.dtype.itemsize
    if kind == "b" or (kind == "u" and size <= 2):
        count = 2 if kind == "b" else 2 ** (8 * size)
        return _unit_table(np.arange(count), samples.top, samples.invert, srgb)
    return None


def _unit_table(values: np.ndarray, top: int, invert: bool, srgb: bool) -> np.ndarray:
    """float32 results of integer ``values`` read against ``top``: value / top (as float32
    division, exact to float32), clipped to 1 (values past ``top``), 1 - that where ``invert``,
    decoded from sRGB where ``srgb``."""
    unit = np.minimum(values.astype(np.float32) / np.float32(top), np.float32(1.0))
    if invert:
        unit = np.float32(1.0) - unit
    return srgb_decode(unit) if srgb else unit


# --- PNG ---------------------------------------------------------------------------------------


def _decode_png(source: _Source, max_pixels: int) -> _Samples:
    data = source.data
    width, height, depth, exif = _check_png(source, max_pixels)
    orientation = 1
    if exif:
        with _decoding(source, "PNG"):
            found = Image.Exif()
            found.load(exif[0])
            orientation = found.get(_EXIF_ORIENTATION, 1)
    if depth != 16:
        samples = _decode_pillow(source, max_pixels, formats=("PNG",))
        return replace(samples, bits=depth, orientation=_orientation(orientation))
    with _decoding(source, "PNG"):
        values = _png16_decode(data)
    if values.ndim == 2:
        values = values[:, :, None]
    if values.shape[:2] != (height, width) or values.dtype != np.uint16:
        raise InputError(
            f"truncated or damaged PNG: '{source}' decodes to {values.shape} {values.dtype}, "
            f"not {height} x {width} 16-bit; save or export it again"
        )
    return _Samples(_drop_alpha(values), 16, 65535, _orientation(orientation))


def _png16_decode(data: bytes) -> np.ndarray:
    """A 16-bit PNG's samples, (H, W) or (H, W, planes) uint16, decoded by libpng (imagecodecs):
    some 40 times faster than a pure-Python decoder. Imported here, as only 16-bit files need it."""
    from imagecodecs import png_decode

    return png_decode(data)


def _drop_alpha(values: np.ndarray) -> np.ndarray:
    """(H, W, planes) with planes 1-4 -> (H, W, 1) gray or (H, W, 3) RGB (a view)."""
    return values[:, :, :1] if values.shape[2] < 3 else values[:, :, :3]


# --- TIFF --------------------------------------------------------------------------------------


def _decode_tiff(source: _Source, max_pixels: int) -> _Samples:
    import tifffile  # here, not at import: most photos are PNG or JPEG

    with _decoding(source, "TIFF"):
        tif = tifffile.TiffFile(io.BytesIO(source.data))
    try:
        with _decoding(source, "TIFF"):
            page = tif.pages.first
        header = _check_tiff_page(source, page, max_pixels)
        with _decoding(source, "TIFF"):
            values = page.asarray(maxworkers=1)  # one thread: decoder pools multiply memory
    finally:
        tif.close()
    return _tiff_samples(source, header, values)


def _tiff_samples(source: _Source, header: dict, values: np.ndarray) -> _Samples:
    axes, shape, bits = header["axes"], header["shape"], header["bits"]
    photometric, orientation = header["photometric"], _orientation(header["orientation"])
    if values.shape != tuple(shape):
        raise InputError(
            f"truncated or damaged TIFF: '{source}' decodes to {values.shape}, not {tuple(shape)}; "
            "save or export it again"
        )
    if axes == "SYX":
        values = np.moveaxis(values, 0, -1)
    if values.ndim == 2:
        values = values[:, :, None]
    if photometric == _PALETTE:
        colormap = header["colormap"]
        index = values[:, :, 0]
        if int(index.max()) >= colormap.shape[1]:
            raise InputError(
                f"truncated or damaged TIFF: '{source}' indexes past its colour map; save or export it again"
            )
        # Colour maps hold 16-bit R, G, B rows.
        palette = np.ascontiguousarray(colormap.T, dtype=np.uint16)
        return _Samples(index, bits, 65535, orientation, palette=palette)
    values = _drop_alpha(values)
    invert = photometric == _MINISWHITE
    if values.dtype.kind == "f":
        if not np.isfinite(values).all():
            raise InputError(
                f"float TIFF '{source}' contains NaN or infinite values; replace them (e.g. by 0) "
                "and save it again"
            )
        # Float images are taken to be in [0, 1] already.
        unit = np.clip(values, 0.0, 1.0).astype(np.float32, copy=False)
        return _Samples(1.0 - unit if invert else unit, bits, None, orientation)
    if values.dtype.kind == "b":
        return _Samples(values, 1, 1, orientation, invert)
    top = 2 ** min(bits, 8 * values.dtype.itemsize) - 1
    return _Samples(values, bits, top, orientation, invert)


# --- Pillow ------------------------------------------------------------------------------------


def _decode_pillow(source: _Source, max_pixels: int, formats=tuple(_PILLOW_FORMATS)) -> _Samples:
    _check_layout(source, max_pixels)
    image, kind = _pillow_open(source, formats)
    with image:
        with _decoding(source, kind):
            (width, height), mode, tiles = image.size, image.mode, list(image.tile)
        _check_dimensions(source, width, height, max_pixels)
        target, bits = _pillow_target(source, image.format, mode)
        _check_pillow_data(source, kind, width, height, tiles)
        if len(tiles) == 1 and tiles[0][0] == "ppm":
            return _pnm_samples(source, tiles[0], width, height, mode)
        with _decoding(source, kind):
            # ImageFile.LOAD_TRUNCATED_IMAGES is False (Pillow's default): short files raise.
            image.load()
            orientation = image.getexif().get(_EXIF_ORIENTATION, 1)
            # A palette image stays indices and its palette (a quarter of the memory of RGB).
            palette = image.getpalette("RGB") if mode == "P" else None
            if palette is not None:
                values = np.asarray(image)
            else:
                values = np.asarray(image if target is None else image.convert(target))
    if values.shape[:2] != (height, width):
        raise InputError(
            f"truncated or damaged {kind}: '{source}' decodes to {values.shape}, not {height} x "
            f"{width}; save or export it again"
        )
    if mode == "I":  # 16-bit PGM: Pillow holds it in 32 bits, at most 65535
        if values.size and not 0 <= int(values.min()) <= int(values.max()) <= 65535:
            raise InputError(
                f"truncated or damaged {kind}: '{source}' holds samples past 65535; save it again"
            )
        values = values.astype(np.uint16)
    if palette is not None:
        # Pillow reads indices past a short palette as black.
        colours = np.zeros((256, 3), np.uint8)
        given = np.asarray(palette[: len(palette) // 3 * 3], np.uint8).reshape(-1, 3)[:256]
        colours[: len(given)] = given
        return _Samples(values, bits, 255, _orientation(orientation), palette=colours)
    if values.ndim == 2:
        values = values[:, :, None]
    top = 1 if values.dtype == bool else 65535 if bits == 16 else 255
    return _Samples(values, bits, top, _orientation(orientation))


def _pillow_open(source: _Source, formats) -> tuple[Image.Image, str]:
    """Open ``source`` with the first of Pillow's ``formats`` that claims it: this reads the
    header, not the pixels. (``Image.open`` would do the same, but with a second pixel limit of
    its own, ``PIL.Image.MAX_IMAGE_PIXELS``; max_pixels is the one limit here.)"""
    Image.init()
    prefix, failure = source.data[:16], None
    for name in formats:
        opener = Image.OPEN.get(name)
        if opener is None:  # a plugin this Pillow lacks
            continue
        factory, accept = opener
        kind = _PILLOW_FORMATS.get(name, name)
        with _decoding(source, kind):
            claimed = accept(prefix) if accept is not None else True
            if isinstance(claimed, str) or not claimed:
                continue
            try:
                return factory(io.BytesIO(source.data), ""), kind
            except (SyntaxError, IndexError, TypeError, struct.error) as err:
                # Pillow's way of saying "not this format after all": try the next one, and
                # if none takes it, the file had this format's signature with a broken header.
                failure = failure or (kind, err)
    if failure is not None:
        raise _damaged(source, *failure)
    raise _not_an_image(source)


def _pnm_samples(source: _Source, tile, width: int, height: int, mode: str) -> _Samples:
    """A binary PGM or PPM whose largest value is not 255 or 65535 (12-bit data, often), read
    here: Pillow's reader for these rescales in Python, a microsecond a sample. Samples are read
    against that largest value, as the format means them."""
    offset, (_, largest) = tile[2], tile[3]
    planes = 3 if mode == "RGB" else 1
    wide = largest > 255
    count = width * height * planes
    _check_holds(source, "PNM", width, height, offset + count * (2 if wide else 1))
    values = np.frombuffer(source.data, ">u2" if wide else np.uint8, count, offset)
    return _Samples(values.reshape(height, width, planes), 16 if wide else 8, int(largest))


def _pillow_target(source: _Source, fmt: str | None, mode: str) -> tuple[str | None, int]:
    """The mode to convert a Pillow image to (None: keep it), and the file's bits per sample."""
    if mode in _PILLOW_KEEP:
        return None, 16 if mode.startswith("I;16") else 8
    if mode == "1":  # as 0 and 255
        return "L", 1
    if mode in _PILLOW_CONVERT:
        return _PILLOW_CONVERT[mode], 8
    if mode == "I" and fmt == "PPM":
        return None, 16
    if mode in ("I", "F"):
        raise _unsupported(
            source, "holds 32-bit samples of unknown range", "save it as 8- or 16-bit PNG or as a float TIFF"
        )
    raise _unsupported(source, f"holds {mode} pixels", "save it as 8- or 16-bit PNG, RGB or grayscale")


# --- EXIF orientation --------------------------------------------------------------------------


def _orientation(value) -> int:
    """An EXIF or TIFF orientation tag's value as 1-8; anything else reads as 1 (as stored)."""
    if isinstance(value, (tuple, list)) and len(value) == 1:
        value = value[0]
    return int(value) if isinstance(value, (int, np.integer)) and 1 <= value <= 8 else 1


def _orient(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """Apply EXIF orientation 1-8 to (H, W, ...) pixels, as PIL.ImageOps.exif_transpose does."""
    if orientation == 2:
        return pixels[:, ::-1]
    if orientation == 3:
        return pixels[::-1, ::-1]
    if orientation == 4:
        return pixels[::-1]
    if orientation == 5:
        return pixels.swapaxes(0, 1)
    if orientation == 6:
        return np.rot90(pixels, -1)
    if orientation == 7:
        return pixels.swapaxes(0, 1)[::-1, ::-1]
    if orientation == 8:
        return np.rot90(pixels, 1)
    # 1, or a value outside the standard's range: leave the pixels as stored.
    return pixels
