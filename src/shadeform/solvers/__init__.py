"""The one registry of shape-from-shading solvers: solver name -> :class:`Solver`.

:func:`shadeform.reconstruct` only looks a solver up here; the CLI (``shadeform solvers``,
``--solver``), the app's solver picker and :func:`available_solvers` are generated from the
registry. A new solver is one module with a ``solve(problem) -> Solution`` function
(:mod:`shadeform.solvers.problem`) and one :func:`register` line; ``docs/architecture.md`` has the
recipe.

``solver="auto"`` follows one rule (:func:`choose`): the solver of lowest ``auto`` rank that takes
the light, the image's noise and its share of outlying detail.

This module imports no solver: each is imported the first time it runs, so that listing the
methods (the CLI's help, the app's options) stays cheap.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from shadeform._deprecated import renamed_attributes
from shadeform.registry import Option, Registry, load
from shadeform.solvers.problem import Problem, Reference, Solution

__all__ = [
    "AUTO",
    "NOISY",
    "OUTLIERS",
    "Option",
    "Problem",
    "Reference",
    "SOLVERS",
    "Solution",
    "Solver",
    "available_solvers",
    "choose",
    "get_solver",
    "register",
    "solver_names",
]

#: The solver name that asks :func:`choose` to pick one.
AUTO = "auto"

#: Noise (standard deviation over the object's brightest value, :func:`shadeform.preprocess.noise_level`)
#: above which an image counts as noisy: a solver's ``max_noise`` and ``denoise`` rules use it.
#: Chosen on the synthetic scenes of ``benchmarks/results/methods.md`` (noise 0-3 %): unfiltered, 1 %
#: noise under oblique light takes the oblique solver's depth error from ~1 % to 40-140 %, while
#: 8-bit quantisation alone (0.1 %) stays below this.
NOISY = 0.003

#: Share of outlying detail (:attr:`shadeform.preprocess.Detail.outliers`) from which a noisy image
#: counts as a photograph with highlights, shadows, paint or texture rather than smooth shading plus
#: noise: a solver's ``min_outliers`` rule uses it. Set between the two groups it was measured on
#: (``benchmarks/results/detail.md``): 252 noisy renderings (7 synthetic scenes, 64-512 px, 3 lights,
#: 1 and 3 % noise, float and 8-bit) reach at most 0.0029, and the 18 real photographs start at
#: 0.0103 (MIT-Berkeley apple; up to 0.126); independent noise alone gives 6e-5.
OUTLIERS = 0.005

LIGHTS = ("any", "frontal")


@dataclass(frozen=True)
class Solver:
    """One solver of the registry.

    Attributes
    ----------
    name : str
        The name users pass (``reconstruct(solver=name)``, ``--solver name``).
    solve : callable or str
        ``solve(problem: Problem) -> Solution``, or ``"module:function"`` naming it (imported on
        first use).
    description : str
        One line in the user's words, shown by ``shadeform solvers`` and the app.
    lights : {"any", "frontal"}
        The lights it takes: any direction, or only (0, 0, 1).
    integrator : str or None
        The integrator that turns its normals into depth when the user names none; None when the
        solver makes its own depth (then ``depth`` says how).
    depth : str
        What makes its depth when ``integrator`` is None, for ``Reconstruction.info``.
    preview_pixels : int
        Most object pixels a quick look (:func:`shadeform.coarse.reconstruct_preview`) solves
        with it: about 0.1 s of its time on one core.
    denoise : str or None
        Its noise policy: when the user gives no filter and the image is noisy (:data:`NOISY`), the
        image is smoothed with this filter (``"KIND:SIZE"``, :func:`shadeform.preprocess.parse_filter`)
        first. Solvers with a policy are also given the measured
        ``Problem.noise``.
    auto : int or None
        Its rank for ``solver="auto"`` (lower is preferred), or None if "auto" never picks it.
    max_noise : float
        "auto" passes it over on images noisier than this (relative to the brightest value).
    min_outliers : float or None
        When given, "auto" takes it only for noisy images (:data:`NOISY`) whose share of outlying
        detail is at least this (:data:`OUTLIERS`): the solver for real photographs.
    options : tuple of Option
        Its own options (:class:`shadeform.registry.Option`: name, type, default, help), given as
        ``reconstruct(solver_options={...})`` or ``--option NAME=VALUE`` and read by the solver as
        ``problem.options[NAME]`` (every one present: the user's value or the default).
    """

    name: str
    solve: Callable[[Problem], Solution] | str
    description: str
    lights: str = "any"
    integrator: str | None = None
    depth: str = ""
    preview_pixels: int = 40_000
    denoise: str | None = None
    auto: int | None = None
    max_noise: float = math.inf
    min_outliers: float | None = None
    options: tuple[Option, ...] = ()

    def __post_init__(self):
        if not self.name.isidentifier() or self.name == AUTO:
            raise ValueError(
                f"solver name must be a Python identifier other than {AUTO!r}, got {self.name!r}"
            )
        if self.lights not in LIGHTS:
            raise ValueError(f"lights must be one of {LIGHTS}, got {self.lights!r}")
        if self.integrator is None and not self.depth:
            raise ValueError("a solver with no default integrator must say what makes its depth")
        object.__setattr__(self, "options", tuple(self.options))
        if not all(isinstance(option, Option) for option in self.options):
            raise ValueError("a solver's options must be shadeform.registry.Option records")

    def run(self, problem: Problem) -> Solution:
        """Solve ``problem`` (imports the solver's module the first time)."""
        return load(self.solve)(problem)

    def takes(self, light) -> bool:
        """Whether it takes ``light``: a (3,) direction, or None for a light to be estimated."""
        return self.lights == "any" or (light is not None and is_frontal(light))


#: The registered solvers (not "auto"), in registration order.
SOLVERS: Registry[Solver] = Registry("solver", Solver)


def register(solver: Solver) -> None:
    """Add (or replace) a solver: it is then available to ``reconstruct``, the CLI and the app."""
    SOLVERS.register(solver)


def solver_names() -> tuple[str, ...]:
    """The registered solvers' names, in registration order."""
    return SOLVERS.names()


def available_solvers() -> dict[str, str]:
    """The solvers ``reconstruct`` takes: ``"auto"`` and every registered one.

    Returns
    -------
    dict of str to str
        Solver name to a one-line description, "auto" first, then in registration order.
    """
    rule = ", else ".join(solver.name + _conditions(solver) for solver in _ranked())
    return {
        AUTO: f"picks the best measured solver: {rule}",
        **SOLVERS.descriptions(),
    }


def get_solver(name: str) -> Solver:
    """The registered solver called ``name`` (not "auto": see :func:`choose`)."""
    return SOLVERS.get(name)


def choose(light, *, noise: float = 0.0, outliers: float = 0.0) -> Solver:
    """The solver ``solver="auto"`` uses: the lowest ``auto`` rank that takes the light, the noise
    and the outlying detail.

    Parameters
    ----------
    light : (3,) float or None
        Unit direction toward the light; None for a light still to be estimated (only solvers for
        any light qualify).
    noise : float, keyword-only
        The image's noise over its brightest object pixel (:func:`shadeform.preprocess.noise_level`).
    outliers : float, keyword-only
        The image's share of outlying detail (:attr:`shadeform.preprocess.Detail.outliers`).

    Returns
    -------
    Solver
    """
    for solver in _ranked():
        photos_only = solver.min_outliers is not None
        if photos_only and not (noise > NOISY and outliers >= solver.min_outliers):
            continue
        if solver.takes(light) and noise <= solver.max_noise:
            return solver
    raise LookupError("no registered solver takes this light for solver='auto'")


def _ranked() -> list[Solver]:
    """The solvers "auto" may pick, best first."""
    return sorted((s for s in SOLVERS.entries() if s.auto is not None), key=lambda s: s.auto)


def _conditions(solver: Solver) -> str:
    """When "auto" takes ``solver``, in words: `` (light at the camera, clean image)``."""
    words = (
        (["light at the camera"] if solver.lights == "frontal" else [])
        + (["clean image"] if solver.max_noise < math.inf else [])
        + (
            ["photographs: noise with highlights, shadows or texture"]
            if solver.min_outliers is not None
            else []
        )
    )
    return f" ({', '.join(words)})" if words else ""


def is_frontal(light) -> bool:
    """Whether the light is at +z (to rounding)."""
    return bool(np.allclose(np.asarray(light, dtype=np.float64), (0.0, 0.0, 1.0), atol=1e-6))


# The built-in solvers. "auto" ranks and noise limits: the best measured on the synthetic scenes of
# benchmarks/results/methods.md and, for photographs, on the real photographs of
# benchmarks/results/real.md: "guided" (the photo energy held to the learned prior) is ahead of
# "photo" on both sets with both lights (DiLiGenT 18.5 against 25.7-26.2 degrees, MIT-Berkeley as
# taken 0.424 against 0.482 rad with the estimated light), and "photo" is far ahead of the others; both are
# behind "oblique" on noisy renders (ellipsoid at +z, 1 % noise: "photo" 7.3 against 1.5 degrees), which their Gaussian detail tells apart
# (OUTLIERS). Preview budgets: about
# 0.1 s of solver time on one core of the 2-core machine of benchmarks/results/app.md (the oblique descent costs ~50x more per pixel than
# fast marching on grids this small).
register(
    Solver(
        "propagation",
        "shadeform.solvers.propagation:solve",
        lights="any",
        integrator="paths",
        description="the 2002 ModelBuilder method: normals grown from the brightest pixel, convex "
        "unless marked, refined for integrability",
    )
)
register(
    Solver(
        "eikonal",
        "shadeform.solvers.eikonal:solve",
        lights="frontal",
        depth="eikonal (fast-marching depth)",
        auto=1,
        max_noise=NOISY,
        description="fast marching from the bright caps and marked dents (light at the camera only); "
        "the most accurate on clean images",
    )
)
register(
    Solver(
        "oblique",
        "shadeform.solvers.oblique:solve",
        lights="any",
        depth="oblique (chord-equation descent depth)",
        preview_pixels=2_500,
        denoise="gaussian:2",
        auto=2,
        description="any light, with attached shadows: marching from the brightest pixels, then descent",
    )
)
register(
    Solver(
        "photo",
        "shadeform.solvers.photo:solve",
        lights="any",
        depth="photo (robust energy over depth, coarse to fine)",
        preview_pixels=20_000,
        description="for real photographs (highlights, shadows, noise): the outline's shape refined "
        "by the shading it can trust",
    )
)
register(
    Solver(
        "learned",
        "shadeform.solvers.learned:solve_learned",
        lights="any",
        integrator="poisson",
        description="the learned shape prior alone: the object's shape as a network trained on "
        "generated photos reads it from the photo and its outline (no light needed)",
    )
)
register(
    Solver(
        "guided",
        "shadeform.solvers.learned:solve_guided",
        lights="any",
        depth="guided (the photo energy started from and held to the learned prior)",
        preview_pixels=20_000,
        auto=0,
        min_outliers=OUTLIERS,
        description="for real photographs: the learned prior's shape, refined by the shading it can trust",
    )
)


# the old name of available_solvers, for one release
__getattr__ = renamed_attributes(
    __name__, {"available_methods": ("available_solvers", lambda: available_solvers)}
)
