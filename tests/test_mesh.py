"""Tests for shadeform.mesh: Mesh checks and to_mesh (counts, winding, no silhouette bridges)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from shadeform.errors import InputError
from shadeform.mesh import Mesh, to_mesh
from shadeform.reconstruction import Reconstruction


def reconstruction(mask, depth=None, normals=None):
    """A Reconstruction over ``mask``: flat depth and +z normals unless given, NaN outside."""
    mask = np.asarray(mask, dtype=bool)
    if depth is None:
        depth = np.zeros(mask.shape)
    if normals is None:
        normals = np.zeros(mask.shape + (3,))
        normals[..., 2] = 1.0
    depth = np.where(mask, depth, np.nan)
    normals = np.where(mask[..., None], normals, np.nan)
    return Reconstruction(normals, depth, mask, np.array([0.0, 0.0, 1.0]), 1.0)


def hemisphere(size=41, radius=18.0):
    """A hemisphere of ``radius`` pixels centred in a ``size`` x ``size`` image."""
    rows, cols = np.mgrid[:size, :size].astype(float)
    centre = (size - 1) / 2
    dx, dy = cols - centre, -(rows - centre)
    mask = dx**2 + dy**2 < radius**2
    depth = np.sqrt(np.maximum(radius**2 - dx**2 - dy**2, 0.0))
    normals = np.stack([dx, dy, depth], axis=-1) / radius
    return reconstruction(mask, depth, normals)


def face_normals(mesh):
    corners = mesh.vertices[mesh.faces]
    return np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])


def covered_pixels_outside(mesh, mask):
    """How many (face, pixel) pairs have a pixel centre in a closed triangle but not in ``mask``.

    An independent rasterisation: every lattice point of each triangle's bounding box is tested
    with edge functions (inclusive), in image coordinates r = -y, c = x.
    """
    rc = np.stack([-mesh.vertices[:, 1], mesh.vertices[:, 0]], axis=1)[mesh.faces]  # (F, 3, 2)
    top_left = np.floor(rc.min(axis=1)).astype(int)
    extent = int(np.ceil((rc.max(axis=1) - rc.min(axis=1)).max())) + 1
    offsets = np.stack(np.meshgrid(np.arange(extent), np.arange(extent), indexing="ij"), -1)
    points = top_left[:, None, None, :] + offsets[None]  # (F, E, E, 2)
    inside = np.ones(points.shape[:3], dtype=bool)
    for k in range(3):
        a, b = rc[:, k], rc[:, (k + 1) % 3]
        edge = (b - a)[:, None, None, :]
        rel = points - a[:, None, None, :]
        cross = edge[..., 0] * rel[..., 1] - edge[..., 1] * rel[..., 0]
        # all three edge functions share the sign of the triangle's orientation
        orientation = np.sign(
            (rc[:, 1, 0] - rc[:, 0, 0]) * (rc[:, 2, 1] - rc[:, 0, 1])
            - (rc[:, 1, 1] - rc[:, 0, 1]) * (rc[:, 2, 0] - rc[:, 0, 0])
        )[:, None, None]
        inside &= cross * orientation >= -1e-9
    r = np.clip(points[..., 0], 0, mask.shape[0] - 1)
    c = np.clip(points[..., 1], 0, mask.shape[1] - 1)
    return int((inside & ~mask[r, c]).sum())


class TestMesh:
    def test_smoke(self):
        mesh = Mesh(np.eye(3), np.array([[0, 1, 2]]), np.tile([0.0, 0.0, 1.0], (3, 1)))
        assert mesh.n_vertices == 3 and mesh.n_faces == 1
        assert mesh.uv is None

    def test_dtypes_are_converted(self):
        mesh = Mesh(
            np.eye(3, dtype=np.float32),
            np.array([[0, 1, 2]], dtype=np.int32),
            np.tile([0, 0, 1], (3, 1)),
            np.zeros((3, 2), dtype=np.float32),
        )
        assert mesh.vertices.dtype == np.float64
        assert mesh.faces.dtype == np.int64
        assert mesh.normals.dtype == np.float64
        assert mesh.uv.dtype == np.float64

    def test_frozen(self):
        mesh = Mesh(np.eye(3), np.array([[0, 1, 2]]), np.tile([0.0, 0.0, 1.0], (3, 1)))
        with pytest.raises(AttributeError):
            mesh.faces = np.zeros((0, 3))

    @pytest.mark.parametrize(
        ("vertices", "faces", "normals", "uv", "message"),
        [
            (np.zeros((3, 2)), [[0, 1, 2]], np.zeros((3, 3)), None, "vertices must have shape"),
            (np.zeros((3, 3)), [0, 1, 2], np.zeros((3, 3)), None, "faces must have shape"),
            (np.zeros((3, 3)), [[0, 1, 3]], np.zeros((3, 3)), None, "indices must lie in"),
            (np.zeros((3, 3)), [[-1, 1, 2]], np.zeros((3, 3)), None, "indices must lie in"),
            (np.zeros((3, 3)), [[0.0, 1.0, 2.0]], np.zeros((3, 3)), None, "integer"),
            (np.zeros((3, 3)), [[0, 1, 2]], np.zeros((2, 3)), None, "normals must have shape"),
            (np.zeros((3, 3)), [[0, 1, 2]], np.zeros((3, 3)), np.zeros((3, 3)), "uv must have"),
            (np.full((3, 3), np.nan), [[0, 1, 2]], np.zeros((3, 3)), None, "NaN"),
            (np.zeros((3, 3)), [[0, 1, 2]], np.full((3, 3), np.inf), None, "NaN or inf"),
        ],
    )
    def test_invalid_is_input_error(self, vertices, faces, normals, uv, message):
        with pytest.raises(InputError, match=message) as info:
            Mesh(vertices, np.asarray(faces), normals, uv)
        assert "\n" not in str(info.value)


class TestToMesh:
    def test_smoke(self):
        mesh = to_mesh(hemisphere())
        assert isinstance(mesh, Mesh)
        assert mesh.n_faces > 0

    def test_shapes(self):
        mesh = to_mesh(hemisphere(), step=2)
        v, f = mesh.n_vertices, mesh.n_faces
        assert mesh.vertices.shape == (v, 3) and mesh.vertices.dtype == np.float64
        assert mesh.faces.shape == (f, 3) and mesh.faces.dtype == np.int64
        assert mesh.normals.shape == (v, 3)
        assert mesh.uv.shape == (v, 2)

    @pytest.mark.parametrize("n", [2, 3, 7])
    def test_square_counts_by_hand(self, n):
        mesh = to_mesh(reconstruction(np.ones((n, n), dtype=bool)))
        assert mesh.n_vertices == n * n
        assert mesh.n_faces == 2 * (n - 1) ** 2

    def test_square_inside_background_counts(self):
        mask = np.zeros((9, 11), dtype=bool)
        mask[2:7, 3:9] = True  # 5 rows x 6 columns of object
        mesh = to_mesh(reconstruction(mask))
        assert mesh.n_vertices == 5 * 6
        assert mesh.n_faces == 2 * 4 * 5

    def test_vertex_positions_are_c_minus_r_depth(self):
        mask = np.ones((3, 4), dtype=bool)
        depth = np.arange(12, dtype=float).reshape(3, 4) / 10
        mesh = to_mesh(reconstruction(mask, depth))
        # vertices are numbered row-major over the grid
        rows, cols = np.nonzero(mask)
        expected = np.column_stack([cols, -rows, depth[rows, cols]])
        np.testing.assert_array_equal(mesh.vertices, expected)

    def test_winding_is_counter_clockwise_from_plus_z(self):
        mesh = to_mesh(reconstruction(np.ones((6, 5), dtype=bool)))
        normals = face_normals(mesh)
        assert (normals[:, 2] > 0).all()
        np.testing.assert_allclose(normals[:, :2], 0.0)

    def test_winding_of_one_corner_triangles(self):
        # an L-shaped 2x2 block: every one-triangle shape appears in some rotation of it
        for missing in [(0, 0), (0, 1), (1, 0), (1, 1)]:
            mask = np.ones((2, 2), dtype=bool)
            mask[missing] = False
            mesh = to_mesh(reconstruction(mask))
            assert mesh.n_faces == 1 and mesh.n_vertices == 3
            assert face_normals(mesh)[0, 2] > 0

    def test_winding_on_a_curved_surface(self):
        mesh = to_mesh(hemisphere(), step=3)
        normals = face_normals(mesh)
        assert (normals[:, 2] > 0).all()
        # face normals agree with the vertex normals they are built from
        mean_vertex_normal = mesh.normals[mesh.faces].mean(axis=1)
        cosine = (normals * mean_vertex_normal).sum(1) / np.linalg.norm(normals, axis=1)
        assert np.median(cosine) > 0.95

    def test_step_two_vertex_and_face_counts(self):
        mesh = to_mesh(reconstruction(np.ones((9, 7), dtype=bool)), step=2)
        # grid rows 0, 2, 4, 6, 8 and columns 0, 2, 4, 6
        assert mesh.n_vertices == 5 * 4
        assert mesh.n_faces == 2 * 4 * 3
        assert set(mesh.vertices[:, 0]) == {0, 2, 4, 6}
        assert set(-mesh.vertices[:, 1]) == {0, 2, 4, 6, 8}

    def test_step_drops_last_partial_row_and_column(self):
        mesh = to_mesh(reconstruction(np.ones((8, 8), dtype=bool)), step=3)
        # grid 0, 3, 6 in each direction: 3 x 3 points, 2 x 2 cells
        assert mesh.n_vertices == 9
        assert mesh.n_faces == 8

    @pytest.mark.parametrize("transpose", [False, True])
    def test_no_triangle_spans_a_one_pixel_gap_step_1(self, transpose):
        mask = np.ones((10, 12), dtype=bool)
        mask[:, 5] = False
        if transpose:
            mask = mask.T
        mesh = to_mesh(reconstruction(mask))
        along = -mesh.vertices[:, 1] if transpose else mesh.vertices[:, 0]
        corner = along[mesh.faces]
        assert not ((corner.min(axis=1) < 5) & (corner.max(axis=1) > 5)).any()
        # left part 10 x 5, right part 10 x 6
        assert mesh.n_faces == 2 * 9 * 4 + 2 * 9 * 5
        assert covered_pixels_outside(mesh, mask) == 0

    # grid columns 0, 2, ..., 10; per grid row of cells, gap 4 (on a grid column) leaves cells
    # [0, 2], [6, 8], [8, 10]; gap 5 falls between grid columns 4 and 6, where corners alone
    # would bridge it, and leaves [0, 2], [2, 4], [6, 8], [8, 10]
    @pytest.mark.parametrize(("gap", "cells_per_row"), [(4, 3), (5, 4)])
    @pytest.mark.parametrize("transpose", [False, True])
    def test_no_triangle_spans_a_one_pixel_gap_step_2(self, gap, cells_per_row, transpose):
        mask = np.ones((9, 11), dtype=bool)
        mask[:, gap] = False
        if transpose:
            mask = mask.T
        mesh = to_mesh(reconstruction(mask), step=2)
        along = -mesh.vertices[:, 1] if transpose else mesh.vertices[:, 0]
        corner = along[mesh.faces]
        assert not ((corner.min(axis=1) < gap) & (corner.max(axis=1) > gap)).any()
        assert mesh.n_faces == 4 * cells_per_row * 2
        assert covered_pixels_outside(mesh, mask) == 0

    def test_a_full_cell_touching_the_background_keeps_its_clean_half(self):
        mask = np.ones((5, 5), dtype=bool)
        mask[0, 1] = False  # inside the top-left cell's block, above its diagonal
        mesh = to_mesh(reconstruction(mask), step=2)
        assert mesh.n_vertices == 9
        assert mesh.n_faces == 3 * 2 + 1
        assert covered_pixels_outside(mesh, mask) == 0
        # the kept half is top-left, bottom-left, bottom-right of that cell
        kept = {tuple(sorted(map(tuple, mesh.vertices[f, :2]))) for f in mesh.faces}
        assert ((0.0, -2.0), (0.0, 0.0), (2.0, -2.0)) in kept

    @pytest.mark.parametrize("step", [1, 2, 3, 5])
    def test_disk_faces_stay_inside_mask(self, step):
        rec = hemisphere(size=61, radius=27.0)
        mesh = to_mesh(rec, step=step)
        rows, cols = -mesh.vertices[:, 1].astype(int), mesh.vertices[:, 0].astype(int)
        assert rec.mask[rows, cols].all()
        assert covered_pixels_outside(mesh, rec.mask) == 0
        area = np.linalg.norm(face_normals(mesh), axis=1).sum() / 2
        # the triangulation covers most of the disk's projected area (minus a rim)
        projected = np.abs(face_normals(mesh)[:, 2]).sum() / 2
        assert projected > 0.8 * np.pi * 27.0**2 * (1 - 2 * step / 27.0)
        assert area >= projected

    @pytest.mark.parametrize("step", [1, 2, 4])
    def test_random_blobs_never_bridge(self, step):
        noise = np.random.default_rng(7).standard_normal((48, 64))
        mask = ndimage.gaussian_filter(noise, 2.0) > 0.05
        mesh = to_mesh(reconstruction(mask), step=step)
        assert covered_pixels_outside(mesh, mask) == 0
        assert (face_normals(mesh)[:, 2] > 0).all()

    def test_unreferenced_vertices_are_dropped(self):
        mask = np.zeros((10, 10), dtype=bool)
        mask[1:4, 1:4] = True
        mask[8, 8] = True  # an island pixel: no triangle, so no vertex
        mask[6, 1:7] = True  # a one-pixel line: no triangle either
        mesh = to_mesh(reconstruction(mask))
        assert mesh.n_vertices == 9
        assert np.array_equal(np.unique(mesh.faces), np.arange(9))

    def test_nan_depth_inside_mask_is_a_hole(self):
        mask = np.ones((5, 5), dtype=bool)
        depth = np.zeros((5, 5))
        depth[2, 2] = np.nan
        mesh = to_mesh(reconstruction(mask, depth))
        assert mesh.n_vertices == 24
        # the 4 cells around the centre lose it and keep the one triangle of their other corners
        assert mesh.n_faces == 32 - 4 * 2 + 4
        assert np.isfinite(mesh.vertices).all()

    def test_normals_copied_and_renormalised(self):
        rec = hemisphere()
        scaled = Reconstruction(rec.normals * 3.0, rec.depth, rec.mask, rec.light, rec.albedo)
        mesh = to_mesh(scaled, step=2)
        rows, cols = -mesh.vertices[:, 1].astype(int), mesh.vertices[:, 0].astype(int)
        np.testing.assert_allclose(mesh.normals, rec.normals[rows, cols], atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0)

    def test_uv_values_and_range(self):
        mask = np.ones((4, 8), dtype=bool)
        mesh = to_mesh(reconstruction(mask))
        u, v = mesh.uv.T
        assert (u > 0).all() and (u < 1).all() and (v > 0).all() and (v < 1).all()
        # vertex 0 is pixel (0, 0): u = 0.5 / W, v = 1 - 0.5 / H
        np.testing.assert_allclose(mesh.uv[0], [0.5 / 8, 1 - 0.5 / 4])
        np.testing.assert_allclose(mesh.uv[-1], [7.5 / 8, 1 - 3.5 / 4])
        cols, rows = mesh.vertices[:, 0], -mesh.vertices[:, 1]
        np.testing.assert_allclose(u, (cols + 0.5) / 8)
        np.testing.assert_allclose(v, 1 - (rows + 0.5) / 4)

    @pytest.mark.parametrize("step", [0, -1, 1.5, 2.0, True, "2", 5, 9])
    def test_bad_step_is_input_error(self, step):
        with pytest.raises(InputError, match="step") as info:
            to_mesh(reconstruction(np.ones((5, 7), dtype=bool)), step=step)
        assert "\n" not in str(info.value)

    def test_numpy_integer_step_is_accepted(self):
        mesh = to_mesh(reconstruction(np.ones((5, 5), dtype=bool)), step=np.int64(2))
        assert mesh.n_faces == 8

    def test_nothing_to_triangulate_is_input_error(self):
        mask = np.zeros((6, 6), dtype=bool)
        mask[2, :] = True
        with pytest.raises(InputError, match="no triangle fits"):
            to_mesh(reconstruction(mask))

    def test_mismatched_shapes_are_input_error(self):
        rec = reconstruction(np.ones((4, 4), dtype=bool))
        bad = Reconstruction(rec.normals, np.zeros((4, 5)), rec.mask, rec.light, rec.albedo)
        with pytest.raises(InputError, match="depth has shape"):
            to_mesh(bad)
        bad = Reconstruction(rec.normals[:, :3], rec.depth, rec.mask, rec.light, rec.albedo)
        with pytest.raises(InputError, match="normals have shape"):
            to_mesh(bad)
