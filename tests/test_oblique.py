"""The oblique-light solver: accuracy bars, kernels against their references, shadows, bad input."""

import numpy as np
import pytest

from shadeform import metrics, reconstruct, synth
from shadeform.errors import InputError
from shadeform.light import light_from_slant_tilt
from shadeform.regions import concave_masks, parse_regions
from shadeform.solvers.oblique import (
    _Descent,
    cone_sweep,
    cone_sweep_reference,
    fill_shadow_normals,
    march_cone,
    march_cone_reference,
    oblique_depth,
)

LIGHT = (5.0, 5.0, 7.0)
SIZE = 128


def errors(rec, scene):
    """The two numbers of ``shadeform evaluate``: depth % (offset fitted) and mean angle."""
    return (metrics.depth_error(rec.depth, scene.depth, fit="offset"),
            metrics.angular_error(rec.normals, scene.normals))


class TestBars:
    """The issue's bars at the light (5, 5, 7), noise-free, at 128 px (256 px: the benchmark)."""

    def test_sphere(self):
        scene = synth.scene("sphere", size=SIZE, light=LIGHT)
        rec = reconstruct(scene.image, mask=scene.mask, light=scene.light, method="oblique")
        depth, angle = errors(rec, scene)
        assert depth <= 3.0
        assert angle <= 4.0

    def test_vase_normals_with_its_neck_marked(self):
        scene = synth.scene("vase", size=SIZE, light=LIGHT)
        rec = reconstruct(scene.image, mask=scene.mask, light=scene.light, method="oblique",
                          concave=synth.concave_regions("vase", size=SIZE))
        _, angle = errors(rec, scene)
        assert angle <= 6.0

    @pytest.mark.xfail(strict=True, reason="known: the neck above the saddle comes out in the wrong "
                       "basin (about 9 % at 128 px, 6.3 % at 256 px); see benchmarks/results/oblique.md")
    def test_vase_depth_with_its_neck_marked(self):
        scene = synth.scene("vase", size=SIZE, light=LIGHT)
        rec = reconstruct(scene.image, mask=scene.mask, light=scene.light, method="oblique",
                          concave=synth.concave_regions("vase", size=SIZE))
        depth, _ = errors(rec, scene)
        assert depth <= 4.0

    def test_light_at_plus_z(self):
        scene = synth.scene("sphere", size=64)
        rec = reconstruct(scene.image, mask=scene.mask, method="oblique")
        depth, angle = errors(rec, scene)
        assert depth < 1.0 and angle < 1.0
        assert rec.info["method"] == "oblique" and rec.info["shadowed"] == 0

    def test_another_integrator_can_give_the_depth(self):
        scene = synth.scene("sphere", size=64, light=LIGHT)
        rec = reconstruct(scene.image, mask=scene.mask, light=scene.light, method="oblique",
                          integrator="poisson")
        assert rec.info["integrator"] == "poisson"
        assert errors(rec, scene)[0] < 3.0


class TestShadows:
    def test_shadow_is_a_constraint_not_a_cliff(self):
        """A crescent in attached shadow continues the sphere: no wall, and N . L <= 0 there."""
        light = light_from_slant_tilt(60, 200)
        scene = synth.scene("sphere", size=96, light=light)
        result = oblique_depth(scene.image, scene.mask, light=light)
        shadow = scene.mask & ~result.lit
        assert shadow.sum() > 0.2 * scene.mask.sum()  # a real crescent
        assert np.all(result.normals[shadow] @ scene.light <= 1e-9)
        fitted = result.depth + np.nanmean(scene.depth - result.depth)
        spread = np.nanmax(scene.depth) - np.nanmin(scene.depth)
        wrong = np.abs(fitted - scene.depth)[shadow] / spread
        # the 2002 propagation reads the shadow as n . L = 0 (a ramp): 15 % RMS, 58 % at worst
        assert np.sqrt(np.mean(wrong**2)) < 0.02
        assert wrong.max() < 0.1
        assert metrics.angular_error(result.normals, scene.normals, shadow) < 5.0

    def test_fill_continues_a_linear_normal_field_exactly(self):
        scene = synth.scene("sphere", size=64, light=LIGHT)
        shadow = scene.mask & (scene.image <= 0)
        # pixels steeper than the fill's cap (n_z >= 0.05) cannot come back exactly
        steep = scene.normals[..., 2] < 0.06
        given = np.where(shadow[..., None], np.nan, scene.normals)
        filled = fill_shadow_normals(given, scene.mask, shadow, light=scene.light)
        check = shadow & ~steep
        np.testing.assert_allclose(filled[check], scene.normals[check], atol=1e-4)

    def test_fill_pushes_normals_off_the_light(self):
        # a flat lit disk continued into a shadowed ring would face the light: it must not
        mask = np.ones((32, 32), bool)
        shadow = np.zeros_like(mask)
        shadow[:, 20:] = True
        normals = np.zeros((32, 32, 3))
        normals[..., 2] = 1.0
        light = np.array([0.6, 0.0, 0.8])
        filled = fill_shadow_normals(normals, mask, shadow, light=light)
        assert np.all(filled[shadow] @ light <= 1e-9)
        np.testing.assert_allclose(np.linalg.norm(filled[mask], axis=-1), 1.0)


class TestKernels:
    def test_march_matches_its_reference(self):
        scene = synth.scene("sphere", size=24, light=LIGHT)
        cos_theta = scene.image / scene.image.max()
        lit = scene.mask & (cos_theta > 0)
        sources = np.array([np.unravel_index(np.argmax(cos_theta), cos_theta.shape)])
        concave = np.zeros(lit.shape, bool)
        concave[:8] = True
        fast = march_cone(cos_theta, lit, light=scene.light, sources=sources, concave_y=concave)
        slow = march_cone_reference(cos_theta, lit, light=scene.light, sources=sources,
                                    concave_y=concave)
        for a, b in zip(fast, slow):
            np.testing.assert_allclose(a, b, atol=1e-9, equal_nan=True)
        assert np.isfinite(fast[1][lit]).all()

    def test_sweep_matches_its_reference(self):
        scene = synth.scene("sphere", size=20, light=LIGHT)
        mask = scene.mask
        cos_theta = np.where(mask, scene.image / scene.image.max(), 0.0)
        lit = mask & (cos_theta > 0)
        descent = _Descent(mask, cos_theta, lit, scene.light, 0.01, 0.1)
        box = descent.box
        rng = np.random.default_rng(1)
        normals = np.nan_to_num(scene.normals[box]) + 0.05 * rng.normal(size=descent.mask.shape + (3,))
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
        normals = np.ascontiguousarray(np.where(descent.mask[..., None], normals, 0.0))
        z = np.ascontiguousarray(np.nan_to_num(scene.depth[box]))
        args = (z, descent.lit, descent.wx, descent.wy, descent.cos_theta)
        fast = cone_sweep(args[0], normals.copy(), *args[1:], light=scene.light)
        slow = cone_sweep_reference(args[0], normals.copy(), *args[1:], light=scene.light)
        # the reference searches a grid of 4096 azimuths: agreement to its spacing
        assert np.max(np.abs(fast - slow)) < 5e-3
        # and the sweep lowers the energy (block-coordinate descent)
        assert descent.energy(z, fast) < descent.energy(z, normals)
        np.testing.assert_allclose((fast @ scene.light)[descent.lit], descent.cos_theta[descent.lit],
                                   atol=1e-12)


class TestBadInput:
    def setup_method(self):
        self.scene = synth.scene("sphere", size=32, light=LIGHT)

    def test_light_below_the_horizon(self):
        with pytest.raises(InputError, match="z"):
            reconstruct(self.scene.image, mask=self.scene.mask, light=(1, 0, -1), method="oblique")

    @pytest.mark.parametrize("options, message", [
        ({"tol": 0}, "tol"), ({"tol": 1.5}, "tol"), ({"dark": 1.0}, "dark"),
        ({"smooth": -1}, "smooth"), ({"shadow_weight": 0}, "shadow_weight"),
        ({"iterations": -1}, "iterations"), ({"iterations": 2.5}, "iterations"),
        ({"k": 0}, "k"), ({"concave": np.zeros((3, 3), bool)}, "concave"),
        ({"k": 1e6, "dark": 0.5}, "shadow"),
    ])
    def test_options(self, options, message):
        with pytest.raises(InputError, match=message):
            oblique_depth(self.scene.image, self.scene.mask, light=self.scene.light, **options)

    def test_mask_of_another_size(self):
        with pytest.raises(InputError, match="mask"):
            oblique_depth(self.scene.image, np.ones((8, 8), bool), light=self.scene.light)

    def test_concave_masks_from_regions_are_accepted(self):
        regions = concave_masks(parse_regions(synth.concave_regions("bowl", size=32)), (32, 32))
        result = oblique_depth(self.scene.image, self.scene.mask, light=self.scene.light,
                               concave=regions, iterations=0)
        assert np.isfinite(result.depth[self.scene.mask]).all()
