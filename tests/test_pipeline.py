"""reconstruct(): the 2002 pipeline end to end, and the issue's accuracy bars (256x256, light +z)."""

import dataclasses
import json

import numpy as np
import pytest

from shadeform import coarse, metrics, pipeline, reconstruct, synth, to_mesh
from shadeform.coarse import preview_step, reconstruct_preview
from shadeform.errors import InputError
from shadeform.reconstruction import Reconstruction
from shadeform.solvers import NOISY, OUTLIERS, choose, get_solver

SIZE = 256


def whole_image_region(shape, axis="both"):
    h, w = shape
    return {"regions": [{"polygon": [[0, 0], [w, 0], [w, h], [0, h]], "axis": axis}]}


@pytest.fixture(scope="module")
def scenes():
    return {name: synth.scene(name, size=SIZE) for name in ("sphere", "ellipsoid", "cylinder", "bowl")}


class TestBars:
    @pytest.mark.parametrize("name", ["sphere", "ellipsoid", "cylinder"])
    def test_convex_shapes(self, scenes, name):
        scene = scenes[name]
        rec = reconstruct(scene.image, mask=scene.mask)
        assert metrics.angular_error(rec.normals, scene.normals, scene.mask) <= 3.0
        assert metrics.depth_error(rec.depth, scene.depth, scene.mask) <= 3.0

    def test_bowl_needs_its_concave_region(self, scenes):
        scene = scenes["bowl"]
        with_region = reconstruct(scene.image, mask=scene.mask, concave=whole_image_region(scene.mask.shape))
        without = reconstruct(scene.image, mask=scene.mask)
        assert metrics.angular_error(with_region.normals, scene.normals, scene.mask) <= 3.0
        assert metrics.depth_error(with_region.depth, scene.depth, scene.mask) <= 3.0
        assert metrics.angular_error(without.normals, scene.normals, scene.mask) > 10.0
        # the convex reading bulges toward the viewer, the concave one away from it
        centre = (SIZE // 2, SIZE // 2)
        rim = np.argwhere(scene.mask)[0]
        assert without.depth[centre] > without.depth[tuple(rim)]
        assert with_region.depth[centre] < with_region.depth[tuple(rim)]

    def test_several_references_never_worse_than_the_worst_single_one(self, scenes):
        scene = scenes["sphere"]
        refs = [(128, 128), (90, 110), (170, 150), (128, 60)]

        def errors(rec):
            return (
                metrics.angular_error(rec.normals, scene.normals, scene.mask),
                metrics.depth_error(rec.depth, scene.depth, scene.mask),
            )

        # eq. 7 of the 2002 report combines the propagated fields of several references
        singles = [
            errors(reconstruct(scene.image, mask=scene.mask, references=[r], solver="propagation"))
            for r in refs
        ]
        combined = errors(reconstruct(scene.image, mask=scene.mask, references=refs, solver="propagation"))
        assert combined[0] <= max(s[0] for s in singles) + 1e-9
        assert combined[1] <= max(s[1] for s in singles) + 1e-9

    def test_refinement_off_is_the_2002_field(self, scenes):
        scene = scenes["sphere"]
        rec = reconstruct(scene.image, mask=scene.mask, refine=0)
        assert rec.info["refine"] == 0
        assert metrics.angular_error(rec.normals, scene.normals, scene.mask) < 1.0


class TestAutoMethod:
    def test_picks_eikonal_at_plus_z_and_oblique_otherwise(self):
        assert choose((0.0, 0.0, 1.0)).name == "eikonal"
        assert choose((0.1, 0.0, 0.995)).name == "oblique"
        assert choose((0.0, 0.0, 1.0), noise=0.01).name == "oblique"  # best at +z with 1 % noise
        assert choose(None).name == "oblique"  # a light still to be estimated may be oblique
        scene = synth.scene("sphere", size=32, light=(1, 0, 3))
        rec = reconstruct(scene.image, mask=scene.mask, light=scene.light)
        assert rec.info["solver"] == "oblique" and rec.info["solver_requested"] == "auto"

    def test_picks_the_guided_photo_solver_for_a_painted_noisy_object(self):
        scene = synth.scene("sphere", size=48, light=(1, 0, 3), noise=0.01)
        plain = reconstruct(scene.image, mask=scene.mask, light=scene.light)
        assert plain.info["solver"] == "oblique" and plain.info["detail"]["outliers"] < OUTLIERS
        painted = scene.image * np.where(np.random.default_rng(0).random(scene.image.shape) < 0.05, 0.5, 1.0)
        rec = reconstruct(painted, mask=scene.mask, light=scene.light)
        assert rec.info["solver"] == "guided" and rec.info["detail"]["outliers"] >= OUTLIERS
        assert rec.info["detail"]["noise"] > NOISY


class TestReconstruct:
    def test_result_shapes_and_conventions(self):
        scene = synth.scene("sphere", size=64)
        rec = reconstruct(scene.image)  # automatic mask
        assert isinstance(rec, Reconstruction)
        assert rec.normals.shape == (64, 64, 3) and rec.depth.shape == (64, 64) and rec.mask.dtype == bool
        assert np.isnan(rec.depth[~rec.mask]).all() and np.isnan(rec.normals[~rec.mask]).all()
        assert np.isfinite(rec.depth[rec.mask]).all()
        ref = rec.info["references"][0]
        assert rec.depth[ref] == 0  # offset rule: z = 0 at the main reference
        # the default picks the best measured solver for the light: eikonal at +z
        assert rec.info["solver_requested"] == "auto" and rec.info["solver"] == "eikonal"
        assert set(rec.info["timings"]) >= {"mask", "normals", "depth"}
        assert rec.albedo == pytest.approx(scene.image.max())
        with pytest.raises(dataclasses.FrozenInstanceError):
            rec.depth = None

    def test_auto_mask_matches_truth(self):
        scene = synth.scene("sphere", size=128)
        rec = reconstruct(scene.image)
        assert np.count_nonzero(rec.mask ^ scene.mask) <= 0.01 * scene.mask.sum()

    def test_user_reference_sets_the_origin(self):
        scene = synth.scene("sphere", size=64)
        rec = reconstruct(scene.image, mask=scene.mask, references=[(20, 30)])
        assert rec.depth[20, 30] == 0 and rec.info["references"][0] == (20, 30)

    def test_reference_with_normal_sets_the_brightness_scale(self):
        scene = synth.scene("sphere", size=64, albedo=0.5)
        n = scene.normals[20, 30]
        rec = reconstruct(scene.image, mask=scene.mask, references=[(20, 30, tuple(n))])
        assert rec.albedo == pytest.approx(0.5, rel=1e-9)

    def test_poisson_integrator(self):
        scene = synth.scene("sphere", size=128)
        rec = reconstruct(scene.image, mask=scene.mask, integrator="poisson")
        assert metrics.depth_error(rec.depth, scene.depth, scene.mask) < 3.0

    def test_filter_helps_with_noise(self):
        scene = synth.scene("sphere", size=128, noise=0.01, seed=3)
        raw = reconstruct(scene.image, mask=scene.mask, solver="eikonal")
        smooth = reconstruct(scene.image, mask=scene.mask, solver="eikonal", filter="gaussian:1")
        assert smooth.info["filter"] == "gaussian"
        assert metrics.angular_error(smooth.normals, scene.normals, scene.mask) < metrics.angular_error(
            raw.normals, scene.normals, scene.mask
        )

    def test_oblique_light_sphere(self):
        from shadeform.light import light_from_slant_tilt

        light = light_from_slant_tilt(30, 45)
        scene = synth.scene("sphere", size=128, light=light)
        rec = reconstruct(scene.image, mask=scene.mask, light=light)
        assert metrics.angular_error(rec.normals, scene.normals, scene.mask) < 3.0

    def test_concave_accepts_json_text_and_paths(self, tmp_path):
        scene = synth.scene("bowl", size=64)
        regions = whole_image_region(scene.mask.shape)
        path = tmp_path / "regions.json"
        path.write_text(json.dumps(regions))
        a = reconstruct(scene.image, mask=scene.mask, concave=json.dumps(regions))
        b = reconstruct(scene.image, mask=scene.mask, concave=path)
        np.testing.assert_allclose(a.depth, b.depth, atol=1e-8)
        assert metrics.angular_error(a.normals, scene.normals, scene.mask) < 3.0

    def test_every_part_of_the_mask_gets_a_reference(self):
        scene = synth.scene("sphere", size=48)
        image = np.hstack([scene.image, scene.image])
        rec = reconstruct(image)  # automatic mask keeps the largest part only
        assert rec.info["parts"] == 1
        mask = np.hstack([scene.mask, scene.mask])
        rec = reconstruct(image, mask=mask)
        assert rec.info["parts"] == 2 and len(rec.info["references"]) == 2
        assert np.isfinite(rec.depth[mask]).all()


class TestBadInput:
    @pytest.fixture
    def scene(self):
        return synth.scene("sphere", size=32)

    @pytest.mark.parametrize(
        "image,match",
        [
            (np.zeros((32, 32)), "black"),
            (np.ones((32, 32)), "saturated|constant"),
            (np.zeros((1, 1)), "at least"),
            (np.zeros((0, 5)), "at least"),
            (np.zeros((8, 8, 3)), "one channel"),
            ([[0.5, 0.5]], "numpy array"),
        ],
    )
    def test_bad_images(self, image, match):
        with pytest.raises(InputError, match=match):
            reconstruct(image)

    def test_nan_in_image(self, scene):
        image = scene.image.copy()
        image[5, 5] = np.nan
        with pytest.raises(InputError, match="NaN"):
            reconstruct(image, mask=scene.mask)

    def test_saturated_with_given_mask(self, scene):
        image = np.where(scene.mask, 1.0, 0.0)
        with pytest.raises(InputError, match="saturated"):
            reconstruct(image, mask=scene.mask)

    def test_reference_outside_mask(self, scene):
        with pytest.raises(InputError, match="not on the object"):
            reconstruct(scene.image, mask=scene.mask, references=[(0, 0)])
        with pytest.raises(InputError, match="not on the object"):
            reconstruct(scene.image, mask=scene.mask, references=[(500, 3)])

    @pytest.mark.parametrize(
        "kwargs,match",
        [
            ({"solver": "magic"}, "unknown solver"),
            ({"integrator": "magic"}, "unknown integrator"),
            ({"refine": -1}, "refine"),
            ({"light": (0, 0, -1)}, "z <= 0"),
            ({"concave": '{"regions": [{"polygon": [[0, 0]], "axis": "x"}]}'}, "3"),
            ({"concave": "{not json"}, "JSON"),
            ({"references": [(1,)]}, "reference"),
            ({"filter": "blur:2"}, "filter|gaussian"),
        ],
    )
    def test_bad_options(self, scene, kwargs, match):
        with pytest.raises(InputError, match=match):
            reconstruct(scene.image, mask=scene.mask, **kwargs)

    def test_mask_of_wrong_shape(self, scene):
        with pytest.raises(InputError, match="shape"):
            reconstruct(scene.image, mask=np.ones((10, 10), bool))
        with pytest.raises(InputError, match="empty"):
            reconstruct(scene.image, mask=np.zeros((32, 32), bool))


class TestEikonalMethod:
    def test_vase_with_its_neck_marked(self):
        scene = synth.scene("vase", size=SIZE)
        rec = reconstruct(
            scene.image, mask=scene.mask, solver="eikonal", concave=synth.concave_regions("vase", size=SIZE)
        )
        assert rec.info["solver"] == "eikonal" and rec.info["singular_points"]
        assert metrics.depth_error(rec.depth, scene.depth, scene.mask) <= 1.0
        assert metrics.angular_error(rec.normals, scene.normals, scene.mask) <= 3.0

    def test_integrator_can_replace_the_marching_depth(self):
        scene = synth.scene("sphere", size=96)
        rec = reconstruct(scene.image, mask=scene.mask, solver="eikonal", integrator="poisson")
        assert rec.info["integrator"] == "poisson"
        assert metrics.depth_error(rec.depth, scene.depth, scene.mask) < 1.0

    def test_needs_the_light_at_plus_z(self):
        scene = synth.scene("sphere", size=32)
        with pytest.raises(InputError, match="eikonal"):
            reconstruct(scene.image, mask=scene.mask, solver="eikonal", light=(0.3, 0, 1))


class TestSynthConcaveRegions:
    @pytest.mark.parametrize("name", synth.SCENES)
    def test_regions_cover_only_truly_concave_pixels(self, name):
        """Inside a drawn region the true surface curves away from the viewer along its axis."""
        from shadeform.regions import concave_masks, parse_regions

        scene = synth.scene(name, size=128)
        concave_x, concave_y = concave_masks(parse_regions(synth.concave_regions(name, size=128)), (128, 128))
        if name in ("sphere", "ellipsoid", "cylinder"):
            assert not concave_x.any() and not concave_y.any()
            return
        z = scene.depth
        zxx = z[1:-1, 2:] - 2 * z[1:-1, 1:-1] + z[1:-1, :-2]
        zyy = z[2:, 1:-1] - 2 * z[1:-1, 1:-1] + z[:-2, 1:-1]
        inner_x = concave_x[1:-1, 1:-1] & np.isfinite(zxx)
        inner_y = concave_y[1:-1, 1:-1] & np.isfinite(zyy)
        assert inner_x.any() or inner_y.any()
        # the bulk of each marked axis is concave (z'' > 0); region edges may overshoot a little
        if inner_x.any():
            assert np.mean(zxx[inner_x] > 0) > 0.6
        if inner_y.any():
            assert np.mean(zyy[inner_y] > 0) > 0.6


class TestEstimatedLight:
    def test_light_and_albedo_are_estimated(self):
        from shadeform.light import light_from_slant_tilt

        truth = light_from_slant_tilt(30, 120)
        scene = synth.scene("sphere", size=128, light=truth, albedo=0.8)
        rec = reconstruct(scene.image, mask=scene.mask, light="estimate")
        assert np.degrees(np.arccos(np.clip(rec.light @ truth, -1, 1))) < 3
        assert rec.albedo == pytest.approx(0.8, rel=0.03)
        assert rec.info["light_estimate"]["evidence"]
        assert metrics.angular_error(rec.normals, scene.normals, scene.mask) < 5

    def test_only_estimate_is_a_valid_word(self):
        scene = synth.scene("sphere", size=32)
        with pytest.raises(InputError, match="estimate"):
            reconstruct(scene.image, mask=scene.mask, light="guess")


class TestLevel:
    """reconstruct_on_level: a large photo's quick look on its pyramid level, the user's settings
    (given in the photo's pixels) carried to the level."""

    @staticmethod
    def level(scene, factor):
        h, w = scene.image.shape
        blocks = (h // factor, factor, w // factor, factor)
        image = scene.image.reshape(blocks).mean(axis=(1, 3))
        return image, scene.mask.reshape(blocks).mean(axis=(1, 3)) >= 0.5

    def test_the_settings_are_the_photos_divided_by_the_block_side(self):
        scene = synth.scene("bumps", size=96)
        image, mask = self.level(scene, 3)
        polygon = [[30.0, 30.0], [60.0, 30.0], [60.0, 60.0], [30.0, 60.0]]
        rec = coarse.reconstruct_on_level(
            image, factor=3, step=1, mask=mask, light=(0, 0, 1), filter="gaussian:1.5",
            references=[(46, 50)], concave={"regions": [{"polygon": polygon, "axis": "both"}]},
        )  # fmt: skip
        same = reconstruct(
            image, mask=mask, light=(0, 0, 1), filter="gaussian:0.5", references=[(15, 16)],
            concave={"regions": [{"polygon": (np.array(polygon) / 3).tolist(), "axis": "both"}]},
        )  # fmt: skip
        np.testing.assert_array_equal(rec.depth, same.depth)
        assert rec.info["references"] == [(15, 16)]

    def test_a_reference_off_the_levels_object_moves_to_its_nearest_pixel(self):
        scene = synth.scene("sphere", size=64)
        image, mask = self.level(scene, 2)
        rec = coarse.reconstruct_on_level(image, factor=2, step=1, mask=mask, references=[(0, 0)])
        row, col = rec.info["references"][0]
        assert mask[row, col] and row + col == min(r + c for r, c in zip(*np.nonzero(mask)))
        with pytest.raises(InputError, match="median"):  # a window that is not whole is refused
            coarse.reconstruct_on_level(image, factor=2, step=1, mask=mask, filter="median:2.5")


class TestPreview:
    """reconstruct_preview: the quick look at the mesh's grid that the app shows first."""

    def test_still_importable_from_pipeline_with_a_deprecation_warning(self):
        with pytest.warns(DeprecationWarning, match="shadeform.coarse.preview_step"):
            from shadeform.pipeline import preview_step as from_pipeline
        assert from_pipeline is preview_step
        with pytest.warns(DeprecationWarning, match="moved to shadeform.coarse"):
            assert pipeline.reconstruct_preview is reconstruct_preview
        with pytest.warns(DeprecationWarning, match="moved to shadeform.coarse"):
            assert pipeline.reconstruct_on_grid is coarse.reconstruct_on_grid
        with pytest.raises(AttributeError, match="no_such_name"):
            pipeline.no_such_name  # noqa: B018

    @pytest.mark.parametrize(
        ("name", "step", "bound"), [("vase", 2, 0.5), ("vase", 3, 0.5), ("bumps", 2, 5.0)]
    )
    def test_bright_caps_between_grid_points_are_kept(self, name, step, bound):
        """The vase's lip (its singular point on the top row) and the bumps' small caps fall
        between grid points: sampled plainly, the eikonal quick look lost them (6.3 % and 19 %)."""
        scene = synth.scene(name, size=256)
        quick = coarse.reconstruct_preview(
            scene.image,
            mask=scene.mask,
            step=step,
            concave=synth.concave_regions(name, size=256),
            solver="eikonal",
        )
        grid = np.zeros_like(scene.mask)
        grid[::step, ::step] = True
        on = grid & scene.mask
        assert (
            metrics.depth_error(np.where(on, quick.depth, np.nan), np.where(on, scene.depth, np.nan), on)
            < bound
        )

    def test_on_grid_is_the_preview_s_grid_in_grid_units(self):
        """reconstruct_on_grid: the grid's own arrays (what a relief with a budget is built from);
        references and unsure areas stay in the input's pixels."""
        scene = synth.scene("vase", size=256)
        regions = synth.concave_regions("vase", size=256)
        grid = coarse.reconstruct_on_grid(
            scene.image, mask=scene.mask, concave=regions, step=3, references=[(128, 128)]
        )
        quick = reconstruct_preview(
            scene.image, mask=scene.mask, concave=regions, step=3, references=[(128, 128)]
        )
        assert grid.depth.shape == grid.mask.shape == (86, 86) and grid.info["grid_step"] == 3
        np.testing.assert_array_equal(grid.mask, scene.mask[::3, ::3])
        np.testing.assert_allclose(grid.depth[grid.mask] * 3, quick.depth[::3, ::3][grid.mask])
        assert grid.info["references"] == quick.info["references"] == [(129, 129)]
        plain = coarse.reconstruct_on_grid(scene.image, mask=scene.mask, concave=regions, step=3)
        assert metrics.depth_error(plain.depth, scene.depth[::3, ::3] / 3, plain.mask) < 0.5
        one = coarse.reconstruct_on_grid(scene.image, mask=scene.mask, step=1)
        assert one.depth.shape == scene.mask.shape and one.info["grid_step"] == 1

    def test_keep_caps_moves_a_cap_to_the_nearest_grid_point(self):
        from shadeform.coarse import _keep_caps

        image = np.full((9, 9), 0.5)
        mask = np.ones((9, 9), bool)
        image[3, 5] = 1.0  # between the grid points of step 2 (rows and columns 0, 2, 4, ...)
        coarse = image[::2, ::2].copy()
        kept = _keep_caps(image, mask, coarse, mask[::2, ::2], 2)
        assert kept.max() == 1.0
        assert kept[1, 2] == 1.0 or kept[2, 2] == 1.0 or kept[1, 3] == 1.0 or kept[2, 3] == 1.0
        assert (kept == 1.0).sum() == 1
        assert (np.delete(kept.ravel(), np.argmax(kept)) == 0.5).all()
        on_grid = image.copy()
        on_grid[3, 5], on_grid[4, 4] = 0.5, 1.0
        np.testing.assert_array_equal(
            _keep_caps(on_grid, mask, on_grid[::2, ::2], mask[::2, ::2], 2), on_grid[::2, ::2]
        )

    @pytest.mark.parametrize(("name", "step"), [("vase", 2), ("sphere", 2), ("sphere", 3)])
    def test_same_mesh_as_the_full_solve_and_close_to_the_truth(self, name, step):
        scene = synth.scene(name, size=128)
        regions = synth.concave_regions(name, size=128) if name == "vase" else None
        full = reconstruct(scene.image, mask=scene.mask, concave=regions)
        quick = reconstruct_preview(scene.image, mask=scene.mask, concave=regions, step=step)
        full_mesh, quick_mesh = to_mesh(full, step=step), to_mesh(quick, step=step)
        np.testing.assert_array_equal(quick_mesh.faces, full_mesh.faces)
        np.testing.assert_array_equal(quick_mesh.vertices[:, :2], full_mesh.vertices[:, :2])
        assert quick.info["preview_step"] == step and quick.info["solver"] == "eikonal"
        grid = scene.mask[::step, ::step]
        # measured: vase step 2 0.41 % / 1.14 deg (full solve 0.09 % / 0.50 deg); sphere step 2
        # 0.12 % / 0.44 deg, step 3 0.21 % / 0.58 deg
        truth_depth, truth_normals = scene.depth[::step, ::step], scene.normals[::step, ::step]
        assert metrics.depth_error(quick.depth[::step, ::step], truth_depth, grid) < 1.0
        assert metrics.angular_error(quick.normals[::step, ::step], truth_normals, grid) < 2.0
        # off the grid there is nothing, on the grid everything
        assert np.isnan(quick.depth[1::step, :]).all()
        assert np.isfinite(quick.depth[::step, ::step][grid]).all()

    def test_concave_region_carried_to_the_grid(self):
        scene = synth.scene("bowl", size=96)
        regions = synth.concave_regions("bowl", size=96)
        quick = reconstruct_preview(scene.image, mask=scene.mask, concave=regions, step=3)
        grid = scene.mask[::3, ::3]
        assert metrics.depth_error(quick.depth[::3, ::3], scene.depth[::3, ::3], grid) < 1.0
        plain = reconstruct_preview(scene.image, mask=scene.mask, step=3)
        assert metrics.depth_error(plain.depth[::3, ::3], scene.depth[::3, ::3], grid) > 10

    def test_filter_and_references_in_input_pixels(self):
        scene = synth.scene("sphere", size=96, noise=0.02)
        quick = reconstruct_preview(
            scene.image,
            mask=scene.mask,
            step=2,
            solver="propagation",
            filter="gaussian:3",
            references=[(31, 47)],
        )
        assert quick.info["references"][0] == (32, 48)  # (31, 47) / 2, rounded, back in input pixels
        assert quick.info["filter"] == "gaussian"
        grid = scene.mask[::2, ::2]
        assert metrics.angular_error(quick.normals[::2, ::2], scene.normals[::2, ::2], grid) < 5

    def test_reference_moves_onto_the_coarse_object(self):
        scene = synth.scene("sphere", size=64)
        rows, cols = np.nonzero(scene.mask)
        edge = next(
            (r, c)
            for r, c in zip(rows, cols)
            if r % 4 and not scene.mask[::4, ::4][round(r / 4), round(c / 4)]
        )
        quick = reconstruct_preview(
            scene.image, mask=scene.mask, step=4, references=[edge], solver="propagation"
        )
        r, c = quick.info["references"][0]
        assert scene.mask[r, c] and abs(r - edge[0]) <= 6 and abs(c - edge[1]) <= 6

    def test_step_one_is_the_full_solve(self):
        scene = synth.scene("sphere", size=48)
        full = reconstruct(scene.image, mask=scene.mask)
        quick = reconstruct_preview(scene.image, mask=scene.mask, step=1)
        np.testing.assert_array_equal(quick.depth, full.depth)

    @pytest.mark.parametrize(
        ("step", "message"),
        [(0, "step must be"), (2.5, "step must be"), (True, "step must be"), (40, "no pixel on the grid")],
    )
    def test_bad_step(self, step, message):
        mask = np.zeros((64, 64), bool)
        mask[30:36, 30:36] = True
        image = np.where(mask, 0.8, 0.0)
        with pytest.raises(InputError, match=message):
            reconstruct_preview(image, mask=mask, step=step)

    def test_preview_step_keeps_to_the_solvers_budget(self):
        mask = np.ones((512, 512), bool)
        # step 2 leaves 65,536 grid pixels, over the eikonal budget: doubled once (16,384)
        assert preview_step(mask, 2, solver="eikonal") == 4
        assert 512**2 / 4**2 <= get_solver("eikonal").preview_pixels < 512**2 / 2**2
        assert preview_step(mask, 2, solver="oblique") == 16  # 1,024 pixels
        assert preview_step(mask, 3, light=(0.5, 0.0, 0.866)) == 12  # auto under oblique light
        assert preview_step(mask, 2, light="estimate") == 16
        assert preview_step(np.ones((64, 64), bool), 1) == 1  # small enough at full resolution
        # never so coarse that the grid has fewer than 3 points across its short side
        assert preview_step(np.ones((20, 100_000), bool), 1, solver="oblique") == 4

    def test_reference_off_the_object(self):
        scene = synth.scene("sphere", size=48)
        with pytest.raises(InputError, match="not on the object"):
            reconstruct_preview(scene.image, mask=scene.mask, step=2, references=[(0, 0)])


class TestAutoOnNoisyImages:
    def test_plus_z_with_noise_goes_to_the_smoothed_oblique_solver(self):
        scene = synth.scene("ellipsoid", size=128, noise=0.01)
        rec = reconstruct(scene.image, mask=scene.mask)
        assert rec.info["solver"] == "oblique" and rec.info["auto_filter"] == "gaussian:2"
        # measured 1.14 % / 1.47 deg (eikonal on the unfiltered image: 2.57 % / 3.41 deg)
        assert metrics.depth_error(rec.depth, scene.depth, scene.mask) < 3.0
        assert metrics.angular_error(rec.normals, scene.normals, scene.mask) < 3.5


class TestObliqueOnNoisyImages:
    """Unfiltered noise scatters the oblique solver's starts; a noisy image is smoothed first."""

    @pytest.mark.parametrize("name", ["sphere", "ellipsoid"])
    def test_one_percent_noise_at_slant_30(self, name):
        from shadeform.light import light_from_slant_tilt

        light = light_from_slant_tilt(30, 45)
        scene = synth.scene(name, size=256, light=light, noise=0.01)
        rec = reconstruct(scene.image, mask=scene.mask, light=light)
        assert rec.info["solver"] == "oblique" and rec.info["auto_filter"] == "gaussian:2"
        # measured 1.7 % / 1.3 deg (sphere), 1.3 % / 1.2 deg (ellipsoid); unfiltered 90-140 %
        assert metrics.depth_error(rec.depth, scene.depth, scene.mask) < 3.0
        assert metrics.angular_error(rec.normals, scene.normals, scene.mask) < 2.5

    def test_a_given_filter_or_a_clean_image_is_left_alone(self):
        light = (0.5, 0.0, 0.866)
        noisy = synth.scene("sphere", size=64, light=light, noise=0.02)
        assert "auto_filter" not in reconstruct(noisy.image, mask=noisy.mask, light=light, filter="none").info
        clean = synth.scene("sphere", size=64, light=light)
        assert "auto_filter" not in reconstruct(clean.image, mask=clean.mask, light=light).info


def test_the_brightest_pixel_s_tie_goes_to_the_deepest_as_by_the_distance_transform():
    """A kernel against its reference (a private name, deliberately: ``pipeline._references``,
    against scipy's exact distance transform). Among equally bright pixels the default reference is
    the one deepest inside the mask: the same pixel as the argmax of scipy's exact distance
    transform (raster order on ties)."""
    from scipy import ndimage as ndi

    from shadeform.pipeline import _references

    rng = np.random.default_rng(5)
    for _ in range(6):
        mask = ndi.gaussian_filter(rng.random((80, 96)), 4) > 0.5
        labels, n_parts = ndi.label(mask)
        image = np.where(mask, np.round(rng.random(mask.shape) * 4) / 4, 0.0)  # many ties at 1.0
        inside = ndi.distance_transform_edt(mask)
        refs = _references(None, image, mask, labels, n_parts)
        assert len(refs) == n_parts
        for part, ref in zip(range(1, n_parts + 1), refs, strict=True):
            tied = (labels == part) & (image >= image[labels == part].max())
            expected = np.unravel_index(np.argmax(np.where(tied, inside, -1.0)), mask.shape)
            assert ref.pixel == (int(expected[0]), int(expected[1]))
