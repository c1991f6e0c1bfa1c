"""The light from rings inside a round object (``cue="round"`` of :func:`~shadeform.light.estimate.estimate_light`).

Real materials darken toward the occluding contour (Fresnel), which biases the contour's slant
low on photographs. On a sphere, and approximately on any object with round cross-sections, the
normals on a ring at one distance from the silhouette share one slant ``theta`` and have the tilt
of the nearest contour normal ``b``, so ``I = b . (k sin(theta) L_xy) + k cos(theta) L_z``: a
plane in ``b``. With the top level ``k L_z`` each ring gives ``cos(theta)`` and ``k L_xy``; the
rings away from the contour and the top, combined by a weighted median, read the light where real
materials are closest to Lambertian.
"""

from __future__ import annotations

import math

import numpy as np

from shadeform.light._evidence import (
    Levels,
    Reading,
    fit_below_highlights,
    from_components,
    jackknife_spread,
    unit_light,
)

# Rings are read between these fractions of the way from the silhouette to the deepest point
# (chosen on the DiLiGenT ball photos: nearer the contour the paint darkens, nearer the top the
# ring's slant is too small to read the tilt).
_RING_SPAN = (0.15, 0.85)
# Fewest lit pixels a ring needs, and fewest rings an estimate needs.
_RING_PIXELS = 20
_FEWEST_RINGS = 3
# Rings whose fitted cos(theta) lies outside this range are too near the top or too grazing.
_RING_COS = (0.3, 0.95)


def read_rings(image, mask, levels: Levels) -> Reading | None:
    """The light from rings inside a round object (``evidence="round"``, ``info["rings"]`` the
    number read), or None when fewer than three rings could be read (a dark, tiny or back-lit
    object). ``image``, ``mask`` and ``levels`` as for :func:`shadeform.light.contour.read_contour`.
    """
    from scipy import ndimage as ndi

    inside = levels.inside
    deepest = float(inside.max())
    smooth = ndi.gaussian_filter(inside, 1.0)
    grad_r, grad_c = np.gradient(smooth)
    length = np.maximum(np.hypot(grad_r, grad_c), 1e-12)
    out_x, out_y = -grad_c / length, grad_r / length
    step = max(1.0, deepest / 60.0)
    estimates, weights = [], []
    for low in np.arange(max(2.0, _RING_SPAN[0] * deepest), _RING_SPAN[1] * deepest, step):
        ring = mask & (inside > low) & (inside <= low + step)
        values = image[ring]
        lit = values > levels.lit
        if lit.sum() < _RING_PIXELS:
            continue
        design = np.column_stack([out_x[ring][lit], out_y[ring][lit], np.ones(lit.sum())])
        coef, kept = fit_below_highlights(design, values[lit], fewest=_RING_PIXELS)
        if coef is None:
            continue
        cos_ring = coef[2] / levels.top
        if not _RING_COS[0] <= cos_ring <= _RING_COS[1]:
            continue
        sin_ring = math.sqrt(1.0 - cos_ring * cos_ring)
        estimates.append(coef[:2] / sin_ring)
        weights.append(kept.sum() * sin_ring * sin_ring)
    if len(estimates) < _FEWEST_RINGS:
        return None
    estimates, weights = np.array(estimates), np.array(weights)
    across = _combine(estimates, weights)
    # the spread: a jackknife over the rings, each left out of the weighted median in turn
    lights = []
    for i in range(len(estimates)):
        rest = np.arange(len(estimates)) != i
        lights.append(unit_light(*from_components(_combine(estimates[rest], weights[rest]), levels.top)[:2]))
    return Reading(
        *from_components(across, levels.top),
        "round",
        {"rings": len(estimates)},
        spread=jackknife_spread(lights),
    )


def _combine(estimates, weights) -> np.ndarray:
    """``k L_xy`` (2,) from the rings' ``estimates`` (m, 2): each component's weighted median."""
    return np.array([_weighted_median(estimates[:, 0], weights), _weighted_median(estimates[:, 1], weights)])


def _weighted_median(values, weights) -> float:
    """The value at which the cumulative ``weights`` (over sorted ``values``) reach half their sum."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])
