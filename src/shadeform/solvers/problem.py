"""What a solver is given and what it returns: the contract of the solver registry.

:func:`shadeform.reconstruct` checks the user's input once, finds the mask, filters the image,
settles the light, the reference pixels and the brightness ``albedo``, and hands a solver one
:class:`Problem`; the solver returns a :class:`Solution` (normals and depth). Solvers never read
files, print or build meshes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np


class Reference(NamedTuple):
    """A reference pixel: ``(row, col)`` on the object, with its unit normal when the user gave one."""

    row: int
    col: int
    normal: np.ndarray | None = None

    @property
    def pixel(self) -> tuple[int, int]:
        """``(row, col)``."""
        return self.row, self.col


@dataclass(frozen=True, eq=False)
class Problem:
    """One shading image, checked and prepared, for a solver.

    Attributes
    ----------
    image : (H, W) float64
        The shading image after the filter, >= 0.
    mask : (H, W) bool
        Object pixels (not empty).
    light : (3,) float64
        Unit vector toward the light (``docs/conventions.md``).
    albedo : float
        ``k * albedo`` of the image model ``I = k * albedo * max(0, N . L)``: the brightness of a
        pixel facing the light.
    references : tuple of Reference
        The user's reference pixels first (``given`` of them), then the brightest pixel of every
        connected part of the mask left without one. ``references[0]`` is the main one: ``z = 0``
        there.
    given : int
        How many of ``references`` the user gave.
    concave_x, concave_y : (H, W) bool
        Where the user marked the surface concave along x / y (:func:`shadeform.regions.concave_masks`).
    labels : (H, W) int
        Connected parts of the mask, 1..``parts`` (0 off the object).
    parts : int
        Number of connected parts.
    integrator : str or None
        The integrator that turns normals into depth (:func:`shadeform.integration.integrate`): the
        user's, else the solver's default; None when the solver makes its own depth.
    refine : int
        Iterations of the integrability refinement, for solvers that have one.
    noise : float or None
        The image's noise (standard deviation, image units; :func:`shadeform.preprocess.noise_level`),
        measured for solvers with a noise policy, else None.
    options : dict of str to value
        The solver's own options (``Solver.options``): every one it declares, the user's value or
        its default.
    lap : callable
        ``lap("stage")`` records the time since the last lap under that stage in ``info["timings"]``.
    """

    image: np.ndarray
    mask: np.ndarray
    light: np.ndarray
    albedo: float
    references: tuple[Reference, ...]
    given: int
    concave_x: np.ndarray
    concave_y: np.ndarray
    labels: np.ndarray
    parts: int
    integrator: str | None = None
    refine: int = 0
    noise: float | None = None
    options: dict[str, Any] = field(default_factory=dict)
    lap: Callable[[str], None] = field(default=lambda stage: None, repr=False)

    @property
    def cos_theta(self) -> np.ndarray:
        """``N . L`` each pixel's brightness implies: ``image / albedo`` clipped to [0, 1], 0 off the object."""
        return np.clip(np.where(self.mask, self.image / self.albedo, 0.0), 0.0, 1.0)

    @property
    def main(self) -> tuple[int, int]:
        """``(row, col)`` of the main reference, where ``z = 0``."""
        return self.references[0].pixel

    def integrate(
        self, normals: np.ndarray, mask: np.ndarray | None = None, *, origin: tuple[int, int] | None = None
    ) -> np.ndarray:
        """Depth from ``normals`` over ``mask`` (default: the object) by :attr:`integrator`, ``z = 0``
        at ``origin`` (default: the main reference). See :func:`shadeform.integration.integrate`."""
        from shadeform.integration import integrate

        return integrate(
            normals,
            self.mask if mask is None else mask,
            integrator=self.integrator,
            origin=self.main if origin is None else origin,
        )


@dataclass(frozen=True, eq=False)
class Solution:
    """A solver's result.

    Attributes
    ----------
    normals : (H, W, 3) float64
        Unit normals on the mask (values off it are ignored). ``reconstruct`` takes both arrays
        over and writes NaN into them off the mask (no image-sized copy): a solver that keeps an
        array, or returns one of the problem's, hands over a copy.
    depth : (H, W) float64
        Height in pixel units, ``z = 0`` at the main reference (values off the mask are ignored).
    info : dict
        What the solver did, merged into ``Reconstruction.info`` (JSON-serialisable values).
    """

    normals: np.ndarray
    depth: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)
