"""The photo solver's starting shapes: the silhouette's (:func:`silhouette_depth`), dented where
the user marked the surface concave (:func:`concave_start`), or a prior's normals integrated
(:mod:`shadeform.solvers.photo`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as spla

from shadeform.solvers.photo.energy import _index, _neighbour


def silhouette_depth(mask: np.ndarray) -> np.ndarray:
    """The shape of the silhouette alone: ``z = 2 sqrt(u)``, ``laplacian(u) = -1`` inside.

    ``u = 0`` on the pixels just outside the mask; where the mask meets the image frame there is
    no condition (the object goes on beyond the picture). Exact for a sphere (a disc of radius R
    gives ``z = sqrt(R^2 - r^2)``).

    Parameters
    ----------
    mask : (H, W) bool

    Returns
    -------
    (H, W) float64
        Height in pixels, 0 off the mask.
    """
    mask = np.asarray(mask, dtype=bool)
    u = _dirichlet_solve(mask, np.zeros(mask.shape), _FOUR, source=1.0)
    depth = np.zeros(mask.shape)
    depth[mask] = 2.0 * np.sqrt(np.maximum(np.nan_to_num(u), 0.0))  # no outline in view: flat
    return depth


def concave_start(depth: np.ndarray, concave_x: np.ndarray, concave_y: np.ndarray) -> np.ndarray:
    """A convex start made concave where the user marked it: what rises above the surface
    spanning each marked region's rim is mirrored below it.

    That surface is, for a region concave along x (only), the straight line along each row's run
    of region pixels joining the heights just outside its two ends; along y (only), the same per
    column; along both, the harmonic surface through the heights round the region. What already
    lies below it (the silhouette's shape at a vase's waist is concave along y already) is kept.
    The start keeps its heights on the rims, so the surface stays whole.

    Parameters
    ----------
    depth : (H, W) float
        The convex start (0 off the object).
    concave_x, concave_y : (H, W) bool
        Where the surface is concave along x / y (:func:`shadeform.regions.concave_masks`).

    Returns
    -------
    (H, W) float64
    """
    start = np.array(depth, dtype=np.float64)
    for region, steps in (
        (concave_x & concave_y, _FOUR),
        (concave_x & ~concave_y, _FOUR[:2]),
        (concave_y & ~concave_x, _FOUR[2:]),
    ):
        if not region.any():
            continue
        rim_surface = _dirichlet_solve(region, depth, steps)
        rim_surface = np.where(np.isnan(rim_surface), depth[region], rim_surface)  # no rim: as it was
        start[region] = rim_surface - np.abs(depth[region] - rim_surface)
    return start


# 4-neighbour steps (row, col): along x first, then along y
_FOUR = ((0, 1), (0, -1), (1, 0), (-1, 0))


def _dirichlet_solve(region, outside, steps, *, source=0.0):
    """``u`` on ``region``'s pixels (n,) with ``-laplacian(u) = source`` along ``steps`` and
    ``u = outside`` (H, W) on the neighbours off the region. A step off the image frame has no
    neighbour (the object goes on beyond the picture); a connected part with no neighbour off the
    region inside the frame has nothing to fix ``u`` and gets NaN."""
    index, rows, cols = _index(region)
    n = rows.size
    neighbours, fixed, anchors = np.zeros(n), np.zeros(n), np.zeros(n)
    pairs_i, pairs_j = [], []
    for d_row, d_col in steps:
        other, inside = _neighbour(index, rows + d_row, cols + d_col)
        neighbours += inside
        off = inside & (other < 0)
        fixed[off] += outside[rows[off] + d_row, cols[off] + d_col]
        anchors += off
        on_region = other >= 0
        pairs_i.append(np.flatnonzero(on_region))
        pairs_j.append(other[on_region])
    i, j = np.concatenate(pairs_i), np.concatenate(pairs_j)
    adjacency = sp.csr_matrix((np.ones(i.size), (i, j)), shape=(n, n))
    _, part = csgraph.connected_components(adjacency, directed=False)
    anchored = np.bincount(part, weights=anchors)[part] > 0
    u = np.full(n, np.nan)
    if anchored.any():
        keep = np.flatnonzero(anchored)
        laplacian = sp.diags(neighbours[keep]) - adjacency[keep][:, keep]
        u[keep] = spla.spsolve(laplacian.tocsc(), fixed[keep] + source)
    return u


def _prior_depth(normals, mask):
    """The start a prior gives: its normals integrated (least squares), slopes bounded so that the
    outline's grazing normals do not throw the surface."""
    from shadeform.integration import integrate

    bounded = normals.copy()
    # slopes of at most about 5 (set once, not tuned): steeper is the outline's wall, where one
    # pixel spans tens of pixels of depth
    bounded[..., 2] = np.maximum(bounded[..., 2], 0.2)
    bounded /= np.linalg.norm(bounded, axis=-1, keepdims=True)
    depth = integrate(bounded, mask, integrator="poisson")
    return np.where(mask, depth - np.nanmin(depth[mask]), 0.0)
