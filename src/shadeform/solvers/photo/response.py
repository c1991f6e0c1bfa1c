"""The photo solver's reflectance curve: brightness as a non-decreasing function of ``n . L``,
estimated from the photo itself (:mod:`shadeform.solvers.photo`'s description).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import isotonic_regression

#: Bins of ``n . L`` over [0, 1] for the reflectance curve, and the fewest pixels a bin needs:
#: set once before any measurement (a tenth of the range per bin; a median of 20 pixels), not
#: tuned on any data.
BINS = 10
BIN_PIXELS = 20


def response_curve(shading: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The reflectance curve: brightness as a non-decreasing function of ``n . L``.

    The median brightness in each of :data:`BINS` equal bins of ``n . L`` over [0, 1] holding at
    least :data:`BIN_PIXELS` pixels, made non-decreasing by isotonic regression weighted by the
    bins' pixel counts, then carried on straight to ``n . L = 0`` (not below 0) and to 1 (not
    downward) from the two end bins.

    Parameters
    ----------
    shading : (N,) float
        ``n . L`` of the current shape's pixels.
    values : (N,) float
        Their brightness.

    Returns
    -------
    (K, 2) float64
        Rows ``(n . L, brightness)`` with increasing ``n . L`` from 0 to 1; the last brightness,
        ``f(1)``, is positive.
    """
    facing = shading > 0
    lit, bright = shading[facing], values[facing]
    which = np.minimum((lit * BINS).astype(np.int64), BINS - 1)
    order = np.argsort(which, kind="stable")
    groups = np.split(order, np.searchsorted(which[order], np.arange(1, BINS)))
    kept = [g for g in groups if g.size >= BIN_PIXELS]
    if len(kept) < 2:  # too few pixels facing the light to see a curve: Lambert's line
        return _lambert(max(float(values.max(initial=0.0)), 1e-12))
    centres = np.array([np.median(lit[g]) for g in kept])
    fitted = isotonic_regression(
        np.array([np.median(bright[g]) for g in kept]),
        weights=np.array([g.size for g in kept], dtype=np.float64),
    ).x
    start = fitted[0] - (fitted[1] - fitted[0]) / (centres[1] - centres[0]) * centres[0]
    end = fitted[-1] + max(0.0, (fitted[-1] - fitted[-2]) / (centres[-1] - centres[-2])) * (1.0 - centres[-1])
    knots = np.r_[0.0, centres, 1.0]
    levels = np.maximum.accumulate(np.r_[np.clip(start, 0.0, fitted[0]), fitted, end])
    if levels[-1] <= 0:
        levels[-1] = max(float(values.max()), 1e-12)
    # a last bin centred at n . L = 1 (a flat patch facing the light) would make a zero-width
    # segment with the end knot
    knots = knots + np.arange(knots.size) * 1e-9
    return np.column_stack([knots, levels])


def _lambert(albedo: float) -> np.ndarray:
    """Lambert's reflectance curve ``albedo * max(0, n . L)`` as a (2, 2) curve."""
    return np.array([[0.0, 0.0], [1.0, albedo]])
