"""Step 2 of the oblique solver: normals in the attached shadow.

A shadowed pixel (``I / albedo <= dark``) says only ``N . L <= 0``: no slope can be read from its
brightness. Its normal continues those of the lit pixels with the least change of curvature, a
thin-plate (second-difference) fit of ``n_x`` and ``n_y`` with the lit normals fixed, after
Ikeuchi and Horn's smoothness of the normal field [1]_; each is then moved to the nearest normal
with ``N . L <= 0`` where the fit broke the constraint. The shadow is a constraint, not a dark
intensity, so the surface continues smoothly into it instead of falling off a cliff.

All filled normals keep ``n_z >= SHADOW_NZ``: a wrong lit normal at the shadow's edge then cannot
extrapolate into a wall of grazing normals.

References
----------
.. [1] K. Ikeuchi and B. K. P. Horn, "Numerical shape from shading and occluding boundaries",
   Artificial Intelligence 17, 141-184, 1981.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: Filled shadow normals keep ``n_z >= SHADOW_NZ``. Set on the synthetic vase under the lights
#: (5, 5, 7) and slant 30 degrees (``benchmarks/bench_oblique.py``), against the worst shadow
#: error of the sphere's crescent under slant 60 (``test_shadow_is_a_constraint_not_a_cliff``).
SHADOW_NZ = 0.15


def _second_differences(mask: np.ndarray) -> sp.csr_matrix:
    """Thin-plate second differences over the mask (xx, yy and sqrt(2) xy, where the stencil
    fits), as a sparse matrix on the mask's pixels in row-major order."""
    index = np.full(mask.shape, -1, dtype=np.int64)
    n = int(mask.sum())
    index[mask] = np.arange(n)
    blocks = []
    for stencil in (
        ((0, 0, 1.0), (0, 1, -2.0), (0, 2, 1.0)),
        ((0, 0, 1.0), (1, 0, -2.0), (2, 0, 1.0)),
        ((0, 0, np.sqrt(2)), (0, 1, -np.sqrt(2)), (1, 0, -np.sqrt(2)), (1, 1, np.sqrt(2))),
    ):
        span_r = max(dr for dr, _, _ in stencil)
        span_c = max(dc for _, dc, _ in stencil)
        height, width = mask.shape[0] - span_r, mask.shape[1] - span_c
        fits = np.ones((height, width), dtype=bool)
        for dr, dc, _ in stencil:
            fits &= mask[dr : dr + height, dc : dc + width]
        rows, cols = np.nonzero(fits)
        eq = np.arange(len(rows))
        data = np.concatenate([np.full(len(rows), v) for _, _, v in stencil])
        where = np.concatenate([index[rows + dr, cols + dc] for dr, dc, _ in stencil])
        blocks.append(sp.csr_matrix((data, (np.tile(eq, len(stencil)), where)), shape=(len(rows), n)))
    return sp.vstack(blocks).tocsr()


def _visible(normals: np.ndarray, min_nz: float) -> np.ndarray:
    """Unit normals from their ``(n_x, n_y)``, with ``|(n_x, n_y)|`` capped so ``n_z >= min_nz``."""
    xy = normals[:, :2]
    length = np.linalg.norm(xy, axis=1)
    cap = np.sqrt(1.0 - min_nz**2)
    xy = xy * np.minimum(1.0, cap / np.maximum(length, 1e-12))[:, None]
    return np.column_stack([xy, np.sqrt(np.maximum(1.0 - (xy * xy).sum(axis=1), 0.0))])


class ShadowFill:
    """The fill of :func:`fill_shadow_normals` for one mask and shadow, factorised once.

    The solver refills the shadow after every descent sweep; the thin-plate system depends only on
    which pixels are free, so its LU factorisation is kept. Call it with the normals (H, W, 3)
    (finite on the lit object pixels) and the light (3,); it returns a new array.
    """

    def __init__(self, mask: np.ndarray, shadow: np.ndarray):
        self.mask = mask
        self.free = shadow[mask]
        self.solve = None
        if self.free.any():
            D = _second_differences(mask)
            self.free_part = D[:, self.free]
            self.known_part = D[:, ~self.free]
            system = (self.free_part.T @ self.free_part).tocsc()
            # a shadowed pixel no stencil reaches would make the system singular: a tiny ridge
            system = system + sp.identity(system.shape[0], format="csc") * 1e-9
            self.solve = spla.splu(system).solve

    def __call__(self, normals: np.ndarray, light: np.ndarray) -> np.ndarray:
        if self.solve is None:
            return normals
        values = normals[self.mask]
        free = self.free
        filled = np.empty((int(free.sum()), 3))
        for axis in (0, 1):
            rhs = -(self.free_part.T @ (self.known_part @ values[~free, axis]))
            filled[:, axis] = self.solve(rhs)
        filled = _visible(filled, SHADOW_NZ)
        # the constraint N . L <= 0: a filled normal that faces the light goes to the nearest
        # one on the terminator
        facing = filled @ light
        bad = facing > 0
        if bad.any():
            moved = filled[bad] - facing[bad, None] * light
            length = np.linalg.norm(moved, axis=1, keepdims=True)
            moved = np.where(length > 1e-12, moved / np.maximum(length, 1e-12), filled[bad])
            visible = _visible(moved, SHADOW_NZ)
            onto = visible - np.maximum(visible @ light, 0.0)[:, None] * light
            # a visible normal along the light (a light within SHADOW_NZ's cone of the viewer) has
            # no terminator to go to: it stays the visible one
            length = np.linalg.norm(onto, axis=1, keepdims=True)
            filled[bad] = np.where(length > 1e-12, onto / np.maximum(length, 1e-12), visible)
        out = normals.copy()
        values[free] = filled
        out[self.mask] = values
        return out


def fill_shadow_normals(normals, mask, shadow, *, light):
    """Continue a normal field into the shadow with the least change of curvature.

    The ``(n_x, n_y)`` of the shadowed pixels minimise the thin-plate energy (squared second
    differences ``xx``, ``yy``, ``xy`` over the mask) with the other pixels' normals fixed; a
    linear normal field (a sphere, a cylinder) continues exactly. Each filled normal is then made
    visible (``n_z >= SHADOW_NZ``) and, where it faces the light, moved to the nearest normal with
    ``N . L = 0``, so the shadow stays a shadow.

    Parameters
    ----------
    normals : (H, W, 3) float
        Finite on ``mask & ~shadow``.
    mask, shadow : (H, W) bool
    light : (3,) float
        Unit vector toward the light.

    Returns
    -------
    (H, W, 3) float64
        ``normals`` with the shadowed pixels replaced, NaN outside ``mask``.

    References
    ----------
    .. [1] K. Ikeuchi and B. K. P. Horn, "Numerical shape from shading and occluding
       boundaries", Artificial Intelligence 17, 1981.
    """
    mask = np.asarray(mask, dtype=bool)
    shadow = np.asarray(shadow, dtype=bool) & mask
    light = np.asarray(light, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    return ShadowFill(mask, shadow)(np.where(mask[..., None], normals, np.nan), light)
