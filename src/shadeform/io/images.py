"""Read photos and masks into arrays, keeping every bit the file holds.

One internal decoder turns a file into an ``(H, W, C)`` float32 array in ``[0, 1]`` with ``C = 1``
(gray) or ``C = 3`` (colour); :func:`read_photo` makes it linear and picks the channel to solve on,
and says what it decided (a :class:`Photo`); :func:`load_image` returns just that channel,
:func:`load_image_rgb` keeps the colour, :func:`load_pixels` keeps the array gray or colour as
stored for :func:`select_channel` to pick from later, :func:`load_mask` keeps the non-zero pixels.
The readers take a path or the file's content as ``bytes`` (an upload, decoded from memory).

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
import struct
import warnings
import zlib
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
import png
import tifffile
from PIL import Image, UnidentifiedImageError

from shadeform.errors import InputError

__all__ = [
    "Photo",
    "read_photo",
    "load_image",
    "load_image_rgb",
    "load_mask",
    "load_pixels",
    "select_channel",
    "ImageTooLargeError",
    "CHANNELS",
    "CALIBRATED_SET_FILE",
    "CLIP_MARGIN",
]

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
_TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")

#: What a file's content, given as bytes instead of a path, is called in messages.
MEMORY_NAME = "image data"
_EXIF_ORIENTATION = 0x0112

# TIFF photometric interpretations the TIFF decoder understands.
_MINISWHITE, _MINISBLACK, _RGB, _PALETTE = 0, 1, 2, 3


class ImageTooLargeError(InputError):
    """An image with more pixels than allowed (``max_pixels`` or Pillow's bomb guard).

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
    max_pixels: int = 250_000_000,
) -> Photo:
    """Read a photo as linear intensities, and say what was decided on the way.

    Parameters
    ----------
    path : str, path-like or bytes
        A PNG, JPEG, TIFF or BMP file (other formats Pillow reads work too): 1-, 8- or 16-bit,
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
        Refuse images that declare more pixels than this, before decoding anything (guards against
        corrupt files and decompression bombs). For files Pillow decodes, Pillow's own limit
        ``PIL.Image.MAX_IMAGE_PIXELS`` applies as well.

    Returns
    -------
    Photo
        The linear pixels, the chosen channel and the decisions; 16-bit samples are
        ``value / 65535`` and 8-bit ones ``value / 255`` before any decoding, and the pictures are
        upright (EXIF orientation applied).

    Raises
    ------
    InputError
        If the file is missing, empty, not an image, truncated or damaged, smaller than 3x3 or
        larger than ``max_pixels``, holds NaN or infinite samples, or ``channel`` or ``linear``
        is not one of the choices.

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
    max_pixels: int = 250_000_000,
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
    path: str | PathLike | bytes, *, linear: bool | None = None, max_pixels: int = 250_000_000
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
        return np.clip(pixels @ _LUMA, 0.0, 1.0)
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
    path: str | PathLike | bytes, *, linear: bool | None = None, max_pixels: int = 250_000_000
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
    pixels, bits, source = _decode(path, max_pixels)
    clipped = _clipped(pixels) if measure else {}
    if linear is not None:
        encoding, encoding_from = ("linear" if linear else "srgb"), "user"
    elif isinstance(source, Path) and (source.parent / CALIBRATED_SET_FILE).is_file():
        encoding, encoding_from = "linear", "set"
    else:
        encoding, encoding_from = ("srgb" if bits <= 8 else "linear"), "file"
    if encoding == "srgb":
        pixels = _srgb_decode(pixels)
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
    mask = (_decode(path, 250_000_000)[0] > 0).any(axis=2)
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
        return MEMORY_NAME


_Source = Path | _Memory


def _open(source: _Source):
    """A binary file object reading ``source`` from its start (every decoder reads it anew)."""
    return io.BytesIO(source.data) if isinstance(source, _Memory) else open(source, "rb")


def _decode(path: str | PathLike | bytes, max_pixels: int) -> tuple[np.ndarray, int, _Source]:
    """File -> (H, W, C) float32 in [0, 1], C in {1, 3}, upright (EXIF orientation applied), with
    the file's bits per sample and the checked source it was read from."""
    whole = isinstance(max_pixels, (int, np.integer)) and not isinstance(max_pixels, bool)
    if not whole or max_pixels < 1:
        raise InputError(f"max_pixels must be a positive whole number, got {max_pixels!r}")
    path = _existing_file(path)
    with _open(path) as fh:
        head = fh.read(33)
    if head.startswith(_PNG_SIGNATURE):
        pixels, orientation, bits = _decode_png(path, head, max_pixels)
    elif head[:4] in _TIFF_MAGICS:
        pixels, orientation, bits = _decode_tiff(path, max_pixels)
    else:
        pixels, orientation, bits = _decode_pillow(path, max_pixels)
    return np.ascontiguousarray(_orient(pixels, orientation)), bits, path


def _existing_file(path: str | PathLike | bytes) -> _Source:
    if isinstance(path, (bytes, bytearray, memoryview)):
        if len(path) == 0:
            raise InputError(f"empty file: the {MEMORY_NAME} has 0 bytes; give an image file")
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


def _decode_png(path: _Source, head: bytes, max_pixels: int) -> tuple[np.ndarray, int, int]:
    if len(head) < 33 or head[12:16] != b"IHDR":
        raise InputError(f"truncated or damaged PNG: '{path}' has no IHDR header; save or download it again")
    width, height, bitdepth = struct.unpack(">IIB", head[16:25])
    _check_dimensions(path, width, height, max_pixels)
    orientation = _png_orientation(path)
    if bitdepth != 16:
        pixels, _, _ = _decode_pillow(path, max_pixels)
        return pixels, orientation, bitdepth
    samples = _decode_png16(path)
    if samples.ndim == 2:
        samples = samples[:, :, None]
    if samples.shape[:2] != (height, width) or samples.dtype != np.uint16:
        raise InputError(
            f"truncated or damaged PNG: '{path}' decodes to {samples.shape} {samples.dtype}, "
            f"not {height} x {width} 16-bit; save or download the file again"
        )
    return _unsigned_to_unit(_drop_alpha(samples), 16), orientation, 16


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


def _decode_tiff(path: _Source, max_pixels: int) -> tuple[np.ndarray, int, int]:
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
        pixels, _, _ = _decode_pillow(path, max_pixels)
        return pixels, orientation, bits

    if axes == "SYX":
        samples = np.moveaxis(samples, 0, -1)
    if samples.ndim == 2:
        samples = samples[:, :, None]
    pixels = _tiff_samples_to_unit(path, samples, bits, photometric, colormap)
    return pixels, orientation, bits


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


def _decode_pillow(path: _Source, max_pixels: int) -> tuple[np.ndarray, int, int]:
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
                bits = 16 if image.mode.startswith("I;16") else 1 if image.mode == "1" else 8
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
    return pixels, orientation, bits


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
