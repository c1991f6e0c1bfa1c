"""Small hostile files the fuzzers send (``fuzz_cli.py``, ``fuzz_server.py``): a PNG whose header
claims more pixels than it holds, and a JPEG whose EXIF block is damaged."""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np


def png_claiming(width: int, height: int, *, colour: bool = True) -> bytes:
    """A PNG of a few dozen bytes whose IHDR declares ``width`` x ``height`` pixels (RGB, or grey
    with ``colour=False``) and holds almost none."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 2 if colour else 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(b"\0" * 16))
        + chunk(b"IEND", b"")
    )


def jpeg_with_damaged_exif(side: int = 16) -> bytes:
    """A ``side`` x ``side`` JPEG of seeded grey noise (a picture that can be solved) whose EXIF
    orientation entry runs past its data (Pillow warns "Corrupt EXIF data" on every read)."""
    from PIL import Image

    exif = b"Exif\x00\x00MM\x00*\x00\x00\x00\x08\x00\x05\x01\x12\x00\x03\x00\x00\x00\x01\x00\x06"
    buffer = io.BytesIO()
    picture = np.random.default_rng(0).integers(0, 256, (side, side), dtype=np.uint8)
    Image.fromarray(picture).save(buffer, format="JPEG", exif=exif)
    return buffer.getvalue()
