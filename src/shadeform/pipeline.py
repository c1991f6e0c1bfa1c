"""``reconstruct()``: one call from a shading image to normals and depth.

load -> (mask, filter) -> light -> normals -> depth, each stage a pure function; this module only
checks the user's input once, at the boundary, and wires the stages together.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage as ndi

from shadeform._checks import StageTimer, shading_image
from shadeform.errors import InputError
from shadeform.light import as_light, estimate_light
from shadeform.preprocess import Filter, apply_filter, noise_level, object_mask, parse_filter
from shadeform.reconstruction import Reconstruction
from shadeform.regions import Region, concave_masks, parse_regions
from shadeform.solvers.propagation import propagate_normals, refine_by_integrability

#: The solvers, and "auto": the best measured one for the light (benchmarks/results/methods.md).
SOLVERS = ("propagation", "eikonal", "oblique")
METHODS = ("auto", *SOLVERS)
INTEGRATORS = ("paths", "poisson", "fourier", "bilateral")
#: What turns each method's normals into depth when ``integrator`` is not given.
DEFAULT_INTEGRATOR = {"propagation": "paths", "eikonal": "eikonal (fast-marching depth)",
                      "oblique": "oblique (chord-equation descent depth)"}

#: Noise (standard deviation over ``k * albedo``, :func:`shadeform.preprocess.noise_level`) above
#: which the oblique solver's image is smoothed when no filter is given, and by how much: unfiltered,
#: 1 % noise under oblique light takes its depth error from ~1 % to 40-140 % on the synthetic
#: scenes (benchmarks/results/methods.md); 8-bit quantisation alone is 0.1 %.
NOISY = 0.003
OBLIQUE_DENOISE = Filter("gaussian", 2.0)

#: Smallest image side the solvers can work on (a gradient needs neighbours on both sides).
MIN_SIDE = 3
#: An object with at least this fraction of its pixels at the white level carries no shading.
SATURATED_FRACTION = 0.9


def reconstruct(
    image: np.ndarray,
    *,
    light: Sequence[float] | str = (0.0, 0.0, 1.0),
    method: str = "auto",
    mask: np.ndarray | None = None,
    filter: str | None = None,
    references: Sequence | None = None,
    concave: Any = None,
    integrator: str | None = None,
    refine: int = 3,
) -> Reconstruction:
    """Recover normals and depth from one shading image.

    The 2002 ModelBuilder pipeline (``DESIGN.md``): object mask, optional filter, reference
    normal(s), normal field by convexity-guided propagation from each reference, depth by
    averaging integration paths, several references combined by the report's eq. 7.

    Parameters
    ----------
    image : (H, W) float array
        One channel, values >= 0 (e.g. from :func:`shadeform.load_image`); integer arrays are
        scaled by their type's maximum.
    light : (3,) float or "estimate"
        Direction toward the light in the camera frame (``docs/conventions.md``), or
        ``"estimate"`` to estimate it and ``k * albedo`` from the image
        (:func:`shadeform.light.estimate_light`; ``info["light_estimate"]`` says how).
    method : {"auto", "propagation", "eikonal", "oblique"}
        Solver. "auto" (the default) picks the best measured one for the light and the image's
        noise (:func:`best_method`): "eikonal" for a light at +z on a clean image, else "oblique". The others: the 2002 convexity-guided propagation (any light), fast marching of the
        eikonal equation from the singular points (light at +z only; concave regions and
        references become minima, saddles and maxima: :mod:`shadeform.solvers.eikonal`), or the
        oblique-light solver (any light, attached shadows as ``N . L <= 0``; marching from the
        brightest pixels, then descent on chord equations: :mod:`shadeform.solvers.oblique`).
        With "oblique" the first reference, if given, only sets where ``z = 0``.
    mask : (H, W) bool, optional
        Object pixels; by default found automatically (dark background).
    filter : str, optional
        ``"none"``, ``"gaussian:SIGMA"``, ``"mean:R"``, ``"median:R"`` or ``"minimum:R"``. Not
        given, the oblique solver's image is smoothed by :data:`OBLIQUE_DENOISE` when its noise
        exceeds :data:`NOISY` (``info["auto_filter"]``); ``"none"`` turns that off.
    references : sequence, optional
        Reference pixels as ``(row, col)`` or ``(row, col, (nx, ny, nz))``. By default the
        brightest object pixel (the one deepest inside the object among equals), whose normal is
        the light. The first is the main reference: ``z = 0`` there. Every connected part of the
        mask without a reference gets its own automatic one.
    concave : regions, optional
        Concave regions: a dict or JSON string in the format of ``docs/conventions.md``, a path to
        such a file, or a sequence of :class:`shadeform.regions.Region`.
    integrator : {"paths", "poisson", "fourier", "bilateral"}, optional
        Depth from normals: the report's path averaging, masked least squares, its DCT solve on
        the bounding rectangle, or discontinuity-preserving (:func:`shadeform.integration.integrate`). By default
        "paths" for propagation, and the solver's own depth for "eikonal" and "oblique".
    refine : int
        Iterations of the integrability refinement of the propagated field
        (:func:`shadeform.solvers.propagation.refine_by_integrability`); 0 gives the report's
        field exactly.

    Returns
    -------
    Reconstruction
        ``normals`` (H, W, 3), ``depth`` (H, W) (NaN outside the mask), ``mask``, ``light``,
        ``albedo`` (``k * albedo`` of the image model) and ``info``.

    Raises
    ------
    InputError
        For every user mistake: wrong shapes, NaN, an empty, black or saturated object, a
        reference off the object, malformed regions, unknown method names.

    Examples
    --------
    >>> from shadeform import synth, metrics
    >>> scene = synth.scene("sphere", size=64)
    >>> rec = reconstruct(scene.image, mask=scene.mask)
    >>> bool(metrics.angular_error(rec.normals, scene.normals) < 3)
    True
    """
    timer = StageTimer()
    lap = timer.lap
    image = _check_image(image)
    estimate_wanted = isinstance(light, str)
    if estimate_wanted and light != "estimate":
        raise InputError(f"light must be a direction (x, y, z) or 'estimate', got {light!r}")
    light = None if estimate_wanted else as_light(light)
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of: {', '.join(METHODS)}")
    requested_method = method
    if integrator is not None and integrator not in INTEGRATORS:
        raise InputError(f"unknown integrator {integrator!r}; choose one of: {', '.join(INTEGRATORS)}")
    if isinstance(refine, bool) or not isinstance(refine, (int, np.integer)) or refine < 0:
        raise InputError(f"refine must be a whole number of iterations >= 0, got {refine!r}")

    mask = object_mask(image) if mask is None else _check_mask(mask, image.shape)
    _check_shading(image, mask)
    lap("mask")
    shading = apply_filter(image, mask, parse_filter(filter)) if filter else image
    lap("filter")
    extra_info = {}
    if estimate_wanted:
        estimate = estimate_light(shading, mask)
        light = np.asarray(estimate.light, dtype=np.float64)
        extra_info = {"light_estimate": {"slant": float(estimate.slant), "tilt": float(estimate.tilt),
                                         "albedo": float(estimate.albedo), "evidence": estimate.evidence}}
        lap("light")
    noise = inside = None
    if method in ("auto", "oblique"):
        inside = ndi.distance_transform_edt(mask)  # shared with _references
        noise = noise_level(shading, mask, inside=inside)
        brightest = float(shading[mask].max())
    if method == "auto":
        method = best_method(light, noise=noise / brightest)
    if method == "oblique":
        # the oblique solver starts from the brightest pixels: noise scatters them
        if not filter and noise > NOISY * brightest:
            shading = apply_filter(shading, mask, OBLIQUE_DENOISE)
            noise = noise_level(shading, mask, inside=inside)
            extra_info["auto_filter"] = str(OBLIQUE_DENOISE)
            lap("filter")
    concave_x, concave_y = concave_masks(_as_regions(concave), image.shape)
    labels, n_parts = ndi.label(mask)
    refs = _references(references, shading, mask, labels, n_parts, inside=inside)
    k = _brightness_scale(shading, mask, refs[0], light,
                          estimated=float(estimate.albedo) if estimate_wanted else None)
    cos_theta = np.clip(np.where(mask, shading / k, 0.0), 0.0, 1.0)
    lap("references")

    if method == "oblique":
        normals, depth, method_info = _oblique(shading, mask, light, k, refs, concave_x, concave_y,
                                               integrator, noise, lap)
    elif method == "eikonal":
        normals, depth, method_info = _eikonal(shading, mask, light, k, references, concave_x, concave_y,
                                               integrator, lap)
    else:
        normals, depth, method_info = _propagation(shading, mask, light, k, refs, labels, n_parts, cos_theta,
                                                   concave_x, concave_y, integrator, refine, lap)
    normals[~mask] = np.nan
    depth[~mask] = np.nan
    lap("combine")
    info = {
        "method": method,
        "method_requested": requested_method,
        "integrator": integrator or DEFAULT_INTEGRATOR[method],
        "refine": int(refine) if method == "propagation" else 0,
        "filter": parse_filter(filter).kind if filter else "none",
        "references": [(int(r), int(c)) for (r, c), _ in refs],
        "parts": int(n_parts),
        "k": float(k),
        "timings": timer.timings,
        **method_info,
        **extra_info,
    }
    return Reconstruction(normals=normals, depth=depth, mask=mask, light=light, albedo=float(k), info=info)


def best_method(light, *, noise: float = 0.0) -> str:
    """The solver ``method="auto"`` uses: the best measured for the light and the noise.

    On the synthetic scenes of ``benchmarks/results/methods.md`` (noise 0-3 %), "eikonal" has the
    lowest errors with the light at +z on a clean image, and "oblique" (which smooths a noisy image
    first, see :data:`NOISY`) under any other light and on noisy images at +z; "eikonal" only takes
    a light at +z.

    Parameters
    ----------
    light : (3,) float
        Unit direction toward the light.
    noise : float, keyword-only
        The image's noise over its brightest object pixel
        (:func:`shadeform.preprocess.noise_level`); noisy above :data:`NOISY`.

    Returns
    -------
    str
        "eikonal" or "oblique".
    """
    return "eikonal" if _is_frontal(light) and noise <= NOISY else "oblique"


def _is_frontal(light) -> bool:
    """Whether the light is at +z (to rounding): the only light the eikonal solver takes."""
    return bool(np.allclose(np.asarray(light, dtype=np.float64), (0.0, 0.0, 1.0), atol=1e-6))


def _propagation(shading, mask, light, k, refs, labels, n_parts, cos_theta, concave_x, concave_y,
                 integrator, refine, lap):
    """The 2002 route: a field per reference, integrated from it, combined by eq. 7."""
    integrator = integrator or "paths"
    normals_sum = np.zeros(mask.shape + (3,))
    depth_sum = np.zeros(mask.shape)
    depth_count = np.zeros(mask.shape)
    for part in range(1, n_parts + 1):
        part_refs = [ref for ref in refs if labels[ref[0]] == part]
        part_mask = labels == part
        depth_main = None
        for (r, c), ref_normal in part_refs:
            field = propagate_normals(shading, part_mask, light=light, reference=(r, c),
                                      reference_normal=ref_normal, k=k,
                                      concave_x=concave_x, concave_y=concave_y)
            lap("normals")
            if refine:
                field = refine_by_integrability(field, cos_theta, part_mask, light=light,
                                                iterations=int(refine))
                lap("refine")
            depth = _integrate(field, part_mask, (r, c), integrator)
            lap("depth")
            # eq. 7: reference J's depths, moved into the main reference's frame by Z_MJ, the
            # main reference's depth at J's origin
            if depth_main is None:
                depth_main = depth
            depth_sum[part_mask] += depth[part_mask] + depth_main[r, c]
            depth_count[part_mask] += 1
            normals_sum[part_mask] += field[part_mask]
    if len(refs) > 1:
        normals_sum /= np.linalg.norm(normals_sum, axis=-1, keepdims=True).clip(1e-300)
        depth_sum /= np.maximum(depth_count, 1)
    return normals_sum, depth_sum, {}


def _eikonal(shading, mask, light, k, references, concave_x, concave_y, integrator, lap):
    """Fast marching from the singular points (light at +z only); its own depth by default."""
    from shadeform.solvers.eikonal import eikonal_depth

    if not _is_frontal(light):
        raise InputError("method 'eikonal' needs the light at (0, 0, 1); use method='propagation' for "
                         "other light directions")
    sources = [(int(item[0]), int(item[1])) for item in references or ()]
    result = eikonal_depth(shading, mask, k=k, sources=sources or None, concave=(concave_x, concave_y))
    lap("normals")
    depth = result.depth.copy()
    if integrator is not None:
        main = (result.sources[0].row, result.sources[0].col)
        depth = _integrate(result.normals, mask, main, integrator)
    lap("depth")
    sources_info = [{"row": s.row, "col": s.col, "kind": s.kind, "height": float(s.height)} for s in result.sources]
    return result.normals.copy(), depth, {"sources": sources_info}


def _oblique(shading, mask, light, k, refs, concave_x, concave_y, integrator, noise, lap):
    """Any light: marching from the brightest pixels, shadow fill, descent; its own depth.
    On a noisy image the start and shadow levels move to twice the noise."""
    from shadeform.solvers.oblique import TOL, oblique_depth

    levels = {}
    if noise > NOISY * k:
        levels = {"tol": max(TOL, 2 * noise / k), "dark": 2 * noise / k}
    result = oblique_depth(shading, mask, light=light, k=k, concave=(concave_x, concave_y), **levels)
    lap("normals")
    main = refs[0][0]
    depth = result.depth - result.depth[main]
    if integrator is not None:
        depth = _integrate(result.normals, mask, main, integrator)
    lap("depth")
    info = {"sources": len(result.info["sources"]), "levels": result.info["levels"],
            "sweeps": result.info["sweeps"],
            "shadowed": int(np.count_nonzero(mask & ~result.lit))}
    return result.normals.copy(), depth, info


def _integrate(normals, mask, origin, integrator):
    from shadeform.integration import integrate

    return integrate(normals, mask, method=integrator, origin=origin)


def _check_image(image) -> np.ndarray:
    image = shading_image(image)
    if min(image.shape) < MIN_SIDE:
        raise InputError(f"image is {image.shape[1]}x{image.shape[0]} pixels; it needs at least "
                         f"{MIN_SIDE}x{MIN_SIDE}")
    return image


def _check_mask(mask, shape) -> np.ndarray:
    mask = np.asarray(mask)
    if mask.shape != shape:
        raise InputError(f"mask has shape {mask.shape} but the image has {shape}; give a mask of the image's size")
    mask = mask.astype(bool)
    if not mask.any():
        raise InputError("mask is empty; it must mark the object's pixels")
    return mask


def _check_shading(image, mask) -> None:
    values = image[mask]
    top = values.max()
    if top <= 0:
        raise InputError("the object is black: there is no shading to work with; check the exposure or the mask")
    at_top = np.count_nonzero(values >= top * (1 - 1e-6)) / values.size
    if top >= 0.999 and at_top >= SATURATED_FRACTION:
        raise InputError(
            f"the image is saturated: {at_top:.0%} of the object is at the white level, so there is "
            "no shading to work with; use a shorter exposure"
        )


def _as_regions(concave) -> tuple[Region, ...]:
    if concave is None:
        return ()
    if isinstance(concave, (dict, str, Path)):
        return parse_regions(concave)
    regions = tuple(concave)
    if not all(isinstance(region, Region) for region in regions):
        raise InputError("concave must be a regions dict, JSON text, a .json path or a sequence of Region")
    return regions


def _references(references, image, mask, labels, n_parts, *, inside=None):
    """User references checked, plus the brightest pixel of every part left without one.
    ``inside``: the mask's distance transform, if the caller has it."""
    refs = [_parse_reference(item, mask) for item in references or ()]
    covered = {labels[r, c] for (r, c), _ in refs}
    for part in range(1, n_parts + 1):
        if part in covered:
            continue
        in_part = labels == part
        top = image[in_part].max()
        brightest = in_part & (image >= top * (1 - 1e-9))
        if np.count_nonzero(brightest) > 1:
            # among equally bright pixels prefer the one deepest inside its part: a flat top's centre
            inside = ndi.distance_transform_edt(mask) if inside is None else inside
            brightest = np.where(brightest, inside, -1.0)
        r, c = np.unravel_index(np.argmax(brightest), brightest.shape)
        refs.append(((int(r), int(c)), None))
    return refs


def _brightness_scale(image, mask, main_ref, light, *, estimated=None) -> float:
    """``k * albedo``: from the main reference when its normal is given, else the light
    estimate's, else the brightest pixel (the 2002 rule: it faces the light)."""
    (r, c), normal = main_ref
    if normal is not None:
        facing = float(normal @ light)
        if facing <= 0 or image[r, c] <= 0:
            raise InputError(f"reference (row {r}, col {c}) is in shadow or its normal faces away from the light; "
                             "pick a lit reference")
        return float(image[r, c] / facing)
    if estimated is not None:
        return estimated
    return float(image[mask].max())


def reconstruct_preview(image: np.ndarray, *, step: int, mask: np.ndarray | None = None,
                        filter: str | None = None, references: Sequence | None = None,
                        concave: Any = None, **options: Any) -> Reconstruction:
    """A quick look at what ``to_mesh(reconstruct(...), step=step)`` will show.

    The image is sampled at the mesh's grid (every ``step``-th row and column) and reconstructed
    there, ``step**2`` times fewer pixels: interactive tools show this while the full-resolution
    solve runs. Filter sizes, references and concave regions are carried to
    the coarse grid; depth is scaled back to pixels of the input image. A bright cap that falls
    between grid points (a singular point on a thin rim or on the object's top row) is kept at the
    nearest grid point, so the solvers still start from it (vase 256 px, eikonal, step 2: 0.12 %
    depth error, 6.3 % without). Other features narrower than the grid are lost until the full
    result replaces the preview.

    Parameters
    ----------
    image : (H, W) float array
        As for :func:`reconstruct`.
    step : int, keyword-only
        The mesh's grid spacing in pixels, ``>= 1`` (1 is the full solve).
    mask, filter, references, concave
        As for :func:`reconstruct`, in pixels of the input image. A reference whose grid point
        falls off the coarse object moves to the nearest grid point on it.
    **options
        ``light``, ``method``, ``integrator``, ``refine``: as for :func:`reconstruct`.

    Returns
    -------
    Reconstruction
        Full-size arrays (H, W): ``mask`` the object mask, ``normals`` and ``depth`` set at the
        grid points ``[::step, ::step]`` inside the mask and NaN elsewhere, so that
        ``to_mesh(preview, step=step)`` has the vertices and triangles of the full result's mesh.
        ``info`` is the coarse solve's, with ``preview_step``; its references are in input
        pixels.

    Examples
    --------
    >>> from shadeform import synth, to_mesh
    >>> scene = synth.scene("sphere", size=64)
    >>> quick = reconstruct_preview(scene.image, mask=scene.mask, step=2)
    >>> to_mesh(quick, step=2).n_vertices == to_mesh(reconstruct(scene.image, mask=scene.mask), step=2).n_vertices
    True
    """
    image = _check_image(image)
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 1:
        raise InputError(f"step must be a whole number of pixels (1, 2, ...), got {step!r}")
    step = int(step)
    mask = object_mask(image) if mask is None else _check_mask(mask, image.shape)
    _check_shading(image, mask)
    if step == 1:
        return reconstruct(image, mask=mask, filter=filter, references=references, concave=concave,
                           **options)
    # sampled, not averaged: an average flattens the narrow bright ridges where the eikonal
    # solver finds its singular points (the vase's rim); the filter, scaled, does the smoothing
    coarse_mask = mask[::step, ::step]
    if not coarse_mask.any():
        raise InputError(f"the object has no pixel on the grid of step {step}; use a smaller step")
    coarse = _keep_caps(image, mask, np.where(coarse_mask, image[::step, ::step], 0.0),
                        coarse_mask, step)

    spec = parse_filter(filter) if filter else None
    if spec is not None and spec.kind != "none":
        size = spec.size / step if spec.kind == "gaussian" else float(round(spec.size / step))
        spec = Filter(spec.kind, size) if size > 0 else None
    coarse_refs = None
    if references:
        coarse_refs = [_coarse_reference(item, mask, coarse_mask, step) for item in references]
    regions = tuple(Region(region.polygon / step, region.axis) for region in _as_regions(concave))
    rec = reconstruct(coarse, mask=coarse_mask, filter=spec, references=coarse_refs,
                      concave=regions or None, **options)

    normals = np.full(image.shape + (3,), np.nan)
    depth = np.full(image.shape, np.nan)
    grid_normals = normals[::step, ::step]
    grid_depth = depth[::step, ::step]
    grid_normals[coarse_mask] = rec.normals[coarse_mask]
    grid_depth[coarse_mask] = rec.depth[coarse_mask] * step  # heights in input pixels
    info = {**rec.info, "preview_step": step,
            "references": [(r * step, c * step) for r, c in rec.info["references"]]}
    return Reconstruction(normals=normals, depth=depth, mask=mask, light=rec.light, albedo=rec.albedo,
                          info=info)


def _keep_caps(image, mask, coarse, coarse_mask, step: int) -> np.ndarray:
    """``coarse`` with every bright cap of ``image`` kept: a cap (the pixels within the eikonal
    solver's tolerance of the object's brightest value, where the eikonal and oblique solvers
    find their singular points) that no grid point samples (the vase's lip on the top row, a thin
    rim) gives its brightest value to the grid point on the object nearest to it. Without it the
    quick look loses that singular point and marches the region from elsewhere (vase 256 px,
    step 2: 6.3 % depth error)."""
    from scipy.spatial import cKDTree

    from shadeform.solvers.eikonal import TOL

    peak = float(image[mask].max())
    labels, count = ndi.label(mask & (image >= (1.0 - TOL) * peak), structure=np.ones((3, 3)))
    sampled = np.zeros(count + 1, dtype=bool)
    sampled[labels[::step, ::step][coarse_mask]] = True
    missing = np.flatnonzero(~sampled[1:]) + 1
    if missing.size == 0:
        return coarse
    # the brightest pixel of each missing cap: the last of its pixels sorted by value
    rows, cols = np.nonzero(np.isin(labels, missing))
    owner = labels[rows, cols]
    order = np.lexsort((image[rows, cols], owner))
    last = order[np.r_[owner[order][1:] != owner[order][:-1], True]]
    brightest = np.column_stack([rows[last], cols[last]])
    # the nearest grid point; a search over the object's grid points only where that is off it
    near = np.minimum(np.rint(brightest / step).astype(int), np.array(coarse_mask.shape) - 1)
    off = ~coarse_mask[near[:, 0], near[:, 1]]
    if off.any():
        grid = np.argwhere(coarse_mask)
        near[off] = grid[cKDTree(grid * step).query(brightest[off])[1]]
    out = coarse.copy()
    np.maximum.at(out, (near[:, 0], near[:, 1]), image[brightest[:, 0], brightest[:, 1]])
    return out


#: Most object pixels a quick look solves with each solver: about 0.1 s of solver time on one core
#: of the 2-core machine of ``benchmarks/results/app.md`` (the oblique solver's descent costs
#: ~50x more per pixel than fast marching on grids this small: 7,400 pixels took 0.36 s).
PREVIEW_PIXELS = {"eikonal": 40_000, "propagation": 40_000, "oblique": 2_500}


def preview_step(mask: np.ndarray, step: int, *, method: str = "auto", light: Any = (0.0, 0.0, 1.0)) -> int:
    """The grid spacing of a quick look (:func:`reconstruct_preview`) for a mesh of ``step``.

    ``step`` itself, doubled until the object's pixels on the grid fit the solver's budget
    (:data:`PREVIEW_PIXELS`); the quick look's mesh is then coarser than the one asked for.

    Parameters
    ----------
    mask : (H, W) bool
        The object.
    step : int
        The mesh's grid spacing in pixels.
    method : str, keyword-only
        As for :func:`reconstruct`; "auto" is resolved for ``light`` on a clean image.
    light : (3,) float or "estimate", keyword-only
        As for :func:`reconstruct`; an estimated light counts as oblique.

    Returns
    -------
    int
        A multiple of ``step``.
    """
    if method == "auto":
        method = "oblique" if isinstance(light, str) else best_method(as_light(light))
    budget = PREVIEW_PIXELS.get(method, PREVIEW_PIXELS["oblique"])
    count = int(np.count_nonzero(mask))
    spacing = max(int(step), 1)
    while count / spacing ** 2 > budget and min(mask.shape) // (2 * spacing) >= MIN_SIDE:
        spacing *= 2
    return spacing


def _parse_reference(item, mask) -> tuple[tuple[int, int], np.ndarray | None]:
    """A reference ``(row, col)`` or ``(row, col, (nx, ny, nz))`` checked against the mask, as
    ``((row, col), unit normal or None)``."""
    try:
        r, c = int(item[0]), int(item[1])
        normal = None if len(item) < 3 or item[2] is None else np.asarray(item[2], dtype=np.float64)
    except (TypeError, ValueError, IndexError):
        raise InputError(f"reference {item!r} must be (row, col) or (row, col, (nx, ny, nz))") from None
    if not (0 <= r < mask.shape[0] and 0 <= c < mask.shape[1]) or not mask[r, c]:
        raise InputError(f"reference pixel (row {r}, col {c}) is not on the object; pick a pixel inside the mask")
    if normal is not None:
        length = np.linalg.norm(normal)
        if normal.shape != (3,) or not np.isfinite(normal).all() or length == 0:
            raise InputError(f"reference normal {item[2]!r} must be three finite numbers, not all zero")
        normal = normal / length
    return (r, c), normal


def _coarse_reference(item, mask, coarse_mask, step):
    """A reference ``(row, col[, normal])`` in input pixels, checked, moved to the coarse grid."""
    (r, c), normal = _parse_reference(item, mask)
    height, width = coarse_mask.shape
    cr, cc = min(round(r / step), height - 1), min(round(c / step), width - 1)
    if not coarse_mask[cr, cc]:
        rows, cols = np.nonzero(coarse_mask)
        nearest = np.argmin((rows - r / step) ** 2 + (cols - c / step) ** 2)
        cr, cc = int(rows[nearest]), int(cols[nearest])
    return (cr, cc) if normal is None else (cr, cc, normal)
