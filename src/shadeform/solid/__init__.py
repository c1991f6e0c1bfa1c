"""Print-ready reliefs: a depth map as a closed solid in millimetres (STL, 3MF).

:func:`relief` turns a reconstruction (or any depth map) into a watertight, outward-oriented solid
a slicer can print: the recovered surface on top, vertical walls along the object's outline (or
the image frame), a flat base. Its size is given in millimetres: the outline's longest side,
the relief's depth from its lowest to its highest point, the base's thickness.

How the solid is built (all on the pixel grid, so it is closed by construction):

1. The depth is scaled to ``[0, height_mm]``, optionally compressed first (bas-relief,
   :func:`compress_depth`), inverted (engraving) and surrounded by a flat rim (``border_mm``).
2. The top: two triangles per grid cell whose four corners are on the object
   (:func:`shadeform.mesh.cell_triangles`); cells that touch another only at a corner are
   dropped, so every boundary vertex has one edge in and one out (no pinched vertex).
3. The walls: one vertical quad below every boundary edge of the top, down to ``z = 0``; the
   base: the top's cells again at ``z = 0``, wound the other way. Every edge is then shared by
   exactly two triangles, wound consistently, facing out.
4. With a triangle budget, the height field is first sampled every ``k`` pixels so that the
   grid's top has about :data:`OVERSAMPLE` times the
   budget; the top is simplified by quadric edge collapses (Garland & Heckbert 1997, via
   ``fast-simplification``) with its boundary kept, the base is the outline's loops triangulated
   (manifold3d), and the walls join the two along the unchanged boundary. The simplified top is
   accepted only if it still projects onto the plane without a fold or an overlap (every triangle
   turning counter-clockwise, their areas summing to the outline's): then the solid cannot
   intersect itself. Otherwise a coarser grid is tried. ``Relief.deviation_mm`` reports how far
   the printed top lies from the full-resolution relief.

References
----------
.. [1] T. Weyrich, J. Deng, C. Barnes, S. Rusinkiewicz, A. Finkelstein, "Digital bas-relief from
   3D scenes", ACM Transactions on Graphics 26(3), 32, 2007 (SIGGRAPH).
.. [2] J. Kerber, A. Tevs, A. Belyaev, R. Zayer, H.-P. Seidel, "Feature sensitive bas relief
   generation", IEEE Shape Modeling and Applications (SMI), 148-154, 2009.
.. [3] R. Fattal, D. Lischinski, M. Werman, "Gradient domain high dynamic range compression",
   ACM Transactions on Graphics 21(3), 249-256, 2002 (SIGGRAPH).
.. [4] M. Garland, P. S. Heckbert, "Surface simplification using quadric error metrics",
   SIGGRAPH 1997, 209-216.

Modules
-------
``options``
    Units, sizes and options: :func:`check_options`, :func:`grid_step`, the ``print`` extra.
``compress``
    :func:`compress_depth`, the bas-relief compression.
``build``
    :class:`Relief` and :func:`relief`: the depth scaled, the rim, the solid on the finest grid
    that fits, its height fitted and its deviation measured.
``grid``
    The grid solid: the height field sampled, the top's cells, walls and base, the budget.
``checks``
    The checks that a simplified top covers its outline once, and its open edges.
``distance``
    The compiled distances from the pixels to the printed top (numba, imported on first use).
"""

from shadeform.solid.build import Relief, relief
from shadeform.solid.compress import compress_depth
from shadeform.solid.options import (
    MIN_TRIANGLES,
    MIN_WALL_MM,
    OUTLINES,
    OVERSAMPLE,
    SIZE_RANGE_MM,
    check_options,
    grid_step,
)

__all__ = [
    "MIN_TRIANGLES",
    "MIN_WALL_MM",
    "OUTLINES",
    "OVERSAMPLE",
    "SIZE_RANGE_MM",
    "Relief",
    "check_options",
    "compress_depth",
    "grid_step",
    "relief",
]
