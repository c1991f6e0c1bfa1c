"""Closed synthetic objects and their views: the object, a view, turntable poses, and the renderer."""

from __future__ import annotations

import functools
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from shadeform.errors import InputError
from shadeform.synth.checks import _check_size, _finite_float, _unit_light
from shadeform.synth.rays import _blocked, _fibonacci_sphere, _radial, first_crossing
from shadeform.synth.shapes import _CLOSED, CLOSED_OBJECTS

TURNTABLE_ANGLES = (0.0, 90.0, 180.0, 270.0)

_SHADOW_OFFSET = 1e-3  # pixels along the normal before a shadow ray leaves the surface
_FIBONACCI = 20000  # directions for the bounding radius and the sampling density bound


@dataclass(frozen=True, eq=False)
class ClosedObject:
    """A closed synthetic object: an implicit surface in its own frame, in pixel units.

    The object is ``implicit(p) < 0``, its surface ``implicit(p) = 0``; ``p`` is in the object
    frame (the camera frame of the view at turntable angle 0), origin at the image centre. The
    implicit function is not a distance in general (only its sign and zero set are meant); the
    distance of a point ``p`` near the surface is about ``|F(p)| / |grad F(p)|``. Every object is
    star-shaped about its origin (each ray from the origin crosses the surface once), which
    :meth:`surface_points` and the volume integrals use.

    Attributes
    ----------
    name : str
        One of :data:`CLOSED_OBJECTS`.
    size : int
        Image side the dimensions were scaled to (lengths are fractions of it).
    implicit : callable
        ``F((..., 3) array) -> (...)`` array, negative inside.
    gradient : callable
        ``grad F((..., 3) array) -> (..., 3)`` array, analytic; points outward on the surface.
    volume : float
        Enclosed volume in cubic pixels: analytic for the ellipsoid, the pebble (gamma functions)
        and the lumpy sphere (a product Gauss rule exact for its polynomial radius); a composite
        Gauss-Legendre integral of ``(2 pi / 3) r(t)^3`` over ``t = cos`` (angle to the x axis)
        for the waisted object, which turns about its x axis (relative error below 1e-9).
    radius : float
        Largest distance from the origin to the surface, in pixels (the largest of 20,000
        directions, each solved to rounding).
    """

    name: str
    size: int
    implicit: Callable[[np.ndarray], np.ndarray]
    gradient: Callable[[np.ndarray], np.ndarray]
    volume: float
    radius: float
    _density_bound: float = field(repr=False)

    def surface_points(self, count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Points spread uniformly by area over the surface, with their outward normals.

        Directions ``u`` drawn uniformly on the unit sphere map to surface points ``r(u) u``
        (``r`` found by bisection of ``F(t u)`` to rounding, so ``F = 0`` exactly up to
        rounding); a direction's share of surface area is ``r^2 / (u . n)`` per unit solid
        angle, so keeping each with probability proportional to it (rejection sampling) makes the
        points uniform by area, as Chamfer distances and F-scores assume. This is exact, unlike a
        marching-cubes mesh whose vertices lie off the surface and whose triangles misweight it.

        Parameters
        ----------
        count : int
            Number of points, at least 1.
        seed : int, optional
            Seed of :func:`numpy.random.default_rng`; the same seed gives the same points.

        Returns
        -------
        points : (count, 3) float64
            Surface points in the object frame, pixel units.
        normals : (count, 3) float64
            Unit outward normals there.

        Raises
        ------
        InputError
            ``count`` is not a positive integer.
        """
        if isinstance(count, bool) or not isinstance(count, numbers.Integral) or count < 1:
            raise InputError(f"count must be a positive integer, got {count!r}")
        rng = np.random.default_rng(seed)
        points, normals, kept = [], [], 0
        while kept < count:
            batch = max(1024, 2 * (count - kept))
            directions = rng.normal(size=(batch, 3))
            directions /= np.linalg.norm(directions, axis=1, keepdims=True)
            radii = _radial(self.implicit, directions, 0.5 * self.size)
            surface_points = radii[:, None] * directions
            normal = _unit_rows(self.gradient(surface_points))
            density = radii**2 / np.einsum("ij,ij->i", directions, normal)
            keep = rng.random(batch) * self._density_bound < density
            points.append(surface_points[keep])
            normals.append(normal[keep])
            kept += int(keep.sum())
        points = np.concatenate(points)[:count]
        normals = np.concatenate(normals)[:count]
        return points, normals


@dataclass(frozen=True, eq=False)
class View:
    """One orthographic view of a closed object, with its analytic ground truth.

    Arrays are read-only and ``(size, size)``; pixel ``(r, c)`` is at ``x = c - (W - 1) / 2``,
    ``y = -(r - (H - 1) / 2)`` in the view's camera frame.

    Attributes
    ----------
    image : (H, W) float64
        ``albedo * max(0, N . L)`` where the point sees the light, 0 in cast shadows and off the
        object; clipped to [0, 1].
    mask : (H, W) bool
        Pixels whose ray hits the object.
    depth : (H, W) float64
        z of the first surface point along the ray, camera frame, pixel units; NaN off the mask.
    normals : (H, W, 3) float64
        Unit outward normals in the camera frame, NaN off the mask.
    pose : (4, 4) float64
        Object frame -> this view's camera frame: ``q = pose[:3, :3] @ p + pose[:3, 3]``.
    angle : float or None
        Turntable angle in degrees, None when the view was given as a pose.
    light : (3,) float64
        Unit vector toward the light, in this view's camera frame.
    albedo : float
        Albedo of the rendering.
    """

    image: np.ndarray
    mask: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    pose: np.ndarray
    angle: float | None
    light: np.ndarray
    albedo: float


def turntable_pose(angle) -> np.ndarray:
    """The 4x4 pose of a turntable view: the object turned by ``angle`` degrees about +y.

    ``R_y(t) = [[cos t, 0, sin t], [0, 1, 0], [-sin t, 0, cos t]]`` (right-handed about +y, so
    at 90 degrees the object's +x points away from the viewer), no translation.

    Parameters
    ----------
    angle : float
        Degrees.

    Returns
    -------
    (4, 4) float64
        Object frame -> camera frame.

    Examples
    --------
    >>> turntable_pose(90.0)[:3, :3].round(12) + 0.0
    array([[ 0.,  0.,  1.],
           [ 0.,  1.,  0.],
           [-1.,  0.,  0.]])
    """
    from shadeform.fusion.geometry import turntable

    return turntable(_finite_float(angle, "angle"))


def closed_object(name: str, *, size: int = 256) -> ClosedObject:
    """A closed synthetic object scaled to ``size x size`` views.

    Parameters
    ----------
    name : str
        One of :data:`CLOSED_OBJECTS` (dimensions in :mod:`shadeform.synth`).
    size : int, optional
        Image side in pixels, at least 16; lengths are fractions of it.

    Returns
    -------
    ClosedObject
        The implicit function, its analytic gradient, volume, bounding radius and a surface
        sampler.

    Raises
    ------
    InputError
        Unknown ``name`` or ``size`` below 16.

    Examples
    --------
    >>> obj = closed_object("ellipsoid", size=100)
    >>> round(obj.volume / (4 / 3 * np.pi * 40 * 30 * 22), 12)
    1.0
    >>> float(obj.implicit(np.array([40.0, 0.0, 0.0])))
    0.0
    """
    if name not in _CLOSED:
        raise InputError(f"unknown closed object {name!r}; choose one of: {', '.join(CLOSED_OBJECTS)}")
    return _closed_object(name, _check_size(size))


@functools.lru_cache(maxsize=32)
def _closed_object(name: str, size: int) -> ClosedObject:
    implicit_of, gradient_of, volume_of = _CLOSED[name]
    implicit = functools.partial(implicit_of, size=float(size))
    gradient = functools.partial(gradient_of, size=float(size))
    directions = _fibonacci_sphere(_FIBONACCI)
    radii = _radial(implicit, directions, 0.5 * size)
    normals = _unit_rows(gradient(radii[:, None] * directions))
    density = radii**2 / np.einsum("ij,ij->i", directions, normals)
    return ClosedObject(
        name=name,
        size=size,
        implicit=implicit,
        gradient=gradient,
        volume=float(volume_of(implicit, float(size))),
        radius=float(radii.max()),
        # 25 % above the densest of 20,000 directions: a safe bound for rejection sampling.
        _density_bound=float(1.25 * density.max()),
    )


def render_views(
    name: str,
    angles=TURNTABLE_ANGLES,
    *,
    size: int = 256,
    light=(0.0, 0.0, 1.0),
    albedo: float = 0.8,
    poses=None,
) -> tuple[View, ...]:
    """Render a closed object from turntable angles (or any poses), with shadows and masks.

    A turntable angle ``t`` means the object was turned by ``t`` about the camera's vertical
    axis: a point ``p`` of the object frame is at ``R_y(t) @ p`` in the view's camera frame
    (:func:`turntable_pose`). Views are orthographic along -z through the pixel centres. Each
    ray is sampled every half pixel from where it enters the object's bounding sphere; the first
    sample inside is refined by bisection to rounding, and the normal is the analytic gradient
    there, rotated into the camera frame. The light stays with the camera (it is given in the
    camera frame and is the same for every view). A lit point (``N . L > 0``) whose ray toward
    the light meets the object (sampled every half pixel) is in a cast shadow and reads 0.
    Crossings shorter than half a pixel (rays grazing the silhouette within ~1e-3 px) are missed.

    Parameters
    ----------
    name : str
        One of :data:`CLOSED_OBJECTS`.
    angles : sequence of float, optional
        Turntable angles in degrees, one view each.
    size : int, optional
        Image side in pixels, at least 16.
    light : (3,) array_like, optional
        Direction toward the light in the camera frame, any nonzero vector (normalised).
    albedo : float, optional
        Positive albedo.
    poses : sequence of (4, 4) array_like, optional
        Object -> camera rigid transforms, one view each, instead of ``angles`` (give one of
        the two). A translation moves the object in the view (pixel units).

    Returns
    -------
    tuple of View
        One per angle or pose, in order.

    Raises
    ------
    InputError
        Unknown ``name``, a bad size, angles, pose, light or albedo, or both angles and poses.

    Examples
    --------
    >>> views = render_views("pebble", (0, 90), size=32)
    >>> [v.mask.shape for v in views], views[1].angle
    ([(32, 32), (32, 32)], 90.0)
    """
    obj = closed_object(name, size=size)
    direction = _unit_light(light, front=False)
    albedo = _finite_float(albedo, "albedo")
    if albedo <= 0:
        raise InputError(f"albedo must be > 0, got {albedo}")
    if poses is not None:
        if angles is not None and angles is not TURNTABLE_ANGLES:
            raise InputError("give either angles or poses, not both")
        transforms = [(_check_pose(pose), None) for pose in _as_list(poses, "poses")]
    else:
        transforms = [
            (turntable_pose(angle), _finite_float(angle, "angle")) for angle in _as_list(angles, "angles")
        ]
    views = []
    for pose, angle in transforms:
        image, mask, depth, normals = _render_closed(obj, pose, direction, albedo)
        pose = pose.copy()
        light_copy = direction.copy()
        for array in (image, mask, depth, normals, pose, light_copy):
            array.flags.writeable = False
        views.append(View(image, mask, depth, normals, pose, angle, light_copy, albedo))
    return tuple(views)


def _render_closed(obj: ClosedObject, pose: np.ndarray, light: np.ndarray, albedo: float):
    """Image, mask, depth and normals of one view (arrays of ``obj.size``)."""
    size = obj.size
    rotation, translation = pose[:3, :3], pose[:3, 3]
    bound = obj.radius + 2.0
    coords = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    x = np.broadcast_to(coords[None, :], (size, size))
    y = np.broadcast_to(-coords[:, None], (size, size))
    rho2 = (x - translation[0]) ** 2 + (y - translation[1]) ** 2
    rows, cols = np.nonzero(rho2 < bound * bound)
    half_chord = np.sqrt(bound * bound - rho2[rows, cols])
    # Ray start (camera frame) on the bounding sphere's near side, then into the object frame.
    start = np.stack([x[rows, cols], y[rows, cols], translation[2] + half_chord], axis=-1)
    origin = (start - translation) @ rotation  # R^T (q - t) for each row
    heading = -rotation[2]  # R^T (0, 0, -1)
    distance = first_crossing(obj.implicit, origin, heading, 2.0 * half_chord)
    hit = np.isfinite(distance)
    rows, cols, origin, distance = rows[hit], cols[hit], origin[hit], distance[hit]
    points = origin + distance[:, None] * heading
    normal_object = _unit_rows(obj.gradient(points))
    light_object = light @ rotation  # R^T l
    shading = normal_object @ light_object
    lit = shading > 0
    shadowed = np.zeros_like(lit)
    shadowed[lit] = _blocked(
        obj.implicit, points[lit] + _SHADOW_OFFSET * normal_object[lit], light_object, bound
    )
    mask = np.zeros((size, size), dtype=bool)
    mask[rows, cols] = True
    depth = np.full((size, size), np.nan)
    depth[rows, cols] = start[hit, 2] - distance
    normals = np.full((size, size, 3), np.nan)
    normals[rows, cols] = normal_object @ rotation.T
    image = np.zeros((size, size))
    image[rows, cols] = np.where(shadowed, 0.0, albedo * np.maximum(shading, 0.0))
    return np.clip(image, 0.0, 1.0), mask, depth, normals


def _unit_rows(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def _as_list(values, what: str) -> list:
    if (what == "angles" and np.ndim(values) == 0) or (what == "poses" and np.ndim(values) == 2):
        values = [values]  # one view
    try:
        items = list(values)
    except TypeError:
        raise InputError(f"{what} must be a sequence, got {values!r}") from None
    if not items:
        raise InputError(f"{what} is empty; give at least one view")
    return items


def _check_pose(pose) -> np.ndarray:
    from shadeform.fusion.geometry import rigid

    return rigid(pose)
