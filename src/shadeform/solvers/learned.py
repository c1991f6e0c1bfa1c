"""Solvers that use the learned shape prior (:mod:`shadeform.prior`).

``learned``
    The network alone: its normals, integrated. It reads the object's shape from the photo as it
    was taken (paint, print and gloss left in) and its outline, and needs no light.
``guided``
    The photo solver (:mod:`shadeform.solvers.photo`) started from the network's shape and held to
    its normals where the network is sure (``w_p = PRIOR * median(s) / s_p`` for its error scale
    ``s``), so that the shading adds what it can measure (fine relief, dents) and cannot bend the
    whole into a sheet or a spike.

Regions the user marks concave overrule the network: its shape is dented there
(:func:`shadeform.solvers.photo.concave_start`) and, in ``guided``, its normals hold nothing there.
"""

from __future__ import annotations

import numpy as np

from shadeform.metrics import normals_of_height
from shadeform.solvers import photo
from shadeform.solvers.photo import concave_start
from shadeform.solvers.problem import Problem, Solution

__all__ = ["PRIOR", "solve_guided", "solve_learned"]

#: Weight of the prior's term per pixel of median certainty in ``guided``, against the shading's
#: Cauchy term (``0.5 r^2`` for a small residual ``r`` of ``N . L``). Chosen on generated photos of
#: a held-out seed (``benchmarks/bench_prior.py --weights``), never on a benchmark's photos.
PRIOR = 1.0


def _prior(problem: Problem):
    from shadeform.prior import predict

    return predict(problem.image, problem.mask)


def solve_learned(problem: Problem) -> Solution:
    """The registry's ``learned`` entry: the network's normals, integrated by the problem's
    integrator (``z = 0`` at the main reference)."""
    prior = _prior(problem)
    problem.lap("network")
    normals = np.where(problem.mask[..., None], prior.normals, 0.0)
    depth = problem.integrate(normals)
    marked = problem.concave_x | problem.concave_y
    if marked.any():
        base = np.where(problem.mask, depth - np.nanmin(depth), 0.0)
        depth = np.where(problem.mask, concave_start(base, problem.concave_x, problem.concave_y), np.nan)
        normals = _normals_of(depth, problem.mask, normals)
    problem.lap("integrate")
    info = {"prior_spread": round(float(np.nanmedian(prior.spread)), 4)}
    return Solution(normals, depth - depth[problem.main], info)


def solve_guided(problem: Problem) -> Solution:
    """The registry's ``guided`` entry: the photo solver with the network's shape as its start and
    prior (depth with ``z = 0`` at the main reference)."""
    prior = _prior(problem)
    problem.lap("network")
    spread = prior.spread[problem.mask]
    weight = np.where(
        problem.mask, PRIOR * np.median(spread) / np.maximum(np.nan_to_num(prior.spread), 1e-3), 0.0
    )
    solution = photo.solve(problem, prior=(np.nan_to_num(prior.normals), weight))
    solution.info["prior_spread"] = round(float(np.median(spread)), 4)
    return solution


def _normals_of(depth, mask, fallback):
    """Unit normals of a depth map, ``fallback`` where a neighbour is off the object."""
    normals = normals_of_height(np.where(mask, depth, np.nan))
    return np.where(np.isfinite(normals).all(axis=-1, keepdims=True), normals, fallback)
