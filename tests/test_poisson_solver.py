"""The fast masked Poisson solver (multigrid-preconditioned CG) against the exact reference."""

import importlib
import pkgutil
from pathlib import Path

import numba
import numpy as np
import pytest

from shadeform.errors import InputError
from shadeform.integration import _multigrid
from shadeform.integration.poisson import (
    integrate_poisson,
    poisson_integrator,
    poisson_integrator_reference,
)

DILIGENT = Path(__file__).resolve().parents[2] / "shared" / "data" / "diligent-normals"


def bumpy_normals(shape, seed=0, noise=0.15):
    """A sphere-like field plus noise: not integrable, so the least-squares answer is not trivial."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    radius = 0.55 * max(shape)
    a = (cols - shape[1] / 2) / radius
    b = -(rows - shape[0] / 2) / radius
    n = np.stack([a, b, np.sqrt(np.clip(1 - a**2 - b**2, 0.02, 1))], axis=-1)
    n += noise * rng.normal(size=n.shape)
    n[..., 2] = np.abs(n[..., 2]) + 0.05
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def disk(n=96):
    rows, cols = np.mgrid[0:n, 0:n]
    return np.hypot(rows - n / 2 + 0.5, cols - n / 2 + 0.5) < 0.45 * n


def annulus(n=96):
    rows, cols = np.mgrid[0:n, 0:n]
    r = np.hypot(rows - n / 2 + 0.5, cols - n / 2 + 0.5)
    return (r < 0.45 * n) & (r > 0.2 * n)


def l_shape(shape=(77, 61)):
    mask = np.zeros(shape, bool)
    mask[3:74, 4:20] = True
    mask[55:74, 4:58] = True
    return mask


def two_parts(shape=(90, 101)):
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    big = np.hypot(rows - 40, cols - 40) < 33
    small = np.hypot(rows - 75, cols - 85) < 9
    return big | small


def bridges_and_islands(shape=(83, 97)):
    mask = np.zeros(shape, bool)
    mask[5:40, 5:40] = True
    mask[50:80, 55:95] = True
    mask[20, 40:75] = True  # 1-pixel bridge, horizontal
    mask[20:50, 74] = True  # and vertical, into the second block
    mask[45:50, 10:12] = True  # a 2-pixel-wide stub of its own
    mask[[2, 60, 81, 44], [90, 10, 2, 60]] = True  # isolated pixels
    mask[0, 0] = mask[0, 96] = mask[82, 96] = True  # corners
    mask[70, 20:23] = True  # a 3-pixel segment
    return mask


MASKS = {
    "disk": disk,
    "annulus": annulus,
    "l_shape": l_shape,
    "two_parts": two_parts,
    "bridges_and_islands": bridges_and_islands,
}


def weights_for(kind, normals):
    shape = normals.shape[:2]
    if kind == "uniform":
        return None
    if kind == "random":
        return np.random.default_rng(7).uniform(1e-4, 1.0, shape)
    if kind == "nz4":  # what the refinement uses: near 0 at the silhouette
        return np.clip(normals[..., 2], 0, 1) ** 4
    raise ValueError(kind)


def assert_matches_reference(mask, normals, weights=None, rel=1e-6):
    fast = poisson_integrator(mask, weights=weights)(normals)
    exact = poisson_integrator_reference(mask, weights=weights)(normals)
    np.testing.assert_array_equal(np.isnan(fast), ~mask)
    np.testing.assert_array_equal(np.isnan(exact), ~mask)
    span = np.nanmax(exact) - np.nanmin(exact)
    assert span > 0
    err = np.nanmax(np.abs(fast - exact))
    assert err <= rel * span, f"max |fast - exact| = {err:.3g}, {err / span:.3g} of the depth range"
    return fast, exact


class TestAgainstReference:
    @pytest.mark.parametrize("weights", ["uniform", "random", "nz4"])
    @pytest.mark.parametrize("name", sorted(MASKS))
    def test_masks_and_weights(self, name, weights):
        mask = MASKS[name]()
        normals = bumpy_normals(mask.shape, seed=len(name))
        assert_matches_reference(mask, normals, weights_for(weights, normals))

    @pytest.mark.parametrize(
        "shape", [(1, 1), (1, 2), (2, 1), (1, 37), (40, 1), (2, 2), (3, 5), (17, 16), (16, 17), (33, 65)]
    )
    def test_small_and_odd_grids(self, shape):
        mask = np.ones(shape, bool)
        normals = bumpy_normals(shape, seed=3)
        fast = poisson_integrator(mask)(normals)
        exact = poisson_integrator_reference(mask)(normals)
        np.testing.assert_allclose(fast, exact, atol=1e-7 * max(1.0, np.ptp(exact)))

    def test_mask_touching_every_border(self):
        mask = np.ones((50, 64), bool)
        mask[20:30, 20:40] = False
        normals = bumpy_normals(mask.shape, seed=5)
        assert_matches_reference(mask, normals, weights_for("random", normals))

    def test_sparse_random_mask(self):
        # many tiny parts and tortuous paths: the hardest case for geometric coarsening
        mask = np.random.default_rng(2).random((64, 64)) < 0.7
        normals = bumpy_normals(mask.shape, seed=9)
        assert_matches_reference(mask, normals)

    def test_pixels_of_weight_zero_are_parts_of_their_own(self):
        mask = disk(48)
        normals = bumpy_normals(mask.shape, seed=4)
        weights = np.ones(mask.shape)
        weights[24, :] = 0.0  # a zero-weight row cuts the disk in two
        weights[5, 24] = 0.0
        fast, exact = assert_matches_reference(mask, normals, weights)
        assert (fast[24][mask[24]] == 0).all() and fast[5, 24] == 0
        for part in (np.arange(48)[:, None] < 24, np.arange(48)[:, None] > 24):
            inside = mask & part & (weights > 0)
            assert abs(fast[inside].mean()) < 1e-9 * np.ptp(fast[inside])

    def test_normals_with_nan_outside_and_steep_inside(self):
        # slopes are taken as in shadeform.integration._slopes.slopes: NaN outside the mask, n_z
        # clipped to MIN_NZ, NaN components inside read as 0 (x, y) and 1 (z)
        mask = annulus(64)
        normals = bumpy_normals(mask.shape, seed=6)
        normals[~mask] = np.nan
        normals[30, 5] = [1.0, 0.0, 0.0]  # n_z = 0: slope capped
        normals[40, 8] = [0.9, -0.1, 0.01]
        normals[33, 60, 0] = np.nan
        assert_matches_reference(mask, normals)

    def test_float32_normals(self):
        mask = l_shape()
        normals = bumpy_normals(mask.shape, seed=8).astype(np.float32)
        assert_matches_reference(mask, normals)

    @pytest.mark.skipif(not DILIGENT.is_dir(), reason=f"DiLiGenT normal maps not found at {DILIGENT}")
    @pytest.mark.parametrize("weights", ["uniform", "nz4"])
    def test_diligent_normal_maps(self, weights):
        from shadeform.io.images import load_mask
        from shadeform.io.maps import load_normal_map

        objects = sorted(p for p in DILIGENT.iterdir() if (p / "normal_map.png").is_file())
        assert objects, f"no */normal_map.png under {DILIGENT}"
        for obj in objects:
            mask = load_mask(obj / "mask.png")
            normals = load_normal_map(obj / "normal_map.png", mask=mask)
            mask &= np.isfinite(normals).all(axis=-1)
            assert_matches_reference(mask, normals, weights_for(weights, np.nan_to_num(normals)))


class TestSemantics:
    def test_integrable_field_is_recovered_exactly(self):
        mask = np.ones((40, 70), bool)
        rows, cols = np.mgrid[0:40, 0:70].astype(float)
        x, y = cols, -rows
        truth = 0.01 * x**2 + 0.02 * y**2 - 0.005 * x * y
        zx, zy = 0.02 * x - 0.005 * y, 0.04 * y - 0.005 * x
        n = np.stack([-zx, -zy, np.ones_like(zx)], axis=-1)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        z = integrate_poisson(n, mask, origin=(20, 35))
        np.testing.assert_allclose(z, truth - truth[20, 35], atol=1e-6)

    def test_each_part_has_mean_zero_and_isolated_pixels_are_zero(self):
        mask = bridges_and_islands()
        from scipy import ndimage

        labels, count = ndimage.label(mask)
        z = poisson_integrator(mask)(bumpy_normals(mask.shape))
        for k in range(1, count + 1):
            part = labels == k
            if part.sum() == 1:
                assert z[part][0] == 0.0
            else:
                assert abs(z[part].mean()) < 1e-9 * max(1.0, np.ptp(z[part]))

    def test_origin_shifts_to_zero(self):
        mask = two_parts()
        normals = bumpy_normals(mask.shape)
        base = integrate_poisson(normals, mask)
        shifted = integrate_poisson(normals, mask, origin=(40, 40))
        assert shifted[40, 40] == 0.0
        np.testing.assert_allclose(shifted, base - base[40, 40], atol=1e-12)

    def test_weight_scale_does_not_matter(self):
        mask = annulus(64)
        normals = bumpy_normals(mask.shape, seed=1)
        w = weights_for("random", normals)
        a = poisson_integrator(mask, weights=w)(normals)
        b = poisson_integrator(mask, weights=w * 1e12)(normals)
        c = poisson_integrator(mask, weights=w * 1e-12)(normals)
        np.testing.assert_allclose(b, a, atol=1e-7 * np.nanmax(np.abs(a)))
        np.testing.assert_allclose(c, a, atol=1e-7 * np.nanmax(np.abs(a)))

    def test_set_up_once_solve_many(self):
        # the closure keeps work arrays between solves: no state may leak from one to the next
        mask = two_parts()
        solve = poisson_integrator(mask, weights=weights_for("random", bumpy_normals(mask.shape)))
        first = solve(bumpy_normals(mask.shape, seed=1))
        other = solve(bumpy_normals(mask.shape, seed=2))
        again = solve(bumpy_normals(mask.shape, seed=1))
        np.testing.assert_array_equal(first, again)
        assert np.nanmax(np.abs(first - other)) > 0.1
        assert 0 < solve.info["iterations"] <= 30 and solve.info["residual"] <= 1e-8

    def test_tolerance_is_honoured(self):
        mask = disk(64)
        normals = bumpy_normals(mask.shape)
        loose = poisson_integrator(mask, tol=1e-3)
        tight = poisson_integrator(mask, tol=1e-12)
        loose(normals)
        tight(normals)
        assert loose.info["residual"] <= 1e-3 and tight.info["residual"] <= 1e-12
        assert loose.info["iterations"] < tight.info["iterations"]

    def test_one_thread_and_two_agree(self):
        mask = disk(256)  # big enough for the parallel kernels
        normals = bumpy_normals(mask.shape)
        before = numba.get_num_threads()
        try:
            numba.set_num_threads(1)
            one = poisson_integrator(mask)(normals)
            numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
            two = poisson_integrator(mask)(normals)
        finally:
            numba.set_num_threads(before)
        np.testing.assert_allclose(one, two, atol=1e-6 * np.nanmax(np.abs(one)))

    def test_multigrid_keeps_the_iteration_count_low(self):
        # a convergence-rate regression guard: about 7 iterations whatever the size
        for n in (64, 256):
            solve = poisson_integrator(disk(n))
            solve(bumpy_normals((n, n)))
            assert solve.info["iterations"] <= 12


class TestInput:
    def test_empty_mask_gives_all_nan(self):
        z = poisson_integrator(np.zeros((5, 6), bool))(np.zeros((5, 6, 3)))
        assert z.shape == (5, 6) and np.isnan(z).all()

    def test_bad_weights(self):
        mask = disk(16)
        for bad in (-np.ones(mask.shape), np.full(mask.shape, np.nan), np.full(mask.shape, np.inf)):
            with pytest.raises(InputError, match="weights"):
                poisson_integrator(mask, weights=bad)
        with pytest.raises(InputError, match="shape"):
            poisson_integrator(mask, weights=np.ones((3, 3)))
        # off the mask anything goes
        w = np.ones(mask.shape)
        w[~mask] = np.nan
        poisson_integrator(mask, weights=w)

    def test_bad_normals_shape(self):
        solve = poisson_integrator(disk(16))
        with pytest.raises(InputError, match="normals"):
            solve(np.zeros((16, 15, 3)))


class TestPixelAndPairWeights:
    def test_the_same_operator_gives_the_same_depth(self):
        """A kernel against its reference (a private module, deliberately): ``_multigrid``'s pair
        solver (``PairHierarchy``, the bilateral integrator's) gives the depth of its pixel solver
        (``Hierarchy``, the Poisson integrator's) on the one operator both stand for."""
        # pixel weights and the pair weights they imply (the smaller of two) run the one CG
        mask = two_parts()
        normals = bumpy_normals(mask.shape, seed=11)
        w = np.where(mask, weights_for("random", normals), 0.0)
        px = np.zeros(mask.shape)
        py = np.zeros(mask.shape)
        px[:, :-1] = np.minimum(w[:, :-1], w[:, 1:])
        py[:-1] = np.minimum(w[:-1], w[1:])
        depths = []
        for hierarchy in (_multigrid.Hierarchy(mask, w, w.max()), _multigrid.PairHierarchy(mask, px, py)):
            out = np.full(mask.shape, np.nan)
            iterations, residual = hierarchy.solve(normals, 0, 0, 0.05, out, tol=1e-10, maxiter=100)
            assert residual <= 1e-10 and iterations < 30
            depths.append(out)
        np.testing.assert_allclose(depths[1], depths[0], atol=1e-8 * np.nanmax(np.abs(depths[0])))


def test_numba_kernels_are_cached():
    """Kernels tested as such (a private module, deliberately: every compiled kernel of
    ``_multigrid``). Every compiled kernel caches its machine code on disk (compiled once, not per
    process)."""
    prefix = _multigrid.__name__ + "."
    modules = [importlib.import_module(m.name) for m in pkgutil.iter_modules(_multigrid.__path__, prefix)]
    kernels = {
        f.py_func.__qualname__ + f.py_func.__module__: f
        for mod in modules
        for f in vars(mod).values()
        if isinstance(f, numba.core.registry.CPUDispatcher)
    }
    assert len(kernels) > 20
    for kernel in kernels.values():
        assert type(kernel._cache).__name__ != "NullCache", kernel.__name__
