"""Shape from one real photograph: the outline's shape, refined by the shading it can trust.

Real photos break the uniform-Lambertian model pixel by pixel (highlights, cast shadows, painted
albedo, noise), so this solver does not march or propagate from single pixels. It finds the depth
``z`` (H, W) itself, integrable by construction, as the minimum of one energy over the object:

    E(z) = sum_p rho((f(n_p . L) - I_p) / a)                              shading, robust
         + mu  * sum_(p,q) (sqrt(eps^2 + |n_p - n_q|^2) - eps)            smooth, creases allowed
         + nu  * sum_(b on the outline) (n_b . m_b - 1)^2                 occluding contour

with ``n = (-dz/dx, -dz/dy, 1) / |.|`` (``docs/conventions.md``), ``rho`` Cauchy's loss of scale
:data:`SCALE` (a highlight, a shadow cast on a lit surface or a patch of other paint costs a
bounded amount, so they cannot drag the shape), ``(p, q)`` neighbouring object pixels and ``m_b``
the outline's outward normal: on an occluding contour the surface normal lies in the image plane,
perpendicular to the outline.

``f`` is the object's reflectance curve: the brightness of a pixel as a function of ``n . L``,
and ``a = f(1)`` the brightness of a pixel facing the light. Lambert's law makes it the straight
line ``a * max(0, n . L)``; real materials and cameras bend it (gloss brightens the pixels facing
the light, a rough or dusty surface flattens the falloff, interreflections lift the dark side),
and a straight line then reads the bend as shape. So ``f`` is estimated from the photo itself:
any non-decreasing curve, fitted to the current shape by isotonic regression of the median
brightness in ten bins of ``n . L`` (medians, so highlights and shadows do not set it), and
re-estimated :data:`ROUNDS` times per level (once on the finest of several), the shape solved
again after each. On a Lambertian render of the right shape the fit is the straight line; but a
shape and a curve can trade: from the silhouette's balloon the curve bends to fit the balloon (a
+z ellipsoid with 1 % noise comes out 7.3 degrees off, 0.8 with Lambert's line through the true
albedo), which is why "auto" keeps renders plus noise for the oblique solver. When the caller
gives the albedo (a reference normal with its brightness), the straight line
``albedo * max(0, n . L)`` is used as given.

The start is the shape of the silhouette alone: ``z = 2 sqrt(u)`` with ``laplacian(u) = -1``
inside the mask and ``u = 0`` just outside it (exact for a sphere; the image frame is not an
outline, so ``u`` has no condition there). The energy is minimised coarse to fine (2x2 pyramid
levels down to about :data:`COARSEST` object pixels) by L-BFGS over a hierarchical basis (the
depth is the sum of bilinearly upsampled grids of every coarser scale, Szeliski 1990), which
is what lets a descent move a whole region at once rather than a pixel at a time.

The shading is summed per pixel, the smoothness per pair and the contour per outline pixel, so
their balance moves with the number of pixels: with the same weights a small object is held
smoother than a large one. The coarsest level, which sets the global shape, is therefore
weighed as one continuous energy sampled at ``2 COARSEST`` object pixels (the middle of that
level's range): with ``h = sqrt(2 COARSEST / n)`` for its ``n`` object pixels, ``mu = MU / h``,
``eps = EPS * h``, ``nu = NU / h``, and every finer level keeps that ``h``, so the shading's share
grows 4x per level from the outline's shape to the shading's detail. (Rescaling the finer levels
too, or all levels to another reference, costs the real photos 0.7-2.7 degrees on MIT-Berkeley's
median: ``benchmarks/results/photo-experiments.md``.)

Concave regions the user marks (the app's "Mark concave", ``concave=``) dent the start
(:func:`concave_start`: what rises above the surface spanning a region's rim is mirrored below
it, along the region's axis), and where such a region meets the outline across its concave axis
the outline is a rim, not an occluding contour, so the contour term leaves it out. The descent
then refines the dent as it would the dome (the synthetic bowl with 1 % noise: depth error 63 %
without its region, 6-9 % with it at +z from 48 to 192 px; at light (5, 5, 7) 52-56 % without,
4.0-4.6 % with it from 48 to 192 px). Under an oblique light the dent is still fragile: with
another noise draw the 96 px bowl ends at 26 %, a shallower, tilted dish that has a lower energy
than the truth (the rim is not an occluding contour, so only the shading holds the walls against
the smoothness; ``benchmarks/results/photo-experiments.md``).

Limits. One light, orthographic camera, one reflectance curve for the whole object (painted
patches of other albedo are left to the robust loss); the
shape is biased toward the silhouette's (a balloon) where the shading is ambiguous, as under a
light at the camera, where a surface and its mirror image give the same picture: there the
concave regions settle it. References are not used beyond ``z = 0`` at the main reference.
Accuracy on real photographs with ground truth: ``benchmarks/results/real.md``.

The weights :data:`MU`, :data:`EPS`, :data:`NU` and :data:`SCALE` were set by hand on the
synthetic sphere and on one real object, MIT-Berkeley ``box``, which is also one of the 18
objects the benchmark reports (its figure there is not independent of that choice), before the
coarsest level was weighed at a fixed size (which leaves them as they were at ``2 COARSEST``
pixels); they were not swept over the benchmark.

References
----------
.. [1] J. T. Barron and J. Malik, "Shape, illumination, and reflectance from shading", IEEE
   TPAMI 37(8), 1670-1687, 2015 (depth as the unknown, contour prior, pyramid L-BFGS).
.. [2] M. K. Johnson and E. H. Adelson, "Shape estimation in natural illumination", CVPR 2011.
.. [3] R. Szeliski, "Fast surface interpolation using hierarchical basis functions", IEEE TPAMI
   12(6), 513-528, 1990.

Modules: :mod:`.solver` (:func:`photo_depth`, :func:`solve`: the coarse-to-fine descent),
:mod:`.energy` (the energy, its compiled kernel and its slow reference, one pyramid level's
operators), :mod:`.pyramid` (the pyramid levels, the hierarchical basis, the prior per level),
:mod:`.start` (the starting shapes: the silhouette's, the concave dents, the prior's) and
:mod:`.response` (the reflectance curve).
"""

from __future__ import annotations

from shadeform.solvers.photo.energy import EPS, MU, NU, SCALE
from shadeform.solvers.photo.response import BIN_PIXELS as BIN_PIXELS
from shadeform.solvers.photo.response import BINS as BINS
from shadeform.solvers.photo.response import response_curve
from shadeform.solvers.photo.solver import COARSEST, PhotoResult, photo_depth, solve
from shadeform.solvers.photo.solver import ITERATIONS as ITERATIONS
from shadeform.solvers.photo.solver import ROUNDS as ROUNDS
from shadeform.solvers.photo.start import concave_start, silhouette_depth

__all__ = [
    "COARSEST",
    "concave_start",
    "EPS",
    "MU",
    "NU",
    "SCALE",
    "PhotoResult",
    "photo_depth",
    "response_curve",
    "silhouette_depth",
    "solve",
]
