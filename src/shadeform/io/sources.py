"""A file to decode, read once and guarded, and the errors the image readers raise.

A file's content is read whole, once (:class:`_Source`), after its size on disk is checked
against what ``max_pixels`` warrants; every failure of a third-party decoder on it becomes an
:class:`~shadeform.errors.InputError` naming the file (:func:`_decoding`), and a picture larger
than ``max_pixels`` allows an :class:`ImageTooLargeError`. The checks of each format's header
(:mod:`shadeform.io.headers`, :mod:`shadeform.io.tiffs`) and the decoders
(:mod:`shadeform.io.decoding`) build on these.
"""

from __future__ import annotations

import stat
import struct
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import png
from PIL import Image

from shadeform.errors import InputError

__all__ = ["MEMORY_NAME", "ImageTooLargeError", "naming"]

#: What a file's content, given as bytes instead of a path, is called in messages.
MEMORY_NAME = "image data"


def naming(message: str, name: str) -> str:
    """A loader's ``message`` about bytes read from memory, naming ``name`` (the file the bytes
    came from: an upload's file name) where it said :data:`MEMORY_NAME`."""
    return message.replace(f"'{MEMORY_NAME}'", f"'{name}'")


class ImageTooLargeError(InputError):
    """An image (or image file) larger than ``max_pixels`` allows, refused before decoding.

    A subclass of :class:`shadeform.InputError`, so that a caller can tell "too large" from
    "not an image" (the app answers 413 to one and 415 to the other).
    """


#: Largest file read, in bytes per pixel of ``max_pixels`` (uncompressed float RGBA), plus a
#: margin for metadata: the whole file is read into memory once, so it is capped before that.
_FILE_BYTES_PER_PIXEL, _FILE_BYTES_MARGIN = 16, 64 * 2**20


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


def _unsupported(source: _Source, what: str, advice: str) -> InputError:
    return InputError(f"unsupported image: '{source}' {what}; {advice}")
