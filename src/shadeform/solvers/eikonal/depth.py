"""The eikonal solver's top level: :func:`eikonal_depth` and its result.

Checks the input, finds and places the singular points
(:mod:`shadeform.solvers.eikonal.singular`), marches the surface from them
(:mod:`shadeform.solvers.eikonal.marching`) and puts the normals on the shading cone
(:mod:`shadeform.solvers.eikonal.normals`). The surface is ``L(x) = max_a (z_a - T_a(x))`` (from
above) where the singular point nearest in the metric ``f`` is a maximum or a saddle, and
``U(x) = min_a (z_a + T_a(x))`` (from below) where it is a minimum; the package docstring says why.

References
----------
.. [1] P. Dupuis and J. Oliensis, "An optimal control formulation and related numerical methods
   for a problem in shape reconstruction", Ann. Appl. Probab. 4(2), 287-346, 1994.
.. [2] R. Kimmel and J. A. Sethian, "Optimal algorithm for shape from shading and path
   planning", J. Math. Imaging Vis. 14(3), 237-244, 2001.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage as ndi

from shadeform._checks import StageTimer, check_mask, finite, fraction, positive, shading_image
from shadeform.errors import InputError
from shadeform.preprocess import Filter, apply_filter
from shadeform.solvers.eikonal.marching import STEEP, run_march, side_by_side, slope_fields
from shadeform.solvers.eikonal.normals import cone_normals
from shadeform.solvers.eikonal.singular import (
    EIGHT,
    TOL,
    SingularPoint,
    find_singular_points,
    place_heights,
)
from shadeform.solvers.problem import Problem, Solution

__all__ = ["EikonalResult", "eikonal_depth"]


@dataclass(frozen=True, eq=False)
class EikonalResult:
    """Shape from the eikonal solver.

    Attributes
    ----------
    depth : (H, W) float64
        Height z in pixel units (larger = nearer the viewer), NaN outside the mask; ``z = 0`` at
        the main singular point of each connected part of the mask.
    normals : (H, W, 3) float64 (or float32, as asked)
        Unit normals on the shading cone (``n_z = I / albedo``) tilted along the depth's steepest
        descent, NaN outside the mask.
    singular_points : tuple of SingularPoint
        The singular points the marching started from; the first is the main one.
    albedo : float
        ``k * albedo`` of the image model: the brightness of a pixel facing the light.
    info : dict
        ``parts`` (8-connected parts of the mask), ``detected`` (singular regions found; at most
        :data:`MAX_DETECTED` are used), ``tol``, ``steep``, ``smooth`` and ``timings`` (seconds
        per stage).
    """

    depth: np.ndarray
    normals: np.ndarray
    singular_points: tuple[SingularPoint, ...]
    albedo: float
    info: dict[str, Any] = field(default_factory=dict)


def eikonal_depth(
    image,
    mask,
    *,
    albedo: float | None = None,
    references=None,
    concave_x=None,
    concave_y=None,
    detect: bool = True,
    tol: float = TOL,
    smooth: float = 0.0,
    steep: float = STEEP,
    dtype=np.float64,
) -> EikonalResult:
    """Depth and normals from one image lit from the viewer's direction, by fast marching.

    Solves ``|grad z| = sqrt(albedo^2 / I^2 - 1)`` (light ``(0, 0, 1)``, orthographic camera,
    Lambertian, uniform albedo) from the singular points of the surface; see
    :mod:`shadeform.solvers.eikonal` for how their kinds and heights make one surface.

    Parameters
    ----------
    image : (H, W) float
        One channel, >= 0 and finite (filter noisy images first, e.g. with
        :func:`shadeform.preprocess.apply_filter`). Integer images are scaled by their type's
        maximum.
    mask : (H, W) bool
        Object pixels.
    albedo : float, optional
        ``k * albedo`` of the image model: the brightness of a pixel facing the light. Default:
        the brightest object pixel (of the smoothed image when ``smooth > 0``).
    references : sequence, optional
        Singular points the user knows, as ``(row, col)`` or ``(row, col, kind)`` with ``kind`` in
        :data:`KINDS` (default: from the concave masks). The surface is taken as level there. A
        reference inside a detected singular region replaces it. The first is the main one:
        ``z = 0`` there.
    concave_x, concave_y : (H, W) bool, optional
        Where the surface is concave along x / y, as returned by
        :func:`shadeform.regions.concave_masks` (default: nowhere). A singular point is a minimum
        where both are set, a saddle where one is, else a maximum.
    detect : bool, optional
        Find singular regions automatically (default). With False only ``references`` are used
        (and the brightest pixel of every part of the mask without one).
    tol : float, optional
        A singular region is a cap of pixels reaching ``I / albedo >= 1 - tol`` (slope below
        ``sqrt(2 tol)``) that rises ``tol`` above the pass to any brighter one. Raise it for noisy
        images (2e-2 at 1% noise after a Gaussian of sigma 2); at most :data:`MAX_DETECTED` caps,
        the largest, are kept.
    smooth : float, optional
        Standard deviation in pixels of a Gaussian (inside the mask) applied before the singular
        points and ``albedo`` are found; the marching itself uses ``image`` unchanged. 0: none.
    steep : float, optional
        Slope above which the arc update replaces finite differences
        (:mod:`shadeform.solvers.eikonal.marching`).
    dtype : {numpy.float64, numpy.float32}, optional
        Of the normals (computed in float64 either way); the registry's solver keeps float32.

    Returns
    -------
    EikonalResult
        ``depth`` (H, W), ``normals`` (H, W, 3), ``singular_points`` (main first), ``albedo``
        and ``info``.

    Raises
    ------
    InputError
        Wrong shapes or types, NaN or negative values in the image, an empty or black object,
        a bad ``albedo``, ``tol``, ``smooth`` or ``steep``, malformed references or concave masks.

    References
    ----------
    .. [1] P. Dupuis and J. Oliensis, "An optimal control formulation and related numerical
       methods for a problem in shape reconstruction", Ann. Appl. Probab. 4(2), 1994.
    .. [2] R. Kimmel and J. A. Sethian, "Optimal algorithm for shape from shading and path
       planning", J. Math. Imaging Vis. 14(3), 2001.

    Examples
    --------
    >>> from shadeform import synth, metrics
    >>> s = synth.scene("sphere", size=64)
    >>> res = eikonal_depth(s.image, s.mask)
    >>> bool(metrics.depth_error(res.depth, s.depth, s.mask) < 0.5)
    True
    """
    timer = StageTimer()
    lap = timer.lap

    image = shading_image(image)
    mask = check_mask(mask, image.shape)
    if image[mask].max() <= 0:
        raise InputError("the object is black: there is no shading to work with")
    concave_x = _concave_mask(concave_x, mask.shape, "concave_x")
    concave_y = _concave_mask(concave_y, mask.shape, "concave_y")
    tol = fraction(tol, "tol")
    smooth = finite(smooth, "smooth")
    if smooth < 0:
        raise InputError(f"smooth must be >= 0 (a Gaussian sigma in pixels), got {smooth}")
    steep = positive(steep, "steep")
    if not isinstance(detect, (bool, np.bool_)):
        raise InputError(f"detect must be True or False, got {detect!r}")

    seen = apply_filter(image, mask, Filter("gaussian", smooth)) if smooth > 0 else image
    albedo = float(seen[mask].max()) if albedo is None else positive(albedo, "albedo")
    cos_theta = _cosines(image, mask, albedo)
    cos_seen = cos_theta if seen is image else _cosines(seen, mask, albedo)
    del seen
    f, theta = slope_fields(cos_theta)
    del cos_theta  # made again for the normals: the marching does not need it (memory)
    parts, n_parts = ndi.label(mask, structure=EIGHT)
    lap("prepare")

    nodes, main_of_part, found = find_singular_points(
        cos_seen,
        mask,
        parts,
        n_parts,
        concave_x=concave_x,
        concave_y=concave_y,
        tol=tol,
        detect=bool(detect),
        references=references,
    )
    del cos_seen, concave_x, concave_y, parts  # (H, W) each, not needed by the marching
    lap("singular points")

    place_heights(nodes, main_of_part, f, theta, mask, steep)
    lap("heights")

    depth = _surface(nodes, f, theta, mask, steep)
    del f, theta  # the marching is over: free them before the normals are made
    offset = np.zeros(n_parts + 1)
    for part, main in main_of_part.items():
        offset[part] = depth[nodes[main].representative]
    # in place: z = 0 at each part's main singular point, NaN off the mask
    depth -= offset[1] if n_parts == 1 else offset[ndi.label(mask, structure=EIGHT)[0]]
    depth[~mask] = np.nan
    lap("depth")

    normals = cone_normals(depth, mask, _cosines(image, mask, albedo), dtype=dtype)
    lap("normals")

    # the main one first: the first reference, else the first part's
    main = 0 if nodes[0].origin == "user" else main_of_part[1]
    points = tuple(node.frozen() for node in [nodes[main], *nodes[:main], *nodes[main + 1 :]])
    info = {
        "parts": int(n_parts),
        "detected": int(found),
        "tol": tol,
        "steep": steep,
        "smooth": smooth,
        "timings": timer.timings,
    }
    return EikonalResult(depth=depth, normals=normals, singular_points=points, albedo=albedo, info=info)


def _surface(nodes, f, theta, mask, steep) -> np.ndarray:
    """``L`` (from above) or ``U`` (from below) per pixel, by the kind of the nearest node."""
    width = mask.shape[1]
    index = np.concatenate([n.pixels[:, 0] * width + n.pixels[:, 1] for n in nodes])
    counts = [len(n.pixels) for n in nodes]
    heights = np.repeat([n.height for n in nodes], counts)
    ids = np.repeat(np.arange(len(nodes)), counts)
    is_min = np.array([n.kind == "min" for n in nodes])
    if not is_min.any():
        low, _ = run_march(f, theta, mask, steep, index, -heights)
        return np.negative(low, out=low)
    if is_min.all():
        return run_march(f, theta, mask, steep, index, heights)[0]

    def march(job):
        values, labels = job
        T, label = run_march(f, theta, mask, steep, index, values, labels)
        return T if labels is None else label

    # three independent marches, side by side: from below, from above, and which node is nearest
    up, low, nearest = side_by_side(march, [(heights, None), (-heights, None), (np.zeros(len(index)), ids)])
    from_below = mask & is_min[np.maximum(nearest, 0)]
    return np.where(from_below, up, -low)


def _cosines(image, mask, albedo: float) -> np.ndarray:
    """``c = I / albedo`` clipped to [0, 1], 0 off the mask: (H, W) float64, made in place."""
    c = np.divide(image, albedo, dtype=np.float64)
    np.clip(c, 0.0, 1.0, out=c)
    c[~mask] = 0.0
    return c


def _concave_mask(value, shape, name: str) -> np.ndarray:
    """A concave mask as bool of ``shape``; None means nowhere."""
    if value is None:
        return np.zeros(shape, dtype=bool)
    value = np.asarray(value)
    if value.shape != shape:
        raise InputError(
            f"{name} has shape {value.shape} but the image has {shape}; give a mask of "
            "the image's size (shadeform.regions.concave_masks)"
        )
    return value.astype(bool, copy=False)


def solve(problem: Problem) -> Solution:
    """The eikonal solver in the registry (:mod:`shadeform.solvers`): fast marching from the
    singular points, the user's references among them, with its own depth unless the user names
    an integrator (then ``z = 0`` at the first singular point). The registry gives it only
    lights at +z."""
    given = [ref.pixel for ref in problem.references[: problem.given]]
    result = eikonal_depth(
        problem.image,
        problem.mask,
        albedo=problem.albedo,
        references=given or None,
        concave_x=problem.concave_x,
        concave_y=problem.concave_y,
        dtype=np.float32,  # what reconstruct keeps: no float64 copy of the normals is made
    )
    problem.lap("normals")
    depth = result.depth
    if problem.integrator is not None:
        first = result.singular_points[0]
        depth = problem.integrate(result.normals, origin=(first.row, first.col))
    problem.lap("depth")
    points = [
        {"row": p.row, "col": p.col, "kind": p.kind, "height": float(p.height)}
        for p in result.singular_points
    ]
    return Solution(result.normals, depth, {"singular_points": points})
