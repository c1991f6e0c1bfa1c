"""Depth by averaging many integration paths from a reference pixel (the 2002 method).

The report sets ``z = 0`` at the reference and integrates the slopes ``dz/dx = -a/c``,
``dz/dy = -b/c`` along several paths to each pixel, averaging the results. Here every pixel takes
the mean, over its 4-neighbours one step nearer the reference (breadth-first layers over the mask),
of the neighbour's depth plus the trapezoid-rule step between them. Unrolled, that is the average
over all shortest in-mask paths from the reference, so no single path's error dominates and paths
never leave the object.
"""

from __future__ import annotations

from collections import deque

import numba
import numpy as np

from shadeform.integration._slopes import slopes

_OFFSETS = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]], dtype=np.int64)


@numba.njit(cache=True)
def _paths_kernel(zx, zy, mask, r0, c0, depth, layer, queue):
    # work arrays come from the caller so that numpy (and memory profilers) see them
    h, w = mask.shape
    layer[r0, c0] = 0
    depth[r0, c0] = 0.0
    queue[0] = r0 * w + c0
    head, tail = 0, 1
    while head < tail:
        idx = queue[head]
        head += 1
        r, c = idx // w, idx % w
        if layer[r, c] > 0:
            # all neighbours of the previous layer are final: average their predictions
            total, count = 0.0, 0
            for k in range(4):
                dr, dc = _OFFSETS[k, 0], _OFFSETS[k, 1]
                rr, cc = r + dr, c + dc
                if 0 <= rr < h and 0 <= cc < w and layer[rr, cc] == layer[r, c] - 1:
                    # step from (rr, cc) to (r, c): dx = -dc, dy = +dr (y is up, rows go down)
                    step = 0.5 * (zx[rr, cc] + zx[r, c]) * (-dc) + 0.5 * (zy[rr, cc] + zy[r, c]) * dr
                    total += depth[rr, cc] + step
                    count += 1
            depth[r, c] = total / count
        for k in range(4):
            rr, cc = r + _OFFSETS[k, 0], c + _OFFSETS[k, 1]
            if 0 <= rr < h and 0 <= cc < w and mask[rr, cc] and layer[rr, cc] < 0:
                layer[rr, cc] = layer[r, c] + 1
                queue[tail] = rr * w + cc
                tail += 1


def integrate_paths(normals: np.ndarray, mask: np.ndarray, *, origin: tuple[int, int]) -> np.ndarray:
    """Depth from normals by averaging integration paths from ``origin`` (compiled).

    Parameters
    ----------
    normals : (H, W, 3) float
        Unit normals (camera frame), finite on the mask.
    mask : (H, W) bool
    origin : (int, int)
        (row, col) of the reference pixel, where ``z = 0``; must be on the mask.

    Returns
    -------
    depth : (H, W) float64
        Height in pixel units; NaN outside the mask and on parts not connected to ``origin``.
    """
    mask = np.asarray(mask, dtype=bool)
    zx, zy = slopes(normals, mask)
    depth = np.full(mask.shape, np.nan)
    layer = np.full(mask.shape, -1, dtype=np.int64)
    queue = np.empty(mask.size, dtype=np.int64)
    _paths_kernel(zx, zy, mask, int(origin[0]), int(origin[1]), depth, layer, queue)
    return depth


def integrate_paths_reference(
    normals: np.ndarray, mask: np.ndarray, *, origin: tuple[int, int]
) -> np.ndarray:
    """Slow, plain-Python version of :func:`integrate_paths`, for the tests only."""
    mask = np.asarray(mask, dtype=bool)
    zx, zy = slopes(normals, mask)
    h, w = mask.shape
    layer = {tuple(origin): 0}
    order = [tuple(origin)]
    queue = deque(order)
    while queue:  # breadth-first layers
        r, c = queue.popleft()
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            p = (r + dr, c + dc)
            if 0 <= p[0] < h and 0 <= p[1] < w and mask[p] and p not in layer:
                layer[p] = layer[(r, c)] + 1
                order.append(p)
                queue.append(p)
    depth = np.full((h, w), np.nan)
    depth[tuple(origin)] = 0.0
    for r, c in order[1:]:
        predictions = []
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            q = (r + dr, c + dc)
            if layer.get(q, -2) == layer[(r, c)] - 1:
                dx, dy = -dc, dr  # from q to (r, c)
                predictions.append(depth[q] + 0.5 * (zx[q] + zx[r, c]) * dx + 0.5 * (zy[q] + zy[r, c]) * dy)
        depth[r, c] = np.mean(predictions)
    return depth
