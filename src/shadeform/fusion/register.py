"""Pose refinement: the views' poses and depth offsets corrected so that what they share agrees.

Two things tie the views together. Every surface point a view recovered must project inside every
other view's silhouette (the visual hull's condition); and where two views see the same surface
squarely, their depths must agree there (registration of overlapping surfaces, point to plane as
in Chen & Medioni 1992: the depth difference along the other view's ray times that view's
``n_z``). Both are residuals of each view's correction, a small rotation and translation (for a
turntable, a turn about the vertical axis and a depth offset), found by Levenberg-Marquardt with
Tukey's biweight on the residuals (a point another part hides from a view must not pull), its
scale re-estimated at every step as the views come together (iteratively reweighted least
squares). The Jacobian is analytic and, as ICP linearises it, holds each pair's tangent planes
fixed: a point crossing a depth edge of the other view must not make a jump in it. Only the
surface whose depth a view's photo fixes takes part, its own points and its planes
(:func:`shadeform.fusion.volume.trusted_surface`: not what lies beyond its own occluding
contours). The first view fixes the frame.

References
----------
.. [1] Y. Chen, G. Medioni, "Object modelling by registration of multiple range images",
   Image and Vision Computing 10(3), 1992.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from shadeform.fusion.volume import FusionView

__all__ = ["disagreement", "refine_poses"]

# The constants below were set by hand, not swept; they were checked only on synthetic views
# (the closed objects of benchmarks/results/fusion.md and an analytic ellipsoid), never on photos.

#: Surface points per view used in the residuals.
SAMPLES = 1500
#: A view's own point counts only where it saw the surface this squarely (``n_z``).
TRUSTED_NZ = 0.3
#: Levenberg-Marquardt steps at most.
STEPS = 40
#: The refinement stops when a step moves no surface point by more than this many pixels.
SETTLED = 0.01
#: The smallest robust scale of the residuals, in pixels (half a pixel: finer is noise).
MIN_SCALE = 0.5
#: Tukey's biweight constant, in units of the residuals' median absolute deviation.
TUKEY = 4.685


def refine_poses(views: list[FusionView], *, turntable: bool, samples: int = SAMPLES) -> list[FusionView]:
    """Correct every view but the first (module description).

    Parameters
    ----------
    views : list of FusionView
        Placed views, their offsets already roughly right.
    turntable : bool
        Views of a turntable: each is corrected by a turn about +y and a depth offset only (the
        first by its offset only).
        Otherwise by a small rotation (3) and translation (3).
    samples : int
        Surface points per view in the residuals.

    Returns
    -------
    list of FusionView
        The corrected views.
    """
    fit = _Fit(views, turntable, samples)
    per_view = fit.per_view
    # the first view's turn (a turntable) or whole pose fixes the frame; a turntable's first view
    # still has its depth offset to find (where its surface lies from the axis)
    free = np.ones(per_view * len(views), bool)
    free[: 1 if turntable else per_view] = False
    rotation = np.tile(np.arange(per_view) < (1 if turntable else 3), len(views))[free]
    # how far a unit step moves a surface point at most, in pixels: a turn by the image's
    # half-diagonal, a shift by one
    reach = np.where(rotation, 0.5 * float(np.hypot(*views[0].mask.shape)), 1.0)
    r, jacobian = fit.residuals(views, jacobian=True)
    damping = 1e-3
    for _ in range(STEPS):
        scale = _scale(r)
        cost = _tukey_cost(r, scale)
        weighted = jacobian[:, free] * _tukey(r, scale)[:, None]
        normal = weighted.T @ jacobian[:, free]
        gradient = weighted.T @ r
        # Levenberg-Marquardt: a step is taken only if it lowers the robust cost
        for _ in range(8):
            step = np.zeros(len(free))
            step[free] = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-9), -gradient)
            trial = fit.moved(views, step)
            trial_r = fit.residuals(trial)
            if _tukey_cost(trial_r, scale) < cost:
                views = trial
                damping = max(damping / 3, 1e-7)
                break
            damping *= 4
        else:
            break
        if np.abs(step[free] * reach).max() < SETTLED:
            break
        r, jacobian = fit.residuals(views, jacobian=True)
    return views


def disagreement(
    views: list[FusionView],
    *,
    turntable: bool,
    scale: float | None = None,
    samples: int = SAMPLES,
    every_piece: bool = False,
) -> tuple[float, float]:
    """How much placed views disagree: the mean Tukey loss of their residuals (the refinement's
    own, :meth:`_Fit.residuals`) at ``scale``, for comparing placements of the same views.

    A point lying behind another view's surface by more than Tukey's cut-off is hidden from that
    view (a lobe behind a lobe) and has no depth there to disagree with: it is not counted. The
    refinement gives such points no weight; counted here, each would add the loss's ceiling and
    favour placements that happen to hide fewer points. A point in front of the other view's
    surface is counted: that view would have seen it.

    Parameters
    ----------
    views : list of FusionView
        Placed views.
    turntable : bool
        As for :func:`refine_poses` (the residuals are the same either way).
    scale : float, optional
        The residuals' robust scale, pixels; default: theirs (:func:`_scale`). Give the same
        scale to every placement being compared.
    samples : int
        Surface points per view in the residuals.
    every_piece : bool
        Count the views' whole facing surface, also what lies beyond their own occluding
        contours (not trusted by the refinement: its depth may be off by tens of pixels, which
        the loss's ceiling bounds; where it is right, it tells placements apart).

    Returns
    -------
    loss : float
        The mean loss per counted residual.
    scale : float
        The scale used.
    """
    fit = _Fit(views, turntable, samples, every_piece=every_piece)
    r = fit.residuals(views)
    if scale is None:
        scale = _scale(r)
    counted = ~(fit.depth_rows() & (r < -TUKEY * scale))
    return _tukey_cost(r[counted], scale) / max(int(counted.sum()), 1), scale


class _Fit:
    """The residuals of a set of views and their Jacobian with respect to each view's correction
    (per view ``(turn, offset)`` on a turntable, else ``(omega, shift)``: ``R <- Rot(omega) R``,
    ``t <- t + shift``), taken at no correction."""

    def __init__(
        self, views: list[FusionView], turntable: bool, samples: int = SAMPLES, *, every_piece: bool = False
    ) -> None:
        self.turntable = turntable
        self.per_view = 2 if turntable else 6
        self.samples = [_samples(view, samples, every_piece=every_piece) for view in views]
        # each view's normals as three images, NaN-free, for the bilinear lookups; 0 where its
        # depth is not trusted (beyond its own occluding contours): no plane to agree with there
        self.normals = [
            np.moveaxis(np.nan_to_num(view.normals) * (every_piece | view.trusted[..., None]), -1, 0).copy()
            for view in views
        ]
        # the silhouette lies half a pixel beyond the outermost object pixels' centres
        self.outside = [np.maximum(ndimage.distance_transform_edt(~view.mask) - 0.5, 0.0) for view in views]
        # forward differences along rows and columns: the bilinear lookup's exact derivative
        self.steps = [
            (np.diff(away, axis=0, append=away[-1:]), np.diff(away, axis=1, append=away[:, -1:]))
            for away in self.outside
        ]

    def moved(self, views: list[FusionView], step: np.ndarray) -> list[FusionView]:
        """The views corrected by ``step`` (``per_view`` parameters each)."""
        out = []
        for view, p in zip(views, step.reshape(len(views), self.per_view)):
            if self.turntable:
                turn = _rotation(np.array([0.0, p[0], 0.0]))
                out.append(view.at(turn @ view.rotation, view.translation, view.offset + p[1]))
            else:
                out.append(view.at(_rotation(p[:3]) @ view.rotation, view.translation + p[3:], view.offset))
        return out

    def depth_rows(self) -> np.ndarray:
        """Which of :meth:`residuals`' rows are depth differences (the rest: silhouette
        distances), in their order."""
        count = len(self.samples)
        return np.concatenate(
            [
                np.repeat([False, True], len(pixels))
                for u, pixels in enumerate(self.samples)
                for v in range(count)
                if v != u
            ]
        )

    def residuals(self, views: list[FusionView], *, jacobian: bool = False):
        """All residuals, one block per ordered pair of views ``(u, v)``: ``u``'s points outside
        ``v``'s silhouette (distance, pixels), then, where ``v`` sees them squarely, their
        distance to ``v``'s tangent plane (the depth difference along ``v``'s ray times its
        ``n_z``). With ``jacobian``, also their derivatives (rows, ``per_view * len(views)``)."""
        values, rows = [], []
        width = self.per_view * len(views)
        for u, (view, pixels) in enumerate(zip(views, self.samples)):
            points = view.surface_points(pixels[:, 0], pixels[:, 1])
            normals = view.normals[pixels[:, 0], pixels[:, 1]] @ view.rotation  # object frame
            # d(object point)/d(u's correction), (n, 3, per_view)
            own = self._own(view, points) if jacobian else None
            for v, other in enumerate(views):
                if v == u:
                    continue
                seen = other.camera(points)
                r, c = other.pixels(seen)
                away = ndimage.map_coordinates(self.outside[v], [r, c], order=1, mode="nearest")
                facing = (normals @ other.rotation.T)[:, 2] > TRUSTED_NZ
                both = facing & other.inside(r, c) & (away == 0)
                planes = np.stack(
                    [
                        ndimage.map_coordinates(normal, [r, c], order=1, mode="nearest")
                        for normal in self.normals[v]
                    ],
                    axis=1,
                )
                planes[:, 2] = np.clip(planes[:, 2], 0.0, 1.0)
                planes[~both] = 0.0
                gap = (seen[:, 2] - other.surface(r, c)) * planes[:, 2]
                values.append(np.concatenate([away, gap]))
                if not jacobian:
                    continue
                # d(seen)/d(correction) of u (its points move) and of v (its camera moves)
                d_seen = np.zeros((len(seen), 3, width))
                d_seen[..., u * self.per_view : (u + 1) * self.per_view] = np.einsum(
                    "ij,njk->nik", other.rotation, own
                )
                d_seen[..., v * self.per_view : (v + 1) * self.per_view] = self._camera(
                    seen - other.translation
                )
                slope_r, slope_c = _bilinear_slopes(*self.steps[v], r, c)
                # row = row0 - y, column = x + column0; inside the silhouette the distance is 0
                # whichever way the point moves a little (a hinge)
                d_away = slope_c[:, None] * d_seen[:, 0] - slope_r[:, None] * d_seen[:, 1]
                d_away[away == 0] = 0.0
                d_gap = np.einsum("ni,nik->nk", planes, d_seen)
                if self.turntable:
                    # v's offset moves its surface toward the camera, not the point
                    d_gap[:, v * 2 + 1] -= planes[:, 2]
                rows.append(np.concatenate([d_away, d_gap]))
        r = np.concatenate(values)
        return (r, np.concatenate(rows)) if jacobian else r

    def _own(self, view: FusionView, points: np.ndarray) -> np.ndarray:
        """d(object point)/d(the view's own correction), (n, 3, per_view): the point is
        ``R^T (x - t)`` with ``x`` its camera point (depth plus offset)."""
        relative = points @ view.rotation.T  # x - t, in the camera frame
        back = view.rotation.T
        if self.turntable:
            # R <- R_y(turn) R: d/dturn = R^T (relative x e_y); offset: R^T e_z
            turn = back @ np.cross(relative, [0.0, 1.0, 0.0]).T
            return np.stack([turn.T, np.broadcast_to(back[:, 2], relative.shape)], axis=2)
        # R <- Rot(omega) R: d/domega = R^T [relative]x; t <- t + dt: d/dt = -R^T
        spin = np.einsum("ij,njk->nik", back, _cross_matrices(relative))
        shift = np.broadcast_to(-back, (len(points), 3, 3))
        return np.concatenate([spin, shift], axis=2)

    def _camera(self, relative: np.ndarray) -> np.ndarray:
        """d(camera point)/d(the camera's correction), (n, 3, per_view), at ``relative`` = the
        point in the camera frame less the translation: ``Rot(omega) R p + t``."""
        if self.turntable:
            # d/dturn = e_y x relative; the offset moves the surface only (see residuals)
            turn = np.cross([0.0, 1.0, 0.0], relative)
            return np.stack([turn, np.zeros_like(relative)], axis=2)
        spin = -_cross_matrices(relative)
        shift = np.broadcast_to(np.eye(3), (len(relative), 3, 3))
        return np.concatenate([spin, shift], axis=2)


def _bilinear_slopes(down, across, rows, cols):
    """The derivatives along rows and columns of a bilinear lookup (``map_coordinates`` with
    ``order=1``) of an image whose forward differences are ``down`` and ``across``."""
    h, w = down.shape
    rows, cols = np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)
    below = np.minimum(np.floor(rows), h - 2)
    left = np.minimum(np.floor(cols), w - 2)
    slope_r = ndimage.map_coordinates(down, [below, cols], order=1, mode="nearest")
    slope_c = ndimage.map_coordinates(across, [rows, left], order=1, mode="nearest")
    return slope_r, slope_c


def _cross_matrices(a: np.ndarray) -> np.ndarray:
    """``[a]x`` for each row: (n, 3) -> (n, 3, 3) with ``[a]x b = a x b``."""
    out = np.zeros((len(a), 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -a[:, 2], a[:, 1]
    out[:, 1, 0], out[:, 1, 2] = a[:, 2], -a[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -a[:, 1], a[:, 0]
    return out


def _samples(view: FusionView, count: int = SAMPLES, *, every_piece: bool = False) -> np.ndarray:
    """Pixels (row, col) of the view's trusted surface (``every_piece``: its whole facing
    surface), evenly thinned to about ``count``."""
    trusted = view.mask & (every_piece | view.trusted) & (np.nan_to_num(view.normals[..., 2]) > TRUSTED_NZ)
    rows, cols = np.nonzero(trusted)
    every = max(1, len(rows) // count)
    return np.stack([rows[::every], cols[::every]], axis=1)


def _rotation(omega: np.ndarray) -> np.ndarray:
    """Rodrigues: the rotation by ``|omega|`` radians about ``omega``."""
    angle = float(np.linalg.norm(omega))
    if angle < 1e-12:
        return np.eye(3)
    k = omega / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def _scale(r: np.ndarray) -> float:
    """The residuals' robust spread: the median absolute deviation of those that are not 0 (a
    point inside a silhouette, or not seen by a view, has a residual of exactly 0), at least
    half a pixel."""
    active = np.abs(r[r != 0])
    return max(1.4826 * float(np.median(active)) if len(active) else 0.0, MIN_SCALE)


def _tukey_cost(r: np.ndarray, scale: float) -> float:
    """Tukey's biweight loss, summed."""
    c = TUKEY * scale
    u = np.minimum(np.abs(r) / c, 1.0)
    return float(np.sum(c * c / 6 * (1 - (1 - u * u) ** 3)))


def _tukey(r: np.ndarray, scale: float) -> np.ndarray:
    u = r / (TUKEY * scale)
    return np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
