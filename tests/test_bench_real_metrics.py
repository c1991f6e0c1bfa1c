"""The scores of ``benchmarks/bench_real.py`` (SIRFS's N-MAE, Z-MAE and geometric mean, in
``benchmarks/real_data.py``) on hand-computed values; no real data needed."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import real_data


def tilted(angle, shape=(4, 5)):
    """Normals ``angle`` radians from +z (toward +x), of length 2 (the scores normalise)."""
    normals = np.zeros(shape + (3,))
    normals[..., 0] = 2 * np.sin(angle)
    normals[..., 2] = 2 * np.cos(angle)
    return normals


def test_n_mae_is_the_mean_angle_in_radians():
    truth = tilted(0.0)
    estimate = tilted(0.3)
    estimate[:2] = tilted(0.1)[:2]  # half the pixels at 0.1 rad, half at 0.3
    where = np.ones(truth.shape[:2], bool)
    assert real_data.n_mae(estimate, truth, where) == pytest.approx(0.2, abs=1e-12)


def test_n_mae_leaves_out_what_is_not_finite_or_not_asked():
    truth = tilted(0.0)
    estimate = tilted(0.25)
    estimate[0, 0] = np.nan  # a hole in the result
    truth[1, 1] = np.nan  # no ground truth there
    estimate[2, 2] = tilted(3.0)[2, 2]
    where = np.ones(truth.shape[:2], bool)
    where[2, 2] = False  # a pixel off the mask does not count, however wrong
    assert real_data.n_mae(estimate, truth, where) == pytest.approx(0.25, abs=1e-12)


def test_z_mae_removes_the_median_offset():
    truth = np.arange(20.0).reshape(4, 5)
    where = np.ones(truth.shape, bool)
    assert real_data.z_mae(truth + 7.5, truth, where) == pytest.approx(0.0, abs=1e-12)
    # d - truth = 5 everywhere but +1 on one pixel and -1 on another: the median is 5 (not the
    # mean, which outliers would move), the error 2 / 20
    depth = truth + 5.0
    depth[0, 0] += 1.0
    depth[3, 4] -= 1.0
    assert real_data.z_mae(depth, truth, where) == pytest.approx(0.1, abs=1e-12)
    # the median is taken over the measured pixels only
    depth[1, :] = np.nan
    where[2, :] = False
    assert real_data.z_mae(depth, truth, where) == pytest.approx(2 / 10, abs=1e-12)


def test_geometric_mean():
    assert real_data.geometric_mean([1.0, 4.0]) == pytest.approx(2.0)
    assert real_data.geometric_mean([0.5, 0.5, 0.5]) == pytest.approx(0.5)
    assert real_data.geometric_mean([0.1, 0.2, 0.4]) == pytest.approx(0.2)


def test_normals_of_a_plane_and_the_degrees_of_a_case():
    rows, cols = np.mgrid[0:6, 0:7].astype(np.float64)
    height = 2.0 * cols - 3.0 * rows  # rises to the right and upward (rows go down)
    expected = np.array([-2.0, -3.0, 1.0]) / np.sqrt(14.0)
    normals = real_data.normals_of_height(height)
    np.testing.assert_allclose(normals, np.broadcast_to(expected, normals.shape), atol=1e-12)
    mask = np.ones(height.shape, bool)
    case = real_data.Case("plane", "mit", height, mask, np.array([0, 0, 1.0]), normals, mask, height)
    flat = np.zeros(normals.shape)
    flat[..., 2] = 1.0
    assert real_data.angular_error(flat, case) == pytest.approx(np.degrees(np.arccos(expected[2])))
