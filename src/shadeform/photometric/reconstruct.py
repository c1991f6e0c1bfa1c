"""Photometric stereo, then depth: :func:`reconstruct_stereo`, the several-photo counterpart of
:func:`shadeform.reconstruct`.
"""

from __future__ import annotations

import numpy as np

from shadeform._checks import check_choice
from shadeform._deprecated import renamed_keywords
from shadeform.errors import InputError
from shadeform.photometric.stereo import photometric_stereo

#: A depth that spans more than this many times the outline's longest side is not a surface the
#: photos show: a bas-relief the uncalibrated stereo resolved wrong (a slab; DiLiGenT's cow and
#: reading read from their photos span 12-13 times their outline, the other five 0.4-1.0). The
#: bar issue 36 set, not a value swept.
SLAB_SPAN = 2.0


@renamed_keywords(method="model")
def reconstruct_stereo(
    images,
    lights=None,
    mask=None,
    *,
    intensities=None,
    model: str = "bivariate",
    integrator: str = "poisson",
    sphere=None,
    refine_lights: bool = True,
):
    """Photometric stereo, then depth: the several-photo counterpart of
    :func:`shadeform.reconstruct`.

    Parameters
    ----------
    images, lights, intensities, model
        As for :func:`photometric_stereo` (``lights=None``: read from the photos).
    mask : (H, W) array_like of bool, optional
        Object pixels. Default: found from all the photos by
        :func:`shadeform.masks.find_object_in_set` (the background, and the insides that few
        lights reach, left out).
    integrator : {"poisson", "bilateral", "fourier", "paths"}
        Depth from the normals (:func:`shadeform.integrate`); ``z = 0`` at the most frontal
        normal.
    sphere : (3,) array_like, optional
        A calibration sphere's circle ``(column, row, radius)`` in the photos: left out of the
        automatic mask (with a rim of a tenth of its radius).
    refine_lights : bool
        As for :func:`photometric_stereo`.

    Returns
    -------
    shadeform.Reconstruction
        ``mask`` is the object (every pixel of it has a normal); ``light`` the mean of the
        lights' directions (for shading a view), ``albedo`` (H, W), or (H, W, C) for colour
        photos,
        ``confidence`` the fit's (:class:`PhotometricStereo`, NaN off the mask); ``info`` holds
        ``solver`` (``"photometric stereo (MODEL)"``, as :func:`shadeform.reconstruct` says what
        ran), ``model`` (the photometric model's name), ``integrator``, ``photos``, ``lights_used`` (median per pixel),
        ``photos_rescaled`` (``[index, factor]`` pairs), ``photos_dropped``, ``light_scale``
        (:class:`PhotometricStereo`), ``lights`` (given or read), ``light_directions`` (the unit
        directions used, a list of ``[x, y, z]``), ``timings`` in seconds and ``quality``: the
        quality line of every stereo result, ``depth_span`` (:func:`depth_span`); with lights read
        from the photos ``relief_settled`` and ``entropy_rise`` (the albedo entropy's rise at half
        and twice the depth, in bootstrap spreads:
        :class:`~shadeform.photometric.uncalibrated.ReliefCheck`); and, when the span is above
        :data:`SLAB_SPAN` or the relief is not settled, a ``warning`` that says what to do.

    Raises
    ------
    InputError
        As :func:`photometric_stereo`, or an unknown integrator.
    """
    import time

    from shadeform.integration import available_integrators, integrate
    from shadeform.reconstruction import Reconstruction

    check_choice(integrator, tuple(available_integrators()), "integrator")
    start = time.perf_counter()
    if mask is None:
        from shadeform.masks import find_object_in_set

        mask = find_object_in_set(images).mask
        if sphere is not None:
            column, row, radius = np.asarray(sphere, dtype=np.float64)
            rows, cols = np.ogrid[0 : mask.shape[0], 0 : mask.shape[1]]
            mask &= (cols - column) ** 2 + (rows - row) ** 2 > (1.1 * radius) ** 2
            if not mask.any():
                raise InputError("the photos show nothing but the sphere; give a mask of the object")
    result = photometric_stereo(
        images, lights, mask, intensities=intensities, model=model, refine_lights=refine_lights
    )
    solved = np.isfinite(result.normals[..., 0])
    normals_time = time.perf_counter()
    depth = integrate(result.normals, solved, integrator=integrator)
    done = time.perf_counter()
    directions = np.asarray(lights if result.lights is None else result.lights, dtype=np.float64)
    mean = (directions / np.linalg.norm(directions, axis=1, keepdims=True)).mean(axis=0)
    span = depth_span(depth, solved)
    checks = {"depth_span": round(span, 3)}
    doubts = []
    if span > SLAB_SPAN:
        doubts.append(
            f"the depth spans {span:.1f} times the outline's longest side: not a surface the photos show"
        )
    if result.relief is not None:
        checks["relief_settled"] = result.relief.resolved
        checks["entropy_rise"] = round(result.relief.rise / max(result.relief.spread, 1e-12), 1)
        if not result.relief.resolved:
            doubts.append(
                "the photos did not settle the relief (the albedo's entropy has no minimum): the depth is a guess"
            )
    if doubts:
        checks["warning"] = "; ".join(doubts) + (
            " (the lights read from the photos resolved the shape wrong); give the light file, or "
            "read the lights from a shiny sphere in the photos"
            if lights is None
            else "; check the light file's frame (x right, y up, z toward the camera) and the mask"
        )
    return Reconstruction(
        normals=result.normals,
        depth=depth,
        mask=solved,
        light=mean / np.linalg.norm(mean),
        albedo=result.albedo,
        info={
            "solver": f"photometric stereo ({model})",
            "model": model,
            "integrator": integrator,
            "photos": len(directions),
            "lights_used": float(np.median(result.lights_used[solved])),
            "photos_rescaled": [[i, round(f, 4)] for i, f in result.photos_rescaled],
            "photos_dropped": list(result.photos_dropped),
            "light_scale": round(result.light_scale, 4),
            "lights": "read from the photos" if lights is None else "given",
            "light_directions": (directions / np.linalg.norm(directions, axis=1, keepdims=True)).tolist(),
            "timings": {"normals": normals_time - start, "depth": done - normals_time},
            "quality": checks,
        },
        confidence=np.where(solved, result.confidence, np.nan),
    )


def depth_span(depth: np.ndarray, mask: np.ndarray) -> float:
    """The depth's range over the mask in units of the outline's longest side (its bounding box's);
    0 for an empty mask."""
    if not mask.any():
        return 0.0
    rows, cols = np.nonzero(mask)
    side = max(np.ptp(rows), np.ptp(cols)) + 1
    values = depth[mask]
    return float((np.nanmax(values) - np.nanmin(values)) / side)
