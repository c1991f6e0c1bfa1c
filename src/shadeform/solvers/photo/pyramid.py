"""The photo solver's pyramid: 2x2 levels of the image, the mask and the prior, a coarse depth
carried to the next finer level, and Szeliski's hierarchical basis over one level's pixels
(:mod:`shadeform.solvers.photo`).
"""

from __future__ import annotations

import numba
import numpy as np
from scipy import ndimage as ndi


class _Basis:
    """Szeliski's hierarchical basis over one pyramid level's object pixels: the depth is each
    pixel's own coefficient plus, for every factor 2, 4, 8, ... (while the coarse grid is at
    least 4 cells across), the bilinear interpolation of a grid that many times coarser (cell
    centres aligned, ends held). A coarse coefficient moves a whole region at once, which is
    what lets a descent cross scales. Coarse cells are kept only where they reach the object.
    """

    def __init__(self, mask):
        self.rows, self.cols = np.nonzero(mask)
        self.n = self.rows.size
        # all coarse grids in one flat array: per grid, each fine row's two grid rows (as flat
        # starts) and the upper one's weight, each fine column's two grid columns and the upper
        # one's weight, and the grid's width (an image under 8 pixels across has no grid)
        row_steps, col_steps, widths, cells = [], [], [], 0
        factor = 2
        while min(mask.shape) // factor >= 4:
            height, width = (-(-side // factor) for side in mask.shape)
            lower, upper, weight = _axis_steps(mask.shape[0], height, factor)
            row_steps.append((cells + lower * width, cells + upper * width, weight))
            col_steps.append(_axis_steps(mask.shape[1], width, factor))
            widths.append(width)
            cells += height * width
            factor *= 2
        self.steps = tuple(
            np.array([step[i] for step in steps], dtype=dtype).reshape(len(steps), length)
            for steps, length in ((row_steps, mask.shape[0]), (col_steps, mask.shape[1]))
            for i, dtype in enumerate((np.int64, np.int64, np.float64))
        )
        self.widths = np.array(widths, dtype=np.int64)
        self.cells = cells
        reached = np.zeros(cells)
        _spread(np.ones(self.n), self.rows, self.cols, self.widths, *self.steps, reached)
        self.kept = np.flatnonzero(reached > 0)
        self.size = self.n + self.kept.size

    def expand(self, coefficients):
        """(n,) depth on the object's pixels of (size,) coefficients."""
        grids = np.zeros(self.cells)
        grids[self.kept] = coefficients[self.n :]
        z = np.array(coefficients[: self.n], dtype=np.float64)
        _gather(grids, self.rows, self.cols, self.widths, *self.steps, z)
        return z

    def reduce(self, gradient):
        """The transpose of :meth:`expand`: (size,) from (n,) (a gradient with respect to the
        depth becomes one with respect to the coefficients)."""
        grids = np.zeros(self.cells)
        gradient = np.ascontiguousarray(gradient, dtype=np.float64)
        _spread(gradient, self.rows, self.cols, self.widths, *self.steps, grids)
        return np.concatenate([gradient, grids[self.kept]])


def _axis_steps(fine, coarse, factor):
    """Linear interpolation along one axis from ``coarse`` cells to ``factor`` times as many
    ``fine`` ones (cell centres aligned, ends held): each fine cell's lower and upper coarse
    cells and the upper one's weight."""
    at = np.clip((np.arange(fine) + 0.5) / factor - 0.5, 0, coarse - 1)
    lower = np.minimum(np.floor(at).astype(np.int64), max(coarse - 2, 0))
    return lower, np.minimum(lower + 1, coarse - 1), at - lower


@numba.njit(cache=True)
def _gather(grids, rows, cols, widths, row_top, row_bottom, row_weight, col_left, col_right, col_weight, z):
    """Add to ``z`` (n,) every coarse grid's bilinear interpolation at the object's pixels
    (:class:`_Basis` holds the steps)."""
    for k in range(widths.size):
        # the grid interpolated along the rows first: one line per fine row
        lines = np.empty((row_top.shape[1], widths[k]))
        for r in range(lines.shape[0]):
            top, bottom, t = row_top[k, r], row_bottom[k, r], row_weight[k, r]
            for j in range(lines.shape[1]):
                lines[r, j] = grids[top + j] + t * (grids[bottom + j] - grids[top + j])
        left, right, weight = col_left[k], col_right[k], col_weight[k]
        for p in range(z.size):
            r, c = rows[p], cols[p]
            z[p] += lines[r, left[c]] + weight[c] * (lines[r, right[c]] - lines[r, left[c]])


@numba.njit(cache=True)
def _spread(
    values, rows, cols, widths, row_top, row_bottom, row_weight, col_left, col_right, col_weight, grids
):
    """The transpose of :func:`_gather`: add each pixel's value to the coarse cells it reads."""
    for k in range(widths.size):
        lines = np.zeros((row_top.shape[1], widths[k]))
        left, right, weight = col_left[k], col_right[k], col_weight[k]
        for p in range(values.size):
            r, c = rows[p], cols[p]
            lines[r, left[c]] += (1.0 - weight[c]) * values[p]
            lines[r, right[c]] += weight[c] * values[p]
        for r in range(lines.shape[0]):
            top, bottom, t = row_top[k, r], row_bottom[k, r], row_weight[k, r]
            for j in range(lines.shape[1]):
                grids[top + j] += (1.0 - t) * lines[r, j]
                grids[bottom + j] += t * lines[r, j]


def _half(image, mask):
    """The next pyramid level: 2x2 blocks, the image averaged over their object pixels, a block
    on the object when at least two of its pixels are."""
    height, width = (mask.shape[0] // 2) * 2, (mask.shape[1] // 2) * 2
    blocks = mask[:height, :width].reshape(height // 2, 2, width // 2, 2)
    count = blocks.sum(axis=(1, 3))
    total = (
        np.where(mask, image, 0.0)[:height, :width].reshape(height // 2, 2, width // 2, 2).sum(axis=(1, 3))
    )
    return np.where(count > 0, total / np.maximum(count, 1), 0.0), count >= 2


def _double(depth, coarse_mask, mask):
    """A coarse level's depth on the next finer level's grid (heights doubled: pixel units)."""
    nearest = ndi.distance_transform_edt(~coarse_mask, return_distances=False, return_indices=True)
    filled = depth[tuple(nearest)]
    rows = (np.arange(mask.shape[0]) + 0.5) / 2 - 0.5
    cols = (np.arange(mask.shape[1]) + 0.5) / 2 - 0.5
    grid = np.meshgrid(rows, cols, indexing="ij")
    return 2.0 * ndi.map_coordinates(filled, grid, order=1, mode="nearest")


def _prior_level(normals, weight, mask):
    """The prior's unit normals and weights on a level's grid, 0 off its object."""
    normals = np.where(mask[..., None], np.nan_to_num(normals), 0.0)
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    normals = np.where(length > 0, normals / np.maximum(length, 1e-12), 0.0)
    return normals, np.where(mask, np.nan_to_num(weight), 0.0)


def _half_prior(normals, weight, mask):
    """The prior one pyramid level coarser: normals and weights averaged over 2x2 blocks."""
    parts = [_half(normals[..., axis], mask)[0] for axis in range(3)]
    return np.stack(parts, axis=-1), _half(weight, mask)[0]
