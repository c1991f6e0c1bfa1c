"""Shape from shading for any light direction, with attached shadows.

With a distant light ``L`` and the Lambertian model ``I = albedo max(0, N . L)`` (``albedo`` for
the ``k * albedo`` of the report) every lit pixel's normal lies on a cone around ``L`` of
half-angle ``acos(I / albedo)``: one unknown per pixel, the azimuth of the normal around ``L``
(:mod:`._cone`). Shadowed pixels (``I / albedo <= dark``) only say ``N . L <= 0``. The solver,
:func:`oblique_depth` (:mod:`.solver`),

1. **marches** over the lit pixels from the brightest ones, the caps of ``N = L`` (the singular
   points [4]_; :mod:`.caps`), each pixel taking the cone normal and height that best fit its
   accepted neighbours under the chord equation ``(n + n_b) . (X_b - X) = 0``, with a
   convexity tie-break and a hinge on turns against the convexity, both flipped inside the user's
   concave regions, in the spirit of Bichsel and Pentland's height-ordered local solves [1]_
   (:mod:`.march`);
2. **fills the shadows**: the normals of shadowed pixels continue those of the lit ones with the
   least change of curvature, then are moved to ``N . L <= 0`` [3]_ (:mod:`.shadow`);
3. **polishes** depth and cone azimuths together by block-coordinate descent on the chord
   equations over 4-neighbour pairs plus a small smoothness term, alternating a pair-weighted
   Poisson solve for the depth [5]_ with red-black sweeps over the cones [2]_ (:mod:`.descent`).

A large object is first solved at half size, recursively, and the full-size descent starts from
that solution (coarse to fine [6]_). Depth is in pixel units, ``z = 0`` at the main source (the
brightest pixel); normals of lit pixels lie exactly on their cones (``N . L = I / albedo``).

The constants were set by hand on the synthetic scenes of ``benchmarks/bench_oblique.py`` (each
says on which); its results, and the measurements behind the choices, are in
``benchmarks/results/oblique.md``.

Limits. Uniform albedo, one distant light, no cast shadows, no interreflections. The marching
decides the convex/concave choice once; the polish only refines within that basin, so the
convexity it assumes (convex unless marked) must hold where it decides: on unmarked concave parts
(the bumps' skirts) the hinge can push the wrong way. Where two singular points are joined by a
ridge of nearly full brightness (the synthetic vase's belly and neck under the light (5, 5, 7)),
marching nearest-first reaches the part above the saddle from the side, in the wrong basin; the
brightness term of the marching order and the hinge are there for it, and it remains the vase's
largest error. Noisy images need a filter
(``reconstruct(filter="gaussian:2")``) and a larger ``tol``.

:func:`march_cone` and :func:`cone_sweep` are the compiled kernels; :func:`march_cone_reference`
and :func:`cone_sweep_reference` are slow, plain-Python transcriptions kept for the tests.

References
----------
.. [1] M. Bichsel and A. P. Pentland, "A simple algorithm for shape from shading", CVPR 1992.
.. [2] B. K. P. Horn and M. J. Brooks, "The variational approach to shape from shading",
   CVGIP 33(2), 174-208, 1986 (integrability and normals as alternating unknowns).
.. [3] K. Ikeuchi and B. K. P. Horn, "Numerical shape from shading and occluding boundaries",
   Artificial Intelligence 17, 141-184, 1981 (smoothness of the normal field).
.. [4] E. Prados and O. Faugeras, "Shape from shading: a well-posed problem?", CVPR 2005
   (oblique light, singular points).
.. [5] Y. Queau, J.-D. Durou and J.-F. Aujol, "Normal integration: a survey", JMIV 60, 2018.
.. [6] B. K. P. Horn, "Height and gradient from shading", IJCV 5(1), 37-75, 1990 (coarse-to-fine
   start of the iterative scheme).
"""

from __future__ import annotations

from shadeform.solvers.oblique._cone import VISIBLE_NZ
from shadeform.solvers.oblique.caps import TOL
from shadeform.solvers.oblique.descent import (
    ITERATIONS,
    REBUILD,
    SHADOW_WEIGHT,
    SMOOTH,
    STOP,
    SWEEP_SAMPLES,
    cone_sweep,
    cone_sweep_reference,
)
from shadeform.solvers.oblique.march import (
    BRIGHTNESS,
    CONTINUITY,
    CONVEXITY,
    HINGE,
    SAMPLES,
    march_cone,
    march_cone_reference,
)
from shadeform.solvers.oblique.shadow import SHADOW_NZ, fill_shadow_normals
from shadeform.solvers.oblique.solver import COARSE, REFINE_ITERATIONS, ObliqueResult, oblique_depth, solve

__all__ = [
    "BRIGHTNESS",
    "COARSE",
    "CONTINUITY",
    "CONVEXITY",
    "HINGE",
    "ITERATIONS",
    "REBUILD",
    "REFINE_ITERATIONS",
    "SAMPLES",
    "SHADOW_NZ",
    "SHADOW_WEIGHT",
    "SMOOTH",
    "STOP",
    "SWEEP_SAMPLES",
    "TOL",
    "VISIBLE_NZ",
    "ObliqueResult",
    "cone_sweep",
    "cone_sweep_reference",
    "fill_shadow_normals",
    "march_cone",
    "march_cone_reference",
    "oblique_depth",
    "solve",
]
