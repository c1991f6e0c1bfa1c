"""Read photos and masks into arrays, keeping every bit the file holds.

One internal decoder turns a file into an ``(H, W, C)`` float32 array in ``[0, 1]`` with ``C = 1``
(gray) or ``C = 3`` (colour); :func:`load_image` picks one channel from it, :func:`load_image_rgb`
keeps the colour for texturing, :func:`load_mask` keeps the non-zero pixels. :func:`load_pixels`
keeps the array as stored (gray or colour) for :func:`select_channel` to pick from later. The
readers take a path or the file's content as ``bytes`` (an upload, decoded from memory).

Decoders, chosen by the file's first bytes (never its name):

- PNG: 16-bit files through ``pypng`` (Pillow would silently drop 16-bit RGB to 8 bits), the rest
  through Pillow. The whole chunk structure and every CRC is checked first, so a truncated or
  damaged file raises instead of returning part of a picture.
- TIFF: ``tifffile`` (8-, 16-, 32-bit unsigned and float samples). A TIFF compressed with a codec
  that ``tifffile`` only has through the optional ``imagecodecs`` package (LZW, JPEG, ...) is read
  by Pillow when its samples are 8-bit or less, and refused otherwise.
- Anything else Pillow reads (JPEG, BMP, GIF, WebP, ...): Pillow, with truncated files refused.

Conventions (``docs/conventions.md``): 16-bit samples become ``value / 65535`` exactly, 8-bit
ones ``value / 255``; EXIF orientation is applied; palette images become RGB through their
palette; alpha is ignored.
"""

from __future__ import annotations

import io
import struct
import warnings
import zlib
from os import PathLike
from pathlib import Path

import numpy as np
import png
import tifffile
from PIL import Image, UnidentifiedImageError

from shadeform.errors import InputError

__all__ = [
    "load_image",
    "load_image_rgb",
    "load_mask",
    "load_pixels",
    "select_channel",
    "ImageTooLargeError",
    "CHANNELS",
]

#: Channel names accepted by :func:`load_image`.
CHANNELS = ("luma", "r", "g", "b", "max")

# Rec. 601 luma weights (docs/conventions.md).
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)

# Shape from shading needs a pixel and its neighbours on every side.
_MIN_SIDE = 3

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")

#: What a file's content, given as bytes instead of a path, is called in messages.
_MEMORY_NAME = "image data"
_EXIF_ORIENTATION = 0x0112

# TIFF photometric interpretations the TIFF decoder understands.
_MINISWHITE, _MINISBLACK, _RGB, _PALETTE = 0, 1, 2, 3


class ImageTooLargeError(InputError):
    """An image with more pixels than allowed (``max_pixels`` or Pillow's bomb guard).

    A subclass of :class:`shadeform.InputError`, so that a caller can tell "too large" from
    "not an image" (the app answers 413 to one and 415 to the other).
    """


def load_image(
    path: str | PathLike | bytes, *, channel: str = "luma", max_pixels: int = 250_000_000
) -> np.ndarray:
    """Read a photo as one channel of intensities.

    Parameters
    ----------
    path : str, path-like or bytes
        A PNG, JPEG, TIFF or BMP file (other formats Pillow reads work too): 1-, 8- or 16-bit,
        gray, gray + alpha, RGB, RGBA or palette; float TIFFs are taken to hold values in
        ``[0, 1]`` and are clipped to it. ``bytes`` (or ``bytearray``, ``memoryview``) are the
        content of such a file, already in memory (e.g. an upload).
    channel : {"luma", "r", "g", "b", "max"}
        Which intensity to return for a colour image: Rec. 601 luma
        ``0.299 R + 0.587 G + 0.114 B``, one of the colour channels, or the largest of R, G, B.
        A gray image returns its gray values for every choice.
    max_pixels : int
        Refuse images that declare more pixels than this, before decoding anything (guards against
        corrupt files and decompression bombs). For files Pillow decodes, Pillow's own limit
        ``PIL.Image.MAX_IMAGE_PIXELS`` applies as well.

    Returns
    -------
    (H, W) float32
        Intensities in ``[0, 1]``, row 0 at the top of the upright (EXIF-rotated) picture;
        16-bit samples are ``value / 65535`` and 8-bit ones ``value / 255``.

    Raises
    ------
    InputError
        If the file is missing, empty, not an image, truncated or damaged, smaller than 3x3 or
        larger than ``max_pixels``, holds NaN or infinite samples, or ``channel`` is unknown.

    Examples
    --------
    >>> image = load_image("photo.png", channel="g")  # doctest: +SKIP
    >>> image.shape, image.dtype  # doctest: +SKIP
    ((512, 612), dtype('float32'))
    """
    _check_channel(channel)
    return select_channel(_decode(path, max_pixels), channel)


def load_pixels(path: str | PathLike | bytes, *, max_pixels: int = 250_000_000) -> np.ndarray:
    """Read a photo as it is stored: gray stays one channel, colour keeps three.

    For a caller that picks channels later, again and again, without decoding again (the app
    keeps this array and calls :func:`select_channel` per request).

    Parameters
    ----------
    path : str, path-like or bytes
        Any file :func:`load_image` reads, or its content.
    max_pixels : int
        As in :func:`load_image`.

    Returns
    -------
    (H, W, C) float32
        ``C = 1`` for gray files, ``C = 3`` (R, G, B) for colour ones; values in ``[0, 1]``.

    Raises
    ------
    InputError
        As :func:`load_image`; :class:`ImageTooLargeError` if the image has too many pixels.
    """
    return _decode(path, max_pixels)


def select_channel(pixels: np.ndarray, channel: str = "luma") -> np.ndarray:
    """One channel of intensities from a gray or colour picture.

    Parameters
    ----------
    pixels : (H, W), (H, W, 1) or (H, W, 3) float32
        E.g. from :func:`load_pixels`; values in ``[0, 1]``.
    channel : {"luma", "r", "g", "b", "max"}
        As in :func:`load_image`; a gray picture returns its gray values for every choice.

    Returns
    -------
    (H, W) float32
        The same values :func:`load_image` returns for the file ``pixels`` came from.

    Raises
    ------
    InputError
        If ``channel`` is unknown or ``pixels`` is not one of those shapes.
    """
    _check_channel(channel)
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        return pixels
    if pixels.ndim != 3 or pixels.shape[2] not in (1, 3):
        raise InputError(
            f"pixels must have shape (H, W), (H, W, 1) or (H, W, 3), got {pixels.shape}; "
            "read them with load_pixels"
        )
    if pixels.shape[2] == 1:
        return np.ascontiguousarray(pixels[:, :, 0])
    if channel == "luma":
        # Weights sum to 1, but float rounding may step just past it.
        return np.clip(pixels @ _LUMA, 0.0, 1.0)
    if channel == "max":
        return pixels.max(axis=2)
    return np.ascontiguousarray(pixels[:, :, "rgb".index(channel)])


def _check_channel(channel) -> None:
    if not isinstance(channel, str) or channel not in CHANNELS:
        raise InputError(f"unknown channel {channel!r}; choose one of {', '.join(map(repr, CHANNELS))}")


def load_image_rgb(path: str | PathLike | bytes, *, max_pixels: int = 250_000_000) -> np.ndarray:
    """Read a photo in colour, e.g. to texture a mesh with it.

    Parameters
    ----------
    path : str, path-like or bytes
        Any file :func:`load_image` reads, or its content.
    max_pixels : int
        As in :func:`load_image`.

    Returns
    -------
    (H, W, 3) float32
        R, G, B in ``[0, 1]``; a gray image has its values in all three channels.

    Raises
    ------
    InputError
        As :func:`load_image`.
    """
    pixels = _decode(path, max_pixels)
    if pixels.shape[2] == 1:
        return np.repeat(pixels, 3, axis=2)
    return pixels


def load_mask(path: str | PathLike, *, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Read an object mask: every non-zero pixel (in any channel) belongs to the object.

    Parameters
    ----------
    path : str or path-like
        Any file :func:`load_image` reads; typically black background, white object. Label
        images that store the object as 1 work too (any non-zero value counts).
    shape : tuple of int, optional
        The image's shape ``(H, W)`` or ``(H, W, C)``; the mask must have the same ``H`` and ``W``.

    Returns
    -------
    (H, W) bool
        True on the object.

    Raises
    ------
    InputError
        If the file cannot be read as an image (see :func:`load_image`), its size differs from
        ``shape``, or it has no non-zero pixel.
    """
    mask = (_decode(path, 250_000_000) > 0).any(axis=2)
    if shape is not None:
        height, width = (int(n) for n in tuple(shape)[:2])
        if mask.shape != (height, width):
            raise InputError(
                f"mask is {mask.shape[1]}x{mask.shape[0]} but the image is {width}x{height} "
                "(width x height); give a mask of the image's size"
            )
    if not mask.any():
        raise InputError(
            f"empty mask: no pixel of '{path}' is non-zero; paint the object in a non-zero colour"
        )
    return mask


# --- the one decoder -------------------------------------------------------------------------


class _Memory:
    """A file's content held in memory; named in messages as a path would be."""

    def __init__(self, data: bytes) -> None:
        self.data = data

    def __str__(self) -> str:
        return _MEMORY_NAME


_Source = Path | _Memory


def _open(source: _Source):
    """A binary file object reading ``source`` from its start (every decoder reads it anew)."""
    return io.BytesIO(source.data) if isinstance(source, _Memory) else open(source, "rb")


def _decode(path: str | PathLike | bytes, max_pixels: int) -> np.ndarray:
    """File -> (H, W, C) float32 in [0, 1], C in {1, 3}, upright (EXIF orientation applied)."""
    whole = isinstance(max_pixels, (int, np.integer)) and not isinstance(max_pixels, bool)
    if not whole or max_pixels < 1:
        raise InputError(f"max_pixels must be a positive whole number, got {max_pixels!r}")
    path = _existing_file(path)
    with _open(path) as fh:
        head = fh.read(33)
    if head.startswith(_PNG_SIGNATURE):
        pixels, orientation = _decode_png(path, head, max_pixels)
    elif head[:4] in _TIFF_MAGICS:
        pixels, orientation = _decode_tiff(path, max_pixels)
    else:
        pixels, orientation = _decode_pillow(path, max_pixels)
    return np.ascontiguousarray(_orient(pixels, orientation))


def _existing_file(path: str | PathLike | bytes) -> _Source:
    if isinstance(path, (bytes, bytearray, memoryview)):
        if len(path) == 0:
            raise InputError(f"empty file: the {_MEMORY_NAME} has 0 bytes; give an image file")
        return _Memory(bytes(path))
    path = Path(path)
    if not path.exists():
        raise InputError(f"file not found: '{path}'; check the path")
    if not path.is_file():
        raise InputError(f"not a file: '{path}' is a folder or a device; give an image file")
    if path.stat().st_size == 0:
        raise InputError(f"empty file: '{path}' has 0 bytes; give an image file")
    return path


def _check_dimensions(path: _Source, width: int, height: int, max_pixels: int) -> None:
    """Refuse absurd declared sizes before any pixel is decoded."""
    if width * height > max_pixels:
        raise ImageTooLargeError(
            f"image too large: '{path}' declares {width}x{height} = {width * height:,} pixels, "
            f"more than max_pixels={max_pixels:,} (a damaged file or a decompression bomb); "
            "crop or downscale it, or raise max_pixels if you trust the file"
        )
    if width < _MIN_SIDE or height < _MIN_SIDE:
        raise InputError(
            f"image too small: '{path}' is {width}x{height} pixels; shape from shading needs at "
            f"least {_MIN_SIDE}x{_MIN_SIDE} pixels"
        )


def _damaged(path: _Source, kind: str, err: BaseException) -> InputError:
    reason = " ".join(str(err).split()) or type(err).__name__
    return InputError(
        f"truncated or damaged {kind}: '{path}' could not be decoded ({reason}); "
        "save or download the file again"
    )


def _not_an_image(path: _Source) -> InputError:
    return InputError(
        f"not an image: '{path}' could not be decoded as PNG, JPEG, TIFF or BMP; give a photo file"
    )


def _unsigned_to_unit(samples: np.ndarray, bits: int) -> np.ndarray:
    """Unsigned integer samples of ``bits`` significant bits -> float32 value / (2**bits - 1)."""
    # float32 division is correctly rounded, so value / 65535 is exact to float32 precision.
    return samples.astype(np.float32) / np.float32(2**bits - 1)


def _drop_alpha(samples: np.ndarray) -> np.ndarray:
    """(H, W, planes) with planes 1-4 -> (H, W, 1) gray or (H, W, 3) RGB."""
    return samples[:, :, :1] if samples.shape[2] < 3 else samples[:, :, :3]


# --- PNG ---------------------------------------------------------------------------------------


def _decode_png(path: _Source, head: bytes, max_pixels: int) -> tuple[np.ndarray, int]:
    if len(head) < 33 or head[12:16] != b"IHDR":
        raise InputError(f"truncated or damaged PNG: '{path}' has no IHDR header; save or download it again")
    width, height, bitdepth = struct.unpack(">IIB", head[16:25])
    _check_dimensions(path, width, height, max_pixels)
    orientation = _png_orientation(path)
    if bitdepth != 16:
        pixels, _ = _decode_pillow(path, max_pixels)
        return pixels, orientation
    samples = _decode_png16(path)
    if samples.ndim == 2:
        samples = samples[:, :, None]
    if samples.shape[:2] != (height, width) or samples.dtype != np.uint16:
        raise InputError(
            f"truncated or damaged PNG: '{path}' decodes to {samples.shape} {samples.dtype}, "
            f"not {height} x {width} 16-bit; save or download the file again"
        )
    return _unsigned_to_unit(_drop_alpha(samples), 16), orientation


def _decode_png16(path: _Source) -> np.ndarray:
    """A 16-bit PNG's samples, (H, W) or (H, W, planes) uint16, decoded by libpng (imagecodecs):
    some 40 times faster than a pure-Python decoder. Imported here, as only 16-bit files need it."""
    from imagecodecs import PngError, png_decode

    try:
        with _open(path) as fh:
            return png_decode(fh.read())
    except (PngError, ValueError) as err:
        raise _damaged(path, "PNG", err) from None


def _png_orientation(path: _Source) -> int:
    """Check every chunk (lengths, CRCs, IEND) and return the eXIf orientation (1 if none)."""
    orientation = 1
    try:
        with _open(path) as fh:
            for kind, data in png.Reader(file=fh).chunks():
                if kind == b"eXIf":
                    exif = Image.Exif()
                    exif.load(data)
                    orientation = exif.get(_EXIF_ORIENTATION, 1)
    except (png.Error, struct.error, SyntaxError, ValueError) as err:
        raise _damaged(path, "PNG", err) from None
    return orientation


# --- TIFF --------------------------------------------------------------------------------------


def _decode_tiff(path: _Source, max_pixels: int) -> tuple[np.ndarray, int]:
    try:
        with _open(path) as fh, tifffile.TiffFile(fh) as tif:
            page = tif.pages.first
            axes, shape = page.axes, page.shape
            bits, fmt = page.bitspersample, page.sampleformat
            photometric, codec = int(page.photometric), page.compression
            colormap = page.colormap
            tag = page.tags.get(274)  # Orientation
            orientation = int(tag.value) if tag is not None else 1
            if axes not in ("YX", "YXS", "SYX"):
                raise InputError(
                    f"unsupported TIFF layout: '{path}' has axes {axes} of shape {shape}; "
                    "give a single 2-D image (gray or colour)"
                )
            height, width = shape[axes.index("Y")], shape[axes.index("X")]
            _check_dimensions(path, width, height, max_pixels)
            if codec not in tifffile.TIFF.DECOMPRESSORS:
                readable_by_pillow = bits <= 8 and fmt == 1
                if not readable_by_pillow:
                    raise InputError(
                        f"unsupported TIFF compression: '{path}' uses {codec.name} with "
                        f"{bits}-bit samples, which needs the 'imagecodecs' package; install it "
                        "or save the TIFF uncompressed or with deflate"
                    )
            else:
                samples = page.asarray()
    except InputError:
        raise
    except (tifffile.TiffFileError, ValueError, KeyError, zlib.error, struct.error, OSError) as err:
        raise _damaged(path, "TIFF", err) from None
    if codec not in tifffile.TIFF.DECOMPRESSORS:
        # 8-bit data loses nothing in Pillow, which has the common codecs built in.
        pixels, _ = _decode_pillow(path, max_pixels)
        return pixels, orientation

    if axes == "SYX":
        samples = np.moveaxis(samples, 0, -1)
    if samples.ndim == 2:
        samples = samples[:, :, None]
    pixels = _tiff_samples_to_unit(path, samples, bits, photometric, colormap)
    return pixels, orientation


def _tiff_samples_to_unit(
    path: _Source, samples: np.ndarray, bits: int, photometric: int, colormap: np.ndarray | None
) -> np.ndarray:
    if photometric not in (_MINISWHITE, _MINISBLACK, _RGB, _PALETTE):
        raise InputError(
            f"unsupported TIFF colour space: '{path}' uses photometric interpretation "
            f"{photometric}; save it as RGB or grayscale"
        )
    if photometric == _PALETTE:
        if colormap is None:
            raise InputError(f"truncated or damaged TIFF: '{path}' is indexed but has no colour map")
        index = samples[:, :, 0].astype(np.intp)
        if index.max() >= colormap.shape[1]:
            raise InputError(
                f"truncated or damaged TIFF: '{path}' indexes past its colour map; save it again"
            )
        # Colour maps hold 16-bit R, G, B rows.
        return _unsigned_to_unit(np.moveaxis(colormap[:, index], 0, -1), 16)

    samples = _drop_alpha(samples)
    kind = samples.dtype.kind
    if kind == "b":
        pixels = samples.astype(np.float32)
    elif kind == "u":
        pixels = _unsigned_to_unit(samples, bits)
    elif kind == "f":
        if not np.isfinite(samples).all():
            raise InputError(
                f"float TIFF '{path}' contains NaN or infinite values; replace them (e.g. by 0) "
                "and save it again"
            )
        # Float images are taken to be in [0, 1] already.
        pixels = np.clip(samples, 0.0, 1.0).astype(np.float32)
    else:
        raise InputError(
            f"unsupported TIFF sample type: '{path}' holds {samples.dtype} samples; "
            "save it as 8- or 16-bit unsigned or as float"
        )
    if photometric == _MINISWHITE:
        pixels = 1.0 - pixels
    return pixels


# --- Pillow ------------------------------------------------------------------------------------


def _decode_pillow(path: _Source, max_pixels: int) -> tuple[np.ndarray, int]:
    try:
        # Pillow warns about large images and only raises past twice its limit; refuse both.
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with _open(path) as fh, Image.open(fh) as image:
                _check_dimensions(path, *image.size, max_pixels)
                # ImageFile.LOAD_TRUNCATED_IMAGES is False (Pillow's default): short files raise.
                image.load()
                orientation = image.getexif().get(_EXIF_ORIENTATION, 1)
                pixels = _pillow_pixels(path, image)
    except UnidentifiedImageError:
        raise _not_an_image(path) from None
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise ImageTooLargeError(
            f"image too large: '{path}' has more pixels than Pillow's limit of "
            f"{Image.MAX_IMAGE_PIXELS:,} (a guard against decompression bombs); downscale it, "
            "or raise PIL.Image.MAX_IMAGE_PIXELS if you trust the file"
        ) from None
    except (OSError, SyntaxError, EOFError, struct.error, zlib.error) as err:
        raise _damaged(path, "image", err) from None
    return pixels, orientation


def _pillow_pixels(path: _Source, image: Image.Image) -> np.ndarray:
    mode = image.mode
    if mode.startswith("I;16"):
        return _unsigned_to_unit(np.asarray(image).astype(np.uint16), 16)[:, :, None]
    if mode in ("I", "F"):
        raise InputError(
            f"unsupported pixel format: '{path}' holds 32-bit samples of unknown range; "
            "save it as 8- or 16-bit PNG or as a float TIFF"
        )
    if mode in ("1", "L", "LA", "La"):
        return _unsigned_to_unit(np.asarray(image.convert("L")), 8)[:, :, None]
    # Palette, RGBA, CMYK, YCbCr, ...: Pillow maps them to RGB (palette through the palette).
    return _unsigned_to_unit(np.asarray(image.convert("RGB")), 8)


# --- EXIF orientation --------------------------------------------------------------------------


def _orient(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """Apply EXIF orientation 1-8 to (H, W, C) pixels, as PIL.ImageOps.exif_transpose does."""
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
