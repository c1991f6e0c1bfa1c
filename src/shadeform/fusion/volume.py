"""The volume the views share: their visual hull, each view's depth offset, and the signed
distance that fuses their surfaces, on one grid of voxels in the object frame.

Signed distance (Curless & Levoy 1996): along view ``v``'s ray through a voxel, ``s = z - z_v``
with ``z_v`` the view's surface (its depth plus offset) and ``z`` the voxel's depth, positive in
front of the surface (toward the camera). Each view that sees the voxel (it projects inside
the view's mask and lies at most ``truncation`` behind the view's surface) adds
``clip(s, -tau, tau) / tau`` weighted by how squarely the view saw that surface (its normal's
``n_z``; only a grazing view's weight where the view's depth is not trusted, beyond its own
occluding contours: :func:`trusted_surface`); a voxel that projects outside any view's
silhouette is outside (the visual hull, Laurentini 1994); one that no view sees is inside where
a view's surface hides it. The zero level is meshed by marching cubes (Lorensen & Cline 1987), on a
grid padded with outside so that the mesh is closed.

References
----------
.. [1] B. Curless, M. Levoy, "A volumetric method for building complex models from range
   images", SIGGRAPH 1996.
.. [2] A. Laurentini, "The visual hull concept for silhouette-based image understanding",
   IEEE TPAMI 16(2), 1994.
.. [3] W. E. Lorensen, H. E. Cline, "Marching cubes", SIGGRAPH 1987.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

__all__ = [
    "Grid",
    "FusionView",
    "crossed",
    "fused_distance",
    "hull",
    "hull_depth",
    "one_solid",
    "rim_offset",
    "trusted_surface",
    "view_offsets",
]

# The constants below were set by hand, not swept, and checked only on synthetic views (the closed
# objects of benchmarks/results/fusion.md).

#: The percentile of the gaps between the hull's front and a view's surface taken as where they
#: touch (a low one: they touch along curves, and a few wrong depths must not decide).
TOUCH_PERCENTILE = 2.0
#: Pixels whose normal has ``n_z`` below this are the view's own rim (left out of the gaps).
RIM_NZ = 0.3
#: The width of a view's rim, in pixels: how far from a facing piece its rim pixels reach.
RIM_WIDTH = 2.5
#: A facing piece of fewer pixels than a disc of the rim's width is a speck of the rim's noisy
#: normals (paint, gloss, 8-bit photos), not a surface: left to the rim around it.
SPECK = np.pi * RIM_WIDTH**2
#: A pixel whose normal is within this (the sine of the angle, about 11.5 degrees) of tangent to
#: another view's line of sight lies on that view's contour generator, on the hull's boundary.
#: Set by hand (0.1 and 0.2 gave the same offsets to 0.05 % of the diagonal on the realistic
#: ellipsoid's four views, results/fusion-realistic.md); 0.2 counts more pixels.
TANGENT = 0.2
#: Smallest weight of a view's reading: how squarely it saw the surface (``n_z``), at least this.
MIN_WEIGHT = 0.05
#: Two views whose directions' dot product is below minus this face each other (within about 18
#: degrees of opposite: the poses :func:`shadeform.fusion.fuse` corrects are at most 10 off).
OPPOSITE = 0.95


@dataclass(frozen=True, eq=False)
class FusionView:
    """One view, placed: its depth map (up to ``offset``), mask, normals and pose.

    ``depth`` is the single-photo height (NaN off the mask); ``rotation`` and ``translation``
    take object points to the camera frame; ``column0`` is the column of ``x = 0``. ``trusted``
    (computed) marks the pixels whose depth is known up to ``offset``
    (:func:`trusted_surface`): elsewhere the view says little.
    """

    depth: np.ndarray
    mask: np.ndarray
    normals: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    column0: float
    offset: float = 0.0
    filled: np.ndarray = field(init=False, repr=False)
    trusted: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "trusted", trusted_surface(self.mask, self.normals))
        # the depth continued off the mask by its nearest object pixel: a bilinear lookup at the
        # silhouette then never reads NaN
        near = ndimage.distance_transform_edt(~self.mask, return_distances=False, return_indices=True)
        object.__setattr__(self, "filled", np.nan_to_num(self.depth[tuple(near)]))

    @property
    def row0(self) -> float:
        return (self.mask.shape[0] - 1) / 2.0

    def camera(self, points: np.ndarray) -> np.ndarray:
        """Object points (M, 3) in this view's camera frame."""
        return points @ self.rotation.T + self.translation

    def pixels(self, camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera points (..., 3) -> their (row, column), fractional, each (...)."""
        return self.row0 - camera[..., 1], camera[..., 0] + self.column0

    def inside(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Whether (row, column) lies on the mask (nearest pixel)."""
        r, c = np.rint(rows).astype(np.int64), np.rint(cols).astype(np.int64)
        h, w = self.mask.shape
        valid = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        out = np.zeros(r.shape, bool)
        out[valid] = self.mask[r[valid], c[valid]]
        return out

    def surface(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """The view's surface depth (with its offset) at (row, column), bilinear."""
        return ndimage.map_coordinates(self.filled, [rows, cols], order=1, mode="nearest") + self.offset

    def surface_points(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """The view's surface at mask pixels (rows, cols) as object points (M, 3)."""
        camera = np.stack(
            [cols - self.column0, self.row0 - rows, self.depth[rows, cols] + self.offset], axis=1
        )
        return (camera - self.translation) @ self.rotation

    def at(self, rotation: np.ndarray, translation: np.ndarray, offset: float) -> FusionView:
        """The same view at another pose and depth offset, sharing its arrays (the depth's
        nearest-pixel fill is not computed again)."""
        moved = object.__new__(FusionView)
        for name, value in vars(self).items():
            object.__setattr__(moved, name, value)
        object.__setattr__(moved, "rotation", rotation)
        object.__setattr__(moved, "translation", translation)
        object.__setattr__(moved, "offset", float(offset))
        return moved


@dataclass(frozen=True)
class Grid:
    """Voxel centres ``origin + spacing * (i, j, k)`` for ``(i, j, k) < shape``, object frame."""

    origin: np.ndarray
    spacing: float
    shape: tuple[int, int, int]

    def slabs(self, view: FusionView):
        """The voxels in a view's camera frame, one slab ``i`` at a time: yields ``(i, camera)``
        with ``camera`` (shape[1], shape[2], 3). The frame is affine in the indices, so a slab is
        one sum of precomputed planes (no matrix product per voxel)."""
        rotation = view.rotation
        base = rotation @ self.origin + view.translation
        step = self.spacing * rotation[:, 0]
        j = np.arange(self.shape[1], dtype=np.float64)[:, None, None]
        k = np.arange(self.shape[2], dtype=np.float64)[None, :, None]
        plane = j * (self.spacing * rotation[:, 1]) + k * (self.spacing * rotation[:, 2]) + base
        for i in range(self.shape[0]):
            yield i, plane + i * step


def trusted_surface(mask: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """The pixels of a view whose depth one photo fixes up to the view's one offset, (H, W) bool.

    Where a part of the object hides another inside the silhouette, the depth jumps across the
    near part's rim (an occluding contour) by an amount no photo shows, and a single-photo
    solver, integrating across it, leaves the surface beyond off by its own unknown offset (on
    synth's waisted object and the held-out shapes of ``benchmarks/results/fusion-shapes.md``,
    tens of pixels, always too near). The view's facing surface (``n_z`` above :data:`RIM_NZ`)
    falls apart at such rims into pieces, and the rim is the near piece's: its normals, turned
    away from the camera, point across the rim toward the piece it hides. So each piece is
    scored by the share of its border (the rim pixels whose nearest facing pixel is in it)
    whose in-plane normal points toward it, and only the least hidden piece is trusted (the
    largest among equals), with the rim around it; a view in one piece is trusted everywhere.
    A piece hidden that way ranked below the trusted one in every view of those objects (8
    turntable angles), including two where it was the larger piece.

    Parameters
    ----------
    mask : (H, W) bool
    normals : (H, W, 3) float
        Camera-frame unit normals (NaN allowed off the mask).

    Returns
    -------
    (H, W) bool
    """
    mask = np.asarray(mask, bool)
    facing = mask & (np.nan_to_num(normals[..., 2]) > RIM_NZ)
    labels, count = ndimage.label(facing)
    if count > 1:  # specks of noisy normals are not pieces of surface
        sizes = np.bincount(labels.ravel(), minlength=count + 1)
        labels, count = ndimage.label((sizes >= SPECK)[labels] & facing)
    if count <= 1:
        return mask.copy()
    # what follows looks at most RIM_WIDTH px from the mask: on its bounding box, a few pixels wider
    rows, cols = np.nonzero(mask)
    box = (
        slice(max(rows.min() - 3, 0), rows.max() + 4),
        slice(max(cols.min() - 3, 0), cols.max() + 4),
    )
    out = np.zeros(mask.shape, bool)
    out[box] = _trusted_piece(
        mask[box], np.nan_to_num(np.asarray(normals[box], np.float64)), labels[box], count
    )
    return out


def _trusted_piece(mask, normals, labels, count) -> np.ndarray:
    """:func:`trusted_surface` once the view's facing surface is cut into ``count`` labelled
    pieces (``labels``)."""
    facing = labels > 0
    # each rim pixel next to a piece (within the rim's width, RIM_WIDTH: set by hand), and the way
    # from it to that piece's nearest pixel
    distance, (near_r, near_c) = ndimage.distance_transform_edt(~facing, return_indices=True)
    rows, cols = np.nonzero(mask & ~facing & (distance <= RIM_WIDTH))
    owner = labels[near_r[rows, cols], near_c[rows, cols]]
    down, across = near_r[rows, cols] - rows, near_c[rows, cols] - cols
    # image rows go down, camera y up; a normal pointing toward the piece (within 60 degrees)
    toward = (normals[rows, cols, 0] * across - normals[rows, cols, 1] * down) / np.maximum(
        np.hypot(down, across), 1e-9
    ) > 0.5
    border = np.bincount(owner, minlength=count + 1)[1:]
    hidden = np.bincount(owner, weights=toward, minlength=count + 1)[1:] / np.maximum(border, 1)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    kept = 1 + int(np.lexsort((-sizes, hidden))[0])
    # the kept piece and the rim pixels that belong to it (its own rim, whose depth it carries)
    rim = mask & ~facing
    ours = np.zeros(mask.shape, bool)
    ours[rim] = labels[near_r[rim], near_c[rim]] == kept
    return (labels == kept) | ours


def hull(views: list[FusionView], grid: Grid) -> np.ndarray:
    """The visual hull on the grid: voxels that project onto every view's mask, (shape) bool."""
    inside = np.ones(grid.shape, bool)
    for view in views:
        for i, camera in grid.slabs(view):
            if inside[i].any():
                inside[i] &= view.inside(*view.pixels(camera))
    return inside


def hull_depth(view: FusionView, grid: Grid, inside: np.ndarray) -> np.ndarray:
    """The hull's front surface seen from a view: per pixel, the largest camera ``z`` of a hull
    voxel on its ray plus half a voxel (NaN where none), (H, W)."""
    h, w = view.mask.shape
    front = np.full(h * w, -np.inf)
    for i, camera in grid.slabs(view):
        points = camera[inside[i]]
        if not len(points):
            continue
        rows, cols = view.pixels(points)
        r, c = np.rint(rows).astype(np.int64), np.rint(cols).astype(np.int64)
        valid = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        np.maximum.at(front, r[valid] * w + c[valid], points[valid, 2])
    front += grid.spacing / 2
    return np.where(np.isfinite(front), front, np.nan).reshape(h, w)


def crossed(view: FusionView, others: list[FusionView]) -> bool:
    """Whether another view looks across this one's direction (by more than about 12 degrees),
    so that its silhouette bounds this view's depths."""
    return any(_crosses(view, other) for other in others)


def _crosses(view: FusionView, other: FusionView) -> bool:
    return bool(np.linalg.norm(np.cross(view.rotation[2], other.rotation[2])) > 0.2)


def hull_gaps(front: np.ndarray, depth: np.ndarray, mask: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """How far the hull's front (:func:`hull_depth`) lies in front of a view's surface
    (``depth``, camera z), over the pixels that face the view (``n_z`` above :data:`RIM_NZ`,
    away from its own rim) where the hull says something, (M,)."""
    facing = mask & np.isfinite(depth) & (np.nan_to_num(normals[..., 2]) > RIM_NZ) & np.isfinite(front)
    return front[facing] - depth[facing]


def view_offsets(views: list[FusionView], grid: Grid, inside: np.ndarray) -> list[float]:
    """Each view's depth offset: the one that brings its surface forward until it touches the
    other views' visual hull.

    The hull's boundary holds the other views' contour generators (where their lines of sight
    graze the surface), and a view that does not look along the same line sees those curves
    from the front: there its surface and the hull's front meet, everywhere else the surface lies
    behind the hull's front. Those curves are where the view's surface is tangent to another
    view's line of sight, which the view's own normals show (:data:`TANGENT`): the offset is the
    median gap between the hull's front and the view's surface over those pixels
    (:func:`touching_offset`), away from the view's own rim, where both surfaces turn away
    steeply. A view whose direction no other view crosses keeps its offset.

    A view that no other crosses but that another, placed before it, faces from the opposite side
    (a turntable's 0 and 180 degrees) shares its outline with that view: in an orthographic
    photo the surface's rim seen from a direction and from its opposite is the same curve (the
    contour generator), so the view is moved until its rim meets the other's
    (:func:`rim_offset`). Without it the two surfaces of a front and back pair lie at a guessed
    distance, crossing each other near the outline (the model then narrower than both
    silhouettes) or far apart.

    Returns
    -------
    list of float
        One offset per view, pixel units.
    """
    offsets: list[float] = []
    for n, view in enumerate(views):
        if crossed(view, [other for m, other in enumerate(views) if m != n]):
            others = [other for m, other in enumerate(views) if m != n]
            offsets.append(touching_offset(view, hull_depth(view, grid, inside), others))
            continue
        facing = [m for m in range(n) if float(views[m].rotation[2] @ view.rotation[2]) < -OPPOSITE]
        if facing:
            other = views[facing[0]]
            offsets.append(rim_offset(view, other.at(other.rotation, other.translation, offsets[facing[0]])))
        else:
            offsets.append(view.offset)
    return offsets


def rim_offset(view: FusionView, other: FusionView) -> float:
    """The offset that brings a view's rim onto the rim of ``other``, a view from the opposite
    side (:func:`view_offsets`): the median, over the view's outline pixels that fall on the
    other's mask, of how far apart the two surfaces lie there along the line of sight; the
    view's offset unchanged where they share no outline."""
    mask = view.mask & np.isfinite(view.depth)
    rim = mask & ~ndimage.binary_erosion(mask, border_value=0)
    rows, cols = np.nonzero(rim)
    if not len(rows):
        return view.offset
    camera = other.camera(view.surface_points(rows, cols))
    r, c = other.pixels(camera)
    on = other.inside(r, c)
    if not on.any():
        return view.offset
    # moving this view's surface by d along its own axis moves it by k * d along the other's
    k = float(other.rotation[2] @ view.rotation[2])
    # an outline pixel's centre lies half a pixel inside the outline, where the surface has
    # already turned toward its camera: each view's rim lies that much behind its pixels
    ahead = _past_rim(view.normals[rows, cols, 2])[on]
    ahead_other = _past_rim(
        ndimage.map_coordinates(np.nan_to_num(other.normals[..., 2]), [r[on], c[on]], order=0)
    )
    gap = (other.surface(r[on], c[on]) - ahead_other) - (camera[on, 2] - k * ahead)
    return view.offset + float(np.median(gap)) / k


def _past_rim(nz: np.ndarray) -> np.ndarray:
    """How far in front of the occluding contour a surface point half a pixel inside the outline
    lies, from its normal's ``n_z``: on a circle of radius ``R`` through the contour, a point
    ``d`` in from the outline with ``n_z = sin(phi)`` lies ``R sin(phi)`` in front, with
    ``d = R (1 - cos(phi))``; ``d = 0.5`` (the outline is half a pixel beyond the outermost pixel
    centres, :func:`silhouette_distance`)."""
    nz = np.clip(np.nan_to_num(np.abs(nz)), 0.05, 1.0)  # 0.05: an outline at most 400 px round
    return 0.5 * nz / (1.0 - np.sqrt(1.0 - nz**2))


def touching_offset(view: FusionView, front: np.ndarray, others: list[FusionView] = ()) -> float:
    """The offset that brings the view's surface forward until it touches the hull's front
    ``front`` (:func:`hull_depth`), as :func:`view_offsets` finds it.

    The median gap over the pixels whose normal is tangent to a crossing view's line of sight
    (``others``; within :data:`TANGENT`): those lie on the hull's boundary, so the median is
    the offset, unbiased by the depths' noise. Where such pixels are fewer than :data:`SPECK`
    (or no view is given), the gaps' :data:`TOUCH_PERCENTILE`-th percentile over every facing
    pixel: the smallest gap, taken robustly, which noisy depths pull behind the hull (on the
    realistic ellipsoid's four views, 1.5 px deep and a model 17 % too small).
    """
    pixels = view.mask & view.trusted
    normals = np.nan_to_num(view.normals)
    tangent = np.zeros(view.mask.shape, bool)
    for other in others:
        if _crosses(view, other):
            tangent |= np.abs(normals @ (view.rotation @ other.rotation[2])) < TANGENT
    gap = hull_gaps(front, view.depth + view.offset, pixels & tangent, view.normals)
    if len(gap) >= SPECK:
        return view.offset + float(np.median(gap))
    gap = hull_gaps(front, view.depth + view.offset, pixels, view.normals)
    touch = float(np.percentile(gap, TOUCH_PERCENTILE)) if len(gap) else 0.0
    return view.offset + touch


def fused_distance(views: list[FusionView], grid: Grid, *, truncation: float) -> np.ndarray:
    """The fused, truncated signed distance in ``[-1, 1]`` on the grid (module description):
    positive outside, negative inside."""
    hull_distance = np.full(grid.shape, -np.inf)
    total = np.zeros(grid.shape)
    weight = np.zeros(grid.shape)
    hidden = np.zeros(grid.shape, bool)  # on a view's mask, behind its surface
    for view in views:
        # a pixel whose depth is not trusted counts as little as a grazing one
        squarely = np.where(
            view.trusted, np.maximum(np.nan_to_num(view.normals[..., 2]), MIN_WEIGHT), MIN_WEIGHT
        )
        outline = silhouette_distance(view.mask)
        for i, camera in grid.slabs(view):
            rows, cols = view.pixels(camera)
            # beyond the image the silhouette distance goes on growing, so that such a voxel is out
            beyond = np.maximum.reduce(
                [
                    -rows,
                    rows - (view.mask.shape[0] - 1),
                    -cols,
                    cols - (view.mask.shape[1] - 1),
                    np.zeros_like(rows),
                ]
            )
            np.maximum(
                hull_distance[i],
                ndimage.map_coordinates(outline, [rows, cols], order=1, mode="nearest") + beyond,
                out=hull_distance[i],
            )
            on = view.inside(rows, cols)
            if not on.any():
                continue
            signed = camera[..., 2] - view.surface(rows, cols)
            seen = on & (signed > -truncation)
            hidden[i] |= on & ~seen
            r, c = np.rint(rows[seen]).astype(np.int64), np.rint(cols[seen]).astype(np.int64)
            w = squarely[r, c]
            total[i][seen] += w * np.clip(signed[seen] / truncation, -1.0, 1.0)
            weight[i][seen] += w
    # a voxel no view sees is inside where a view's surface hides it; one on no view's mask (a
    # pixel's width off the outline, where the outline's distance, interpolated, still reads
    # inside) is outside: counted inside, such voxels made needles along every line of sight
    fused = np.where(weight > 0, total / np.maximum(weight, 1e-12), np.where(hidden, -1.0, 1.0))
    # the solid within the visual hull: the larger of the two signed distances (an intersection),
    # so that where the surface is the hull's it is as smooth as the silhouettes, not voxel steps
    return np.maximum(fused, np.clip(hull_distance / truncation, -1.0, 1.0))


def silhouette_distance(mask: np.ndarray) -> np.ndarray:
    """Signed distance (pixels) to a view's silhouette, negative inside: the outline lies half a
    pixel beyond the outermost object pixels' centres, (H, W)."""
    outside = ndimage.distance_transform_edt(~mask)
    inside = ndimage.distance_transform_edt(mask)
    return np.where(mask, 0.5 - inside, outside - 0.5)


def one_solid(distance: np.ndarray) -> np.ndarray:
    """The signed distance of one solid: the largest connected inside part (face-connected
    voxels), its inner voids filled; other inside bits become outside. Where views disagree
    (slightly wrong poses, wrong depths) the fused distance leaves floating crumbs and bubbles,
    which a printable, renderable model must not have."""
    labels, count = ndimage.label(distance < 0)
    if count == 0:
        return distance
    sizes = np.bincount(labels.ravel())[1:]
    solid = ndimage.binary_fill_holes(labels == 1 + int(np.argmax(sizes)))
    # never (nearly) 0: a grid point on the level would put several mesh vertices at one place
    # (to float32 precision, which marching cubes returns)
    magnitude = np.maximum(np.abs(distance), 1e-3)
    return np.where(solid, -magnitude, magnitude)
