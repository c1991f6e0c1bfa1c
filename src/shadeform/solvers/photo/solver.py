"""The photo solver's descent (:mod:`shadeform.solvers.photo`'s description): the energy
minimised coarse to fine over the pyramid, the reflectance curve re-estimated on the way, and the
registry's entry.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from shadeform.solvers.lbfgs import descend
from shadeform.solvers.photo.energy import _Level
from shadeform.solvers.photo.pyramid import _double, _half, _half_prior, _prior_level
from shadeform.solvers.photo.response import _lambert, response_curve
from shadeform.solvers.photo.start import _prior_depth, concave_start, silhouette_depth
from shadeform.solvers.problem import Problem, Solution

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
    """Depth and normals of one photo by the energy of :mod:`shadeform.solvers.photo`'s description.

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
