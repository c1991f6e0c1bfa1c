"""Normals on the shading cone, tilted along the depth's gradient (compiled, with a reference).

With the light at +z the image fixes each normal's angle to the view (``n_z = c = I / k``) but not
its tilt, which the eikonal depth gives. :func:`cone_normals` keeps ``n_z = c`` exactly and takes
only the tilt (the direction of steepest descent) from the depth, by central differences where
both neighbours are on the mask and one-sided ones where only one is: the normals then render
back to the image whatever error the depth's finite differences carry. It is compiled;
:func:`cone_normals_reference` is the same in plain numpy, for the tests.

Conventions (``docs/conventions.md``): x along the columns, y up (one row down is -1 in y),
z toward the viewer.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["cone_normals", "cone_normals_reference"]


def cone_normals(
    depth: np.ndarray, mask: np.ndarray, cos_theta: np.ndarray, *, dtype=np.float64
) -> np.ndarray:
    """Normals with ``n_z = cos_theta`` tilted along the steepest descent of ``depth`` (compiled).

    Parameters
    ----------
    depth : (H, W) float
        Height; read only on ``mask``.
    mask : (H, W) bool
    cos_theta : (H, W) float
        Required ``n_z``, clipped to [0, 1] (``I / k`` for a light at +z).
    dtype : {numpy.float64, numpy.float32}, keyword-only
        Of the result; computed in float64 either way (float32 is what
        :func:`shadeform.reconstruct` keeps: half the memory).

    Returns
    -------
    normals : (H, W, 3) ``dtype``
        Unit normals, NaN outside the mask. The gradient uses central differences where both
        neighbours are on the mask, one-sided ones where only one is; where it vanishes the
        normal is ``(0, 0, 1)``.
    """
    # C-ordered, fixed types: one compiled specialisation per output type
    depth = np.ascontiguousarray(depth, dtype=np.float64)
    mask = np.ascontiguousarray(mask, dtype=bool)
    cos = np.ascontiguousarray(cos_theta, dtype=np.float64)  # clipped in the kernel: no copy
    normals = np.full(mask.shape + (3,), np.nan, dtype=dtype)
    _cone_normals_kernel(depth, mask, cos, normals)
    return normals


def cone_normals_reference(depth: np.ndarray, mask: np.ndarray, cos_theta: np.ndarray) -> np.ndarray:
    """Plain numpy version of :func:`cone_normals` (same arguments and result), for the tests."""
    mask = np.asarray(mask, dtype=bool)
    z = np.where(mask, depth, 0.0)

    def derivative(axis: int) -> np.ndarray:
        forward = np.zeros_like(z)
        has_forward = np.zeros(mask.shape, dtype=bool)
        lead = [slice(None)] * 2
        trail = [slice(None)] * 2
        lead[axis], trail[axis] = slice(1, None), slice(None, -1)
        lead, trail = tuple(lead), tuple(trail)
        pair = mask[lead] & mask[trail]
        forward[trail] = np.where(pair, z[lead] - z[trail], 0.0)
        has_forward[trail] = pair
        backward = np.zeros_like(z)
        has_backward = np.zeros(mask.shape, dtype=bool)
        backward[lead] = forward[trail]
        has_backward[lead] = pair
        count = has_forward.astype(np.float64) + has_backward
        return (forward + backward) / np.maximum(count, 1.0)

    zx = derivative(1)
    zy = -derivative(0)  # y is up: one row down is -1 in y
    slope = np.hypot(zx, zy)
    cos = np.clip(cos_theta, 0.0, 1.0)
    sin = np.sqrt(1.0 - cos * cos)
    flat = slope == 0
    scale = np.where(flat, 0.0, sin / np.where(flat, 1.0, slope))
    normals = np.stack([-zx * scale, -zy * scale, np.where(flat, 1.0, cos)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[~mask] = np.nan
    return normals


@numba.njit(cache=True)
def _cone_normals_kernel(z, mask, cos, out):
    height, width = mask.shape
    for r in range(height):
        for c in range(width):
            if not mask[r, c]:
                continue
            # d/dx along the row, d/drow down the column: the mean of the one-sided
            # differences that stay on the mask
            gx = 0.0
            n = 0
            if c + 1 < width and mask[r, c + 1]:
                gx += z[r, c + 1] - z[r, c]
                n += 1
            if c > 0 and mask[r, c - 1]:
                gx += z[r, c] - z[r, c - 1]
                n += 1
            if n:
                gx /= n
            grow = 0.0
            n = 0
            if r + 1 < height and mask[r + 1, c]:
                grow += z[r + 1, c] - z[r, c]
                n += 1
            if r > 0 and mask[r - 1, c]:
                grow += z[r, c] - z[r - 1, c]
                n += 1
            if n:
                grow /= n
            gy = -grow  # y is up
            slope = np.sqrt(gx * gx + gy * gy)
            if slope == 0.0:
                out[r, c, 0] = 0.0
                out[r, c, 1] = 0.0
                out[r, c, 2] = 1.0
                continue
            nz = min(max(cos[r, c], 0.0), 1.0)
            sin = np.sqrt(1.0 - nz * nz)
            nx = -gx / slope * sin
            ny = -gy / slope * sin
            length = np.sqrt(nx * nx + ny * ny + nz * nz)
            out[r, c, 0] = nx / length
            out[r, c, 1] = ny / length
            out[r, c, 2] = nz / length
