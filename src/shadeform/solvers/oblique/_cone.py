"""The shading cone of a lit pixel and its azimuth ``phi`` (private, shared by the steps).

With a distant light ``L`` and ``I = albedo max(0, N . L)``, the normals that explain a lit pixel
form a cone around ``L`` of half-angle ``acos(I / albedo)``. With a frame ``e1, e2``
perpendicular to ``L`` a normal on it is

    n = c L + s (cos phi e1 + sin phi e2),    c = I / albedo,  s = sqrt(1 - c^2),

so each lit pixel has one unknown, the azimuth ``phi``; ``phi = 0`` is the normal leaning most
toward the viewer. Cones are cut to the normals that face the camera (``n_z >= VISIBLE_NZ``).
"""

from __future__ import annotations

import numba
import numpy as np

#: Lit normals keep ``n_z >= VISIBLE_NZ`` (they face the camera). Set by hand on the synthetic
#: sphere and vase under the light (5, 5, 7) (``benchmarks/bench_oblique.py``).
VISIBLE_NZ = 0.02


def cone_frame(light: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors ``e1, e2`` perpendicular to ``light``; ``e1`` leans toward the viewer (+z)."""
    up = np.array([0.0, 0.0, 1.0]) - light[2] * light
    length = np.linalg.norm(up)
    e1 = up / length if length > 1e-9 else np.array([1.0, 0.0, 0.0])
    return e1, np.cross(light, e1)


def azimuth_limits(cos_theta: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Largest ``|phi|`` with ``n_z >= VISIBLE_NZ`` on each cone (pi: the whole cone is visible).

    On the cone ``n_z = c L_z + s sin(slant) cos phi``.
    """
    sin_slant = np.sqrt(max(1.0 - light[2] ** 2, 0.0))
    if sin_slant < 1e-9:
        return np.full(cos_theta.shape, np.pi)
    s = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        lowest = (VISIBLE_NZ - cos_theta * light[2]) / (s * sin_slant)
    return np.arccos(np.clip(np.nan_to_num(lowest, nan=-1.0), -1.0, 1.0))


def azimuth(normals: np.ndarray, light: np.ndarray) -> np.ndarray:
    """The azimuth ``phi`` of ``normals`` (..., 3) about ``light``."""
    e1, e2 = cone_frame(light)
    return np.arctan2(normals @ e2, normals @ e1)


def on_cone(cos_theta: np.ndarray, phi: np.ndarray, light: np.ndarray) -> np.ndarray:
    """The normals (..., 3) at azimuths ``phi`` on the cones of ``cos_theta`` (same shape)."""
    e1, e2 = cone_frame(light)
    s = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, 1.0))
    return cos_theta[..., None] * light + s[..., None] * (
        np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2
    )


@numba.njit(cache=True)
def cone_basis(cos_t, light, e1, e2, a0, a1, a2):
    """Fill ``a0, a1, a2`` (3,) so that the cone of ``cos_t`` is ``a0 + a1 cos phi + a2 sin phi``."""
    s = np.sqrt(max(1.0 - cos_t * cos_t, 0.0))
    for i in range(3):
        a0[i] = cos_t * light[i]
        a1[i] = s * e1[i]
        a2[i] = s * e2[i]
