"""Bilateral (discontinuity-preserving) normal integration: synthetic checks, DiLiGenT bar."""

from pathlib import Path

import numpy as np
import pytest

from helpers.surfaces import l_shaped_mask, normals_of, pixel_xy
from shadeform.errors import InputError
from shadeform.integration._multigrid import PairHierarchy
from shadeform.integration.bilateral import MIN_SCALE, contour_scale, integrate_bilateral
from shadeform.integration.poisson import integrate_poisson

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "diligent-normals"


def offset_error(depth, truth, mask):
    d = depth[mask] - truth[mask]
    return np.abs(d - d.mean()).max()


class TestOrthographic:
    def test_plane_is_exact_on_a_nonconvex_mask(self):
        mask = l_shaped_mask()
        x, y = pixel_xy(mask.shape)
        truth = 0.3 * x - 0.7 * y
        n = normals_of(np.full(mask.shape, 0.3), np.full(mask.shape, -0.7))
        z = integrate_bilateral(n, mask).depth
        assert offset_error(z, truth, mask) < 1e-6
        assert np.isnan(z[~mask]).all()

    def test_paraboloid_is_exact(self):
        # equally weighted one-sided differences are the trapezoid rule, exact for quadratics
        # when every equation has the same scale (n_z = 1: unnormalised normals); with unit
        # normals the n_z^2 equation weights leave a small bias.
        mask = np.zeros((40, 50), bool)
        mask[3:37, 4:46] = True
        mask[15:22, 20:30] = False  # a hole
        x, y = pixel_xy(mask.shape)
        x, y = x - 25, y + 20
        truth = 0.01 * x**2 + 0.02 * y**2
        n = np.stack([-0.02 * x, -0.04 * y, np.ones(mask.shape)], axis=-1)
        uniform = integrate_bilateral(n, mask, iterations=0, cg_tol=1e-10).depth
        z = integrate_bilateral(n, mask).depth
        assert offset_error(uniform, truth, mask) < 1e-6
        # one-sided differences on a curved surface are not equal, so the weights leave 1/2
        # a little (BiNI's semi-smooth model): a small, bounded bias
        assert offset_error(z, truth, mask) < 0.01
        unit = n / np.linalg.norm(n, axis=-1, keepdims=True)
        assert offset_error(integrate_bilateral(unit, mask).depth, truth, mask) < 0.02

    def test_uniform_solution_is_the_weighted_least_squares_one(self):
        # iterations=0 with nz = 1 everywhere is plain least squares with trapezoid steps
        mask = l_shaped_mask()
        rng = np.random.default_rng(0)
        zx, zy = rng.normal(0, 0.02, mask.shape), rng.normal(0, 0.02, mask.shape)
        n = np.stack([-zx, -zy, np.ones(mask.shape)], axis=-1)  # not unit: nz = 1
        z = integrate_bilateral(n, mask, iterations=0, cg_tol=1e-10).depth
        ref = integrate_poisson(n, mask, tol=1e-12)
        assert offset_error(z, ref, mask) < 1e-6

    def test_floating_hemisphere_keeps_both_surfaces_undistorted(self):
        # a hemisphere floating above a plane: a depth jump all round its rim. Least squares
        # bends the sphere and the plane towards each other; bilateral weights let them apart.
        shape = (80, 80)
        x, y = pixel_xy(shape)
        x, y = x - 40, y + 40
        R = 25.0
        rho2 = x**2 + y**2
        inside = rho2 < (R - 0.5) ** 2
        zs = np.sqrt(np.maximum(R**2 - rho2, 0))
        n = np.zeros((*shape, 3))
        n[..., 2] = 1
        n[inside] = np.stack([x[inside], y[inside], zs[inside]], -1) / R
        truth = np.where(inside, zs + 5.0, 0.0)
        mask = np.ones(shape, bool)

        def shape_error(d):  # each surface after fitting its own offset
            return (
                sum(np.abs((d - truth)[reg] - (d - truth)[reg].mean()).sum() for reg in (inside, ~inside))
                / mask.sum()
            )

        ls = shape_error(integrate_bilateral(n, mask, iterations=0).depth)
        bi = shape_error(integrate_bilateral(n, mask).depth)
        assert bi < 0.8 * ls

    def test_origin_sets_zero(self):
        mask = l_shaped_mask()
        n = normals_of(np.full(mask.shape, 0.3), np.zeros(mask.shape))
        z = integrate_bilateral(n, mask, origin=(25, 30)).depth
        assert z[25, 30] == 0.0


class TestPerspective:
    def render_sphere(self, K, shape=(120, 160), centre=(0.1, -0.05, 3.0), R=1.0):
        """Depth and normals (project frame) of a sphere seen by a pinhole camera."""
        v, u = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
        rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(shape)], -1)
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        c = np.asarray(centre)
        bq = rays @ c
        disc = bq**2 - (c @ c - R**2)
        mask = disc > 0.05
        t = bq - np.sqrt(np.maximum(disc, 0))
        P = rays * t[..., None]
        ncv = (P - c) / R  # OpenCV frame: x right, y down, z forward
        n = np.stack([ncv[..., 0], -ncv[..., 1], -ncv[..., 2]], -1)
        n[~mask] = np.nan
        return P[..., 2], n, mask

    @pytest.mark.parametrize("iterations", [0, 150])
    def test_sphere_depth_up_to_scale(self, iterations):
        K = np.array([[300.0, 0, 70], [0, 280.0, 65], [0, 0, 1]])
        Z, n, mask = self.render_sphere(K)
        z = integrate_bilateral(n, mask, K=K, iterations=iterations).depth
        s = np.sum(z[mask] * Z[mask]) / np.sum(z[mask] ** 2)
        assert np.abs(s * z[mask] - Z[mask]).mean() < 1e-4 * Z[mask].mean()
        assert np.isnan(z[~mask]).all() and (z[mask] > 0).all()

    def test_tilted_plane_is_exact(self):
        K = np.array([[500.0, 0, 40], [0, 500.0, 30], [0, 0, 1]])
        shape = (60, 80)
        v, u = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
        a, b, Z0 = 0.3, -0.2, 4.0  # Z = Z0 + a X + b Y (OpenCV frame)
        xb, yb = (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]
        Z = Z0 / (1 - a * xb - b * yb)
        ncv = np.array([a, b, -1.0]) / np.linalg.norm([a, b, -1.0])
        n = np.broadcast_to(np.array([ncv[0], -ncv[1], -ncv[2]]), (*shape, 3)).copy()
        mask = l_shaped_mask(shape)
        z = integrate_bilateral(n, mask, K=K).depth
        s = np.sum(z[mask] * Z[mask]) / np.sum(z[mask] ** 2)
        np.testing.assert_allclose(s * z[mask], Z[mask], rtol=1e-6)


def disc(radius, pad=6, offset=(0.17, 0.31)):
    """A disc mask of the given radius in pixels (centre off the pixel grid) and the distance of
    every pixel centre from its centre."""
    size = int(2 * radius) + 2 * pad
    r, c = np.mgrid[0:size, 0:size].astype(float)
    rho = np.hypot(r - size / 2 - offset[0], c - size / 2 - offset[1])
    return rho < radius, rho


class TestContourScale:
    @pytest.mark.parametrize("radius", [40.0, 20.0])
    def test_floor_is_the_mean_rim_normal_of_a_sphere(self, radius):
        # a sphere of radius R pixels: its outermost pixel centres lie 0-1 pixel inside the
        # silhouette, with n_z from 0 to about sqrt(2 / R); the floor is their mean, at either
        # resolution
        from scipy import ndimage

        mask, rho = disc(radius)
        rim = mask & ~ndimage.binary_erosion(mask)
        nz = np.sqrt(1.0 - (rho[rim] / radius) ** 2)
        floor = contour_scale(mask)
        assert np.ptp(floor[mask]) == 0.0
        assert np.percentile(nz, 25) < floor[mask][0] < np.percentile(nz, 75)
        # the rim pixels of a digital disc are not spread exactly uniformly over 0-1 pixel
        assert abs(floor[mask][0] / nz.mean() - 1.0) < 0.15

    def test_floor_is_the_mean_over_one_pixel(self):
        # the closed form against the mean of n_z over t in (0, 1) at the mask's own R
        from scipy import ndimage

        mask, _ = disc(30.0)
        R = ndimage.distance_transform_edt(np.pad(mask, 1)).max() - 0.5
        t = (np.arange(100000) + 0.5) / 100000
        expect = np.mean(np.sqrt(1.0 - (1.0 - t / R) ** 2))
        np.testing.assert_allclose(contour_scale(mask)[mask], expect, rtol=1e-6)

    def test_halving_the_resolution_raises_the_floor_by_sqrt2(self):
        # the slope cap follows the sampling, as the rim normals do: R halves, n_z at half a
        # pixel in grows by sqrt(2)
        fine, _ = disc(48.0)
        coarse = fine.reshape(fine.shape[0] // 2, 2, fine.shape[1] // 2, 2).all(axis=(1, 3))
        ratio = contour_scale(coarse)[coarse].min() / contour_scale(fine)[fine].min()
        assert abs(ratio - np.sqrt(2.0)) < 0.05

    def test_each_part_has_its_own_floor(self):
        big, _ = disc(30.0)
        small, _ = disc(6.0)
        h, w = big.shape
        mask = np.zeros((h, w + small.shape[1] + 4), bool)
        mask[:h, :w] = big
        mask[: small.shape[0], -small.shape[1] :] = small
        mask[-1, w + 1] = True  # a single pixel (no equations): R = 1/2, mean n_z pi / 4
        floor = contour_scale(mask)
        on_big, on_small = floor[:, :w][big], floor[:, -small.shape[1] :][mask[:, -small.shape[1] :]]
        assert on_big.max() < on_small.min()
        np.testing.assert_allclose(on_big, (2.0 / 3.0) * np.sqrt(2.0 / 30.0), rtol=0.05)
        assert floor[-1, w + 1] == pytest.approx(np.pi / 4)
        assert (floor[~mask] == 1.0).all()

    def test_default_cap_is_one_angle_at_any_resolution(self):
        # issue 36: the default slope cap is an angle (MIN_SCALE), not the pixel-radius rule of
        # contour_scale, which moved with the image's resolution (a sphere seen at 2.5 times the
        # resolution had its cap lowered by sqrt(2.5)) and raised the error on data it was not
        # chosen on (benchmarks/results/bilateral-generalise.md)
        for scale in (1.0, 2.5):
            K = np.array([[300.0 * scale, 0, 70 * scale], [0, 280.0 * scale, 65 * scale], [0, 0, 1]])
            shape = (int(120 * scale), int(160 * scale))
            _, n, mask = TestPerspective().render_sphere(K, shape=shape)
            # the outermost ring as grazing as a rim pixel's normal can be, so the cap acts
            from scipy import ndimage

            rim = mask & ~ndimage.binary_erosion(mask)
            n[rim, 2] = 0.02
            n[rim] /= np.linalg.norm(n[rim], axis=-1, keepdims=True)
            default = integrate_bilateral(n, mask, K=K).depth
            np.testing.assert_array_equal(
                default, integrate_bilateral(n, mask, K=K, min_scale=MIN_SCALE).depth
            )
            assert not np.array_equal(default, integrate_bilateral(n, mask, K=K, min_scale=0.9).depth)


class TestInputs:
    def test_bad_inputs_raise(self):
        mask = l_shaped_mask()
        n = normals_of(np.zeros(mask.shape), np.zeros(mask.shape))
        with pytest.raises(InputError):
            integrate_bilateral(n[..., :2], mask)
        with pytest.raises(InputError):
            integrate_bilateral(n, np.zeros_like(mask))
        with pytest.raises(InputError):
            integrate_bilateral(n, mask, K=np.eye(2))
        with pytest.raises(InputError):
            integrate_bilateral(n, mask, sharpness=0.0)
        with pytest.raises(InputError):
            integrate_bilateral(n, mask, iterations=-1)
        bad = n.copy()
        bad[5, 5] = np.nan
        with pytest.raises(InputError):
            integrate_bilateral(bad, mask)
        with pytest.raises(InputError):
            integrate_bilateral(n, mask, origin=(0, 0))
        for bad_scale in (0.0, 1.5, np.nan):
            with pytest.raises(InputError):
                integrate_bilateral(n, mask, min_scale=bad_scale)


def test_pair_hierarchy_matches_a_direct_solve():
    """A kernel against its reference (a name of a private module, deliberately): the multigrid
    ``_multigrid.PairHierarchy`` solves the weighted system as a direct sparse solve does."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    rng = np.random.default_rng(1)
    mask = l_shaped_mask((33, 41))
    h, w = mask.shape
    px = np.where(np.pad(mask[:, :-1] & mask[:, 1:], ((0, 0), (0, 1))), rng.uniform(0.01, 2.0, (h, w)), 0.0)
    py = np.where(np.pad(mask[:-1] & mask[1:], ((0, 1), (0, 0))), rng.uniform(0.01, 2.0, (h, w)), 0.0)
    b = np.where(mask, rng.normal(size=(h, w)), 0.0)
    b[mask] -= b[mask].mean()
    hier = PairHierarchy(mask, px, py)
    x, its, res = hier.solve_pairs(b, np.zeros((h, w)), tol=1e-10, maxiter=200)
    assert res < 1e-9
    index = -np.ones((h, w), int)
    index[mask] = np.arange(mask.sum())
    r, c = np.nonzero(px)
    r2, c2 = np.nonzero(py)
    a_ = np.r_[index[r, c], index[r2, c2]]
    b_ = np.r_[index[r, c + 1], index[r2 + 1, c2]]
    wts = np.r_[px[r, c], py[r2, c2]]
    n = mask.sum()
    D = sp.csr_matrix(
        (
            np.r_[-np.ones(len(a_)), np.ones(len(a_))],
            (np.r_[np.arange(len(a_)), np.arange(len(a_))], np.r_[a_, b_]),
        ),
        shape=(len(a_), n),
    )
    A = (D.T @ sp.diags(wts) @ D).tocsc()
    ref = np.zeros(n)
    ref[1:] = spla.spsolve(A[1:, 1:], b[mask][1:])
    got = x[mask]
    np.testing.assert_allclose(got - got.mean(), ref - ref.mean(), atol=1e-7)


#: Published BiNI (k = 2) MADE in mm on DiLiGenT (shared/data/README.md); BiNI's evaluation
#: fits the scale by the median depth ratio, so the bar is measured the same way.
BINI = {"bear": 0.334, "buddha": 1.098, "cat": 0.074, "cow": 0.058, "pot1": 0.635, "reading": 0.257}
#: Where the default slope cap is behind BiNI's published figure: none with the constant angle
#: (benchmarks/results/diligent.md, column 0.12: cat 0.073 against 0.074); the pixel-radius rule of
#: 2026-11-27 was behind on cat (0.078).
BEHIND: set[str] = set()


@pytest.mark.skipif(not DATA.is_dir(), reason=f"DiLiGenT normals not found at {DATA}")
@pytest.mark.parametrize(
    "name",
    [
        pytest.param(
            name,
            marks=pytest.mark.xfail(strict=True, reason="4 % behind BiNI: the paw's depth jump (issue 12)"),
        )
        if name in BEHIND
        else name
        for name in sorted(BINI)
    ],
)
def test_diligent_made(name):
    from shadeform.io.images import load_mask
    from shadeform.io.maps import load_normal_map
    from shadeform.metrics import made

    folder = DATA / name
    mask = load_mask(folder / "mask.png")
    normals = load_normal_map(folder / "normal_map.png", mask=mask)
    K = np.loadtxt(folder / "K.txt")
    gt = np.load(folder / "depth_gt.npz")["depth_gt"].astype(np.float64)
    depth = integrate_bilateral(normals, mask, K=K).depth
    # issue 3's bar, under the protocol of the published figures (benchmarks/results/diligent.md)
    assert made(depth, gt, mask, fit="median_scale") <= BINI[name]


@pytest.mark.skipif(not DATA.is_dir(), reason=f"DiLiGenT normals not found at {DATA}")
def test_published_figures_fit_the_scale_by_median_ratio():
    """The benchmark's re-run of BiNI gives the published reading figure under the median-ratio
    scale, and a higher one under least squares: the protocol the bar is measured by."""
    import sys

    from shadeform.io.images import load_mask
    from shadeform.io.maps import load_normal_map
    from shadeform.metrics import made

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_diligent import bini_rerun

    folder = DATA / "reading"
    mask = load_mask(folder / "mask.png")
    normals = load_normal_map(folder / "normal_map.png", mask=mask)
    K = np.loadtxt(folder / "K.txt")
    gt = np.load(folder / "depth_gt.npz")["depth_gt"].astype(np.float64)
    depth = bini_rerun(normals, mask, K)
    assert abs(made(depth, gt, mask, fit="median_scale") - BINI["reading"]) < 0.001
    assert made(depth, gt, mask) > BINI["reading"] + 0.02
