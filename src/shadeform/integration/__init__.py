"""Depth from normals: ``integrate(normals, mask, method=...)``.

Methods
-------
paths
    The 2002 report's method: average of many integration paths from a reference pixel
    (:mod:`shadeform.integration.paths`).
poisson
    Masked least squares, solved by multigrid-preconditioned conjugate gradients
    (:mod:`shadeform.integration.poisson`).
fourier
    The discrete Poisson equation on the mask's bounding rectangle, one DCT solve
    (Frankot & Chellappa 1988; :mod:`shadeform.integration.fourier`): the fastest, exact on full
    rectangles, approximate near the silhouette of other masks.
bilateral
    Discontinuity-preserving integration in the spirit of BiNI (Cao et al., ECCV 2022):
    one-sided differences reweighted by how well each side agrees; orthographic or perspective
    (:mod:`shadeform.integration.bilateral`).
"""

from __future__ import annotations

import numpy as np

from shadeform.errors import InputError

METHODS = ("paths", "poisson", "fourier", "bilateral")


def integrate(normals: np.ndarray, mask: np.ndarray, *, method: str = "paths",
              origin: tuple[int, int] | None = None, K: np.ndarray | None = None) -> np.ndarray:
    """Depth from a normal field over a mask.

    Parameters
    ----------
    normals : (H, W, 3) float
        Unit normals in the camera frame (``docs/conventions.md``), finite on the mask.
    mask : (H, W) bool
    method : {"paths", "poisson", "fourier", "bilateral"}
    origin : (int, int), optional
        (row, col) where ``z = 0`` (orthographic only). For "paths" only the mask's part holding
        the origin is integrated. Default: the most frontal normal's pixel.
    K : (3, 3) float, optional
        Pinhole intrinsics (OpenCV layout) for a perspective camera; "bilateral" only.

    Returns
    -------
    depth : (H, W) float64
        NaN outside the mask. Without ``K``: height in pixel units (larger = nearer the viewer)
        up to an offset. With ``K``: depth along the optical axis up to one scale factor.
    """
    normals = np.asarray(normals, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    if normals.ndim != 3 or normals.shape[2] != 3 or normals.shape[:2] != mask.shape:
        raise InputError(f"normals must be (H, W, 3) and mask (H, W), got {normals.shape} and {mask.shape}")
    if not mask.any():
        raise InputError("mask is empty; it must mark the object's pixels")
    if not np.isfinite(normals[mask]).all():
        raise InputError("normals have NaN inside the mask; fill them or leave those pixels out of the mask")
    if method not in METHODS:
        raise InputError(f"unknown integration method {method!r}; choose one of: {', '.join(METHODS)}")
    if K is not None:
        if method != "bilateral":
            raise InputError(f"a perspective camera (K) needs method='bilateral', not {method!r}")
        from shadeform.integration.bilateral import integrate_bilateral

        return integrate_bilateral(normals, mask, K=K)
    if origin is None:
        origin = np.unravel_index(np.argmax(np.where(mask, normals[..., 2], -np.inf)), mask.shape)
    origin = (int(origin[0]), int(origin[1]))
    if not (0 <= origin[0] < mask.shape[0] and 0 <= origin[1] < mask.shape[1]) or not mask[origin]:
        raise InputError(f"origin (row {origin[0]}, col {origin[1]}) is not on the mask")
    if method == "paths":
        from shadeform.integration.paths import integrate_paths

        return integrate_paths(normals, mask, origin=origin)
    if method == "poisson":
        from shadeform.integration.poisson import integrate_poisson

        return integrate_poisson(normals, mask, origin=origin)
    if method == "fourier":
        from shadeform.integration.fourier import integrate_fourier

        depth = integrate_fourier(normals, mask)
        return depth - depth[origin]
    from shadeform.integration.bilateral import integrate_bilateral

    return integrate_bilateral(normals, mask, origin=origin)
