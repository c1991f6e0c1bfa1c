"""What every kind of evidence for the light shares: the object's levels and the reading it returns.

:func:`shadeform.light.estimate_light` measures the object once (:class:`Levels`: noise, the
brightest level with and without the specular highlights, the level at the top, a plateau the
camera clipped, the distance of every pixel inside the silhouette) and asks each kind of evidence
in turn (the occluding contour, rings inside a round object, a relief on a flat base) for a
:class:`Reading`; each answers one or None, so the dispatcher decides in one place. Each reading
carries its spread, which :func:`confidence` turns into the estimate's confidence. Private: the
modules of :mod:`shadeform.light` only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Fewest object pixels whose light :func:`shadeform.light.estimate_light` will estimate.
MIN_OBJECT_PIXELS = 100

# Radius (pixels) of the quadratic fit at the brightest point: at most twice this, or this much
# past a clipped plateau.
_PEAK_RADIUS = 8
# Most moves of the disk of the Lambertian peak's fit toward the fit's stationary point, and most
# passes of its fit without the highlights (a broad highlight's flanks go a few at a time).
_PEAK_MOVES = 5
_PEAK_PASSES = 20
# The fractions of the lit pixels (brightest first) over which the level is extrapolated to the
# top of a Lambertian dome: on the synthetic sphere, ellipsoid and vase of bench_light that reads
# the top within 1% (noise-free and 2% noise) but where the vase's normals miss the light.
_SURVIVAL_BAND = (0.02, 0.10)
# A plateau at the brightest value with this many connected pixels inside it (all their
# neighbours at that value) was clipped by the camera: a smooth maximum is one pixel (a few where
# a synthetic scene is symmetric about it), a ridge's a line, noise scatters its clipped pixels.
_PLATEAU_PIXELS = 5


#: The angle (degrees) of :attr:`shadeform.light.LightEstimate.confidence`: the confidence is the
#: chance that the true light lies within this angle of the estimate.
CONFIDENCE_ANGLE = 10.0


@dataclass(frozen=True)
class Reading:
    """One kind of evidence's answer: slant and tilt (degrees, before ``convex`` turns the tilt),
    ``k * albedo``, the name of the ``evidence``, what it measured (``info``) and the ``spread``
    of the light it reads: the root-mean-square angle (degrees) between that light and the true
    one, as the evidence itself measures it (:func:`confidence`)."""

    slant: float
    tilt: float
    albedo: float
    evidence: str
    info: dict = field(default_factory=dict)
    spread: float = math.inf

    @property
    def light(self) -> np.ndarray:
        """The unit vector of :attr:`slant` and :attr:`tilt`."""
        return unit_light(self.slant, self.tilt)


def unit_light(slant, tilt) -> np.ndarray:
    """``(sin s cos t, sin s sin t, cos s)`` for slant ``s`` and tilt ``t`` in degrees."""
    s, t = math.radians(slant), math.radians(tilt)
    return np.array([math.sin(s) * math.cos(t), math.sin(s) * math.sin(t), math.cos(s)])


def angle_between(a, b) -> float:
    """Angle (degrees) between two vectors (3,)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b)))


def jackknife_spread(lights) -> float:
    """Root-mean-square angle (degrees) of a light read from all the evidence, from the lights
    ``(m, 3)`` read with each of ``m`` parts of it left out in turn (the jackknife's variance,
    ``(m - 1) / m`` times the sum of squared deviations from their mean direction)."""
    lights = np.asarray(lights, dtype=np.float64)
    count = lights.shape[0]
    if count < 2:
        return math.inf
    mean = lights.sum(axis=0)
    deviations = np.array([angle_between(light, mean) for light in lights])
    return math.sqrt((count - 1) / count * float(deviations @ deviations))


def confidence(spread: float) -> float:
    """The chance that the true light lies within :data:`CONFIDENCE_ANGLE` of an estimate whose
    error is an isotropic two-dimensional Gaussian on the sphere of root-mean-square angle
    ``spread`` (degrees): ``1 - exp(-(CONFIDENCE_ANGLE / spread)^2)``; 1 for a spread of 0, 0 for
    an infinite one."""
    if not math.isfinite(spread):
        return 0.0
    if spread <= 0.0:
        return 1.0
    return 1.0 - math.exp(-((CONFIDENCE_ANGLE / spread) ** 2))


def bound_spread(slant: float) -> float:
    """Root-mean-square angle (degrees) of a slant known only to be at least ``slant``: the truth
    taken as evenly spread between that bound and the horizon."""
    return (90.0 - slant) / math.sqrt(3.0)


@dataclass(frozen=True, eq=False)
class Levels:
    """Measured once per image, read by every kind of evidence.

    Attributes
    ----------
    inside : (H, W) float64
        Distance (pixels) of each object pixel to the nearest background pixel.
    noise : float
        Standard deviation of the pixel noise (:func:`shadeform.preprocess.noise_level`).
    peak : float
        Brightest level of the object (:func:`_peak_level`).
    top : float
        Level at the point deepest inside the silhouette (:func:`_top_level`), taken as ``k L_z``.
    quartile : float
        Lower quartile of the lit object pixels (those above :attr:`lit`).
    brightest : float
        Brightest Lambertian level, taken as ``k`` where the brightest point faces the light: the
        larger of :func:`_lambertian_peak` (:attr:`peak` without the specular highlights) and
        :func:`_survival_peak` (from the distribution of the levels).
    clipped : int
        Object pixels on a plateau at the brightest value (clipped by the camera), left out of the
        fits of :attr:`peak`, :attr:`top` and :attr:`brightest`.
    """

    inside: np.ndarray
    noise: float
    peak: float
    top: float
    quartile: float
    brightest: float
    clipped: int = 0

    @property
    def lit(self) -> float:
        """Intensity above which a pixel counts as lit: well above the noise and 2% of the peak."""
        return max(3.0 * self.noise, 0.02 * self.peak)


def measure_levels(image, mask) -> Levels:
    """The :class:`Levels` of the object ``mask`` in ``image`` (float64 (H, W), bool (H, W))."""
    from scipy import ndimage as ndi

    from shadeform.preprocess import noise_level

    inside = ndi.distance_transform_edt(mask)
    noise = noise_level(image, mask, inside=inside)
    values = image[mask]
    brightest = float(values.max())
    clipped = _clipped_plateau(image, mask, brightest)
    peak = max(_peak_level(image, mask, inside, noise, clipped), 1e-3 * brightest)
    # a top in shadow would put the light behind the object's horizon
    top = max(_top_level(image, mask, inside, clipped), 1e-3 * peak)
    lit_level = max(3.0 * noise, 0.02 * peak)
    # two readings of the brightest Lambertian level, local and global; the larger, since a level
    # too low sends the light toward the horizon, one too high only toward the viewer
    brightest = max(
        _lambertian_peak(image, mask, inside, clipped),
        _survival_peak(values[values > lit_level]),
        1e-3 * peak,
    )
    lit = values[values > lit_level]
    quartile = float(np.percentile(lit, 25)) if lit.size else 0.0
    return Levels(
        inside=inside,
        noise=noise,
        peak=peak,
        top=top,
        quartile=quartile,
        brightest=brightest,
        clipped=int(clipped.sum()),
    )


def from_components(across, along_view) -> tuple[float, float, float]:
    """Slant, tilt (degrees) and ``k`` from ``k L_xy`` (2,) and ``k L_z``."""
    size = math.hypot(float(across[0]), float(across[1]))
    slant = math.degrees(math.atan2(size, along_view))
    tilt = math.degrees(math.atan2(float(across[1]), float(across[0]))) if size > 0 else 0.0
    return slant, tilt, math.hypot(size, along_view)


def slant_from_peak(along_view, peak) -> float:
    """Slant (degrees) at which the brightest point faces the light: ``cos(slant) = k L_z / I_max``."""
    return math.degrees(math.acos(min(along_view / peak, 1.0)))


def fit_below_highlights(design, values, *, fewest: int, passes: int = 3):
    """Least-squares fit of ``values`` (n,) by ``design`` (n, p), refitted without the values far
    above the fit (specular highlights: more than three robust standard deviations), ``passes``
    fits in all or until the values left out stay the same.

    Returns
    -------
    coef : (p,) float64 or None
        The last fit; None when fewer than ``fewest`` values were left to fit.
    kept : (n,) bool
        The values below the last fit's cut.
    """
    kept = np.ones(values.size, dtype=bool)
    coef = None
    for _ in range(passes):
        if kept.sum() < fewest:
            return None, kept
        coef, *_ = np.linalg.lstsq(design[kept], values[kept], rcond=None)
        residual = values - design @ coef
        spread = 1.4826 * float(np.median(np.abs(residual[kept]))) + 1e-12
        below = residual < 3.0 * spread
        if np.array_equal(below, kept):
            break
        kept = below
    return coef, kept


def _quadratic_design(rows, cols) -> np.ndarray:
    """Columns ``1, r, c, r^2, r c, c^2`` (n, 6) of a quadratic in row and column offsets."""
    return np.column_stack([np.ones_like(rows), rows, cols, rows * rows, rows * cols, cols * cols])


def _quadratic_peak(rows, cols, values, centre, reach=None) -> float:
    """Value at the stationary point of a least-squares quadratic, or at ``centre`` if that point
    lies farther than ``reach`` (default :data:`_PEAK_RADIUS`) from it."""
    dr, dc = rows - centre[0], cols - centre[1]
    coef, *_ = np.linalg.lstsq(_quadratic_design(dr, dc), values, rcond=None)
    hessian = np.array([[2 * coef[3], coef[4]], [coef[4], 2 * coef[5]]])
    try:
        offset = np.linalg.solve(hessian, -coef[1:3])
    except np.linalg.LinAlgError:
        offset = np.zeros(2)
    if not np.isfinite(offset).all() or np.hypot(*offset) > (reach or _PEAK_RADIUS):
        offset = np.zeros(2)
    return float(_quadratic_design(offset[:1], offset[1:])[0] @ coef)


def _disk(mask, centre, radius):
    """Rows and columns of the object pixels within ``radius`` of ``centre`` (row, col)."""
    r0, c0 = centre
    rr, cc = np.mgrid[
        max(r0 - radius, 0) : min(r0 + radius + 1, mask.shape[0]),
        max(c0 - radius, 0) : min(c0 + radius + 1, mask.shape[1]),
    ]
    inside = mask[rr, cc] & ((rr - r0) ** 2 + (cc - c0) ** 2 <= radius * radius)
    return rr[inside], cc[inside]


def _peak_level(image, mask, inside, noise, clipped) -> float:
    """Brightest level of the object: the peak of a quadratic fitted around the brightest point.

    The fit covers a disk around the maximum of the smoothed image, sized from the blob that lies
    within a few noise levels (at least 1%) of that maximum. The maximum of a noisy image is
    biased upward; the fitted quadratic's peak is not. ``clipped`` pixels (H, W) bool are left
    out, and the disk reaches :data:`_PEAK_RADIUS` past them.
    """
    from scipy import ndimage as ndi

    weight = mask.astype(np.float64)
    width = 1.5
    smooth = ndi.gaussian_filter(image * weight, width) / np.maximum(
        ndi.gaussian_filter(weight, width), 1e-12
    )
    region = mask & (inside > 2)
    if not region.any():
        region = mask
    centre = np.unravel_index(np.argmax(np.where(region, smooth, -np.inf)), mask.shape)
    top = float(smooth[centre])
    # noise left after smoothing: sigma / (2 sqrt(pi) width)
    drop = max(4.0 * noise / (2.0 * math.sqrt(math.pi) * width), 0.01 * top)
    labels, _ = ndi.label(region & (smooth >= top - drop))
    area = float(np.count_nonzero(labels == labels[centre]))
    # a disk, not the blob itself: choosing pixels by their noisy values would bias the fit
    largest = 2.0 * _PEAK_RADIUS
    if clipped.any():
        rows, cols = np.nonzero(clipped)
        largest = max(largest, float(np.hypot(rows - centre[0], cols - centre[1]).max()) + _PEAK_RADIUS)
    radius = int(round(min(max(1.5 * math.sqrt(area / math.pi), 3.0), largest)))
    rr, cc = _disk(mask & ~clipped, centre, radius)
    if rr.size < 12:
        return top
    return _quadratic_peak(
        rr.astype(np.float64), cc.astype(np.float64), image[rr, cc], centre, reach=float(radius)
    )


def _top_level(image, mask, inside, clipped) -> float:
    """Intensity at the point deepest inside the silhouette, taken to face the viewer.

    A quadratic is fitted on a disk around that point, without the specular highlights
    (:func:`fit_below_highlights`) and the ``clipped`` pixels (H, W) bool; its value at the point
    is returned. Where the clipped pixels cover the point, the disk grows to reach past them; where
    nothing unclipped is left, the clipped level is all there is.
    """
    centre = np.unravel_index(np.argmax(inside), mask.shape)
    depth = float(inside[centre])
    radius = int(max(3, min(0.25 * depth, depth - 1)))
    rr, cc = _disk(mask & ~clipped, centre, radius)
    if clipped[centre]:
        rows, cols = np.nonzero(clipped)
        reach = float(np.hypot(rows - centre[0], cols - centre[1]).max())
        rr, cc = _disk(mask & ~clipped, centre, int(max(radius, reach + radius)))
    values = image[rr, cc]
    if values.size == 0:
        return float(image[centre])
    rf, cf = (rr - centre[0]).astype(np.float64), (cc - centre[1]).astype(np.float64)
    coef, _ = fit_below_highlights(_quadratic_design(rf, cf), values, fewest=12)
    return float(np.median(values)) if coef is None else float(coef[0])


def _clipped_plateau(image, mask, brightest) -> np.ndarray:
    """The plateau (H, W) bool at the ``brightest`` value where the camera clipped the object (or
    quantised a smooth top into one level): the fits at the top and the peak leave it out and
    reach past it. Only a solid plateau counts: at least :data:`_PLATEAU_PIXELS` connected pixels
    whose neighbours are all at that value. A ridge (the top line of a cylinder) has no such
    pixels, nor do the scattered pixels that noise pushes past the clipping level."""
    from scipy import ndimage as ndi

    plateau = mask & (image >= brightest)
    labels, count = ndi.label(ndi.binary_erosion(plateau, structure=np.ones((3, 3), dtype=bool)))
    if count == 0:
        return np.zeros_like(mask)
    sizes = np.bincount(labels.ravel())[1:]
    solid = np.isin(labels, 1 + np.flatnonzero(sizes >= _PLATEAU_PIXELS))
    if not solid.any():
        return np.zeros_like(mask)
    return ndi.binary_propagation(solid, mask=plateau)


def _survival_peak(values) -> float:
    """The brightest Lambertian level of the lit ``values`` (n,), read from their distribution.

    Near the top of a Lambertian dome the area brighter than ``t`` shrinks linearly to zero at the
    top (the normals within an angle ``a`` of the light cover an area in proportion to
    ``1 - cos a``), so the level exceeded by a fraction ``f`` of the pixels is a line in ``f``
    reaching the top at ``f = 0``. The line is fitted over :data:`_SURVIVAL_BAND`, clear of the
    few pixels a narrow highlight brightens and of the dome's curvature further down.
    """
    if values.size < 50:
        return float(values.max()) if values.size else 0.0
    ordered = np.sort(values)[::-1]
    fraction = (np.arange(ordered.size) + 0.5) / ordered.size
    band = (fraction >= _SURVIVAL_BAND[0]) & (fraction <= _SURVIVAL_BAND[1])
    slope, intercept = np.polyfit(fraction[band], ordered[band], 1)
    return float(intercept)


def _lambertian_peak(image, mask, inside, clipped) -> float:
    """The brightest level of the Lambertian shading: a quadratic fitted without the highlights.

    A specular highlight sits where the normal halves the angle between the light and the viewer,
    a narrow lobe on or beside the broad Lambertian dome around the normal that faces the light.
    A quadratic is fitted on a disk a quarter of the object's depth across (within about 15
    degrees of normal on a sphere, where the dome is a quadratic to 1e-4), leaving out the values
    far above it (:func:`fit_below_highlights`) and the ``clipped`` pixels; the disk moves to the
    fit's stationary point until it stays. Starts at the brightest point of the smoothed image.
    """
    from scipy import ndimage as ndi

    weight = mask.astype(np.float64)
    smooth = ndi.gaussian_filter(image * weight, 1.5) / np.maximum(ndi.gaussian_filter(weight, 1.5), 1e-12)
    centre = np.unravel_index(np.argmax(np.where(mask, smooth, -np.inf)), mask.shape)
    radius = max(3.0, 0.25 * float(inside.max()))
    if clipped.any():
        rows, cols = np.nonzero(clipped)
        radius += float(np.hypot(rows - centre[0], cols - centre[1]).max())
    level = float(smooth[centre])
    for _ in range(_PEAK_MOVES):
        rr, cc = _disk(mask & ~clipped, centre, int(round(radius)))
        if rr.size < 12:
            break
        dr, dc = (rr - centre[0]).astype(np.float64), (cc - centre[1]).astype(np.float64)
        coef, _ = fit_below_highlights(
            _quadratic_design(dr, dc), image[rr, cc], fewest=12, passes=_PEAK_PASSES
        )
        if coef is None:
            break
        hessian = np.array([[2 * coef[3], coef[4]], [coef[4], 2 * coef[5]]])
        try:
            offset = np.linalg.solve(hessian, -coef[1:3])
        except np.linalg.LinAlgError:
            offset = np.full(2, np.inf)
        if (
            not np.isfinite(offset).all()
            or np.hypot(*offset) > radius
            or np.linalg.eigvalsh(hessian).max() >= 0
        ):
            level = float(coef[0])  # no maximum within the disk: the fit's value at its centre
            break
        level = float(_quadratic_design(offset[:1], offset[1:])[0] @ coef)
        moved = (int(round(centre[0] + offset[0])), int(round(centre[1] + offset[1])))
        inside_image = 0 <= moved[0] < mask.shape[0] and 0 <= moved[1] < mask.shape[1]
        if moved == tuple(centre) or not inside_image or not mask[moved]:
            break
        centre = moved
    return level
