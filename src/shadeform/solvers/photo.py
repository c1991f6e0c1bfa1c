"""Shape from one real photograph: the outline's shape, refined by the shading it can trust.

Real photos break the uniform-Lambertian model pixel by pixel (highlights, cast shadows, painted
albedo, noise), so this solver does not march or propagate from single pixels. It finds the depth
``z`` (H, W) itself, integrable by construction, as the minimum of one energy over the object:

    E(z) = sum_p rho((f(n_p . L) - I_p) / a)                              shading, robust
         + mu  * sum_(p,q) (sqrt(eps^2 + |n_p - n_q|^2) - eps)            smooth, creases allowed
         + nu  * sum_(b on the outline) (n_b . m_b - 1)^2                 occluding contour

with ``n = (-dz/dx, -dz/dy, 1) / |.|`` (``docs/conventions.md``), ``rho`` Cauchy's loss of scale
:data:`SCALE` (a highlight, a shadow cast on a lit surface or a patch of other paint costs a
bounded amount, so they cannot drag the shape), ``(p, q)`` neighbouring object pixels and ``m_b``
the outline's outward normal: on an occluding contour the surface normal lies in the image plane,
perpendicular to the outline.

``f`` is the object's reflectance curve: the brightness of a pixel as a function of ``n . L``,
and ``a = f(1)`` the brightness of a pixel facing the light. Lambert's law makes it the straight
line ``a * max(0, n . L)``; real materials and cameras bend it (gloss brightens the pixels facing
the light, a rough or dusty surface flattens the falloff, interreflections lift the dark side),
and a straight line then reads the bend as shape. So ``f`` is estimated from the photo itself:
any non-decreasing curve, fitted to the current shape by isotonic regression of the median
brightness in ten bins of ``n . L`` (medians, so highlights and shadows do not set it), and
re-estimated :data:`ROUNDS` times per level (once on the finest of several), the shape solved
again after each. On a Lambertian render of the right shape the fit is the straight line; but a
shape and a curve can trade: from the silhouette's balloon the curve bends to fit the balloon (a
+z ellipsoid with 1 % noise comes out 7.3 degrees off, 0.8 with Lambert's line through the true
albedo), which is why "auto" keeps renders plus noise for the oblique solver. When the caller
gives the albedo (a reference normal with its brightness), the straight line
``albedo * max(0, n . L)`` is used as given.

The start is the shape of the silhouette alone: ``z = 2 sqrt(u)`` with ``laplacian(u) = -1``
inside the mask and ``u = 0`` just outside it (exact for a sphere; the image frame is not an
outline, so ``u`` has no condition there). The energy is minimised coarse to fine (2x2 pyramid
levels down to about :data:`COARSEST` object pixels) by L-BFGS over a hierarchical basis (the
depth is the sum of bilinearly upsampled grids of every coarser scale, Szeliski 1990), which
is what lets a descent move a whole region at once rather than a pixel at a time.

The shading is summed per pixel, the smoothness per pair and the contour per outline pixel, so
their balance moves with the number of pixels: with the same weights a small object is held
smoother than a large one. The coarsest level, which sets the global shape, is therefore
weighed as one continuous energy sampled at ``2 COARSEST`` object pixels (the middle of that
level's range): with ``h = sqrt(2 COARSEST / n)`` for its ``n`` object pixels, ``mu = MU / h``,
``eps = EPS * h``, ``nu = NU / h``, and every finer level keeps that ``h``, so the shading's share
grows 4x per level from the outline's shape to the shading's detail. (Rescaling the finer levels
too, or all levels to another reference, costs the real photos 0.7-2.7 degrees on MIT-Berkeley's
median: ``benchmarks/results/photo-experiments.md``.)

Concave regions the user marks (the app's "Mark concave", ``concave=``) dent the start
(:func:`concave_start`: what rises above the surface spanning a region's rim is mirrored below
it, along the region's axis), and where such a region meets the outline across its concave axis
the outline is a rim, not an occluding contour, so the contour term leaves it out. The descent
then refines the dent as it would the dome (the synthetic bowl with 1 % noise: depth error 63 %
without its region, 6-9 % with it at +z from 48 to 192 px; at light (5, 5, 7) 52-56 % without,
4.0-4.6 % with it from 48 to 192 px). Under an oblique light the dent is still fragile: with
another noise draw the 96 px bowl ends at 26 %, a shallower, tilted dish that has a lower energy
than the truth (the rim is not an occluding contour, so only the shading holds the walls against
the smoothness; ``benchmarks/results/photo-experiments.md``).

Limits. One light, orthographic camera, one reflectance curve for the whole object (painted
patches of other albedo are left to the robust loss); the
shape is biased toward the silhouette's (a balloon) where the shading is ambiguous, as under a
light at the camera, where a surface and its mirror image give the same picture: there the
concave regions settle it. References are not used beyond ``z = 0`` at the main reference.
Accuracy on real photographs with ground truth: ``benchmarks/results/real.md``.

The weights :data:`MU`, :data:`EPS`, :data:`NU` and :data:`SCALE` were set by hand on the
synthetic sphere and on one real object, MIT-Berkeley ``box``, which is also one of the 18
objects the benchmark reports (its figure there is not independent of that choice), before the
coarsest level was weighed at a fixed size (which leaves them as they were at ``2 COARSEST``
pixels); they were not swept over the benchmark.

References
----------
.. [1] J. T. Barron and J. Malik, "Shape, illumination, and reflectance from shading", IEEE
   TPAMI 37(8), 1670-1687, 2015 (depth as the unknown, contour prior, pyramid L-BFGS).
.. [2] M. K. Johnson and E. H. Adelson, "Shape estimation in natural illumination", CVPR 2011.
.. [3] R. Szeliski, "Fast surface interpolation using hierarchical basis functions", IEEE TPAMI
   12(6), 513-528, 1990.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as spla
from scipy import ndimage as ndi
from scipy.optimize import isotonic_regression

from shadeform.integration.poisson import _difference_system
from shadeform.solvers.lbfgs import descend
from shadeform.solvers.problem import Problem, Solution

__all__ = [
    "COARSEST",
    "concave_start",
    "EPS",
    "MU",
    "NU",
    "SCALE",
    "PhotoResult",
    "photo_depth",
    "response_curve",
    "silhouette_depth",
    "solve",
]

#: Smoothness weight per pair of neighbouring pixels, for an object of ``2 COARSEST`` pixels
#: (other sizes: the module's description).
MU = 1e-2
#: Change of the unit normal between neighbours (about 3 degrees) below which smoothness is
#: quadratic; above it grows linearly, so a crease costs its length, not its square (same size).
EPS = 0.05
#: Contour weight per outline pixel (same size).
NU = 1e-2
#: Scale of Cauchy's loss on the shading residual, in units of ``N . L``.
SCALE = 0.1
#: About this many object pixels at the coarsest pyramid level.
COARSEST = 4000
#: L-BFGS iterations at the coarsest level, the next two, and every finer one. Levels past the
#: third only sharpen detail: on four benchmark objects scaled up until their pyramid has four
#: levels (0.3-0.5 Mpx), 12 instead of 50 iterations there moved the error by -0.1 to +0.2
#: degrees and saved 34-45 % of the time (``benchmarks/results/photo-experiments.md``).
ITERATIONS = (300, 100, 50, 12)
#: Times per level the reflectance curve is re-estimated and the level solved again on the first
#: two levels; once on every finer one and on the finest of several, where the coarser ones have
#: settled it (the 18 real photos of ``benchmarks/results/real.md``: same medians, each object
#: within 0.4 degrees; six benchmark objects scaled up to four levels within -0.1..+0.3 degrees
#: and 19-29 % faster).
ROUNDS = 2
#: Bins of ``n . L`` over [0, 1] for the reflectance curve, and the fewest pixels a bin needs:
#: set once before any measurement (a tenth of the range per bin; a median of 20 pixels), not
#: tuned on any data.
BINS = 10
BIN_PIXELS = 20


@dataclass(frozen=True, eq=False)
class PhotoResult:
    """What :func:`photo_depth` found.

    Attributes
    ----------
    depth : (H, W) float64
        Height in pixels (arbitrary offset), NaN off the mask.
    normals : (H, W, 3) float64
        Unit normals of ``depth``, NaN off the mask.
    albedo : float
        The brightness of a pixel facing the light, ``f(1)``, as estimated (or given).
    response : (K, 2) float64
        The reflectance curve ``f``: rows ``(n . L, brightness)``, piecewise linear between them,
        non-decreasing (constant below the first row and above the last).
    levels : int
        Pyramid levels solved.
    iterations : int
        L-BFGS iterations over all levels.
    """

    depth: np.ndarray
    normals: np.ndarray
    albedo: float
    response: np.ndarray
    levels: int
    iterations: int


def silhouette_depth(mask: np.ndarray) -> np.ndarray:
    """The shape of the silhouette alone: ``z = 2 sqrt(u)``, ``laplacian(u) = -1`` inside.

    ``u = 0`` on the pixels just outside the mask; where the mask meets the image frame there is
    no condition (the object goes on beyond the picture). Exact for a sphere (a disc of radius R
    gives ``z = sqrt(R^2 - r^2)``).

    Parameters
    ----------
    mask : (H, W) bool

    Returns
    -------
    (H, W) float64
        Height in pixels, 0 off the mask.
    """
    mask = np.asarray(mask, dtype=bool)
    u = _dirichlet_solve(mask, np.zeros(mask.shape), _FOUR, source=1.0)
    depth = np.zeros(mask.shape)
    depth[mask] = 2.0 * np.sqrt(np.maximum(np.nan_to_num(u), 0.0))  # no outline in view: flat
    return depth


def concave_start(depth: np.ndarray, concave_x: np.ndarray, concave_y: np.ndarray) -> np.ndarray:
    """A convex start made concave where the user marked it: what rises above the surface
    spanning each marked region's rim is mirrored below it.

    That surface is, for a region concave along x (only), the straight line along each row's run
    of region pixels joining the heights just outside its two ends; along y (only), the same per
    column; along both, the harmonic surface through the heights round the region. What already
    lies below it (the silhouette's shape at a vase's waist is concave along y already) is kept.
    The start keeps its heights on the rims, so the surface stays whole.

    Parameters
    ----------
    depth : (H, W) float
        The convex start (0 off the object).
    concave_x, concave_y : (H, W) bool
        Where the surface is concave along x / y (:func:`shadeform.regions.concave_masks`).

    Returns
    -------
    (H, W) float64
    """
    start = np.array(depth, dtype=np.float64)
    for region, steps in (
        (concave_x & concave_y, _FOUR),
        (concave_x & ~concave_y, _FOUR[:2]),
        (concave_y & ~concave_x, _FOUR[2:]),
    ):
        if not region.any():
            continue
        rim_surface = _dirichlet_solve(region, depth, steps)
        rim_surface = np.where(np.isnan(rim_surface), depth[region], rim_surface)  # no rim: as it was
        start[region] = rim_surface - np.abs(depth[region] - rim_surface)
    return start


# 4-neighbour steps (row, col): along x first, then along y
_FOUR = ((0, 1), (0, -1), (1, 0), (-1, 0))


def _dirichlet_solve(region, outside, steps, *, source=0.0):
    """``u`` on ``region``'s pixels (n,) with ``-laplacian(u) = source`` along ``steps`` and
    ``u = outside`` (H, W) on the neighbours off the region. A step off the image frame has no
    neighbour (the object goes on beyond the picture); a connected part with no neighbour off the
    region inside the frame has nothing to fix ``u`` and gets NaN."""
    index, rows, cols = _index(region)
    n = rows.size
    neighbours, fixed, anchors = np.zeros(n), np.zeros(n), np.zeros(n)
    pairs_i, pairs_j = [], []
    for d_row, d_col in steps:
        other, inside = _neighbour(index, rows + d_row, cols + d_col)
        neighbours += inside
        off = inside & (other < 0)
        fixed[off] += outside[rows[off] + d_row, cols[off] + d_col]
        anchors += off
        on_region = other >= 0
        pairs_i.append(np.flatnonzero(on_region))
        pairs_j.append(other[on_region])
    i, j = np.concatenate(pairs_i), np.concatenate(pairs_j)
    adjacency = sp.csr_matrix((np.ones(i.size), (i, j)), shape=(n, n))
    _, part = csgraph.connected_components(adjacency, directed=False)
    anchored = np.bincount(part, weights=anchors)[part] > 0
    u = np.full(n, np.nan)
    if anchored.any():
        keep = np.flatnonzero(anchored)
        laplacian = sp.diags(neighbours[keep]) - adjacency[keep][:, keep]
        u[keep] = spla.spsolve(laplacian.tocsc(), fixed[keep] + source)
    return u


def photo_depth(
    image: np.ndarray,
    mask: np.ndarray,
    light: np.ndarray,
    *,
    albedo: float | None = None,
    concave_x: np.ndarray | None = None,
    concave_y: np.ndarray | None = None,
    prior: tuple[np.ndarray, np.ndarray] | None = None,
) -> PhotoResult:
    """Depth and normals of one photo by the energy of this module's description.

    Parameters
    ----------
    image : (H, W) float
        Linear intensities, >= 0.
    mask : (H, W) bool
        The object (not empty).
    light : (3,) float
        Unit direction toward the light.
    albedo : float, optional
        The brightness of a pixel facing the light; when given, the reflectance curve is Lambert's
        straight line through it; otherwise the curve is estimated (module description).
    concave_x, concave_y : (H, W) bool, optional
        Where the user marked the surface concave along x / y: the start is dented there
        (:func:`concave_start`) and the descent goes on from the dent.
    prior : ((H, W, 3), (H, W)) float, optional
        Normals the shape is expected to have and each one's weight (the learned prior,
        :mod:`shadeform.solvers.learned`): the start is their integrated shape instead of the
        silhouette's, and the energy gains ``sum_p w_p (1 - n_p . prior_p)``.

    Returns
    -------
    PhotoResult
    """
    image = np.where(mask, np.asarray(image, dtype=np.float64), 0.0)
    light = np.asarray(light, dtype=np.float64)
    pyramid = [(image, mask)]
    marked = [
        tuple(
            np.zeros(mask.shape, dtype=bool) if m is None else np.asarray(m, dtype=bool) & mask
            for m in (concave_x, concave_y)
        )
    ]
    expected = [None if prior is None else _prior_level(*prior, mask)]
    while np.count_nonzero(pyramid[-1][1]) > 4 * COARSEST and min(pyramid[-1][1].shape) >= 16:
        finer = pyramid[-1][1]
        pyramid.append(_half(*pyramid[-1]))
        if prior is not None:
            expected.append(_prior_level(*_half_prior(*expected[-1], finer), pyramid[-1][1]))
        # a coarse pixel is marked when most of its object pixels are
        marked.append(
            tuple((_half(m.astype(np.float64), finer)[0] >= 0.5) & pyramid[-1][1] for m in marked[-1])
        )
    # the coarsest level, which sets the global shape, weighs shading against smoothness as an
    # object of 2 COARSEST pixels would (the middle of its range, taken as such, not swept): where
    # in that range it falls, or how small the photo is, does not tip the balance; every finer
    # level keeps its spacing
    spacing = np.sqrt(2 * COARSEST / np.count_nonzero(pyramid[-1][1]))
    depth = previous = None
    curve = None if albedo is None else _lambert(float(albedo))
    total = 0
    expected += [None] * (len(pyramid) - len(expected))  # no prior: None on every level
    levels = zip(pyramid[::-1], marked[::-1], expected[::-1])
    for level, ((values, level_mask), (level_x, level_y), guide) in enumerate(levels):
        grid = _Level(
            values, level_mask, light, spacing=spacing, concave_x=level_x, concave_y=level_y, prior=guide
        )
        if depth is None:
            shape = silhouette_depth(level_mask) if guide is None else _prior_depth(guide[0], level_mask)
            depth = concave_start(shape, level_x, level_y)
        else:
            depth = _double(depth, previous, level_mask)
        iterations = ITERATIONS[min(level, len(ITERATIONS) - 1)]
        # the curve is settled on the first two levels: the finer ones (the costliest) fit it once
        settled = albedo is not None or level >= 2 or 0 < level == len(pyramid) - 1
        for _ in range(1 if settled else ROUNDS):
            if albedo is None:
                shading = grid.normals(depth[level_mask]) @ light
                curve = (
                    response_curve(shading[grid.data], grid.values[grid.data])
                    if grid.data.any()
                    else _lambert(max(float(grid.values.max()), 1e-12))  # all one clipped plateau
                )
            start = np.zeros(grid.unknowns)
            start[: grid.n] = depth[level_mask]
            coefficients, steps = descend(partial(grid.energy, curve=curve), start, iterations=iterations)
            total += steps
            depth = np.zeros(level_mask.shape)
            depth[level_mask] = grid.depth(coefficients)
        previous = level_mask
    normals = np.full(mask.shape + (3,), np.nan)
    normals[mask] = grid.normals(depth[mask])
    depth = np.where(mask, depth, np.nan)
    return PhotoResult(depth, normals, float(curve[-1, 1]), curve, len(pyramid), total)


def solve(problem: Problem, *, prior: tuple[np.ndarray, np.ndarray] | None = None) -> Solution:
    """The registry's entry (:mod:`shadeform.solvers`): depth with ``z = 0`` at the main reference.
    ``prior``: normals and weights the shape is held to (:func:`photo_depth`)."""
    given = problem.references[0].normal is not None
    result = photo_depth(
        problem.image,
        problem.mask,
        problem.light,
        albedo=problem.albedo if given else None,
        concave_x=problem.concave_x,
        concave_y=problem.concave_y,
        prior=prior,
    )
    problem.lap("solve")
    depth = result.depth - result.depth[problem.main]
    info = {
        "albedo": result.albedo,
        "response": np.round(result.response, 4).tolist(),
        "levels": result.levels,
        "iterations": result.iterations,
    }
    return Solution(result.normals, depth, info)


class _Level:
    """One pyramid level: the object's pixels, its difference operators and hierarchical basis."""

    def __init__(self, image, mask, light, *, spacing=1.0, concave_x=None, concave_y=None, prior=None):
        from shadeform.light.contour import find_boundary

        self.mask = mask
        self.spacing = spacing
        index, rows, cols = _index(mask)
        self.n = rows.size
        self.values = image[mask]
        self.light = light
        self.col_stencil, self.row_stencil = (
            _slope_stencil(index, rows, cols, step) for step in ((0, 1), (1, 0))
        )
        # the 4-neighbouring object pixels p, q of each difference z_q - z_p of Poisson's operator
        _, pairs, _ = _difference_system(mask, np.ones(mask.shape))
        ends = pairs.tocoo()
        self.first, self.second = np.empty((2, pairs.shape[0]), dtype=np.int64)
        self.first[ends.row[ends.data < 0]] = ends.col[ends.data < 0]  # p of z_q - z_p
        self.second[ends.row[ends.data > 0]] = ends.col[ends.data > 0]  # q
        boundary = find_boundary(mask)
        # where the outline crosses a region concave along the outline's normal, it is a rim, not
        # an occluding contour (there the surface turns away from the viewer: convex across it)
        contour = np.ones(boundary.rows.size, dtype=bool)
        if concave_x is not None:
            across_x = np.abs(boundary.normals[:, 0]) >= np.abs(boundary.normals[:, 1])
            on_x = concave_x[boundary.rows, boundary.cols]
            on_y = concave_y[boundary.rows, boundary.cols]
            contour = ~((on_x & across_x) | (on_y & ~across_x))
        self.outline = index[boundary.rows[contour], boundary.cols[contour]]
        self.outward = np.ascontiguousarray(boundary.normals[contour], dtype=np.float64)
        # a clipped plateau (two or more pixels at the object's top value) carries no shading
        top = self.values.max()
        at_top = self.values >= top * (1.0 - 1e-3)
        self.data = ~at_top if np.count_nonzero(at_top) > 1 else np.ones(self.n, dtype=bool)
        self.basis = _Basis(mask)
        self.unknowns = self.basis.size
        self.work = np.empty((11, self.n))
        # the prior's normals and weights on the object's pixels; none where marked concave (the
        # user's marks overrule what the prior expects)
        self.prior = None
        if prior is not None:
            weight = prior[1][mask]
            if concave_x is not None:
                weight = np.where((concave_x | concave_y)[mask], 0.0, weight)
            self.prior = (np.ascontiguousarray(prior[0][mask]), weight)

    def weights(self):
        """``(MU, EPS, NU, SCALE)`` at this level's pixel spacing ``h`` (in units of the reference
        resolution): ``MU / h``, ``EPS * h``, ``NU / h``. Read per call: tests and experiments may
        change the module's constants."""
        h = self.spacing
        return np.array([MU / h, EPS * h, NU / h, SCALE])

    def depth(self, coefficients):
        """Depth on the object's pixels from the basis coefficients."""
        return self.basis.expand(coefficients)

    def normals(self, z):
        """(n, 3) unit normals of depth ``z`` on the object's pixels."""
        gx, gy = (
            half * (z[ahead] - z[behind]) for ahead, behind, half in (self.col_stencil, self.row_stencil)
        )
        inverse = 1.0 / np.sqrt(1.0 + gx * gx + gy * gy)
        return np.column_stack([-gx * inverse, gy * inverse, inverse])

    def energy(self, coefficients, curve):
        """The energy and its gradient with respect to the basis coefficients, under the
        reflectance curve ``curve`` ((K, 2) rows ``(n . L, brightness)``): one compiled pass
        (:func:`_energy_kernel`) between the basis and its transpose."""
        z = self.depth(coefficients)
        g_z = np.empty(self.n)
        energy = _energy_kernel(
            z,
            self.values,
            self.data,
            self.light,
            np.ascontiguousarray(curve[:, 0]),
            np.ascontiguousarray(curve[:, 1]),
            *self.col_stencil,
            *self.row_stencil,
            self.first,
            self.second,
            self.outline,
            self.outward,
            self.weights(),
            self.work,
            g_z,
        )
        if self.prior is not None:
            energy += self._prior_term(z, g_z)
        return energy, self.basis.reduce(g_z)

    def _prior_term(self, z, g_z):
        """``sum_p w_p (1 - n_p . m_p)`` for the prior's normals ``m``; its gradient is added to
        ``g_z``. Vectorised numpy (a few array passes; the kernel's loops need no change)."""
        (col_ahead, col_behind, col_half), (row_ahead, row_behind, row_half) = (
            self.col_stencil,
            self.row_stencil,
        )
        a = col_half * (z[col_ahead] - z[col_behind])
        b = row_half * (z[row_ahead] - z[row_behind])
        c = 1.0 / np.sqrt(1.0 + a * a + b * b)
        m, w = self.prior
        dot = (-a * m[:, 0] + b * m[:, 1] + m[:, 2]) * c  # n = (-a, b, 1) c
        # d(dot)/da, d(dot)/db of the energy -w dot
        g_a = -w * (-m[:, 0] * c - dot * a * c * c)
        g_b = -w * (m[:, 1] * c - dot * b * c * c)
        n = z.size
        g_z += np.bincount(col_ahead, col_half * g_a, n) - np.bincount(col_behind, col_half * g_a, n)
        g_z += np.bincount(row_ahead, row_half * g_b, n) - np.bincount(row_behind, row_half * g_b, n)
        return float(np.sum(w * (1.0 - dot)))

    def energy_reference(self, coefficients, curve):
        """:meth:`energy` in plain numpy and sparse products (slow, obviously correct: the
        compiled kernel is tested against it)."""
        d_col, d_row = (_slope_matrix(*stencil) for stencil in (self.col_stencil, self.row_stencil))
        _, pairs, _ = _difference_system(self.mask, np.ones(self.mask.shape))
        z = self.depth(coefficients)
        gx, gy = d_col @ z, d_row @ z
        inverse = 1.0 / np.sqrt(1.0 + gx * gx + gy * gy)
        nx, ny, nz = -gx * inverse, gy * inverse, inverse
        lx, ly, lz = self.light
        shading = nx * lx + ny * ly + nz * lz
        # shading: Cauchy loss on (f(n . L) - I) / a, f piecewise linear
        knots, levels = curve[:, 0], curve[:, 1]
        inverse_albedo = 1.0 / levels[-1]
        segment = np.clip(np.searchsorted(knots, shading) - 1, 0, knots.size - 2)
        slope = np.diff(levels) / np.diff(knots)
        inside = (shading > knots[0]) & (shading < knots[-1])  # f is flat beyond its ends
        residual = (np.interp(shading, knots, levels) - self.values) * inverse_albedo
        ratio = residual * residual / (SCALE * SCALE)
        energy = 0.5 * SCALE * SCALE * np.sum(np.log1p(ratio)[self.data])
        d_shading = np.where(
            self.data & inside, residual / (1.0 + ratio) * slope[segment] * inverse_albedo, 0.0
        )
        g_x = d_shading * (-lx * inverse - shading * gx * inverse * inverse)
        g_y = d_shading * (ly * inverse - shading * gy * inverse * inverse)
        # smoothness: robust in the change of the normal between neighbours
        mu, eps, nu, _ = self.weights()
        steps = [pairs @ component for component in (nx, ny, nz)]
        root = np.sqrt(eps * eps + steps[0] ** 2 + steps[1] ** 2 + steps[2] ** 2)
        energy += mu * np.sum(root - eps)
        weight = mu / root
        g_n = [pairs.T @ (weight * step) for step in steps]
        # contour: the normal on the outline is its outward normal
        miss = nx[self.outline] * self.outward[:, 0] + ny[self.outline] * self.outward[:, 1] - 1.0
        energy += nu * np.sum(miss * miss)
        g_n[0][self.outline] += 2.0 * nu * miss * self.outward[:, 0]  # outline pixels are distinct
        g_n[1][self.outline] += 2.0 * nu * miss * self.outward[:, 1]
        if self.prior is not None:  # prior: w (1 - n . m)
            m, w = self.prior
            energy += np.sum(w * (1.0 - (nx * m[:, 0] + ny * m[:, 1] + nz * m[:, 2])))
            for axis in range(3):
                g_n[axis] = g_n[axis] - w * m[:, axis]
        # back through n(gx, gy) to the slopes, the depth and the basis
        cube = inverse**3
        g_x += g_n[0] * (gx * gx * cube - inverse) - g_n[1] * gx * gy * cube - g_n[2] * gx * cube
        g_y += g_n[0] * gx * gy * cube + g_n[1] * (inverse - gy * gy * cube) - g_n[2] * gy * cube
        g_z = d_col.T @ g_x + d_row.T @ g_y
        return energy, self.basis.reduce(g_z)


def response_curve(shading: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The reflectance curve: brightness as a non-decreasing function of ``n . L``.

    The median brightness in each of :data:`BINS` equal bins of ``n . L`` over [0, 1] holding at
    least :data:`BIN_PIXELS` pixels, made non-decreasing by isotonic regression weighted by the
    bins' pixel counts, then carried on straight to ``n . L = 0`` (not below 0) and to 1 (not
    downward) from the two end bins.

    Parameters
    ----------
    shading : (N,) float
        ``n . L`` of the current shape's pixels.
    values : (N,) float
        Their brightness.

    Returns
    -------
    (K, 2) float64
        Rows ``(n . L, brightness)`` with increasing ``n . L`` from 0 to 1; the last brightness,
        ``f(1)``, is positive.
    """
    facing = shading > 0
    lit, bright = shading[facing], values[facing]
    which = np.minimum((lit * BINS).astype(np.int64), BINS - 1)
    order = np.argsort(which, kind="stable")
    groups = np.split(order, np.searchsorted(which[order], np.arange(1, BINS)))
    kept = [g for g in groups if g.size >= BIN_PIXELS]
    if len(kept) < 2:  # too few pixels facing the light to see a curve: Lambert's line
        return _lambert(max(float(values.max(initial=0.0)), 1e-12))
    centres = np.array([np.median(lit[g]) for g in kept])
    fitted = isotonic_regression(
        np.array([np.median(bright[g]) for g in kept]),
        weights=np.array([g.size for g in kept], dtype=np.float64),
    ).x
    start = fitted[0] - (fitted[1] - fitted[0]) / (centres[1] - centres[0]) * centres[0]
    end = fitted[-1] + max(0.0, (fitted[-1] - fitted[-2]) / (centres[-1] - centres[-2])) * (1.0 - centres[-1])
    knots = np.r_[0.0, centres, 1.0]
    levels = np.maximum.accumulate(np.r_[np.clip(start, 0.0, fitted[0]), fitted, end])
    if levels[-1] <= 0:
        levels[-1] = max(float(values.max()), 1e-12)
    # a last bin centred at n . L = 1 (a flat patch facing the light) would make a zero-width
    # segment with the end knot
    knots = knots + np.arange(knots.size) * 1e-9
    return np.column_stack([knots, levels])


def _lambert(albedo: float) -> np.ndarray:
    """Lambert's reflectance curve ``albedo * max(0, n . L)`` as a (2, 2) curve."""
    return np.array([[0.0, 0.0], [1.0, albedo]])


def _index(mask):
    """Object pixel numbers (-1 off it) and the pixels' rows and columns."""
    rows, cols = np.nonzero(mask)
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[rows, cols] = np.arange(rows.size)
    return index, rows, cols


def _neighbour(index, rows, cols):
    """Pixel numbers at (rows, cols) (-1 off the object or the frame) and whether in the frame."""
    height, width = index.shape
    inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    other = np.full(rows.size, -1, dtype=np.int64)
    other[inside] = index[rows[inside], cols[inside]]
    return other, inside


def _slope_stencil(index, rows, cols, step):
    """d/dcol (step (0, 1)) or d/drow (step (1, 0)) on the object's pixels as
    ``half * (z[ahead] - z[behind])``: central differences where both neighbours are on it,
    one-sided where one is, zero where none is (both are the pixel itself). Rows point down
    (``y = -row``), so a normal is ``(-dz/dcol, +dz/drow, 1)`` normalised.

    Returns
    -------
    ahead, behind : (n,) int64
    half : (n,) float64
    """
    forward, _ = _neighbour(index, rows + step[0], cols + step[1])
    backward, _ = _neighbour(index, rows - step[0], cols - step[1])
    me = np.arange(rows.size)
    has_f, has_b = forward >= 0, backward >= 0
    half = np.where(has_f & has_b, 0.5, 1.0)
    return np.where(has_f, forward, me), np.where(has_b, backward, me), half


def _slope_matrix(ahead, behind, half):
    """A slope stencil (:func:`_slope_stencil`) as an (n, n) sparse matrix."""
    n = ahead.size
    me = np.arange(n)
    some = ahead != behind
    i = np.r_[me[some], me[some]]
    j = np.r_[ahead[some], behind[some]]
    v = np.r_[half[some], -half[some]]
    return sp.csr_matrix((v, (i, j)), shape=(n, n))


@numba.njit(cache=True)
def _energy_kernel(
    z, values, data, light, knots, levels,
    col_ahead, col_behind, col_half, row_ahead, row_behind, row_half,
    first, second, outline, outward, weights, work, g_z,
):  # fmt: skip
    """The energy of the module's description at depth ``z`` (n,) and its gradient, written into
    ``g_z`` (n,); ``weights`` is :meth:`_Level.weights`, ``work`` (11, n) scratch space (kept by
    the caller: fresh arrays on every call cost a fifth of the time). Same terms, in the same
    order, as :meth:`_Level.energy_reference`."""
    mu, eps, nu, scale = weights[0], weights[1], weights[2], weights[3]
    n = z.size
    lx, ly, lz = light[0], light[1], light[2]
    k = knots.size
    inverse_albedo = 1.0 / levels[k - 1]
    gx, gy, inv, nx, ny, nz = work[0], work[1], work[2], work[3], work[4], work[5]
    g_x, g_y, g_nx, g_ny, g_nz = work[6], work[7], work[8], work[9], work[10]
    g_x[:], g_y[:], g_nx[:], g_ny[:], g_nz[:] = 0.0, 0.0, 0.0, 0.0, 0.0
    energy = 0.0
    # the sum of the Cauchy terms' logarithms is taken as the logarithm of their product, one
    # logarithm per 1e50 of product instead of one per pixel (a third of the kernel's time)
    product, logs = 1.0, 0.0
    for p in range(n):  # shading: Cauchy loss on (f(n . L) - I) / a
        a = col_half[p] * (z[col_ahead[p]] - z[col_behind[p]])
        b = row_half[p] * (z[row_ahead[p]] - z[row_behind[p]])
        c = 1.0 / np.sqrt(1.0 + a * a + b * b)
        gx[p], gy[p], inv[p] = a, b, c
        nx[p], ny[p], nz[p] = -a * c, b * c, c
        if not data[p]:
            continue
        shading = nx[p] * lx + ny[p] * ly + nz[p] * lz
        below = 0  # knots below shading: np.searchsorted(knots, shading)
        while below < k and knots[below] < shading:
            below += 1
        segment = min(max(below - 1, 0), k - 2)
        slope = (levels[segment + 1] - levels[segment]) / (knots[segment + 1] - knots[segment])
        if shading <= knots[0]:
            value = levels[0]
        elif shading >= knots[k - 1]:
            value = levels[k - 1]
        else:
            value = levels[segment] + slope * (shading - knots[segment])
        residual = (value - values[p]) * inverse_albedo
        ratio = residual * residual / (scale * scale)
        if ratio > 1e200:  # a product could not hold it
            logs += np.log1p(ratio)
        else:
            product *= 1.0 + ratio
            if product > 1e50:
                logs += np.log(product)
                product = 1.0
        if knots[0] < shading < knots[k - 1]:  # f is flat beyond its ends
            d = residual / (1.0 + ratio) * slope * inverse_albedo
            g_x[p] = d * (-lx * c - shading * a * c * c)
            g_y[p] = d * (ly * c - shading * b * c * c)
    energy += 0.5 * scale * scale * (logs + np.log(product))
    for e in range(first.size):  # smoothness: robust in the change of the normal
        p, q = first[e], second[e]
        sx, sy, sz = nx[q] - nx[p], ny[q] - ny[p], nz[q] - nz[p]
        root = np.sqrt(eps * eps + sx * sx + sy * sy + sz * sz)
        energy += mu * (root - eps)
        w = mu / root
        g_nx[q] += w * sx
        g_nx[p] -= w * sx
        g_ny[q] += w * sy
        g_ny[p] -= w * sy
        g_nz[q] += w * sz
        g_nz[p] -= w * sz
    for i in range(outline.size):  # contour: the normal on the outline is its outward normal
        o = outline[i]
        miss = nx[o] * outward[i, 0] + ny[o] * outward[i, 1] - 1.0
        energy += nu * miss * miss
        g_nx[o] += 2.0 * nu * miss * outward[i, 0]
        g_ny[o] += 2.0 * nu * miss * outward[i, 1]
    for p in range(n):  # back through n(gx, gy) to the slopes and the depth
        a, b, c = gx[p], gy[p], inv[p]
        cube = c * c * c
        g_x[p] += g_nx[p] * (a * a * cube - c) - g_ny[p] * a * b * cube - g_nz[p] * a * cube
        g_y[p] += g_nx[p] * a * b * cube + g_ny[p] * (c - b * b * cube) - g_nz[p] * b * cube
    g_z[:] = 0.0
    for p in range(n):
        g_z[col_ahead[p]] += col_half[p] * g_x[p]
        g_z[col_behind[p]] -= col_half[p] * g_x[p]
        g_z[row_ahead[p]] += row_half[p] * g_y[p]
        g_z[row_behind[p]] -= row_half[p] * g_y[p]
    return energy


class _Basis:
    """Szeliski's hierarchical basis over one pyramid level's object pixels: the depth is each
    pixel's own coefficient plus, for every factor 2, 4, 8, ... (while the coarse grid is at
    least 4 cells across), the bilinear interpolation of a grid that many times coarser (cell
    centres aligned, ends held). A coarse coefficient moves a whole region at once, which is
    what lets a descent cross scales. Coarse cells are kept only where they reach the object.
    """

    def __init__(self, mask):
        self.rows, self.cols = np.nonzero(mask)
        self.n = self.rows.size
        # all coarse grids in one flat array: per grid, each fine row's two grid rows (as flat
        # starts) and the upper one's weight, each fine column's two grid columns and the upper
        # one's weight, and the grid's width (an image under 8 pixels across has no grid)
        row_steps, col_steps, widths, cells = [], [], [], 0
        factor = 2
        while min(mask.shape) // factor >= 4:
            height, width = (-(-side // factor) for side in mask.shape)
            lower, upper, weight = _axis_steps(mask.shape[0], height, factor)
            row_steps.append((cells + lower * width, cells + upper * width, weight))
            col_steps.append(_axis_steps(mask.shape[1], width, factor))
            widths.append(width)
            cells += height * width
            factor *= 2
        self.steps = tuple(
            np.array([step[i] for step in steps], dtype=dtype).reshape(len(steps), length)
            for steps, length in ((row_steps, mask.shape[0]), (col_steps, mask.shape[1]))
            for i, dtype in enumerate((np.int64, np.int64, np.float64))
        )
        self.widths = np.array(widths, dtype=np.int64)
        self.cells = cells
        reached = np.zeros(cells)
        _spread(np.ones(self.n), self.rows, self.cols, self.widths, *self.steps, reached)
        self.kept = np.flatnonzero(reached > 0)
        self.size = self.n + self.kept.size

    def expand(self, coefficients):
        """(n,) depth on the object's pixels of (size,) coefficients."""
        grids = np.zeros(self.cells)
        grids[self.kept] = coefficients[self.n :]
        z = np.array(coefficients[: self.n], dtype=np.float64)
        _gather(grids, self.rows, self.cols, self.widths, *self.steps, z)
        return z

    def reduce(self, gradient):
        """The transpose of :meth:`expand`: (size,) from (n,) (a gradient with respect to the
        depth becomes one with respect to the coefficients)."""
        grids = np.zeros(self.cells)
        gradient = np.ascontiguousarray(gradient, dtype=np.float64)
        _spread(gradient, self.rows, self.cols, self.widths, *self.steps, grids)
        return np.concatenate([gradient, grids[self.kept]])


def _axis_steps(fine, coarse, factor):
    """Linear interpolation along one axis from ``coarse`` cells to ``factor`` times as many
    ``fine`` ones (cell centres aligned, ends held): each fine cell's lower and upper coarse
    cells and the upper one's weight."""
    at = np.clip((np.arange(fine) + 0.5) / factor - 0.5, 0, coarse - 1)
    lower = np.minimum(np.floor(at).astype(np.int64), max(coarse - 2, 0))
    return lower, np.minimum(lower + 1, coarse - 1), at - lower


@numba.njit(cache=True)
def _gather(grids, rows, cols, widths, row_top, row_bottom, row_weight, col_left, col_right, col_weight, z):
    """Add to ``z`` (n,) every coarse grid's bilinear interpolation at the object's pixels
    (:class:`_Basis` holds the steps)."""
    for k in range(widths.size):
        # the grid interpolated along the rows first: one line per fine row
        lines = np.empty((row_top.shape[1], widths[k]))
        for r in range(lines.shape[0]):
            top, bottom, t = row_top[k, r], row_bottom[k, r], row_weight[k, r]
            for j in range(lines.shape[1]):
                lines[r, j] = grids[top + j] + t * (grids[bottom + j] - grids[top + j])
        left, right, weight = col_left[k], col_right[k], col_weight[k]
        for p in range(z.size):
            r, c = rows[p], cols[p]
            z[p] += lines[r, left[c]] + weight[c] * (lines[r, right[c]] - lines[r, left[c]])


@numba.njit(cache=True)
def _spread(
    values, rows, cols, widths, row_top, row_bottom, row_weight, col_left, col_right, col_weight, grids
):
    """The transpose of :func:`_gather`: add each pixel's value to the coarse cells it reads."""
    for k in range(widths.size):
        lines = np.zeros((row_top.shape[1], widths[k]))
        left, right, weight = col_left[k], col_right[k], col_weight[k]
        for p in range(values.size):
            r, c = rows[p], cols[p]
            lines[r, left[c]] += (1.0 - weight[c]) * values[p]
            lines[r, right[c]] += weight[c] * values[p]
        for r in range(lines.shape[0]):
            top, bottom, t = row_top[k, r], row_bottom[k, r], row_weight[k, r]
            for j in range(lines.shape[1]):
                grids[top + j] += (1.0 - t) * lines[r, j]
                grids[bottom + j] += t * lines[r, j]


def _half(image, mask):
    """The next pyramid level: 2x2 blocks, the image averaged over their object pixels, a block
    on the object when at least two of its pixels are."""
    height, width = (mask.shape[0] // 2) * 2, (mask.shape[1] // 2) * 2
    blocks = mask[:height, :width].reshape(height // 2, 2, width // 2, 2)
    count = blocks.sum(axis=(1, 3))
    total = (
        np.where(mask, image, 0.0)[:height, :width].reshape(height // 2, 2, width // 2, 2).sum(axis=(1, 3))
    )
    return np.where(count > 0, total / np.maximum(count, 1), 0.0), count >= 2


def _double(depth, coarse_mask, mask):
    """A coarse level's depth on the next finer level's grid (heights doubled: pixel units)."""
    nearest = ndi.distance_transform_edt(~coarse_mask, return_distances=False, return_indices=True)
    filled = depth[tuple(nearest)]
    rows = (np.arange(mask.shape[0]) + 0.5) / 2 - 0.5
    cols = (np.arange(mask.shape[1]) + 0.5) / 2 - 0.5
    grid = np.meshgrid(rows, cols, indexing="ij")
    return 2.0 * ndi.map_coordinates(filled, grid, order=1, mode="nearest")


def _prior_level(normals, weight, mask):
    """The prior's unit normals and weights on a level's grid, 0 off its object."""
    normals = np.where(mask[..., None], np.nan_to_num(normals), 0.0)
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    normals = np.where(length > 0, normals / np.maximum(length, 1e-12), 0.0)
    return normals, np.where(mask, np.nan_to_num(weight), 0.0)


def _half_prior(normals, weight, mask):
    """The prior one pyramid level coarser: normals and weights averaged over 2x2 blocks."""
    parts = [_half(normals[..., axis], mask)[0] for axis in range(3)]
    return np.stack(parts, axis=-1), _half(weight, mask)[0]


def _prior_depth(normals, mask):
    """The start a prior gives: its normals integrated (least squares), slopes bounded so that the
    outline's grazing normals do not throw the surface."""
    from shadeform.integration import integrate

    bounded = normals.copy()
    # slopes of at most about 5 (set once, not tuned): steeper is the outline's wall, where one
    # pixel spans tens of pixels of depth
    bounded[..., 2] = np.maximum(bounded[..., 2], 0.2)
    bounded /= np.linalg.norm(bounded, axis=-1, keepdims=True)
    depth = integrate(bounded, mask, method="poisson")
    return np.where(mask, depth - np.nanmin(depth[mask]), 0.0)
