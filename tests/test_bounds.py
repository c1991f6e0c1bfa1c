"""No depth deeper than its outline allows: shadeform.solvers.bounds and its place in reconstruct."""

from __future__ import annotations

import numpy as np
import pytest

import shadeform
from shadeform import synth
from shadeform.solvers import Solution, Solver
from shadeform.solvers.bounds import GRID_PIXELS, HEADROOM, SPREAD, bound_depth, soft_limit


def _normals_of(depth):
    """Unit normals (H, W, 3) of a height map by central differences (``docs/conventions.md``)."""
    d_row, d_col = np.gradient(depth)
    normals = np.dstack([-d_col, d_row, np.ones_like(depth)])
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def _angles(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def _pitted(size, *, pit, sigma, centre=None):
    """The synthetic sphere of ``size`` with a Gaussian pit ``pit`` pixels deep: its true depth
    (NaN off the mask), the pitted depth and the pitted surface's analytic normals, the mask,
    and the outline's diameter in pixels."""
    scene = synth.scene("sphere", size=size)
    rows, cols = np.mgrid[:size, :size].astype(np.float64)
    r0, c0 = centre if centre is not None else ((size - 1) / 2, (size - 1) / 2)
    bump = pit * np.exp(-((rows - r0) ** 2 + (cols - c0) ** 2) / (2.0 * sigma**2))
    truth = np.where(scene.mask, scene.depth, np.nan)
    depth = truth - bump
    # slopes of the sphere plus those of the pit: dz/dx = -nx / nz, dz/dy = -ny / nz (y = -row)
    nz = scene.normals[..., 2]
    zx = -scene.normals[..., 0] / nz + bump * (cols - c0) / sigma**2
    zy = -scene.normals[..., 1] / nz - bump * (rows - r0) / sigma**2
    normals = np.dstack([-zx, -zy, np.ones_like(zx)])
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[~scene.mask] = np.nan
    return truth, depth, normals, scene.mask, 2 * 0.42 * size


class TestSoftLimit:
    def test_identity_within_the_bound_and_below_its_ceiling_beyond(self):
        values = np.linspace(-50, 50, 2001)
        limited = soft_limit(values, 10.0)
        within = np.abs(values) <= 10.0
        np.testing.assert_array_equal(limited[within], values[within])
        assert np.all(np.abs(limited) < (1 + HEADROOM) * 10.0)
        assert np.all(np.diff(limited) > 0)  # order kept: a deeper pit stays deeper

    def test_smooth_at_the_bound(self):
        # slope 1 on both sides of the bound: no crease where the compression starts
        step = 1e-4
        for bound in (1.0, 37.0):
            below = (soft_limit(bound, bound) - soft_limit(bound - step, bound)) / step
            above = (soft_limit(bound + step, bound) - soft_limit(bound, bound)) / step
            assert below == pytest.approx(1.0) and above == pytest.approx(1.0, abs=1e-3)


class TestWithinTheBound:
    @pytest.mark.parametrize("name", synth.SCENES)
    @pytest.mark.parametrize("size", [64, 160])
    def test_the_synthetic_truths_come_out_as_they_are(self, name, size):
        scene = synth.scene(name, size=size)
        depth = np.where(scene.mask, scene.depth, np.nan)
        result = bound_depth(depth, scene.normals, scene.mask)
        assert not result.applied and result.pixels == 0.0
        assert result.depth is depth and result.normals is scene.normals
        assert result.max_over < 0.8  # the saddle, steepest of them, reaches 0.75

    def test_a_rod_tilted_toward_the_viewer_is_no_sheet(self):
        # the outline's depth spreads over 1.5 times its length (56 degrees), past half its
        # diameter from the middle: the fitted tilt takes it
        scene = synth.scene("cylinder", size=128)
        rows = np.arange(128, dtype=np.float64)[:, None]
        depth = np.where(scene.mask, scene.depth + 1.5 * rows, np.nan)
        result = bound_depth(depth, _normals_of(depth), scene.mask)
        assert not result.applied and result.depth is depth

    def test_the_scale_does_not_matter(self):
        # the bound is in the outline's units: a shape scaled up with its image is judged alike
        small, large = (bound_depth(np.where(s.mask, s.depth, np.nan), s.normals, s.mask) for s in (
            synth.scene("ellipsoid", size=64), synth.scene("ellipsoid", size=256)
        ))  # fmt: skip
        assert small.max_over == pytest.approx(large.max_over, abs=0.05)


class TestPastTheBound:
    def test_a_pit_far_past_the_outline_is_caught_said_and_pulled_back(self):
        truth, depth, normals, mask, diameter = _pitted(96, pit=200.0, sigma=6.0)
        result = bound_depth(depth, normals, mask)
        bound = SPREAD * diameter
        assert result.applied
        assert result.max_over == pytest.approx(200.0 / bound, rel=0.15)  # how far it went
        deep = mask & (truth - depth > bound)
        assert result.pixels == pytest.approx(np.count_nonzero(deep) / np.count_nonzero(mask), rel=0.3)
        # pulled back within the limiter's ceiling of the round shape, and still a pit
        assert np.nanmin(result.depth - truth) >= -(1 + HEADROOM) * bound - 2.0
        centre = (47, 47)
        assert result.depth[centre] < truth[centre] - bound
        # the rest of the sphere is untouched, bit for bit
        rows, cols = np.mgrid[:96, :96]
        far = mask & (np.hypot(rows - 47.5, cols - 47.5) > 6.0 * 6 + 4)
        np.testing.assert_array_equal(result.depth[far], depth[far])
        np.testing.assert_array_equal(result.normals[far], normals[far])

    @pytest.mark.parametrize("slope", [5.0, 40.0])
    def test_a_sheet_stood_on_edge_is_caught_whatever_its_slope(self, slope):
        # a result marched down a wrong slope: the fitted tilt takes it whole, so nothing strays
        # from the fit unless the fit itself is held to the outline's diameter
        scene = synth.scene("sphere", size=128)
        rows = np.arange(128, dtype=np.float64)[:, None]
        depth = np.where(scene.mask, scene.depth - slope * rows, np.nan)
        result = bound_depth(depth, _normals_of(depth), scene.mask)
        rows_in, cols_in = np.nonzero(scene.mask)
        diameter = max(np.ptp(rows_in), np.ptp(cols_in)) + 1
        assert result.applied and result.max_over > 1.0
        # the fit's span (the diameter) plus the limiter's ceiling either side
        assert (
            np.nanmax(result.depth) - np.nanmin(result.depth)
            <= (1 + 2 * (1 + HEADROOM) * SPREAD) * diameter + 2
        )

    @pytest.mark.parametrize("size", [96, 400])  # 400: on a grid, the normals in bands of rows
    def test_the_normals_are_those_of_the_new_depth(self, size):
        # normals that are exactly the depth's differences, so the check reads the bound alone
        _, depth, _, mask, _ = _pitted(size, pit=2.0 * size, sigma=size / 10)
        normals = np.where(mask[..., None], _normals_of(depth), np.nan)
        result = bound_depth(depth, normals, mask)
        moved = mask & (result.depth != depth) & np.isfinite(_normals_of(result.depth)).all(axis=-1)
        assert np.count_nonzero(moved) > 100
        # the old normals describe the pit, not the new depth; the new ones describe it
        assert np.median(_angles(normals, _normals_of(result.depth))[moved]) > 15.0
        assert np.max(_angles(result.normals, _normals_of(result.depth))[moved]) < 0.5
        known = np.isfinite(normals).all(axis=-1)
        np.testing.assert_array_equal(np.isfinite(result.normals).all(axis=-1), known)  # none made up
        assert np.allclose(np.linalg.norm(result.normals[known], axis=-1), 1.0)

    def test_a_large_object_is_bounded_on_a_grid(self):
        # 4 x GRID_PIXELS object pixels: worked out every second pixel, applied to every one
        size = int(np.sqrt(4 * GRID_PIXELS / (np.pi * 0.42**2)))
        truth, depth, normals, mask, diameter = _pitted(size, pit=3.0 * size, sigma=size / 16)
        result = bound_depth(depth, normals, mask)
        assert result.applied and result.max_over > 2.0
        assert np.nanmin(result.depth - truth) >= -(1 + HEADROOM) * SPREAD * diameter - 0.02 * size
        # smooth: no step between neighbours larger than the pit's own slopes gave
        moved = result.depth - depth
        assert np.nanmax(np.abs(np.diff(moved, axis=0))) < 0.1 * size

    def test_a_part_with_no_outline_in_view_is_not_bounded(self):
        # the whole frame is the object: nothing says how deep it may be
        rows = np.arange(40, dtype=np.float64)[:, None]
        depth = np.broadcast_to(-500.0 * (rows / 39) ** 4, (40, 40)).copy()
        result = bound_depth(depth, _normals_of(depth), np.ones((40, 40), dtype=bool))
        assert not result.applied and result.depth is depth


def _solver_of(depth, normals):
    """A registered solver that returns this depth and these normals, whatever the photo."""

    def solve(problem):
        return Solution(np.array(normals), np.array(depth), {})

    return Solver(
        "given", solve, lights="any", integrator=None, depth="given", description="returns what it was given"
    )


class TestInReconstruct:
    def test_a_spiked_result_is_bounded_and_said(self, registries):
        truth, depth, normals, mask, _ = _pitted(96, pit=200.0, sigma=6.0)
        scene = synth.scene("sphere", size=96)
        registries[0].register(_solver_of(depth, normals))
        rec = shadeform.reconstruct(scene.image, mask=mask, solver="given")
        said = rec.info["depth_bounded"]
        assert set(said) == {"pixels", "max_over"} and 0 < said["pixels"] < 0.1 and said["max_over"] > 2
        expected = bound_depth(depth, normals, mask)
        np.testing.assert_allclose(rec.depth, expected.depth, equal_nan=True)
        np.testing.assert_allclose(rec.normals, expected.normals, atol=1e-5, equal_nan=True)  # float32

    def test_a_result_within_it_is_not_touched(self, registries):
        scene = synth.scene("sphere", size=96)
        truth = np.where(scene.mask, scene.depth, np.nan)
        registries[0].register(_solver_of(truth, scene.normals))
        rec = shadeform.reconstruct(scene.image, mask=scene.mask, solver="given")
        assert "depth_bounded" not in rec.info
        np.testing.assert_array_equal(rec.depth, truth)
        np.testing.assert_array_equal(rec.normals, scene.normals.astype(np.float32))
