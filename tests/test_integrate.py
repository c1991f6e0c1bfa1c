"""Depth from normals: path averaging (2002) and masked least squares."""

import numpy as np
import pytest

from helpers.surfaces import l_shaped_mask, normals_of, pixel_xy
from shadeform import synth
from shadeform.errors import InputError
from shadeform.integration import integrate
from shadeform.integration.paths import integrate_paths, integrate_paths_reference
from shadeform.integration.poisson import integrate_poisson


class TestIntegratePaths:
    def test_plane_is_exact_on_a_nonconvex_mask(self):
        mask = l_shaped_mask()
        x, y = pixel_xy(mask.shape)
        truth = 0.3 * x - 0.7 * y
        n = normals_of(np.full(mask.shape, 0.3), np.full(mask.shape, -0.7))
        z = integrate_paths(n, mask, origin=(5, 5))
        np.testing.assert_allclose(z[mask], (truth - truth[5, 5])[mask], atol=1e-10)
        assert np.isnan(z[~mask]).all()

    def test_paraboloid_is_exact_with_the_trapezoid_rule(self):
        mask = l_shaped_mask()
        x, y = pixel_xy(mask.shape)
        truth = 0.01 * x**2 + 0.02 * y**2 - 0.005 * x * y  # slopes are linear: trapezoid is exact
        zx, zy = 0.02 * x - 0.005 * y, 0.04 * y - 0.005 * x
        z = integrate_paths(normals_of(zx, zy), mask, origin=(24, 20))
        np.testing.assert_allclose(z[mask], (truth - truth[24, 20])[mask], atol=1e-9)

    def test_origin_is_zero_and_disconnected_parts_nan(self):
        mask = np.zeros((10, 10), bool)
        mask[1:4, 1:4] = True
        mask[6:9, 6:9] = True
        n = normals_of(np.full(mask.shape, 0.1), np.zeros(mask.shape))
        z = integrate_paths(n, mask, origin=(2, 2))
        assert z[2, 2] == 0 and np.isnan(z[6:9, 6:9]).all()

    def test_compiled_matches_reference(self):
        scene = synth.scene("vase", size=48)
        origin = np.unravel_index(np.nanargmax(scene.normals[..., 2]), scene.mask.shape)
        fast = integrate_paths(scene.normals, scene.mask, origin=origin)
        slow = integrate_paths_reference(scene.normals, scene.mask, origin=origin)
        np.testing.assert_array_equal(np.isnan(fast), np.isnan(slow))
        np.testing.assert_allclose(fast[scene.mask], slow[scene.mask], atol=1e-12)


class TestIntegratePoisson:
    def test_paraboloid_matches_truth(self):
        mask = l_shaped_mask()
        x, y = pixel_xy(mask.shape)
        truth = 0.01 * x**2 + 0.02 * y**2
        z = integrate_poisson(normals_of(0.02 * x, 0.04 * y), mask, origin=(24, 20))
        np.testing.assert_allclose(z[mask], (truth - truth[24, 20])[mask], atol=1e-4)  # CG tolerance

    def test_agrees_with_paths_on_an_integrable_field(self):
        scene = synth.scene("sphere", size=64)
        inner = scene.mask & (scene.normals[..., 2] > 0.3)
        a = integrate_poisson(scene.normals, inner, origin=(32, 32))
        b = integrate_paths(scene.normals, inner, origin=(32, 32))
        assert np.nanmax(np.abs(a - b)) < 0.05 * np.nanmax(np.abs(b))

    def test_weights_move_the_solution_toward_trusted_pixels(self):
        # an inconsistent field: the top half says slope +1, the bottom half slope -1 along y;
        # heavy weights on the top half make its slope win
        mask = np.ones((20, 20), bool)
        zy = np.where(np.arange(20)[:, None] < 10, 1.0, -1.0) * np.ones((20, 20))
        n = normals_of(np.zeros((20, 20)), zy)
        w = np.where(np.arange(20)[:, None] < 10, 100.0, 1.0) * np.ones((20, 20))
        z = integrate_poisson(n, mask, weights=w)
        assert z[2, 5] - z[8, 5] == pytest.approx(6.0, rel=1e-3)


class TestIntegrate:
    def test_dispatch_and_default_origin(self):
        scene = synth.scene("sphere", size=32)
        for integrator in ("paths", "poisson"):
            z = integrate(scene.normals, scene.mask, integrator=integrator)
            assert np.isfinite(z[scene.mask]).all() and np.isnan(z[~scene.mask]).all()

    def test_the_old_keyword_method_warns_and_gives_the_same_depth(self):
        scene = synth.scene("sphere", size=32)
        new = integrate(scene.normals, scene.mask, integrator="poisson")
        with pytest.warns(DeprecationWarning, match="integrator="):
            old = integrate(scene.normals, scene.mask, method="poisson")
        np.testing.assert_array_equal(old, new)
        with pytest.raises(TypeError, match="both method= and integrator="):
            integrate(scene.normals, scene.mask, integrator="fourier", method="poisson")

    def test_errors(self):
        scene = synth.scene("sphere", size=32)
        with pytest.raises(InputError, match="unknown integrator 'magic'"):
            integrate(scene.normals, scene.mask, integrator="magic")
        with pytest.raises(InputError, match="not on the mask"):
            integrate(scene.normals, scene.mask, origin=(0, 0))
        with pytest.raises(InputError, match=r"\(H, W, 3\)"):
            integrate(scene.normals[..., :2], scene.mask)
        bad = scene.normals.copy()
        bad[16, 16] = np.nan
        with pytest.raises(InputError, match="NaN"):
            integrate(bad, scene.mask)


class TestPublicIntegrate:
    def test_top_level_name_and_every_integrator(self):
        import shadeform

        scene = synth.scene("sphere", size=48)
        inner = scene.mask & (scene.normals[..., 2] > 0.3)
        for integrator in ("paths", "poisson", "bilateral"):
            z = shadeform.integrate(scene.normals, inner, integrator=integrator, origin=(24, 24))
            assert z[24, 24] == pytest.approx(0, abs=1e-9)
            truth = scene.depth - scene.depth[24, 24]
            assert np.nanmax(np.abs(z - truth)[inner]) < 0.05 * np.ptp(truth[inner]), integrator

    def test_perspective_needs_bilateral(self):
        scene = synth.scene("sphere", size=32)
        K = np.array([[100.0, 0, 16], [0, 100.0, 16], [0, 0, 1]])
        with pytest.raises(InputError, match="needs integrator='bilateral'"):
            integrate(scene.normals, scene.mask, integrator="poisson", K=K)


class TestIntegrateFourier:
    def test_equals_least_squares_on_a_full_rectangle(self):
        from shadeform.integration.fourier import integrate_fourier

        rng = np.random.default_rng(4)
        mask = np.ones((37, 52), bool)
        # a non-integrable field: the two least-squares solutions must still agree
        n = normals_of(rng.normal(0, 0.5, mask.shape), rng.normal(0, 0.5, mask.shape))
        a = integrate_fourier(n, mask)
        b = integrate_poisson(n, mask)
        np.testing.assert_allclose(a - a.mean(), b - b.mean(), atol=1e-6)

    def test_fused_divergence_equals_reference(self):
        """A kernel against its reference (private names, deliberately): the fused
        ``fourier._divergence`` is ``_divergence_reference``, with the slopes' own floor on n_z
        (``_slopes.MIN_NZ``)."""
        from shadeform.integration._slopes import MIN_NZ
        from shadeform.integration.fourier import _divergence, _divergence_reference

        rng = np.random.default_rng(7)
        normals = rng.normal(size=(23, 31, 3))
        normals[..., 2] = np.abs(normals[..., 2])  # some below MIN_NZ after normalising
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
        normals[3, 4] = np.nan  # NaN slopes count as flat, as in slopes()
        normals[5, 6, 2] = np.nan
        mask = rng.random((23, 31)) > 0.3
        np.testing.assert_allclose(
            _divergence(normals, mask, MIN_NZ), _divergence_reference(normals, mask), atol=1e-12
        )

    def test_paraboloid_on_a_box_inside_the_image(self):
        mask = np.zeros((40, 50), bool)
        mask[5:30, 8:45] = True
        x, y = pixel_xy(mask.shape)
        truth = 0.01 * x**2 - 0.02 * y**2 + 0.003 * x * y
        zx, zy = 0.02 * x + 0.003 * y, -0.04 * y + 0.003 * x
        z = integrate(normals_of(zx, zy), mask, integrator="fourier", origin=(10, 10))
        np.testing.assert_allclose(z[mask], (truth - truth[10, 10])[mask], atol=1e-8)
        assert np.isnan(z[~mask]).all()
