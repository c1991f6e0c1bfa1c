"""Read photos and masks into arrays, keeping every bit the file holds.

One internal decoder turns a file into an ``(H, W, C)`` float32 array in ``[0, 1]`` with ``C = 1``
(gray) or ``C = 3`` (colour); :func:`read_photo` makes it linear and picks the channel to solve on,
and says what it decided (a :class:`Photo`); :func:`load_image` returns just that channel,
:func:`load_image_rgb` keeps the colour, :func:`load_pixels` keeps the array gray or colour as
stored for :func:`select_channel` to pick from later, :func:`load_mask` keeps the non-zero pixels.
The readers take a path or the file's content as ``bytes`` (an upload, decoded from memory).

Decoders, chosen by the file's first bytes (never its name):

- PNG: 16-bit files through libpng (``imagecodecs``; Pillow would silently drop 16-bit RGB to 8
  bits), the rest through Pillow. The whole chunk structure and every CRC is checked first (with
  ``pypng``), so a truncated or damaged file raises instead of returning part of a picture.
- TIFF: ``tifffile`` with the codecs of ``imagecodecs`` (1- to 16-bit and 32-bit unsigned, and
  float samples; uncompressed, LZW, deflate, PackBits, JPEG, zstd, ...), first page only.
- JPEG (and MPO), BMP, GIF (first frame), WebP and PBM/PGM/PPM: Pillow, with truncated files
  refused. Other formats Pillow knows are refused unread.

Hostile files: every failure while reading is an :class:`~shadeform.errors.InputError` naming the
file, and sizes are refused from the header: more pixels than ``max_pixels`` (:data:`MAX_PIXELS`
by default; :class:`ImageTooLargeError`), or more than the file's bytes could hold given its
compression, is refused before the picture is allocated, so that reading costs a small multiple
of the image's real size (``benchmarks/fuzz_loader.py`` tries ten thousand damaged files).

Conventions (``docs/conventions.md``): 16-bit samples become ``value / 65535`` exactly, 8-bit
ones ``value / 255``; EXIF orientation is applied; palette images become RGB through their
palette; alpha is ignored.

Encoding: shading needs values proportional to the light received. Files of 8 bits or fewer per
sample (JPEG, most PNGs) are taken to be sRGB-encoded, as cameras and phones write them, and are
decoded to linear values (IEC 61966-2-1); 16-bit, 32-bit and float files are taken to be linear
already, and so is every photo in a folder holding :data:`CALIBRATED_SET_FILE` (a radiometrically
calibrated photo set such as DiLiGenT's, which is linear camera data even in 8-bit PNGs).
``linear=True`` or ``False`` overrides the rule. Colour profiles and PNG gamma chunks are not read.

Channel: by default (``channel=None`` or ``"auto"``) a colour photo is solved on its luma, unless
one colour channel clips at the white level on clearly fewer pixels than luma does (see
:data:`CLIP_MARGIN`): then on the least clipped channel, green first among near-equals.
"""

from __future__ import annotations

import io
import logging
import re
import stat
import struct
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from os import PathLike
from pathlib import Path

import numpy as np
import png
from PIL import Image

from shadeform.errors import InputError

__all__ = [
    "Photo",
    "TIFF_MAGICS",
    "read_photo",
    "load_image",
    "load_image_rgb",
    "load_mask",
    "load_pixels",
    "select_channel",
    "ImageTooLargeError",
    "MAX_PIXELS",
    "CHANNELS",
    "CALIBRATED_SET_FILE",
    "CLIP_MARGIN",
]

#: The one pixel limit: the readers here (and the command line's ``--max-pixels``) refuse an
#: image whose header declares more pixels than this, before decoding it, unless given a larger
#: ``max_pixels``. 8192 x 8192, a 64 Mpx photo: more than most cameras take (a phone 12 to 48);
#: reading costs about 20 bytes a pixel of colour photo and solving far more, so that a larger
#: file, or a header claiming to be one, needs the caller's say-so.
MAX_PIXELS = 8192 * 8192

#: Channel names accepted by :func:`load_image` (which also takes ``"auto"`` or None: see
#: :func:`read_photo`).
CHANNELS = ("luma", "r", "g", "b", "max")

#: A photo in a folder holding this file belongs to a radiometrically calibrated photo set (the
#: DiLiGenT layout, ``docs/conventions.md``): its values are linear whatever its bit depth, since
#: light strengths can only be divided out of linear values.
CALIBRATED_SET_FILE = "light_intensities.txt"

#: How many fewer pixels (a fraction of the photo's) one colour channel must clip at the white
#: level than luma does before ``channel="auto"`` solves on it instead of luma; channels within
#: this of the least clipped one count as equals (green is taken first). The few highlight pixels
#: of a glossy object, which clip in every channel alike or almost, leave luma and its lower noise;
#: a colour channel saturated over a part of the object moves the choice. A judgement, not a fit:
#: of the 792 photos in ``../shared/data/real`` it moves 5 (DiLiGenT reading under bluish lights:
#: blue clips on 0.7-0.9 % of the photo, green on 0.2 %) to green.
CLIP_MARGIN = 0.005

# Rec. 601 luma weights (docs/conventions.md).
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)

# Shape from shading needs a pixel and its neighbours on every side.
_MIN_SIDE = 3

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The first four bytes of a TIFF (little- and big-endian) and a BigTIFF.
TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")

# tifffile logs each oddity of a damaged file as a warning, and where nothing configured logging,
# Python prints them all on stderr around our one-line error. A handler that drops them ends that
# fallback; records still reach the handlers of an application that configured logging.
logging.getLogger("tifffile").addHandler(logging.NullHandler())

#: What a file's content, given as bytes instead of a path, is called in messages.
MEMORY_NAME = "image data"


def naming(message: str, name: str) -> str:
    """A loader's ``message`` about bytes read from memory, naming ``name`` (the file the bytes
    came from: an upload's file name) where it said :data:`MEMORY_NAME`."""
    return message.replace(f"'{MEMORY_NAME}'", f"'{name}'")


_EXIF_ORIENTATION = 0x0112

# TIFF photometric interpretations the TIFF decoder understands; YCbCr only JPEG-compressed,
# which the codec decodes to RGB.
_MINISWHITE, _MINISBLACK, _RGB, _PALETTE, _YCBCR = 0, 1, 2, 3, 6


class ImageTooLargeError(InputError):
    """An image (or image file) larger than ``max_pixels`` allows, refused before decoding.

    A subclass of :class:`shadeform.InputError`, so that a caller can tell "too large" from
    "not an image" (the app answers 413 to one and 415 to the other).
    """


@dataclass(frozen=True, eq=False)
class Photo:
    """A photo read for shading: linear values, the channel to solve on, and how both were decided.

    Made by :func:`read_photo`; :attr:`info` is what ``Reconstruction.info["photo"]`` records.

    Attributes
    ----------
    pixels : (H, W, C) float32
        Every channel of the photo, linear, in ``[0, 1]``: ``C = 1`` gray, ``C = 3`` R, G, B.
    image : (H, W) float32
        The channel shading is solved on (:attr:`channel`), linear, in ``[0, 1]``.
    channel : {"luma", "r", "g", "b", "max", "gray"}
        Which channel :attr:`image` is; ``"gray"`` for a gray photo, whatever was asked.
    channel_from : {"auto", "user"}
        Chosen by the least-clipping rule (:data:`CLIP_MARGIN`), or given by the caller.
    bits : int
        Bits per sample in the file: 1 to 8 for sRGB-style files, 16 or 32 for linear ones.
    encoding : {"srgb", "linear"}
        How the file holds its values; ``"srgb"`` ones were decoded to linear (IEC 61966-2-1).
    encoding_from : {"file", "set", "user"}
        Decided by the file's bit depth, by its folder being a calibrated photo set
        (:data:`CALIBRATED_SET_FILE`), or given by the caller (``linear=``).
    clipped : dict of str to float
        Fraction of the photo's pixels at the white level (the largest value the file holds):
        ``{"gray": f}`` for a gray photo; ``{"r", "g", "b", "any"}`` for a colour one, ``"any"``
        counting the pixels clipped in at least one channel (where luma and max are wrong).
    """

    pixels: np.ndarray
    image: np.ndarray
    channel: str
    channel_from: str
    bits: int
    encoding: str
    encoding_from: str
    clipped: dict[str, float]

    @property
    def info(self) -> dict:
        """The decisions as plain JSON-ready values (everything but the arrays)."""
        return {
            "bits": self.bits,
            "encoding": self.encoding,
            "encoding_from": self.encoding_from,
            "channel": self.channel,
            "channel_from": self.channel_from,
            "clipped": dict(self.clipped),
        }


def read_photo(
    path: str | PathLike | bytes,
    *,
    channel: str | None = None,
    linear: bool | None = None,
    max_pixels: int = MAX_PIXELS,
) -> Photo:
    """Read a photo as linear intensities, and say what was decided on the way.

    Parameters
    ----------
    path : str, path-like or bytes
        A PNG, JPEG, TIFF, BMP, GIF, WebP or PBM/PGM/PPM file: 1-, 8- or 16-bit,
        gray, gray + alpha, RGB, RGBA or palette; float TIFFs are taken to hold values in
        ``[0, 1]`` and are clipped to it. ``bytes`` (or ``bytearray``, ``memoryview``) are the
        content of such a file, already in memory (e.g. an upload).
    channel : {None, "auto", "luma", "r", "g", "b", "max"}
        Which intensity to solve on for a colour photo. None or ``"auto"``: luma, unless one
        colour channel clips at the white level on at least :data:`CLIP_MARGIN` of the photo's
        pixels fewer than luma does (luma is wrong wherever any channel clips); then the least
        clipped channel, green first, then red, among channels within that margin of it (green
        weighs most in luma and has the most sensor sites). Otherwise Rec. 601
        luma ``0.299 R + 0.587 G + 0.114 B``, one colour channel, or the largest of R, G, B. A gray
        photo gives its gray values for every choice.
    linear : bool or None
        None: decide from the file: 8 bits per sample or fewer is sRGB and is decoded to linear,
        16-bit and float is linear, and so is any photo in a folder holding
        :data:`CALIBRATED_SET_FILE`. True: the file holds linear values; keep them. False: the
        file is sRGB-encoded; decode it.
    max_pixels : int
        Refuse images that declare more pixels than this (:data:`MAX_PIXELS` by default), before
        decoding anything: a guard against damaged files and decompression bombs. Pillow's own
        limit (``PIL.Image.MAX_IMAGE_PIXELS``) is not applied, but for its GIF, WebP and MPO
        readers, which refuse more than twice it (about 179 Mpx) whatever ``max_pixels`` says.

    Returns
    -------
    Photo
        The linear pixels, the chosen channel and the decisions; 16-bit samples are
        ``value / 65535`` and 8-bit ones ``value / 255`` before any decoding, and the pictures are
        upright (EXIF orientation applied).

    Raises
    ------
    InputError
        If the file is missing, empty, not an image, truncated or damaged, smaller than 3x3,
        holds NaN or infinite samples, or ``channel`` or ``linear`` is not one of the choices:
        every failure while reading, with a one-line message naming the file.
        :class:`ImageTooLargeError` (a subclass) if it declares more than ``max_pixels`` pixels.

    Examples
    --------
    >>> photo = read_photo("phone.jpg")  # doctest: +SKIP
    >>> photo.encoding, photo.channel, photo.image.shape  # doctest: +SKIP
    ('srgb', 'luma', (3024, 4032))
    """
    asked = _check_channel(channel, auto=True)
    pixels, bits, encoding, encoding_from, clipped = _read(path, linear, max_pixels)
    if pixels.shape[2] == 1:
        chosen = "gray"
    else:
        chosen = asked or _least_clipped(clipped)
    image = select_channel(pixels, "luma" if chosen == "gray" else chosen)
    return Photo(
        pixels,
        image,
        chosen,
        "auto" if asked is None else "user",
        bits,
        encoding,
        encoding_from,
        clipped,
    )


def load_image(
    path: str | PathLike | bytes,
    *,
    channel: str | None = None,
    linear: bool | None = None,
    max_pixels: int = MAX_PIXELS,
) -> np.ndarray:
    """Read a photo as one channel of linear intensities.

    The image of :func:`read_photo`, without the record of what was decided.

    Parameters
    ----------
    path : str, path-like or bytes
        Any file :func:`read_photo` reads, or its content.
    channel : {None, "auto", "luma", "r", "g", "b", "max"}
        As in :func:`read_photo`: by default luma, or the least clipped colour channel when one
        channel clips clearly less.
    linear : bool or None
        As in :func:`read_photo`: by default 8-bit files are decoded from sRGB, 16-bit and float
        ones kept; True keeps the values as stored, False decodes them from sRGB.
    max_pixels : int
        As in :func:`read_photo`.

    Returns
    -------
    (H, W) float32
        Linear intensities in ``[0, 1]``, row 0 at the top of the upright (EXIF-rotated) picture.

    Raises
    ------
    InputError
        As :func:`read_photo`.

    Examples
    --------
    >>> image = load_image("photo.png", channel="g")  # doctest: +SKIP
    >>> image.shape, image.dtype  # doctest: +SKIP
    ((512, 612), dtype('float32'))
    """
    return read_photo(path, channel=channel, linear=linear, max_pixels=max_pixels).image


def load_pixels(
    path: str | PathLike | bytes, *, linear: bool | None = None, max_pixels: int = MAX_PIXELS
) -> np.ndarray:
    """Read a photo with its channels: gray stays one channel, colour keeps three.

    For a caller that picks channels later, again and again, without decoding again (the app
    keeps this array and calls :func:`select_channel` per request).

    Parameters
    ----------
    path : str, path-like or bytes
        Any file :func:`read_photo` reads, or its content.
    linear : bool or None
        As in :func:`read_photo`.
    max_pixels : int
        As in :func:`read_photo`.

    Returns
    -------
    (H, W, C) float32
        ``C = 1`` for gray files, ``C = 3`` (R, G, B) for colour ones; linear values in ``[0, 1]``.

    Raises
    ------
    InputError
        As :func:`read_photo`; :class:`ImageTooLargeError` if the image has too many pixels.
    """
    return _read(path, linear, max_pixels, measure=False)[0]


def select_channel(pixels: np.ndarray, channel: str = "luma") -> np.ndarray:
    """One channel of intensities from a gray or colour picture.

    Parameters
    ----------
    pixels : (H, W), (H, W, 1) or (H, W, 3) float32
        E.g. from :func:`load_pixels`; values in ``[0, 1]``.
    channel : {"luma", "r", "g", "b", "max"}
        As in :func:`read_photo`; a gray picture returns its gray values for every choice.

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
        luma = pixels @ _LUMA
        return np.clip(luma, 0.0, 1.0, out=luma)
    if channel == "max":
        return pixels.max(axis=2)
    return np.ascontiguousarray(pixels[:, :, "rgb".index(channel)])


def _check_channel(channel, *, auto: bool = False) -> str | None:
    """The channel asked for; None where ``auto`` allows the rule to choose (None or "auto")."""
    if auto and (channel is None or channel == "auto"):
        return None
    if not isinstance(channel, str) or channel not in CHANNELS:
        choices = ("auto", *CHANNELS) if auto else CHANNELS
        raise InputError(f"unknown channel {channel!r}; choose one of {', '.join(map(repr, choices))}")
    return channel


def load_image_rgb(
    path: str | PathLike | bytes, *, linear: bool | None = None, max_pixels: int = MAX_PIXELS
) -> np.ndarray:
    """Read a photo in colour.

    Parameters
    ----------
    path : str, path-like or bytes
        Any file :func:`read_photo` reads, or its content.
    linear : bool or None
        As in :func:`read_photo`. A texture shows the photo as it looks: read it with
        ``linear=True``, which keeps the values as stored.
    max_pixels : int
        As in :func:`read_photo`.

    Returns
    -------
    (H, W, 3) float32
        R, G, B in ``[0, 1]``; a gray image has its values in all three channels.

    Raises
    ------
    InputError
        As :func:`read_photo`.
    """
    pixels = load_pixels(path, linear=linear, max_pixels=max_pixels)
    if pixels.shape[2] == 1:
        return np.repeat(pixels, 3, axis=2)
    return pixels


def _read(path: str | PathLike | bytes, linear: bool | None, max_pixels: int, *, measure: bool = True):
    """The one reading: (pixels made linear, bits, encoding, encoding_from, clipped fractions).

    ``measure=False`` skips counting the clipped pixels (``clipped`` is then empty)."""
    if linear is not None and not isinstance(linear, (bool, np.bool_)):
        raise InputError(
            f"linear must be True (the file holds linear values), False (it is sRGB-encoded) or "
            f"None (decide from the file), got {linear!r}"
        )
    samples, source = _decode(path, max_pixels)
    bits = samples.bits
    if linear is not None:
        encoding, encoding_from = ("linear" if linear else "srgb"), "user"
    elif source.path is not None and (source.path.parent / CALIBRATED_SET_FILE).is_file():
        encoding, encoding_from = "linear", "set"
    else:
        encoding, encoding_from = ("srgb" if bits <= 8 else "linear"), "file"
    pixels = _unit(samples, srgb=encoding == "srgb")
    # Decoding from sRGB keeps 1.0 at 1.0 and every value below it below: the same pixels clip.
    clipped = _clipped(pixels) if measure else {}
    return pixels, bits, encoding, encoding_from, clipped


def _clipped(pixels: np.ndarray) -> dict[str, float]:
    """Fraction of the pixels at the white level, per channel (and in any channel for colour)."""
    count = pixels.shape[0] * pixels.shape[1]
    if pixels.shape[2] == 1:
        return {"gray": int(np.count_nonzero(pixels >= 1.0)) / count}
    fractions = {name: int(np.count_nonzero(pixels[:, :, i] >= 1.0)) / count for i, name in enumerate("rgb")}
    fractions["any"] = int(np.count_nonzero(pixels.max(axis=2) >= 1.0)) / count
    return fractions


def _least_clipped(clipped: dict[str, float]) -> str:
    """The rule of ``channel="auto"`` for a colour photo (:func:`read_photo`)."""
    fewest = min(clipped[name] for name in "rgb")
    if clipped["any"] - fewest < CLIP_MARGIN:
        return "luma"
    # green, then red, then blue: the first within the margin of the least clipped
    return next(name for name in "grb" if clipped[name] - fewest < CLIP_MARGIN)


def _srgb_decode(values: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear (IEC 61966-2-1), a new array of the same float type.

    The one implementation of the transfer curve (:func:`shadeform.preprocess.srgb_to_linear`
    checks its input and calls this)."""
    number = values.dtype.type  # float32 stays float32
    encoded = ((values + number(0.055)) / number(1.055)) ** number(2.4)
    return np.where(values <= number(0.04045), values / number(12.92), encoded)


def srgb_encode(values: np.ndarray) -> np.ndarray:
    """Linear values in [0, 1] -> sRGB-encoded, the inverse of :func:`_srgb_decode` (to show a
    decoded photo as it looked: 8-bit values come back exactly)."""
    number = values.dtype.type
    encoded = number(1.055) * values ** number(1 / 2.4) - number(0.055)
    return np.where(values <= number(0.0031308), values * number(12.92), encoded)


def load_mask(
    path: str | PathLike | bytes, *, shape: tuple[int, ...] | None = None, max_pixels: int = MAX_PIXELS
) -> np.ndarray:
    """Read an object mask: every non-zero pixel (in any channel) belongs to the object.

    Parameters
    ----------
    path : str, path-like or bytes
        Any file :func:`load_image` reads, or its content; typically black background, white
        object. Label images that store the object as 1 work too (any non-zero value counts).
    shape : tuple of int, optional
        The image's shape ``(H, W)`` or ``(H, W, C)``; the mask must have the same ``H`` and ``W``.
    max_pixels : int
        As in :func:`read_photo`.

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
    samples, source = _decode(path, max_pixels)
    mask = (_unit(samples, srgb=False) > 0).any(axis=2)
    if shape is not None:
        height, width = (int(n) for n in tuple(shape)[:2])
        if mask.shape != (height, width):
            raise InputError(
                f"mask '{source}' is {mask.shape[1]}x{mask.shape[0]} but the image is {width}x{height} "
                "(width x height); give a mask of the image's size"
            )
    if not mask.any():
        raise InputError(
            f"empty mask: no pixel of '{path}' is non-zero; paint the object in a non-zero colour"
        )
    return mask


# --- the one decoder -------------------------------------------------------------------------
#
# Every failure while reading a file is an InputError that names it. The checks run in order,
# each before anything it guards against is allocated: the file's size, then the size, bit depth
# and layout its header declares (max_pixels), then whether its data could hold that many pixels
# at all (a 2 KB JPEG cannot hold 9000x9000: it is damaged or a bomb), and only then decoding.
# Decoding itself writes the float pixels block by block through a lookup table, so that it
# never holds more than the file's samples, their float copy and a few small blocks.

#: Pillow's formats read here, tried in this order (PNG and TIFF have their own paths, above
#: them); every other format Pillow knows is refused unread. The name each has in messages.
_PILLOW_FORMATS = {"JPEG": "JPEG", "BMP": "BMP", "GIF": "GIF", "WEBP": "WebP", "PPM": "PNM"}
_READABLE = "PNG, JPEG, TIFF, BMP, GIF, WebP or PNM (PBM, PGM, PPM)"

# Signatures of image formats not read here, to name them in the message (only formats whose
# files start with a fixed signature: a guess from looser tests would mislead).
_OTHER_FORMATS = (
    (b"\x00\x00\x00\x0cjP  \r\n", "JPEG 2000"),
    (b"\xffO\xffQ", "JPEG 2000"),
    (b"\xff\x0a", "JPEG XL"),
    (b"\x00\x00\x00\x0cJXL ", "JPEG XL"),
    (b"8BPS", "Photoshop"),
    (b"DDS ", "DDS"),
    (b"qoif", "QOI"),
    (b"\x01\xda", "SGI"),
    (b"\x76\x2f\x31\x01", "OpenEXR"),
    (b"#?RADIANCE", "Radiance HDR"),
    (b"#?RGBE", "Radiance HDR"),
    (b"SIMPLE  =", "FITS"),
    (b"/* XPM */", "XPM"),
    (b"gimp xcf", "GIMP"),
    (b"%PDF", "PDF"),
    (b"%!PS", "PostScript"),
    (b"\xc5\xd0\xd3\xc6", "PostScript"),
)
# ISO media (HEIF) brands of photos: iPhones' HEIC and AVIF.
_HEIF_BRANDS = {b"heic": "HEIC", b"heix": "HEIC", b"mif1": "HEIF", b"avif": "AVIF", b"avis": "AVIF"}

#: Largest file read, in bytes per pixel of ``max_pixels`` (uncompressed float RGBA), plus a
#: margin for metadata: the whole file is read into memory once, so it is capped before that.
_FILE_BYTES_PER_PIXEL, _FILE_BYTES_MARGIN = 16, 64 * 2**20

# The most bytes one byte of compressed data can become: deflate's limit (a 258-byte match in
# two 1-bit codes), LZW's (a 4094-byte string in one 9-bit code), PackBits' (128 bytes in 2),
# JPEG's (an 8x8 block, 64 bytes, in one bit; three times that for colour with subsampled
# chroma). Formats without such a bound (zstd, GIF, RLE BMP, ...) are held by max_pixels alone.
_DEFLATE_RATIO = 1032
_TIFF_RATIOS = {1: 1, 32773: 64, 5: 3641, 8: 1032, 32946: 1032, 7: 3 * 512}

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

# Pillow decodes these in Python, up to a microsecond a pixel (a whole row when a run-length
# BMP ends a line), where its other decoders are C: past this many pixels, they are refused.
_SLOW_PIXELS = 2**22
_SLOW_CODECS = {"bmp_rle": "a run-length compressed BMP", "ppm_plain": "a plain-text PBM/PGM/PPM"}

# Bits per pixel of the raw (uncompressed) layouts Pillow reads PBM, PGM and PPM files with.
_RAW_BITS = {"1;I": 1, "L": 8, "RGB": 24, "I;16B": 16, "F;32BF": 32, "F;32F": 32}

# Bit depths PNG allows for each colour type, and its samples per pixel.
_PNG_DEPTHS = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8), 4: (8, 16), 6: (8, 16)}
_PNG_PLANES = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}

# JPEG start-of-frame markers of Huffman-coded files (arithmetic coding has no 1-bit floor).
_JPEG_HUFFMAN_SOF = {0xC0, 0xC1, 0xC2}
_JPEG_SOF = set(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


@dataclass(frozen=True, eq=False)
class _Source:
    """A file's content, read once, and how messages name it (its path, or MEMORY_NAME);
    ``size``, the file's bytes, where only its header is checked (``data`` left empty)."""

    data: bytes
    path: Path | None = None
    size: int | None = None

    @property
    def length(self) -> int:
        return len(self.data) if self.size is None else self.size

    def __str__(self) -> str:
        return MEMORY_NAME if self.path is None else str(self.path)


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


def _read_source(path: str | PathLike | bytes, max_pixels: int) -> _Source:
    """The file's content, refused if missing, empty, not a regular file or absurdly large."""
    limit = max_pixels * _FILE_BYTES_PER_PIXEL + _FILE_BYTES_MARGIN
    if isinstance(path, (bytes, bytearray, memoryview)):
        source = _Source(bytes(path))
        _check_file_size(source, len(source.data), limit, max_pixels)
    else:
        path = Path(path)
        try:
            info = path.stat()
        except FileNotFoundError:
            raise InputError(f"file not found: '{path}'; check the path") from None
        except (OSError, ValueError) as err:  # ValueError: a NUL in the name
            raise _unreadable(path, err) from None
        if not stat.S_ISREG(info.st_mode):
            # A folder, or a device or pipe that could be endless or block forever.
            raise InputError(f"not a file: '{path}' is a folder or a device; give an image file")
        _check_file_size(_Source(b"", path), info.st_size, limit, max_pixels)
        try:
            source = _Source(path.read_bytes(), path)
        except OSError as err:
            raise _unreadable(path, err) from None
    if not source.data:
        raise InputError(f"empty file: '{source}' has 0 bytes; give an image file")
    return source


def _check_file_size(source: _Source, size: int, limit: int, max_pixels: int) -> None:
    if size > limit:
        raise ImageTooLargeError(
            f"file too large: '{source}' has {size:,} bytes, more than an image of "
            f"max_pixels={max_pixels:,} pixels needs; crop or downscale it, or raise max_pixels "
            "(--max-pixels) if you trust the file"
        )


def _unreadable(path: Path, err: BaseException) -> InputError:
    reason = getattr(err, "strerror", None) or str(err) or type(err).__name__
    return InputError(f"cannot read '{path}': {reason}; check the path and the file's permissions")


def _check_dimensions(source: _Source, width, height, max_pixels: int) -> None:
    """Refuse absurd declared sizes before any pixel is decoded."""
    if not all(isinstance(n, (int, np.integer)) and n >= 0 for n in (width, height)):
        raise InputError(
            f"truncated or damaged image: '{source}' declares a size of {width!r} x {height!r} "
            "pixels; save or export it again"
        )
    width, height = int(width), int(height)
    if width * height > max_pixels:
        raise ImageTooLargeError(
            f"image too large: '{source}' declares {width}x{height} = {width * height:,} pixels, "
            f"more than max_pixels={max_pixels:,} (a damaged file or a decompression bomb); "
            "crop or downscale it, or raise max_pixels (--max-pixels) if you trust the file"
        )
    if width < _MIN_SIDE or height < _MIN_SIDE:
        raise InputError(
            f"image too small: '{source}' is {width}x{height} pixels; shape from shading needs at "
            f"least {_MIN_SIDE}x{_MIN_SIDE} pixels"
        )


def _check_holds(source: _Source, kind: str, width: int, height: int, needed: int) -> None:
    """Refuse a file whose data is too short to hold the pixels its header declares, before the
    decoder allocates the picture (a truncated file, or a bomb claiming more than it holds)."""
    if needed > source.length:
        raise InputError(
            f"truncated or damaged {kind}: '{source}' declares {width}x{height} pixels but its "
            f"{source.length:,} bytes cannot hold them; save or export it again"
        )


def _damaged(source: _Source, kind: str, err: BaseException) -> InputError:
    reason = " ".join(str(err).split())[:160]
    # The decoders' own failure kinds speak for themselves; any other is named, for bug reports.
    expected = (OSError, ValueError, SyntaxError, EOFError, RuntimeError, struct.error, zlib.error, png.Error)
    if not reason or not isinstance(err, expected):
        reason = f"{type(err).__name__}: {reason}" if reason else type(err).__name__
    return InputError(
        f"truncated or damaged {kind}: '{source}' could not be decoded ({reason}); save or export it again"
    )


@contextmanager
def _decoding(source: _Source, kind: str) -> Iterator[None]:
    """Turn a third-party decoder's failure on a bad file into "truncated or damaged KIND".

    Only calls into Pillow, tifffile, imagecodecs and pypng run inside this block, never our own
    logic (our checks run between the blocks), so it cannot hide a bug of ours. Those libraries
    raise many kinds on malformed data: OSError, SyntaxError, ValueError, EOFError, struct.error
    and zlib.error from Pillow; TiffFileError, but also IndexError, TypeError, KeyError or
    NotImplementedError from tifffile's tag parsing; RuntimeError subclasses from imagecodecs.
    What they raise is theirs to choose and changes between versions, and whichever it is, the
    file could not be read: so every Exception becomes an InputError naming the file, except
    MemoryError (the machine's state, not the file's; the checks before decoding keep files from
    asking for more than their size warrants) and InputError itself.
    """
    try:
        yield
    except (MemoryError, InputError):
        raise
    except Image.DecompressionBombError:
        # Pillow's own limit, which its GIF, WebP and MPO readers apply as they open a file
        # (max_pixels, checked first, is lower unless raised past it)
        raise ImageTooLargeError(
            f"image too large: '{source}' has more than {2 * Image.MAX_IMAGE_PIXELS:,} pixels, "
            f"the most Pillow reads in a {kind} file; crop or downscale it"
        ) from None
    except Exception as err:
        raise _damaged(source, kind, err) from None


def _not_an_image(source: _Source) -> InputError:
    data = source.data
    name = next((name for start, name in _OTHER_FORMATS if data.startswith(start)), None)
    if name is None and data[4:8] == b"ftyp":
        name = _HEIF_BRANDS.get(data[8:12])
    if name is not None:
        return InputError(
            f"unsupported image format: '{source}' is in the {name} format, which is not read "
            "here; convert it to PNG, JPEG or TIFF"
        )
    return InputError(f"not an image: '{source}' is not a {_READABLE} file; convert it to PNG or TIFF")


def _unsupported(source: _Source, what: str, advice: str) -> InputError:
    return InputError(f"unsupported image: '{source}' {what}; {advice}")


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
            out[start : start + step] = _srgb_decode(block) if srgb else block
        else:  # 32-bit integers: too many values for a table
            unit = np.minimum(block.astype(np.float32) / np.float32(samples.top), np.float32(1.0))
            if samples.invert:
                unit = np.float32(1.0) - unit
            out[start : start + step] = _srgb_decode(unit) if srgb else unit
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
    return _srgb_decode(unit) if srgb else unit


# --- PNG ---------------------------------------------------------------------------------------


def _decode_png(source: _Source, max_pixels: int) -> _Samples:
    data = source.data
    if len(data) < 33 or data[12:16] != b"IHDR":
        raise InputError(f"truncated or damaged PNG: '{source}' has no IHDR header; save or export it again")
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", data[16:29])
    if depth not in _PNG_DEPTHS.get(colour, ()) or interlace > 1:
        raise InputError(
            f"truncated or damaged PNG: '{source}' declares bit depth {depth} with colour type "
            f"{colour} (interlace {interlace}), which PNG does not have; save or export it again"
        )
    _check_dimensions(source, width, height, max_pixels)
    # Real files have a few chunks and IDATs of kilobytes; millions of empty chunks would keep
    # this walk (and Pillow's) busy for minutes.
    most = 1000 + len(data) // 1024
    chunks = []
    with _decoding(source, "PNG"):
        # Walks every chunk: lengths, CRCs and the closing IEND, so a truncated file is refused.
        for kind, body in png.Reader(bytes=data).chunks():
            chunks.append((kind, len(body), body if kind == b"eXIf" else b""))
            if len(chunks) > most:
                break
    if len(chunks) > most:
        raise InputError(
            f"truncated or damaged PNG: '{source}' has more than {most:,} chunks, too many for its "
            f"{len(data):,} bytes; save or export it again"
        )
    compressed = sum(length for kind, length, _ in chunks if kind == b"IDAT")
    row = 1 + (width * _PNG_PLANES[colour] * depth + 7) // 8
    if compressed * _DEFLATE_RATIO < height * row - 64 * _DEFLATE_RATIO:
        raise InputError(
            f"truncated or damaged PNG: '{source}' declares {width}x{height} pixels but holds "
            f"only {compressed:,} bytes of compressed pixels, too few for that; save or export it again"
        )
    orientation = 1
    exif = [body for kind, _, body in chunks if kind == b"eXIf"]
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
    _check_tiff(source, header, max_pixels)
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


def _check_tiff(source: _Source, header: dict, max_pixels: int) -> None:
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


def _check_pillow_data(source: _Source, kind: str, width: int, height: int, tiles) -> None:
    """Refuse, before decoding, data too short for the declared size where the format bounds
    it: raw rows (BMP, PNM), one byte per pixel of plain PNM; and a GIF whose first frame fills
    less than a quarter of its canvas (the rest would be a flat background, holding no data,
    however large the canvas claims to be). JPEG and WebP files have the like checks before
    Pillow opens them (:func:`_check_layout`)."""
    frame = None
    for tile in tiles:
        codec, extents, offset, args = tile[0], tile[1], tile[2], tile[3]
        rows = extents[3] - extents[1]
        if codec == "gif" and frame is None:
            frame = (extents[2] - extents[0], rows)
        elif codec == "raw":
            rawmode = args[0] if isinstance(args, tuple) and args else args
            stride = args[1] if isinstance(args, tuple) and len(args) > 1 else 0
            if not stride and rawmode in _RAW_BITS:
                stride = ((extents[2] - extents[0]) * _RAW_BITS[rawmode] + 7) // 8
            _check_holds(source, kind, width, height, offset + abs(stride) * rows)
        elif codec == "ppm_plain":
            _check_holds(source, kind, width, height, offset + (extents[2] - extents[0]) * rows)
        if codec in _SLOW_CODECS and width * height > _SLOW_PIXELS:
            raise _unsupported(
                source,
                f"is {_SLOW_CODECS[codec]} of {width}x{height} pixels, more than the "
                f"{_SLOW_PIXELS:,} read in this slow format",
                "save it as PNG or TIFF",
            )
    if frame is not None:
        _check_frame(source, width, height, *frame)


def _check_frame(source: _Source, width: int, height: int, frame_width: int, frame_height: int) -> None:
    if 4 * frame_width * frame_height < width * height:
        raise _unsupported(
            source,
            f"has a {width}x{height} canvas of which its first frame fills only "
            f"{frame_width}x{frame_height} pixels",
            "save the picture itself as PNG or JPEG",
        )


# --- what Pillow's readers would walk in Python ------------------------------------------------
#
# Pillow reads the headers of JPEG, GIF and PNM files in Python, a segment, a block or a byte at
# a time: a file of millions of empty segments, or megabytes of comment, would keep it busy for
# minutes before any check on the pixels. Real files have tens of segments: the headers are
# walked here first, in bounded time, and refused past these bounds.

#: Most JPEG segments before the image data, and stray bytes between them.
_MAX_SEGMENTS, _MAX_STRAY = 10_000, 2**20
#: Most GIF extension sub-blocks before the first frame (an XMP packet takes a few thousand).
_MAX_SUBBLOCKS = 100_000
#: The longest PBM/PGM/PPM header, comments included.
_MAX_PNM_HEADER = 2**16
# One header token of a PBM/PGM/PPM file, after whitespace and comments (atomic: no backtracking).
_PNM_TOKEN = re.compile(rb"(?:\s|#[^\r\n]*+(?:[\r\n]|\Z))*+([^\s#]++)")


def _check_layout(source: _Source, max_pixels: int) -> None:
    """Walk the header of a JPEG, GIF, PNM or WebP file before Pillow does (see above); for JPEG
    and WebP also check the declared size and what the data could hold, which Pillow's WebP
    reader would otherwise find out only by decoding."""
    data = source.data
    if data.startswith(b"\xff\xd8"):
        _check_jpeg(source, max_pixels)
    elif data[:6] in (b"GIF87a", b"GIF89a"):
        _check_gif(source)
    elif len(data) > 2 and data[:1] == b"P" and data[1] in b"123456fFy":
        _check_pnm(source)
    else:
        canvas = _webp_canvas(data)
        if canvas is not None:
            _check_dimensions(source, *canvas, max_pixels)
            _check_webp(source, *canvas)


def _check_jpeg(source: _Source, max_pixels: int) -> None:
    data = source.data
    at, segments, stray, frame = 2, 0, 0, None
    while at + 4 <= len(data):
        if data[at] != 0xFF:  # stray bytes: libjpeg skips them, and so does Pillow, one by one
            found = data.find(b"\xff", at)
            stray += (len(data) if found < 0 else found) - at
            if found < 0:
                break
            at = found
            continue
        marker = data[at + 1]
        if marker == 0xFF:  # a fill byte
            at, stray = at + 1, stray + 1
            continue
        segments += 1
        if segments > _MAX_SEGMENTS or stray > _MAX_STRAY:
            raise InputError(
                f"truncated or damaged JPEG: '{source}' has more than {_MAX_SEGMENTS:,} segments "
                f"or {_MAX_STRAY:,} stray bytes before its image data; save or export it again"
            )
        if marker in (0x01, 0xD8) or 0xD0 <= marker <= 0xD7:  # markers without a length
            at += 2
            continue
        if marker in (0xDA, 0xD9):  # the image data (or the end) begins
            break
        if marker in _JPEG_SOF and frame is None:
            frame = at
        at += 2 + int.from_bytes(data[at + 2 : at + 4], "big")
    if frame is None or data[frame + 1] not in _JPEG_HUFFMAN_SOF or frame + 10 > len(data):
        return  # Pillow's reader decides
    height, width, count = struct.unpack(">HHB", data[frame + 5 : frame + 10])
    factors = [(b >> 4, b & 15) for b in data[frame + 11 : frame + 10 + 3 * count : 3]]
    if not factors or len(factors) != count or not all(h and v for h, v in factors):
        return  # Pillow's reader refuses it
    _check_dimensions(source, width, height, max_pixels)
    # Each 8x8 block of each component costs at least one bit of Huffman-coded data.
    most_h, most_v = max(h for h, _ in factors), max(v for _, v in factors)
    across = [_ceil_div(_ceil_div(width * h, most_h), 8) for h, _ in factors]
    down = [_ceil_div(_ceil_div(height * v, most_v), 8) for _, v in factors]
    _check_holds(source, "JPEG", width, height, sum(a * d for a, d in zip(across, down)) // 8)


def _check_gif(source: _Source) -> None:
    data = source.data
    if len(data) < 13:
        return
    at = 13 + (3 << ((data[10] & 7) + 1) if data[10] & 0x80 else 0)
    blocks = 0
    while at + 1 < len(data) and data[at] == 0x21:  # an extension: label, then sub-blocks
        at += 2
        while at < len(data) and data[at]:
            at += data[at] + 1
            blocks += 1
            if blocks > _MAX_SUBBLOCKS:
                raise InputError(
                    f"truncated or damaged GIF: '{source}' has more than {_MAX_SUBBLOCKS:,} "
                    "extension blocks before its first frame; save or export it again"
                )
        at += 1


def _check_pnm(source: _Source) -> None:
    head = source.data[:_MAX_PNM_HEADER]
    at = 2
    # PBM: width and height; the others: width, height and the largest value (or scale)
    for _ in range(2 if head[1] in b"14" else 3):
        found = _PNM_TOKEN.match(head, at)
        if found is None:
            raise InputError(
                f"truncated or damaged PNM: '{source}' has no complete header in its first "
                f"{_MAX_PNM_HEADER:,} bytes; save or export it again"
            )
        at = found.end()


def _check_webp(source: _Source, width: int, height: int) -> None:
    """A WebP file's first frame: an animation's must fill a quarter of the canvas at least,
    and lossy data must be long enough for the canvas."""
    lossy, frame = False, None
    for name, at, _ in _webp_chunks(source.data):
        if name == b"ANMF" and frame is None:
            frame = _webp_frame(source.data, at)
        elif name in (b"VP8 ", b"VP8L"):
            lossy = name == b"VP8 "
            break  # the first frame's image: enough
    if frame is not None:
        _check_frame(source, width, height, *frame)
    if lossy:
        # A key frame codes each 16x16 macroblock's prediction modes with fixed probabilities,
        # over 1.6 bits; 1 bit per 4 macroblocks of the canvas leaves room for a first frame
        # filling a quarter of it.
        _check_holds(source, "WebP", width, height, _ceil_div(width, 16) * _ceil_div(height, 16) // 32)


def _webp_chunks(data: bytes) -> Iterator[tuple[bytes, int, int]]:
    """A WebP file's RIFF chunks as (name, offset of the payload, size), each animation frame's
    (ANMF, after its 16-byte frame header) following it; at most _MAX_SEGMENTS of them."""
    stack = [(12, len(data))]
    walked = 0
    while stack and walked < _MAX_SEGMENTS:
        at, end = stack.pop()
        if at + 8 > min(end, len(data)):
            continue
        name, size = data[at : at + 4], int.from_bytes(data[at + 4 : at + 8], "little")
        walked += 1
        yield name, at + 8, size
        # the next chunk at this level, after this frame's own chunks (frames do not nest)
        stack.append((at + 8 + size + (size & 1), end))
        if name == b"ANMF" and end == len(data):
            stack.append((at + 24, at + 8 + size))


def _webp_canvas(data: bytes) -> tuple[int, int] | None:
    """Width and height a WebP file's first chunk declares (None: not a WebP file, or a header
    too short to say; Pillow's reader then decides)."""
    if data[:4] != b"RIFF" or data[8:12] != b"WEBP" or len(data) < 30:
        return None
    kind, body = data[12:16], data[20:30]
    if kind == b"VP8X":
        return 1 + int.from_bytes(body[4:7], "little"), 1 + int.from_bytes(body[7:10], "little")
    if kind == b"VP8 " and body[3:6] == b"\x9d\x01\x2a":
        width, height = struct.unpack("<HH", body[6:10])
        return width & 0x3FFF, height & 0x3FFF
    if kind == b"VP8L" and body[0] == 0x2F:
        bits = int.from_bytes(body[1:5], "little")
        return 1 + (bits & 0x3FFF), 1 + ((bits >> 14) & 0x3FFF)
    return None


def _webp_frame(data: bytes, at: int) -> tuple[int, int] | None:
    """Width and height of the animation frame whose ANMF payload starts at ``at``."""
    if at + 12 > len(data):
        return None
    width = 1 + int.from_bytes(data[at + 6 : at + 9], "little")
    return width, 1 + int.from_bytes(data[at + 9 : at + 12], "little")


def _ceil_div(a: int, b: int) -> int:
    return -(-a // b)


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
