"""``reconstruct()``: one call from a shading image to normals and depth.

load -> (mask, filter) -> light -> solvers[solver] -> depth. This module checks the user's input
once, at the boundary, prepares what every solver needs (:class:`shadeform.solvers.Problem`) and
looks the solver up in the registry (:mod:`shadeform.solvers`); it knows no solver by name.
The solves on the image's grid (quick looks, :func:`~shadeform.coarse.reconstruct_preview`) are
in :mod:`shadeform.coarse`, which calls :func:`reconstruct`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy import ndimage as ndi

from shadeform._checks import StageTimer, check_choice, check_mask, shading_image, whole
from shadeform._deprecated import renamed_keywords
from shadeform.confidence import assess
from shadeform.errors import InputError
from shadeform.integration import available_integrators
from shadeform.light import as_light, estimate_light
from shadeform.masks import FoundObject, find_object
from shadeform.preprocess import Filter, apply_filter, image_detail, noise_level, parse_filter
from shadeform.reconstruction import Reconstruction
from shadeform.regions import as_regions, concave_masks
from shadeform.solvers import (
    AUTO,
    NOISY,
    SOLVERS,
    Problem,
    Reference,
    available_solvers,
    choose,
    get_solver,
    solver_names,
)
from shadeform.solvers.bounds import bound_depth

#: Smallest image side the solvers can work on (a gradient needs neighbours on both sides).
MIN_SIDE = 3
#: An object with at least this fraction of its pixels at the white level carries no shading.
SATURATED_FRACTION = 0.9


#: Most integrability refinement iterations (``refine``) accepted; the app's limit too.
MAX_REFINE = 100


@renamed_keywords(method="solver", method_options="solver_options")
def reconstruct(
    image: np.ndarray,
    *,
    light: Sequence[float] | str = (0.0, 0.0, 1.0),
    solver: str = "auto",
    mask: np.ndarray | FoundObject | None = None,
    filter: str | Filter | None = None,
    references: Sequence | None = None,
    concave: Any = None,
    integrator: str | None = None,
    refine: int = 3,
    solver_options: Mapping[str, Any] | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> Reconstruction:
    """Recover normals and depth from one shading image.

    The image is checked, the object found (or the mask checked), the filter applied, the light
    settled (given or estimated), the reference pixels and the brightness ``k * albedo`` found;
    then the solver named by ``solver`` (:func:`shadeform.solvers.available_solvers`) turns them
    into normals and depth.

    Parameters
    ----------
    image : (H, W) float array
        One channel, values >= 0 (e.g. from :func:`shadeform.load_image`); integer arrays are
        scaled by their type's maximum.
    light : (3,) float or "estimate"
        Direction toward the light in the camera frame (``docs/conventions.md``), or
        ``"estimate"`` to estimate it and ``k * albedo`` from the image
        (:func:`shadeform.light.estimate_light`; ``info["light_estimate"]`` says how).
    solver : str
        "auto" (the default: the best measured solver for the light and the image's noise and
        outlying detail, :func:`shadeform.solvers.choose`, ``info["detail"]``: "photo" for a
        noisy photograph with highlights, shadows or texture) or a registered solver: "photo"
        (:mod:`shadeform.solvers.photo`), "propagation" (the 2002
        convexity-guided propagation, any light), "eikonal" (fast marching of the eikonal equation
        from the singular points, light at +z only; concave regions and references become minima,
        saddles and maxima: :mod:`shadeform.solvers.eikonal`), "oblique" (any light, attached
        shadows as ``N . L <= 0``; marching from the brightest pixels, then descent on chord
        equations: :mod:`shadeform.solvers.oblique`; the first reference only sets where
        ``z = 0``), or any solver added with :func:`shadeform.solvers.register`.
    mask : (H, W) bool or FoundObject, optional
        Object pixels; by default found automatically on ``image``
        (:func:`shadeform.masks.find_object`). A :class:`~shadeform.masks.FoundObject` is an
        automatic mask the caller found, e.g. on the photo's colours (``find_object(photo.pixels)``,
        as the command line does; colours find an object on a textured background far more often
        than brightness does, ``benchmarks/results/masks.md``): its warning, if doubtful, is
        ``info["mask_warning"]`` as for the mask found here.
    filter : str or Filter, optional
        ``"none"``, ``"gaussian:SIGMA"``, ``"mean:R"``, ``"median:R"`` or ``"minimum:R"``. Not
        given, a solver with a noise policy smooths a noisy image its own way (the oblique solver:
        ``info["auto_filter"]``); ``"none"`` turns that off.
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
        the bounding rectangle, or discontinuity-preserving (:func:`shadeform.integration.integrate`).
        By default the solver's own ("paths" for propagation, the solver's depth for "eikonal" and
        "oblique").
    refine : int
        Iterations of the integrability refinement of the propagated field
        (:func:`shadeform.solvers.propagation.refine_by_integrability`); 0 gives the report's
        field exactly.
    solver_options : mapping, optional
        The solver's own options, name to value (text is read as the option's type): those its
        registry entry declares (:class:`shadeform.solvers.Solver` ``options``; ``shadeform
        solvers`` lists them). The built-in solvers declare none. ``method=`` and ``method_options=``,
        their old names, still work for one release (``DeprecationWarning``).
    progress : callable, optional, keyword-only
        Called as ``progress(stage, fraction)`` after each stage (the names of
        ``info["timings"]``), ``fraction`` the rough share of the work done (:data:`STAGE_SHARES`);
        for a progress bar. An exception it raises stops the solve there.

    Returns
    -------
    Reconstruction
        ``normals`` (H, W, 3), ``depth`` (H, W) (NaN outside the mask), ``mask``, ``light``,
        ``albedo`` (``k * albedo`` of the image model) and ``info``. A depth that runs past what
        the outline allows is pulled back toward it (:func:`shadeform.solvers.bounds.bound_depth`,
        ``info["depth_bounded"]``).

    Raises
    ------
    InputError
        For every user mistake: wrong shapes, NaN, an empty, black or saturated object, a
        reference off the object, malformed regions, unknown solver names.

    Examples
    --------
    >>> from shadeform import synth, metrics
    >>> scene = synth.scene("sphere", size=64)
    >>> rec = reconstruct(scene.image, mask=scene.mask)
    >>> bool(metrics.angular_error(rec.normals, scene.normals) < 3)
    True
    """
    timer = StageTimer()
    lap = timer.lap if progress is None else _reporting(timer.lap, progress)
    image = _check_image(image)
    estimate_wanted = isinstance(light, str)
    if estimate_wanted and light != "estimate":
        raise InputError(f"light must be a direction (x, y, z) or 'estimate', got {light!r}")
    light = None if estimate_wanted else as_light(light)
    check_choice(solver, tuple(available_solvers()), "solver")  # "auto" too, unlike get_solver's list
    requested, solver = solver, None if solver == AUTO else get_solver(solver)
    # a named solver's options are checked before any work; "auto"'s once it has chosen
    settled_options = None if solver is None else SOLVERS.settle(solver.name, solver_options)
    if integrator is not None:
        check_choice(integrator, tuple(available_integrators()), "integrator")
    refine = whole(refine, "refine")
    if refine > MAX_REFINE:  # each iteration is a pass over the image: refuse before any work
        raise InputError(f"refine must be at most {MAX_REFINE} iterations, got {refine}")
    user_filter = parse_filter(filter) if filter else None

    decided: dict[str, Any] = {}  # what was settled on the way, for info
    mask, warning = _object(image, mask)
    if warning:  # a doubtful automatic mask: the CLI prints it, the app shows it
        decided["mask_warning"] = warning
    _check_shading(image, mask)
    lap("mask")
    shading = apply_filter(image, mask, user_filter) if user_filter else image
    lap("filter")
    if estimate_wanted:
        estimate = estimate_light(shading, mask)
        light = np.asarray(estimate.light, dtype=np.float64)
        decided["light_estimate"] = {
            "slant": float(estimate.slant),
            "tilt": float(estimate.tilt),
            "albedo": float(estimate.albedo),
            "evidence": estimate.evidence,
            "confidence": float(estimate.confidence),
            "unsure": estimate.unsure,
        }
        lap("light")
    noise = None
    if solver is None or solver.denoise is not None:
        detail = image_detail(shading, mask)
        noise = detail.noise
        brightest = float(shading[mask].max())
        if solver is None:
            solver = choose(light, noise=noise / brightest, outliers=detail.outliers)
            decided["detail"] = {"noise": noise / brightest, "outliers": detail.outliers}
        # the solver's noise policy: its own smoothing of a noisy image, unless the user chose a filter
        if solver.denoise is not None and user_filter is None and noise > NOISY * brightest:
            denoise = parse_filter(solver.denoise)
            shading = apply_filter(shading, mask, denoise)
            noise = noise_level(shading, mask)
            decided["auto_filter"] = str(denoise)
            lap("filter")
        if solver.denoise is None:
            noise = None
    if settled_options is None:
        settled_options = SOLVERS.settle(solver.name, solver_options)
    if not solver.takes(light):
        raise InputError(
            f"solver {solver.name!r} needs the light at (0, 0, 1); use "
            f"{' or '.join(repr(s) for s in _any_light())} for other light directions"
        )
    concave_x, concave_y = concave_masks(as_regions(concave), image.shape)
    labels, n_parts = ndi.label(mask)
    refs = _references(references, shading, mask, labels, n_parts)
    albedo = _brightness_scale(
        shading, mask, refs[0], light, estimated=float(estimate.albedo) if estimate_wanted else None
    )
    lap("references")

    problem = Problem(
        image=shading,
        mask=mask,
        light=light,
        albedo=albedo,
        references=tuple(refs),
        given=len(references or ()),
        concave_x=concave_x,
        concave_y=concave_y,
        labels=labels,
        parts=int(n_parts),
        integrator=integrator or solver.integrator,
        refine=refine,
        noise=noise,
        options=settled_options,
        lap=lap,
    )
    del concave_x, concave_y, labels  # the problem holds them until the solver is done
    solution = solver.run(problem)
    used_integrator = problem.integrator
    del problem  # free the solver's inputs before the confidence is assessed
    normals = _taken_over(solution.normals, mask, np.float32)
    depth = _taken_over(solution.depth, mask, np.float64)
    solved = solution.info
    del solution
    bounded = bound_depth(depth, normals, mask)  # no deeper than the outline allows
    normals, depth = bounded.normals, bounded.depth
    lap("combine")
    albedo = float(solved.get("albedo", albedo))  # a solver that estimates it knows better
    assessed = assess(shading, mask, light, normals, albedo=albedo, depth=depth)
    lap("confidence")
    info = {
        "solver": solver.name,
        "solver_requested": requested,
        "integrator": used_integrator or solver.depth,
        "refine": 0,
        "filter": user_filter.kind if user_filter else "none",
        "references": [ref.pixel for ref in refs],
        "parts": int(n_parts),
        "albedo": float(albedo),
        "timings": timer.timings,
        **solved,
        **decided,
        "unsure": [
            {
                "polygon": area.polygon.tolist(),
                "axis": area.axis,
                "share": area.share,
                "centre": list(area.centre),
            }
            for area in assessed.unsure
        ],
    }
    if settled_options:
        info["solver_options"] = settled_options
    if assessed.others:
        info["unsure_others"] = {"areas": assessed.others, "share": assessed.others_share}
    if bounded.applied:
        info["depth_bounded"] = {"pixels": bounded.pixels, "max_over": bounded.max_over}
    return Reconstruction(
        normals=normals,
        depth=depth,
        mask=mask,
        light=light,
        albedo=float(albedo),
        info=info,
        confidence=assessed.map,
    )


#: Share of the work done after each stage of :func:`reconstruct`, for ``progress``; a solver's own
#: stages (normals, depth, ...) keep the share reached before them. Measured on the 12 Mpx vase
#: (light +z, eikonal): references 11 % of the time, the solver 68 %, confidence 20 %.
STAGE_SHARES = {
    "mask": 0.02,
    "filter": 0.03,
    "light": 0.08,
    "references": 0.12,
    "combine": 0.8,
    "confidence": 1.0,
}


def _reporting(lap: Callable[[str], None], progress: Callable[[str, float], None]) -> Callable[[str], None]:
    """``lap`` that also tells ``progress`` the stage and the share of the work done."""
    done = [0.0]

    def report(stage: str) -> None:
        lap(stage)
        done[0] = max(done[0], STAGE_SHARES.get(stage, done[0]))
        progress(stage, done[0])

    return report


def _taken_over(values, mask, dtype) -> np.ndarray:
    """A solver's normals (H, W, 3) or depth (H, W) as ``dtype`` with NaN off ``mask``: its own
    array, written in place when it is a writable one of that type
    (:class:`shadeform.solvers.Solution` hands them over), else a converted copy. The normals are
    float32 (unit vectors: float64 adds nothing but 12 bytes per pixel); the depth float64."""
    values = np.asarray(values)
    if values.dtype != dtype or not values.flags.writeable:
        values = values.astype(dtype)
    values[~mask] = np.nan
    return values


def _any_light() -> list[str]:
    """The registered solvers that take any light."""
    return [name for name in solver_names() if get_solver(name).lights == "any"]


def _check_image(image) -> np.ndarray:
    image = shading_image(image)
    if min(image.shape) < MIN_SIDE:
        raise InputError(
            f"image is {image.shape[1]}x{image.shape[0]} pixels; it needs at least {MIN_SIDE}x{MIN_SIDE}"
        )
    return image


def _check_shading(image, mask) -> None:
    values = image[mask]
    top = values.max()
    if top <= 0:
        raise InputError(
            "the object is black: there is no shading to work with; check the exposure or the mask"
        )
    at_top = np.count_nonzero(values >= top * (1 - 1e-6)) / values.size
    if top >= 0.999 and at_top >= SATURATED_FRACTION:
        raise InputError(
            f"the image is saturated: {at_top:.0%} of the object is at the white level, so there is "
            "no shading to work with; use a shorter exposure"
        )


def _references(references, image, mask, labels, n_parts) -> list[Reference]:
    """User references checked, plus the brightest pixel of every part left without one."""
    refs = [_parse_reference(item, mask) for item in references or ()]
    covered = {labels[ref.pixel] for ref in refs}
    for part in range(1, n_parts + 1):
        if part in covered:
            continue
        in_part = labels == part
        top = image[in_part].max()
        rows, cols = np.nonzero(in_part & (image >= top * (1 - 1e-9)))
        # among equally bright pixels prefer the one deepest inside its part: a flat top's centre
        best = np.argmax(_depth_inside(mask, rows, cols)) if rows.size > 1 else 0
        refs.append(Reference(int(rows[best]), int(cols[best])))
    return refs


def _depth_inside(mask, rows, cols) -> np.ndarray:
    """``scipy.ndimage.distance_transform_edt(mask)`` at the given pixels only (inf where the
    mask has no background): the distance to the nearest background pixel that touches the mask,
    which is the nearest of all. A tree of those few pixels instead of the image's transform
    (on a megapixel 80-160 ms, and float and index arrays of the image's size)."""
    from scipy.spatial import cKDTree

    rim = np.argwhere(ndi.binary_dilation(mask, structure=np.ones((3, 3), dtype=bool)) & ~mask)
    if rim.size == 0:
        return np.full(rows.size, np.inf)
    distance, _ = cKDTree(rim).query(np.column_stack([rows, cols]))
    return distance


def _brightness_scale(image, mask, main: Reference, light, *, estimated=None) -> float:
    """``k * albedo``: from the main reference when its normal is given, else the light
    estimate's, else the brightest pixel (the 2002 rule: it faces the light)."""
    if main.normal is not None:
        facing = float(main.normal @ light)
        if facing <= 0 or image[main.pixel] <= 0:
            raise InputError(
                f"reference (row {main.row}, col {main.col}) is in shadow or its normal faces "
                "away from the light; pick a lit reference"
            )
        return float(image[main.pixel] / facing)
    if estimated is not None:
        return estimated
    return float(image[mask].max())


def _object(image: np.ndarray, mask) -> tuple[np.ndarray, str | None]:
    """The object's mask, checked, and the warning of a doubtful automatic one: found here on
    ``image`` when ``mask`` is None, or by the caller (a :class:`FoundObject`)."""
    if mask is None:
        mask = find_object(image)
    if isinstance(mask, FoundObject):
        return check_mask(mask.mask, image.shape), mask.warning
    return check_mask(mask, image.shape), None


def _parse_reference(item, mask) -> Reference:
    """A reference ``(row, col)`` or ``(row, col, (nx, ny, nz))`` checked against the mask."""
    try:
        r, c = int(item[0]), int(item[1])
        normal = None if len(item) < 3 or item[2] is None else np.asarray(item[2], dtype=np.float64)
    except (TypeError, ValueError, IndexError):
        raise InputError(f"reference {item!r} must be (row, col) or (row, col, (nx, ny, nz))") from None
    if not (0 <= r < mask.shape[0] and 0 <= c < mask.shape[1]) or not mask[r, c]:
        raise InputError(
            f"reference pixel (row {r}, col {c}) is not on the object; pick a pixel inside the mask"
        )
    if normal is not None:
        length = np.linalg.norm(normal)
        if normal.shape != (3,) or not np.isfinite(normal).all() or length == 0:
            raise InputError(f"reference normal {item[2]!r} must be three finite numbers, not all zero")
        normal = normal / length
    return Reference(r, c, normal)


def warm() -> dict[str, float]:
    """Compile the numba kernels of every solver and photometric model now, or load them from
    numba's cache.

    Set-up runs this (``make venv``, ``shadeform warm``) so that a user's first reconstruction
    or photo set does not wait for the compiler (nor does each test worker compile them again):
    each path runs once on a small image, which compiles exactly the specialisations a photo of
    any size uses (the kernels take C-ordered arrays of fixed types). numba keeps them beside the installed sources (``__pycache__``, or
    ``NUMBA_CACHE_DIR``), valid until those sources change.

    Returns
    -------
    dict of str to float
        Seconds per path: ``"light +z"`` (a 96-pixel synthetic vase lit from the viewer: the
        eikonal solver, the confidence, a mesh and its glTF file, what ``shadeform reconstruct``
        runs by default), ``"demo"`` (the shipped coin photo as ``shadeform demo`` solves it),
        ``"every solver"`` (each registered solver with its own integrator and every other one,
        on float32 photos as uploads are and float64 ones, and the light estimated) and
        ``"photo sets"`` (each photometric model and a set's depth).
    """
    import tempfile
    import time
    from pathlib import Path

    from shadeform import synth
    from shadeform.examples import load_example
    from shadeform.io.exporters import export
    from shadeform.mesh import to_mesh

    seconds = {}
    start = time.perf_counter()
    scene = synth.scene("vase", size=96)
    with tempfile.TemporaryDirectory() as folder:
        export(to_mesh(reconstruct(scene.image), step=2), Path(folder) / "warm.glb")
    seconds["light +z"] = time.perf_counter() - start
    start = time.perf_counter()
    image, info = load_example("coin")
    rec = reconstruct(
        image, light=info["light"], mask=info["mask"], filter=info["filter"], solver=info["solver"]
    )
    to_mesh(rec, step=2)
    seconds["demo"] = time.perf_counter() - start
    start = time.perf_counter()
    sphere = synth.scene("sphere", size=24)
    for image in (sphere.image.astype(np.float32), sphere.image):
        for solver in available_solvers():
            for integrator in (None, *available_integrators()):
                reconstruct(image, mask=sphere.mask, solver=solver, integrator=integrator)
        reconstruct(image, light="estimate")
    seconds["every solver"] = time.perf_counter() - start
    seconds["photo sets"] = _warm_photo_sets(sphere)
    return seconds


def _warm_photo_sets(scene) -> float:
    """Seconds to run each photometric model and a set's depth on ``scene`` under six lights."""
    import time

    from shadeform import synth
    from shadeform.light import light_from_slant_tilt
    from shadeform.photometric import available_stereo_models, reconstruct_stereo

    start = time.perf_counter()
    lights = np.array([light_from_slant_tilt(0.0 if i == 0 else 30.0, 72.0 * i) for i in range(6)])
    photos = np.stack([synth.render(scene.normals, scene.mask, light=light) for light in lights])
    for model in available_stereo_models():
        reconstruct_stereo(photos, lights, scene.mask, model=model)
    return time.perf_counter() - start


# moved to shadeform.coarse, which imports this module: still importable from here for one
# release, with a DeprecationWarning; imported when first asked for (no import at load, no cycle)
_MOVED = ("preview_step", "reconstruct_on_grid", "reconstruct_preview")


def __getattr__(name: str):
    if name in _MOVED:
        import warnings

        from shadeform import coarse

        warnings.warn(
            f"shadeform.pipeline.{name} moved to shadeform.coarse.{name}; the old name goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(coarse, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
