"""Photos that contradict the rest (:mod:`shadeform.photometric`'s description): each photo's
deleted residual against the typical photo's; a photo whose light's strength explains its
disagreement is rescaled, one nothing explains is left out.
"""

from __future__ import annotations

import numpy as np

from shadeform.photometric import lambertian
from shadeform.photometric.lambertian import MIN_SHADING

#: A photo whose median deleted residual is more than this many times the median photo's
#: disagrees with the others (the package's description); a round factor, not swept. With it, of the
#: seven real DiLiGenT sets and the 16-bit ball, bear's first 19 photos disagree (17-43 % brighter
#: than calibrated, and rescaled) and cat's last, grazing one (10.5 % dim, rescaled); no other.
FAULTY = 3.0
#: A photo whose typical residual is under this share of the albedo agrees with the others,
#: whatever theirs are (a noise-free set's residuals are rounding, and their ratios mean nothing:
#: set on a noise-free synthetic sphere, where without it a clean photo was dropped; not swept).
AGREE = 0.01
#: A disagreeing photo whose light's strength is off by more than this share is rescaled; within
#: it the disagreement is left to the robust fit. Set while the residuals were not yet deleted
#: ones: then the 16-bit ball's five grazing photos disagreed, 3-5 % dim, and rescaling them cost
#: the ball 0.07 degrees; bear's faulty photos are 17-43 % off.
TOLERANCE = 0.1


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
