"""What every kind of evidence for the light shares: the object's levels and the reading it returns.

:func:`shadeform.light.estimate_light` measures the object once (:class:`Levels`: noise, the
brightest level, the level at the top, the distance of every pixel inside the silhouette) and asks
each kind of evidence in turn (the occluding contour, rings inside a round object, a relief on a
flat base) for a :class:`Reading`; each answers one or None, so the dispatcher decides in one
place. Private: the modules of :mod:`shadeform.light` only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Fewest object pixels whose light :func:`shadeform.light.estimate_light` will estimate.
MIN_OBJECT_PIXELS = 100

# Radius (pixels) of the quadratic fit at the brightest point: at most twice this.
_PEAK_RADIUS = 8


@dataclass(frozen=True)
class Reading:
    """One kind of evidence's answer: slant and tilt (degrees, before ``convex`` turns the tilt),
    ``k * albedo``, the name of the ``evidence`` and what it measured (``info``)."""

    slant: float
    tilt: float
    albedo: float
    evidence: str
    info: dict = field(default_factory=dict)


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
    """

    inside: np.ndarray
    noise: float
    peak: float
    top: float

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
    brightest = float(image[mask].max())
    peak = max(_peak_level(image, mask, inside, noise), 1e-3 * brightest)
    # a top in shadow would put the light behind the object's horizon
    top = max(_top_level(image, mask, inside), 1e-3 * peak)
    return Levels(inside=inside, noise=noise, peak=peak, top=top)


def from_components(across, along_view) -> tuple[float, float, float]:
    """Slant, tilt (degrees) and ``k`` from ``k L_xy`` (2,) and ``k L_z``."""
    size = math.hypot(float(across[0]), float(across[1]))
    slant = math.degrees(math.atan2(size, along_view))
    tilt = math.degrees(math.atan2(float(across[1]), float(across[0]))) if size > 0 else 0.0
    return slant, tilt, math.hypot(size, along_view)


def slant_from_peak(along_view, peak) -> float:
    """Slant (degrees) at which the brightest point faces the light: ``cos(slant) = k L_z / I_max``."""
    return math.degrees(math.acos(min(along_view / peak, 1.0)))


def fit_below_highlights(design, values, *, fewest: int):
    """Least-squares fit of ``values`` (n,) by ``design`` (n, p), refitted twice without the
    values far above the fit (specular highlights: more than three robust standard deviations).

    Returns
    -------
    coef : (p,) float64 or None
        The last fit; None when fewer than ``fewest`` values were left to fit.
    kept : (n,) bool
        The values below the last fit's cut.
    """
    kept = np.ones(values.size, dtype=bool)
    coef = None
    for _ in range(3):
        if kept.sum() < fewest:
            return None, kept
        coef, *_ = np.linalg.lstsq(design[kept], values[kept], rcond=None)
        residual = values - design @ coef
        spread = 1.4826 * float(np.median(np.abs(residual[kept]))) + 1e-12
        kept = residual < 3.0 * spread
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


def _peak_level(image, mask, inside, noise) -> float:
    """Brightest level of the object: the peak of a quadratic fitted around the brightest point.

    The fit covers a disk around the maximum of the smoothed image, sized from the blob that lies
    within a few noise levels (at least 1%) of that maximum. The maximum of a noisy image is
    biased upward; the fitted quadratic's peak is not.
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
    radius = int(round(min(max(1.5 * math.sqrt(area / math.pi), 3.0), 2.0 * _PEAK_RADIUS)))
    rr, cc = _disk(mask, centre, radius)
    if rr.size < 12:
        return top
    return _quadratic_peak(
        rr.astype(np.float64), cc.astype(np.float64), image[rr, cc], centre, reach=float(radius)
    )


def _top_level(image, mask, inside) -> float:
    """Intensity at the point deepest inside the silhouette, taken to face the viewer.

    A quadratic is fitted on a disk around that point, without the specular highlights
    (:func:`fit_below_highlights`); its value at the point is returned.
    """
    centre = np.unravel_index(np.argmax(inside), mask.shape)
    depth = float(inside[centre])
    radius = int(max(3, min(0.25 * depth, depth - 1)))
    rr, cc = _disk(mask, centre, radius)
    values = image[rr, cc]
    rf, cf = (rr - centre[0]).astype(np.float64), (cc - centre[1]).astype(np.float64)
    coef, _ = fit_below_highlights(_quadratic_design(rf, cf), values, fewest=12)
    return float(np.median(values)) if coef is None else float(coef[0])
