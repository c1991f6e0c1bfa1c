"""Lambertian photometric stereo: Woodham's least squares and its robust variant.

Both fit ``g = rho n`` per pixel from ``I_j = l_j . g``; the robust fit leaves out each pixel's
shadowed, grazing and highlighted readings (:mod:`shadeform.photometric`'s description). The
robust fit's thresholds below were chosen on synthetic Blinn-Phong spheres
(``benchmarks/bench_stereo.py``), not on the real photos it is reported on.
"""

from __future__ import annotations

import numpy as np

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


def fit(lights, readings, weights):
    """Per pixel, ``g`` minimising ``sum_j w_j (l_j . g - I_j)^2``: (P, 3), NaN where the used
    lights do not span 3-D; and the 0/1 usage (N, P)."""
    A = outer(weights, lights)
    b = (weights * readings).T @ lights
    # det(A) against (trace / 3)^3 (1 for well-spread lights): near 0 when the used lights are
    # (nearly) coplanar or fewer than three
    ok = np.linalg.det(A) > 1e-6 * (np.trace(A, axis1=1, axis2=2) / 3) ** 3
    ok &= np.trace(A, axis1=1, axis2=2) > 0
    g = np.full(b.shape, np.nan)
    if ok.any():
        g[ok] = np.linalg.solve(A[ok], b[ok, :, None])[..., 0]
    return g, np.broadcast_to(weights > 0, readings.shape) & ok[None, :]


def robust(lights, readings, *, min_shading, highlight_cos, iterations):
    """The robust fit (:mod:`shadeform.photometric`'s description): (P, 3) ``g`` and the final
    usage (N, P). Black readings are never counted; a pixel whose final fit counts a reading
    its normal puts in shadow gets NaN."""
    count = len(lights)
    order = np.argsort(readings, axis=0)
    low = int(DROP_DARK * count) if count > 4 else min(1, count - 3)
    high = int(DROP_BRIGHT * count) if count > 4 else 0
    start = np.zeros_like(readings)
    np.put_along_axis(start, order[low : count - high], 1.0, axis=0)
    lit = readings > 0  # a black reading says only "no light reached": not a linear equation
    g, usable = fit(lights, readings, start * lit)
    # pixels whose middle readings do not span 3-D start from all of their lit readings
    lost = ~np.isfinite(g[:, 0])
    if lost.any():
        g[lost], usable[:, lost] = fit(lights, readings[:, lost], lit[:, lost].astype(np.float64))
    half = half_vectors(lights)
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
        keep = (lights @ n.T >= min_shading) & (half @ n.T <= highlight_cos) & (excess <= limit) & lit
        g_new, usable_new = fit(lights, readings, keep.astype(np.float64))
        better = solved & np.isfinite(g_new[:, 0])
        g[better] = g_new[better]
        usable[:, better] = usable_new[:, better]
    # a fit that still counts a reading its own normal puts in shadow (the pixel never had three
    # lit readings to refit from) is not a normal: the pixel is left to the caller's fill
    shadowed = np.any(usable & (lights @ np.nan_to_num(g).T <= 0), axis=0)
    g[shadowed] = np.nan
    return g, usable


def half_vectors(lights):
    """(N, 3) unit half vectors between each light (N, 3) and the viewer ``v = (0, 0, 1)``."""
    half = lights + np.array([0.0, 0.0, 1.0])
    return half / np.maximum(np.linalg.norm(half, axis=1, keepdims=True), 1e-12)


def scaled_lights(lights, scale):
    """Unit lights (N, 3) whose ``tan(slant)`` is ``scale`` times that of ``lights`` (N, 3): their
    x and y components scaled, then normalised."""
    out = np.array(lights, dtype=np.float64)
    out[:, :2] *= scale
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def outer(weights, lights):
    """Per pixel ``sum_j w_j l_j l_j^T``: (P, 3, 3) from weights (N, P) and lights (N, 3)."""
    return (weights.T @ (lights[:, :, None] * lights[:, None, :]).reshape(len(lights), 9)).reshape(-1, 3, 3)


def least_squares(lights, readings, **_):
    """Woodham's fit of every reading: ``g`` (P, 3) and the usage (N, P)."""
    return fit(lights, readings, np.ones_like(readings))
