"""Small hand-made surfaces of known depth and normals, shared by the integration tests."""

import numpy as np


def normals_of(zx, zy):
    """Unit normals of a surface with slopes ``dz/dx = zx``, ``dz/dy = zy``: (H, W, 3)."""
    n = np.stack([-zx, -zy, np.ones_like(zx)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def pixel_xy(shape):
    """Camera-frame pixel coordinates ``x = col``, ``y = -row``."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    return cols, -rows


def l_shaped_mask(shape=(30, 40)):
    """A non-convex mask: two bars meeting at a corner."""
    mask = np.zeros(shape, bool)
    mask[2:28, 3:12] = True
    mask[20:28, 3:37] = True
    return mask
