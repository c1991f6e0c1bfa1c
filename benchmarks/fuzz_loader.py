"""Fuzzing the image loader: every malformed file must end as ``InputError``, never escape or hang.

Run with ``python benchmarks/fuzz_loader.py --cases 10000`` (under a minute on two cores; run it
under ``nice``). Valid seed files of every format the loader reads are made here in code (PNG 1-,
8- and 16-bit gray, RGB, RGBA, palette, interlaced, with eXIf; JPEG baseline, progressive, gray,
CMYK, EXIF-rotated, MPO; TIFF uncompressed, LZW, deflate, PackBits, JPEG, tiled, multi-page,
planar, palette, 16-bit, float, bilevel, BigTIFF; BMP, GIF still and animated, WebP lossy,
lossless and animated, PBM/PGM/PPM), next to files of formats it refuses (SGI, DDS, QOI, XBM,
TGA, JPEG 2000, EPS, PDF, ...). Each case is one seed, unchanged or mutated by a seeded random
draw: ``truncate`` (cut anywhere, often in the header), ``flip`` (1 to 64 bits),
``overwrite`` (a run of random, zero, 0xFF or copied bytes), ``splice`` (one seed's header on
another format's body, or a run deleted or doubled), ``lie`` (the header rewritten to claim
another width, height, bit depth, sample count, tile size, strip offset ... with checksums
fixed where the format has them, so that the lie gets past them), ``flood`` (up to 60,000
empty header elements: PNG text chunks, JPEG comments, GIF comment blocks, a PNM comment, RIFF
chunks, which decoders walk one at a time in Python) or ``multi`` (two or three of these).

Each case runs :func:`shadeform.io.images.read_photo` on the file (every fourth case:
:func:`shadeform.io.images.load_image` on its bytes in memory, the app's path) in a worker
process whose address space is capped (``--memory-mb``, so that a bomb shows as a MemoryError
and not as a frozen machine) and which is killed past ``--time-limit`` seconds. A case is
``loaded`` (a finite float32 image in [0, 1] of at least 3x3 pixels), ``InputError`` (one line,
naming the file, ``;`` before what to do; otherwise it counts as a *bad message*), a *raw*
exception (anything else: its type, message and the line that raised it are listed), a *hang*
(killed at the time limit) or a *crash* (the worker died). Peak memory is the worker's peak
resident memory during the case above what it held before (``VmHWM``, reset per case). Last,
a valid 3000x2000 photo of each main format is read once, its peak memory set against the
image's real size (the bytes of its samples) and against the result's.

Prints Markdown and writes it (atomically) to ``benchmarks/results/fuzz_loader.md``. The same
case number with the same ``--seed`` is the same file: ``--case N`` reruns one case in this
process and prints its traceback; ``--keep DIR`` saves every failing case's file.
"""

from __future__ import annotations

import os

# One thread per worker: decoder thread pools would multiply the address space under the cap.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
# Every allocation past 128 KiB mapped and unmapped on its own (glibc would otherwise raise the
# threshold after the first free and keep freed memory resident): a case's peak is its own.
os.environ.setdefault("MALLOC_MMAP_THRESHOLD_", str(128 * 1024))
os.environ.setdefault("MALLOC_TRIM_THRESHOLD_", str(128 * 1024))

import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import logging  # noqa: E402
import multiprocessing as mp  # noqa: E402
import platform  # noqa: E402
import random  # noqa: E402
import re  # noqa: E402
import struct  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
import warnings  # noqa: E402
import zlib  # noqa: E402
from collections import Counter, defaultdict  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from multiprocessing.connection import wait  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

MUTATIONS = ("truncate", "flip", "overwrite", "splice", "lie", "flood", "multi")
FAILURES = ("raw", "bad_message", "bad_result", "hang", "crash")
RESULTS = Path(__file__).resolve().parent / "results" / "fuzz_loader.md"

# Measured once with this harness and not rerun: the loader before issue 14 (commit 1793cbb).
BEFORE = (
    "Before (measured once, not rerun): the same 10,000 cases (seed 14) through the loader of "
    "commit 1793cbb gave 733 raw exceptions of 13 types (ValueError, IndexError, TypeError, "
    "AttributeError, ZeroDivisionError, NotImplementedError, RuntimeError, MemoryError and "
    "imagecodecs' DeflateError, ImcdError, ZstdError, Jpeg8Error, CcittError), 2 hangs (a GIF "
    "frame placed at 6000,6000; a 1 KB progressive JPEG claiming 9000x6000), 3 messages not "
    "saying what to do, 15 foreign formats read, and a peak of 1,339 MiB (MemoryError under the "
    "cap) for a 2 KB WebP claiming 6000x6000."
)

# Side lengths a lying header claims: empty or too small, near the truth (relative to it), and
# large: within the default limit for one side, past it for two, past any limit.
LIE_SIDES = (0, 1, 2, 3) + ("+1", "-1", "x2", "/2", "x16") + (3000, 6000, 9000, 30000, 65535, 65536)
LIE_SIDES += (2**31 - 1, 2**32 - 1)


@dataclass(frozen=True)
class Seed:
    """A valid file of one format, and whether the loader should read it (or refuse it)."""

    family: str
    name: str
    data: bytes
    readable: bool = True


# --- seed files -------------------------------------------------------------------------------


def _picture(height: int = 28, width: int = 36, channels: int = 3, dtype=np.uint8) -> np.ndarray:
    """Smooth gradients with a little noise: compresses like a photo, not like noise."""
    rng = np.random.default_rng(7)
    rows, cols = np.mgrid[0:height, 0:width]
    planes = [(rows * (k + 1) * 5 + cols * (3 - k) * 4) % 256 for k in range(channels)]
    values = np.stack(planes, axis=-1).astype(float) + rng.normal(0, 6, (height, width, channels))
    top = np.iinfo(dtype).max
    scaled = np.clip(values, 0, 255) / 255 * top
    out = scaled.astype(dtype)
    return out[:, :, 0] if channels == 1 else out


def _pil(image, fmt: str, **options) -> bytes:
    buffer = io.BytesIO()
    image.save(buffer, fmt, **options)
    return buffer.getvalue()


def _tiff(values, **options) -> bytes:
    import tifffile

    buffer = io.BytesIO()
    tifffile.imwrite(buffer, values, **options)
    return buffer.getvalue()


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _pypng(values: np.ndarray, *, bitdepth: int, interlace: bool = False) -> bytes:
    import png

    height, width = values.shape[:2]
    planes = 1 if values.ndim == 2 else values.shape[2]
    writer = png.Writer(
        width,
        height,
        greyscale=planes in (1, 2),
        alpha=planes in (2, 4),
        bitdepth=bitdepth,
        interlace=interlace,
    )
    buffer = io.BytesIO()
    writer.write(buffer, values.reshape(height, -1).tolist())
    return buffer.getvalue()


def _bmp_rle8(index: np.ndarray, palette: np.ndarray) -> bytes:
    """An RLE8 BMP (bottom-up), written here since Pillow only reads them."""
    body = bytearray()
    for row in index[::-1]:
        start = 0
        while start < len(row):
            run = 1
            while start + run < len(row) and run < 255 and row[start + run] == row[start]:
                run += 1
            body += bytes([run, int(row[start])])
            start += run
        body += b"\x00\x00"
    body += b"\x00\x01"
    height, width = index.shape
    colours = b"".join(bytes([b, g, r, 0]) for r, g, b in palette)
    offset = 14 + 40 + len(colours)
    info = struct.pack("<IiiHHIIiiII", 40, width, height, 1, 8, 1, len(body), 2835, 2835, len(palette), 0)
    return b"BM" + struct.pack("<IHHI", offset + len(body), 0, 0, offset) + info + colours + bytes(body)


def _with_exif_orientation(image, fmt: str, orientation: int, **options) -> bytes:
    from PIL import Image

    exif = Image.Exif()
    exif[0x0112] = orientation
    return _pil(image, fmt, exif=exif, **options)


def _fits(values: np.ndarray) -> bytes:
    cards = [
        "SIMPLE  =                    T",
        "BITPIX  =                    8",
        "NAXIS   =                    2",
        f"NAXIS1  = {values.shape[1]:>20}",
        f"NAXIS2  = {values.shape[0]:>20}",
        "END",
    ]
    header = "".join(card.ljust(80) for card in cards).ljust(2880).encode("ascii")
    data = values.tobytes()
    return header + data + b"\x00" * (-len(data) % 2880)


def _psd(values: np.ndarray) -> bytes:
    """A minimal Photoshop file: 8-bit RGB, raw image data."""
    height, width = values.shape[:2]
    head = b"8BPS" + struct.pack(">H6xHIIHH", 1, 3, height, width, 8, 3)
    sections = struct.pack(">III", 0, 0, 0)  # colour mode data, resources, layers: empty
    planes = np.moveaxis(values, -1, 0).tobytes()
    return head + sections + struct.pack(">H", 0) + planes


def make_seeds() -> list[Seed]:
    """Valid files of every format the loader reads, and of formats it should refuse."""
    import imagecodecs
    from PIL import Image, features

    rgb, gray = _picture(), _picture(channels=1)
    rgba = np.dstack([rgb, _picture(channels=1)[:, :, None] // 2 + 128])
    rgb16, gray16 = _picture(dtype=np.uint16), _picture(channels=1, dtype=np.uint16)
    rgba16 = np.dstack([rgb16, np.full(gray16.shape, 50000, np.uint16)])
    image, image_l = Image.fromarray(rgb), Image.fromarray(gray)
    palette = image.quantize(16)
    bilevel = image_l.point(lambda v: 255 if v > 128 else 0).convert("1")
    frames = [Image.fromarray(np.roll(rgb, 5 * k, axis=1)) for k in range(3)]
    seeds = []

    def add(family, name, data, readable=True):
        seeds.append(Seed(family, name, data, readable))

    # PNG
    add("png", "gray8", _pil(image_l, "PNG"))
    add("png", "gray-alpha8", _pil(Image.fromarray(rgba[:, :, [0, 3]], "LA"), "PNG"))
    add("png", "rgb8", _pil(image, "PNG"))
    add("png", "rgba8", _pil(Image.fromarray(rgba), "PNG"))
    add("png", "palette", _pil(palette, "PNG"))
    add("png", "palette-4bit", _pil(palette, "PNG", bits=4))
    add("png", "bilevel", _pil(bilevel, "PNG"))
    add("png", "gray16", imagecodecs.png_encode(gray16))
    add("png", "rgb16", imagecodecs.png_encode(rgb16))
    add("png", "rgba16", imagecodecs.png_encode(rgba16))
    add("png", "gray16-interlaced", _pypng(gray16, bitdepth=16, interlace=True))
    add("png", "rgb8-interlaced", _pypng(rgb, bitdepth=8, interlace=True))
    add("png", "exif-rotated", _with_exif_orientation(image, "PNG", 6))
    add("png", "animated", _pil(frames[0], "PNG", save_all=True, append_images=frames[1:]))
    # JPEG
    add("jpeg", "baseline", _pil(image, "JPEG", quality=90))
    add("jpeg", "gray", _pil(image_l, "JPEG"))
    add("jpeg", "progressive", _pil(image, "JPEG", progressive=True))
    add("jpeg", "exif-rotated", _with_exif_orientation(image, "JPEG", 6))
    add("jpeg", "444-optimized", _pil(image, "JPEG", subsampling=0, optimize=True))
    add("jpeg", "cmyk", _pil(image.convert("CMYK"), "JPEG"))
    add("jpeg", "restart-markers", _pil(image, "JPEG", restart_marker_blocks=2))
    add("jpeg", "mpo", _pil(frames[0], "MPO", save_all=True, append_images=frames[1:2]))
    # TIFF
    add("tiff", "gray8", _tiff(gray))
    add("tiff", "rgb8", _tiff(rgb, photometric="rgb"))
    add("tiff", "rgba8", _tiff(rgba, photometric="rgb", extrasamples=["unassalpha"]))
    add("tiff", "lzw", _tiff(rgb, photometric="rgb", compression="lzw"))
    add("tiff", "lzw-predictor", _tiff(gray16, compression="lzw", predictor=True))
    add("tiff", "deflate", _tiff(rgb, photometric="rgb", compression="adobe_deflate"))
    add("tiff", "packbits", _tiff(gray, compression="packbits", rowsperstrip=4))
    add("tiff", "jpeg", _tiff(rgb, photometric="rgb", compression="jpeg"))
    add("tiff", "zstd", _tiff(rgb16, photometric="rgb", compression="zstd"))
    add("tiff", "tiled", _tiff(rgb, photometric="rgb", tile=(16, 16)))
    add("tiff", "tiled-deflate16", _tiff(gray16, tile=(16, 16), compression="zlib"))
    add("tiff", "multipage", _tiff(np.stack([rgb, rgb[::-1]]), photometric="rgb"))
    add("tiff", "gray16", _tiff(gray16))
    add("tiff", "rgb16", _tiff(rgb16, photometric="rgb"))
    add("tiff", "float32", _tiff(gray.astype(np.float32) / 255))
    add("tiff", "planar", _tiff(np.moveaxis(rgb, -1, 0), photometric="rgb", planarconfig="separate"))
    colormap = np.stack([np.linspace(0, 65535, 256)] * 3).astype(np.uint16)
    add("tiff", "palette", _tiff(gray, photometric="palette", colormap=colormap))
    add("tiff", "miniswhite", _tiff(gray, photometric="miniswhite"))
    add("tiff", "bigtiff", _tiff(rgb, photometric="rgb", bigtiff=True))
    add("tiff", "bilevel", _tiff(gray > 128))
    add("tiff", "group4", _pil(bilevel, "TIFF", compression="group4"))
    add("tiff", "pillow-lzw", _pil(image, "TIFF", compression="tiff_lzw"))
    # BMP
    add("bmp", "rgb24", _pil(image, "BMP"))
    add("bmp", "rgba32", _pil(Image.fromarray(rgba), "BMP"))
    add("bmp", "palette8", _pil(palette, "BMP"))
    add("bmp", "gray8", _pil(image_l, "BMP"))
    add("bmp", "bilevel", _pil(bilevel, "BMP"))
    index = np.asarray(palette)
    add("bmp", "rle8", _bmp_rle8(index, np.asarray(palette.getpalette()[: 3 * 16]).reshape(-1, 3)))
    # GIF
    add("gif", "still", _pil(palette, "GIF"))
    add("gif", "gray", _pil(image_l, "GIF"))
    add("gif", "animated", _pil(frames[0], "GIF", save_all=True, append_images=frames[1:], duration=100))
    add("gif", "interlaced", _pil(palette, "GIF", interlace=True))
    # WebP, where this Pillow has libwebp (without it, the loader cannot read WebP either)
    if features.check("webp"):
        add("webp", "lossy", _pil(image, "WEBP", quality=80))
        add("webp", "lossless", _pil(image, "WEBP", lossless=True))
        add("webp", "alpha", _pil(Image.fromarray(rgba), "WEBP", quality=80))
        animated = _pil(frames[0], "WEBP", save_all=True, append_images=frames[1:], duration=100)
        add("webp", "animated", animated)
    # PBM, PGM, PPM
    add("pnm", "pgm8", _pil(image_l, "PPM"))
    add("pnm", "pgm16", _pil(Image.fromarray(gray16), "PPM"))
    add("pnm", "ppm", _pil(image, "PPM"))
    add("pnm", "pbm", _pil(bilevel, "PPM"))
    ascii_body = " ".join(str(v) for v in gray.ravel())
    add("pnm", "pgm-ascii", f"P2\n{gray.shape[1]} {gray.shape[0]}\n255\n{ascii_body}\n".encode())
    add("pnm", "pfm-float", _pil(Image.fromarray(gray.astype(np.float32) / 255, "F"), "PPM"), False)
    # Formats the loader refuses, with their own magic numbers.
    for fmt, picture, options in (
        ("SGI", image, {}),
        ("DDS", image, {}),
        ("QOI", image, {}),
        ("XBM", bilevel, {}),
        ("TGA", image, {}),
        ("ICO", image, {}),
        ("PCX", image, {}),
        ("EPS", image, {}),
        ("JPEG2000", image, {}),
        ("SPIDER", image_l.convert("F"), {}),
        ("MSP", bilevel, {}),
        ("AVIF", image, {}),
        ("PDF", image, {}),
    ):
        with contextlib.suppress(KeyError, OSError, ValueError):  # a writer this Pillow lacks
            add("other", fmt.lower(), _pil(picture, fmt, **options), False)
    add("other", "fits", _fits(gray), False)
    add("other", "psd", _psd(rgb), False)
    add(
        "other",
        "xpm",
        b'/* XPM */\nstatic char *x[] = {\n"4 4 1 1",\n"a c #ff0000",\n' + b'"aaaa",\n' * 4 + b"};\n",
        False,
    )
    add("other", "text", b"width 36 height 28\n" * 40, False)
    add("other", "zip", b"PK\x03\x04" + bytes(range(256)), False)
    add("other", "heic", b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00mif1heic" + bytes(200), False)
    add("other", "random", random.Random(3).randbytes(600), False)
    return seeds


def large_files(height: int = 2000, width: int = 3000) -> list[tuple[str, bytes, int]]:
    """Valid photos of 6 Mpx in the main formats, each with its real size: the bytes of the
    samples it holds (alpha and padding not counted), to set reading's peak memory against."""
    import imagecodecs
    from PIL import Image

    rgb, gray = _picture(height, width), _picture(height, width, channels=1)
    rgb16, gray16 = _picture(height, width, dtype=np.uint16), _picture(height, width, 1, np.uint16)
    image = Image.fromarray(rgb)
    pixels = height * width
    return [
        ("PNG 8-bit RGB", _pil(image, "PNG", compress_level=1), 3 * pixels),
        ("PNG 16-bit RGB", imagecodecs.png_encode(rgb16, level=1), 6 * pixels),
        ("JPEG RGB", _pil(image, "JPEG", quality=90), 3 * pixels),
        ("JPEG progressive", _pil(image, "JPEG", quality=90, progressive=True), 3 * pixels),
        ("TIFF 8-bit RGB, LZW", _tiff(rgb, photometric="rgb", compression="lzw"), 3 * pixels),
        ("TIFF 16-bit gray, deflate", _tiff(gray16, compression="zlib"), 2 * pixels),
        ("TIFF float32 gray", _tiff(gray.astype(np.float32) / 255), 4 * pixels),
        ("BMP 24-bit", _pil(image, "BMP"), 3 * pixels),
        ("GIF", _pil(image.quantize(256), "GIF"), pixels),
        ("WebP lossy", _pil(image, "WEBP", quality=80), 3 * pixels),
        ("PPM", _pil(image, "PPM"), 3 * pixels),
    ]


# --- mutations --------------------------------------------------------------------------------


def _where(rng: random.Random, size: int, head: int = 512) -> int:
    """A position in the file: half the time in its first ``head`` bytes, where headers are."""
    if size <= 1:
        return 0
    return rng.randrange(min(size, head)) if rng.random() < 0.5 else rng.randrange(size)


def truncate(rng, data, seeds):
    if len(data) < 2:
        return data, "too short to cut"
    cut = rng.randrange(1, min(len(data), 300)) if rng.random() < 0.5 else rng.randrange(1, len(data))
    return data[:cut], f"cut at {cut} of {len(data)}"


def flip(rng, data, seeds):
    out = bytearray(data)
    count = rng.choice((1, 1, 1, 2, 3, 4, 8, 16, 64))
    for _ in range(count):
        at = _where(rng, len(out))
        out[at] ^= 1 << rng.randrange(8)
    return bytes(out), f"{count} bits"


def overwrite(rng, data, seeds):
    out = bytearray(data)
    length = rng.choice((1, 2, 4, 8, 16, 32, 64))
    at = _where(rng, len(out))
    kind = rng.choice(("random", "zero", "ff", "copy"))
    if kind == "random":
        run = rng.randbytes(length)
    elif kind == "zero":
        run = b"\x00" * length
    elif kind == "ff":
        run = b"\xff" * length
    else:
        start = rng.randrange(len(out))
        run = bytes(out[start : start + length])
    out[at : at + len(run)] = run
    return bytes(out[: max(len(data), at)]), f"{kind} x{length} at {at}"


def splice(rng, data, seeds):
    kind = rng.choice(("header", "header", "delete", "double"))
    if kind == "header":
        # One format's header on another format's body.
        own = rng.choice([s for s in seeds if s.data is not data])
        cut = rng.randrange(4, max(5, min(len(data), 600)))
        start = rng.randrange(len(own.data))
        return data[:cut] + own.data[start:], f"first {cut} bytes + {own.family}/{own.name} from {start}"
    at, length = _where(rng, len(data)), rng.choice((1, 4, 16, 64, 256))
    if kind == "delete":
        return data[:at] + data[at + length :], f"{length} bytes deleted at {at}"
    return data[: at + length] + data[at:], f"{length} bytes doubled at {at}"


def _lie_side(rng, true: int, top: int) -> int:
    pick = rng.choice(LIE_SIDES)
    value = {"+1": true + 1, "-1": true - 1, "x2": true * 2, "/2": true // 2, "x16": true * 16}.get(
        pick, pick
    )
    return max(0, min(int(value), top))


def _lie_png(rng, data):
    if data[12:16] != b"IHDR":
        return None
    ihdr = bytearray(data[16:29])
    width, height = struct.unpack(">II", ihdr[:8])
    field = rng.choice(("size", "size", "size", "depth"))
    if field == "size":
        width, height = _lie_side(rng, width, 2**32 - 1), _lie_side(rng, height, 2**32 - 1)
        ihdr[:8] = struct.pack(">II", width, height)
        what = f"IHDR {width}x{height}"
    else:
        ihdr[8] = rng.choice((0, 1, 2, 3, 4, 8, 16, 32, 255))
        ihdr[9] = rng.choice((0, 1, 2, 3, 4, 6, 7))
        what = f"IHDR depth {ihdr[8]} colour type {ihdr[9]}"
    crc = struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))
    if rng.random() < 0.1:
        crc, what = data[29:33], what + " (old CRC)"
    return data[:16] + bytes(ihdr) + crc + data[33:], what


_SOF = set(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def _jpeg_sof(data: bytes) -> int | None:
    """Offset of the first SOF segment's length field, walking the markers from SOI."""
    at = 2
    while at + 4 <= len(data):
        if data[at] != 0xFF:
            return None
        marker = data[at + 1]
        if marker in _SOF:
            return at + 2
        if marker == 0xDA:
            return None
        at += 2 + struct.unpack(">H", data[at + 2 : at + 4])[0]
    return None


def _lie_jpeg(rng, data):
    at = _jpeg_sof(data)
    if at is None or at + 8 > len(data):
        return None
    out = bytearray(data)
    field = rng.choice(("size", "size", "size", "precision", "components", "sampling"))
    if field == "size":
        height, width = struct.unpack(">HH", out[at + 3 : at + 7])
        height, width = _lie_side(rng, height, 65535), _lie_side(rng, width, 65535)
        out[at + 3 : at + 7] = struct.pack(">HH", height, width)
        what = f"SOF {width}x{height}"
    elif field == "precision":
        out[at + 2] = rng.choice((0, 1, 12, 16, 255))
        what = f"SOF precision {out[at + 2]}"
    elif field == "components":
        out[at + 7] = rng.choice((0, 1, 2, 4, 255))
        what = f"SOF {out[at + 7]} components"
    else:
        out[at + 9] = rng.choice((0x00, 0x11, 0x44, 0x55, 0xFF, 0x1F))
        what = f"SOF sampling {out[at + 9]:#x}"
    return bytes(out), what


_TIFF_LIES = {
    256: "width",
    257: "height",
    258: "bits",
    259: "compression",
    262: "photometric",
    273: "strip offset",
    277: "samples",
    278: "rows per strip",
    279: "strip bytes",
    284: "planar",
    322: "tile width",
    323: "tile length",
    324: "tile offset",
    325: "tile bytes",
    339: "sample format",
}


def _lie_tiff(rng, data):
    order = {b"II": "<", b"MM": ">"}.get(data[:2])
    if order is None or struct.unpack(order + "H", data[2:4])[0] != 42:
        return None  # BigTIFF: the generic lie
    (ifd,) = struct.unpack(order + "I", data[4:8])
    if ifd + 2 > len(data):
        return None
    (count,) = struct.unpack(order + "H", data[ifd : ifd + 2])
    entries = {}
    for k in range(count):
        at = ifd + 2 + 12 * k
        if at + 12 > len(data):
            break
        tag, kind, n = struct.unpack(order + "HHI", data[at : at + 8])
        if tag in _TIFF_LIES and kind in (3, 4):
            entries[tag] = (at, kind, n)
    if not entries:
        return None
    sizes = [t for t in entries if t in (256, 257, 322, 323)]
    tag = rng.choice(sizes) if sizes and rng.random() < 0.6 else rng.choice(sorted(entries))
    at, kind, n = entries[tag]
    top = 65535 if kind == 3 else 2**32 - 1
    fmt = order + ("H" if kind == 3 else "I")
    size = struct.calcsize(fmt)
    where = at + 8
    if n * size > 4:  # the values live elsewhere: lie about the first one
        (where,) = struct.unpack(order + "I", data[at + 8 : at + 12])
        if where + size > len(data):
            return None
    (true,) = struct.unpack(fmt, data[where : where + size])
    if tag in (256, 257, 322, 323, 278):
        value = _lie_side(rng, true, top)
    elif tag in (273, 279, 324, 325):
        value = rng.choice((0, 1, true + 1, len(data), len(data) * 1000, top))
    else:
        value = rng.choice((0, 1, 2, 3, 4, 5, 7, 8, 12, 16, 24, 32, 64, 255, 32773, top))
    value = min(value, top)
    out = data[:where] + struct.pack(fmt, value) + data[where + size :]
    return out, f"TIFF {_TIFF_LIES[tag]} {value}"


def _lie_gif(rng, data):
    if data[:3] != b"GIF" or len(data) < 13:
        return None
    out = bytearray(data)
    if rng.random() < 0.5:
        width, height = struct.unpack("<HH", out[6:10])
        width, height = _lie_side(rng, width, 65535), _lie_side(rng, height, 65535)
        out[6:10] = struct.pack("<HH", width, height)
        return bytes(out), f"GIF screen {width}x{height}"
    at = 13 + (3 * 2 ** ((out[10] & 7) + 1) if out[10] & 0x80 else 0)
    while at < len(out) and out[at] == 0x21:  # extensions: skip their sub-blocks
        at += 2
        while at < len(out) and out[at]:
            at += out[at] + 1
        at += 1
    if at + 10 > len(out) or out[at] != 0x2C:
        return None
    field = rng.choice(("size", "offset"))
    base = at + 5 if field == "size" else at + 1
    a, b = struct.unpack("<HH", out[base : base + 4])
    a, b = _lie_side(rng, a, 65535), _lie_side(rng, b, 65535)
    out[base : base + 4] = struct.pack("<HH", a, b)
    return bytes(out), f"GIF frame {field} {a},{b}"


def _lie_bmp(rng, data):
    if data[:2] != b"BM" or len(data) < 54:
        return None
    out = bytearray(data)
    field = rng.choice(("size", "size", "bits", "compression", "offset", "colours"))
    if field == "size":
        width, height = struct.unpack("<ii", out[18:26])
        width = _lie_side(rng, width, 2**31 - 1)
        height = _lie_side(rng, abs(height), 2**31 - 1) * rng.choice((1, 1, -1))
        out[18:26] = struct.pack("<ii", width, height)
        what = f"BMP {width}x{height}"
    elif field == "bits":
        bits = rng.choice((0, 1, 2, 4, 8, 16, 24, 32, 64, 65535))
        out[28:30] = struct.pack("<H", bits)
        what = f"BMP {bits} bits"
    elif field == "compression":
        kind = rng.choice((0, 1, 2, 3, 4, 5, 6, 2**32 - 1))
        out[30:34] = struct.pack("<I", kind)
        what = f"BMP compression {kind}"
    elif field == "offset":
        offset = rng.choice((0, 14, len(data), len(data) + 100, 2**32 - 1))
        out[10:14] = struct.pack("<I", offset)
        what = f"BMP data offset {offset}"
    else:
        colours = rng.choice((0, 1, 255, 257, 65536, 2**32 - 1))
        out[46:50] = struct.pack("<I", colours)
        what = f"BMP {colours} colours"
    return bytes(out), what


def _lie_webp(rng, data):
    if data[:4] != b"RIFF" or data[8:12] != b"WEBP" or len(data) < 30:
        return None
    out = bytearray(data)
    chunk = bytes(out[12:16])
    if chunk == b"VP8X":
        width, height = _lie_side(rng, 36, 2**24), _lie_side(rng, 28, 2**24)
        out[24:30] = (width - 1 & 0xFFFFFF).to_bytes(3, "little") + (height - 1 & 0xFFFFFF).to_bytes(
            3, "little"
        )
    elif chunk == b"VP8 ":
        width, height = _lie_side(rng, 36, 16383), _lie_side(rng, 28, 16383)
        out[26:30] = struct.pack("<HH", width & 0x3FFF, height & 0x3FFF)
    elif chunk == b"VP8L":
        width, height = _lie_side(rng, 36, 16384), _lie_side(rng, 28, 16384)
        (bits,) = struct.unpack("<I", out[21:25])
        bits = (bits & ~((1 << 28) - 1)) | ((width - 1) & 0x3FFF) | (((height - 1) & 0x3FFF) << 14)
        out[21:25] = struct.pack("<I", bits)
    else:
        return None
    return bytes(out), f"WebP {chunk.decode().strip()} {width}x{height}"


def _lie_pnm(rng, data):
    found = re.match(rb"(P[1-7f]\s+(?:#[^\n]*\n\s*)*)(\d+)(\s+)(\d+)", data)
    if not found:
        return None
    width = _lie_side(rng, int(found[2]), 2**40)
    height = _lie_side(rng, int(found[4]), 2**40)
    head = found[1] + str(width).encode() + found[3] + str(height).encode()
    return head + data[found.end() :], f"PNM {width}x{height}"


def lie(rng, data, seeds):
    """Rewrite what the header says about the picture's size and layout."""
    for lie_in in (_lie_png, _lie_jpeg, _lie_tiff, _lie_gif, _lie_bmp, _lie_webp, _lie_pnm):
        try:
            made = lie_in(rng, data)
        except (struct.error, IndexError, ValueError):  # a header already cut or mangled
            made = None
        if made is not None:
            return made
    # Any other format: a huge 16- or 32-bit number somewhere in the first 64 bytes.
    out = bytearray(data)
    at = rng.randrange(max(1, min(len(out) - 4, 64)))
    value = rng.choice((b"\xff\xff", b"\xff\xff\xff\x7f", b"\x7f\xff\xff\xff", b"\x00\x00"))
    out[at : at + len(value)] = value
    return bytes(out), f"{value.hex()} at {at}"


def flood(rng, data, seeds):
    """Many copies of an empty header element where the format allows one (a PNG text chunk, a
    JPEG comment, a GIF comment block, a PNM comment line, a RIFF chunk), or of a few bytes: the
    decoders walk headers in Python, an element at a time."""
    count = rng.choice((10, 1000, 20_000, 60_000))
    if data.startswith(b"\x89PNG") and len(data) > 33:
        return data[:33] + _png_chunk(b"tEXt", b"a\x00b") * count + data[33:], f"{count} PNG text chunks"
    if data.startswith(b"\xff\xd8"):
        return data[:2] + b"\xff\xfe\x00\x02" * count + data[2:], f"{count} JPEG comments"
    if data[:3] == b"GIF" and len(data) > 13:
        at = 13 + (3 << ((data[10] & 7) + 1) if data[10] & 0x80 else 0)
        return data[:at] + b"\x21\xfe" + b"\x01a" * count + b"\x00" + data[at:], f"{count} GIF comment blocks"
    if data[:1] == b"P" and data[1:2] in b"123456":
        return data[:2] + b"\n#" + b"x" * (30 * count) + data[2:], f"PNM comment of {30 * count} bytes"
    if data[:4] == b"RIFF" and len(data) > 12:
        return data[:12] + b"JUNK\x00\x00\x00\x00" * count + data[12:], f"{count} empty RIFF chunks"
    at = min(len(data), 16)
    return data[:at] + rng.randbytes(4) * count + data[at:], f"{count} copies of 4 bytes at {at}"


def multi(rng, data, seeds):
    steps = []
    for _ in range(rng.choice((2, 2, 3))):
        data, what = rng.choice((truncate, flip, overwrite, splice, lie, flood))(rng, data, seeds)
        steps.append(what)
        if not data:
            data = b"\x00"
    return data, " + ".join(steps)


MUTATE = {
    "truncate": truncate,
    "flip": flip,
    "overwrite": overwrite,
    "splice": splice,
    "lie": lie,
    "flood": flood,
    "multi": multi,
}


@dataclass(frozen=True)
class Case:
    number: int
    family: str
    seed_name: str
    mutation: str
    detail: str
    data: bytes
    in_memory: bool
    readable: bool  # the unmutated seed must load (False: it must be refused)


def make_case(number: int, seeds: list[Seed], master_seed: int) -> Case:
    """Case ``number``: the first ``len(seeds)`` are the seeds as they are, then every mutation in
    turn over every seed. The same number and seed always make the same file."""
    seed = seeds[number % len(seeds)]
    rng = random.Random(f"{master_seed}:{number}")
    if number < len(seeds):
        mutation, detail, data = "none", "", seed.data
    else:
        mutation = MUTATIONS[(number // len(seeds) - 1) % len(MUTATIONS)]
        data, detail = MUTATE[mutation](rng, seed.data, seeds)
        if not data:
            data = b"\x00"
    return Case(number, seed.family, seed.name, mutation, detail, data, number % 4 == 3, seed.readable)


# --- running one case -------------------------------------------------------------------------


def _memory_kib(key: str) -> int:
    """A ``/proc/self/status`` figure in KiB (Linux; 0 elsewhere, where peaks read as 0)."""
    with contextlib.suppress(OSError), open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def _reset_peak() -> None:
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")  # resets VmHWM, the peak resident set
    except OSError:
        pass


def _raised_at(err: BaseException) -> str:
    """The innermost ``file:line`` the exception came from (shortened to package/file)."""
    frames = traceback.extract_tb(err.__traceback__)
    if not frames:
        return "?"
    frame = frames[-1]
    parts = Path(frame.filename).parts
    return f"{'/'.join(parts[-2:])}:{frame.lineno}"


class _Counter(logging.Handler):
    """Counts the log records that reach the root logger (tifffile logs damaged tags)."""

    count = 0

    def emit(self, record) -> None:
        _Counter.count += 1


_LOG_RECORDS = _Counter()


def run_case(case: Case, folder: Path) -> dict:
    """Read one case's file; classify what happened."""
    from shadeform.errors import InputError
    from shadeform.io.images import MEMORY_NAME, ImageTooLargeError, load_image, read_photo

    path = folder / f"case{case.number}.{case.family}"
    if not case.in_memory:
        path.write_bytes(case.data)
    name = MEMORY_NAME if case.in_memory else str(path)
    _reset_peak()
    before = _memory_kib("VmRSS")
    start = time.perf_counter()
    result = {"outcome": "loaded", "detail": ""}
    logged = _LOG_RECORDS.count
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if case.in_memory:
                image = kept = load_image(case.data)
            else:
                photo = read_photo(path)
                image, kept = photo.image, photo.pixels
                if not np.shares_memory(photo.image, photo.pixels):
                    kept = (photo.pixels, photo.image)
    except InputError as err:
        message = str(err)
        result["detail"] = message
        if "\n" in message or name not in message or "; " not in message:
            result["outcome"] = "bad_message"
        else:
            result["outcome"] = "too_large" if isinstance(err, ImageTooLargeError) else "input_error"
    except Exception as err:  # everything that escapes is what this benchmark counts
        first = (str(err).splitlines() or [""])[0][:160]
        result.update(outcome="raw", detail=f"{type(err).__name__}: {first}", where=_raised_at(err))
    else:
        good = (
            isinstance(image, np.ndarray)
            and image.dtype == np.float32
            and image.ndim == 2
            and min(image.shape) >= 3
            and bool(np.isfinite(image).all())
            and float(image.min()) >= 0.0
            and float(image.max()) <= 1.0
        )
        if not good:
            result.update(
                outcome="bad_result",
                detail=f"{getattr(image, 'shape', None)} {getattr(image, 'dtype', None)}",
            )
        result["shape"] = getattr(image, "shape", None)
        result["result_mib"] = sum(a.nbytes for a in (kept if isinstance(kept, tuple) else (kept,))) / 2**20
    result["seconds"] = time.perf_counter() - start
    result["peak_mib"] = max(0, _memory_kib("VmHWM") - before) / 1024
    # what the decoders said besides: Python warnings (printed on stderr unless filtered) and
    # log records (tifffile's; dropped unless the application configured logging)
    result["warnings"], result["logged"] = bool(caught), _LOG_RECORDS.count > logged
    if not case.in_memory:
        path.unlink(missing_ok=True)
    return result


def _worker(conn, memory_mib: int) -> None:
    import resource

    if memory_mib:
        cap = memory_mib * 2**20
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    import shadeform.io.images  # noqa: F401  (imported before the first case is timed)

    logging.getLogger().addHandler(_LOG_RECORDS)

    with tempfile.TemporaryDirectory(prefix="fuzz-loader-") as folder:
        while True:
            try:
                case = conn.recv()
            except EOFError:
                return
            if case is None:
                return
            conn.send((case.number, run_case(case, Path(folder))))


class _Pool:
    """Worker processes, each reading one case at a time, replaced when killed or dead."""

    def __init__(self, workers: int, memory_mib: int, time_limit: float) -> None:
        self.context = mp.get_context("spawn")
        self.memory_mib, self.time_limit = memory_mib, time_limit
        self.slots = [self._start() for _ in range(workers)]

    def _start(self) -> dict:
        parent, child = self.context.Pipe()
        process = self.context.Process(target=_worker, args=(child, self.memory_mib), daemon=True)
        process.start()
        child.close()
        return {"process": process, "conn": parent, "case": None, "since": 0.0}

    def run(self, cases, on_result) -> None:
        pending = iter(cases)
        active = 0
        for slot in self.slots:
            active += self._feed(slot, pending)
        while active:
            ready = wait([s["conn"] for s in self.slots if s["case"] is not None], timeout=0.5)
            now = time.monotonic()
            for slot in self.slots:
                case = slot["case"]
                if case is None:
                    continue
                if slot["conn"] in ready:
                    try:
                        number, result = slot["conn"].recv()
                    except (EOFError, OSError):
                        slot["process"].join(5)
                        code = slot["process"].exitcode
                        result = {"outcome": "crash", "detail": f"worker died (exit code {code})"}
                        result.update(seconds=now - slot["since"], peak_mib=0.0)
                        self._replace(slot)
                    on_result(case, result)
                elif now - slot["since"] > self.time_limit:
                    slot["process"].kill()
                    slot["process"].join(5)
                    on_result(
                        case,
                        {"outcome": "hang", "detail": "", "seconds": now - slot["since"], "peak_mib": 0.0},
                    )
                    self._replace(slot)
                else:
                    continue
                slot["case"] = None
                active -= 1
                active += self._feed(slot, pending)

    def _feed(self, slot, pending) -> int:
        case = next(pending, None)
        if case is None:
            return 0
        slot["case"], slot["since"] = case, time.monotonic()
        slot["conn"].send(case)
        return 1

    def _replace(self, slot) -> None:
        slot["conn"].close()
        slot.update(self._start())

    def close(self) -> None:
        for slot in self.slots:
            with contextlib.suppress(OSError):
                slot["conn"].send(None)
            slot["process"].join(5)
            if slot["process"].is_alive():
                slot["process"].kill()


# --- report -----------------------------------------------------------------------------------


def _table(rows, records) -> list[str]:
    lines = [
        "| family | mutation | cases | loaded | InputError (too large) | raw | bad message | hangs | crashes | worst s | peak MiB |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for key in rows:
        group = records[key]
        count = Counter(r["outcome"] for _, r in group)
        refused = count["input_error"] + count["too_large"]
        lines.append(
            f"| {key[0]} | {key[1]} | {len(group):,} | {count['loaded']:,} | {refused:,} ({count['too_large']:,}) | "
            f"{count['raw']:,} | {count['bad_message'] + count['bad_result']:,} | {count['hang']:,} | "
            f"{count['crash']:,} | {max(r['seconds'] for _, r in group):.2f} | "
            f"{max(r['peak_mib'] for _, r in group):,.0f} |"
        )
    return lines


def report(results: list[tuple[Case, dict]], args, seconds: float, seeds: list[Seed], large=()) -> str:
    import imagecodecs
    import PIL
    import tifffile

    by_key = defaultdict(list)
    by_family = defaultdict(list)
    for case, result in results:
        by_key[(case.family, case.mutation)].append((case, result))
        by_family[(case.family, "all")].append((case, result))
    by_key_all = {**by_key, **by_family, ("all", "all"): results}
    count = Counter(r["outcome"] for _, r in results)
    failures = sum(count[k] for k in FAILURES)
    # An unmutated seed must load if its format is read, and be refused otherwise.
    wrong_seeds = [
        f"{c.family}/{c.seed_name}: {r['outcome']} {r['detail']}"
        for c, r in results
        if c.mutation == "none" and (r["outcome"] == "loaded") != c.readable
    ]
    families = sorted({c.family for c, _ in results})
    lines = [
        "# Loader fuzzing",
        "",
        f"`python benchmarks/fuzz_loader.py --cases {args.cases} --seed {args.seed}`: {len(results):,} cases "
        f"from {len(seeds)} seed files in {len(families)} families, {args.workers} workers, "
        f"{args.time_limit:g} s per case, address space capped at {args.memory_mb:,} MiB; "
        f"{seconds / 60:.1f} min wall. Python {platform.python_version()}, Pillow {PIL.__version__}, "
        f"tifffile {tifffile.__version__}, imagecodecs {imagecodecs.__version__}, "
        f"{os.cpu_count()} cores.",
        "",
        f"**{count['raw']:,} raw exceptions, {count['hang']:,} hangs, {count['crash']:,} crashes, "
        f"{count['bad_message']:,} bad messages, {count['bad_result']:,} bad results** "
        f"({failures:,} failures); {count['loaded']:,} loaded, "
        f"{count['input_error'] + count['too_large']:,} refused with InputError "
        f"({count['too_large']:,} of them as too large, from the header). "
        f"Unmutated seeds with the wrong outcome: {len(wrong_seeds)}.",
        "",
        "InputError counts every refusal with a one-line message naming the file and what to do "
        "(too large: ImageTooLargeError); raw: any other exception; bad message: an InputError "
        "on several lines, not naming the file or not saying what to do; peak MiB: the worker's "
        "peak resident memory during the case above what it held before.",
        "",
        "## By family",
        "",
        *_table([(f, "all") for f in families] + [("all", "all")], by_key_all),
        "",
        "## By family and mutation",
        "",
        *_table([k for f in families for k in sorted(by_key) if k[0] == f], by_key_all),
        "",
    ]
    if wrong_seeds:
        lines += ["## Unmutated seeds with the wrong outcome", "", *[f"- {w}" for w in wrong_seeds], ""]
    raws = defaultdict(list)
    for case, result in results:
        if result["outcome"] in FAILURES:
            key = (result["outcome"], result["detail"].split(":")[0], result.get("where", ""))
            raws[key].append((case, result))
    if raws:
        lines += [
            "## Failures by kind",
            "",
            "| outcome | kind | raised at | cases | example case: family/seed, mutation | message |",
        ]
        lines += ["|---|---|---|---:|---|---|"]
        for (outcome, kind, where), group in sorted(raws.items(), key=lambda item: -len(item[1])):
            case, result = group[0]
            message = result["detail"].replace("|", "\\|")[:140]
            lines.append(
                f"| {outcome} | {kind} | {where} | {len(group)} | {case.number}: {case.family}/{case.seed_name}, "
                f"{case.mutation} {case.detail} | {message} |"
            )
        lines.append("")
    if large:
        lines += [
            "## Valid large files",
            "",
            "Each format's 3000x2000 photo read once with read_photo: peak memory against the "
            "image's real size (the bytes of its samples, alpha not counted) and against the "
            "result itself (the float32 pixels and the channel solved on, 16 bytes per pixel for "
            "colour); the peak includes the file's bytes, read once.",
            "",
            "| file | file MiB | real size MiB | result MiB | peak MiB | peak / real size | peak / result | s |",
            "|---|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for (name, data, real), result in large:
            if result["outcome"] != "loaded":
                lines.append(
                    f"| {name} | {len(data) / 2**20:.1f} | {real / 2**20:.1f} | {result['outcome']} | | | | |"
                )
                continue
            lines.append(
                f"| {name} | {len(data) / 2**20:.1f} | {real / 2**20:.1f} | {result['result_mib']:.0f} | "
                f"{result['peak_mib']:,.0f} | {result['peak_mib'] * 2**20 / real:.1f} | "
                f"{result['peak_mib'] / result['result_mib']:.2f} | {result['seconds']:.2f} |"
            )
        lines.append("")
    warned = sum(1 for _, r in results if r.get("warnings"))
    logged = sum(1 for _, r in results if r.get("logged"))
    lines += [
        f"Cases during which a decoder issued a Python warning (printed on stderr unless "
        f"filtered; Pillow's, on odd EXIF or MPO data): {warned:,}; a log record (tifffile's, on "
        f"damaged tags; dropped unless the application configured logging): {logged:,}.",
        "",
    ]
    lines += [BEFORE, ""]
    slowest = sorted(results, key=lambda cr: -cr[1]["seconds"])[:5]
    biggest = sorted(results, key=lambda cr: -cr[1]["peak_mib"])[:5]
    lines += [
        "## Slowest and largest cases",
        "",
        "| case | family/seed | mutation | outcome | s | peak MiB |",
    ]
    lines += ["|---:|---|---|---|---:|---:|"]
    for case, result in slowest + biggest:
        lines.append(
            f"| {case.number} | {case.family}/{case.seed_name} | {case.mutation} {case.detail} | "
            f"{result['outcome']} | {result['seconds']:.2f} | {result['peak_mib']:,.0f} |"
        )
    lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=10_000, help="How many cases (default 10,000).")
    parser.add_argument("--seed", type=int, default=14, help="Master seed of the mutations.")
    parser.add_argument("--out", type=Path, default=RESULTS, help="Markdown file to write.")
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--time-limit", type=float, default=10.0, help="Seconds before a case is a hang.")
    parser.add_argument("--memory-mb", type=int, default=1536, help="Address-space cap of a worker, MiB.")
    parser.add_argument("--case", type=int, help="Run this one case here and print what happened.")
    parser.add_argument("--keep", type=Path, help="Save the file of every failing case in this folder.")
    args = parser.parse_args(argv)

    seeds = make_seeds()
    if args.case is not None:
        case = make_case(args.case, seeds, args.seed)
        print(f"case {case.number}: {case.family}/{case.seed_name}, {case.mutation} {case.detail}")
        from shadeform.io.images import load_image, read_photo

        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / f"case{case.number}.{case.family}"
            path.write_bytes(case.data)
            image = load_image(case.data) if case.in_memory else read_photo(path).image
        print("loaded", image.shape, image.dtype)
        return 0

    results: list[tuple[Case, dict]] = []
    started = time.perf_counter()

    def on_result(case: Case, result: dict) -> None:
        results.append((case, result))
        if result["outcome"] in FAILURES:
            print(
                f"case {case.number} {case.family}/{case.seed_name} {case.mutation} {case.detail}: "
                f"{result['outcome']} {result['detail'][:200]} {result.get('where', '')}",
                file=sys.stderr,
            )
            if args.keep:
                args.keep.mkdir(parents=True, exist_ok=True)
                (args.keep / f"case{case.number}.{case.family}").write_bytes(case.data)
        if len(results) % 1000 == 0:
            print(f"{len(results):,} cases, {time.perf_counter() - started:.0f} s", file=sys.stderr)

    inputs = large_files()
    read_large: dict[int, dict] = {}
    pool = _Pool(args.workers, args.memory_mb, args.time_limit)
    try:
        pool.run((make_case(n, seeds, args.seed) for n in range(args.cases)), on_result)
        large_cases = [
            Case(-1 - k, "large", name, "none", "", data, False, True)
            for k, (name, data, _) in enumerate(inputs)
        ]
        pool.run(large_cases, lambda case, result: read_large.__setitem__(case.number, result))
    finally:
        pool.close()
    results.sort(key=lambda cr: cr[0].number)
    large = [(entry, read_large[-1 - k]) for k, entry in enumerate(inputs)]
    text = report(results, args, time.perf_counter() - started, seeds, large)
    print(text)
    from shadeform.io.atomic import atomic_write

    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, mode="w") as fh:
        fh.write(text)
    count = Counter(r["outcome"] for _, r in results)
    unread = [name for (name, _, _), result in large if result["outcome"] != "loaded"]
    return 1 if any(count[k] for k in FAILURES) or unread else 0


if __name__ == "__main__":
    sys.exit(main())
