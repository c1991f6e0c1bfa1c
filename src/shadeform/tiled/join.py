"""The tiles' grid and their join: one offset per tile from the overlaps, then the blend."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Tiling:
    """An image cut into tiles: tile ``(i, j)`` has core rows ``[i t, (i + 1) t)``, a halo of ``o``
    each side, clipped to the image."""

    height: int
    width: int
    tile: int
    overlap: int

    @property
    def rows(self) -> int:
        return math.ceil(self.height / self.tile)

    @property
    def cols(self) -> int:
        return math.ceil(self.width / self.tile)

    def span(self, k: int, size: int) -> tuple[int, int, int, int]:
        """Core ``[k0, k1)`` and extended ``[e0, e1)`` of tile ``k`` along an axis of ``size``."""
        k0, k1 = k * self.tile, min((k + 1) * self.tile, size)
        return k0, k1, max(k0 - self.overlap, 0), min(k1 + self.overlap, size)

    def window(self, i: int, j: int) -> tuple[slice, slice]:
        _, _, r0, r1 = self.span(i, self.height)
        _, _, c0, c1 = self.span(j, self.width)
        return slice(r0, r1), slice(c0, c1)

    def weight(self, k: int, size: int) -> np.ndarray:
        """1-D blend weight over tile ``k``'s extended span: 1 in the core, a smooth step
        ``3u^2 - 2u^3`` across ``overlap`` pixels centred on each border with a neighbour, 0
        beyond. Two neighbours' steps are mirror images, so the weights sum to one."""
        k0, k1, e0, e1 = self.span(k, size)
        x = np.arange(e0, e1, dtype=np.float64) + 0.5
        w = np.ones(e1 - e0)
        half = self.overlap / 2.0
        if k0 > 0:
            w *= _smoothstep((x - (k0 - half)) / self.overlap)
        if k1 < size:
            w *= 1.0 - _smoothstep((x - (k1 - half)) / self.overlap)
        return w

    def used(self, k: int, size: int) -> tuple[int, int]:
        """Where tile ``k``'s weight is not zero: its core widened by half the overlap."""
        k0, k1, _, _ = self.span(k, size)
        half = self.overlap // 2
        return max(k0 - half, 0), min(k1 + half, size)


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _load(path: Path) -> np.ndarray:
    return np.load(path, mmap_mode="r")


def _pairs(grid: Tiling):
    """Overlapping tile pairs ``((i, j), (i2, j2), rows, cols)``: neighbours and diagonals, with
    the slices (image coordinates) where both tiles' weights are not zero."""
    for i in range(grid.rows):
        for j in range(grid.cols):
            for di, dj in ((0, 1), (1, -1), (1, 0), (1, 1)):
                i2, j2 = i + di, j + dj
                if not (0 <= i2 < grid.rows and 0 <= j2 < grid.cols):
                    continue
                a0, a1 = grid.used(i, grid.height)
                b0, b1 = grid.used(i2, grid.height)
                c0, c1 = grid.used(j, grid.width)
                d0, d1 = grid.used(j2, grid.width)
                rows = (max(a0, b0), min(a1, b1))
                cols = (max(c0, d0), min(c1, d1))
                if rows[1] > rows[0] and cols[1] > cols[0]:
                    yield (i, j), (i2, j2), rows, cols


def _part(grid: Tiling, names, key, rows, cols) -> np.ndarray:
    """Tile ``key``'s depth over image rows ``[rows)`` and columns ``[cols)``."""
    i, j = key
    window = grid.window(i, j)
    r0, c0 = window[0].start, window[1].start
    return np.asarray(
        _load(names[key])[rows[0] - r0 : rows[1] - r0, cols[0] - c0 : cols[1] - c0], dtype=np.float64
    )


def _offsets(grid: Tiling, names) -> dict:
    """Each tile's offset: least squares over the median differences of overlapping tiles, zero
    for the first tile with data of every connected group of tiles."""
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse.linalg import spsolve

    keys = list(names)
    index = {key: n for n, key in enumerate(keys)}
    rows, cols, weights, values = [], [], [], []
    for a, b, r, c in _pairs(grid):
        diff = _part(grid, names, a, r, c) - _part(grid, names, b, r, c)
        diff = diff[np.isfinite(diff)]
        if diff.size == 0:
            continue
        rows.append(index[a])
        cols.append(index[b])
        weights.append(float(diff.size))
        values.append(float(np.median(diff)))  # robust to a feature one tile reads wrongly
    n = len(keys)
    offsets = np.zeros(n)
    if rows:
        # normal equations of sum w (x_a - x_b + d)^2: a weighted graph Laplacian
        rows_, cols_, w, d = map(np.asarray, (rows, cols, weights, values))
        adjacency = sparse.coo_matrix((w, (rows_, cols_)), shape=(n, n)).tocsr()
        adjacency = adjacency + adjacency.T
        laplacian = sparse.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency
        rhs = np.zeros(n)
        np.add.at(rhs, rows_, -w * d)
        np.add.at(rhs, cols_, w * d)
        _, group = connected_components(adjacency, directed=False)
        pinned = np.zeros(n, dtype=bool)
        for g in np.unique(group):
            pinned[np.flatnonzero(group == g)[0]] = True
        free = ~pinned
        if free.any():
            system = laplacian[free][:, free].tocsc()
            offsets[free] = spsolve(system, rhs[free])
    return {key: float(offsets[index[key]]) for key in keys}


def _disagreement(grid: Tiling, names, offsets) -> tuple[float, float]:
    """Largest and root-mean-square height difference of overlapping tiles after the offsets."""
    largest, squares, count = 0.0, 0.0, 0
    for a, b, r, c in _pairs(grid):
        diff = (_part(grid, names, a, r, c) + offsets[a]) - (_part(grid, names, b, r, c) + offsets[b])
        diff = diff[np.isfinite(diff)]
        if diff.size:
            largest = max(largest, float(np.abs(diff).max()))
            squares += float(np.sum(diff * diff))
            count += diff.size
    return largest, (math.sqrt(squares / count) if count else 0.0)


def _band(grid: Tiling, names, offsets, i: int) -> np.ndarray:
    """Core rows of tile row ``i``, all columns: the aligned tiles blended."""
    k0, k1, _, _ = grid.span(i, grid.height)
    total = np.zeros((k1 - k0, grid.width), dtype=np.float32)
    weight = np.zeros((k1 - k0, grid.width), dtype=np.float32)
    for a in range(max(i - 1, 0), min(i + 2, grid.rows)):
        u0, u1 = grid.used(a, grid.height)
        r0, r1 = max(u0, k0), min(u1, k1)
        if r1 <= r0:
            continue
        _, _, e0, _ = grid.span(a, grid.height)
        w_rows = grid.weight(a, grid.height)[r0 - e0 : r1 - e0]
        for b in range(grid.cols):
            c0, c1 = grid.used(b, grid.width)
            _, _, f0, _ = grid.span(b, grid.width)
            w_cols = grid.weight(b, grid.width)[c0 - f0 : c1 - f0]
            part = _part(grid, names, (a, b), (r0, r1), (c0, c1)) + offsets[(a, b)]
            w = np.outer(w_rows, w_cols)
            w[~np.isfinite(part)] = 0.0
            total[r0 - k0 : r1 - k0, c0:c1] += (w * np.nan_to_num(part)).astype(np.float32)
            weight[r0 - k0 : r1 - k0, c0:c1] += w.astype(np.float32)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 0, total / weight, np.float32(np.nan)).astype(np.float32)
