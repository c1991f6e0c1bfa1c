"""Synthetic scenes with analytic ground truth.

Every accuracy bar of the project is measured on these scenes, so depth and normals are
evaluated from closed-form expressions at pixel centres (never by finite differences) and follow
``docs/conventions.md``: x = column, y = -row (here centred on the image), z toward the viewer,
unit normals ``n = (-dz/dx, -dz/dy, 1) / |.|``, NaN outside the mask.

Scenes (all images are ``size x size``; lengths below are fractions of ``size``):

========== =================================================================================
sphere     hemisphere of radius 0.42; mask is the disk.
ellipsoid  triaxial half ellipsoid, semi-axes a = 0.45 (x), b = 0.30 (y), c = 0.25 (z).
cylinder   half cylinder of radius 0.35 with its axis along y, |y| < 0.42.
vase       the synthetic vase of Zhang et al. (1999), 0.9 tall: z = sqrt(F(y)^2 - x^2).
bowl       concave spherical cap (sphere radius 0.42 / 0.9) over a disk of radius 0.42; the
           rim is not vertical (n_z = sqrt(0.19) ~ 0.436 there) and lies at z = 0.
saddle     z = (x^2 - y^2) / (2 s) over a disk of radius 0.42, s set so max |grad z| = 1.5.
bumps      four gaussian bumps and one dent on a flat base over the square |x|, |y| < 0.45.
========== =================================================================================

Closed objects (:data:`CLOSED_OBJECTS`, :func:`closed_object`, :func:`render_views`) are whole
bodies for multi-view fusion: implicit surfaces ``F(p) < 0`` inside, with analytic gradients, in
an object frame centred on the image centre, seen orthographically from turntable angles (the
object turned by ``t`` about +y: ``q = R_y(t) p``) or any 4x4 pose, with attached and cast
shadows. Every one lies within 0.40 of ``size`` of its centre, so it fits in every view:

========== =================================================================================
ellipsoid  triaxial ellipsoid, semi-axes 0.40 (x), 0.30 (y), 0.22 (z).
pebble     superellipsoid ``|x/a|^e + |y/b|^e + |z/c|^e = 1``, e = 2.6, a = 0.38 (x),
           b = 0.20 (y, flattened), c = 0.28 (z); radius at most 0.383.
waisted    two spheres of radius 0.22 centred at x = +-0.17, joined by a polynomial smooth
           minimum of their distances (blend width 0.08): a concave waist of radius ~0.169 at
           x = 0, seen from the front (angle 0); 0.78 long.
lumpy      sphere of radius 0.36 times ``1 + 0.1 h(u)``, h a sum of five spherical harmonics of
           degrees 2 and 3 in [-0.86, 0.98]: radius 0.329 to 0.395.
========== =================================================================================

The package's modules: ``scenes`` (the height-field scenes, their geometry and concave regions),
``shading`` (:func:`render` and :func:`chrome_sphere`), ``reliefs`` (frame-filling surfaces:
:func:`material_surface`, :func:`bump_relief`), ``closed`` (:class:`ClosedObject`, :class:`View`,
the turntable and :func:`render_views`), ``shapes`` (the closed objects' implicit functions,
gradients and volumes), ``rays`` (ray marching: :func:`first_crossing`, shadow rays, radii) and
``checks`` (argument checks they share).

References
----------
.. [1] R. Zhang, P.-S. Tsai, J. E. Cryer and M. Shah, "Shape from shading: a survey",
   IEEE Trans. PAMI 21(8), 690-706, 1999 (the synthetic vase).
"""

from __future__ import annotations

from shadeform.synth.closed import (
    TURNTABLE_ANGLES,
    ClosedObject,
    View,
    closed_object,
    render_views,
    turntable_pose,
)
from shadeform.synth.rays import first_crossing
from shadeform.synth.reliefs import bump_relief, material_surface
from shadeform.synth.scenes import SCENES, Scene, concave_regions, scene, surface
from shadeform.synth.shading import chrome_sphere, render
from shadeform.synth.shapes import CLOSED_OBJECTS

__all__ = [
    "CLOSED_OBJECTS",
    "SCENES",
    "TURNTABLE_ANGLES",
    "ClosedObject",
    "Scene",
    "View",
    "bump_relief",
    "chrome_sphere",
    "closed_object",
    "concave_regions",
    "first_crossing",
    "material_surface",
    "render",
    "render_views",
    "scene",
    "surface",
    "turntable_pose",
]
