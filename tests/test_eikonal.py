"""Eikonal solver (light at +z): the issue's bars, kernel vs reference, singular points, references and
concave regions, bad input."""

import numpy as np
import pytest

from shadeform import metrics, synth
from shadeform.errors import InputError
from shadeform.regions import concave_masks, parse_regions
from shadeform.solvers.eikonal import (
    MAX_DETECTED,
    EikonalResult,
    SingularPoint,
    arrival_times,
    arrival_times_reference,
    cone_normals,
    cone_normals_reference,
    eikonal_depth,
)

SIZE = 256
# The vase's neck: F'' > 0 between u = 0.596 and 0.921 of its height (rows 31-105 at 256 px), so
# the surface curves away from the viewer along y there, while it stays convex across (along x).
NECK = {"regions": [{"polygon": [[70, 32], [186, 32], [186, 102], [70, 102]], "axis": "y"}]}
# The bumps scene's dent, at (x, y) = (-0.22, -0.17) of the size: column 71, row 171.
DENT = {"regions": [{"polygon": [[41, 141], [101, 141], [101, 201], [41, 201]], "axis": "both"}]}


def concave(document, shape=(SIZE, SIZE)):
    """``concave_x=`` and ``concave_y=`` of the regions in ``document``."""
    concave_x, concave_y = concave_masks(parse_regions(document), shape)
    return {"concave_x": concave_x, "concave_y": concave_y}


def whole(axis="both"):
    return {"regions": [{"polygon": [[0, 0], [SIZE, 0], [SIZE, SIZE], [0, SIZE]], "axis": axis}]}


def errors(result, scene):
    return (
        metrics.depth_error(result.depth, scene.depth, scene.mask),
        metrics.angular_error(result.normals, scene.normals, scene.mask),
    )


@pytest.fixture(scope="module")
def scenes():
    return {
        name: synth.scene(name, size=SIZE)
        for name in ("sphere", "ellipsoid", "cylinder", "vase", "bowl", "bumps")
    }


class TestBars:
    def test_sphere(self, scenes):
        depth_err, angle_err = errors(
            eikonal_depth(scenes["sphere"].image, scenes["sphere"].mask), scenes["sphere"]
        )
        assert depth_err <= 0.5
        assert angle_err <= 0.5

    def test_vase_with_its_neck_marked(self, scenes):
        scene = scenes["vase"]
        result = eikonal_depth(scene.image, scene.mask, **concave(NECK))
        depth_err, angle_err = errors(result, scene)
        assert depth_err <= 1.0
        assert angle_err <= 3.0

    def test_vase_needs_its_neck(self, scenes):
        scene = scenes["vase"]
        depth_err, _ = errors(eikonal_depth(scene.image, scene.mask), scene)
        assert depth_err > 3.0  # the part above the neck is read as falling, not rising

    # not bars of the issue: guards that what is measured now does not slide back
    @pytest.mark.parametrize("name", ["ellipsoid", "cylinder"])
    def test_other_convex_shapes(self, scenes, name):
        depth_err, angle_err = errors(eikonal_depth(scenes[name].image, scenes[name].mask), scenes[name])
        assert depth_err <= 0.2
        assert angle_err <= 0.3

    def test_bowl_with_its_region(self, scenes):
        scene = scenes["bowl"]
        depth_err, angle_err = errors(eikonal_depth(scene.image, scene.mask, **concave(whole())), scene)
        assert depth_err <= 0.2
        assert angle_err <= 0.3

    def test_bumps_with_the_dent_marked(self, scenes):
        scene = scenes["bumps"]
        depth_err, angle_err = errors(eikonal_depth(scene.image, scene.mask, **concave(DENT)), scene)
        assert depth_err <= 0.5
        assert angle_err <= 0.5


class TestArrivalTimes:
    @staticmethod
    def blob(seed, height=18, width=21):
        rng = np.random.default_rng(seed)
        cos_theta = rng.uniform(0.1, 1.0, (height, width))  # f from 0 to ~10: both updates run
        rows, cols = np.mgrid[:height, :width]
        mask = ((rows - height / 2) / (height / 2.2)) ** 2 + ((cols - width / 2) / (width / 2.2)) ** 2 < 1
        mask[height // 2 - 3, width // 4 : width // 2] = False  # a wall to march around
        return cos_theta, mask

    @pytest.mark.parametrize("seed", [0, 1])
    def test_kernel_matches_reference(self, seed):
        cos_theta, mask = self.blob(seed)
        sources = [(9, 10), (4, 9)]
        fast = arrival_times(cos_theta, mask, sources, values=[0.0, 0.4])
        slow = arrival_times_reference(cos_theta, mask, sources, values=[0.0, 0.4])
        assert np.array_equal(np.isinf(fast), np.isinf(slow))
        np.testing.assert_allclose(fast[mask], slow[mask], rtol=0, atol=1e-10)

    def test_kernel_matches_reference_with_finite_differences_only(self):
        cos_theta, mask = self.blob(2)
        fast = arrival_times(cos_theta, mask, [(9, 10)], steep=1e9)
        slow = arrival_times_reference(cos_theta, mask, [(9, 10)], steep=1e9)
        np.testing.assert_allclose(fast[mask], slow[mask], rtol=0, atol=1e-10)

    def test_kernel_matches_reference_where_times_tie(self):
        # a symmetric sphere marched from its four top pixels: many pixels reach the same time,
        # and both pop equal times in the same order (smaller row, then column), so they agree
        scene = synth.scene("sphere", size=48)
        cos_theta = np.where(scene.mask, scene.image / scene.image[scene.mask].max(), 0.0)
        top = [tuple(p) for p in np.argwhere(cos_theta >= cos_theta.max() - 1e-4)]
        fast = arrival_times(cos_theta, scene.mask, top)
        slow = arrival_times_reference(cos_theta, scene.mask, top)
        assert len(top) == 4
        np.testing.assert_allclose(fast[scene.mask], slow[scene.mask], rtol=0, atol=1e-12)

    @pytest.mark.parametrize("cos", [0.6, 0.3])  # slope 1.33: differences; 3.18: arc update
    def test_plane_wave_is_exact(self, cos):
        cos_theta = np.full((12, 15), cos)
        mask = np.ones((12, 15), bool)
        times = arrival_times(cos_theta, mask, [(r, 0) for r in range(12)])
        slope = np.sqrt(1 / cos**2 - 1)
        np.testing.assert_allclose(times, np.tile(slope * np.arange(15.0), (12, 1)), rtol=0, atol=1e-12)

    def test_arc_update_is_exact_on_a_circle(self):
        # half cylinder of radius 20 along the rows: the drop from the ridge is R (1 - n_z)
        radius = 20.0
        x = np.arange(41) - 20.0
        x = x[np.abs(x) < radius]
        cos_theta = np.tile(np.sqrt(1 - (x / radius) ** 2), (9, 1))
        mask = np.ones_like(cos_theta, bool)
        ridge = int(np.argmax(cos_theta[0]))
        times = arrival_times(cos_theta, mask, [(r, ridge) for r in range(9)], steep=1e-9)
        np.testing.assert_allclose(times, radius * (1 - cos_theta), rtol=0, atol=1e-9)

    def test_values_shift_the_times(self):
        cos_theta, mask = self.blob(3)
        base = arrival_times(cos_theta, mask, [(9, 10)])
        shifted = arrival_times(cos_theta, mask, [(9, 10)], values=[2.5])
        np.testing.assert_allclose(shifted[mask], base[mask] + 2.5, atol=1e-12)

    def test_unreached_and_outside_are_inf(self):
        cos_theta = np.full((10, 10), 0.8)
        mask = np.zeros((10, 10), bool)
        mask[1:4, 1:4] = True
        mask[6:9, 6:9] = True  # not connected to the source
        times = arrival_times(cos_theta, mask, [(2, 2)])
        assert np.isfinite(times[1:4, 1:4]).all()
        assert np.isinf(times[6:9, 6:9]).all() and np.isinf(times[~mask]).all()

    def test_times_grow_away_from_the_source(self):
        cos_theta, mask = self.blob(4)
        times = arrival_times(cos_theta, mask, [(9, 10)])
        assert times[9, 10] == 0 and (times[mask] >= 0).all()


class TestSolver:
    def test_result_shapes_and_frame(self, scenes):
        scene = scenes["sphere"]
        result = eikonal_depth(scene.image, scene.mask)
        assert isinstance(result, EikonalResult)
        assert result.depth.shape == (SIZE, SIZE) and result.normals.shape == (SIZE, SIZE, 3)
        assert np.isnan(result.depth[~scene.mask]).all() and np.isnan(result.normals[~scene.mask]).all()
        assert np.isfinite(result.depth[scene.mask]).all()
        main = result.singular_points[0]
        assert isinstance(main, SingularPoint)
        assert (main.kind, main.origin, main.height) == ("max", "detected", 0.0)
        assert abs(main.row - 127.5) < 1 and abs(main.col - 127.5) < 1
        assert result.depth[main.row, main.col] == 0
        assert np.nanmax(result.depth) <= 1e-9  # a convex object hangs below its top
        assert result.albedo == scene.image[scene.mask].max()

    def test_normals_lie_on_the_shading_cone(self, scenes):
        scene = scenes["ellipsoid"]
        result = eikonal_depth(scene.image, scene.mask)
        n = result.normals[scene.mask]
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-12)
        cos = np.clip(scene.image[scene.mask] / result.albedo, 0, 1)
        np.testing.assert_allclose(n[:, 2], cos, atol=1e-12)

    def test_inputs_are_not_modified(self, scenes):
        scene = scenes["sphere"]
        image, mask = scene.image.copy(), scene.mask.copy()
        image.flags.writeable = mask.flags.writeable = False
        eikonal_depth(image, mask, **concave(whole()))
        np.testing.assert_array_equal(image, scene.image)

    def test_bowl_flips_with_its_region(self, scenes):
        scene = scenes["bowl"]
        dome = eikonal_depth(scene.image, scene.mask)
        bowl = eikonal_depth(scene.image, scene.mask, **concave(whole()))
        rim = tuple(np.argwhere(scene.mask)[0])
        centre = (SIZE // 2, SIZE // 2)
        assert dome.depth[centre] > dome.depth[rim]
        assert bowl.depth[centre] < bowl.depth[rim]
        assert bowl.singular_points[0].kind == "min"

    def test_masks_equal_the_regions_they_come_from(self, scenes):
        scene = scenes["bowl"]
        regions = eikonal_depth(scene.image, scene.mask, **concave(whole()))
        everywhere = np.ones((SIZE, SIZE), bool)
        masks = eikonal_depth(scene.image, scene.mask, concave_x=everywhere, concave_y=everywhere)
        np.testing.assert_array_equal(regions.depth, masks.depth)

    def test_a_reference_of_a_given_kind_replaces_the_detected_point(self, scenes):
        scene = scenes["bowl"]
        marked = eikonal_depth(scene.image, scene.mask, **concave(whole()))
        told = eikonal_depth(scene.image, scene.mask, references=[(128, 128, "min")])
        assert len(told.singular_points) == 1
        assert told.singular_points[0].origin == "user" and told.singular_points[0].kind == "min"
        assert (told.singular_points[0].row, told.singular_points[0].col) == (128, 128)
        assert metrics.depth_error(told.depth, marked.depth, scene.mask) < 0.05

    def test_a_reference_takes_its_kind_from_the_regions(self, scenes):
        scene = scenes["bowl"]
        told = eikonal_depth(scene.image, scene.mask, references=[(127, 127)], **concave(whole()))
        assert told.singular_points[0].kind == "min"

    def test_vase_singular_points_and_heights(self, scenes):
        scene = scenes["vase"]
        result = eikonal_depth(scene.image, scene.mask, **concave(NECK))
        kinds = sorted((p.row, p.kind) for p in result.singular_points)
        # lip (top row), neck (saddle), belly: rows 13, ~57, ~158 of the 256 px image
        assert [k for _, k in kinds] == ["max", "saddle", "max"]
        (lip_row, _), (neck_row, _), (belly_row, _) = kinds
        assert lip_row <= 15 and 50 <= neck_row <= 62 and 150 <= belly_row <= 165
        heights = {p.kind + str(p.row < 100): p.height for p in result.singular_points}
        true = {p.kind + str(p.row < 100): scene.depth[p.row, p.col] for p in result.singular_points}
        main = result.singular_points[0]
        for key in heights:
            assert abs(heights[key] - (true[key] - scene.depth[main.row, main.col])) < 0.3

    def test_without_detection_the_brightest_pixel_is_used(self, scenes):
        scene = scenes["sphere"]
        result = eikonal_depth(scene.image, scene.mask, detect=False)
        assert [p.origin for p in result.singular_points] == ["brightest"]
        assert errors(result, scene)[0] <= 0.5

    def test_every_part_gets_a_singular_point_and_its_own_zero(self):
        left = synth.scene("sphere", size=64)
        image = np.hstack([left.image, 0.8 * left.image])  # the right one is dimmer
        mask = np.hstack([left.mask, left.mask])
        result = eikonal_depth(image, mask, albedo=1.0)
        assert result.info["parts"] == 2
        assert np.isfinite(result.depth[mask]).all()
        assert len(result.singular_points) == 2
        assert {p.origin for p in result.singular_points} == {"detected", "brightest"}
        for p in result.singular_points:
            assert result.depth[p.row, p.col] == 0

    def test_noise_is_capped_and_still_finishes(self):
        scene = synth.scene("sphere", size=96, noise=0.05, seed=1)
        result = eikonal_depth(scene.image, scene.mask)
        assert result.info["detected"] > MAX_DETECTED
        assert len(result.singular_points) == MAX_DETECTED
        assert np.isfinite(result.depth[scene.mask]).all()

    def test_smoothing_finds_one_top_under_noise(self):
        scene = synth.scene("sphere", size=128, noise=0.01, seed=2)
        result = eikonal_depth(scene.image, scene.mask, smooth=2.0, tol=1e-2)
        assert len(result.singular_points) == 1
        assert metrics.depth_error(result.depth, scene.depth, scene.mask) < 2.0

    def test_cone_normals_kernel_matches_reference(self, scenes):
        scene = scenes["vase"]
        result = eikonal_depth(scene.image, scene.mask)
        cos = np.where(scene.mask, scene.image / result.albedo, 0.0)
        mask = scene.mask.copy()
        mask[100:103, :] = False  # thin strips and isolated pixels: one-sided and no differences
        mask[60, 128] = True
        mask[59, 127:130] = mask[61, 127:130] = mask[60, 127] = mask[60, 129] = False
        fast = cone_normals(result.depth, mask, cos)
        slow = cone_normals_reference(result.depth, mask, cos)
        assert np.array_equal(np.isnan(fast), np.isnan(slow))
        np.testing.assert_allclose(fast[mask], slow[mask], rtol=0, atol=1e-14)
        np.testing.assert_array_equal(fast[60, 128], [0.0, 0.0, 1.0])

    def test_cone_normals_of_a_plane(self):
        rows, cols = np.mgrid[:6, :7]
        depth = 0.5 * cols - 0.25 * (-rows)  # z = 0.5 x - 0.25 y with y = -row
        mask = np.ones((6, 7), bool)
        slope = np.hypot(0.5, 0.25)
        cos = np.full((6, 7), 1 / np.sqrt(1 + slope**2))
        normals = cone_normals(depth, mask, cos)
        expected = np.array([-0.5, 0.25, 1.0]) / np.sqrt(1 + slope**2)
        np.testing.assert_allclose(normals.reshape(-1, 3), np.tile(expected, (42, 1)), atol=1e-12)


class TestBadInput:
    @pytest.fixture
    def small(self):
        return synth.scene("sphere", size=32)

    @pytest.mark.parametrize(
        "image, message",
        [
            ([[0.5, 0.5], [0.5, 0.5]], "numpy array"),
            (np.zeros((4, 4, 3)), "one channel"),
            (np.array([["a"]]), "numbers"),
        ],
    )
    def test_bad_image(self, image, message):
        with pytest.raises(InputError, match=message):
            eikonal_depth(image, np.ones((4, 4), bool))

    def test_bad_mask(self, small):
        with pytest.raises(InputError, match="mask has shape"):
            eikonal_depth(small.image, small.mask[:-1])
        with pytest.raises(InputError, match="empty"):
            eikonal_depth(small.image, np.zeros_like(small.mask))

    @pytest.mark.parametrize("value, message", [(np.nan, "NaN"), (-0.1, "negative")])
    def test_bad_values_on_the_object(self, small, value, message):
        image = small.image.copy()
        image[16, 16] = value
        with pytest.raises(InputError, match=message):
            eikonal_depth(image, small.mask)

    def test_black_object(self, small):
        with pytest.raises(InputError, match="black"):
            eikonal_depth(np.zeros((32, 32)), small.mask)

    @pytest.mark.parametrize(
        "options, message",
        [
            ({"albedo": 0}, "albedo must be > 0"),
            ({"albedo": np.nan}, "albedo must be a finite number"),
            ({"albedo": "1"}, "albedo must be a finite number"),
            ({"tol": 0}, r"tol must be in \(0, 1\)"),
            ({"tol": 1.0}, r"tol must be in \(0, 1\)"),
            ({"smooth": -1}, "smooth must be >= 0"),
            ({"steep": 0}, "steep must be > 0"),
            ({"detect": "yes"}, "detect must be True or False"),
        ],
    )
    def test_bad_options(self, small, options, message):
        with pytest.raises(InputError, match=message):
            eikonal_depth(small.image, small.mask, **options)

    @pytest.mark.parametrize(
        "references, message",
        [
            ([(0, 0)], "not on the object"),
            ([(99, 3)], "not on the object"),
            ([(16, 16, "peak")], "unknown reference kind"),
            ([(16,)], r"\(row, col\)"),
            ([(16.5, 16)], "whole number"),
            ("16,16", "sequence"),
        ],
    )
    def test_bad_references(self, small, references, message):
        with pytest.raises(InputError, match=message):
            eikonal_depth(small.image, small.mask, references=references)

    @pytest.mark.parametrize(
        "masks, message",
        [
            ({"concave_x": np.ones((5, 5), bool)}, "concave_x has shape"),
            (
                {"concave_x": np.ones((32, 32), bool), "concave_y": np.ones((3, 3), bool)},
                "concave_y has shape",
            ),
            ({"concave_x": "both"}, "concave_x has shape"),
        ],
    )
    def test_bad_concave_masks(self, small, masks, message):
        with pytest.raises(InputError, match=message):
            eikonal_depth(small.image, small.mask, **masks)

    def test_messages_are_one_line(self, small):
        with pytest.raises(InputError) as err:
            eikonal_depth(small.image, small.mask, references=[(0, 0)])
        assert "\n" not in str(err.value)

    @pytest.mark.parametrize(
        "kwargs, message",
        [
            ({"sources": []}, "at least one source"),
            ({"sources": [(0, 0)]}, "not on the mask"),
            ({"sources": [(16, 16)], "values": [0.0, 1.0]}, "one per source"),
            ({"sources": [(16, 16)], "steep": -1}, "steep must be > 0"),
        ],
    )
    def test_bad_arrival_times_input(self, small, kwargs, message):
        cos = small.image / small.image.max()
        with pytest.raises(InputError, match=message):
            arrival_times(cos, small.mask, **kwargs)
        with pytest.raises(InputError, match=message):
            arrival_times_reference(cos, small.mask, **kwargs)


def test_pairwise_distances_stop_early_and_side_by_side_as_one_full_march_each():
    """A kernel against its reference (a private name, deliberately: ``_pairwise_distances``,
    against full marches). The singular points' distances (marches run on threads, each stopping
    once it has reached the nodes after it, one target map shared) equal a full march from each node
    read at the later nodes' pixels (the table is made symmetric from those); a node sharing its
    pixels with a later one is at distance 0 from it."""
    from shadeform.solvers.eikonal.marching import slope_fields
    from shadeform.solvers.eikonal.singular import Node, _pairwise_distances

    s = synth.scene("bumps", size=96)
    c = np.clip(s.image / s.image[s.mask].max(), 0.0, 1.0)
    c[~s.mask] = 0.0
    f, theta = slope_fields(c)
    spots = [(20, 20), (48, 70), (75, 30), (48, 70), (30, 60)]  # the second and fourth coincide
    nodes = [
        Node(pixels=np.array([[r, col], [r, col + 1]]), part=1, kind="max", size=2, top=1.0, origin="user")
        for r, col in spots
    ]
    assert all(s.mask[r, col] and s.mask[r, col + 1] for r, col in spots)
    distance = _pairwise_distances(nodes, f, theta, s.mask, 1.5)
    for a, node in enumerate(nodes):
        full = arrival_times(c, s.mask, [tuple(p) for p in node.pixels])
        for b, other in enumerate(nodes[a + 1 :], start=a + 1):
            assert distance[b, a] == distance[a, b]
            assert distance[a, b] == pytest.approx(
                full[other.pixels[:, 0], other.pixels[:, 1]].min(), rel=1e-12
            )
    assert distance[1, 3] == distance[3, 1] == 0.0
    apart = ~np.eye(5, dtype=bool)
    apart[1, 3] = apart[3, 1] = False
    assert np.all(distance[apart] > 0)
