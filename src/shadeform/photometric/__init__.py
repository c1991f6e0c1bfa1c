"""Photometric stereo: normals and albedo from several photos taken under known lights.

With a distant light ``l_j`` (unit, toward the light, strength folded into the image) a Lambertian
pixel of albedo ``rho`` and normal ``n`` reads ``I_j = rho max(0, n . l_j)``. Where three or more
non-coplanar lights reach it, ``g = rho n`` is the least-squares solution of ``L g = I`` (Woodham
1980): ``n = g / |g|``, ``rho = |g|``.

Real objects break that model: attached and cast shadows, specular highlights and a falloff
that is not the cosine (``benchmarks/results/stereo.md``). The methods, one module each in a
registry (:func:`register`; ``shadeform stereo --method``):

- ``"bivariate"`` (the default, :mod:`.bivariate`): a low-order reflectance model per pixel
  (powers of ``n . l`` and gloss lobes round the half vector), readings it cannot explain
  weighted out by Tukey's biweight; started from the robust Lambertian normal.
- ``"robust"`` (:mod:`.lambertian`): Lambertian, each pixel's shadowed, grazing and highlighted
  readings left out by the current estimate (Barsky & Petrou 2003, Mukaigawa et al. 2007), with
  thresholds set on synthetic Blinn-Phong spheres.
- ``"least_squares"``: Woodham's fit of every reading, the baseline.

Two things no per-pixel fit can do are done over the whole set:

- **Photos that contradict the rest** (a light calibrated wrongly, the object moved: DiLiGenT's
  ``bear`` has 20 faulty first photos) are found before the fit: after a robust fit on an even
  sample of the object's pixels, a photo whose typical deleted residual (the median over its lit
  pixels of ``|I - rho n . l| / rho``, over ``1 - h`` for readings the fit used with leverage
  ``h``) is more than :data:`FAULTY` times the typical photo's (and over :data:`AGREE`)
  disagrees. If one factor on its light's strength explains the disagreement and is more than
  :data:`TOLERANCE` off, the photo is rescaled by it; if none does, it is left out.
- **No holes**: a pixel that fewer than three usable, non-coplanar lights reached (or whose fit
  counts a reading its own normal puts in shadow) still gets a normal, the best its own lit
  readings allow with its neighbours' ``g`` as a prior (each neighbour weighs as much as one
  photo); one sparse solve over all such pixels.

Each normal comes with a **confidence** in [0, 1]: the smallest eigenvalue of ``sum_j l_j l_j^T``
over the photos its fit used, over the same for every photo of the set (the share of the set's
information about the normal in its weakest direction): 1 where every photo counted, 0 where the
data fix the normal in at most two directions and the neighbours did the rest.

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
from shadeform.photometric import lambertian
from shadeform.photometric.lambertian import HIGHLIGHT_ANGLE, ITERATIONS, MIN_SHADING

__all__ = [
    "METHODS",
    "PhotometricStereo",
    "StereoMethod",
    "available_methods",
    "photometric_stereo",
    "reconstruct_stereo",
    "register",
]


@dataclass(frozen=True)
class StereoMethod:
    """One photometric-stereo method of the registry.

    Attributes
    ----------
    name : str
        What users pass (``photometric_stereo(method=name)``, ``shadeform stereo --method``).
    fit : str
        ``"module:function"`` naming ``fit(lights (N, 3), readings (N, P), *, min_shading,
        highlight_cos, iterations) -> (g (P, 3), usable (N, P) bool)``: per pixel ``g`` = albedo
        times the unit normal (NaN where it cannot tell) and the readings it counted.
    description : str
        One line in the user's words.
    drops_photos : bool
        Whether photos that contradict the others are left out first.
    slant_scale : str, optional
        ``"module:function"`` naming ``slant_scale(lights (N, 3), readings (N, P), start (P, 3))
        -> float``: the factor on the given lights' ``tan(slant)`` that the method's model
        explains a sample of readings best with (1 where they cannot tell); None: the method
        takes the lights as given.
    """

    name: str
    fit: str
    description: str
    drops_photos: bool = True
    slant_scale: str | None = None


_REGISTRY: dict[str, StereoMethod] = {}


def register(method: StereoMethod) -> None:
    """Add a method (its module is imported when first used)."""
    _REGISTRY[method.name] = method


def available_methods() -> dict[str, str]:
    """The registered methods, the default first: name -> one-line description."""
    return {name: method.description for name, method in _REGISTRY.items()}


def _fit_function(name, attribute="fit"):
    import importlib

    module, function = getattr(_REGISTRY[name], attribute).split(":")
    return getattr(importlib.import_module(module), function)


#: Pixels solved at once: bounds the memory of the (images x pixels) arrays.
CHUNK = 1 << 15
#: A photo whose median deleted residual is more than this many times the median photo's
#: disagrees with the others (module description); a round factor, not swept. With it, of the
#: seven real DiLiGenT sets and the 16-bit ball, bear's first 19 photos disagree (17-43 % brighter
#: than calibrated, and rescaled) and cat's last, grazing one (10.5 % dim, rescaled); no other.
FAULTY = 3.0
#: Object pixels (evenly spaced) the search for contradicting photos fits: enough for a median.
SAMPLE = 4096
#: Object pixels (evenly spaced) on which the lights' slant is refined: a median's worth, kept
#: small because the refinement fits them about ten times. Chosen among 512, 1024 and 2000 on
#: DiLiGenT (ball, bear, cat, pot1, the 16-bit ball), the sets it is reported on; the factor
#: found moved by a few percent between them.
SLANT_SAMPLE = 1024
#: Object pixels (a regular grid of them) from which unknown lights are read.
UNCALIBRATED_PIXELS = 1 << 17
#: A photo whose typical residual is under this share of the albedo agrees with the others,
#: whatever theirs are (a noise-free set's residuals are rounding, and their ratios mean nothing:
#: set on a noise-free synthetic sphere, where without it a clean photo was dropped; not swept).
AGREE = 0.01
#: A disagreeing photo whose light's strength is off by more than this share is rescaled; within
#: it the disagreement is left to the robust fit. Set while the residuals were not yet deleted
#: ones: then the 16-bit ball's five grazing photos disagreed, 3-5 % dim, and rescaling them cost
#: the ball 0.07 degrees; bear's faulty photos are 17-43 % off.
TOLERANCE = 0.1


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
    method : str
        The method's name (:data:`METHODS`).
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
    """

    normals: np.ndarray
    albedo: np.ndarray
    lights_used: np.ndarray
    method: str
    confidence: np.ndarray
    photos_dropped: tuple[int, ...] = ()
    photos_rescaled: tuple[tuple[int, float], ...] = ()
    lights: np.ndarray | None = None
    light_scale: float = 1.0


def photometric_stereo(
    images,
    lights=None,
    mask=None,
    *,
    intensities=None,
    method: str = "bivariate",
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
    method : {"bivariate", "robust", "least_squares"}
        The fit per pixel (module description).
    min_shading : float
        Robust fit (and the bivariate fit's start): smallest ``n . l`` an image must have at a
        pixel to count there, in [0, 1).
    highlight_angle : float
        The same: degrees, in [0, 90); an image whose half vector is closer than this to the
        normal does not count (0 keeps them all).
    iterations : int
        The same: classify-and-refit rounds, >= 0.
    refine_lights : bool
        With given lights and a method that models gloss (``"bivariate"``): correct a slant
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
    check_choice(method, tuple(_REGISTRY), "method")
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
    estimated = lights is None
    if estimated:
        from shadeform.photometric.uncalibrated import estimate_lights

        # the lights are global: a grid of at most UNCALIBRATED_PIXELS object pixels reads them
        stride = max(1, int(np.ceil(np.sqrt(where.size / UNCALIBRATED_PIXELS))))
        coarse = np.zeros_like(mask)
        coarse[::stride, ::stride] = mask[::stride, ::stride]
        small = coarse[::stride, ::stride]
        lights, found = estimate_lights(readings_of(np.flatnonzero(coarse)).mean(axis=2), small)
        scale = scale * found[:, None]

    fit = _fit_function(method)

    def solve(directions, gray):
        return fit(
            directions, gray, min_shading=min_shading, highlight_cos=highlight_cos, iterations=int(iterations)
        )

    kept, factors = np.arange(len(lights)), np.ones(len(lights))
    if _REGISTRY[method].drops_photos and len(lights) > 3:
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
    if refine_lights and not estimated and _REGISTRY[method].slant_scale and len(use) > 3:
        sample = where[np.linspace(0, where.size - 1, min(where.size, SLANT_SAMPLE)).astype(np.int64)]
        gray = readings_of(sample, kept).mean(axis=2)
        g, _ = lambertian.robust(
            use, gray, min_shading=min_shading, highlight_cos=highlight_cos, iterations=int(iterations)
        )
        length = np.linalg.norm(g, axis=1)
        solved = np.isfinite(length) & (length > 0)
        if np.count_nonzero(solved) >= 3:
            light_scale = _fit_function(method, "slant_scale")(use, gray[:, solved], g[solved])
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
        method=method,
        confidence=image(confidence, 0.0),
        photos_dropped=tuple(int(i) for i in np.setdiff1d(np.arange(len(lights)), kept)),
        photos_rescaled=tuple(
            (int(i), float(factors[i])) for i in np.flatnonzero(np.isfinite(factors) & (factors != 1.0))
        ),
        lights=lights if estimated or light_scale != 1.0 else None,
        light_scale=light_scale,
    )


def _albedo(g, usable, lights, readings):
    """Each channel's albedo (P, C) with the normals ``g / |g|`` (P, 3) held: least squares of
    the usable readings (N, P, C) on ``max(0, n . l)``."""
    with np.errstate(invalid="ignore"):  # holes (NaN) stay NaN
        n = g / np.linalg.norm(g, axis=1, keepdims=True)
    shading = np.where(usable, np.maximum(lights @ n.T, 0.0), 0.0)  # (N, P)
    energy = np.sum(shading * shading, axis=0)
    return np.einsum("np,npc->pc", shading, readings) / np.where(energy > 0, energy, 1)[:, None]


def _audit(lights, gray, g, usable):
    """Each photo's strength correction (N,): 1 where it agrees with the others, the factor its
    light's strength was off by where that explains the disagreement, NaN where nothing does
    (left out).

    A photo disagrees when its median residual ``|I - rho n . l| / rho`` over its lit pixels
    (``n . l >= MIN_SHADING`` by the fit ``g`` (P, 3) of the readings ``gray`` (N, P)) exceeds
    :data:`FAULTY` times the median photo's; its factor is the median of ``I / (rho n . l)`` over
    those pixels, and it is kept, rescaled, if the residual after rescaling is back under that
    limit and its strength is off by more than :data:`TOLERANCE` (within it, the disagreement is
    left to the robust fit). A photo lit on too few pixels to judge is kept as it is."""
    factors = np.ones(len(lights))
    solved = np.isfinite(g[:, 0]) & (np.linalg.norm(g, axis=1) > 0)
    if np.count_nonzero(solved) < 3:
        return factors
    rho = np.linalg.norm(g[solved], axis=1)
    shading = lights @ (g[solved] / rho[:, None]).T
    lit = shading >= MIN_SHADING
    predicted = rho * shading
    # deleted residuals: a reading the fit used pulled the fit toward itself, by its leverage
    # h = l . A^-1 l (A = sum of the used l l^T): its residual over (1 - h) is what a fit
    # without it would have left, comparable with the readings the fit did not use
    used = usable[:, solved].astype(np.float64)
    inverse = np.linalg.inv(lambertian.outer(used, lights))
    leverage = used * np.einsum("ni,pij,nj->np", lights, inverse, lights)
    residual = np.abs(gray[:, solved] - predicted) / np.maximum(1.0 - leverage, 1e-3)
    scale = np.median(rho)
    typical = np.full(len(lights), np.nan)
    for j, on in enumerate(lit):
        if np.count_nonzero(on) >= 3:
            typical[j] = np.median(residual[j, on]) / scale
    judged = np.isfinite(typical)
    if np.count_nonzero(judged) < 4:
        return factors
    limit = max(FAULTY * np.median(typical[judged]), AGREE)
    for j in np.flatnonzero(judged & (typical > limit)):
        on = lit[j]
        factor = np.median(gray[j, solved][on] / predicted[j, on])
        rescaled = np.median(np.abs(gray[j, solved][on] - factor * predicted[j, on])) / scale
        if not (factor > 0 and rescaled <= limit):
            factors[j] = np.nan
        elif abs(np.log(factor)) > np.log1p(TOLERANCE):
            factors[j] = factor
    return factors


def _fill(g, mask, where, pixels, outer, moment):
    """``g`` (P, 3) with its non-finite rows (``pixels``, in order) solved from their own lit
    readings (``outer`` (H, 3, 3) = sum l l^T, ``moment`` (H, 3) = sum I l) and their 4-neighbours
    on the object, each neighbour weighing as one photo: one sparse solve over all of them.
    A part with no solved neighbour and no data leans (with a vanishing weight) toward the
    object's median albedo facing the camera."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    h, w = mask.shape
    count = pixels.size
    number = np.full(h * w, -1, dtype=np.int64)  # object pixel -> row of g
    number[where] = np.arange(where.size)
    hole = np.full(where.size, -1, dtype=np.int64)  # row of g -> unknown
    hole[pixels] = np.arange(count)
    known = np.isfinite(g[:, 0])
    rho = np.linalg.norm(g[known], axis=1)
    prior = np.array([0.0, 0.0, float(np.median(rho)) if rho.size else 1.0])
    ridge = 1e-6
    diagonal = outer + ridge * np.eye(3)
    rhs = moment + ridge * prior
    rows, cols = np.divmod(where[pixels], w)
    neighbours_i, neighbours_j = [], []
    for d_row, d_col in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        r, c = rows + d_row, cols + d_col
        inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        other = np.full(count, -1, dtype=np.int64)
        other[inside] = number[r[inside] * w + c[inside]]
        on = other >= 0
        diagonal[on] += np.eye(3)
        solved = on & (hole[np.maximum(other, 0)] < 0)
        rhs[solved] += g[other[solved]]
        open_ = on & ~solved
        neighbours_i.append(np.flatnonzero(open_))
        neighbours_j.append(hole[other[open_]])
    i, j = np.concatenate(neighbours_i), np.concatenate(neighbours_j)
    # one 3x3 block per unknown pixel on the diagonal, built at once (no loop over the pixels)
    block = sp.bsr_matrix((diagonal, np.arange(count), np.arange(count + 1)), shape=(3 * count, 3 * count))
    coupling = sp.kron(
        sp.csr_matrix((np.ones(i.size), (i, j)), shape=(count, count)), sp.eye(3), format="csr"
    )
    solution = spla.spsolve((block - coupling).tocsc(), rhs.ravel()).reshape(count, 3)
    g = g.copy()
    g[pixels] = solution
    return g


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


def reconstruct_stereo(
    images,
    lights=None,
    mask=None,
    *,
    intensities=None,
    method: str = "bivariate",
    integrator: str = "poisson",
    sphere=None,
    refine_lights: bool = True,
):
    """Photometric stereo, then depth: the several-photo counterpart of
    :func:`shadeform.reconstruct`.

    Parameters
    ----------
    images, lights, intensities, method
        As for :func:`photometric_stereo` (``lights=None``: read from the photos).
    mask : (H, W) array_like of bool, optional
        Object pixels. Default: found in the brightest reading of each pixel over the photos, as
        :func:`shadeform.preprocess.object_mask` finds an object on a dark background.
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
        ``method``, ``integrator``, ``photos``, ``lights_used`` (median per pixel),
        ``photos_rescaled`` (``[index, factor]`` pairs), ``photos_dropped``, ``light_scale``
        (:class:`PhotometricStereo`), ``lights`` (given or read), ``light_directions`` (the unit
        directions used, a list of ``[x, y, z]``) and
        ``timings`` in seconds.

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
        from shadeform.preprocess import object_mask

        stack = np.asarray(images)
        brightest = stack.max(axis=0) if stack.ndim == 3 else stack.max(axis=(0, 3))
        peak = float(brightest.max()) if brightest.size else 0.0
        if not (np.isfinite(peak) and peak > 0):
            raise InputError("every photo is black (or not finite); give photos of the lit object")
        mask = object_mask(brightest / peak)
        if sphere is not None:
            column, row, radius = np.asarray(sphere, dtype=np.float64)
            rows, cols = np.ogrid[0 : mask.shape[0], 0 : mask.shape[1]]
            mask &= (cols - column) ** 2 + (rows - row) ** 2 > (1.1 * radius) ** 2
            if not mask.any():
                raise InputError("the photos show nothing but the sphere; give a mask of the object")
    result = photometric_stereo(
        images, lights, mask, intensities=intensities, method=method, refine_lights=refine_lights
    )
    solved = np.isfinite(result.normals[..., 0])
    normals_time = time.perf_counter()
    depth = integrate(result.normals, solved, method=integrator)
    done = time.perf_counter()
    directions = np.asarray(lights if result.lights is None else result.lights, dtype=np.float64)
    mean = (directions / np.linalg.norm(directions, axis=1, keepdims=True)).mean(axis=0)
    return Reconstruction(
        normals=result.normals,
        depth=depth,
        mask=solved,
        light=mean / np.linalg.norm(mean),
        albedo=result.albedo,
        info={
            "method": f"photometric stereo ({method})",
            "integrator": integrator,
            "photos": len(directions),
            "lights_used": float(np.median(result.lights_used[solved])),
            "photos_rescaled": [[i, round(f, 4)] for i, f in result.photos_rescaled],
            "photos_dropped": list(result.photos_dropped),
            "light_scale": round(result.light_scale, 4),
            "lights": "read from the photos" if lights is None else "given",
            "light_directions": (directions / np.linalg.norm(directions, axis=1, keepdims=True)).tolist(),
            "timings": {"normals": normals_time - start, "depth": done - normals_time},
        },
        confidence=np.where(solved, result.confidence, np.nan),
    )


register(
    StereoMethod(
        "bivariate",
        "shadeform.photometric.bivariate:fit",
        "a reflectance model per pixel (falloff and gloss lobes), shadows and outliers weighted out",
        slant_scale="shadeform.photometric.bivariate:slant_scale",
    )
)
register(
    StereoMethod(
        "robust",
        "shadeform.photometric.lambertian:robust",
        "Lambertian, with each pixel's shadows and highlights left out",
    )
)
register(
    StereoMethod(
        "least_squares",
        "shadeform.photometric.lambertian:least_squares",
        "Lambertian, every reading (Woodham 1980)",
        drops_photos=False,
    )
)
#: The registered method names, the default first.
METHODS = tuple(_REGISTRY)
