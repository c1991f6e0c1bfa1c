"""Photometric stereo: normals and albedo from several photos taken under known lights.

With a distant light ``l_j`` (unit, toward the light, strength folded into the image) a Lambertian
pixel of albedo ``rho`` and normal ``n`` reads ``I_j = rho max(0, n . l_j)``. Where three or more
non-coplanar lights reach it, ``g = rho n`` is the least-squares solution of ``L g = I`` (Woodham
1980): ``n = g / |g|``, ``rho = |g|``.

Real objects break the model in two ways that bias that solution: attached shadows (``n . l <= 0``
reads 0, not the negative value the linear model wants; dim, grazing light is also where real
matte paints depart most from Lambert) and specular highlights (far above the Lambertian value,
near the mirror direction). The robust method (the default) leaves them out, pixel by pixel:

1. a first fit from each pixel's middle-ranked intensities (its darkest and brightest readings,
   where shadows and highlights fall, are left out);
2. then, for ``iterations`` rounds, each image counts at a pixel only where the current normal
   says it is lit (``n . l >= min_shading``), away from the mirror direction (the half vector
   ``h = (l + v) / |l + v|``, ``v = +z``, more than ``highlight_angle`` from ``n``) and not
   brighter than the Lambertian prediction by more than the noise explains (``EXCESS``,
   ``SPREAD``; a highlight only adds light, so the test is one-sided); the pixel is refitted from
   those. A pixel left with fewer than three usable, non-coplanar lights keeps its last estimate.

This is the shadow and highlight masking of Barsky & Petrou (2003) and Mukaigawa et al. (2007)
driven by the current estimate. The thresholds were set on synthetic Blinn-Phong spheres with
noise (``benchmarks/bench_stereo.py``), not on the real data the benchmark reports.

Colour photos are solved on their mean channel (after dividing each channel by its light's
strength); each channel's albedo is then the least-squares fit with the normals held.

References
----------
.. [1] R. J. Woodham, "Photometric method for determining surface orientation from multiple
   images", Optical Engineering 19(1), 1980.
.. [2] S. Barsky, M. Petrou, "The 4-source photometric stereo technique for three-dimensional
   surfaces in the presence of highlights and shadows", IEEE PAMI 25(10), 2003.
.. [3] Y. Mukaigawa, Y. Ishii, T. Shakunaga, "Analysis of photometric factors based on photometric
   linearization", JOSA A 24(10), 2007.
.. [4] B. Shi et al., "A benchmark dataset and evaluation for non-Lambertian and uncalibrated
   photometric stereo", IEEE PAMI 41(2), 2019 (DiLiGenT).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shadeform._checks import check_choice, check_mask
from shadeform.errors import InputError

METHODS = ("robust", "least_squares")
# The robust fit's thresholds below were chosen on synthetic Blinn-Phong spheres
# (benchmarks/bench_stereo.py), not on the real photos it is reported on.

#: Smallest ``n . l`` of an image the robust fit uses: dimmer readings are shadowed or grazing.
MIN_SHADING = 0.1
#: Degrees: an image whose half vector lies within this of the normal may hold a highlight.
HIGHLIGHT_ANGLE = 10.0
#: A reading above the Lambertian prediction by more than this fraction of the albedo, or by more
#: than ``SPREAD`` times the spread (sigma) of the pixel's residuals if that is larger, is taken
#: as a highlight: highlights only ever add light.
EXCESS = 0.02
SPREAD = 2.0
#: Rounds of the robust fit's classify-and-refit.
ITERATIONS = 8
#: Fractions of each pixel's darkest and brightest readings the robust first fit leaves out.
DROP_DARK, DROP_BRIGHT = 0.3, 0.2
#: Pixels solved at once: bounds the memory of the (images x pixels) arrays.
CHUNK = 1 << 15


@dataclass(frozen=True)
class PhotometricStereo:
    """Result of :func:`photometric_stereo`.

    Attributes
    ----------
    normals : (H, W, 3) float64
        Unit normals in the camera frame; NaN outside the mask and where no three usable lights
        reached the pixel.
    albedo : (H, W) or (H, W, C) float64
        Albedo per pixel (per channel for colour photos), in the images' units after dividing by
        the lights' strengths; NaN where the normal is.
    lights_used : (H, W) int
        How many images the final fit used at each pixel (0 outside the mask).
    method : str
        ``"robust"`` or ``"least_squares"``.
    """

    normals: np.ndarray
    albedo: np.ndarray
    lights_used: np.ndarray
    method: str


def photometric_stereo(
    images,
    lights,
    mask=None,
    *,
    intensities=None,
    method: str = "robust",
    min_shading: float = MIN_SHADING,
    highlight_angle: float = HIGHLIGHT_ANGLE,
    iterations: int = ITERATIONS,
) -> PhotometricStereo:
    """Normals and albedo of a still object photographed under several known distant lights.

    Parameters
    ----------
    images : (N, H, W) or (N, H, W, C) array_like
        ``N >= 3`` photos, linear intensities (not gamma-encoded), same camera and object.
    lights : (N, 3) array_like
        Direction toward each photo's light in the camera frame (``docs/conventions.md``: x right,
        y up, z toward the viewer); normalised here.
    mask : (H, W) array_like of bool, optional
        Object pixels. Default: every pixel that is non-zero in some photo.
    intensities : (N,) or (N, C) array_like, optional
        Strength of each photo's light (per channel): the photos are divided by it.
    method : {"robust", "least_squares"}
        ``"least_squares"``: Woodham's fit of every reading. ``"robust"``: shadows and highlights
        left out per pixel (module docstring).
    min_shading : float
        Robust only: smallest ``n . l`` an image must have at a pixel to count there, in [0, 1).
    highlight_angle : float
        Robust only: degrees, in [0, 90); an image whose half vector is closer than this to the
        normal does not count (0 keeps them all).
    iterations : int
        Robust only: classify-and-refit rounds, >= 0.

    Returns
    -------
    PhotometricStereo
        Normals (H, W, 3), albedo, lights used per pixel.

    Raises
    ------
    InputError
        Shapes that do not match, fewer than three photos, lights that are not finite, are zero
        or all lie in one plane, non-finite or negative intensities, an empty mask, or options
        out of range.

    References
    ----------
    .. [1] R. J. Woodham, "Photometric method for determining surface orientation from multiple
       images", Optical Engineering 19(1), 1980.
    .. [2] S. Barsky, M. Petrou, "The 4-source photometric stereo technique for
       three-dimensional surfaces in the presence of highlights and shadows", IEEE PAMI 25(10),
       2003.

    Examples
    --------
    >>> import numpy as np
    >>> from shadeform import synth
    >>> scene = synth.scene("sphere", size=64)
    >>> lights = np.array([[0, 0, 1], [0.5, 0, 0.87], [0, 0.5, 0.87], [-0.5, -0.5, 0.71]])
    >>> photos = [synth.render(scene.normals, scene.mask, light=l, albedo=0.6) for l in lights]
    >>> result = photometric_stereo(photos, lights, scene.mask)
    >>> inner = scene.mask & (scene.normals[..., 2] > 0.8)
    >>> bool(np.allclose(result.normals[inner], scene.normals[inner], atol=1e-6))
    True
    >>> round(float(np.nanmedian(result.albedo)), 3)
    0.6
    """
    stack, lights, mask, scale = _check(images, lights, mask, intensities)
    check_choice(method, METHODS, "method")
    if not (np.isfinite(min_shading) and 0 <= min_shading < 1):
        raise InputError(f"min_shading must be in [0, 1), got {min_shading!r}")
    if not (np.isfinite(highlight_angle) and 0 <= highlight_angle < 90):
        raise InputError(f"highlight_angle must be in [0, 90) degrees, got {highlight_angle!r}")
    if int(iterations) != iterations or iterations < 0:
        raise InputError(f"iterations must be a non-negative integer, got {iterations!r}")

    h, w = mask.shape
    channels = stack.shape[3] if stack.ndim == 4 else 0
    where = np.flatnonzero(mask)
    normals = np.full((where.size, 3), np.nan)
    albedo = np.full((where.size, max(channels, 1)), np.nan)
    used = np.zeros(where.size, dtype=np.int64)
    flat = stack.reshape(len(lights), h * w, -1)
    for start in range(0, where.size, CHUNK):
        part = slice(start, start + CHUNK)
        # only the object's readings are read, converted and divided by the lights' strengths
        readings = flat[:, where[part]] / scale[:, None, :]  # (N, P, C or 1) float64
        if not np.isfinite(readings).all():
            raise InputError("images contain NaN or inf on the object; give finite intensities")
        gray = readings.mean(axis=2)
        if method == "least_squares":
            g, usable = _fit(lights, gray, np.ones_like(gray))
        else:
            g, usable = _robust(
                lights,
                gray,
                min_shading=min_shading,
                highlight_cos=np.cos(np.radians(highlight_angle)),
                iterations=int(iterations),
            )
        length = np.linalg.norm(g, axis=1)
        ok = np.isfinite(length) & (length > 0)
        n = np.full_like(g, np.nan)
        n[ok] = g[ok] / length[ok, None]
        normals[part] = n
        used[part] = np.where(ok, usable.sum(axis=0), 0)
        if channels:
            shading = np.where(usable, lights @ np.nan_to_num(n).T, 0.0)  # (N, P)
            energy = np.sum(shading * shading, axis=0)
            fit = np.einsum("np,npc->pc", shading, readings) / np.where(energy > 0, energy, 1)[:, None]
            albedo[part] = np.where(ok[:, None], fit, np.nan)
        else:
            albedo[part, 0] = np.where(ok, length, np.nan)

    out_normals = np.full((h * w, 3), np.nan)
    out_normals[where] = normals
    out_albedo = np.full((h * w, albedo.shape[1]), np.nan)
    out_albedo[where] = albedo
    out_used = np.zeros(h * w, dtype=np.int64)
    out_used[where] = used
    shape = (h, w, channels) if channels else (h, w)
    return PhotometricStereo(
        normals=out_normals.reshape(h, w, 3),
        albedo=out_albedo.reshape(shape),
        lights_used=out_used.reshape(h, w),
        method=method,
    )


def _fit(lights, readings, weights):
    """Per pixel, ``g`` minimising ``sum_j w_j (l_j . g - I_j)^2``: (P, 3), NaN where the used
    lights do not span 3-D; and the 0/1 usage (N, P)."""
    outer = (lights[:, :, None] * lights[:, None, :]).reshape(len(lights), 9)
    A = (weights.T @ outer).reshape(-1, 3, 3)
    b = (weights * readings).T @ lights
    # det(A) against (trace / 3)^3 (1 for well-spread lights): near 0 when the used lights are
    # (nearly) coplanar or fewer than three
    ok = np.linalg.det(A) > 1e-6 * (np.trace(A, axis1=1, axis2=2) / 3) ** 3
    ok &= np.trace(A, axis1=1, axis2=2) > 0
    g = np.full(b.shape, np.nan)
    if ok.any():
        g[ok] = np.linalg.solve(A[ok], b[ok, :, None])[..., 0]
    return g, np.broadcast_to(weights > 0, readings.shape) & ok[None, :]


def _robust(lights, readings, *, min_shading, highlight_cos, iterations):
    """The robust fit (module docstring): (P, 3) ``g`` and the final usage (N, P)."""
    count = len(lights)
    order = np.argsort(readings, axis=0)
    low = int(DROP_DARK * count) if count > 4 else min(1, count - 3)
    high = int(DROP_BRIGHT * count) if count > 4 else 0
    start = np.zeros_like(readings)
    np.put_along_axis(start, order[low : count - high], 1.0, axis=0)
    g, usable = _fit(lights, readings, start)
    # pixels whose middle readings do not span 3-D start from all of their lit readings
    lost = ~np.isfinite(g[:, 0])
    if lost.any():
        g[lost], usable[:, lost] = _fit(lights, readings[:, lost], (readings[:, lost] > 0).astype(np.float64))
    half = lights + np.array([0.0, 0.0, 1.0])
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    for _ in range(iterations):
        solved = np.isfinite(g[:, 0])
        n = np.where(solved[:, None], g, 0.0)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        current = np.where(solved[:, None], g, 0.0)
        excess = readings - lights @ current.T
        # the spread of the residuals the last fit used, so that noise is not taken for a
        # highlight: their mean absolute value, times sqrt(pi / 2) for a Gaussian's sigma
        spread = 1.2533 * np.sum(np.abs(excess) * usable, axis=0) / np.maximum(usable.sum(axis=0), 1)
        limit = np.maximum(EXCESS * np.linalg.norm(current, axis=1), SPREAD * spread)
        keep = (lights @ n.T >= min_shading) & (half @ n.T <= highlight_cos) & (excess <= limit)
        g_new, usable_new = _fit(lights, readings, keep.astype(np.float64))
        better = solved & np.isfinite(g_new[:, 0])
        g[better] = g_new[better]
        usable[:, better] = usable_new[:, better]
    return g, usable


def _check(images, lights, mask, intensities):
    try:
        stack = np.asarray(images)  # kept as given: only the object's readings are converted
        lights = np.asarray(lights, dtype=np.float64)
    except (TypeError, ValueError):
        stack = None
    if stack is None or not (
        np.issubdtype(stack.dtype, np.floating) or np.issubdtype(stack.dtype, np.integer)
    ):
        raise InputError("images and lights must be numeric arrays: (N, H, W[, C]) and (N, 3)")
    if stack.ndim not in (3, 4) or (stack.ndim == 4 and stack.shape[3] not in (1, 3, 4)):
        raise InputError(
            f"images must be (N, H, W) or (N, H, W, C) with C 1, 3 or 4, got shape {stack.shape}"
        )
    if stack.ndim == 4 and stack.shape[3] == 4:
        stack = stack[..., :3]  # alpha carries no shading
    if stack.ndim == 4 and stack.shape[3] == 1:
        stack = stack[..., 0]
    count = stack.shape[0]
    if count < 3:
        raise InputError(f"photometric stereo needs at least 3 photos under different lights, got {count}")
    if lights.shape != (count, 3):
        raise InputError(f"lights must be (N, 3) with N = {count} (one per photo), got shape {lights.shape}")
    if not np.isfinite(lights).all():
        raise InputError("lights contain NaN or inf; give a direction toward each photo's light")
    lengths = np.linalg.norm(lights, axis=1)
    if (lengths == 0).any():
        raise InputError(f"light {int(np.argmin(lengths)) + 1} is the zero vector; give a direction")
    lights = lights / lengths[:, None]
    if np.linalg.matrix_rank(lights, tol=1e-3) < 3:
        raise InputError(
            "the lights all lie in one plane, so they cannot fix a normal; photograph "
            "the object under lights from at least three non-coplanar directions"
        )
    scale = np.ones((count, 1))
    if intensities is not None:
        strength = np.asarray(intensities, dtype=np.float64)
        channels = stack.shape[3] if stack.ndim == 4 else None
        allowed = {(count,)} | ({(count, channels)} if channels else set())
        if strength.shape not in allowed:
            raise InputError(
                f"intensities must be (N,) or (N, C) = {sorted(allowed)}, got shape {strength.shape}"
            )
        if not (np.isfinite(strength).all() and (strength > 0).all()):
            raise InputError("intensities must be finite and positive (each photo's light strength)")
        scale = strength.reshape(count, -1)
    if mask is None:
        mask = (stack.reshape(count, *stack.shape[1:3], -1) > 0).any(axis=(0, 3))
    else:
        mask = check_mask(mask, stack.shape[1:3], of="each photo")
    if not mask.any():
        raise InputError("the mask is empty (or every photo is black); mark the object's pixels")
    return stack, lights, mask, scale


def reconstruct_stereo(
    images, lights, mask=None, *, intensities=None, method: str = "robust", integrator: str = "poisson"
):
    """Photometric stereo, then depth: the several-photo counterpart of
    :func:`shadeform.reconstruct`.

    Parameters
    ----------
    images, lights, intensities, method
        As for :func:`photometric_stereo`.
    mask : (H, W) array_like of bool, optional
        Object pixels. Default: found in the brightest reading of each pixel over the photos, as
        :func:`shadeform.preprocess.object_mask` finds an object on a dark background.
    integrator : {"poisson", "bilateral", "fourier", "paths"}
        Depth from the normals (:func:`shadeform.integrate`); ``z = 0`` at the most frontal
        normal.

    Returns
    -------
    shadeform.Reconstruction
        ``mask`` is the object less the pixels no three lights reached; ``light`` the mean of the
        lights' directions (for shading a view), ``albedo`` the gray albedo (H, W); ``info``
        holds ``method``, ``integrator``, ``photos``, ``lights_used`` (median per pixel) and
        ``timings`` in seconds.

    Raises
    ------
    InputError
        As :func:`photometric_stereo`, an unknown integrator, or no pixel reached by three lights.
    """
    import time

    from shadeform.integration import available_integrators, integrate
    from shadeform.reconstruction import Reconstruction

    check_choice(integrator, tuple(available_integrators()), "integrator")
    start = time.perf_counter()
    if mask is None:
        from shadeform.preprocess import object_mask

        stack = np.asarray(images)
        brightest = stack.max(axis=0) if stack.ndim == 3 else stack.max(axis=(0, 3))
        peak = float(brightest.max()) if brightest.size else 0.0
        if not (np.isfinite(peak) and peak > 0):
            raise InputError("every photo is black (or not finite); give photos of the lit object")
        mask = object_mask(brightest / peak)
    result = photometric_stereo(images, lights, mask, intensities=intensities, method=method)
    solved = np.isfinite(result.normals[..., 0])
    if not solved.any():
        raise InputError(
            "no pixel is lit by three photos whose lights span 3-D; check the lights "
            "and that the photos show the object"
        )
    normals_time = time.perf_counter()
    depth = integrate(result.normals, solved, method=integrator)
    done = time.perf_counter()
    directions = np.asarray(lights, dtype=np.float64)
    mean = (directions / np.linalg.norm(directions, axis=1, keepdims=True)).mean(axis=0)
    albedo = result.albedo if result.albedo.ndim == 2 else result.albedo.mean(axis=2)
    return Reconstruction(
        normals=np.where(solved[..., None], result.normals, np.nan),
        depth=depth,
        mask=solved,
        light=mean / np.linalg.norm(mean),
        albedo=albedo,
        info={
            "method": f"photometric stereo ({method})",
            "integrator": integrator,
            "photos": len(directions),
            "lights_used": float(np.median(result.lights_used[solved])),
            "timings": {"normals": normals_time - start, "depth": done - normals_time},
        },
    )
