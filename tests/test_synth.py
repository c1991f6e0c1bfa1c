"""Synthetic scenes: the analytic ground truth every accuracy bar is measured with."""

from __future__ import annotations

import numpy as np
import pytest

from shadeform.errors import InputError
from shadeform.synth import SCENES, Scene, render, scene, surface

SIZE = 96


def _central_difference_errors(depth, normals, step):
    """Central differences of ``depth`` minus the analytic slopes, along columns and rows.

    With ``y = -row``: ``dz/dcol = -n_x / n_z`` and ``dz/drow = +n_y / n_z``.
    """
    slope_col = -normals[..., 0] / normals[..., 2]
    slope_row = normals[..., 1] / normals[..., 2]
    k = step
    err_col = np.full(depth.shape, np.nan)
    err_row = np.full(depth.shape, np.nan)
    err_col[:, k:-k] = (depth[:, 2 * k :] - depth[:, : -2 * k]) / (2 * k) - slope_col[:, k:-k]
    err_row[k:-k] = (depth[2 * k :] - depth[: -2 * k]) / (2 * k) - slope_row[k:-k]
    return err_col, err_row


def _convex_cap(size):
    """The bowl's convex twin, written out independently: z = sqrt(R^2 - r^2) - rim height."""
    c = np.arange(size) - (size - 1) / 2
    x, y = c[None, :], -c[:, None]
    rim = 0.42 * size
    radius = rim / 0.9
    w = np.sqrt(np.clip(radius**2 - x**2 - y**2, 0, None))
    depth = w - np.sqrt(radius**2 - rim**2)
    normals = np.stack(np.broadcast_arrays(x / radius, y / radius, w / radius), axis=-1)
    return depth, normals


class TestSurface:
    @pytest.mark.parametrize("name", SCENES)
    def test_smoke(self, name):
        depth, normals, mask = surface(name, size=32)
        assert mask.any()

    @pytest.mark.parametrize("name", SCENES)
    def test_shapes_and_nan_outside(self, name):
        depth, normals, mask = surface(name, size=SIZE)
        assert depth.shape == (SIZE, SIZE) and depth.dtype == np.float64
        assert normals.shape == (SIZE, SIZE, 3) and normals.dtype == np.float64
        assert mask.shape == (SIZE, SIZE) and mask.dtype == bool
        assert np.isfinite(depth[mask]).all() and np.isnan(depth[~mask]).all()
        assert np.isfinite(normals[mask]).all() and np.isnan(normals[~mask]).all()
        # The object fills most of the frame but does not touch its border.
        assert 0.25 < mask.mean() < 0.9
        assert not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())

    @pytest.mark.parametrize("name", SCENES)
    def test_normals_unit_and_facing_viewer(self, name):
        _, normals, mask = surface(name, size=SIZE)
        n = normals[mask]
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
        assert (n[:, 2] > 0).all()

    @pytest.mark.parametrize("name", SCENES)
    def test_depth_normals_consistent_second_order(self, name):
        depth, normals, mask = surface(name, size=128)
        e1_col, e1_row = _central_difference_errors(depth, normals, 1)
        e2_col, e2_row = _central_difference_errors(depth, normals, 2)
        # Away from the silhouette, where slopes stay below ~3.
        inner = np.isfinite(e2_col) & np.isfinite(e2_row) & (np.nan_to_num(normals[..., 2]) > 0.3)
        assert inner.sum() > 0.3 * mask.sum()
        for e1, e2 in ((e1_col, e2_col), (e1_row, e2_row)):
            assert np.abs(e1[inner]).max() < 0.1
            assert np.abs(e1[inner]).mean() < 0.01
            # Second order: doubling the step multiplies the truncation error by 4, pointwise.
            big = inner & (np.abs(e1) > 1e-7)
            if big.sum() > 20:
                ratio = e2[big] / e1[big]
                assert abs(np.median(ratio) - 4.0) < 0.05
                assert np.mean(np.abs(ratio - 4.0) < 0.5) > 0.9
            else:  # the stencil is exact (a quadratic) or the slope is constant
                assert np.abs(e1[inner]).max() < 1e-9

    def test_sphere_values(self):
        depth, normals, mask = surface("sphere", size=SIZE)
        radius = 0.42 * SIZE
        c = np.arange(SIZE) - (SIZE - 1) / 2
        x, y = np.meshgrid(c, -c)
        np.testing.assert_array_equal(mask, x**2 + y**2 < radius**2)
        np.testing.assert_allclose(depth[mask], np.sqrt((radius**2 - x**2 - y**2)[mask]))
        # Pixel (row 0 side) is up: y > 0 on the upper half means n_y > 0 there.
        assert (normals[: SIZE // 2][mask[: SIZE // 2]][:, 1] > 0).all()
        assert (normals[:, SIZE // 2 :][mask[:, SIZE // 2 :]][:, 0] > 0).all()
        np.testing.assert_allclose(normals[..., 0][mask], x[mask] / radius)

    def test_ellipsoid_semi_axes(self):
        depth, _, mask = surface("ellipsoid", size=200)
        cols = np.flatnonzero(mask.any(axis=0))
        rows = np.flatnonzero(mask.any(axis=1))
        assert abs((cols[-1] - cols[0] + 1) - 2 * 0.45 * 200) <= 2
        assert abs((rows[-1] - rows[0] + 1) - 2 * 0.30 * 200) <= 2
        assert abs(np.nanmax(depth) - 0.25 * 200) < 0.1

    def test_cylinder_has_no_y_slope(self):
        depth, normals, mask = surface("cylinder", size=SIZE)
        assert np.all(normals[..., 1][mask] == 0)
        column = depth[:, SIZE // 2][mask[:, SIZE // 2]]
        np.testing.assert_allclose(column, column[0])

    def test_vase_profile(self):
        # Zhang et al. (1999): f(u) = 0.15 - 0.1 u (6u+1)^2 (u-1)^2 (3u-2), u in [0, 1].
        size = 400
        depth, _, mask = surface("vase", size=size)
        height = 0.9 * size
        c = np.arange(size) - (size - 1) / 2
        u = -c / height + 0.5  # per row, bottom = 0
        f = 0.15 - 0.1 * u * (6 * u + 1) ** 2 * (u - 1) ** 2 * (3 * u - 2)
        inside = (u > 0) & (u < 1)
        assert (f[inside] > 0.1).all()  # positive on the whole domain
        radius, x = np.meshgrid(height * f, c, indexing="ij")
        expected = np.sqrt(radius[mask] ** 2 - x[mask] ** 2)
        np.testing.assert_allclose(depth[mask], expected, rtol=1e-9, atol=1e-9)
        widths = mask.sum(axis=1)
        np.testing.assert_allclose(widths[inside], 2 * height * f[inside], atol=2.0)
        assert np.all(widths[~inside] == 0)
        # A vase: belly low (u ~ 0.37), neck high (u ~ 0.81), lip flaring out above the neck.
        rows = np.flatnonzero(inside)
        belly = rows[np.argmax(widths[rows])]
        neck_rows = rows[u[rows] > 0.5]
        neck = neck_rows[np.argmin(widths[neck_rows])]
        assert abs(u[belly] - 0.366) < 0.03 and abs(u[neck] - 0.808) < 0.02  # flat extrema
        assert widths[belly] > 2.5 * widths[neck]
        assert widths[rows[0]] > widths[neck] and widths[rows[-1]] > widths[neck]

    def test_bowl_rim_not_vertical(self):
        depth, normals, mask = surface("bowl", size=SIZE)
        nz = normals[..., 2][mask]
        assert 0.43 < nz.min() < 0.45
        assert abs(nz.max() - 1.0) < 1e-3
        # Concave: the centre is the farthest point, the rim is at z = 0.
        assert depth[SIZE // 2, SIZE // 2] == pytest.approx(np.nanmin(depth), abs=0.05)
        assert np.nanmax(depth) <= 0 and np.nanmax(depth) > -0.5

    def test_bowl_is_negated_convex_cap(self):
        depth, normals, mask = surface("bowl", size=SIZE)
        depth_convex, normals_convex = _convex_cap(SIZE)
        np.testing.assert_allclose(depth[mask], -depth_convex[mask], atol=1e-9)
        np.testing.assert_allclose(normals[..., 2][mask], normals_convex[..., 2][mask])
        np.testing.assert_allclose(normals[..., :2][mask], -normals_convex[..., :2][mask])

    def test_saddle_values(self):
        depth, normals, mask = surface("saddle", size=SIZE)
        s = 0.42 * SIZE / 1.5
        c = np.arange(SIZE) - (SIZE - 1) / 2
        x, y = np.meshgrid(c, -c)
        np.testing.assert_allclose(depth[mask], ((x**2 - y**2) / (2 * s))[mask])
        slope = np.hypot(normals[..., 0], normals[..., 1]) / normals[..., 2]
        assert 1.4 < np.nanmax(slope) <= 1.5

    def test_bumps_flat_base_and_dent(self):
        depth, normals, mask = surface("bumps", size=SIZE)
        assert np.nanmax(depth) > 0.08 * SIZE and np.nanmin(depth) < -0.05 * SIZE
        # Far from every bump the base is flat: normals along +z (the 2002 method's hard case).
        assert np.nanmax(normals[..., 2]) > 1 - 1e-6
        slope = np.hypot(normals[..., 0], normals[..., 1]) / normals[..., 2]
        assert np.nanmax(slope) < 1.5

    def test_deterministic(self):
        a = surface("bumps", size=48)
        b = surface("bumps", size=48)
        for u, v in zip(a, b):
            np.testing.assert_array_equal(u, v)

    def test_odd_size_is_centred(self):
        depth, _, mask = surface("sphere", size=33)
        np.testing.assert_array_equal(mask, mask[::-1])
        np.testing.assert_array_equal(mask, mask[:, ::-1])
        assert np.nanargmax(depth) == 16 * 33 + 16

    @pytest.mark.parametrize("name", ["cube", "Sphere", ""])
    def test_unknown_name(self, name):
        with pytest.raises(InputError, match="sphere, ellipsoid, cylinder"):
            surface(name)

    @pytest.mark.parametrize("size", [8, 15, 0, -3, 32.0, True, "64"])
    def test_bad_size(self, size):
        with pytest.raises(InputError, match="size must be a whole number from 16"):
            surface("sphere", size=size)


class TestRender:
    def test_smoke(self):
        _, normals, mask = surface("sphere", size=32)
        image = render(normals, mask)
        assert image.shape == (32, 32) and image.dtype == np.float64

    def test_frontal_light_gives_nz_exactly(self):
        _, normals, mask = surface("sphere", size=SIZE)
        image = render(normals, mask)
        np.testing.assert_array_equal(image[mask], normals[..., 2][mask])
        assert np.all(image[~mask] == 0)

    def test_albedo_and_light_normalised(self):
        _, normals, mask = surface("ellipsoid", size=SIZE)
        image = render(normals, mask, light=(0, 0, 5), albedo=0.5)
        np.testing.assert_allclose(image[mask], 0.5 * normals[..., 2][mask], atol=1e-15)

    def test_oblique_light_attached_shadows(self):
        _, normals, mask = surface("sphere", size=SIZE)
        slant, tilt = np.radians(60), np.radians(30)
        light = np.array([np.sin(slant) * np.cos(tilt), np.sin(slant) * np.sin(tilt), np.cos(slant)])
        image = render(normals, mask, light=light)
        dot = normals @ light
        shadow = mask & (dot < 0)
        lit = mask & (dot > 0)
        assert shadow.sum() > 50
        assert np.all(image[shadow] == 0)
        np.testing.assert_allclose(image[lit], dot[lit], atol=1e-15)
        # The light comes from the upper right (tilt from +x toward +y, y up): the brightest
        # pixel is in the upper-right quadrant of the image.
        r, c = np.unravel_index(np.argmax(image), image.shape)
        assert r < SIZE // 2 and c > SIZE // 2

    def test_noise_deterministic_and_clipped(self):
        _, normals, mask = surface("sphere", size=SIZE)
        clean = render(normals, mask)
        a = render(normals, mask, noise=0.05, seed=3)
        b = render(normals, mask, noise=0.05, seed=3)
        c = render(normals, mask, noise=0.05, seed=4)
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, c)
        assert a.min() >= 0 and a.max() <= 1 and a.max() == 1.0
        assert np.all(a[~mask] == 0)
        residual = (a - clean)[mask & (clean > 0.2) & (clean < 0.8)]
        assert abs(residual.std() - 0.05) < 0.005 and abs(residual.mean()) < 0.005

    def test_noise_scales_with_albedo(self):
        _, normals, mask = surface("cylinder", size=SIZE)
        clean = render(normals, mask, albedo=0.5)
        noisy = render(normals, mask, albedo=0.5, noise=0.04, seed=1)
        residual = (noisy - clean)[mask & (clean > 0.1)]
        assert abs(residual.std() - 0.02) < 0.002

    @pytest.mark.parametrize("light", [(0, 0, -1), (1, 0, 0), (0.5, 0.5, -0.1)])
    def test_light_behind_rejected(self, light):
        _, normals, mask = surface("sphere", size=32)
        with pytest.raises(InputError, match="z > 0"):
            render(normals, mask, light=light)

    @pytest.mark.parametrize("light", [(0, 1), (0, 0, np.nan), "up"])
    def test_malformed_light_rejected(self, light):
        _, normals, mask = surface("sphere", size=32)
        with pytest.raises(InputError, match="light must be 3 finite numbers"):
            render(normals, mask, light=light)

    def test_bad_inputs(self):
        _, normals, mask = surface("sphere", size=32)
        with pytest.raises(InputError, match=r"\(H, W, 3\)"):
            render(normals[..., :2], mask)
        with pytest.raises(InputError, match="does not match"):
            render(normals, mask[1:])
        with pytest.raises(InputError, match="NaN"):
            render(normals, np.ones_like(mask))
        with pytest.raises(InputError, match="albedo"):
            render(normals, mask, albedo=0)
        with pytest.raises(InputError, match="noise"):
            render(normals, mask, noise=-0.1)


class TestScene:
    @pytest.mark.parametrize("name", SCENES)
    def test_smoke(self, name):
        s = scene(name, size=32)
        assert isinstance(s, Scene) and s.name == name

    def test_shapes_and_fields(self):
        s = scene("vase", size=SIZE, light=(1, 1, 2), albedo=0.8)
        assert s.image.shape == s.mask.shape == s.depth.shape == (SIZE, SIZE)
        assert s.normals.shape == (SIZE, SIZE, 3)
        np.testing.assert_allclose(s.light, np.array([1, 1, 2]) / np.sqrt(6))
        assert s.albedo == 0.8 and isinstance(s.albedo, float)
        np.testing.assert_array_equal(s.image, render(s.normals, s.mask, light=(1, 1, 2), albedo=0.8))

    def test_matches_surface(self):
        s = scene("saddle", size=SIZE)
        depth, normals, mask = surface("saddle", size=SIZE)
        np.testing.assert_array_equal(s.mask, mask)
        np.testing.assert_array_equal(s.depth, depth)
        np.testing.assert_array_equal(s.normals, normals)

    def test_ground_truth_read_only(self):
        s = scene("sphere", size=32)
        with pytest.raises(ValueError):
            s.depth[16, 16] = 0.0
        with pytest.raises(ValueError):
            s.image[0, 0] = 1.0

    def test_concave_convex_ambiguity(self):
        bowl = scene("bowl", size=SIZE)
        depth_convex, normals_convex = _convex_cap(SIZE)
        image_convex = render(normals_convex, bowl.mask)
        # Indistinguishable under a frontal light ...
        np.testing.assert_allclose(bowl.image, image_convex, atol=1e-15)
        # ... but opposite depths, and an oblique light tells them apart.
        m = bowl.mask
        np.testing.assert_allclose(bowl.depth[m], -depth_convex[m], atol=1e-9)
        assert np.nanmax(bowl.depth) <= 0 < np.max(depth_convex[m])
        oblique = (0.5, 0.0, 1.0)
        assert (
            np.abs(render(bowl.normals, m, light=oblique) - render(normals_convex, m, light=oblique)).max()
            > 0.3
        )

    def test_noise_seed(self):
        a = scene("bumps", size=48, noise=0.02, seed=7)
        b = scene("bumps", size=48, noise=0.02, seed=7)
        np.testing.assert_array_equal(a.image, b.image)

    def test_errors(self):
        with pytest.raises(InputError, match="unknown scene 'teapot'; choose one of: sphere"):
            scene("teapot")
        with pytest.raises(InputError, match="size"):
            scene("sphere", size=12)
        with pytest.raises(InputError, match="z > 0"):
            scene("sphere", light=(0, 0, -1))
