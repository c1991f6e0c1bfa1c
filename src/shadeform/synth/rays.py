"""Rays through implicit surfaces: first crossings, shadow rays, and radii along directions."""

from __future__ import annotations

import numpy as np

_MARCH_STEP = 0.5  # pixels between samples along a ray
_BLOCK = 16  # samples per ray evaluated at once
_BISECTIONS = 48


def first_crossing(
    implicit, origin, heading, length, *, refine: bool = True, step: float = _MARCH_STEP
) -> np.ndarray:
    """Distance along ``heading`` from each origin to the first point with F < 0, NaN if none.

    Samples every ``step`` (pixels) up to ``length`` (per ray), in blocks of ``_BLOCK`` samples,
    then (with ``refine``) bisects the bracketing step to rounding. ``F(origin)`` must be > 0.
    A part of the object thinner than ``step`` along the ray may be missed.

    Parameters
    ----------
    implicit : callable
        ``F(points)`` for points ``(..., 3)``, negative inside.
    origin : (N, 3) float64
    heading : (3,) float64
        Unit direction of every ray.
    length : (N,) float64
        How far to look along each ray.

    Returns
    -------
    (N,) float64
    """
    count = origin.shape[0]
    found = np.full(count, np.nan)
    alive = np.arange(count)
    offsets = step * np.arange(1, _BLOCK + 1)
    base = 0.0
    while alive.size:
        steps = base + offsets  # (B,)
        samples = origin[alive, None, :] + steps[None, :, None] * heading
        inside = (implicit(samples) < 0) & (steps[None, :] <= length[alive, None] + step)
        any_inside = inside.any(axis=1)
        first = np.argmax(inside, axis=1)
        found[alive[any_inside]] = steps[first[any_inside]]
        base += _BLOCK * step
        alive = alive[~any_inside & (base < length[alive] + step)]
    if not refine:
        return found
    hit = np.nonzero(np.isfinite(found))[0]
    lo, hi = found[hit] - step, found[hit]
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        inside = implicit(origin[hit] + mid[:, None] * heading) < 0
        lo, hi = np.where(inside, lo, mid), np.where(inside, mid, hi)
    found[hit] = 0.5 * (lo + hi)
    return found


def _blocked(implicit, origin, heading, bound) -> np.ndarray:
    """Whether the ray from each origin along ``heading`` meets F < 0 before leaving the bound."""
    along = origin @ heading
    exit_distance = -along + np.sqrt(
        np.maximum(along**2 - np.einsum("ij,ij->i", origin, origin) + bound**2, 0)
    )
    return np.isfinite(first_crossing(implicit, origin, heading, exit_distance, refine=False))


def _radial(implicit, directions, reach: float) -> np.ndarray:
    """Distance from the origin to the surface along each unit direction (bisection on [0, reach])."""
    lo = np.zeros(directions.shape[0])
    hi = np.full(directions.shape[0], reach)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        inside = implicit(mid[:, None] * directions) < 0
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    return 0.5 * (lo + hi)


def _fibonacci_sphere(count: int) -> np.ndarray:
    """``count`` nearly evenly spread unit vectors (the Fibonacci lattice)."""
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    rho = np.sqrt(1.0 - z * z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=-1)
