"""How well a fused model keeps the outlines it was given: its projection into each view against
the view's mask.

A fused model that does not cover a view's silhouette, or that reaches far outside it, is wrong
whatever else it scores (issue 35): the silhouettes are the one thing every view measures
directly. :func:`outline_iou` projects the model into each placed view and scores the overlap.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["OUTLINE_KEPT", "outline_iou", "projection"]

#: Below this IoU a view's outline is not kept (issue 35's bar; a user is warned).
OUTLINE_KEPT = 0.95

#: Surface samples per square pixel of the model's area (at most :data:`MAX_SAMPLES`): a face
#: turned edge-on still drops a sample on most pixels it covers, and a one-pixel closing fills
#: the rest.
DENSITY = 3.0
#: Most surface samples drawn for one projection.
MAX_SAMPLES = 2_000_000


def projection(mesh, view) -> np.ndarray:
    """The model's silhouette in a placed view (:class:`shadeform.fusion.volume.FusionView`):
    the pixels its surface falls on, closed over one pixel and holes filled, (H, W) bool."""
    return _projected(_samples(mesh), view)


def outline_iou(mesh, placement) -> list[float]:
    """Per view of a placement (:func:`shadeform.fusion.place`), the intersection over union of
    the fused model's projection (:func:`projection`) with the view's mask, in ``[0, 1]``.

    Parameters
    ----------
    mesh : shadeform.Mesh
        The fused model (:func:`shadeform.fusion.solid`), in the placement's object frame.
    placement : shadeform.fusion.Placement

    Returns
    -------
    list of float
    """
    points = _samples(mesh)  # once for every view
    out = []
    for view in placement.views:
        shown = _projected(points, view)
        union = np.count_nonzero(shown | view.mask)
        out.append(float(np.count_nonzero(shown & view.mask) / union) if union else 1.0)
    return out


def _samples(mesh) -> np.ndarray:
    """Points spread uniformly over the model's surface, :data:`DENSITY` per square pixel, (N, 3)."""
    import trimesh

    surface = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False)
    count = int(min(MAX_SAMPLES, max(1000, DENSITY * surface.area)))
    points, _ = trimesh.sample.sample_surface(surface, count, seed=0)
    return points


def _projected(points: np.ndarray, view) -> np.ndarray:
    rows, cols = view.pixels(view.camera(points))
    r, c = np.rint(rows).astype(np.int64), np.rint(cols).astype(np.int64)
    shape = view.mask.shape
    keep = (r >= 0) & (r < shape[0]) & (c >= 0) & (c < shape[1])
    hit = np.zeros(shape, bool)
    hit[r[keep], c[keep]] = True
    return ndimage.binary_fill_holes(ndimage.binary_closing(hit, np.ones((3, 3), bool)))
