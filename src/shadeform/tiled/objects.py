"""The object in a huge photo: found once on a coarse overview of the whole frame, carried to
every tile.

A tile of a photo of an object does not see the photo's frame, so it cannot tell the object
from its background; the whole photo can. The image is read once, band by band, into an
overview of at most :data:`OVERVIEW_PIXELS` pixels (each the mean of a square block of
``factor`` x ``factor`` pixels), :func:`shadeform.masks.find_object` finds the object there as
it would on a photo solved whole, and every tile takes the overview's mask over its window,
enlarged back to full resolution (:class:`CoarseMask`). Within one block of the outline, where
a block holds both object and background, a pixel is object only if it stands out from the
background as the overview shows it (past the 99th percentile of the background's blocks away
from the object). A picture that is one surface filling the frame (a relief, a microscope
field) is all object, as when solved whole. A mask given by the user is used as it is, at full
resolution: an array, or an image file (a TIFF read window by window).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage as ndi

from shadeform.errors import InputError
from shadeform.tiled.reading import TiffWindows, shading

#: Most pixels of the overview the object is found on: 2^22 (2048 x 2048), found in about
#: 1.3 s (a 2048-pixel sphere); a 108 Mpx photo is seen in blocks of 6 x 6 pixels.
OVERVIEW_PIXELS = 2**22
#: Bytes of input read at once while making the overview.
_BAND_BYTES = 2**26
#: Percentile of the background's blocks a pixel near the outline must pass to be object.
_BACKGROUND_PERCENTILE = 99.0
#: The word for "every pixel is the object" (``mask="whole"``).
WHOLE = "whole"


def overview_factor(shape: tuple[int, int]) -> int:
    """Side of the square blocks averaged into one overview pixel."""
    return max(1, math.ceil(math.sqrt(shape[0] * shape[1] / OVERVIEW_PIXELS)))


def overview(reader, dtype, shape: tuple[int, int], factor: int) -> np.ndarray:
    """The image's shading averaged over blocks of ``factor`` x ``factor`` pixels (partial
    blocks at the right and bottom edges averaged over what they hold), read band by band."""
    height, width = shape
    rows = max(factor, _BAND_BYTES // max(1, width * 16) // factor * factor)
    out = np.empty((math.ceil(height / factor), math.ceil(width / factor)), dtype=np.float32)
    for r0 in range(0, height, rows):
        r1 = min(r0 + rows, height)
        band = shading(np.asarray(reader[r0:r1, :]), dtype).astype(np.float64)
        out[r0 // factor : math.ceil(r1 / factor)] = _block_mean(band, factor)
    return out


def _block_mean(band: np.ndarray, factor: int) -> np.ndarray:
    if factor == 1:
        return band
    h, w = band.shape
    rows, cols = math.ceil(h / factor), math.ceil(w / factor)
    sums = np.add.reduceat(
        np.add.reduceat(band, np.arange(0, h, factor), axis=0), np.arange(0, w, factor), axis=1
    )
    counts = np.outer(np.diff(np.r_[np.arange(0, h, factor), h]), np.diff(np.r_[np.arange(0, w, factor), w]))
    return (sums / counts)[:rows, :cols]


@dataclass(frozen=True, eq=False)
class CoarseMask:
    """The object found on the overview: ``cells`` (one per block of ``factor`` pixels),
    ``limit`` the background's level a pixel near the outline must pass (``dark``: stay below)."""

    cells: np.ndarray
    factor: int
    limit: float
    dark: bool
    note: str

    def part(self, window: tuple[slice, slice]) -> _CoarsePart:
        """What a tile needs of the mask: the blocks over its window, and one more each side."""
        f = self.factor
        b0, b1 = max(window[0].start // f - 1, 0), window[0].stop // f + 2
        a0, a1 = max(window[1].start // f - 1, 0), window[1].stop // f + 2
        cells = self.cells[b0:b1, a0:a1]
        return _CoarsePart(np.array(cells), window[0].start - b0 * f, window[1].start - a0 * f, self)


@dataclass(frozen=True, eq=False)
class _CoarsePart:
    cells: np.ndarray
    row: int
    col: int
    whole: CoarseMask

    def mask(self, image: np.ndarray) -> np.ndarray:
        """The tile's mask at full resolution, given its shading ``image``."""
        f, (h, w) = self.whole.factor, image.shape
        if f == 1:
            return self.cells[self.row : self.row + h, self.col : self.col + w].copy()
        cells = self.cells
        edge = ndi.binary_dilation(cells, np.ones((3, 3), bool)) & ~ndi.binary_erosion(
            cells, np.ones((3, 3), bool), border_value=1
        )
        rows = (np.arange(h) + self.row) // f
        cols = (np.arange(w) + self.col) // f
        inside = cells[np.ix_(rows, cols)]
        near = edge[np.ix_(rows, cols)]
        stands_out = image < self.whole.limit if self.whole.dark else image > self.whole.limit
        return np.where(near, stands_out, inside)


@dataclass(frozen=True, eq=False)
class _GivenPart:
    """A window of a mask given at full resolution: in memory, or read from a TIFF."""

    values: np.ndarray | None = None
    reader: TiffWindows | None = None
    window: tuple[slice, slice] | None = None

    def mask(self, image: np.ndarray) -> np.ndarray:
        values = self.values if self.reader is None else self.reader[self.window]
        values = np.asarray(values)
        return (values[..., 0] if values.ndim == 3 else values) != 0


class ObjectMask:
    """Where the object is, for every tile: found on the overview, given, or the whole frame."""

    def __init__(self, kind: str, *, coarse: CoarseMask | None = None, given=None, note: str = ""):
        self.kind, self.coarse, self.given, self.note = kind, coarse, given, note

    def part(self, window: tuple[slice, slice]):
        """What travels with a tile's task (small): None for the whole frame."""
        if self.kind == WHOLE:
            return None
        if self.coarse is not None:
            return self.coarse.part(window)
        if isinstance(self.given, TiffWindows):
            return _GivenPart(reader=self.given, window=window)
        return _GivenPart(values=np.asarray(self.given[window]))

    def identity(self):
        """What names the mask in the work folder's manifest."""
        if self.kind == "given" and isinstance(self.given, TiffWindows):
            stat = self.given.path.stat()
            return {
                "path": str(self.given.path.resolve()),
                "bytes": stat.st_size,
                "mtime_ns": stat.st_mtime_ns,
            }
        if self.kind == "given":
            import hashlib

            return {
                "sha1": hashlib.sha1(np.packbits(np.asarray(self.given, dtype=bool)).tobytes()).hexdigest()
            }
        return self.kind


def object_mask(mask, reader, dtype, shape: tuple[int, int]) -> ObjectMask:
    """The object's mask for a tiled run (see the module's description).

    ``mask``: None (found on the overview), ``"whole"``, an (H, W) array, or a path to a mask
    image of the photo's size (non-zero pixels are the object)."""
    if isinstance(mask, str) and mask == WHOLE:
        return ObjectMask(WHOLE, note="the whole frame is the object")
    if mask is None:
        return _found(reader, dtype, shape)
    if isinstance(mask, (str, os.PathLike)):
        return _given_file(Path(mask), shape)
    try:
        array = np.asarray(mask)
    except (TypeError, ValueError):
        array = None
    if array is None or array.dtype == object or array.shape != tuple(shape):
        raise InputError(
            f"mask must be an array of the image's shape {tuple(shape)}, a mask image or "
            f"'{WHOLE}', got {type(mask).__name__} {getattr(array, 'shape', '')}"
        )
    if not array.any():
        raise InputError("the mask is empty: no pixel is object; give a mask with the object on it")
    return ObjectMask("given", given=array.astype(bool, copy=False), note="the mask given")


def _given_file(path: Path, shape: tuple[int, int]) -> ObjectMask:
    from shadeform.io.images import load_mask

    if path.suffix.lower() in (".tif", ".tiff"):  # read window by window, never whole
        reader = TiffWindows(path)
        if tuple(reader.shape[:2]) != tuple(shape):
            raise InputError(
                f"mask '{path}' is {reader.shape[1]}x{reader.shape[0]} pixels, the image "
                f"{shape[1]}x{shape[0]}; give a mask of the image's size"
            )
        return ObjectMask("given", given=reader, note=f"the mask {path.name}")
    array = load_mask(path, shape=tuple(shape), max_pixels=shape[0] * shape[1])
    return ObjectMask("given", given=array, note=f"the mask {path.name}")


def _found(reader, dtype, shape: tuple[int, int]) -> ObjectMask:
    from shadeform.masks import find_object

    factor = overview_factor(shape)
    small = overview(reader, dtype, shape, factor)
    found = find_object(small)
    if found.whole_frame:
        return ObjectMask(WHOLE, note=found.note)
    cells = found.mask
    away = ~ndi.binary_dilation(cells, iterations=2)
    background = small[away] if away.any() else small[~cells]
    percentile = 100.0 - _BACKGROUND_PERCENTILE if found.dark else _BACKGROUND_PERCENTILE
    limit = float(np.percentile(background, percentile)) if background.size else float(found.threshold)
    coarse = CoarseMask(cells, factor, limit, bool(found.dark), found.note)
    return ObjectMask("found", coarse=coarse, note=found.note)
