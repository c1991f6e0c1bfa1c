"""Error measures: hand-computed values, NaN handling, validation."""

from __future__ import annotations

import numpy as np
import pytest

from shadeform.errors import InputError
from shadeform.metrics import angular_error, depth_error, made
from shadeform.synth import surface


def _field(*vectors):
    """A (1, N, 3) normal field from N vectors."""
    return np.array(vectors, dtype=np.float64)[None]


class TestAngularError:
    def test_smoke(self):
        n = _field((0, 0, 1))
        assert angular_error(n, n) == 0.0

    def test_shapes(self):
        _, normals, mask = surface("sphere", size=32)
        out = angular_error(normals, normals, reduce="none")
        assert out.shape == (32, 32)
        assert np.all(out[mask] == 0) and np.isnan(out[~mask]).all()
        assert isinstance(angular_error(normals, normals), float)

    def test_hand_values(self):
        a = _field((1, 0, 0), (0, 0, 1), (0, 0, 2), (1, 0, 0), (0, 0, 1))
        b = _field((0, 1, 0), (0, 1, 1), (0, 3, 3), (-1, 0, 0), (0, 0, 1))
        out = angular_error(a, b, reduce="none")
        np.testing.assert_allclose(out[0], [90, 45, 45, 180, 0], atol=1e-12)
        assert angular_error(a, b) == pytest.approx(72.0)
        assert angular_error(a, b, reduce="median") == pytest.approx(45.0)

    def test_near_parallel_is_exact(self):
        # An arccos of the dot product would return NaN (dot > 1 by rounding) or lose digits.
        u = np.array([1.0, 1.0, 1.0]) / np.sqrt(3)
        assert angular_error(_field(u), _field(u)) == pytest.approx(0.0, abs=1e-12)
        tiny = 1e-7
        v = (np.sin(tiny), 0.0, np.cos(tiny))
        assert angular_error(_field(v), _field((0, 0, 1))) == pytest.approx(np.degrees(tiny), rel=1e-9)

    def test_mask(self):
        a = _field((1, 0, 0), (0, 0, 1))
        b = _field((0, 1, 0), (0, 0, 1))
        assert angular_error(a, b, np.array([[False, True]])) == 0.0
        assert angular_error(a, b, np.array([[True, False]])) == pytest.approx(90.0)

    def test_nan_estimate_inside_fails(self):
        a = _field((np.nan, np.nan, np.nan), (0, 0, 1))
        b = _field((0, 0, 1), (0, 0, 1))
        assert angular_error(a, b) == np.inf
        assert angular_error(_field((0, 0, 0), (0, 0, 1)), b) == np.inf
        out = angular_error(a, b, reduce="none")
        assert np.isnan(out[0, 0]) and out[0, 1] == 0.0
        # Outside the ground truth a NaN estimate does not count.
        b_hole = _field((np.nan, np.nan, np.nan), (0, 0, 1))
        assert angular_error(a, b_hole) == 0.0

    def test_errors(self):
        n = _field((0, 0, 1), (0, 0, 1))
        with pytest.raises(InputError, match="reduce"):
            angular_error(n, n, reduce="max")
        with pytest.raises(InputError, match=r"\(H, W, 3\)"):
            angular_error(n, n[..., :2])
        with pytest.raises(InputError, match="mask shape"):
            angular_error(n, n, np.ones((2, 2), bool))
        with pytest.raises(InputError, match="no pixels"):
            angular_error(n, n, np.zeros((1, 2), bool))
        with pytest.raises(InputError, match="inside the mask"):
            angular_error(n, _field((0, 0, 1), (np.nan, 0, 1)), np.ones((1, 2), bool))


class TestDepthError:
    truth = np.array([[0.0, 1.0], [2.0, 3.0]])

    def test_smoke(self):
        assert depth_error(self.truth, self.truth) == 0.0

    def test_offset_is_free(self):
        assert depth_error(self.truth + 5.0, self.truth) == pytest.approx(0.0, abs=1e-12)
        # Without the fit: RMSE 5 over a range of 3.
        assert depth_error(self.truth + 5.0, self.truth, fit="none") == pytest.approx(500 / 3)

    def test_ten_percent_scale(self):
        est = 1.1 * self.truth
        # Offset fit leaves 0.1 * (t - mean t): RMSE 0.1 * sqrt(1.25), range 3.
        assert depth_error(est, self.truth) == pytest.approx(100 * 0.1 * np.sqrt(1.25) / 3)
        # No fit: RMSE 0.1 * sqrt(mean t^2) = 0.1 * sqrt(3.5).
        assert depth_error(est, self.truth, fit="none") == pytest.approx(10 * np.sqrt(3.5) / 3)
        assert depth_error(est - 7.0, self.truth, fit="scale_offset") == pytest.approx(0.0, abs=1e-10)
        assert depth_error(est, self.truth, fit="scale") == pytest.approx(0.0, abs=1e-12)

    def test_on_scene(self):
        depth, _, mask = surface("vase", size=48)
        assert depth_error(depth - 12.0, depth) == pytest.approx(0.0, abs=1e-10)
        flat = np.where(mask, 0.0, np.nan)
        # A flat guess: RMSE = std of the true depth.
        spread = np.nanmax(depth) - np.nanmin(depth)
        assert depth_error(flat, depth) == pytest.approx(100 * np.nanstd(depth) / spread)

    def test_nan_inside_fails(self):
        est = self.truth.copy()
        est[0, 1] = np.nan
        assert depth_error(est, self.truth) == np.inf
        # ... unless that pixel is outside the evaluated mask.
        mask = np.array([[True, False], [True, True]])
        assert depth_error(est, self.truth, mask) == 0.0
        truth = self.truth.copy()
        truth[0, 1] = np.nan
        assert depth_error(est, truth) == 0.0

    def test_errors(self):
        with pytest.raises(InputError, match="fit must be one of"):
            depth_error(self.truth, self.truth, fit="affine")
        with pytest.raises(InputError, match="constant"):
            depth_error(self.truth, np.ones((2, 2)))
        with pytest.raises(InputError, match=r"\(H, W\)"):
            depth_error(self.truth, self.truth[None])
        with pytest.raises(InputError, match="inside the mask"):
            depth_error(self.truth, np.full((2, 2), np.nan), np.ones((2, 2), bool))
        with pytest.raises(InputError, match="no pixels"):
            depth_error(self.truth, self.truth, np.zeros((2, 2), bool))


class TestMade:
    truth = np.array([[1.0, 2.0], [3.0, 4.0]])

    def test_smoke(self):
        assert made(self.truth, self.truth) == 0.0

    def test_scale_is_free(self):
        assert made(2 * self.truth, self.truth) == pytest.approx(0.0, abs=1e-12)
        assert made(2 * self.truth, self.truth, fit="none") == pytest.approx(2.5)
        # Offset fit: 2t - 2.5 - t = t - 2.5, mean |.| = 1.
        assert made(2 * self.truth, self.truth, fit="offset") == pytest.approx(1.0)

    def test_least_squares_scale(self):
        est = np.array([[1.0, 1.0]])
        truth = np.array([[1.0, 3.0]])
        # a = (1 + 3) / 2 = 2: fitted (2, 2), errors (1, 1).
        assert made(est, truth) == pytest.approx(1.0)
        assert made(np.zeros((1, 2)), truth) == pytest.approx(2.0)

    def test_median_scale(self):
        # ratios truth / est = 3, 1, 2: median 2, fitted (2, 4, 4) against (3, 2, 4)
        est = np.array([[1.0, 2.0, 2.0]])
        truth = np.array([[3.0, 2.0, 4.0]])
        assert made(est, truth, fit="median_scale") == pytest.approx(1.0)
        # least squares gives a different scale: a = (3 + 4 + 8) / 9
        a = 15 / 9
        assert made(est, truth) == pytest.approx(np.mean(np.abs(a * est - truth)))
        # one wild pixel moves the least-squares scale but not the median one
        est = np.array([[1.0, 1.0, 1.0, 1.0, 100.0]])
        truth = np.full((1, 5), 2.0)
        assert made(est, truth, fit="median_scale") == pytest.approx(198 / 5)
        assert made(2 * self.truth, self.truth, fit="median_scale") == pytest.approx(0.0)
        assert made(np.zeros((1, 2)), truth[:, :2], fit="median_scale") == pytest.approx(2.0)
        assert depth_error(3 * self.truth, self.truth, fit="median_scale") == pytest.approx(0.0)

    def test_nan_inside_fails(self):
        est = 2 * self.truth
        est[1, 1] = np.nan
        assert made(est, self.truth) == np.inf
        assert made(est, self.truth, self.truth < 4) == pytest.approx(0.0, abs=1e-12)

    def test_errors(self):
        with pytest.raises(InputError, match="fit"):
            made(self.truth, self.truth, fit="similarity")
        with pytest.raises(InputError, match="shape"):
            made(self.truth, self.truth.ravel())
