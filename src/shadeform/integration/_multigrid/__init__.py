"""Multigrid-preconditioned conjugate gradients for masked, weighted 5-point graph Laplacians: the
least-squares solver of :mod:`shadeform.integration.poisson` (one weight per pixel,
:class:`Hierarchy`), :mod:`shadeform.integration.bilateral` and :mod:`shadeform.solvers.oblique`
(one weight per pair, :class:`PairHierarchy`).

Modules, in the order the data flows:

``layout``
    The padded grids and their red-black order, which every kernel runs on.
``levels``
    Set-up: the multigrid levels (2x2 coarsening, coarsest pseudo-inverse) and connected parts.
``cycle``
    The preconditioner: one V-cycle of red-black Gauss-Seidel, restriction and prolongation.
``pcg``
    The conjugate gradients, one iteration for both kinds of weights.
``hierarchy``, ``pairs``
    The two problems: right-hand side from normals, solution to image.

``benchmarks/bench_poisson.py`` times it; what each tuned constant was chosen on is in
``benchmarks/results/poisson.md``.
"""

from shadeform.integration._multigrid.hierarchy import Hierarchy, weight_range
from shadeform.integration._multigrid.pairs import PairHierarchy

__all__ = ["Hierarchy", "PairHierarchy", "weight_range"]
