"""Checks of a simplified top: its triangles cover the outline once (no fold, no overlap), its
open (boundary) edges, and the keys that compare edges and grid positions across meshes."""

from __future__ import annotations

import numpy as np

# relative tolerance of the area checks after simplification: float64 sums of up to ~1e7 areas
_AREA_TOLERANCE = 1e-9


def _projected_areas(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed area of each triangle seen from +z (positive: counter-clockwise)."""
    a, b, c = (points[faces[:, k], :2] for k in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))


def _checked_top(points, faces, outline_area, pixel_mm):
    """The simplified top, checked to be a fold-free height field over the outline it had.

    Returns the vertices, the faces and the boundary edges, or None when a check fails: every
    triangle turns counter-clockwise seen from +z, their areas sum to the outline's (so they
    cover it once: no fold, no overlap) and no directed edge repeats. With its boundary kept
    (checked by the caller), the top is then an embedded disk (with holes) over the outline:
    walls and a flat base below it close a solid that cannot intersect itself.
    """
    if not _covers_once(_projected_areas(points, faces), outline_area):
        return None
    edges = _open_edges(faces, len(points))
    if edges is None:
        return None
    return points, faces, edges


def _covers_once(areas: np.ndarray, outline_area: float) -> bool:
    """Whether triangles of these signed areas (seen from +z) can only tile the outline: all turn
    counter-clockwise and together they have its area."""
    tiny = _AREA_TOLERANCE * outline_area
    return bool(
        areas.min() > tiny * 1e-3 and abs(areas.sum() - outline_area) <= tiny * max(1, len(areas)) ** 0.5
    )


def _sorted_rows(pairs: np.ndarray) -> np.ndarray:
    """``(E, 2)`` integer pairs in lexicographic order (to compare two sets of edges)."""
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _edge_key(edges: np.ndarray, n: int) -> np.ndarray:
    return edges[:, 0].astype(np.int64) * n + edges[:, 1]


def _open_edges(faces: np.ndarray, n: int) -> np.ndarray | None:
    """Directed edges of ``faces`` whose reverse is not an edge (the boundary), ``(E, 2)``; None if
    a directed edge appears twice (two triangles wound against each other across it)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    keys = _edge_key(edges, n)
    ordered = np.sort(keys)
    if (ordered[1:] == ordered[:-1]).any():
        return None
    reverse = _edge_key(edges[:, ::-1], n)
    found = np.searchsorted(ordered, reverse)
    found = np.minimum(found, len(ordered) - 1)
    return edges[ordered[found] != reverse]


def _grid_key(points: np.ndarray, pixel_mm: float) -> np.ndarray:
    """One integer per pixel position ``(x, y) / pixel_mm`` (rounded: exact for grid points)."""
    x = np.rint(points[:, 0] / pixel_mm).astype(np.int64)
    y = np.rint(points[:, 1] / pixel_mm).astype(np.int64)
    return x * (np.int64(1) << 32) + y
