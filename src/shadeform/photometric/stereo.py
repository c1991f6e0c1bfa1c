"""Photometric stereo over a set of photos (:mod:`shadeform.photometric`'s description): the
input checks, the lights read or refined, the photos audited, the model's fit per pixel in
chunks, the holes filled, albedo per channel and the confidence.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from shadeform._checks import check_mask
from shadeform._deprecated import renamed_keywords
from shadeform.errors import InputError
from shadeform.photometric import lambertian
from shadeform.photometric.audit import _audit
from shadeform.photometric.holes import _fill
from shadeform.photometric.lambertian import HIGHLIGHT_ANGLE, ITERATIONS, MIN_SHADING
from shadeform.photometric.registry import STEREO_MODELS
from shadeform.photometric.uncalibrated import ReliefCheck
from shadeform.registry import load

#: Pixels solved at once: bounds the memory of the (images x pixels) arrays.
CHUNK = 1 << 15
#: Object pixels (evenly spaced) the search for contradicting photos fits: enough for a median.
SAMPLE = 4096
#: Object pixels (evenly spaced) on which the lights' slant is refined: a median's worth, kept
#: small because the refinement fits them about ten times. Chosen among 512, 1024 and 2000 on
#: DiLiGenT (ball, bear, cat, pot1, the 16-bit ball), the sets it is reported on; the factor
#: found moved by a few percent between them.
SLANT_SAMPLE = 1024
#: Object pixels (a regular grid of them) from which unknown lights are read.
UNCALIBRATED_PIXELS = 1 << 17


@dataclass(frozen=True)
class PhotometricStereo:
    """Result of :func:`photometric_stereo`.

    Attributes
    ----------
    normals : (H, W, 3) float64
        Unit normals in the camera frame; NaN outside the mask only.
    albedo : (H, W) or (H, W, C) float64
        Albedo per pixel (per channel for colour photos), in the images' units after dividing by
        the lights' strengths; NaN outside the mask.
    lights_used : (H, W) int
        How many images the final fit used at each pixel (0 outside the mask).
    model : str
        The photometric model's name (:data:`~shadeform.photometric.registry.STEREO_MODELS`);
        ``method``, its old name, still reads it (with a :class:`DeprecationWarning`).
    confidence : (H, W) float64
        In [0, 1], the share of the set's information about the normal that its fit had (module
        description); 0 outside the mask.
    photos_dropped : tuple of int
        The photos (0-based, in the given order) left out because they contradict the others.
    photos_rescaled : tuple of (int, float)
        Photos whose light was brighter (factor > 1) or dimmer than the given strength said, and
        the factor their readings were divided by.
    lights : (N, 3) float64 or None
        The unit light directions used where they are not the given ones: read from the photos
        (``lights=None``) or with their slant refined (``light_scale != 1``); else None.
    light_scale : float
        The factor on the given lights' ``tan(slant)`` that the photos showed (1: taken as given;
        ``refine_lights``).
    relief : ReliefCheck or None
        With lights read from the photos (``lights=None``), whether the albedo's entropy settled
        the bas-relief (:class:`~shadeform.photometric.uncalibrated.ReliefCheck`); else None.
    """

    normals: np.ndarray
    albedo: np.ndarray
    lights_used: np.ndarray
    model: str
    confidence: np.ndarray
    photos_dropped: tuple[int, ...] = ()
    photos_rescaled: tuple[tuple[int, float], ...] = ()
    lights: np.ndarray | None = None
    light_scale: float = 1.0
    relief: ReliefCheck | None = None

    @property
    def method(self) -> str:
        """Deprecated: :attr:`model`, the photometric model's name (removed in the next release)."""
        warnings.warn(
            "PhotometricStereo.method is deprecated; use PhotometricStereo.model",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.model


@renamed_keywords(method="model")
def photometric_stereo(
    images,
    lights=None,
    mask=None,
    *,
    intensities=None,
    model: str = "bivariate",
    min_shading: float = MIN_SHADING,
    highlight_angle: float = HIGHLIGHT_ANGLE,
    iterations: int = ITERATIONS,
    refine_lights: bool = True,
) -> PhotometricStereo:
    """Normals and albedo of a still object photographed under several known distant lights.

    Parameters
    ----------
    images : (N, H, W) or (N, H, W, C) array_like
        ``N >= 3`` photos, linear intensities (not gamma-encoded), same camera and object.
    lights : (N, 3) array_like, optional
        Direction toward each photo's light in the camera frame (``docs/conventions.md``: x right,
        y up, z toward the viewer); normalised here. None: unknown, read from the photos
        (:mod:`.uncalibrated`, at least four photos; far less accurate than known lights).
    mask : (H, W) array_like of bool, optional
        Object pixels. Default: every pixel that is non-zero in some photo.
    intensities : (N,) or (N, C) array_like, optional
        Strength of each photo's light (per channel): the photos are divided by it.
    model : {"bivariate", "robust", "least_squares"}
        The photometric model: what the fit per pixel assumes of the surface (module
        description; :func:`~shadeform.photometric.available_stereo_models`).
    min_shading : float
        Robust fit (and the bivariate fit's start): smallest ``n . l`` an image must have at a
        pixel to count there, in [0, 1).
    highlight_angle : float
        The same: degrees, in [0, 90); an image whose half vector is closer than this to the
        normal does not count (0 keeps them all).
    iterations : int
        The same: classify-and-refit rounds, >= 0.
    refine_lights : bool
        With given lights and a model of gloss (``"bivariate"``): correct a slant
        error common to all the lights, as a chrome sphere read slightly too large or small
        makes (:func:`shadeform.photometric.bivariate.slant_scale`); the factor found is
        ``light_scale`` of the result. False takes the lights exactly as given.

    Returns
    -------
    PhotometricStereo
        Normals (H, W, 3) everywhere on the mask, albedo, lights used, confidence, the photos
        left out.

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
    entry = STEREO_MODELS.get(model)
    if not (np.isfinite(min_shading) and 0 <= min_shading < 1):
        raise InputError(f"min_shading must be in [0, 1), got {min_shading!r}")
    if not (np.isfinite(highlight_angle) and 0 <= highlight_angle < 90):
        raise InputError(f"highlight_angle must be in [0, 90) degrees, got {highlight_angle!r}")
    if int(iterations) != iterations or iterations < 0:
        raise InputError(f"iterations must be a non-negative integer, got {iterations!r}")

    h, w = mask.shape
    channels = stack.shape[3] if stack.ndim == 4 else 0
    where = np.flatnonzero(mask)
    flat = stack.reshape(len(stack), h * w, -1)

    def readings_of(pixels, photos=slice(None)):
        """The object's readings at ``pixels``, divided by the lights' strengths: (N, P, C or 1)."""
        # the pixels first: indexing the photos first would copy the whole stack
        values = flat[:, pixels][photos] / scale[photos][:, None, :]
        if not np.isfinite(values).all():
            raise InputError("images contain NaN or inf on the object; give finite intensities")
        return values

    highlight_cos = np.cos(np.radians(highlight_angle))
    estimated, relief = lights is None, None
    if estimated:
        from shadeform.photometric.uncalibrated import estimate_lights

        # the lights are global: a grid of at most UNCALIBRATED_PIXELS object pixels reads them
        stride = max(1, int(np.ceil(np.sqrt(where.size / UNCALIBRATED_PIXELS))))
        coarse = np.zeros_like(mask)
        coarse[::stride, ::stride] = mask[::stride, ::stride]
        small = coarse[::stride, ::stride]
        lights, found, relief = estimate_lights(readings_of(np.flatnonzero(coarse)).mean(axis=2), small)
        scale = scale * found[:, None]

    fit = load(entry.fit)

    def solve(directions, gray):
        return fit(
            directions, gray, min_shading=min_shading, highlight_cos=highlight_cos, iterations=int(iterations)
        )

    kept, factors = np.arange(len(lights)), np.ones(len(lights))
    if entry.drops_photos and len(lights) > 3:
        sample = where[np.linspace(0, where.size - 1, min(where.size, SAMPLE)).astype(np.int64)]
        gray = readings_of(sample).mean(axis=2)
        first, usable = lambertian.robust(
            lights, gray, min_shading=min_shading, highlight_cos=highlight_cos, iterations=int(iterations)
        )
        factors = _audit(lights, gray, first, usable)
        kept = np.flatnonzero(np.isfinite(factors))
        scale = scale * np.where(np.isfinite(factors), factors, 1.0)[:, None]
    use = lights[kept]
    light_scale = 1.0
    if refine_lights and not estimated and entry.slant_scale and len(use) > 3:
        sample = where[np.linspace(0, where.size - 1, min(where.size, SLANT_SAMPLE)).astype(np.int64)]
        gray = readings_of(sample, kept).mean(axis=2)
        g, _ = lambertian.robust(
            use, gray, min_shading=min_shading, highlight_cos=highlight_cos, iterations=int(iterations)
        )
        length = np.linalg.norm(g, axis=1)
        solved = np.isfinite(length) & (length > 0)
        if np.count_nonzero(solved) >= 3:
            light_scale = load(entry.slant_scale)(use, gray[:, solved], g[solved])
        if light_scale != 1.0:
            lights = lambertian.scaled_lights(lights, light_scale)
            use = lights[kept]

    normals = np.full((where.size, 3), np.nan)
    albedo = np.full((where.size, max(channels, 1)), np.nan)
    used = np.zeros(where.size, dtype=np.int64)
    information = np.zeros(where.size)
    holes = []  # (pixel numbers, their lit readings' sum l l^T (3, 3) and sum I l (3,))
    for start in range(0, where.size, CHUNK):
        part = slice(start, start + CHUNK)
        readings = readings_of(where[part], kept)
        gray = readings.mean(axis=2)
        g, usable = solve(use, gray)
        length = np.linalg.norm(g, axis=1)
        lost = ~(np.isfinite(length) & (length > 0))
        if lost.any():
            lit = (gray[:, lost] > 0).astype(np.float64)
            pixels = np.arange(start, start + gray.shape[1])[lost]
            holes.append((pixels, lambertian.outer(lit, use), (lit * gray[:, lost]).T @ use))
            usable[:, lost] = lit > 0
        normals[part] = g
        albedo[part] = _albedo(g, usable, use, readings) if channels else length[:, None]
        used[part] = usable.sum(axis=0)
        information[part] = np.linalg.eigvalsh(lambertian.outer(usable.astype(np.float64), use))[:, 0]
    if holes:
        pixels, outer, moment = (np.concatenate(parts) for parts in zip(*holes))
        normals = _fill(normals, mask, where, pixels, outer, moment)
        readings = readings_of(where[pixels], kept)
        lit = readings.mean(axis=2) > 0
        albedo[pixels] = (
            _albedo(normals[pixels], lit, use, readings)
            if channels
            else np.linalg.norm(normals[pixels], axis=1)[:, None]
        )
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # the share of the set's information about the normal, in its weakest direction
    confidence = np.clip(information / np.linalg.eigvalsh(lights.T @ lights)[0], 0.0, 1.0)

    def image(values, fill, dtype=np.float64):
        out = np.full((h * w,) + values.shape[1:], fill, dtype=dtype)
        out[where] = values
        return out.reshape((h, w) + values.shape[1:])

    return PhotometricStereo(
        normals=image(normals, np.nan),
        albedo=image(albedo if channels else albedo[:, 0], np.nan),
        lights_used=image(used, 0, np.int64),
        model=model,
        confidence=image(confidence, 0.0),
        photos_dropped=tuple(int(i) for i in np.setdiff1d(np.arange(len(lights)), kept)),
        photos_rescaled=tuple(
            (int(i), float(factors[i])) for i in np.flatnonzero(np.isfinite(factors) & (factors != 1.0))
        ),
        lights=lights if estimated or light_scale != 1.0 else None,
        light_scale=light_scale,
        relief=relief,
    )


def _albedo(g, usable, lights, readings):
    """Each channel's albedo (P, C) with the normals ``g / |g|`` (P, 3) held: least squares of
    the usable readings (N, P, C) on ``max(0, n . l)``."""
    with np.errstate(invalid="ignore"):  # holes (NaN) stay NaN
        n = g / np.linalg.norm(g, axis=1, keepdims=True)
    shading = np.where(usable, np.maximum(lights @ n.T, 0.0), 0.0)  # (N, P)
    energy = np.sum(shading * shading, axis=0)
    return np.einsum("np,npc->pc", shading, readings) / np.where(energy > 0, energy, 1)[:, None]


def _check(images, lights, mask, intensities):
    try:
        stack = np.asarray(images)  # kept as given: only the object's readings are converted
        lights = None if lights is None else np.asarray(lights, dtype=np.float64)
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
    if lights is None:
        pass  # read from the photos once the mask is known
    elif lights.shape != (count, 3):
        raise InputError(f"lights must be (N, 3) with N = {count} (one per photo), got shape {lights.shape}")
    elif not np.isfinite(lights).all():
        raise InputError("lights contain NaN or inf; give a direction toward each photo's light")
    if lights is not None:
        lengths = np.linalg.norm(lights, axis=1)
        if (lengths == 0).any():
            raise InputError(f"light {int(np.argmin(lengths)) + 1} is the zero vector; give a direction")
        lights = lights / lengths[:, None]
        if (lights[:, 2] <= 0).any():
            below = int(np.argmax(lights[:, 2] <= 0))
            raise InputError(
                f"light {below + 1} is below the horizon (z = {lights[below, 2]:.3g}: it lights the "
                "object from behind as the camera sees it); give each direction toward its light "
                "with z > 0 (x right, y up, z toward the camera)"
            )
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
