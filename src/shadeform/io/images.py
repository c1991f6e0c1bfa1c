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

Where the parts live: :mod:`shadeform.io.sources` reads the file once and holds the errors,
:mod:`shadeform.io.headers` and :mod:`shadeform.io.tiffs` refuse hostile files from their headers,
:mod:`shadeform.io.decoding` decodes them to float pixels, :mod:`shadeform.io.colour` holds the
sRGB curve, luma and the clipping rule.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike

import numpy as np

from shadeform.errors import InputError
from shadeform.io.colour import _LUMA, CLIP_MARGIN, _clipped, _least_clipped
from shadeform.io.colour import srgb_encode as srgb_encode
from shadeform.io.decoding import _decode, _unit
from shadeform.io.headers import TIFF_MAGICS
from shadeform.io.sources import MEMORY_NAME as MEMORY_NAME
from shadeform.io.sources import ImageTooLargeError
from shadeform.io.sources import naming as naming

__all__ = [
    "Photo",
    "TIFF_MAGICS",
    "read_photo",
    "reading_info",
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
        return {**reading_info(self, self.channel_from), "clipped": dict(self.clipped)}


def reading_info(read, channel_from: str) -> dict:
    """How a photo (or a photo set) was read, as plain JSON-ready values.

    Parameters
    ----------
    read : Photo or PhotoSet
        Anything with the attributes ``bits``, ``encoding``, ``encoding_from`` and ``channel``.
    channel_from : {"auto", "user"}
        Whether the channel was chosen or given.

    Returns
    -------
    dict
        ``bits``, ``encoding``, ``encoding_from``, ``channel`` and ``channel_from``, in this order.
    """
    return {
        "bits": read.bits,
        "encoding": read.encoding,
        "encoding_from": read.encoding_from,
        "channel": read.channel,
        "channel_from": channel_from,
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
