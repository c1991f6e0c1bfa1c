"""The oblique-light solver: accuracy bars, kernels against their references, shadows, bad input."""

import numba
import numpy as np
import pytest

from shadeform import metrics, reconstruct, synth
from shadeform.errors import InputError
from shadeform.light import light_from_slant_tilt
from shadeform.regions import concave_masks, parse_regions
from shadeform.solvers.oblique import (
    SHADOW_NZ,
    cone_sweep,
    cone_sweep_reference,
    fill_shadow_normals,
    march_cone,
    march_cone_reference,
    oblique_depth,
)
from shadeform.solvers.oblique.caps import cap_datums
from shadeform.solvers.oblique.descent import Descent, _cone_coefficients, _cone_minimum, _serial
from shadeform.solvers.oblique.march import _fit_pixel, _fit_work, _gather, _local_cost
from shadeform.solvers.oblique.solver import _double_normals

LIGHT = (5.0, 5.0, 7.0)


def errors(rec, scene):
    """The two numbers of ``shadeform evaluate``: depth % (offset fitted) and mean angle."""
    return (
        metrics.depth_error(rec.depth, scene.depth, fit="offset"),
        metrics.angular_error(rec.normals, scene.normals),
    )


class TestBars:
    """The issue's bars at the light (5, 5, 7), noise-free, at 256 px as in the benchmark."""

    def test_sphere(self):
        scene = synth.scene("sphere", size=256, light=LIGHT)
        rec = reconstruct(scene.image, mask=scene.mask, light=scene.light, solver="oblique")
        depth, angle = errors(rec, scene)
        assert rec.info["levels"] == 1  # 256 px: marched at full size
        assert depth <= 3.0
        assert angle <= 4.0

    def test_vase_with_its_neck_marked(self):
        scene = synth.scene("vase", size=256, light=LIGHT)
        rec = reconstruct(
            scene.image,
            mask=scene.mask,
            light=scene.light,
            solver="oblique",
            concave=synth.concave_regions("vase", size=256),
        )
        depth, angle = errors(rec, scene)
        assert depth <= 4.0
        assert angle <= 6.0

    def test_light_at_plus_z(self):
        scene = synth.scene("sphere", size=64)
        rec = reconstruct(scene.image, mask=scene.mask, solver="oblique")
        depth, angle = errors(rec, scene)
        assert depth < 1.0 and angle < 1.0
        assert rec.info["solver"] == "oblique" and rec.info["shadowed"] == 0

    def test_another_integrator_can_give_the_depth(self):
        scene = synth.scene("sphere", size=64, light=LIGHT)
        rec = reconstruct(
            scene.image, mask=scene.mask, light=scene.light, solver="oblique", integrator="poisson"
        )
        assert rec.info["integrator"] == "poisson"
        assert errors(rec, scene)[0] < 3.0


class TestCoarseToFine:
    def test_half_size_start_keeps_the_sphere(self):
        """Forcing the coarse-to-fine route (two half-size levels) on a 128 px sphere."""
        scene = synth.scene("sphere", size=128, light=LIGHT)
        result = oblique_depth(scene.image, scene.mask, light=scene.light, coarse=40)
        assert result.info["levels"] == 3 and result.info["sweeps"] <= 10
        assert metrics.depth_error(result.depth, scene.depth, fit="offset") < 1.0
        assert metrics.angular_error(result.normals, scene.normals) < 1.0
        lit = result.lit
        np.testing.assert_allclose(
            result.normals[lit] @ scene.light, scene.image[lit] / scene.image[scene.mask].max(), atol=1e-9
        )

    def test_one_concave_axis_alone_goes_down_the_levels(self):
        scene = synth.scene("bowl", size=64, light=LIGHT)
        concave_y = np.zeros(scene.mask.shape, bool)
        concave_y[:, :32] = True
        result = oblique_depth(
            scene.image, scene.mask, light=scene.light, concave_y=concave_y, coarse=40, iterations=0
        )
        assert result.info["levels"] == 2
        assert np.isfinite(result.depth[scene.mask]).all()

    def test_doubled_normals_lie_on_their_cones(self):
        """A kernel against its reference (a private name, deliberately): the normals
        ``_double_normals`` brings up a level lie on their cones, and near the true sphere's."""
        scene = synth.scene("sphere", size=64, light=LIGHT)
        half = synth.scene("sphere", size=32, light=LIGHT)
        cos_theta = np.where(scene.mask, scene.image / scene.image.max(), 0.0)
        lit = scene.mask & (cos_theta > 0)
        doubled = _double_normals(half.normals, scene.mask, cos_theta, lit, scene.light)
        np.testing.assert_allclose(doubled[lit] @ scene.light, cos_theta[lit], atol=1e-12)
        assert np.isnan(doubled[~lit]).all()
        # a sphere's normals are smooth: the doubled ones are close to the true ones
        assert metrics.angular_error(doubled, scene.normals, lit) < 3.0


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
        # pixels steeper than the fill's cap (n_z >= SHADOW_NZ) cannot come back exactly
        steep = scene.normals[..., 2] < SHADOW_NZ + 0.01
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
        slow = march_cone_reference(cos_theta, lit, light=scene.light, sources=sources, concave_y=concave)
        for a, b in zip(fast, slow):
            np.testing.assert_allclose(a, b, atol=1e-9, equal_nan=True)
        assert np.isfinite(fast[1][lit]).all()

    def test_march_with_two_caps_matches_its_reference(self):
        # two separate caps of sources: two height datums, fronts that meet
        scene = synth.scene("sphere", size=24, light=LIGHT)
        cos_theta = scene.image / scene.image.max()
        lit = scene.mask & (cos_theta > 0)
        main = np.unravel_index(np.argmax(cos_theta), cos_theta.shape)
        far = np.argwhere(lit)[np.argmax(np.where(lit, cos_theta, 2.0)[lit] < 0.5)]
        sources = np.array([main, far])
        fast = march_cone(cos_theta, lit, light=scene.light, sources=sources)
        slow = march_cone_reference(cos_theta, lit, light=scene.light, sources=sources)
        for a, b in zip(fast, slow):
            np.testing.assert_allclose(a, b, atol=1e-9, equal_nan=True)
        assert np.isfinite(fast[1][lit]).all()

    def test_caps_merge_only_what_one_plateau_can_hold(self):
        """Separate groups of sources share a height datum only when the brightest path between
        them keeps the plateau's height error under a pixel."""
        lit = np.ones((9, 40), bool)
        seeds = np.zeros_like(lit)
        seeds[4, [2, 6, 30]] = True
        cos_theta = np.full(lit.shape, 0.9)
        cos_theta[seeds] = 1.0
        cos_theta[3:6, 2:7] = np.maximum(cos_theta[3:6, 2:7], 0.999)  # 4 px at 1e-3: 0.18 px
        caps = cap_datums(seeds, cos_theta, lit)
        assert caps[4, 2] == caps[4, 6] != caps[4, 30]  # 24 px at 0.1: up to 10.6 px
        cos_theta[3:6, 2:7] = np.where(seeds[3:6, 2:7], 1.0, 0.9)  # 4 px at 0.1: up to 1.8 px
        caps = cap_datums(seeds, cos_theta, lit)
        assert len({caps[4, 2], caps[4, 6], caps[4, 30]}) == 3

    def test_vase_belly_and_neck_are_separate_caps(self):
        scene = synth.scene("vase", size=128, light=tuple(light_from_slant_tilt(30, 45)))
        cos_theta = scene.image / scene.image.max()
        lit = scene.mask & (cos_theta > 0)
        seeds = lit & (cos_theta >= 1 - 2e-3)
        caps = cap_datums(seeds, cos_theta, lit)
        assert len(np.unique(caps[seeds])) == 2

    def test_hinge_costs_only_a_turn_against_the_convexity(self):
        """A compiled kernel against a hand-made case (a private name, deliberately:
        ``_local_cost``). One neighbour to the right (d = (1, 0)) and normals n = (sin phi, 0, cos
        phi) at two azimuths on either side of it in n_x: the hinge adds hinge * shortfall^2 only to
        the turn that goes the wrong way for the convexity (convex: n_x grows to the right)."""
        nb = np.zeros((8, 3))
        nb[0] = (0.1, 0.0, np.sqrt(0.99))
        db = np.zeros((8, 2))
        db[0] = (1.0, 0.0)
        zb, wb = np.zeros(8), np.ones(8)
        a0, a1, a2 = np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
        out = np.empty(1)

        def cost(phi, hinge, cx):
            return _local_cost(phi, a0, a1, a2, nb, db, zb, wb, 1, 0.0, np.zeros(2), hinge, cx, 1.0, out)

        low, high = np.arcsin(-0.2), np.arcsin(0.3)  # n_x = -0.2 and 0.3 beside n_b,x = 0.1
        # convex along x: n_x must not exceed the right neighbour's
        assert cost(low, 50.0, 1.0) == pytest.approx(cost(low, 0.0, 1.0))
        assert cost(high, 50.0, 1.0) == pytest.approx(cost(high, 0.0, 1.0) + 50.0 * 0.2**2)
        # marked concave along x: the other way round
        assert cost(high, 50.0, -1.0) == pytest.approx(cost(high, 0.0, -1.0))
        assert cost(low, 50.0, -1.0) == pytest.approx(cost(low, 0.0, -1.0) + 50.0 * 0.3**2)

    @pytest.mark.parametrize("compiled", [True, False])
    def test_convexity_pull_has_no_sign_across_a_region_edge(self, compiled):
        """A compiled kernel against a hand-made case (private names, deliberately: ``_gather``,
        ``_fit_work``, ``_fit_pixel``). A pixel on the last convex row above a region marked concave
        along y, with all eight neighbours accepted: the three below straddle the inflection and
        pull neither way, so the tie-break is the three above's alone (weights 1, 1/2, 1/2; convex:
        moving down from them n_y falls, so the cost 2 kappa n_y) instead of cancelling to zero.
        Along x every pair is convex and cancels."""
        kappa = 0.03
        z = np.zeros((3, 3))
        normals = np.zeros((3, 3, 3))
        normals[..., 2] = 1.0
        done = np.ones((3, 3), bool)
        done[1, 1] = False
        datum = np.ones((3, 3), np.int64)
        convex_x = np.ones((3, 3))
        convex_y = np.ones((3, 3))
        convex_y[2] = -1.0  # the row below is marked concave along y
        state = (z, normals, done, datum)
        convex = (convex_x, convex_y)
        work = _fit_work()
        labels = np.empty(8, np.int64)
        gather = _gather if compiled else _gather.py_func
        count, spans = gather(1, 1, state, convex, kappa, work, labels)
        assert count == 8 and spans
        np.testing.assert_allclose(work[4], [0.0, -2.0 * kappa], atol=1e-15)
        # the local fit recomputes the pull over its datum's neighbours: the same, so on this
        # flat patch (the chords are symmetric in n_y) the fitted normal leans down the cone
        light = np.array([0.0, 0.0, 1.0])
        cone = (
            np.full((3, 3), 0.95),
            np.full((3, 3), np.pi),
            light,
            np.array([1.0, 0.0, 0.0]),
            np.array([0.0, 1.0, 0.0]),
        )
        out = np.empty(6)
        fit = _fit_pixel if compiled else _fit_pixel.py_func
        fit(1, 1, state, cone, convex, (0.05, kappa, 0.0), 72, work, labels, out)
        assert out[1] < -0.3 and abs(out[0]) < 1e-6

    def test_sweep_matches_its_reference(self):
        scene = synth.scene("sphere", size=20, light=LIGHT)
        mask = scene.mask
        cos_theta = np.where(mask, scene.image / scene.image.max(), 0.0)
        lit = mask & (cos_theta > 0)
        descent = Descent(mask, cos_theta, lit, scene.light, 0.01, 0.1)
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
        np.testing.assert_allclose(
            (fast @ scene.light)[descent.lit], descent.cos_theta[descent.lit], atol=1e-12
        )

    def test_cone_coefficients_are_the_quadratic_up_to_a_constant(self):
        """A compiled kernel against its reference (a private name, deliberately):
        ``_cone_coefficients`` gives the quadratic n M n + 2 n g on the cone, evaluated directly, up
        to a constant."""
        rng = np.random.default_rng(3)
        A = rng.normal(size=(3, 3))
        M, g = A @ A.T, rng.normal(size=3)
        a0, a1, a2 = rng.normal(size=(3, 3))
        coef = np.empty(4)
        _cone_coefficients(a0, a1, a2, M, g, coef)
        t = np.linspace(-np.pi, np.pi, 50)
        n = a0 + np.cos(t)[:, None] * a1 + np.sin(t)[:, None] * a2
        quadratic = np.einsum("pi,ij,pj->p", n, M, n) + 2 * n @ g
        trig = coef @ np.array([np.cos(t), np.sin(t), np.cos(2 * t), np.sin(2 * t)])
        np.testing.assert_allclose(quadratic - trig, (quadratic - trig)[0], atol=1e-9)

    @pytest.mark.parametrize("seed", range(20))
    def test_cone_minimum_matches_a_fine_grid(self, seed):
        """A compiled kernel against its reference (a private name, deliberately): ``_cone_minimum``
        finds the minimum of a 200,001-point grid, or lower, within the limit."""
        rng = np.random.default_rng(seed)
        coef = rng.normal(size=4)
        limit = rng.uniform(0.3, np.pi)
        best = _cone_minimum(coef, limit, 0.0, 24)
        grid = np.linspace(-limit, limit, 200001)
        cost = coef @ np.array([np.cos(grid), np.sin(grid), np.cos(2 * grid), np.sin(2 * grid)])
        value = coef @ np.array([np.cos(best), np.sin(best), np.cos(2 * best), np.sin(2 * best)])
        assert -limit <= best <= limit
        assert value <= cost.min() + 1e-9

    def test_serial_restores_the_thread_count(self):
        before = numba.get_num_threads()
        with _serial():
            assert numba.get_num_threads() == 1
        assert numba.get_num_threads() == before


class TestBadInput:
    def setup_method(self):
        self.scene = synth.scene("sphere", size=32, light=LIGHT)

    def test_light_below_the_horizon(self):
        with pytest.raises(InputError, match="z"):
            reconstruct(self.scene.image, mask=self.scene.mask, light=(1, 0, -1), solver="oblique")

    @pytest.mark.parametrize(
        "options, message",
        [
            ({"tol": 0}, "tol"),
            ({"tol": 1.5}, "tol"),
            ({"dark": 1.0}, "dark"),
            ({"smooth": -1}, "smooth"),
            ({"shadow_weight": 0}, "shadow_weight"),
            ({"iterations": -1}, "iterations"),
            ({"iterations": 2.5}, "iterations"),
            ({"albedo": 0}, "albedo"),
            ({"concave_x": np.zeros((3, 3), bool)}, "concave_x"),
            ({"concave_y": np.zeros((3, 3), bool)}, "concave_y"),
            ({"albedo": 1e6, "dark": 0.5}, "shadow"),
            ({"coarse": 8}, "coarse"),
            ({"coarse": 1.5}, "coarse"),
        ],
    )
    def test_options(self, options, message):
        with pytest.raises(InputError, match=message):
            oblique_depth(self.scene.image, self.scene.mask, light=self.scene.light, **options)

    def test_mask_of_another_size(self):
        with pytest.raises(InputError, match="mask"):
            oblique_depth(self.scene.image, np.ones((8, 8), bool), light=self.scene.light)

    def test_concave_masks_from_regions_are_accepted(self):
        concave_x, concave_y = concave_masks(parse_regions(synth.concave_regions("bowl", size=32)), (32, 32))
        result = oblique_depth(
            self.scene.image,
            self.scene.mask,
            light=self.scene.light,
            concave_x=concave_x,
            concave_y=concave_y,
            iterations=0,
        )
        assert np.isfinite(result.depth[self.scene.mask]).all()
