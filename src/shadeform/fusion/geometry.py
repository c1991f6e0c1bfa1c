"""Where each view is: poses (turntable angles or 4x4 matrices), the turntable's axis column
found from the silhouettes, and the mapping between a view's pixels and its camera frame.

A view's camera frame is the project's (``docs/conventions.md``): x right, y up, z toward the
viewer, pixel units. Its pixel ``(row r, column c)`` is at ``x = c - c0``, ``y = (H - 1) / 2 - r``
with ``c0`` the turntable axis's column (turntable poses) or the image's centre column (matrix
poses); the height a single-photo reconstruction gives is ``z`` up to one offset per view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shadeform.errors import InputError

__all__ = ["ViewPose", "axis_column", "parse_pose", "rigid", "turntable"]


def turntable(angle: float) -> np.ndarray:
    """The 4x4 pose of a view of an object turned by ``angle`` degrees about +y (right-handed):
    camera point ``= R_y(angle) @ object point``."""
    t = np.radians(angle)
    c, s = np.cos(t), np.sin(t)
    pose = np.eye(4)
    pose[:3, :3] = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
    return pose


@dataclass(frozen=True)
class ViewPose:
    """A view's pose: ``matrix`` takes object points to its camera frame; ``angle`` is the
    turntable angle in degrees it came from (None for a matrix)."""

    matrix: np.ndarray
    angle: float | None = None


def parse_pose(pose, index: int) -> ViewPose:
    """A turntable angle (degrees) or a 4x4 rigid matrix, checked."""
    if np.ndim(pose) == 0:
        try:
            angle = float(pose)
        except (TypeError, ValueError):
            raise InputError(
                f"view {index + 1}: a pose is a turntable angle in degrees or a 4x4 matrix"
            ) from None
        if not np.isfinite(angle):
            raise InputError(f"view {index + 1}: the turntable angle must be a finite number of degrees")
        return ViewPose(turntable(angle), angle)
    return ViewPose(rigid(pose, f"view {index + 1}: a pose"), None)


def rigid(pose, what: str = "a pose") -> np.ndarray:
    """A 4x4 rigid transform (rotation, translation, last row 0 0 0 1) as float64, checked;
    ``what`` names it in the one-line message."""
    try:
        matrix = np.asarray(pose, dtype=np.float64)
    except (TypeError, ValueError):
        matrix = None
    if matrix is None or matrix.shape != (4, 4) or not np.isfinite(matrix).all():
        raise InputError(f"{what} must be a finite 4x4 matrix, got shape {np.shape(pose)}")
    rotation = matrix[:3, :3]
    if (
        not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9)
        or not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6)
        or np.linalg.det(rotation) <= 0
    ):
        raise InputError(
            f"{what} must be rigid: a rotation (orthonormal, det +1), a translation, last row 0 0 0 1"
        )
    return matrix


def axis_column(masks, angles) -> float:
    """The turntable axis's column, from the silhouettes.

    Views half a turn apart see mirror images: the silhouette of ``angle + 180`` is that of
    ``angle`` reflected about the axis, row by row, so each such pair gives the axis as the mean
    of the two silhouettes' middles (the average over rows of ``(left_a + right_a + left_b +
    right_b) / 4`` with left and right the extreme object columns). Without such a pair every
    view's silhouette middle counts, which holds for shapes symmetric enough to fill each view
    evenly about the axis; the caller's value is better then.

    Parameters
    ----------
    masks : sequence of (H, W) bool
    angles : sequence of float
        Turntable angles in degrees, one per mask.

    Returns
    -------
    float
        The axis's column (may lie between pixels).
    """
    estimates = []
    for i, a in enumerate(angles):
        for j in range(i + 1, len(angles)):
            if abs(((angles[j] - a) % 360.0) - 180.0) < 1.0:
                middle = _row_middles(masks[i]) + _row_middles(masks[j])
                rows = np.isfinite(middle)
                if rows.any():
                    estimates.append(float(np.mean(middle[rows])) / 2)
    if estimates:
        return float(np.mean(estimates))
    middles = np.concatenate([_row_middles(mask) for mask in masks])
    return float(np.nanmean(middles))


def _row_middles(mask: np.ndarray) -> np.ndarray:
    """Per row, the middle of the object's extreme columns ((left + right) / 2), NaN where the
    row is empty."""
    on = mask.any(axis=1)
    left = np.where(on, np.argmax(mask, axis=1), 0)
    right = np.where(on, mask.shape[1] - 1 - np.argmax(mask[:, ::-1], axis=1), 0)
    return np.where(on, (left + right) / 2.0, np.nan)
