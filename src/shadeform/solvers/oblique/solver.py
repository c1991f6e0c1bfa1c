"""The oblique solver's entry point, :func:`oblique_depth`: checks, the three steps, coarse to fine.

The three steps (package docstring) run on the image as given when the object is small. An object
longer than ``coarse`` pixels (default :data:`COARSE`) is solved first on the image halved (2x2
block means, recursively), and the full-size descent starts from that solution's normals,
interpolated and put back on their cones, for at most :data:`REFINE_ITERATIONS` sweeps, instead of
marching at full size: the marching's drift grows with the path length, and the descent moves
long wavelengths slowly, so the half-size solution gets them cheaply and with half the drift.
This is the coarse-to-fine start of Horn's iterative scheme [1]_.

References
----------
.. [1] B. K. P. Horn, "Height and gradient from shading", IJCV 5(1), 37-75, 1990.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage as ndi

from shadeform._checks import (
    StageTimer,
    check_mask,
    finite,
    fraction,
    positive,
    shading_image,
    whole,
)
from shadeform.errors import InputError
from shadeform.solvers.oblique._cone import azimuth, azimuth_limits, on_cone
from shadeform.solvers.oblique.caps import TOL, march_sources
from shadeform.solvers.oblique.descent import (
    ITERATIONS,
    SHADOW_WEIGHT,
    SMOOTH,
    STOP,
    Descent,
    polish,
)
from shadeform.solvers.oblique.march import march_cone
from shadeform.solvers.oblique.shadow import ShadowFill
from shadeform.solvers.problem import Problem, Solution


@dataclass(frozen=True, eq=False)
class ObliqueResult:
    """Shape from the oblique-light solver (:func:`oblique_depth`).

    Attributes
    ----------
    depth : (H, W) float64
        Height z in pixel units, NaN outside the mask, ``z = 0`` at ``main``.
    normals : (H, W, 3) float64
        Unit normals, NaN outside the mask; on their shading cones where lit
        (``N . L = I / albedo``), with ``N . L <= 0`` where shadowed.
    lit : (H, W) bool
        Pixels read as lit (``I / albedo > dark``); the others are the shadow.
    main : (int, int)
        ``(row, col)`` of the main source (the brightest pixel), where ``z = 0``.
    info : dict
        ``sources`` (the pixels that start the marching at this size), ``levels`` (sizes solved:
        1, or more when the coarse-to-fine start was used, the marching then ran at the smallest),
        ``sweeps`` (descent sweeps done at this size), ``energy`` (per sweep), ``unreached`` (lit
        pixels the marching did not reach, filled like the shadow) and ``timings`` (seconds per
        stage).
    """

    depth: np.ndarray
    normals: np.ndarray
    lit: np.ndarray
    main: tuple[int, int]
    info: dict[str, Any] = field(default_factory=dict)


#: Objects longer than this (pixels) are first solved at half size (coarse to fine). Set on the
#: synthetic sphere and vase under the light (5, 5, 7) by their time at 256 and 512 px, keeping
#: 256 px images on the marching at full size (``benchmarks/results/oblique.md``).
COARSE = 320
#: Descent sweeps at most at a size that starts from the half-size solution; set with ``COARSE``.
REFINE_ITERATIONS = 10


def oblique_depth(
    image,
    mask,
    *,
    light,
    albedo=None,
    concave_x=None,
    concave_y=None,
    tol=TOL,
    dark=0.0,
    smooth=SMOOTH,
    shadow_weight=SHADOW_WEIGHT,
    iterations=ITERATIONS,
    stop=STOP,
    coarse=COARSE,
) -> ObliqueResult:
    """Depth and normals from one shading image under any light direction.

    Marches the lit pixels' normals from the brightest caps, fills the attached shadow, then
    polishes depth and normals together by block-coordinate descent (see
    :mod:`shadeform.solvers.oblique`).

    Parameters
    ----------
    image : (H, W) float
        Shading image, >= 0 (integer images are scaled by their type's maximum).
    mask : (H, W) bool
        Object pixels.
    light : (3,) float
        Direction toward the light (any length), ``z > 0``.
    albedo : float, optional
        ``albedo`` of the image model ``I = albedo max(0, N . L)`` (the ``k * albedo`` of the
        report): the brightness of a pixel facing the light. Default: the brightest object pixel
        (which faces the light in a noise-free image).
    concave_x, concave_y : (H, W) bool, optional
        Where the user marked the surface concave along x / y
        (:func:`shadeform.regions.concave_masks`): the marching's convexity tie-break and its
        one-sided penalty on turns against the convexity flip there.
    tol : float
        Pixels with ``I / albedo >= 1 - tol`` start the marching with ``N = L``; raise it for noisy
        images (about the noise's relative level).
    dark : float
        Pixels with ``I / albedo <= dark`` are the shadow (``N . L <= 0``); 0 for noise-free
        images, about twice the noise's relative level otherwise.
    smooth : float
        Weight of the smoothness of the lit normals in the polished energy, >= 0.
    shadow_weight : float
        Weight of the chord equations in which a shadowed pixel takes part, in (0, 1].
    iterations : int
        Descent sweeps at most (0: the marching's normals, integrated).
    stop : float
        The sweeps stop when the energy falls by less than this fraction in one.
    coarse : int
        When the object's bounding box is longer than this many pixels (>= 16), the steps run
        first on the image halved (2x2 block means, recursively), and the full-size polish starts
        from that solution's normals, moved onto their cones, instead of from a marching at full
        size.

    Returns
    -------
    ObliqueResult

    Raises
    ------
    InputError
        Wrong shapes, an empty or black object, a light with ``z <= 0``, bad numbers.

    Examples
    --------
    >>> from shadeform import synth, metrics
    >>> scene = synth.scene("sphere", size=64, light=(1, 1, 2))
    >>> result = oblique_depth(scene.image, scene.mask, light=scene.light)
    >>> bool(metrics.angular_error(result.normals, scene.normals) < 3)
    True
    """
    from shadeform.light import as_light

    timer = StageTimer()
    image = shading_image(image)
    mask = check_mask(mask, image.shape)
    if image[mask].max() <= 0:
        raise InputError("the object is black: there is no shading to work with")
    light = as_light(light)
    albedo = float(image[mask].max()) if albedo is None else positive(albedo, "albedo")
    tol = fraction(tol, "tol")
    dark = finite(dark, "dark")
    if not 0 <= dark < 1:
        raise InputError(f"dark must be in [0, 1), got {dark}")
    smooth = finite(smooth, "smooth")
    if smooth < 0:
        raise InputError(f"smooth must be >= 0, got {smooth}")
    shadow_weight = fraction(shadow_weight, "shadow_weight", closed=True)
    iterations = whole(iterations, "iterations")
    stop = fraction(stop, "stop")
    coarse = whole(coarse, "coarse", minimum=16)
    concave_x = _concave(concave_x, "concave_x", mask.shape)
    concave_y = _concave(concave_y, "concave_y", mask.shape)

    cos_theta = np.clip(np.where(mask, image / albedo, 0.0), 0.0, 1.0)
    lit = mask & (cos_theta > dark)
    if not lit.any():
        raise InputError("the whole object is in shadow (I / albedo <= dark); lower dark or check albedo")
    sources = march_sources(cos_theta, lit, tol)
    timer.lap("prepare")

    extent = max(np.ptp(np.flatnonzero(mask.any(axis=1))), np.ptp(np.flatnonzero(mask.any(axis=0))))
    if extent + 1 > coarse:
        # albedo is the full-size one, so the cones keep their angles
        half_image, half_mask, half_x, half_y = _halve(image, mask, concave_x, concave_y)
        start = oblique_depth(
            half_image,
            half_mask,
            light=light,
            albedo=albedo,
            concave_x=half_x,
            concave_y=half_y,
            tol=tol,
            dark=dark,
            smooth=smooth,
            shadow_weight=shadow_weight,
            iterations=iterations,
            stop=stop,
            coarse=coarse,
        )
        normals = _double_normals(start.normals, mask, cos_theta, lit, light)
        reached = lit.copy()
        unreached = int(start.info["unreached"])
        levels = start.info["levels"] + 1
        # the start is already polished at half size: a few sweeps move the short wavelengths
        iterations = min(iterations, REFINE_ITERATIONS)
    else:
        normals, _ = march_cone(
            cos_theta, lit, light=light, sources=sources, concave_x=concave_x, concave_y=concave_y
        )
        reached = np.isfinite(normals[..., 0])
        unreached = int(np.count_nonzero(lit & ~reached))
        levels = 1
    timer.lap("march" if levels == 1 else "half-size solve")

    fill = ShadowFill(mask, mask & ~reached)
    normals = fill(np.where(mask[..., None], normals, np.nan), light)
    timer.lap("shadow")

    descent = Descent(mask, cos_theta, lit & reached, light, shadow_weight, smooth)
    normals, z, energies, sweeps = polish(descent, fill, normals, light, iterations, stop)
    timer.lap("descent")

    depth = np.full(mask.shape, np.nan)
    depth[descent.box] = np.where(descent.mask, z, np.nan)
    main = (int(sources[0, 0]), int(sources[0, 1]))
    depth -= depth[main]
    normals[~mask] = np.nan
    timer.lap("depth")
    info = {
        "sources": [(int(r), int(c)) for r, c in sources],
        "levels": levels,
        "sweeps": int(sweeps),
        "energy": energies,
        "unreached": unreached,
        "timings": timer.timings,
    }
    return ObliqueResult(depth=depth, normals=normals, lit=lit, main=main, info=info)


def _concave(concave, what: str, shape) -> np.ndarray | None:
    """A concave-region mask of the image's shape as bool, or None."""
    if concave is None:
        return None
    concave = np.asarray(concave)
    if concave.shape != tuple(shape):
        raise InputError(
            f"{what} has shape {concave.shape} but the image has {tuple(shape)}; give "
            "a bool mask of the image's size (shadeform.regions.concave_masks)"
        )
    return concave.astype(bool)


def _halve(image, mask, concave_x, concave_y):
    """The image at half size: 2x2 block means over the object's pixels; a block is object when
    at least two of its pixels are, concave where any of its pixels is.

    Returns ``(image, mask, concave_x, concave_y)`` at half size (the concave masks None where
    given None)."""
    height, width = mask.shape
    pad = ((0, height % 2), (0, width % 2))

    def blocks(a):
        a = np.pad(a, pad)
        return a.reshape(a.shape[0] // 2, 2, a.shape[1] // 2, 2)

    count = blocks(mask.astype(np.float64)).sum(axis=(1, 3))
    total = blocks(np.where(mask, image, 0.0)).sum(axis=(1, 3))
    half_mask = count >= 2
    half_image = np.where(half_mask, total / np.maximum(count, 1.0), 0.0)
    half_x, half_y = (None if m is None else blocks(m).any(axis=(1, 3)) for m in (concave_x, concave_y))
    return half_image, half_mask, half_x, half_y


def _double_normals(half_normals, mask, cos_theta, lit, light) -> np.ndarray:
    """Normals of a half-size solution at full size: bilinear between the half-size pixel
    centres (valid ones only; the nearest valid one past the edge), then each lit pixel's moved
    to the nearest normal on its own cone (same azimuth about ``L``). Shadowed pixels stay NaN."""
    valid = np.isfinite(half_normals[..., 0])
    # past the half-size object: the nearest valid pixel's normal
    _, (near_r, near_c) = ndi.distance_transform_edt(~valid, return_indices=True)
    filled = half_normals[near_r, near_c]
    height, width = mask.shape
    # full pixel (r, c) sits at half-size coordinate (r + 0.5) / 2 - 0.5
    rows = (np.arange(height) + 0.5) / 2 - 0.5
    cols = (np.arange(width) + 0.5) / 2 - 0.5
    grid = np.stack(np.meshgrid(rows, cols, indexing="ij"))
    normals = np.stack(
        [ndi.map_coordinates(filled[..., i], grid, order=1, mode="nearest") for i in range(3)], axis=-1
    )
    phi = azimuth(normals, light)
    limits = azimuth_limits(cos_theta, light)
    on = on_cone(cos_theta, np.clip(phi, -limits, limits), light)
    return np.where(lit[..., None], on, np.nan)


def solve(problem: Problem) -> Solution:
    """The oblique solver in the registry (:mod:`shadeform.solvers`): any light, with its own depth
    unless the user names an integrator; ``z = 0`` at the main reference. Its noise policy: on an
    image noisier than :data:`shadeform.solvers.NOISY` (the registry smooths it first unless the
    user chose a filter) the start and shadow levels move to twice the remaining noise."""
    from shadeform.solvers import NOISY

    levels = {}
    relative = problem.noise / problem.albedo
    if relative > NOISY:
        levels = {"tol": max(TOL, 2 * relative), "dark": 2 * relative}
    result = oblique_depth(
        problem.image,
        problem.mask,
        light=problem.light,
        albedo=problem.albedo,
        concave_x=problem.concave_x,
        concave_y=problem.concave_y,
        **levels,
    )
    problem.lap("normals")
    depth = result.depth - result.depth[problem.main]
    if problem.integrator is not None:
        depth = problem.integrate(result.normals)
    problem.lap("depth")
    info = {
        "sources": len(result.info["sources"]),
        "levels": result.info["levels"],
        "sweeps": result.info["sweeps"],
        "shadowed": int(np.count_nonzero(problem.mask & ~result.lit)),
    }
    return Solution(result.normals, depth, info)
