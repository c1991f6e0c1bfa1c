"""The "photo" solver: the silhouette's shape refined by robust shading, on renders and real photos."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import minimize, rosen, rosen_der

from shadeform import available_solvers, metrics, reconstruct, synth
from shadeform.solvers.lbfgs import descend, two_loop
from shadeform.solvers.photo import concave_start, photo_depth, response_curve, silhouette_depth
from shadeform.solvers.photo.energy import _Level
from shadeform.solvers.photo.pyramid import _Basis


def test_silhouette_depth_is_a_sphere_for_a_disc():
    size, radius = 161, 60.0
    rows, cols = np.mgrid[:size, :size] - size // 2
    r2 = rows**2 + cols**2
    mask = r2 < radius**2
    depth = silhouette_depth(mask)
    truth = np.sqrt(np.maximum(radius**2 - r2, 0.0))
    inner = r2 < (0.8 * radius) ** 2
    # the discrete outline sits about half a pixel off the disc's: under 2 % of the height
    assert np.max(np.abs(depth - truth)[inner]) < 0.02 * radius
    assert depth[~mask].max() == 0.0


@pytest.mark.parametrize("light", [(0.0, 0.0, 1.0), (0.5, 0.3, 0.81)])
def test_compiled_energy_is_the_reference(light):
    """A compiled kernel against its reference (a private name, deliberately): a pyramid level's
    (``_Level``) compiled energy and gradient are the reference's, every term active."""
    # a rough state (every term active: shadows, both ends of the curve, creases, the outline)
    scene = synth.scene("vase", size=48, light=light, noise=0.02)
    light = np.asarray(scene.light)
    # at a spacing other than 1, so that the weights' scaling is checked too
    level = _Level(np.where(scene.mask, scene.image, 0.0), scene.mask, light, spacing=1.6)
    rng = np.random.default_rng(3)
    state = rng.normal(0.0, 0.5, level.unknowns)
    state[: level.n] += silhouette_depth(scene.mask)[scene.mask]
    shading = level.normals(level.depth(state)) @ light
    level.values[rng.choice(level.n, 3, replace=False)] = (1e3, 1e60, 1e120)  # wild outliers
    for curve in (response_curve(shading, level.values), np.array([[0.0, 0.0], [1.0, 0.9]])):
        energy, gradient = level.energy(state, curve)
        expected, expected_gradient = level.energy_reference(state, curve)
        assert energy == pytest.approx(expected, rel=1e-12)
        np.testing.assert_allclose(
            gradient, expected_gradient, rtol=1e-9, atol=1e-12 * np.abs(expected_gradient).max()
        )
    # the spacing reaches the energy: the same state weighs differently at the reference spacing
    level.spacing = 1.0
    assert level.energy(state, curve)[0] != pytest.approx(energy, rel=1e-6)
    level.spacing = 1.6
    # and the reference is the energy's gradient (central differences on a few coefficients)
    step = 1e-6
    for i in rng.choice(level.unknowns, 5, replace=False):
        bump = np.zeros(level.unknowns)
        bump[i] = step
        numeric = (
            level.energy_reference(state + bump, curve)[0] - level.energy_reference(state - bump, curve)[0]
        ) / (2 * step)
        assert numeric == pytest.approx(expected_gradient[i], rel=1e-4, abs=1e-9)


def _bilinear_matrix(mask, factor):
    """The obvious reference for one coarse grid of the hierarchical basis: (object pixels,
    coarse cells) weights of bilinear interpolation from a grid ``factor`` times coarser, cell
    centres aligned and ends held, written pixel by pixel."""
    height, width = -(-mask.shape[0] // factor), -(-mask.shape[1] // factor)
    entries = {}
    for i, (row, col) in enumerate(zip(*np.nonzero(mask))):
        at_row = min(max((row + 0.5) / factor - 0.5, 0.0), height - 1)
        at_col = min(max((col + 0.5) / factor - 0.5, 0.0), width - 1)
        r0 = min(int(np.floor(at_row)), max(height - 2, 0))
        c0 = min(int(np.floor(at_col)), max(width - 2, 0))
        for r, w_r in ((r0, 1 - (at_row - r0)), (min(r0 + 1, height - 1), at_row - r0)):
            for c, w_c in ((c0, 1 - (at_col - c0)), (min(c0 + 1, width - 1), at_col - c0)):
                entries[i, r * width + c] = entries.get((i, r * width + c), 0.0) + w_r * w_c
    keys = list(entries)
    return sp.csr_matrix(
        ([entries[k] for k in keys], ([k[0] for k in keys], [k[1] for k in keys])),
        shape=(int(mask.sum()), height * width),
    )


def test_hierarchical_basis_is_the_sum_of_bilinear_grids():
    """A kernel against its reference (a private name, deliberately): the hierarchical basis
    (``_Basis``) applies what the sum of the bilinear grids' sparse matrices does."""
    rng = np.random.default_rng(0)
    mask = synth.scene("vase", size=37).mask.copy()
    mask[30:, :5] = True  # a part touching the frame's corner: the ends are held
    basis = _Basis(mask)
    matrices = [sp.identity(int(mask.sum()), format="csr")]
    factor = 2
    while min(mask.shape) // factor >= 4:
        matrices.append(_bilinear_matrix(mask, factor))
        factor *= 2
    # the basis keeps the coarse cells that reach the object; put its coefficients on all of them
    full = sp.hstack(matrices).tocsr()
    reaching = np.flatnonzero(np.abs(full).sum(axis=0).A1 > 0)
    assert basis.size == reaching.size
    coefficients = rng.normal(size=basis.size)
    whole = np.zeros(full.shape[1])
    whole[reaching] = coefficients
    np.testing.assert_allclose(basis.expand(coefficients), full @ whole, atol=1e-12)
    gradient = rng.normal(size=basis.n)
    np.testing.assert_allclose(basis.reduce(gradient), (full.T @ gradient)[reaching], atol=1e-12)


def test_two_loop_is_the_textbook_recursion():
    # Nocedal and Wright, Algorithm 7.4, written plainly, against the fused compiled loop
    rng = np.random.default_rng(2)
    n, rows = 500, 6
    steps_s, steps_y = rng.normal(size=(2, rows, n))
    steps_y = steps_s * rng.uniform(0.5, 3.0, (rows, n)) + 0.1 * steps_y
    rho = 1.0 / np.sum(steps_s * steps_y, axis=1)
    gradient = rng.normal(size=n)
    for order in ([], [3], [4, 0, 2, 5, 1]):
        q = gradient.copy()
        alphas = {}
        for i in reversed(order):
            alphas[i] = rho[i] * (steps_s[i] @ q)
            q = q - alphas[i] * steps_y[i]
        if order:
            newest = order[-1]
            q = q * (steps_s[newest] @ steps_y[newest]) / (steps_y[newest] @ steps_y[newest])
        for i in order:
            q = q + (alphas[i] - rho[i] * (steps_y[i] @ q)) * steps_s[i]
        out = np.empty(n)
        two_loop(gradient, steps_s, steps_y, rho, np.array(order, dtype=np.int64), out)
        np.testing.assert_allclose(out, q, rtol=1e-12, atol=1e-12 * np.abs(q).max())


def test_descent_finds_a_minimum():
    # Rosenbrock's curved valley from its classic start: the minimum is (1, 1)
    start = np.array([-1.2, 1.0])
    x, steps = descend(lambda x: (rosen(x), rosen_der(x)), start, iterations=400)
    np.testing.assert_allclose(x, 1.0, atol=1e-6)
    assert steps <= 400
    # a quadratic in 2000 unknowns: within the iterations SciPy's L-BFGS-B needs, as close
    rng = np.random.default_rng(1)
    scales = np.exp(rng.uniform(0, 4, 2000))
    target = rng.normal(size=2000)

    def bowl(x):
        return 0.5 * np.sum(scales * (x - target) ** 2), scales * (x - target)

    x, _ = descend(bowl, np.zeros(2000), iterations=150)
    reference = minimize(bowl, np.zeros(2000), jac=True, method="L-BFGS-B", options={"maxiter": 150})
    assert bowl(x)[0] <= max(10 * reference.fun, 1e-10)


def test_tiny_and_featureless_photos_give_a_shape():
    # under 8 pixels across (no coarse grid in the basis), and one clipped plateau (no shading)
    mask = np.zeros((6, 40), dtype=bool)
    mask[1:5, 3:37] = True
    for image in (np.where(mask, np.linspace(0.2, 0.9, 40)[None], 0.0), np.where(mask, 0.8, 0.0)):
        result = photo_depth(image, mask, np.array([0.0, 0.0, 1.0]))
        assert np.isfinite(result.depth[mask]).all() and np.isnan(result.depth[~mask]).all()
    assert result.albedo == pytest.approx(0.8)


def test_no_outline_in_view_is_flat():
    # a mask filling the frame (a relief, a landscape): nothing fixes the silhouette's height
    assert np.all(silhouette_depth(np.ones((24, 32), dtype=bool)) == 0.0)
    # nor a concave run from frame to frame: it stays as it was
    depth = np.add.outer(np.zeros(24), np.linspace(0.0, 5.0, 32))
    band = np.zeros((24, 32), dtype=bool)
    band[10:14] = True
    start = concave_start(depth, band, np.zeros_like(band))
    assert np.isfinite(start).all() and np.array_equal(start, depth)


def test_concave_start_dents_a_dome_and_keeps_a_dent():
    size, radius = 81, 30.0
    rows, cols = np.mgrid[:size, :size] - size // 2
    dome = silhouette_depth(rows**2 + cols**2 < radius**2)
    region = rows**2 + cols**2 < 15.0**2
    dented = concave_start(dome, region, region)
    centre, rim = dented[size // 2, size // 2], dome[size // 2, size // 2 + 15]
    assert centre < rim < dome[size // 2, size // 2]  # the cap now dips below its rim
    assert np.abs(dented[~region] - dome[~region]).max() == 0.0  # nothing else moves
    assert np.allclose(concave_start(dented, region, region), dented)  # a dent stays a dent
    # along y only: each column's run bends down below its two ends
    trough = concave_start(dome, np.zeros_like(region), region)
    column = trough[size // 2 - 16 : size // 2 + 17, size // 2]
    assert column[16] < min(column[0], column[-1])
    assert np.all(np.diff(column, 2)[1:-1] >= -1e-9)  # concave up along the run


@pytest.mark.parametrize(
    "light, size",
    [((0.0, 0.0, 1.0), 48), ((5.0, 5.0, 7.0), 64), ((5.0, 5.0, 7.0), 96), ((5.0, 5.0, 7.0), 128)],
)
def test_concave_regions_turn_the_bowl(light, size):
    scene = synth.scene("bowl", size=size, light=light, noise=0.01)
    regions = synth.concave_regions("bowl", size=size)
    errors = [
        metrics.depth_error(
            reconstruct(scene.image, mask=scene.mask, light=scene.light, solver="photo", concave=given).depth,
            scene.depth,
            scene.mask,
        )
        for given in (None, regions)
    ]
    # measured: +z 63 % -> 6.7 %; (5, 5, 7) 52-53 % -> 4.1 % (64 px), 4.6 % (96), 4.6 % (128). With
    # another noise draw (seed 1) 96 px ends at 26 %: a known limit, in the module's description
    assert errors[0] > 40.0 and errors[1] < 10.0


def test_silhouette_depth_has_no_outline_on_the_frame():
    mask = np.zeros((40, 60), dtype=bool)
    mask[:, :30] = True  # a half-plane cut by the frame on three sides
    depth = silhouette_depth(mask)
    # it rises from its one real outline (column 30) and keeps rising toward the frame
    assert depth[20, 29] < depth[20, 20] < depth[20, 5]


@pytest.mark.parametrize("light", [(0.0, 0.0, 1.0), (0.5, 0.3, 0.81)])
def test_sphere(light):
    scene = synth.scene("sphere", size=96, light=light)
    rec = reconstruct(scene.image, mask=scene.mask, light=light, solver="photo")
    assert metrics.angular_error(rec.normals, scene.normals, scene.mask) < 3.0
    assert rec.info["solver"] == "photo" and rec.info["levels"] >= 1 and rec.info["response"][-1][0] == 1.0
    assert rec.depth[rec.info["references"][0]] == 0.0


def test_noisy_oblique_vase_beats_the_oblique_solver():
    light = (0.5, 0.5, 0.707)
    scene = synth.scene("vase", size=128, light=light, noise=0.01)
    photo = reconstruct(scene.image, mask=scene.mask, light=light, solver="photo")
    oblique = reconstruct(scene.image, mask=scene.mask, light=light, solver="oblique")
    error = metrics.angular_error(photo.normals, scene.normals, scene.mask)
    assert error < 8.0  # measured 6.3
    assert error < metrics.angular_error(oblique.normals, scene.normals, scene.mask)


def test_albedo_is_estimated_past_a_highlight():
    light = np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
    scene = synth.scene("sphere", size=96, light=light, albedo=0.5)
    image = scene.image.copy()
    rows, cols = np.nonzero(scene.mask)
    spot = (rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2 < 16
    image[rows[spot], cols[spot]] = 1.0  # a highlight twice as bright as any Lambertian pixel
    result = photo_depth(image, scene.mask, light)
    assert abs(result.albedo - 0.5) < 0.05
    assert metrics.angular_error(result.normals, scene.normals, scene.mask) < 4.0


def test_response_curve_of_a_lambertian_render_is_its_straight_line():
    scene = synth.scene("sphere", size=96, light=(0.4, 0.2, 0.89), albedo=0.7)
    shading = scene.normals[scene.mask] @ scene.light
    curve = response_curve(shading, scene.image[scene.mask])
    assert curve[0, 0] == 0.0 and curve[-1, 0] == pytest.approx(1.0)
    assert np.all(np.diff(curve[:, 1]) >= 0)
    assert np.allclose(curve[:, 1], 0.7 * np.maximum(curve[:, 0], 0.0), atol=0.02)


def test_response_curve_follows_a_bent_material_past_highlights():
    rng = np.random.default_rng(1)
    shading = rng.uniform(-0.2, 1.0, 20_000)
    values = 0.8 * np.maximum(shading, 0.0) ** 2  # a glossy falloff, far from Lambert's line
    values[rng.random(values.size) < 0.05] = 1.0  # 5 % highlights anywhere
    curve = response_curve(shading, values)
    assert np.all(np.diff(curve[:, 1]) >= 0)
    inner = curve[1:-1]
    assert np.allclose(inner[:, 1], 0.8 * inner[:, 0] ** 2, atol=0.03)
    assert curve[-1, 1] == pytest.approx(0.8, abs=0.05)


def test_a_bent_reflectance_is_not_read_as_shape():
    """A sphere whose brightness is (n . L)^2: Lambert's line reads it as a sharper cap; the
    estimated curve keeps the sphere."""
    light = (0.0, 0.0, 1.0)
    scene = synth.scene("sphere", size=96, light=light)
    image = np.where(scene.mask, scene.image**2, 0.0)
    estimated = photo_depth(image, scene.mask, np.array(light))
    lambert = photo_depth(image, scene.mask, np.array(light), albedo=1.0)
    error = metrics.angular_error(estimated.normals, scene.normals, scene.mask)
    assert error < 4.0
    assert error < 0.5 * metrics.angular_error(lambert.normals, scene.normals, scene.mask)


def test_is_offered():
    assert "photo" in available_solvers()


@pytest.mark.parametrize(
    "set_name, name, bar",
    # bars with a margin over what was measured (bear 19.8, box 21.2, cup1 7.6); the silhouette
    # alone gives 23.9, 33.8, 24.6 and the constant normal 38.8, 54.7, 41.9
    [("diligent", "bear", 22.5), ("mit", "box", 26.0), ("mit", "cup1", 11.0)],
)
def test_real_photos_beat_the_silhouette(real_data, set_name, name, bar):
    case = real_data.diligent(name) if set_name == "diligent" else real_data.mit(name)
    rec = reconstruct(case.image, mask=case.mask, light=case.light, solver="photo")
    assert real_data.angular_error(rec.normals, case) < bar
