"""The light on a relief over a flat base facing the camera: from round features, else the spectrum.

A relief (bumps, dimples, craters on a plate, a coin, a relief tile) has no occluding contour to
read; its flat base, though, faces the camera, so its intensity is ``k L_z``. The relief is fitted
as a sum of round features (:mod:`shadeform.light.features`) together with ``tau = L_xy / L_z``:
a free-form relief could explain the image under many lights, each with its own distorted shape,
but restricted to round features the fit pins the light down (the shading's odd part around each
centre follows the tilt, its even part the profile), and it reads the slant also when no facet
faces the light, where the brightest point only bounds it (``evidence="relief"``). When round
features do not explain the image, the brightest point bounds the slant from below and the tilt is
where the relief's spectrum vanishes (``"relief-spectrum"``, after A. P. Pentland, "Linear shape
from shading", IJCV 4, 153-162, 1990).

The features are found on a block-averaged copy of the image:

1. at every pixel the rings around it are fitted by ``a(r) + b(r) . u``: around a round feature's
   centre ``a`` is ``n_z(r) - 1`` and ``b = sqrt(1 - n_z^2) tau`` (all in units of ``k L_z``). The
   share of the image's energy this explains peaks at the centres (:func:`ring_scores`);
2. a single feature, with its own light, is fitted in a window at each peak; those whose light
   agrees with the best one's (up to sign: a dimple lit from one side looks like a bump lit from
   the other) seed the joint fit, with that light;
3. while the residual is above the noise, window fits at the residual's energy and ring peaks and
   at the unused seeds are tried, best first, and the first that cuts the residual by a fifth
   joins. These fits use a robust loss, so that the features found are not bent toward those still
   missing. Features whose loss the others make up for are dropped.

The final fit, on a finer copy, is trusted when its residual is near the noise; if it is not, the
search is repeated with larger, then smaller rings, and if none is, the best fit is still used
when it explains all but a few per cent of the relief's variance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shadeform.light._evidence import (
    MIN_OBJECT_PIXELS,
    Levels,
    Reading,
    bound_spread,
    from_components,
    slant_from_peak,
)
from shadeform.light.features import (
    FEATURE_REACH,
    PROFILE_KNOTS,
    Fit,
    feature_params,
    fit_features,
    fit_window,
    pixels,
    render_features,
    window_feature,
)

# An object with this fraction of its pixels at one level, shared by its edge, is a relief on a
# base facing the camera (chosen on the synthetic bumps against the other scenes of bench_light).
_RELIEF_FRACTION = 0.1
# The search for features runs on the image block-averaged to about this many pixels across the
# relief, the final fit on about twice as many: enough pixels per feature, seconds per estimate
# (chosen on the synthetic bumps of bench_light).
_SEARCH_SPAN = 64
_REFINE_SPAN = 128
# Radius of the ring windows that find feature centres, as a fraction of the relief's span (at
# least 4 pixels of the search image), first choice then the retries: for features a twentieth
# to a tenth of the relief across (chosen on the synthetic bumps of bench_light).
_RING_WINDOWS = (0.1, 0.13, 0.075)
_MAX_FEATURES = 12
# A window fit seeds the relief if its light agrees with the best window's within this angle and
# length ratio; a feature joins if it cuts the squared residual to this fraction, and leaves if
# dropping it raises that by less than this factor (chosen on the synthetic bumps of bench_light
# and the caps of tests/test_light.py).
_SEED_ANGLE = math.radians(20.0)
_SEED_RATIO = (0.7, 1.4)
_FEATURE_GAIN = 0.8
_PRUNE_LOSS = 1.05
# Joint fits tried per pass when growing the relief by a feature, best window fit first.
_GROW_TRIALS = 6
# Mean squared residual, over noise^2 and a fraction of the relief's variance: where the search
# stops, and what a final fit must reach to be trusted (chosen on the synthetic bumps of
# bench_light; the measured residuals are in benchmarks/results/light.md, "Tuning notes").
_SEARCH_FLOOR = (1.5, 3e-4)
_FIT_ACCEPT = (2.0, 1e-2)
# When no search reaches that, the best fit is still used if it leaves under this fraction of the
# relief's variance: it found the features' shading, if not every detail (chosen between the
# synthetic bumps at slant 60 and a straight ridge of tests/test_light.py; see "Tuning notes").
_FIT_FALLBACK = 5e-2


def base_level(image, mask, levels: Levels, edge_values) -> float | None:
    """The level of a flat base facing the camera, or None if the object has none.

    A relief on such a base has an evenly lit edge (``edge_values``, the intensities of the
    object's outermost pixels), the same level a few pixels further in (a curved rim gets
    brighter or darker inward), and a good part of its pixels at that level.
    """
    noise, peak = levels.noise, levels.peak
    level = float(np.median(edge_values))
    if level <= levels.lit:
        return None  # a base in shadow (or the black background) faces no light
    spread = 1.4826 * float(np.median(np.abs(edge_values - level)))
    if spread > max(2.0 * noise, 0.01 * peak):
        return None
    inner = image[mask & (levels.inside > 4) & (levels.inside <= 6)]
    if inner.size == 0 or abs(float(np.median(inner)) - level) > max(0.2 * noise, 0.005 * peak):
        return None
    band = max(2.0 * noise, 0.01 * level)
    fraction = float(np.count_nonzero(np.abs(image[mask] - level) <= band)) / float(mask.sum())
    return level if fraction >= _RELIEF_FRACTION else None


def read_relief(image, mask, levels: Levels, edge_values) -> Reading | None:
    """The light on a relief over a flat base facing the camera, or None if the object has no
    such base (:func:`base_level`; ``edge_values`` (n,) are the intensities of the object's
    outermost pixels).

    From round features fitted to the relief (``"relief"``: ``info`` has the number of features
    and the rms residual over the base level), else from the brightest point and the image's
    spectrum (``"relief-spectrum"``). ``image``, ``mask`` and ``levels`` as for
    :func:`shadeform.light.contour.read_contour`.
    """
    from threadpoolctl import threadpool_limits

    level = base_level(image, mask, levels, edge_values)
    if level is None:
        return None
    info: dict = {"base_level": level}
    # the fit's many small matrix products: BLAS threads cost more than they give, and on a busy
    # machine they spin against each other (see "Tuning notes" in benchmarks/results/light.md)
    with threadpool_limits(1, user_api="blas"):
        fit = round_features(image, mask, level, levels.noise)
    if fit is not None:
        info.update(relief_features=fit.features, relief_residual=fit.residual)
        return Reading(*from_components(fit.across * fit.level, fit.level), "relief", info, spread=fit.spread)
    slant = slant_from_peak(level, levels.peak)
    tilt = _relief_tilt(image, mask, level)
    # the brightest point only bounds the slant from below
    return Reading(slant, tilt, max(levels.peak, level), "relief-spectrum", info, spread=bound_spread(slant))


def _relief_tilt(image, mask, level) -> float:
    """Tilt (degrees) of the light on a relief over a base at intensity ``level``.

    To first order a relief darkens the base by ``tan(slant)`` times its slope along the tilt, so
    the darkening's line integrals along the tilt vanish and, by the projection-slice theorem, its
    spectrum is empty on the frequency line perpendicular to the tilt. Of the two opposite tilts,
    the one that makes the relief mostly raised is returned.
    """
    from scipy import ndimage as ndi

    darkening = np.where(mask, 1.0 - image / level, 0.0)
    height, width = darkening.shape
    size = 2 * max(height, width)
    power = np.fft.fftshift(np.abs(np.fft.fft2(darkening, s=(size, size))) ** 2)
    centre = size // 2
    radii = np.arange(1, size // 4, dtype=np.float64)
    angles = np.radians(np.arange(0.0, 180.0, 0.5))
    energy = np.empty(angles.size)
    for i, angle in enumerate(angles):
        # frequencies along (-sin, cos) in (x, y); y is up, frequency rows go down
        fr = centre - radii * math.cos(angle)
        fc = centre - radii * math.sin(angle)
        energy[i] = ndi.map_coordinates(power, [fr, fc], order=1).sum()
    best = int(np.argmin(energy))
    before, after = energy[best - 1], energy[(best + 1) % angles.size]
    curve = before - 2.0 * energy[best] + after
    shift = 0.5 * (before - after) / curve if curve > 0 else 0.0
    tilt = math.degrees(angles[best]) + 0.5 * float(np.clip(shift, -1.0, 1.0))
    # a raised relief lit from tilt t has first moment sum(darkening * x . t) = -tan(s) * volume
    rows, cols = np.nonzero(mask)
    x = cols - cols.mean()
    y = -(rows - rows.mean())
    direction = (math.cos(math.radians(tilt)), math.sin(math.radians(tilt)))
    moment = float((darkening[rows, cols] * (x * direction[0] + y * direction[1])).sum())
    return tilt + 180.0 if moment > 0 else tilt


@dataclass(frozen=True)
class ReliefFit:
    """Round features fitted to a relief (:func:`round_features`).

    Attributes
    ----------
    across : (2,) float64
        ``L_xy / L_z`` (the tangent of the slant along the tilt).
    level : float
        ``k L_z``.
    features : int
        Number of features.
    residual : float
        Root-mean-square misfit over ``level``.
    spread : float
        Root-mean-square angle (degrees) of the light, from the fit's covariance.
    """

    across: np.ndarray
    level: float
    features: int
    residual: float
    spread: float


def round_features(image, mask, level, noise) -> ReliefFit | None:
    """The light from round features (bumps, dimples, craters) on a flat base facing the camera.

    Parameters
    ----------
    image : (H, W) float64
        Intensities.
    mask : (H, W) bool
        Object pixels.
    level : float
        The base's intensity, ``k L_z``.
    noise : float
        Standard deviation of the pixel noise.

    Returns
    -------
    ReliefFit or None
        None when no feature is found or the fit does not explain the image (the relief is not
        made of round features, or they were not all found). Of the two opposite lights a relief
        allows (raised features lit from one side, sunk ones from the other), the one that makes
        the features' total volume positive.
    """
    rows, cols = np.nonzero(mask)
    span = max(int(rows.max() - rows.min()) + 1, int(cols.max() - cols.min()) + 1)
    coarse = max(1, round(span / _SEARCH_SPAN))
    fine = max(1, round(span / _REFINE_SPAN))
    small, small_mask = block_mean(image, mask, coarse)
    if np.count_nonzero(small_mask) < MIN_OBJECT_PIXELS:
        return None
    big, big_mask = block_mean(image, mask, fine)
    x, y, values = pixels(big, big_mask)
    variance = float(np.mean((values - level) ** 2))
    scale = coarse / fine
    tried = set()
    best = None
    # a search that misses a feature or misplaces one is tried again with other ring windows
    for size in _RING_WINDOWS:
        window = max(4, round(size * span / coarse))
        if window in tried:
            continue
        tried.add(window)
        # independent noise averages down with the block's side
        found = _search_features(small, small_mask, level, noise / coarse, window)
        if found is None:
            continue
        # the centre of block pixel c at one size is at (c + 0.5) * scale - 0.5 at the other
        features = [
            (np.array([(c[0] + 0.5) * scale - 0.5, (c[1] - 0.5) * scale + 0.5]), s) for c, s in found.features
        ]
        fit = fit_features(x, y, values, found.level, found.across, features, window * scale, robust=False)
        floor = _FIT_ACCEPT[0] * (noise / fine) ** 2
        if fit.mse <= floor + _FIT_ACCEPT[1] * variance:
            return _relief_fit(fit, x, y, window * scale)
        if fit.mse <= floor + _FIT_FALLBACK * variance and (best is None or fit.mse < best[0].mse):
            best = (fit, window * scale)
    # no search explained the image to near the noise: the best one, if it explains most of it
    return None if best is None else _relief_fit(best[0], x, y, best[1])


def _relief_fit(fit: Fit, x, y, window) -> ReliefFit:
    """The light of a joint fit of the pixels at ``x``, ``y`` (features found with ring windows
    of ``window`` pixels): of the two opposite lights a relief allows, the one that makes the
    features' total volume positive (pi * integral of r^2 s(r) dr, from the coefficients)."""
    knots = np.arange(1, PROFILE_KNOTS + 1, dtype=np.float64)
    raised = sum(float(knots**2 @ s) for _, s in fit.features) >= 0
    return ReliefFit(
        across=fit.across if raised else -fit.across,
        level=fit.level,
        features=len(fit.features),
        residual=math.sqrt(fit.mse) / fit.level,
        spread=_fit_spread(fit, x, y, window),
    )


def _fit_spread(fit: Fit, x, y, window) -> float:
    """Root-mean-square angle (degrees) of the light of a joint fit, from the fit's covariance.

    The covariance of ``tau`` is ``mse`` times its block of ``(J^T J)^-1`` (J the image's Jacobian
    in all the parameters at the fit); the light ``(tau, 1) / |(tau, 1)|`` turns by
    ``d tau_parallel / (1 + |tau|^2)`` along the tilt and ``d tau_perpendicular / sqrt(1 + |tau|^2)``
    across it.
    """
    reaches = [FEATURE_REACH * window] * len(fit.features)
    _, jac = render_features(
        feature_params(fit.level, fit.across, fit.features), x, y, reaches, jacobian=True
    )
    normal = jac.T @ jac
    try:
        inverse = np.linalg.pinv(normal, hermitian=True)
    except np.linalg.LinAlgError:
        return math.inf
    covariance = fit.mse * inverse[1:3, 1:3]
    size = float(np.hypot(*fit.across))
    along = fit.across / size if size > 0 else np.array([1.0, 0.0])
    across = np.array([-along[1], along[0]])
    stretch = 1.0 + size * size
    variance = float(along @ covariance @ along) / stretch**2 + float(across @ covariance @ across) / stretch
    return math.degrees(math.sqrt(max(variance, 0.0)))


def _search_features(image, mask, level, noise, window) -> Fit | None:
    """Round features of a relief, found one by one (steps 1-3 of the module's search)."""
    x, y, values = pixels(image, mask)
    variance = float(np.mean((values - level) ** 2))
    floor = _SEARCH_FLOOR[0] * noise**2 + _SEARCH_FLOOR[1] * variance
    seeded = _seed_features(image, mask, level, window)
    if seeded is None:
        return None
    across, features, pool = seeded
    fit = fit_features(x, y, values, level, across, features, window, robust=True, tolerance=1e-6)
    tried: list = []
    while len(fit.features) < _MAX_FEATURES and fit.mse > floor:
        grown = _grow(image, mask, (x, y, values), fit, window, pool, tried)
        if grown is None:
            break
        fit = grown
        pool = [(misfit, p) for misfit, p in pool if _is_new(p, fit.features)]
    while len(fit.features) > 1:
        # drop the feature the image misses least, if the others can make up for it
        params = feature_params(fit.level, fit.across, fit.features)
        reaches = [FEATURE_REACH * window] * len(fit.features)
        loss = []
        for i in range(len(fit.features)):
            without = params.copy()
            first = 5 + i * (2 + PROFILE_KNOTS)
            without[first : first + PROFILE_KNOTS] = 0.0
            miss = render_features(without, x, y, reaches) - values
            loss.append(float(miss @ miss))
        i = int(np.argmin(loss))
        others = fit.features[:i] + fit.features[i + 1 :]
        trial = fit_features(
            x, y, values, fit.level, fit.across, others, window, robust=True, iterations=25, tolerance=1e-6
        )
        if trial.mse > max(_PRUNE_LOSS * fit.mse, floor):
            break
        fit = trial
    return fit


def _seed_features(image, mask, level, window):
    """Window fits at the ring peaks of the image (steps 1-2 of the module's search).

    Returns ``(across, features, pool)``: the seeds' light, the seeds as features, and the
    window fits whose light disagrees as ``(misfit, params)`` to try later; or None.
    """
    reach = 2 * window
    seeds = []
    deviation = np.where(mask, image / level - 1.0, 0.0)
    for _, centre, across in _ring_peaks(deviation, mask, window, (), count=8, threshold=math.log(10.0)):
        params, misfit = fit_window(image, mask, centre, reach, level, across)
        # a fit that ran off its peak, or onto a feature already seeded, found nothing new
        if math.dist(params[3:5], centre) > window or any(
            math.dist(params[3:5], other[3:5]) < 2 for other, _ in seeds
        ):
            continue
        seeds.append((params, misfit))
    if not seeds:
        return None
    best = seeds[0][0][1:3]
    size = float(np.hypot(*best))
    if size == 0:
        return None

    def agrees(params):
        length = float(np.hypot(*params[1:3]))
        return (
            length > 0
            and abs(float(params[1:3] @ best)) >= math.cos(_SEED_ANGLE) * length * size
            and _SEED_RATIO[0] < length / size < _SEED_RATIO[1]
        )

    axis = best / size
    start = [params for params, _ in seeds if agrees(params)]
    pool = [(misfit, params) for params, misfit in seeds if not agrees(params)]
    across = axis * float(np.median([abs(float(p[1:3] @ axis)) for p in start]))
    features = [window_feature(p, reach, window, 1.0 if p[1:3] @ axis >= 0 else -1.0) for p in start]
    return across, features, pool


def _grow(image, mask, fitted, fit: Fit, window, pool, tried) -> Fit | None:
    """The joint fit of the pixels ``fitted`` (x, y, values) with one more feature (step 3 of the
    module's search), or None.

    Window fits are made at the residual's energy and ring peaks not yet ``tried`` and added to
    the ``pool``'s; of the :data:`_GROW_TRIALS` best, the first whose joint fit cuts the mean
    squared residual to :data:`_FEATURE_GAIN` of it joins.
    """
    from scipy import ndimage as ndi
    from skimage.feature import peak_local_max

    reach = 2 * window
    rest = np.zeros(image.shape)
    rest[mask] = -fit.residual / fit.level
    energy = ndi.gaussian_filter(rest**2, window / 2)
    spots = [
        np.array([float(c), -float(r)]) for r, c in peak_local_max(energy, min_distance=window, num_peaks=3)
    ]
    centres = [c for c, _ in fit.features]
    spots += [c for _, c, _ in _ring_peaks(rest, mask, window, centres, count=2, threshold=0.0)]
    spots = [s for s in spots if all(math.dist(s, t) >= 1 for t in tried)]
    tried += spots
    candidates = [(misfit, p) for misfit, p in pool if _is_new(p, fit.features)]
    for spot in spots:
        params, misfit = fit_window(image, mask, spot, reach, fit.level, fit.across, iterations=25)
        if _is_new(params, fit.features) and all(math.dist(params[3:5], p[3:5]) >= 1 for _, p in candidates):
            candidates.append((misfit, params))
    candidates.sort(key=lambda item: item[0])
    for _, params in candidates[:_GROW_TRIALS]:
        sign = 1.0 if params[1:3] @ fit.across >= 0 else -1.0
        features = fit.features + [window_feature(params, reach, window, sign)]
        trial = fit_features(
            *fitted, fit.level, fit.across, features, window, robust=True, iterations=10, tolerance=1e-5
        )
        if trial.mse < _FEATURE_GAIN * fit.mse:
            return fit_features(
                *fitted, trial.level, trial.across, trial.features, window, robust=True, tolerance=1e-6
            )
    return None


def _is_new(params, features) -> bool:
    """Whether a window fit's centre is at least 2 pixels from every feature's."""
    return all(math.dist(params[3:5], centre) >= 2 for centre, _ in features)


def block_mean(image, mask, factor: int):
    """The image averaged over ``factor x factor`` blocks, and the mask of the blocks all of whose
    pixels are object (the last rows and columns that do not fill a block are cropped).

    Parameters
    ----------
    image : (H, W) float64
    mask : (H, W) bool
    factor : int
        Side of a block, >= 1.

    Returns
    -------
    (H // factor, W // factor) float64, and (H // factor, W // factor) bool
    """
    if factor == 1:
        return image, mask
    height, width = image.shape[0] // factor, image.shape[1] // factor

    def blocks(a):
        return a[: height * factor, : width * factor].reshape(height, factor, width, factor)

    return blocks(image).mean(axis=(1, 3)), blocks(mask).all(axis=(1, 3))


def ring_scores(deviation, window: int):
    """Rings around every pixel fitted as a round feature's (step 1 of the module's search).

    ``deviation`` is ``I / (k L_z) - 1`` (0 off the object). Around a round feature's centre the
    ring of radius ``r`` reads ``a(r) + b(r) . u``, ``u`` the unit vector from the centre, with
    ``a = n_z - 1 <= 0`` and ``b = sqrt(1 - n_z^2) tau``. Ring means, and first harmonics by
    correlation with ``cos`` and ``sin`` of the angle, come from FFT correlations that share the
    image's transform.

    Parameters
    ----------
    deviation : (H, W) float64
        ``I / (k L_z) - 1`` on the object, 0 elsewhere.
    window : int
        Radius (pixels) of the outermost ring.

    Returns
    -------
    across : (H, W, 2) float64
        Least-squares ``tau`` from the rings around each pixel.
    score : (H, W) float64
        ``-log`` of the share of the energy within ``window`` that the rings leave unexplained.
    energy : (H, W) float64
        Sum of ``deviation^2`` within ``window``.
    """
    from scipy import fft

    reach = window + 1
    dr, dc = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    radius = np.hypot(dc, dr)
    angle = np.arctan2(-dr, dc)  # y up
    height, width = deviation.shape
    shape = tuple(fft.next_fast_len(n + 2 * reach, real=True) for n in (height, width))
    spectrum = fft.rfft2(deviation, shape)

    def correlate(kernel, transform=spectrum):
        # sum over the kernel's offsets v of deviation(x + v) kernel(v), zero past the image
        full = fft.irfft2(transform * fft.rfft2(kernel[::-1, ::-1], shape), shape)
        return full[reach : reach + height, reach : reach + width]

    disk = (radius < window + 0.5).astype(np.float64)
    energy = correlate(disk, fft.rfft2(deviation * deviation, shape))
    explained = np.zeros(deviation.shape)
    moment = np.zeros(deviation.shape + (2,))
    weight = np.full(deviation.shape, 1e-300)
    for k in range(1, window + 1):
        ring = np.abs(radius - k) < 0.5
        count = float(ring.sum())
        spread = float((ring * np.cos(angle) ** 2).sum())
        mean = correlate(ring.astype(np.float64)) / count
        harmonic = (
            np.stack([correlate(ring * np.cos(angle)), correlate(ring * np.sin(angle))], axis=-1) / spread
        )
        # a brighter ring than the base is not a round feature's
        explained += count * np.minimum(mean, 0.0) ** 2
        lean = np.sqrt(1.0 - np.clip(1.0 + mean, 0.0, 1.0) ** 2)
        moment += (spread * lean)[..., None] * harmonic
        weight += spread * lean * lean
    explained += (moment**2).sum(axis=-1) / weight
    across = moment / weight[..., None]
    left = 1.0 - np.clip(explained / np.maximum(energy, 1e-300), 0.0, 1.0)
    return across, -np.log(np.maximum(left, 1e-9)), energy


def _ring_peaks(deviation, mask, window, exclude, *, count, threshold):
    """Up to ``count`` peaks of :func:`ring_scores` at least ``window / 2`` from the centres in
    ``exclude``, best first, as ``(score, centre (x, y), across)``. Pixels whose window leaves the
    object, or holds under 5% of the largest energy (the bare base), are not candidates."""
    from scipy import ndimage as ndi
    from skimage.feature import peak_local_max

    across, score, energy = ring_scores(deviation, window)
    inner = ndi.binary_erosion(mask, iterations=max(window // 2, 1))
    if not inner.any():
        return []
    score = np.where(inner & (energy > 0.05 * energy[inner].max()), score, 0.0)
    found = []
    for r, c in peak_local_max(score, min_distance=2, threshold_abs=threshold):
        centre = np.array([float(c), -float(r)])
        if all(math.dist(centre, e) >= window / 2 for e in exclude):
            found.append((float(score[r, c]), centre, across[r, c]))
    found.sort(key=lambda item: -item[0])
    return found[:count]
