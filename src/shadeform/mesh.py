"""Triangle meshes from reconstructions: grid vertices, per-vertex normals, no silhouette bridges.

Layout and winding follow ``docs/conventions.md`` ("Meshes"): a vertex at every ``step``-th pixel
``(r, c)`` of the object at ``(x, y, z) = (c, -r, depth[r, c])``, triangles counter-clockwise
seen from +z, per-vertex normals copied from the reconstruction, ``u = (c + 0.5) / W``,
``v = 1 - (r + 0.5) / H``.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from shadeform.errors import InputError
from shadeform.reconstruction import Reconstruction

__all__ = ["UNITS", "Mesh", "cell_triangles", "outward", "solid_measures", "to_mesh", "vertex_normals"]

#: The units a mesh's coordinates may be in (the names 3MF uses where it has one).
UNITS = ("pixel", "millimeter")

# faces per chunk where a whole-mesh temporary would be large (vertex normals)
_CHUNK_FACES = 1 << 20


@dataclass(frozen=True, eq=False)
class Mesh:
    """An indexed triangle mesh with per-vertex normals.

    Attributes
    ----------
    vertices : (V, 3) float64
        Positions, finite.
    faces : (F, 3) int64
        Vertex indices in ``[0, V)``, counter-clockwise seen from the front.
    normals : (V, 3) float64
        Unit per-vertex normals.
    uv : (V, 2) float64 or None
        Texture coordinates, ``(0, 0)`` at the bottom left of the image.
    unit : str
        What one coordinate unit is, one of :data:`UNITS`: ``"pixel"`` for meshes of
        reconstructions (``docs/conventions.md``), ``"millimeter"`` for print-ready solids
        (:func:`shadeform.relief`). Exporters write it where the format has a place for it.

    Raises
    ------
    InputError
        On construction, if a shape, an index or a value is invalid.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uv: np.ndarray | None = None
    unit: str = "pixel"

    def __post_init__(self) -> None:
        vertices = np.asarray(self.vertices, dtype=np.float64)
        faces = np.asarray(self.faces)
        normals = np.asarray(self.normals, dtype=np.float64)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise InputError(f"mesh vertices must have shape (V, 3), got {vertices.shape}")
        n_vertices = vertices.shape[0]
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise InputError(f"mesh faces must have shape (F, 3), got {faces.shape}")
        if faces.size and not np.issubdtype(faces.dtype, np.integer):
            raise InputError(f"mesh faces must be integer vertex indices, got dtype {faces.dtype}")
        faces = faces.astype(np.int64, copy=False)
        if faces.size and (faces.min() < 0 or faces.max() >= n_vertices):
            raise InputError(
                f"mesh faces index vertices {faces.min()}..{faces.max()}, "
                f"but there are {n_vertices} vertices; indices must lie in [0, {n_vertices})"
            )
        if normals.shape != (n_vertices, 3):
            raise InputError(
                f"mesh normals must have shape ({n_vertices}, 3) like the vertices, got {normals.shape}"
            )
        if not np.isfinite(vertices).all():
            raise InputError("mesh vertices contain NaN or inf; drop those vertices first")
        if not np.isfinite(normals).all():
            raise InputError("mesh normals contain NaN or inf; give a unit normal per vertex")
        uv = self.uv
        if uv is not None:
            uv = np.asarray(uv, dtype=np.float64)
            if uv.shape != (n_vertices, 2):
                raise InputError(
                    f"mesh uv must have shape ({n_vertices}, 2) like the vertices, got {uv.shape}"
                )
            if not np.isfinite(uv).all():
                raise InputError("mesh uv contain NaN or inf; give finite texture coordinates")
        if self.unit not in UNITS:
            raise InputError(f"mesh unit must be one of {', '.join(UNITS)}, got {self.unit!r}")
        # frozen: set the converted arrays through object.__setattr__
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "faces", faces)
        object.__setattr__(self, "normals", normals)
        object.__setattr__(self, "uv", uv)

    @property
    def n_vertices(self) -> int:
        """Number of vertices ``V``."""
        return self.vertices.shape[0]

    @property
    def n_faces(self) -> int:
        """Number of triangles ``F``."""
        return self.faces.shape[0]


def _check_step(step: object, shape: tuple[int, int]) -> int:
    if isinstance(step, bool) or not isinstance(step, numbers.Integral):
        raise InputError(f"step must be a whole number of pixels (1, 2, ...), got {step!r}")
    step = int(step)
    limit = min(shape)
    if not 1 <= step < limit:
        raise InputError(f"step must be at least 1 and below {limit} (the smaller image side), got {step}")
    return step


def _check_reconstruction(reconstruction: Reconstruction) -> tuple[np.ndarray, ...]:
    mask = np.asarray(reconstruction.mask, dtype=bool)
    depth = np.asarray(reconstruction.depth, dtype=np.float64)
    normals = np.asarray(reconstruction.normals)  # float32 or float64: only the grid's are converted
    if not np.issubdtype(normals.dtype, np.floating):
        normals = normals.astype(np.float64)
    if mask.ndim != 2:
        raise InputError(f"reconstruction mask must have shape (H, W), got {mask.shape}")
    if depth.shape != mask.shape:
        raise InputError(
            f"reconstruction depth has shape {depth.shape} but the mask {mask.shape}; they must match"
        )
    if normals.shape != mask.shape + (3,):
        raise InputError(f"reconstruction normals have shape {normals.shape}, expected {mask.shape + (3,)}")
    return mask, depth, normals


def _outside_count(background: np.ndarray, top: np.ndarray, left: np.ndarray, size: int) -> np.ndarray:
    """Background pixels in each ``size`` x ``size`` block at ``(top, left)`` (integral image).

    Parameters
    ----------
    background : (H, W) bool
    top, left : (n,) or (R, C) int
        Top-left pixel of each block; the block must lie inside the image.
    size : int

    Returns
    -------
    counts : same shape as ``top``, int32 (int64 past 2**31 pixels)
    """
    # int32 while every count fits: half the memory of int64 for this image-sized table
    dtype = np.int32 if background.size < 2**31 else np.int64
    integral = np.zeros((background.shape[0] + 1, background.shape[1] + 1), dtype=dtype)
    np.cumsum(background, axis=0, dtype=dtype, out=integral[1:, 1:])
    np.cumsum(integral[1:, 1:], axis=1, out=integral[1:, 1:])
    bottom, right = top + size, left + size
    return (integral[bottom, right] - integral[top, right]) - (integral[bottom, left] - integral[top, left])


# The four single triangles of a cell with one corner missing, as (corner, corner, corner) with
# corners 0 = top-left, 1 = top-right, 2 = bottom-left, 3 = bottom-right, counter-clockwise seen
# from +z (rows go down, so "bottom" is -y). The key is the missing corner.
_SINGLE_TRIANGLES = {0: (2, 3, 1), 1: (0, 2, 3), 2: (0, 3, 1), 3: (0, 2, 1)}
# (row, column) offset of each corner from the cell's top-left grid point
_CORNER_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))


def _half_block(missing: int, size: int) -> np.ndarray:
    """Pixels of a ``size`` x ``size`` cell block covered by the triangle opposite ``missing``.

    Returns
    -------
    (size, size) bool
        Offsets ``(dr, dc)`` inside the closed triangle (its diagonal included).
    """
    dr, dc = np.indices((size, size))
    last = size - 1
    return {
        0: dr + dc >= last,  # triangle BL-BR-TR: below the anti-diagonal
        1: dr >= dc,  # TL-BL-BR: below the main diagonal
        2: dr <= dc,  # TL-BR-TR: above the main diagonal
        3: dr + dc <= last,  # TL-BL-TR: above the anti-diagonal
    }[missing]


def cell_triangles(tl: np.ndarray, tr: np.ndarray, bl: np.ndarray, br: np.ndarray) -> np.ndarray:
    """Two triangles per square grid cell, split along its top-left to bottom-right diagonal.

    Parameters
    ----------
    tl, tr, bl, br : (n,) int
        Vertex index of each cell's top-left, top-right, bottom-left and bottom-right corner
        (rows go down, so "bottom" is -y).

    Returns
    -------
    faces : (2 n, 3) int64
        ``(tl, bl, br)`` and ``(tl, br, tr)`` per cell, in cell order: counter-clockwise seen
        from +z.
    """
    pairs = np.empty((np.size(tl), 6), dtype=np.int64)
    for column, corner in enumerate((tl, bl, br, tl, br, tr)):
        pairs[:, column] = corner
    return pairs.reshape(-1, 3)


def to_mesh(reconstruction: Reconstruction, *, step: int = 1) -> Mesh:
    """Triangulate a reconstruction's depth map on a regular pixel grid.

    Vertices sit at every ``step``-th pixel (rows and columns ``0, step, 2 step, ...``) that is in
    the mask with a finite depth and a finite, non-zero normal. Each grid cell (a square of side
    ``step`` pixels) becomes two triangles split along its top-left to bottom-right diagonal
    when all four corners are valid, or the one triangle of the three valid corners when one is
    missing. A triangle is kept only if every pixel it covers is in the mask, so no triangle
    bridges the silhouette (a gap, a hole, a concave notch) even where the gap falls between
    grid points. For ``step=1`` that is just its corners. For ``step > 1`` a two-triangle cell
    needs its whole ``(step + 1) x (step + 1)`` pixel block in the mask; if it touches the
    background, each of its two halves is kept on its own when the closed half-block (diagonal
    included) is in the mask; a one-triangle cell needs its closed half-block in the mask.
    Vertices no triangle uses are dropped.

    Parameters
    ----------
    reconstruction : Reconstruction
        Uses ``depth`` (H, W), ``normals`` (H, W, 3) and ``mask`` (H, W).
    step : int, keyword-only
        Grid spacing in pixels, ``1 <= step < min(H, W)``.

    Returns
    -------
    Mesh
        ``vertices[k] = (c, -r, depth[r, c])``, ``normals[k]`` the renormalised reconstruction
        normal at ``(r, c)``, ``uv[k] = ((c + 0.5) / W, 1 - (r + 0.5) / H)``; triangles
        counter-clockwise seen from +z.

    Raises
    ------
    InputError
        If ``step`` is not an integer in range, the arrays' shapes disagree, or no triangle
        fits in the mask at this ``step``.

    Notes
    -----
    Fully vectorised; memory is a few arrays of the grid's size, plus one pixel block per cell
    along the silhouette. Face order: the two-triangle cells row-major (each cell's pair
    adjacent), then the one-triangle cells grouped by shape. Vertices are numbered row-major.
    """
    mask, depth, normals = _check_reconstruction(reconstruction)
    height, width = mask.shape
    step = _check_step(step, mask.shape)

    rows = np.arange(0, height, step)
    cols = np.arange(0, width, step)
    grid_mask = mask[::step, ::step]
    grid_depth = depth[::step, ::step]
    grid_normals = normals[::step, ::step]
    lengths = np.sqrt(np.einsum("ijk,ijk->ij", grid_normals, grid_normals, dtype=np.float64))
    with np.errstate(invalid="ignore"):
        valid = grid_mask & np.isfinite(grid_depth) & np.isfinite(lengths) & (lengths > 0)

    # corner validity of every cell, each (R - 1, C - 1); order as in _SINGLE_TRIANGLES
    corner_ok = (valid[:-1, :-1], valid[:-1, 1:], valid[1:, :-1], valid[1:, 1:])
    n_ok = sum(ok.astype(np.int8) for ok in corner_ok)
    background = ~mask

    full = n_ok == 4
    # one-triangle candidates: cell row, cell column, missing corner
    cell_r, cell_c = np.nonzero(n_ok == 3)
    missing = np.argmin(np.stack([ok[cell_r, cell_c] for ok in corner_ok]), axis=0)
    if step > 1:
        # corners alone miss a background gap that falls between grid points
        top, left = np.meshgrid(rows[:-1], cols[:-1], indexing="ij")
        clear = _outside_count(background, top, left, step + 1) == 0
        # a full cell touching the background may still keep one of its two halves
        split_r, split_c = np.nonzero(full & ~clear)
        cell_r = np.concatenate([cell_r, split_r, split_r])
        cell_c = np.concatenate([cell_c, split_c, split_c])
        missing = np.concatenate([missing, np.full(split_r.size, 1), np.full(split_r.size, 2)])
        full &= clear

    singles = []  # (cell rows, cell cols, corners) of the kept one-triangle cells, per shape
    for kind, corners in _SINGLE_TRIANGLES.items():
        pick = missing == kind
        r, c = cell_r[pick], cell_c[pick]
        if step > 1 and r.size:
            # gather each candidate's pixel block (few cells: only along the silhouette)
            offsets = np.arange(step + 1)
            block_rows = rows[r][:, None, None] + offsets[None, :, None]
            block_cols = cols[c][:, None, None] + offsets[None, None, :]
            block_bg = background[block_rows, block_cols]
            inside = ~(block_bg & _half_block(kind, step + 1)).any(axis=(1, 2))
            r, c = r[inside], c[inside]
        singles.append((r, c, corners))

    # number the grid points some triangle uses, row-major, before building the faces
    used = np.zeros(valid.shape, dtype=bool)
    for dr, dc in _CORNER_OFFSETS:
        used[dr : dr + full.shape[0], dc : dc + full.shape[1]] |= full
    for r, c, corners in singles:
        for k in corners:
            used[r + _CORNER_OFFSETS[k][0], c + _CORNER_OFFSETS[k][1]] = True
    if not used.any():
        raise InputError(
            f"no triangle fits inside the mask at step={step}; use a smaller step or a larger mask"
        )
    vertex_id = np.cumsum(used.ravel()).reshape(used.shape) - 1
    corner_id = tuple(
        vertex_id[dr : dr + full.shape[0], dc : dc + full.shape[1]] for dr, dc in _CORNER_OFFSETS
    )

    pieces = [cell_triangles(*(ids[full] for ids in corner_id))]
    for r, c, corners in singles:
        pieces.append(np.stack([corner_id[k][r, c] for k in corners], axis=1))
    faces = np.concatenate(pieces)

    vertex_r, vertex_c = np.nonzero(used)
    vertex_r, vertex_c = rows[vertex_r], cols[vertex_c]
    vertices = np.column_stack([vertex_c, -vertex_r, grid_depth[used]]).astype(np.float64)
    vertex_normals = grid_normals[used] / lengths[used][:, None]
    uv = np.column_stack([(vertex_c + 0.5) / width, 1.0 - (vertex_r + 0.5) / height])
    return Mesh(vertices, faces, vertex_normals, uv)


def solid_measures(mesh: Mesh) -> dict:
    """A closed model's enclosed volume (cubic pixels) and whether it is watertight (every edge
    shared by exactly two consistently wound faces), as trimesh measures them:
    ``{"volume": float, "watertight": bool}``."""
    import trimesh

    solid = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    return {"volume": float(solid.volume), "watertight": bool(solid.is_watertight)}


def outward(solid) -> Mesh:
    """A closed :class:`trimesh.Trimesh` as a :class:`Mesh` whose faces wind outward (its
    volume positive), with its vertex normals."""
    if solid.volume < 0:
        solid.invert()
    return Mesh(
        vertices=np.asarray(solid.vertices),
        faces=np.asarray(solid.faces, dtype=np.int64),
        normals=np.asarray(solid.vertex_normals),
    )


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (``+z`` where they cancel), summed a chunk of faces at a
    time so that the temporaries stay small next to the mesh.

    Parameters
    ----------
    vertices : (V, 3) float
        Vertex positions.
    faces : (F, 3) int
        Triangles, counter-clockwise seen from outside (the normals point that way).

    Returns
    -------
    (V, 3) float64
        Unit normals; ``(0, 0, 1)`` at a vertex no face uses or whose faces' normals cancel.
    """
    normals = np.zeros((len(vertices), 3))
    for start in range(0, len(faces), _CHUNK_FACES):
        chunk = faces[start : start + _CHUNK_FACES]
        a = vertices[chunk[:, 0]]
        face_normals = np.cross(vertices[chunk[:, 1]] - a, vertices[chunk[:, 2]] - a)
        # a chunk's faces use a narrow band of vertex numbers (the grid is numbered row by row)
        low, high = int(chunk.min()), int(chunk.max()) + 1
        for corner in range(3):
            for k in range(3):
                normals[low:high, k] += np.bincount(
                    chunk[:, corner] - low, face_normals[:, k], minlength=high - low
                )
    length = np.linalg.norm(normals, axis=1)
    flat = length <= 0
    normals[flat] = (0.0, 0.0, 1.0)
    length[flat] = 1.0
    normals /= length[:, None]
    return normals
