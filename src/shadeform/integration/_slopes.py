"""Surface slopes from normals, shared by the integrators."""

from __future__ import annotations

import numpy as np

#: Smallest |n_z| used when turning normals into slopes: caps |grad z| at 1 / MIN_NZ so the few
#: silhouette pixels that face sideways cannot throw the depth around.
MIN_NZ = 0.05


def slopes(normals: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``dz/dx = -n_x / n_z`` and ``dz/dy = -n_y / n_z`` (y up), 0 outside the mask.

    Parameters
    ----------
    normals : (H, W, 3) float
    mask : (H, W) bool

    Returns
    -------
    zx, zy : (H, W) float64
    """
    nz = np.maximum(np.nan_to_num(normals[..., 2], nan=1.0), MIN_NZ)
    zx = np.where(mask, -np.nan_to_num(normals[..., 0]) / nz, 0.0)
    zy = np.where(mask, -np.nan_to_num(normals[..., 1]) / nz, 0.0)
    return zx, zy
