"""No depth deeper than its outline allows: a bound from the mask alone, and a soft limiter.

A solver's depth can run far past what the object's outline allows where the shading misleads it
(a dark mouth read as a deep pit, a printed label read as relief, a part of the object marched
down a wrong slope). The outline tells how deep the object is likely to be, at any scale:

- its *round shape*: the silhouette's shape ``s = 2 sqrt(u)``, ``laplacian(u) = -1`` inside,
  ``u = 0`` on the outline (:func:`shadeform.solvers.photo.silhouette_depth`; exact for a
  sphere). The result's own shape is taken as ``a + b x + c y + d s`` (a tilt, and the round
  shape scaled, d < 0 for a bowl), fitted to its depth in least absolute deviations, so that the
  pixels that stray do not pull the fit;
- its *diameter* ``D``: an object no deeper along the view than across fits in a ball of that
  diameter, whose depths lie within ``D / 2`` of its middle. The fitted shape itself may span at
  most ``D`` over the part (a steeper fit, a sheet stood on edge, is scaled down about its
  median: without this a result marched down a wrong slope is all "shape" and nothing strays),
  and a pixel may stray from it by :data:`SPREAD` ``* D`` (per connected part of the object).
  A plane tilted up to 63 degrees (slope ``1 + 2 SPREAD``) passes unchanged.

Where a result is within the bound it is returned as it is. Beyond, the excess is compressed
smoothly (:func:`soft_limit`: the identity up to the bound, then rising ever more slowly to at
most ``1 + HEADROOM`` times it): a region past the bound follows the fitted shape, tilted and
round, at that distance, not a flat plateau. The change is worked out on a grid of at most
:data:`GRID_PIXELS` object pixels and interpolated to every pixel, so the detail the solver found
stays; the normals are tilted by its gradient, so they stay those of the new depth, and pixels it
leaves alone keep the solver's normals exactly.

Why not the depths on the outline itself: in a result they sit on near-vertical walls (the
occluding contour), where one pixel spans tens of pixels of depth; a surface spanning them
(harmonic) follows a part that was marched down a wrong slope, outline and all (the oblique
solver's vase lit from (5, 5, 7): its neck 170 pixels behind its body on a 128-pixel image).

Where it applies on real photos and on the synthetic grid, and what it does to the errors:
``benchmarks/results/bounds.md`` (``benchmarks/bench_bounds.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

from shadeform._checks import least_absolute
from shadeform.integration._slopes import slopes
from shadeform.solvers.photo import silhouette_depth

__all__ = ["GRID_PIXELS", "HEADROOM", "SPREAD", "DepthBound", "bound_depth", "soft_limit"]

#: How far a pixel may stray from the fitted shape, in units of the outline's diameter: half, the
#: depths of a ball of that diameter around its middle (module description), from geometry.
#: Checked on truths, not tuned: the synthetic scenes reach at most 0.75 of this bound (the
#: saddle, whose slope is 1.5 on its rim), the ground-truth depths of the twelve MIT-Berkeley
#: objects of ../shared/data/real at most 0.92 (paper1, a crumpled sheet; the others 0.67).
SPREAD = 0.5
#: How far past the bound the limiter may go at most, in units of the bound: its output rises to
#: ``1 + HEADROOM`` times it. Set once (half the bound), not tuned.
HEADROOM = 0.5
#: At most this many object pixels on the grid the bound is worked out on (the silhouette's shape
#: is a sparse solve, 0.2 s at 20 000 pixels); a larger object is sampled every few pixels.
GRID_PIXELS = 20_000
# Fewest grid pixels of a part for its shape to be fitted (four coefficients); smaller parts
# are left as they are.
_MIN_PIXELS = 16
# Iterations of the least-absolute-deviations fit.
_FIT_ITERATIONS = 30
# Directions over which the outline's diameter is taken: its extent along each, the largest
# within cos(pi / 32), 0.5 %, of the true diameter.
_DIRECTIONS = 16


@dataclass(frozen=True, eq=False)
class DepthBound:
    """A depth held within what its outline allows.

    Attributes
    ----------
    depth : (H, W) float64
        The depth; the input's own array where nothing was past the bound.
    normals : (H, W, 3)
        Unit normals of ``depth``, of the input's type; the input's own array where nothing was
        past the bound.
    pixels : float
        Share of the object's pixels that were past the bound; 0 when none was.
    max_over : float
        How far the result strayed from its fitted shape at most, in units of the bound: above 1
        where it was past it.
    """

    depth: np.ndarray
    normals: np.ndarray
    pixels: float
    max_over: float

    @property
    def applied(self) -> bool:
        """Whether any pixel was past the bound (and the depth changed)."""
        return self.pixels > 0.0


def soft_limit(values, bound):
    """``values`` unchanged up to ``bound``, then compressed smoothly below ``(1 + HEADROOM) * bound``.

    ``bound + h * bound * tanh((|v| - bound) / (h * bound))`` with the sign of ``v`` and
    ``h = HEADROOM``: continuous with its first derivative at the bound (slope 1 there), so the
    limited surface has no crease and no plateau.

    Parameters
    ----------
    values : array_like
        Heights (any sign).
    bound : array_like
        Positive bounds, broadcast against ``values``.

    Returns
    -------
    ndarray
        The limited values, float64 of ``values``'s shape.

    Examples
    --------
    >>> soft_limit(np.array([1.0, -2.0, 3.0, 100.0]), 2.0).round(3)
    array([ 1.   , -2.   ,  2.762,  3.   ])
    """
    values = np.asarray(values, dtype=np.float64)
    bound = np.broadcast_to(np.asarray(bound, dtype=np.float64), values.shape)
    over = np.abs(values) > bound
    out = values.copy()
    size, room = np.abs(values[over]), HEADROOM * bound[over]
    out[over] = np.sign(values[over]) * (bound[over] + room * np.tanh((size - bound[over]) / room))
    return out


def bound_depth(depth, normals, mask) -> DepthBound:
    """The depth held within what its outline allows (the module's description).

    Parameters
    ----------
    depth : (H, W) float
        Height in pixels (larger = nearer the viewer); only the mask's finite values are read.
    normals : (H, W, 3) float
        Unit normals of ``depth`` (``docs/conventions.md``), NaN where unknown.
    mask : (H, W) bool
        The object. Where it meets the image frame there is no outline (the object goes on
        beyond the picture); a part with no outline in view is not bounded.

    Returns
    -------
    DepthBound
        The input arrays themselves when the result is within the bound; else new ones (the depth
        NaN where the input's was) and how far past the bound it went.

    Examples
    --------
    >>> from shadeform import synth
    >>> scene = synth.scene("sphere", size=64)
    >>> depth = np.where(scene.mask, scene.depth, np.nan)
    >>> bound_depth(depth, scene.normals, scene.mask).applied
    False
    >>> depth[28:36, 28:36] -= 300.0  # a pit far deeper than the outline (54 pixels across) allows
    >>> result = bound_depth(depth, scene.normals, scene.mask)
    >>> result.applied, bool(np.nanmin(result.depth) > -1.5 * SPREAD * 54)
    (True, True)
    """
    depth = np.asarray(depth, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool) & np.isfinite(depth)
    count = int(np.count_nonzero(mask))
    step = max(1, math.ceil(math.sqrt(count / GRID_PIXELS)))
    grid = mask[::step, ::step]
    change = np.zeros(grid.shape)
    worst, past = 0.0, 0
    if grid.any():
        z = depth[::step, ::step]
        shape = silhouette_depth(grid) * step  # in pixels of the input, like the depth
        parts, n_parts = ndi.label(grid)
        for part, where in enumerate(ndi.find_objects(parts), start=1):
            on = parts[where] == part
            if np.count_nonzero(on) < _MIN_PIXELS or not shape[where][on].any():
                continue  # too small to fit, or no outline in view
            rows, cols = np.nonzero(on)
            diameter = _diameter(rows, cols) * step
            bound = SPREAD * diameter
            stray = _stray(z[where][on], rows, cols, shape[where][on], bound, span=diameter)
            worst = max(worst, float(np.abs(stray).max()) / bound)
            past += int(np.count_nonzero(np.abs(stray) > bound))
            change[where][on] = soft_limit(stray, bound) - stray
    if past == 0:
        return DepthBound(depth, normals, 0.0, worst)
    new_depth, new_normals = _moved(depth, normals, mask, change, grid, step)
    return DepthBound(new_depth, new_normals, past / int(np.count_nonzero(grid)), worst)


def _stray(z, rows, cols, shape, scale, *, span):
    """How far the depths ``z`` (n,) at ``rows``, ``cols`` (n,) stray from ``a + b x + c y + d
    shape`` fitted to them in least absolute deviations (``shape`` (n,) the silhouette's, ``scale``
    a length that keeps the coefficients of one size), the fit scaled about its median to span
    at most ``span``, (n,)."""
    design = np.column_stack(
        [np.ones(z.size), (cols - cols.mean()) / scale, (rows - rows.mean()) / scale, shape / scale]
    )
    fit = design @ least_absolute(design, z, iterations=_FIT_ITERATIONS)
    extent = float(np.ptp(fit))
    if extent > span:
        middle = float(np.median(fit))
        fit = middle + (fit - middle) * (span / extent)
    return z - fit


def _diameter(rows, cols):
    """The largest extent of the pixels ``rows``, ``cols`` (n,) over :data:`_DIRECTIONS` directions."""
    angles = np.pi * np.arange(_DIRECTIONS) / _DIRECTIONS
    along = np.column_stack([rows, cols]) @ np.stack([np.cos(angles), np.sin(angles)])
    return max(float(np.ptp(along, axis=0).max()), 1.0)


def _moved(depth, normals, mask, change, grid, step):
    """``depth`` (H, W) plus ``change`` (h, w), given on the object's pixels ``grid`` (h, w) of
    every ``step``-th row and column, interpolated (bilinear) to every pixel, and ``normals``
    (H, W, 3) tilted by its slopes; both new arrays, changed only where the change or its slope
    is not zero (a pixel with no normal keeps none)."""
    if step > 1:  # off the grid's object the change goes on as at its nearest object pixel
        nearest = ndi.distance_transform_edt(~grid, return_distances=False, return_indices=True)
        change = change[tuple(nearest)]
    # the input pixels the change reaches: within a grid step of a changed grid pixel
    rows, cols = np.nonzero(ndi.binary_dilation(change != 0.0, iterations=2))
    box = (
        slice(rows.min() * step, min((rows.max() + 1) * step, depth.shape[0])),
        slice(cols.min() * step, min((cols.max() + 1) * step, depth.shape[1])),
    )
    at = np.meshgrid(
        np.arange(box[0].start, box[0].stop) / step,
        np.arange(box[1].start, box[1].stop) / step,
        indexing="ij",
    )
    moved = ndi.map_coordinates(change, at, order=1, mode="nearest")
    del at
    inside = mask[box]
    new_depth = depth.copy()
    new_depth[box] += np.where(inside, moved, 0.0)
    new_normals = np.array(normals, copy=True)
    # the normals a band of rows at a time (no box-sized (h, w, 3) temporaries): dz/dx = -nx / nz
    # and dz/dy = -ny / nz (y up, rows down), the change's slopes added
    height, width = moved.shape
    rows_per_band = max(1, (1 << 16) // width)
    for top in range(0, height, rows_per_band):
        band = slice(top, min(top + rows_per_band, height))
        around = slice(max(band.start - 1, 0), min(band.stop + 1, height))  # for the differences
        part = moved[around]
        d_row = np.gradient(part, axis=0) if part.shape[0] > 1 else np.zeros_like(part)
        d_col = np.gradient(part, axis=1) if width > 1 else np.zeros_like(part)
        cut = slice(band.start - around.start, band.stop - around.start)
        d_row, d_col = d_row[cut], d_col[cut]
        lines = slice(box[0].start + band.start, box[0].start + band.stop)
        given = normals[lines, box[1]]
        zx, zy = slopes(given, inside[band])
        tilted = np.stack([-(zx + d_col), -(zy - d_row), np.ones_like(zx)], axis=-1)
        tilted /= np.linalg.norm(tilted, axis=-1, keepdims=True)
        turn = inside[band] & ((d_row != 0.0) | (d_col != 0.0)) & np.isfinite(given).all(axis=-1)
        new_normals[lines, box[1]][turn] = tilted[turn]
    return new_depth, new_normals
