"""Writing a tiled run's result: the depth band by band (a tiled BigTIFF or an array), the mesh."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from shadeform.errors import InputError
from shadeform.tiled.join import Tiling, _band

#: Side of the output's TIFF tiles: the largest of these dividing ``tile``.
_TIFF_TILES = (512, 256, 128, 64, 32, 16)


def _write(grid: Tiling, names, offsets, out: Path | None, tags: dict, step: int | None, progress):
    """Blend band by band into ``out`` (a tiled BigTIFF) or an array; also the mesh's samples
    (every ``step``-th row and column), if ``step``, and the depth's range (:func:`_extent`).
    Returns ``(depth or None, samples or None, range)``."""
    samples: list[np.ndarray] = []
    spans: list[np.ndarray] = []
    bands = grid.rows

    def sample(band: np.ndarray, i: int) -> None:
        seen = band[::4, ::4]
        seen = seen[np.isfinite(seen)]
        if seen.size:
            spans.append(np.percentile(seen, [1, 99]))
        if step is not None:
            k0 = i * grid.tile
            first = (-k0) % step
            samples.append(np.array(band[first::step, ::step]))
        if progress:
            progress("write", i + 1, bands)

    if out is None:
        depth = np.empty((grid.height, grid.width), dtype=np.float32)
        for i in range(bands):
            k0, k1, _, _ = grid.span(i, grid.height)
            depth[k0:k1] = _band(grid, names, offsets, i)
            sample(depth[k0:k1], i)
        return depth, _stack(samples), _extent(spans)

    import tifffile

    from shadeform.io.atomic import atomic_write

    side = next(s for s in _TIFF_TILES if grid.tile % s == 0)

    def tiff_tiles():
        for i in range(bands):
            band = _band(grid, names, offsets, i)
            sample(band, i)
            for r in range(0, band.shape[0], side):
                for c in range(0, grid.width, side):
                    block = np.full((side, side), np.nan, dtype=np.float32)
                    part = band[r : r + side, c : c + side]
                    block[: part.shape[0], : part.shape[1]] = part
                    yield block

    extratags = [(code, dtype, count, value, True) for code, (dtype, count, value) in sorted(tags.items())]
    with atomic_write(out) as handle:
        tifffile.imwrite(
            handle,
            data=tiff_tiles(),
            shape=(grid.height, grid.width),
            dtype=np.float32,
            tile=(side, side),
            bigtiff=True,
            compression="zlib",
            predictor=3,
            extratags=extratags,
            metadata=None,
        )
    return None, _stack(samples), _extent(spans)


def _extent(spans: list[np.ndarray]) -> float:
    """The depth's range, from the bands' 1st to 99th percentiles (spikes left out)."""
    return float(max(s[1] for s in spans) - min(s[0] for s in spans)) if spans else 0.0


def _stack(samples: list[np.ndarray]) -> np.ndarray | None:
    return np.concatenate(samples, axis=0) if samples else None


# --- mesh --------------------------------------------------------------------------------------


def _mesh_step(grid: Tiling, max_triangles: int) -> int:
    """Grid spacing giving about ``OVERSAMPLE * max_triangles`` triangles (two per cell)."""
    from shadeform.solid import OVERSAMPLE

    cells = OVERSAMPLE * max_triangles / 2
    return max(1, math.ceil(math.sqrt(grid.height * grid.width / cells)))


def _write_mesh(samples: np.ndarray, step: int, max_triangles: int, path: Path) -> None:
    """The depth samples (every ``step``-th pixel) as a grid mesh, decimated to the budget."""
    from shadeform.io.exporters import export
    from shadeform.mesh import Mesh, cell_triangles, vertex_normals
    from shadeform.solid.options import require_print_extra

    valid = np.isfinite(samples)
    ids = np.full(samples.shape, -1, dtype=np.int64)
    ids[valid] = np.arange(np.count_nonzero(valid))
    rows, cols = np.nonzero(valid)
    vertices = np.column_stack([cols * step, -rows * step, samples[valid]]).astype(np.float64)
    tl, tr, bl, br = ids[:-1, :-1], ids[:-1, 1:], ids[1:, :-1], ids[1:, 1:]
    cells = (tl >= 0) & (tr >= 0) & (bl >= 0) & (br >= 0)
    faces = cell_triangles(tl[cells], tr[cells], bl[cells], br[cells])
    if len(faces) == 0:
        raise InputError("the depth map has no 2x2 block of data on the mesh grid; there is no mesh to make")
    if len(faces) > max_triangles:
        simplify, _ = require_print_extra()
        vertices, faces = simplify(
            vertices.astype(np.float32),
            faces.astype(np.int64),
            target_count=max_triangles,
            preserve_border=True,
        )
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
    export(Mesh(vertices, faces, vertex_normals(vertices, faces)), path)
