"""The solid on the pixel grid: the height field sampled every ``step`` pixels, the top's cells
(no pinched vertex), the walls below its boundary and the base; with a budget, the top simplified
and the base the outline's loops triangulated."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shadeform.mesh import cell_triangles
from shadeform.solid.checks import _checked_top, _covers_once, _grid_key, _projected_areas, _sorted_rows

# (row, column) offsets of a cell's corners: top-left, top-right, bottom-left, bottom-right
_CORNERS = ((0, 0), (0, 1), (1, 0), (1, 1))


@dataclass(frozen=True)
class _HeightSamples:
    """The height field sampled every ``step`` pixels: grid rows/cols in pixels, heights (mm),
    the cells kept (four corners on the domain, no pinch) and the vertex number of each point."""

    rows: np.ndarray
    cols: np.ndarray
    heights: np.ndarray
    cells: np.ndarray
    vertex_id: np.ndarray
    used: np.ndarray


def _sample(heights: np.ndarray, domain: np.ndarray, step: int) -> _HeightSamples:
    """Grid points every ``step`` pixels (the last row and column always in), each the height at
    its pixel. (Means over the pixels around each point were tried: on the 12 Mpx vase of
    ``benchmarks/bench_relief.py`` and on DiLiGenT's cat and buddha and MIT's deer they left the
    simplified top as far or farther from the full-resolution relief, twice as far on the vase,
    whose means are biased along the outline.)"""
    h, w = domain.shape
    rows = _grid_lines(h, step)
    cols = _grid_lines(w, step)
    grid = np.ix_(rows, cols)
    values, ok = heights[grid], domain[grid]
    cells = ok[:-1, :-1] & ok[:-1, 1:] & ok[1:, :-1] & ok[1:, 1:]
    _drop_pinches(cells)
    used = np.zeros(ok.shape, dtype=bool)
    n_r, n_c = cells.shape
    for dr in (0, 1):
        for dc in (0, 1):
            used[dr : dr + n_r, dc : dc + n_c] |= cells
    vertex_id = np.cumsum(used.ravel()).reshape(used.shape) - 1
    return _HeightSamples(rows, cols, values, cells, vertex_id, used)


def _grid_lines(n: int, step: int) -> np.ndarray:
    lines = np.arange(0, n, step)
    return lines if lines[-1] == n - 1 else np.append(lines, n - 1)


def _drop_pinches(cells: np.ndarray) -> None:
    """Drop cells, in place, until no two touch at a corner only (2 x 2 blocks of cells with
    exactly a diagonal pair): such a vertex would be shared by two walls, a non-manifold edge."""
    while True:
        a, b = cells[:-1, :-1], cells[:-1, 1:]
        c, d = cells[1:, :-1], cells[1:, 1:]
        diagonal = a & d & ~b & ~c
        anti = b & c & ~a & ~d
        if not (diagonal.any() or anti.any()):
            return
        d[diagonal] = False
        c[anti] = False


def _boundary_edges(grid: _HeightSamples) -> np.ndarray:
    """The top's boundary edges, ``(E, 2)`` vertex numbers, directed with the top on their left
    (the order they have in :func:`shadeform.mesh.cell_triangles`' triangles)."""
    cells = np.pad(grid.cells, 1)
    inner = np.s_[1:-1, 1:-1]
    vid = grid.vertex_id
    n_r, n_c = grid.cells.shape
    tl, tr = vid[:n_r, :n_c], vid[:n_r, 1:]
    bl, br = vid[1:, :n_c], vid[1:, 1:]
    here = cells[inner]
    edges = []
    for gone, start, end in (
        (~cells[:-2, 1:-1], tr, tl),  # no cell above: the top side, right to left
        (~cells[2:, 1:-1], bl, br),  # below: the bottom side, left to right
        (~cells[1:-1, :-2], tl, bl),  # left: down the left side
        (~cells[1:-1, 2:], br, tr),  # right: up the right side
    ):
        pick = here & gone
        edges.append(np.column_stack([start[pick], end[pick]]))
    return np.concatenate(edges)


def _walls(top_edges: np.ndarray, below: np.ndarray) -> np.ndarray:
    """Two triangles per boundary edge ``a -> b`` of the top, down to the base's copies
    ``below[a]``, ``below[b]``, facing out (to the right of ``a -> b``)."""
    a, b = top_edges[:, 0], top_edges[:, 1]
    a_, b_ = below[a], below[b]
    return np.concatenate([np.column_stack([a, a_, b_]), np.column_stack([a, b_, b])])


def _grid_solid(grid: _HeightSamples, width_mm, base_mm, max_triangles, print_tools):
    """The solid on ``grid``: vertices (mm), faces, the pixel size (mm), the grid origin
    ``(col, row)`` and whether it was simplified (to ``max_triangles``); None if it does not fit
    or the simplified top fails the checks of :func:`_checked_top`.

    Unsimplified, the base is the top's cells at ``z = 0``. With a budget, the base is the
    outline's loops triangulated (manifold3d's ear clipping: about one triangle per boundary
    vertex) and the top is simplified to what the budget leaves after the base and the walls.
    """
    r_idx, c_idx = np.nonzero(grid.used)
    rows, cols = grid.rows[r_idx], grid.cols[c_idx]
    col0, row1 = cols.min(), rows.max()
    extent = max(cols.max() - col0, row1 - rows.min())
    if extent == 0:
        return None
    pixel_mm = float(width_mm / extent)
    n = len(rows)
    top_v = np.column_stack(
        [(cols - col0) * pixel_mm, (row1 - rows) * pixel_mm, base_mm + grid.heights[grid.used]]
    )
    n_r, n_c = grid.cells.shape
    corner_ids = (grid.vertex_id[dr : dr + n_r, dc : dc + n_c][grid.cells] for dr, dc in _CORNERS)
    top_f = cell_triangles(*corner_ids)
    boundary = _boundary_edges(grid)
    if max_triangles is None or 2 * len(top_f) + 2 * len(boundary) <= max_triangles:
        base_v = top_v.copy()
        base_v[:, 2] = 0.0
        vertices = np.concatenate([top_v, base_v])
        faces = np.concatenate([top_f, top_f[:, ::-1] + n, _walls(boundary, np.arange(n) + n)])
        return _drop_unused(vertices, faces) + (pixel_mm, (col0, row1), False)
    simplify, triangulate = print_tools
    loops = _loops(boundary, n)
    ring = np.concatenate(loops)
    # the base: the loops' points at z = 0, triangulated, facing down
    base_f = triangulate([top_v[loop, :2] for loop in loops])[:, ::-1].astype(np.int64)
    target = max_triangles - len(base_f) - 2 * len(boundary)
    if target < 2:
        return None
    outline_area = float(_projected_areas(top_v, top_f).sum())
    base_v = np.column_stack([top_v[ring, :2], np.zeros(len(ring))])
    if not _covers_once(-_projected_areas(base_v, base_f), outline_area):
        return None  # the triangulator's result folds or overlaps
    if target >= len(top_f):  # the triangulated base alone makes it fit
        points, triangles = top_v, top_f
    else:
        points, triangles = simplify(top_v, top_f, target_count=target, preserve_border=True)
    checked = _checked_top(points, np.asarray(triangles, dtype=np.int64), outline_area, pixel_mm)
    if checked is None:
        return None
    top_points, top_faces, top_edges = checked
    # each kept boundary vertex's copy on the base: the same grid position
    key = _grid_key(base_v, pixel_mm)
    order = np.argsort(key)
    kept = np.unique(top_edges)
    found = order[
        np.minimum(np.searchsorted(key[order], _grid_key(top_points[kept], pixel_mm)), len(order) - 1)
    ]
    if (base_v[found, :2] != top_points[kept, :2]).any() or len(kept) != len(ring):
        return None
    # and the same boundary edges (preserve_border keeps them; checked, not assumed)
    before = _sorted_rows(_grid_key(top_v, pixel_mm)[boundary])
    after = _sorted_rows(_grid_key(top_points, pixel_mm)[top_edges])
    if not np.array_equal(before, after):
        return None
    below = np.full(len(top_points), -1, dtype=np.int64)
    below[kept] = found + len(top_points)
    vertices = np.concatenate([top_points, base_v])
    faces = np.concatenate([top_faces, base_f + len(top_points), _walls(top_edges, below)])
    if len(faces) > max_triangles:
        return None
    return _drop_unused(vertices, faces) + (pixel_mm, (col0, row1), True)


def _loops(edges: np.ndarray, n: int) -> list[np.ndarray]:
    """The boundary's closed loops, each an array of vertex numbers in the edges' direction (every
    vertex has one edge out: the pinches were dropped)."""
    following = np.full(n, -1, dtype=np.int64)
    following[edges[:, 0]] = edges[:, 1]
    seen = np.zeros(n, dtype=bool)
    loops = []
    for start in edges[:, 0]:
        if seen[start]:
            continue
        loop = []
        vertex = start
        while not seen[vertex]:
            seen[vertex] = True
            loop.append(vertex)
            vertex = following[vertex]
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def _drop_unused(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices some face uses, renumbered in their order."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    if used.all():
        return vertices, faces
    number = np.cumsum(used) - 1
    return vertices[used], number[faces]
