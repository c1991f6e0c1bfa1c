"""TEMPORARY: the eikonal and oblique solvers' ``solve`` until their packages settle."""

from __future__ import annotations

import numpy as np

from shadeform.solvers import NOISY
from shadeform.solvers.problem import Problem, Solution


def solve_eikonal(problem: Problem) -> Solution:
    """Fast marching from the singular points (light at +z only); its own depth by default."""
    from shadeform.solvers.eikonal import eikonal_depth

    given = [ref.pixel for ref in problem.references[: problem.given]]
    result = eikonal_depth(problem.image, problem.mask, albedo=problem.albedo, references=given or None,
                           concave_x=problem.concave_x, concave_y=problem.concave_y)
    problem.lap("normals")
    depth = result.depth.copy()
    if problem.integrator is not None:
        first = result.singular_points[0]
        depth = problem.integrate(result.normals, origin=(first.row, first.col))
    problem.lap("depth")
    points = [{"row": p.row, "col": p.col, "kind": p.kind, "height": float(p.height)}
              for p in result.singular_points]
    return Solution(result.normals.copy(), depth, {"singular_points": points})


def solve_oblique(problem: Problem) -> Solution:
    """Any light: marching from the brightest pixels, shadow fill, descent; its own depth.
    On a noisy image the start and shadow levels move to twice the noise."""
    from shadeform.solvers.oblique import TOL, oblique_depth

    levels = {}
    relative = problem.noise / problem.albedo
    if relative > NOISY:
        levels = {"tol": max(TOL, 2 * relative), "dark": 2 * relative}
    result = oblique_depth(problem.image, problem.mask, light=problem.light, albedo=problem.albedo,
                           concave_x=problem.concave_x, concave_y=problem.concave_y, **levels)
    problem.lap("normals")
    depth = result.depth - result.depth[problem.main]
    if problem.integrator is not None:
        depth = problem.integrate(result.normals)
    problem.lap("depth")
    info = {"sources": len(result.info["sources"]), "levels": result.info["levels"],
            "sweeps": result.info["sweeps"], "shadowed": int(np.count_nonzero(problem.mask & ~result.lit))}
    return Solution(result.normals.copy(), depth, info)
