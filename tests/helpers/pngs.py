"""Pixel arrays and PNG files for the image-loading tests, written without Pillow (the loader's
own decoder) so that a round trip checks the loader against an independent encoder."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import png

#: The arrays below are its first draws; the image tests draw on from it.
RNG = np.random.default_rng(20020101)
RGB8 = RNG.integers(0, 256, size=(12, 17, 3), dtype=np.uint8)
GRAY8 = RNG.integers(0, 256, size=(12, 17), dtype=np.uint8)
# Values spread over the whole 16-bit range, most of them not multiples of 257.
RGB16 = RNG.integers(0, 65536, size=(12, 17, 3), dtype=np.uint16)
GRAY16 = RNG.integers(0, 65536, size=(12, 17), dtype=np.uint16)


def unit16(values):
    return values.astype(np.float32) / np.float32(65535)


def unit8(values):
    return values.astype(np.float32) / np.float32(255)


def write_png16(path, values):
    """Write (H, W) or (H, W, 3) uint16 with pypng (an encoder independent of Pillow)."""
    height, width = values.shape[:2]
    greyscale = values.ndim == 2
    writer = png.Writer(width, height, greyscale=greyscale, bitdepth=16)
    with open(path, "wb") as fh:
        writer.write(fh, values.reshape(height, -1).tolist())
    return path


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_with_ihdr(width, height, *, bitdepth=8, colortype=2):
    """A tiny PNG whose IHDR declares any size (the pixel data is a few bytes)."""
    ihdr = struct.pack(">IIBBBBB", width, height, bitdepth, colortype, 0, 0, 0)
    idat = zlib.compress(b"\x00" * 16)
    return (
        b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", idat) + png_chunk(b"IEND", b"")
    )
