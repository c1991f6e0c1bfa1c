"""Texture maps from a reconstruction, for texture artists: normal, height, ambient occlusion and
curvature maps, each an image in [0, 1] the size of the photo.

- **Normal map** ``RGB = (n + 1) / 2`` in the camera frame: OpenGL convention (green = +y, up in
  the image; Blender, Unity, glTF) or DirectX (green flipped: Unreal, 3ds Max).
- **Height** (displacement) map: the depth over the object, lowest 0, highest 1; its range in
  pixels is ``nanmax(depth) - nanmin(depth)`` (what a displacement strength of 1 stands for).
- **Ambient occlusion**, horizon-based, from the height field: along each of :data:`DIRECTIONS`
  azimuths the horizon's elevation ``h`` over the pixel (the steepest rise to the object's
  points within ``reach`` pixels); a height field lit by a uniform sky receives, from that
  azimuth's slice, the cosine-weighted visible fraction ``cos^2 h`` (``h > 0``; 1 when nothing
  rises above the tangent plane's horizontal). The map is the mean over azimuths: 1 unoccluded,
  toward 0 in deep cavities (Bavoil et al. 2008 for screen space; here exact on the height
  field up to the sampling along each azimuth).
- **Curvature**: the mean curvature's sum of principal curvatures from the normals,
  ``k = d n_x / dx + d n_y / dy`` (1/pixel; ``2 / R`` on a sphere of radius ``R``, positive
  convex), shown as ``0.5 + 0.5 tanh(k / s)``: 0.5 flat, brighter convex, darker cavities, with
  ``s`` the 98th percentile of ``|k|`` over the object (the map uses its range whatever the
  object's size; :func:`curvature` gives ``k`` itself).

Outside the object the maps hold what a flat, open surface would: normal ``(0, 0, 1)``,
height 0, occlusion 1, curvature 0.5.

References
----------
.. [1] L. Bavoil, M. Sainz, R. Dimitrov, "Image-space horizon-based ambient occlusion",
   SIGGRAPH 2008 talks.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange
from scipy import ndimage

from shadeform.errors import InputError

__all__ = ["DIRECTIONS", "MAPS", "ambient_occlusion", "curvature", "maps"]

#: Azimuths the occlusion is averaged over (every 22.5 degrees); not swept.
DIRECTIONS = 16
#: The percentile of ``|k|`` that the curvature map's ``tanh`` is scaled to; not swept.
CURVATURE_PERCENTILE = 98.0
#: The maps :func:`maps` returns, in order.
MAPS = ("normal_opengl", "normal_directx", "height", "ambient_occlusion", "curvature")


def maps(reconstruction, *, reach: float | None = None) -> dict[str, np.ndarray]:
    """Every texture map of a reconstruction.

    Parameters
    ----------
    reconstruction : Reconstruction
        From :func:`shadeform.reconstruct` (or any object with ``normals`` (H, W, 3), ``depth``
        (H, W) and ``mask`` (H, W)).
    reach : float, optional
        How far (pixels) the occlusion looks for occluders; default the radius of the largest
        disc inside the object (:func:`default_reach`), so it follows the object's size.

    Returns
    -------
    dict of str to ndarray
        ``normal_opengl``, ``normal_directx`` (H, W, 3); ``height``, ``ambient_occlusion``,
        ``curvature`` (H, W); all float64 in [0, 1] (:data:`MAPS`).
    """
    normals, depth, mask = _check(reconstruction.normals, reconstruction.depth, reconstruction.mask)
    opengl = np.where(mask[..., None], (normals + 1.0) / 2.0, [0.5, 0.5, 1.0])
    directx = opengl.copy()
    directx[..., 1] = 1.0 - directx[..., 1]
    low, high = np.nanmin(depth[mask]), np.nanmax(depth[mask])
    height = np.where(mask, (depth - low) / (high - low) if high > low else 0.0, 0.0)
    k = curvature(normals, mask)
    scale = np.percentile(np.abs(k[mask]), CURVATURE_PERCENTILE)
    shown = 0.5 + 0.5 * np.tanh(k / scale) if scale > 0 else np.full(k.shape, 0.5)
    return {
        "normal_opengl": opengl,
        "normal_directx": directx,
        "height": height,
        "ambient_occlusion": ambient_occlusion(depth, mask, reach=reach),
        "curvature": np.where(mask, shown, 0.5),
    }


def default_reach(mask: np.ndarray) -> float:
    """The radius (pixels) of the largest disc inside ``mask``: the occlusion's default reach."""
    return max(1.0, float(ndimage.distance_transform_edt(np.pad(mask, 1)).max()))


def curvature(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The sum of the principal curvatures ``k = d n_x / dx + d n_y / dy`` (H, W), 1/pixel,
    positive where the surface is convex toward the viewer; 0 outside ``mask`` and where a
    neighbour needed for the central differences is off the object."""
    normals, mask = np.asarray(normals, dtype=np.float64), np.asarray(mask, dtype=bool)
    # x = column, y = -row (docs/conventions.md)
    k = np.gradient(normals[..., 0], axis=1) - np.gradient(normals[..., 1], axis=0)
    return np.where(mask & np.isfinite(k), k, 0.0)


def ambient_occlusion(
    depth: np.ndarray, mask: np.ndarray, *, reach: float | None = None, directions: int = DIRECTIONS
) -> np.ndarray:
    """Horizon-based ambient occlusion of a height field (module docstring): (H, W) in [0, 1],
    1 outside ``mask``.

    Along each azimuth the horizon is sought at distances growing by ``sqrt(2)`` from one pixel
    to ``reach`` (about 2 log2(reach) samples, depth read bilinearly from object pixels): fine
    near the pixel, where occluders matter most, and the cost grows with the log of the reach.
    """
    mask = np.asarray(mask, dtype=bool)
    depth = np.where(mask, np.asarray(depth, dtype=np.float64), np.nan)
    reach = default_reach(mask) if reach is None else float(reach)
    if not (np.isfinite(reach) and reach >= 1):
        raise InputError(f"the occlusion's reach must be at least 1 pixel, got {reach!r}")
    if int(directions) != directions or directions < 1:
        raise InputError(f"directions must be a whole number >= 1, got {directions!r}")
    out = np.ones(depth.shape)
    _occlusion_kernel(depth, mask, _distances(reach), _azimuths(int(directions)), out)
    return out


def _distances(reach: float) -> np.ndarray:
    steps = [1.0]
    while steps[-1] * np.sqrt(2.0) <= reach:
        steps.append(steps[-1] * np.sqrt(2.0))
    return np.array(steps)


def _azimuths(count: int) -> np.ndarray:
    angles = 2 * np.pi * np.arange(count) / count
    return np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (column, row) steps


def ambient_occlusion_reference(depth, mask, *, reach, directions=DIRECTIONS):
    """:func:`ambient_occlusion` one pixel, azimuth and sample at a time in plain Python (slow,
    obviously correct: the compiled kernel is tested against it)."""
    depth = np.where(mask, np.asarray(depth, dtype=np.float64), np.nan)
    out = np.ones(depth.shape)
    for r, c in zip(*np.nonzero(mask)):
        total = 0.0
        for dc, dr in _azimuths(directions):
            rise = 0.0  # tan of the horizon's elevation, never below the horizontal
            for t in _distances(reach):
                z = _bilinear_reference(depth, r + t * dr, c + t * dc)
                if np.isfinite(z):
                    rise = max(rise, (z - depth[r, c]) / t)
            total += 1.0 / (1.0 + rise * rise)  # cos^2 of the elevation
        out[r, c] = total / directions
    return out


def _bilinear_reference(depth, row, col):
    """Bilinear depth at ``(row, col)``, NaN if any of the four pixels is off the object."""
    r0, c0 = int(np.floor(row)), int(np.floor(col))
    if r0 < 0 or c0 < 0 or r0 + 1 >= depth.shape[0] or c0 + 1 >= depth.shape[1]:
        return np.nan
    fr, fc = row - r0, col - c0
    patch = depth[r0 : r0 + 2, c0 : c0 + 2]
    return float(np.array([1 - fr, fr]) @ patch @ np.array([1 - fc, fc]))


@numba.njit(cache=True, parallel=True)
def _occlusion_kernel(depth, mask, distances, azimuths, out):
    rows, cols = depth.shape
    for r in prange(rows):
        for c in range(cols):
            if not mask[r, c]:
                continue
            here = depth[r, c]
            total = 0.0
            for a in range(azimuths.shape[0]):
                dc, dr = azimuths[a, 0], azimuths[a, 1]
                rise = 0.0
                for t in distances:
                    row, col = r + t * dr, c + t * dc
                    r0, c0 = int(np.floor(row)), int(np.floor(col))
                    if r0 < 0 or c0 < 0 or r0 + 1 >= rows or c0 + 1 >= cols:
                        break  # the rest of this azimuth is off the image too
                    fr, fc = row - r0, col - c0
                    z = (1 - fr) * ((1 - fc) * depth[r0, c0] + fc * depth[r0, c0 + 1]) + fr * (
                        (1 - fc) * depth[r0 + 1, c0] + fc * depth[r0 + 1, c0 + 1]
                    )
                    if z == z:  # all four on the object (NaN otherwise)
                        rise = max(rise, (z - here) / t)
                total += 1.0 / (1.0 + rise * rise)
            out[r, c] = total / azimuths.shape[0]


def _check(normals, depth, mask):
    normals = np.asarray(normals, dtype=np.float64)
    depth = np.asarray(depth, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    if normals.shape != depth.shape + (3,) or mask.shape != depth.shape or depth.ndim != 2:
        raise InputError(
            f"normals (H, W, 3), depth and mask (H, W) must match, got {normals.shape}, {depth.shape}, "
            f"{mask.shape}"
        )
    mask = mask & np.isfinite(depth) & np.isfinite(normals).all(axis=2)
    if not mask.any():
        raise InputError("the reconstruction has no object pixels to make maps of")
    return normals, depth, mask
