"""Each format's header checked before decoding: hostile files refused from what they declare.

A file is refused, before its picture is allocated, where its header declares more pixels than
``max_pixels`` or fewer than 3 a side (:func:`_check_dimensions`), or more than its bytes could
hold given its compression (:func:`_check_holds`, with the decompression ratios below). Per
format: PNG's IHDR, chunks and CRCs (:func:`_check_png`); JPEG's segments, GIF's extension
blocks, PNM's header tokens and WebP's chunks, walked in bounded time before Pillow's readers
walk them in Python (:func:`_check_layout`); the tiles Pillow would decode, with raw BMP and PNM
rows and the slow codecs (:func:`_check_pillow_data`); formats not read here named from their
signatures, HEIF by its brand (:func:`_not_an_image`). TIFF's checks are in
:mod:`shadeform.io.tiffs`.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Iterator

import numpy as np
import png

from shadeform.errors import InputError
from shadeform.io.sources import ImageTooLargeError, _decoding, _Source, _unsupported

__all__ = ["TIFF_MAGICS"]

# Shape from shading needs a pixel and its neighbours on every side.
_MIN_SIDE = 3

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The first four bytes of a TIFF (little- and big-endian) and a BigTIFF.
TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")

#: The formats read here, as messages name them.
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

# The most bytes one byte of compressed data can become: deflate's limit (a 258-byte match in
# two 1-bit codes), LZW's (a 4094-byte string in one 9-bit code), PackBits' (128 bytes in 2),
# JPEG's (an 8x8 block, 64 bytes, in one bit; three times that for colour with subsampled
# chroma). Formats without such a bound (zstd, GIF, RLE BMP, ...) are held by max_pixels alone.
_DEFLATE_RATIO = 1032
_TIFF_RATIOS = {1: 1, 32773: 64, 5: 3641, 8: 1032, 32946: 1032, 7: 3 * 512}

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


# --- PNG ---------------------------------------------------------------------------------------


def _check_png(source: _Source, max_pixels: int) -> tuple[int, int, int, list[bytes]]:
    """Every check of a PNG before its pixels are decoded: its IHDR, the size it declares, every
    chunk (lengths, CRCs, the closing IEND) and whether its IDAT data could hold that many pixels.
    Returns its width, height, bit depth and the bodies of its eXIf chunks."""
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
    return width, height, depth, [body for kind, _, body in chunks if kind == b"eXIf"]


# --- what Pillow would decode ------------------------------------------------------------------


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
