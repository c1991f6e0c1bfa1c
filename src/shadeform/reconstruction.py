"""The result of one reconstruction: a small frozen dataclass of arrays."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """Shape recovered from one image.

    Attributes
    ----------
    normals : (H, W, 3) float32 or float64
        Unit normals in the camera frame (``docs/conventions.md``), NaN outside ``mask``;
        float32 from :func:`shadeform.reconstruct` (half the memory; a unit vector's float32
        rounding is below 1e-5 degrees).
    depth : (H, W) float64
        Height z in pixel units (larger = nearer the viewer), NaN outside ``mask``;
        z = 0 at the main reference pixel.
    mask : (H, W) bool
        Object pixels.
    light : (3,) float64
        Unit vector toward the light.
    albedo : float or (H, W) float64 or (H, W, C) float64
        ``k * albedo`` of the image model ``I = k * albedo * max(0, N . L)``; per channel for
        colour photos in photometric stereo.
    info : dict
        What ran: solver, integrator, references, iterations, timings in seconds per stage;
        ``info["unsure"]``: the areas whose convexity the photo cannot settle that matter most
        (:func:`shadeform.confidence.assess`), each ``{"polygon", "axis", "share", "centre"}``;
        ``info["unsure_others"]``: ``{"areas", "share"}`` of the rest, when there are more;
        ``info["depth_bounded"]``: ``{"pixels", "max_over"}`` when the solver's depth ran past
        what the outline allows and was pulled back (:func:`shadeform.solvers.bounds.bound_depth`).
    confidence : (H, W) float32 (from :func:`shadeform.reconstruct`) or float64, or None
        How far each pixel's shape can be trusted, in [0, 1] (NaN off the mask): how well the
        normals explain the photo times how settled its convexity is
        (:func:`shadeform.confidence.assess`); None where it was not assessed.
    """

    normals: np.ndarray
    depth: np.ndarray
    mask: np.ndarray
    light: np.ndarray
    albedo: float | np.ndarray
    info: dict[str, Any] = field(default_factory=dict)
    confidence: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(H, W)``."""
        return self.mask.shape
