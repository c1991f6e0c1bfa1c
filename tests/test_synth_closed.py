"""Closed synthetic objects seen from several views, and the surface measures that score fusion."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from shadeform.errors import InputError
from shadeform.mesh import Mesh
from shadeform.metrics import chamfer, f_score, volume_error
from shadeform.synth import (
    CLOSED_OBJECTS,
    ClosedObject,
    View,
    closed_object,
    render_views,
    turntable_pose,
)

SIZE = 64


def _camera_points(view: View) -> np.ndarray:
    """The recovered surface points of a view, (K, 3) in its camera frame."""
    size = view.mask.shape[0]
    coords = np.arange(size) - (size - 1) / 2
    x = np.broadcast_to(coords[None, :], (size, size))
    y = np.broadcast_to(-coords[:, None], (size, size))
    return np.stack([x, y, view.depth], axis=-1)[view.mask]


def _to_object(view: View, q: np.ndarray) -> np.ndarray:
    """Camera-frame points (K, 3) -> object frame: R^T (q - t)."""
    return (q - view.pose[:3, 3]) @ view.pose[:3, :3]


def _sphere_points(count: int, radius: float) -> np.ndarray:
    """Nearly evenly spread points on a sphere (Fibonacci lattice)."""
    k = np.arange(count) + 0.5
    z = 1 - 2 * k / count
    phi = np.pi * (3 - np.sqrt(5)) * k
    rho = np.sqrt(1 - z * z)
    return radius * np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=-1)


class TestClosedObject:
    @pytest.mark.parametrize("name", CLOSED_OBJECTS)
    def test_smoke(self, name):
        obj = closed_object(name, size=SIZE)
        assert isinstance(obj, ClosedObject) and obj.name == name and obj.size == SIZE
        assert obj.implicit(np.zeros(3)) < 0  # the origin is inside
        assert obj.volume > 0

    @pytest.mark.parametrize("name", CLOSED_OBJECTS)
    def test_fits_in_every_view(self, name):
        obj = closed_object(name, size=SIZE)
        assert 0.3 * SIZE < obj.radius <= 0.42 * SIZE
        # Outside the bounding radius the implicit function is positive in every direction.
        assert (obj.implicit(_sphere_points(5000, obj.radius + 0.5)) > 0).all()

    @pytest.mark.parametrize("name", CLOSED_OBJECTS)
    def test_gradient_matches_finite_differences(self, name):
        obj = closed_object(name, size=SIZE)
        points, _ = obj.surface_points(300, seed=3)
        step = 1e-5
        numeric = np.stack(
            [
                (obj.implicit(points + step * e) - obj.implicit(points - step * e)) / (2 * step)
                for e in np.eye(3)
            ],
            axis=-1,
        )
        analytic = obj.gradient(points)
        assert np.abs(numeric - analytic).max() < 1e-6 * np.abs(analytic).max()

    @pytest.mark.parametrize("name", CLOSED_OBJECTS)
    def test_surface_points_lie_on_the_surface(self, name):
        obj = closed_object(name, size=SIZE)
        points, normals = obj.surface_points(2000, seed=1)
        assert points.shape == normals.shape == (2000, 3)
        gradient = obj.gradient(points)
        distance = np.abs(obj.implicit(points)) / np.linalg.norm(gradient, axis=1)
        assert distance.max() < 1e-9
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(
            normals, gradient / np.linalg.norm(gradient, axis=1, keepdims=True), atol=1e-12
        )
        # Star-shaped about the origin and outward: the normal never faces the centre.
        assert (np.einsum("ij,ij->i", points, normals) > 0).all()
        again, _ = obj.surface_points(2000, seed=1)
        np.testing.assert_array_equal(points, again)

    def test_surface_points_uniform_by_area(self):
        # Share of the ellipsoid's area in the slab |x| < a / 2, from a fine marching-cubes mesh.
        from skimage.measure import marching_cubes

        obj = closed_object("ellipsoid", size=SIZE)
        step = 0.4
        grid = np.arange(-obj.radius - 1, obj.radius + 1, step)
        x, y, z = np.meshgrid(grid, grid, grid, indexing="ij")
        values = obj.implicit(np.stack([x, y, z], axis=-1))
        vertices, faces, _, _ = marching_cubes(values, 0.0, spacing=(step, step, step))
        vertices += grid[0]
        triangles = vertices[faces]
        areas = 0.5 * np.linalg.norm(
            np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1
        )
        half = 0.5 * 0.40 * SIZE
        share_mesh = areas[np.abs(triangles.mean(axis=1)[:, 0]) < half].sum() / areas.sum()
        points, _ = obj.surface_points(40000, seed=0)
        share_points = np.mean(np.abs(points[:, 0]) < half)
        assert share_points == pytest.approx(share_mesh, abs=0.01)

    def test_ellipsoid_volume_is_analytic(self):
        a, b, c = 0.40 * SIZE, 0.30 * SIZE, 0.22 * SIZE
        assert closed_object("ellipsoid", size=SIZE).volume == pytest.approx(
            4 / 3 * np.pi * a * b * c, rel=1e-14
        )

    @pytest.mark.parametrize("name", CLOSED_OBJECTS)
    def test_volume_matches_voxel_count(self, name):
        obj = closed_object(name, size=SIZE)
        step = 0.5
        grid = np.arange(-obj.radius - 1, obj.radius + 1, step) + step / 4
        x, y, z = np.meshgrid(grid, grid, grid, indexing="ij")
        counted = np.count_nonzero(obj.implicit(np.stack([x, y, z], axis=-1)) < 0) * step**3
        assert counted == pytest.approx(obj.volume, rel=2e-3)

    def test_scales_with_size(self):
        small, large = closed_object("waisted", size=64), closed_object("waisted", size=128)
        assert large.volume == pytest.approx(8 * small.volume, rel=1e-9)
        assert large.radius == pytest.approx(2 * small.radius, rel=1e-9)

    @pytest.mark.parametrize(
        "kwargs",
        [
            {"name": "cube"},
            {"name": "sphere"},
            {"name": "pebble", "size": 8},
            {"name": "pebble", "size": 64.0},
        ],
    )
    def test_bad_input(self, kwargs):
        name = kwargs.pop("name")
        with pytest.raises(InputError):
            closed_object(name, **kwargs)

    def test_bad_count(self):
        with pytest.raises(InputError, match="count"):
            closed_object("lumpy", size=SIZE).surface_points(0)


class TestRenderViews:
    def test_shapes_and_read_only(self):
        views = render_views("pebble", (0, 30), size=SIZE)
        assert len(views) == 2 and all(isinstance(v, View) for v in views)
        for view, angle in zip(views, (0.0, 30.0)):
            assert view.image.shape == view.mask.shape == view.depth.shape == (SIZE, SIZE)
            assert view.normals.shape == (SIZE, SIZE, 3) and view.pose.shape == (4, 4)
            assert view.mask.dtype == bool and view.angle == angle and view.albedo == 0.8
            assert np.isnan(view.depth[~view.mask]).all() and np.isfinite(view.depth[view.mask]).all()
            assert np.isnan(view.normals[~view.mask]).all()
            assert (view.image[~view.mask] == 0).all() and 0 <= view.image.min() <= view.image.max() <= 1
            np.testing.assert_allclose(np.linalg.norm(view.normals[view.mask], axis=1), 1.0, atol=1e-12)
            # The object fills a good part of the frame but never touches its border.
            assert 0.1 < view.mask.mean() < 0.6
            assert not (
                view.mask[0].any() or view.mask[-1].any() or view.mask[:, 0].any() or view.mask[:, -1].any()
            )
            for array in (view.image, view.mask, view.depth, view.normals, view.pose, view.light):
                assert not array.flags.writeable
        np.testing.assert_allclose(views[1].pose, turntable_pose(30))

    @pytest.mark.parametrize("name", CLOSED_OBJECTS)
    def test_depth_and_normals_agree_with_the_implicit_function(self, name):
        obj = closed_object(name, size=SIZE)
        for view in render_views(name, (0, 37, 90, 211), size=SIZE):
            points = _to_object(view, _camera_points(view))
            gradient = obj.gradient(points)
            distance = np.abs(obj.implicit(points)) / np.linalg.norm(gradient, axis=1)
            assert distance.max() < 1e-8
            rotation = view.pose[:3, :3]
            expected = gradient / np.linalg.norm(gradient, axis=1, keepdims=True) @ rotation.T
            np.testing.assert_allclose(view.normals[view.mask], expected, atol=1e-12)
            # The visible point faces the viewer: n_z >= 0 up to the silhouette.
            assert view.normals[view.mask][:, 2].min() > -1e-6

    @pytest.mark.parametrize("name", ["waisted", "lumpy"])
    def test_depth_is_the_first_crossing(self, name):
        obj = closed_object(name, size=SIZE)
        (view,) = render_views(name, (60,), size=SIZE)
        front = _camera_points(view)
        # Fine samples between the viewer and the recovered point are all outside the object.
        offsets = np.arange(0.05, 2 * obj.radius, 0.1)
        samples = front[:, None, :] + offsets[None, :, None] * np.array([0.0, 0.0, 1.0])
        assert (obj.implicit(_to_object(view, samples.reshape(-1, 3))) > 0).all()

    @pytest.mark.parametrize("name", CLOSED_OBJECTS)
    def test_opposite_views_mirror_about_the_turntable_axis(self, name):
        for angle in (0, 70):
            view, opposite = render_views(name, (angle, angle + 180), size=SIZE)
            # R_y(t + 180) = diag(-1, 1, -1) R_y(t): x -> -x, i.e. column c -> W - 1 - c.
            differ = np.count_nonzero(view.mask != opposite.mask[:, ::-1])
            assert differ <= 2

    def test_pose_equals_its_angle(self):
        by_angle = render_views("lumpy", (0, 123.0), size=SIZE, light=(0.3, 0.2, 0.9))
        by_pose = render_views(
            "lumpy", size=SIZE, light=(0.3, 0.2, 0.9), poses=[np.eye(4), turntable_pose(123.0)]
        )
        for a, b in zip(by_angle, by_pose):
            assert b.angle is None
            np.testing.assert_array_equal(a.mask, b.mask)
            np.testing.assert_allclose(a.depth, b.depth, atol=1e-9)
            np.testing.assert_allclose(a.normals, b.normals, atol=1e-9)
            np.testing.assert_allclose(a.image, b.image, atol=1e-9)
            np.testing.assert_allclose(a.pose, b.pose, atol=1e-15)

    def test_turntable_convention(self):
        # At 90 degrees the ellipsoid's long x axis lies along the view: the view is its
        # 0.22 x 0.30 cross-section; its +x end points away from the viewer, its -x end toward.
        np.testing.assert_allclose(turntable_pose(90)[:3, :3] @ [1, 0, 0], [0, 0, -1], atol=1e-15)
        (view,) = render_views("ellipsoid", (90,), size=SIZE)
        columns = np.nonzero(view.mask.any(axis=0))[0]
        rows = np.nonzero(view.mask.any(axis=1))[0]
        assert columns.size == pytest.approx(2 * 0.22 * SIZE, abs=1.5)
        assert rows.size == pytest.approx(2 * 0.30 * SIZE, abs=1.5)
        assert np.nanmax(view.depth) == pytest.approx(0.40 * SIZE, abs=0.05)
        nearest = _to_object(view, _camera_points(view))[np.nanargmax(view.depth[view.mask])]
        np.testing.assert_allclose(nearest, [-0.40 * SIZE, 0, 0], atol=0.5)

    def test_any_rigid_pose(self):
        angle = np.radians(40)
        pose = np.eye(4)
        pose[:3, :3] = [[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]]
        pose[:3, 3] = [3.0, -2.0, 5.0]
        obj = closed_object("waisted", size=SIZE)
        (view,) = render_views("waisted", size=SIZE, poses=[pose])
        points = _to_object(view, _camera_points(view))
        assert (np.abs(obj.implicit(points)) / np.linalg.norm(obj.gradient(points), axis=1)).max() < 1e-8
        # The waisted object turns about its x axis, so its silhouette stays centred on the
        # translated origin: x = 3 is 3 columns right, y = -2 is 2 rows down.
        rows, cols = np.nonzero(view.mask)
        assert cols.mean() - (SIZE - 1) / 2 == pytest.approx(3.0, abs=0.1)
        assert rows.mean() - (SIZE - 1) / 2 == pytest.approx(2.0, abs=0.1)

    def test_lambertian_image_on_a_convex_object(self):
        # A convex object casts no shadow on itself: the image is albedo * max(0, n . l).
        light = np.array([0.7, -0.4, 0.5])
        (view,) = render_views("ellipsoid", (25,), size=SIZE, light=light, albedo=0.9)
        light = light / np.linalg.norm(light)
        np.testing.assert_allclose(view.light, light)
        expected = 0.9 * np.maximum(view.normals[view.mask] @ light, 0)
        np.testing.assert_allclose(view.image[view.mask], expected, atol=1e-12)

    def test_light_from_the_camera_by_default(self):
        (view,) = render_views("lumpy", (0,), size=SIZE)
        np.testing.assert_allclose(
            view.image[view.mask], 0.8 * np.maximum(view.normals[view.mask][:, 2], 0), atol=1e-12
        )

    def test_cast_shadow_on_the_waist(self):
        # Light grazing from the right: the right sphere shadows the left one next to the waist.
        size = 96
        obj = closed_object("waisted", size=size)
        light = np.array([1.0, 0.0, 0.3])
        (view,) = render_views("waisted", (0,), size=size, light=light)
        shading = view.normals[view.mask] @ view.light
        shadowed = (shading > 0.05) & (view.image[view.mask] == 0)
        assert shadowed.sum() > 20
        points = _camera_points(view)
        assert (points[shadowed, 0] < 0.02 * size).all()  # on the left lobe and the waist
        # Independent check: fine samples toward the light from shadowed points enter the object,
        # and from lit points they do not.
        offsets = np.arange(0.2, 2 * obj.radius, 0.05)

        def blocked(q):
            samples = q[:, None, :] + offsets[None, :, None] * view.light
            return (obj.implicit(_to_object(view, samples.reshape(-1, 3))).reshape(len(q), -1) < 0).any(
                axis=1
            )

        assert blocked(points[shadowed]).all()
        lit = view.image[view.mask] > 0
        assert not blocked(points[lit][::5]).any()

    def test_light_from_behind(self):
        # Any light is allowed; from behind, only the rim of the silhouette is lit.
        (view,) = render_views("ellipsoid", (0,), size=SIZE, light=(1.0, 0.0, -0.5))
        assert 0 < np.count_nonzero(view.image) < 0.3 * np.count_nonzero(view.mask)

    @pytest.mark.parametrize(
        "kwargs",
        [
            {"name": "cube"},
            {"angles": ()},
            {"angles": (0, float("nan"))},
            {"angles": ("north",)},
            {"poses": [np.diag([2.0, 1, 1, 1])]},
            {"poses": [np.eye(3)]},
            {"poses": [np.diag([-1.0, 1, 1, 1])]},
            {"poses": [np.eye(4)], "angles": (0,)},
            {"light": (0, 0, 0)},
            {"light": (1, 2)},
            {"albedo": 0},
            {"size": 10},
        ],
    )
    def test_bad_input(self, kwargs):
        name = kwargs.pop("name", "pebble")
        kwargs.setdefault("size", 16)
        with pytest.raises(InputError):
            render_views(name, **kwargs)


class TestChamfer:
    def test_identical_sets(self):
        points = _sphere_points(500, 10.0)
        assert chamfer(points, points) == 0.0
        assert chamfer(points, points, translate=False) == 0.0

    def test_shift_is_free_with_translation(self):
        lattice = 10.0 * np.stack(np.meshgrid(*[np.arange(5.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
        shift = np.array([1.0, -2.0, 2.0])  # |shift| = 3 < half the spacing: counterparts are nearest
        diagonal = np.sqrt(3) * 40
        assert chamfer(lattice + shift, lattice) == pytest.approx(0.0, abs=1e-9)
        assert chamfer(lattice + shift, lattice, translate=False) == pytest.approx(100 * 3 / diagonal)

    def test_scale_change(self):
        truth = _sphere_points(4000, 50.0)
        scaled = 1.02 * truth
        diagonal = np.linalg.norm(truth.max(axis=0) - truth.min(axis=0))
        # Each point's nearest neighbour is its counterpart, the radial gap 0.02 * 50 = 1 away.
        expected = 100 * 1.0 / diagonal
        assert chamfer(scaled, truth, translate=False) == pytest.approx(expected, rel=1e-9)
        assert chamfer(scaled, truth) == pytest.approx(expected, rel=1e-6)  # no shift helps

    def test_recovers_a_shift_of_a_sampled_surface(self):
        obj = closed_object("lumpy", size=SIZE)
        truth, _ = obj.surface_points(6000, seed=0)
        estimate, _ = obj.surface_points(3000, seed=1)
        assert chamfer(estimate + [4.0, 1.0, -3.0], truth) == pytest.approx(
            chamfer(estimate, truth, translate=False), abs=0.05
        )

    @pytest.mark.parametrize(
        "points, truth",
        [
            (np.zeros((0, 3)), np.ones((4, 3))),
            (np.zeros((4, 2)), np.eye(3)),
            (np.full((4, 3), np.nan), np.eye(3)),
            (np.eye(3), np.ones((4, 3))),
        ],
    )
    def test_bad_input(self, points, truth):
        with pytest.raises(InputError):
            chamfer(points, truth)


class TestFScore:
    def test_identical_sets(self):
        points = _sphere_points(500, 10.0)
        assert f_score(points, points) == 100.0

    def test_shift(self):
        lattice = 10.0 * np.stack(np.meshgrid(*[np.arange(5.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
        shifted = lattice + [1.0, -2.0, 2.0]  # 3 away; the diagonal is 69.3, 1 % of it 0.69
        assert f_score(shifted, lattice) == pytest.approx(100.0)
        assert f_score(shifted, lattice, translate=False) == 0.0
        assert f_score(shifted, lattice, threshold=0.05, translate=False) == 100.0

    def test_scale_change(self):
        truth = _sphere_points(20000, 50.0)
        # 1 % of the diagonal (~173) is ~1.73: a radial gap of 1 is within it, one of 2.5 is not.
        assert f_score(1.02 * truth, truth) == pytest.approx(100.0)
        assert f_score(1.05 * truth, truth) == 0.0

    def test_half_the_points_far(self):
        truth = _sphere_points(2000, 50.0)
        estimate = np.concatenate([truth, 1.5 * truth])  # precision 1/2, recall 1 -> F = 2/3
        assert f_score(estimate, truth, translate=False) == pytest.approx(100 * 2 / 3)

    @pytest.mark.parametrize("threshold", [0, -0.1, float("nan"), "1%", True])
    def test_bad_threshold(self, threshold):
        points = _sphere_points(50, 1.0)
        with pytest.raises(InputError, match="threshold"):
            f_score(points, points, threshold=threshold)


class TestVolumeError:
    def test_numbers(self):
        assert volume_error(100.0, 100.0) == 0.0
        assert volume_error(90.0, 100.0) == pytest.approx(10.0)
        assert volume_error(90.0, 100.0, signed=True) == pytest.approx(-10.0)

    def test_meshes(self):
        sphere = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
        assert volume_error(sphere, sphere.volume) == pytest.approx(0.0, abs=1e-9)
        mesh = Mesh(sphere.vertices * 1.1, sphere.faces, sphere.vertex_normals)
        assert volume_error(mesh, sphere.volume, signed=True) == pytest.approx(33.1)
        inverted = Mesh(sphere.vertices, sphere.faces[:, ::-1], -sphere.vertex_normals)
        assert volume_error(inverted, sphere.volume) == pytest.approx(0.0, abs=1e-9)

    def test_against_a_closed_object(self):
        obj = closed_object("ellipsoid", size=SIZE)
        ellipsoid = trimesh.creation.icosphere(subdivisions=5)
        ellipsoid.apply_scale([0.40 * SIZE, 0.30 * SIZE, 0.22 * SIZE])
        assert volume_error(ellipsoid, obj.volume) < 0.2  # the inscribed polyhedron is a bit smaller

    def test_open_or_miswound_mesh(self):
        sphere = trimesh.creation.icosphere(subdivisions=1)
        with pytest.raises(InputError, match="not closed"):
            volume_error(Mesh(sphere.vertices, sphere.faces[1:], sphere.vertex_normals), 1.0)
        faces = sphere.faces.copy()
        faces[0] = faces[0, ::-1]
        with pytest.raises(InputError, match="wound"):
            volume_error(Mesh(sphere.vertices, faces, sphere.vertex_normals), 1.0)

    @pytest.mark.parametrize(
        "value, truth", [(1.0, 0.0), (1.0, -2.0), (float("nan"), 1.0), ("big", 1.0), (0.0, 1.0)]
    )
    def test_bad_numbers(self, value, truth):
        with pytest.raises(InputError):
            volume_error(value, truth)
