"""True views of the closed synthetic objects and the scores of a fused mesh against them, shared
by the fusion tests."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

import shadeform
from shadeform import metrics, synth
from shadeform.reconstruction import Reconstruction

SMALL = 128  # tests of other properties: an eighth of the voxels


def true_views(name, angles, *, size=SMALL, poses=None, seed=0):
    """Each view's true depth and normals, every depth shifted by an unknown offset."""
    rng = np.random.default_rng(seed)
    views = synth.render_views(name, angles, size=size, poses=poses)
    return [
        Reconstruction(
            normals=np.array(view.normals),
            depth=np.array(view.depth) + rng.uniform(-40, 40),
            mask=np.array(view.mask),
            light=np.array([0.0, 0.0, 1.0]),
            albedo=1.0,
        )
        for view in views
    ]


def photographed(name, angles, *, size=SMALL):
    """Each view rendered (``synth.render_views``) and solved alone with the light at the camera,
    and a ``resolve(i, regions)`` that solves view ``i`` again with concave regions, as
    :func:`shadeform.fusion.place` asks. Cached per view: several tests place the same photos
    (run them in one worker: ``pytest.mark.xdist_group``)."""
    solved = [_photographed(name, float(angle), size) for angle in angles]

    def resolve(i, regions):
        key = (
            name,
            float(angles[i]),
            size,
            tuple((r.axis, np.asarray(r.polygon).tobytes()) for r in regions),
        )
        if key not in _RESOLVED:
            view, _ = _photographed(*key[:3])
            _RESOLVED[key] = shadeform.reconstruct(
                view.image, mask=view.mask, light=(0, 0, 1), concave=regions
            )
        return _RESOLVED[key]

    return [view for view, _ in solved], [rec for _, rec in solved], resolve


@lru_cache(maxsize=32)
def _photographed(name, angle, size):
    (view,) = synth.render_views(name, (angle,), size=size)
    return view, shadeform.reconstruct(view.image, mask=view.mask, light=(0, 0, 1))


_RESOLVED = {}  # (name, angle, size, regions) -> the view solved again with those regions


@lru_cache(maxsize=8)
def fused_truth(name, angles, *, size=SMALL):
    """The fusion of the true views at ``angles`` (``true_views``' offsets) and its :func:`scores`."""
    mesh = shadeform.fuse(list(zip(true_views(name, angles, size=size), angles)))
    return mesh, scores(mesh, name, size=size)


def scores(mesh, name, size=SMALL):
    """Chamfer (%), F-score (%), |volume error| (%), closed: 50,000 points on the mesh against
    200,000 on the true surface."""
    points, volume = _truth(name, size)
    got = metrics.surface_scores(mesh, points, volume)
    return got["chamfer"], got["f_score"], abs(got["volume_error"]), got["watertight"]


@lru_cache(maxsize=8)
def _truth(name, size):
    """The true surface's points and volume: the same for every mesh scored against it."""
    truth = synth.closed_object(name, size=size)
    points = truth.surface_points(200_000, seed=1)[0]
    points.setflags(write=False)
    return points, truth.volume
