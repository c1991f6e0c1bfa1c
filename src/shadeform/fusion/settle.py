"""Settle what one photo cannot: convex or concave, decided by the other views' silhouettes.

Under a light from the camera a bright spot is a bump, a dimple or a saddle alike, and the
single-photo solvers take it convex; each view reports the areas whose convexity its photo leaves
open (``Reconstruction.info["unsure"]``, :func:`shadeform.confidence.assess`). A wrong guess can
move more than its area: an unmarked waist between two lobes is read as a third hill top, and
one lobe comes out tens of pixels too deep. The other views see that. Their silhouettes bound
the object (the visual hull) and the surface touches the hull along their contour generators, so
of a view's readings the right one lies closest under the hull's front. :func:`settle` (run by
:func:`shadeform.fusion.place` when it is given a way to solve a view again) re-solves each view
with each combination of its largest unsure areas marked concave and keeps the reading whose
surface lies closest under the hull (the median gap, after the view is moved forward until it
touches, as :func:`shadeform.fusion.volume.view_offsets` moves it); a reading must be closer by
more than a voxel to replace the photo's own guess, so where the silhouettes cannot tell (a
dimple no outline sees) the guess stays.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from shadeform.fusion.volume import TOUCH_PERCENTILE, FusionView, Grid, crossed, hull_depth, hull_gaps
from shadeform.regions import Region

__all__ = ["MAX_AREAS", "settle"]

#: At most this many unsure areas of a view (the largest) are tried: 2**3 readings per view. A
#: bound on the work (each reading is a solve), not a measurement.
MAX_AREAS = 3


def settle(
    views: list[FusionView],
    grid: Grid,
    inside: np.ndarray,
    readings: list,
    resolve: Callable[[int, list[Region]], object],
) -> tuple[list, tuple[tuple[dict, ...], ...]]:
    """Each view's unsure areas read as concave where the other views' silhouettes say so.

    Parameters
    ----------
    views : list of FusionView
        The views, placed (:func:`shadeform.fusion.place` before its settling).
    grid : Grid
        Voxels over their visual hull.
    inside : (grid.shape) bool
        The visual hull on the grid (:func:`shadeform.fusion.volume.hull`).
    readings : list of Reconstruction
        Each view's reconstruction (its ``info["unsure"]`` lists the areas to try).
    resolve : callable
        ``resolve(i, regions)`` solves view ``i`` again with ``regions`` (a list of
        :class:`shadeform.regions.Region`) marked concave in addition to any the user drew, and
        returns its :class:`~shadeform.Reconstruction`.

    Returns
    -------
    readings : list of Reconstruction
        Per view, the reading whose surface lies closest under the hull's front.
    concave : tuple of tuple of dict
        Per view, the unsure areas (``info["unsure"]`` entries) it now reads as concave.
    """
    kept, concave = [], []
    for i, (view, rec) in enumerate(zip(views, readings)):
        best, marked = rec, ()
        areas = list((rec.info or {}).get("unsure") or [])[:MAX_AREAS]
        if areas and crossed(view, [other for other in views if other is not view]):
            front = hull_depth(view, grid, inside)
            best_gap = _gap(rec, front)
            for chosen, regions in _alternatives(rec):
                other = resolve(i, regions)
                gap = _gap(other, front)
                # a reading must be closer by more than a voxel, which the hull cannot resolve
                if gap < best_gap - grid.spacing:
                    best, best_gap, marked = other, gap, chosen
        kept.append(best)
        concave.append(tuple(marked))
    return kept, tuple(concave)


def _alternatives(rec) -> list[tuple[tuple[dict, ...], list[Region]]]:
    """The other readings of a view to try: every combination of its largest :data:`MAX_AREAS`
    unsure areas, each as the areas (``info["unsure"]`` entries) and the concave regions."""
    areas = list((rec.info or {}).get("unsure") or [])[:MAX_AREAS]
    return [
        (chosen, [Region(np.asarray(area["polygon"], float), area["axis"]) for area in chosen])
        for count in range(1, len(areas) + 1)
        for chosen in itertools.combinations(areas, count)
    ]


def _gap(rec, front: np.ndarray) -> float:
    """The median gap between a reading's surface and the hull's front over the pixels that
    face the camera, once the surface is moved forward until it touches (as
    :func:`shadeform.fusion.volume.view_offsets` moves it); NaN where the hull says nothing."""
    gap = hull_gaps(front, rec.depth, np.asarray(rec.mask, bool), np.asarray(rec.normals))
    if not len(gap):
        return float("nan")
    return float(np.median(gap) - np.percentile(gap, TOUCH_PERCENTILE))
