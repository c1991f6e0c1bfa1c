"""Pose refinement: the views' poses and depth offsets corrected so that what they share agrees.

Two things tie the views together. Every surface point a view recovered must project inside every
other view's silhouette (the visual hull's condition); and where two views see the same surface
squarely, their depths must agree there (registration of overlapping surfaces, point to plane as
in Chen & Medioni 1992: the depth difference along the other view's ray times that view's
``n_z``). Both are residuals of each view's correction, a small rotation and translation (for a
turntable, a turn about the vertical axis and a depth offset), found by Gauss-Newton with a
numerical Jacobian and Tukey's biweight on the residuals (a point another part hides from a view
must not pull). The first view fixes the frame.

References
----------
.. [1] Y. Chen, G. Medioni, "Object modelling by registration of multiple range images",
   Image and Vision Computing 10(3), 1992.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from shadeform.fusion.volume import FusionView

__all__ = ["refine_poses"]

# The constants below were set by hand, not swept; they were checked only on synthetic views
# (the closed objects of benchmarks/results/fusion.md and an analytic ellipsoid), never on photos.

#: Surface points per view used in the residuals.
SAMPLES = 1500
#: A view's own point counts only where it saw the surface this squarely (``n_z``).
TRUSTED_NZ = 0.3
#: Levenberg-Marquardt steps at most (raised from 12 after an ellipsoid with 9-degree pose errors
#: stopped short at 12 and converged, to 0.03 degrees, within 40).
STEPS = 40
#: Tukey's biweight constant, in units of the residuals' median absolute deviation.
TUKEY = 4.685


def refine_poses(views: list[FusionView], *, turntable: bool) -> list[FusionView]:
    """Correct every view but the first (module description).

    Parameters
    ----------
    views : list of FusionView
        Placed views, their offsets already roughly right.
    turntable : bool
        Views of a turntable: each is corrected by a turn about +y and a depth offset only (the
        first by its offset only).
        Otherwise by a small rotation (3) and translation (3).

    Returns
    -------
    list of FusionView
        The corrected views.
    """
    samples = [_samples(view) for view in views]
    # the silhouette lies half a pixel beyond the outermost object pixels' centres
    outside = [np.maximum(ndimage.distance_transform_edt(~view.mask) - 0.5, 0.0) for view in views]
    per_view = 2 if turntable else 6
    # a turntable's first view still has its depth offset to find (where its surface lies from
    # the axis); only its turn fixes the frame
    params = np.zeros(per_view * (len(views) - 1) + (1 if turntable else 0))

    def owner(k: int) -> int:
        """The view parameter ``k`` moves."""
        return 0 if k == per_view * (len(views) - 1) else 1 + k // per_view

    def residuals(params, base=None, moved_view=None):
        """All residual blocks (one per ordered pair of views); with ``base`` (the blocks at
        other parameters differing only in ``moved_view``'s), only the blocks of pairs that
        involve that view are recomputed."""
        placed = _corrected(views, params, turntable)
        return _residuals(placed, samples, outside, base=base, moved=moved_view)

    blocks = residuals(params)
    r = np.concatenate(blocks)
    scale = _scale(r)
    cost = _tukey_cost(r, scale)
    damping = 1e-3
    for _ in range(STEPS):
        weights = _tukey(r, scale)
        jacobian = np.empty((len(r), len(params)))
        for k in range(len(params)):
            rotation = k < per_view * (len(views) - 1) and (k % per_view) < (1 if turntable else 3)
            delta = 1e-3 if rotation else 1e-2
            moved = params.copy()
            moved[k] += delta
            jacobian[:, k] = (np.concatenate(residuals(moved, blocks, owner(k))) - r) / delta
        weighted = jacobian * weights[:, None]
        normal = weighted.T @ jacobian
        gradient = weighted.T @ r
        # Levenberg-Marquardt: a step is taken only if it lowers the robust cost
        for _ in range(8):
            step = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-9), -gradient)
            trial_blocks = residuals(params + step)
            trial = np.concatenate(trial_blocks)
            trial_cost = _tukey_cost(trial, scale)
            if trial_cost < cost:
                params, blocks, r, cost = params + step, trial_blocks, trial, trial_cost
                damping = max(damping / 3, 1e-7)
                break
            damping *= 4
        else:
            break
        if np.abs(step).max() < 1e-5:
            break
    return _corrected(views, params, turntable)


def _samples(view: FusionView) -> np.ndarray:
    """Pixels (row, col) of the view's trusted surface, evenly thinned to :data:`SAMPLES`."""
    trusted = view.mask & (np.nan_to_num(view.normals[..., 2]) > TRUSTED_NZ)
    rows, cols = np.nonzero(trusted)
    every = max(1, len(rows) // SAMPLES)
    return np.stack([rows[::every], cols[::every]], axis=1)


def _corrected(views, params, turntable) -> list[FusionView]:
    first = views[0]
    if turntable:
        first = first.at(first.rotation, first.translation, first.offset + params[-1])
    out = [first]
    per_view = 2 if turntable else 6
    for n, view in enumerate(views[1:]):
        p = params[per_view * n : per_view * (n + 1)]
        if turntable:
            turn = _rotation(np.array([0.0, p[0], 0.0]))
            out.append(view.at(turn @ view.rotation, view.translation, view.offset + p[1]))
        else:
            out.append(view.at(_rotation(p[:3]) @ view.rotation, view.translation + p[3:], view.offset))
    return out


def _rotation(omega: np.ndarray) -> np.ndarray:
    """Rodrigues: the rotation by ``|omega|`` radians about ``omega``."""
    angle = float(np.linalg.norm(omega))
    if angle < 1e-12:
        return np.eye(3)
    k = omega / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def _residuals(views, samples, outside, *, base=None, moved=None) -> list[np.ndarray]:
    """The residual blocks, one per ordered pair of views ``(u, v)``: ``u``'s points outside
    ``v``'s silhouette (distance, pixels) and, where ``v`` sees them squarely, their depth
    difference along ``v``'s ray times its ``n_z``. With ``base``, the blocks of pairs without
    view ``moved`` are taken from it."""
    blocks = []
    for u, (view, pixels) in enumerate(zip(views, samples)):
        rows, cols = pixels[:, 0], pixels[:, 1]
        points = view.surface_points(rows, cols)
        normals = view.normals[rows, cols] @ view.rotation  # into the object frame
        for v, other in enumerate(views):
            if v == u:
                continue
            if base is not None and moved not in (u, v):
                blocks.append(base[len(blocks)])
                continue
            seen = other.camera(points)
            r, c = other.pixels(seen)
            away = ndimage.map_coordinates(outside[v], [r, c], order=1, mode="nearest")
            facing = (normals @ other.rotation.T)[:, 2] > TRUSTED_NZ
            both = facing & other.inside(r, c) & (away == 0)
            nz = ndimage.map_coordinates(
                np.nan_to_num(other.normals[..., 2]), [r, c], order=1, mode="nearest"
            )
            gap = (seen[:, 2] - other.surface(r, c)) * np.clip(nz, 0.0, 1.0)
            blocks.append(np.concatenate([away, np.where(both, gap, 0.0)]))
    return blocks


def _scale(r: np.ndarray) -> float:
    """The residuals' robust spread: the median absolute deviation of those that are not 0 (a
    point inside a silhouette, or not seen by a view, has a residual of exactly 0), at least
    half a pixel."""
    active = np.abs(r[r != 0])
    return max(1.4826 * float(np.median(active)) if len(active) else 0.0, 0.5)


def _tukey_cost(r: np.ndarray, scale: float) -> float:
    """Tukey's biweight loss, summed."""
    c = TUKEY * scale
    u = np.minimum(np.abs(r) / c, 1.0)
    return float(np.sum(c * c / 6 * (1 - (1 - u * u) ** 3)))


def _tukey(r: np.ndarray, scale: float) -> np.ndarray:
    u = r / (TUKEY * scale)
    return np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
