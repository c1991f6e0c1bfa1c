"""Eikonal shape from shading for a light at +z: fast marching from the singular points.

With the light behind the camera (``L = (0, 0, 1)``) the image model ``I = k (N . L)`` reads
``c = I / k = n_z = 1 / sqrt(1 + |grad z|^2)``, so the height obeys the eikonal equation

    |grad z| = f,   f = sqrt(1 / c^2 - 1).

The equation fixes how steep the surface is, not which way it goes. Its solutions are built from
the **singular points**, where ``c = 1`` and the surface is level: local maxima, minima and saddles
of ``z`` (Oliensis, 1991). If ``T_a`` is the weighted distance from the singular point ``a``
(``|grad T_a| = f``, ``T_a = 0`` at ``a``; the geodesic distance in the metric ``f``), then for
every pixel ``x`` and every singular point ``a`` of height ``z_a``

    z_a - T_a(x) <= z(x) <= z_a + T_a(x),

with equality on the left when ``x`` lies on a path of steepest descent from ``a`` and on the
right when it lies on a path of steepest ascent from ``a``. Hence (Dupuis & Oliensis, 1994;
Kimmel & Sethian, 2001, march from the minima)

* ``L(x) = max_a (z_a - T_a(x))`` is exact wherever the steepest ascent from ``x`` ends in a
  singular point (every pixel of a convex object: ascent ends at its top);
* ``U(x) = min_a (z_a + T_a(x))`` is exact wherever the steepest descent from ``x`` ends in one
  (every pixel of a bowl: descent ends at its bottom).

The solver, :func:`eikonal_depth`,

1. finds the singular regions (bright caps), gives each its kind from the user's concave masks
   and adds the user's references (:mod:`~shadeform.solvers.eikonal.singular`);
2. fixes their heights from the weighted distances between them, with ``z = 0`` at each part's
   main singular point (:mod:`~shadeform.solvers.eikonal.singular`);
3. takes ``U`` where the singular point nearest in the metric ``f`` is a minimum and ``L``
   everywhere else (:mod:`~shadeform.solvers.eikonal.depth`); each ``T`` comes from fast marching
   (:mod:`~shadeform.solvers.eikonal.marching`, :func:`arrival_times`);
4. returns the normals on each pixel's shading cone (``n_z = c`` exactly) with the tilt of the
   depth's gradient (:mod:`~shadeform.solvers.eikonal.normals`, :func:`cone_normals`).

Unmarked, all singular points are maxima and each rises as high as the placed ones allow: bumps
on a plate come out as bumps (and an unmarked dent as one more).

Limits. Uniform albedo, the light at +z, no cast shadows. What the singular points and the
user's marks do not decide, no marching can: a surface whose slopes run out through the image
border on both sides (the synthetic saddle, whose image is also that of a dome) needs heights on
that border, and a neck left unmarked is read as a hill top. ``tol`` must exceed what noise does
to the brightest pixels: filter noisy images and raise it (see :data:`TOL`). Accuracy and speed
on the synthetic scenes: ``benchmarks/results/eikonal.md``.

References
----------
.. [1] J. Oliensis, "Uniqueness in shape from shading", IJCV 6(2), 75-104, 1991.
.. [2] P. Dupuis and J. Oliensis, "An optimal control formulation and related numerical methods
   for a problem in shape reconstruction", Ann. Appl. Probab. 4(2), 287-346, 1994.
.. [3] R. Kimmel and J. A. Sethian, "Optimal algorithm for shape from shading and path
   planning", J. Math. Imaging Vis. 14(3), 237-244, 2001.
.. [4] J. A. Sethian, "A fast marching level set method for monotonically advancing fronts",
   PNAS 93(4), 1591-1595, 1996.
"""

from shadeform.solvers.eikonal.depth import EikonalResult, eikonal_depth, solve
from shadeform.solvers.eikonal.marching import COS_FLOOR, STEEP, arrival_times, arrival_times_reference
from shadeform.solvers.eikonal.normals import cone_normals, cone_normals_reference
from shadeform.solvers.eikonal.singular import KINDS, MAX_DETECTED, SOURCE_FRACTION, TOL, SingularPoint

__all__ = [
    "COS_FLOOR",
    "KINDS",
    "MAX_DETECTED",
    "SOURCE_FRACTION",
    "STEEP",
    "TOL",
    "EikonalResult",
    "SingularPoint",
    "arrival_times",
    "arrival_times_reference",
    "cone_normals",
    "cone_normals_reference",
    "eikonal_depth",
    "solve",
]
