"""Depth by the discrete Poisson equation on the whole rectangle, solved with the DCT.

Frankot & Chellappa (1988) project the gradient onto integrable fields with the Fourier transform;
with Neumann boundaries (no periodic wrap-around) the discrete least-squares problem over every
4-neighbour pair of a rectangle, ``D^T D z = D^T s``, is diagonalised by the type-II discrete cosine
transform (Simchony, Chellappa & Shao 1990), so one forward and one inverse DCT solve it exactly.
This is the speed limit for full rectangles. On any other mask the slopes outside the mask are
taken as 0 (a flat surround), which is only an approximation near the silhouette: use "poisson"
there.

References
----------
.. [1] R. T. Frankot, R. Chellappa, "A method for enforcing integrability in shape from shading
   algorithms", IEEE PAMI 10(4), 1988.
.. [2] T. Simchony, R. Chellappa, M. Shao, "Direct analytical methods for solving Poisson
   equations in computer vision problems", IEEE PAMI 12(5), 1990.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy import fft

from shadeform.integration._slopes import MIN_NZ, slopes


def integrate_fourier(
    normals: np.ndarray, mask: np.ndarray, *, origin: tuple[int, int] | None = None
) -> np.ndarray:
    """Least-squares depth over the mask's bounding rectangle by one DCT solve.

    Parameters
    ----------
    normals : (H, W, 3) float
        Unit normals in the camera frame, finite on the mask.
    mask : (H, W) bool
        Object pixels; exact when it covers its whole bounding box, approximate otherwise.
    origin : (int, int), optional
        (row, col) where ``z = 0``; by default the mean over the bounding box is 0.

    Returns
    -------
    depth : (H, W) float64
        Height in pixel units, NaN outside the mask.
    """
    mask = np.asarray(mask, dtype=bool)
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    divergence = _divergence(
        np.ascontiguousarray(normals[box], dtype=np.float64), np.ascontiguousarray(mask[box]), MIN_NZ
    )
    h, w = divergence.shape
    eigen = (2 - 2 * np.cos(np.pi * np.arange(h) / h))[:, None] + (2 - 2 * np.cos(np.pi * np.arange(w) / w))[
        None, :
    ]
    spectrum = fft.dctn(divergence, type=2, norm="ortho", workers=-1, overwrite_x=True)
    eigen[0, 0] = 1.0  # the free offset: its coefficient is set to 0 below
    spectrum /= eigen
    spectrum[0, 0] = 0.0
    height = fft.idctn(spectrum, type=2, norm="ortho", workers=-1, overwrite_x=True)
    height[~mask[box]] = np.nan
    depth = np.full(mask.shape, np.nan)
    depth[box] = height
    if origin is not None:
        depth -= depth[tuple(origin)]
    return depth


@numba.njit(cache=True)
def _divergence(normals, mask, min_nz):
    """``D^T s`` over a rectangle: the trapezoid step of each 4-neighbour pair (the mean of its two
    pixels' slopes, :func:`shadeform.integration._slopes.slopes`) pushes its far pixel up and its
    near pixel down. Fused, one pass; :func:`_divergence_reference` is the plain version."""
    h, w = mask.shape
    zx = np.zeros((h, w))
    zy = np.zeros((h, w))
    for r in range(h):
        for c in range(w):
            if mask[r, c]:
                nz = normals[r, c, 2]
                nz = max(1.0 if np.isnan(nz) else nz, min_nz)
                nx, ny = normals[r, c, 0], normals[r, c, 1]
                zx[r, c] = 0.0 if np.isnan(nx) else -nx / nz
                zy[r, c] = 0.0 if np.isnan(ny) else -ny / nz
    out = np.zeros((h, w))
    for r in range(h):
        for c in range(w):
            if c + 1 < w:
                step = 0.5 * (zx[r, c] + zx[r, c + 1])  # (r, c) -> (r, c + 1): dx = +1
                out[r, c + 1] += step
                out[r, c] -= step
            if r + 1 < h:
                step = -0.5 * (zy[r, c] + zy[r + 1, c])  # (r, c) -> (r + 1, c): dy = -1
                out[r + 1, c] += step
                out[r, c] -= step
    return out


def _divergence_reference(normals, mask):
    """Plain numpy ``D^T s`` (the reference for :func:`_divergence`)."""
    zx, zy = slopes(normals, mask)
    step_x = 0.5 * (zx[:, :-1] + zx[:, 1:])
    step_y = -0.5 * (zy[:-1, :] + zy[1:, :])
    divergence = np.zeros(zx.shape)
    divergence[:, 1:] += step_x
    divergence[:, :-1] -= step_x
    divergence[1:, :] += step_y
    divergence[:-1, :] -= step_y
    return divergence
