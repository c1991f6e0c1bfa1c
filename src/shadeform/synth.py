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

References
----------
.. [1] R. Zhang, P.-S. Tsai, J. E. Cryer and M. Shah, "Shape from shading: a survey",
   IEEE Trans. PAMI 21(8), 690-706, 1999 (the synthetic vase).
"""

from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import Polynomial

from shadeform.errors import InputError

SCENES = ("sphere", "ellipsoid", "cylinder", "vase", "bowl", "saddle", "bumps")

_MIN_SIZE = 16
#: The largest side a synthetic scene is made at (64 Mpx, the loader's pixel limit): checked
#: before anything is allocated.
_MAX_SIZE = 8192

# Zhang et al. (1999) vase profile on 0 <= u <= 1 (units of the image width): positive on the
# whole domain, 0.15 at both ends, belly ~0.286 at u ~0.366, neck ~0.107 at u ~0.808.
_VASE_PROFILE = 0.15 - 0.1 * (
    Polynomial([0.0, 1.0])
    * Polynomial([1.0, 6.0]) ** 2
    * Polynomial([-1.0, 1.0]) ** 2
    * Polynomial([-2.0, 3.0])
)
_VASE_SLOPE = _VASE_PROFILE.deriv()

# Bumps scene: (x0, y0, height, sigma) in units of size; the negative height is the dent.
_BUMPS = (
    (-0.18, 0.16, 0.10, 0.090),
    (0.18, 0.18, 0.08, 0.070),
    (0.02, -0.20, 0.12, 0.100),
    (0.26, -0.14, 0.06, 0.055),
    (-0.22, -0.17, -0.07, 0.070),
)


@dataclass(frozen=True, eq=False)
class Scene:
    """A rendered synthetic scene with its analytic ground truth.

    The arrays are read-only: they are the reference every method is scored against.

    Attributes
    ----------
    name : str
        One of :data:`SCENES`.
    image : (H, W) float64
        Lambertian rendering ``albedo * max(0, N . L)`` (plus noise), in [0, 1], 0 outside
        ``mask``.
    mask : (H, W) bool
        Object pixels.
    depth : (H, W) float64
        Analytic height z in pixel units, NaN outside ``mask``.
    normals : (H, W, 3) float64
        Analytic unit normals in the camera frame, NaN outside ``mask``.
    light : (3,) float64
        Unit vector toward the light.
    albedo : float
        Albedo used for the rendering.
    """

    name: str
    image: np.ndarray
    mask: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    light: np.ndarray
    albedo: float


def surface(name: str, *, size: int = 256) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Analytic geometry of a synthetic scene, sampled at pixel centres.

    Pixel ``(r, c)`` has ``x = c - (W - 1) / 2`` and ``y = -(r - (H - 1) / 2)``, so the image
    centre is the origin; depth and normals are exact at those points.

    Parameters
    ----------
    name : str
        One of :data:`SCENES` (see the module docstring for the shapes and their dimensions).
    size : int, optional
        Image height and width in pixels, at least 16.

    Returns
    -------
    depth : (size, size) float64
        Height z in pixel units, NaN outside ``mask``.
    normals : (size, size, 3) float64
        Unit normals ``(n_x, n_y, n_z)`` with ``n_z > 0``, NaN outside ``mask``.
    mask : (size, size) bool
        Object pixels.

    Raises
    ------
    InputError
        Unknown ``name`` or ``size`` below 16.

    References
    ----------
    .. [1] R. Zhang, P.-S. Tsai, J. E. Cryer and M. Shah, "Shape from shading: a survey",
       IEEE Trans. PAMI 21(8), 690-706, 1999.
    """
    _check_name(name)
    size = _check_size(size)
    centre = (size - 1) / 2.0
    coords = np.arange(size, dtype=np.float64) - centre
    x = np.broadcast_to(coords[None, :], (size, size))
    y = np.broadcast_to(-coords[:, None], (size, size))
    with np.errstate(invalid="ignore", divide="ignore"):
        depth, normal, mask = _BUILDERS[name](x, y, float(size))
    depth = np.where(mask, depth, np.nan)
    normals = np.where(mask[..., None], np.stack(normal, axis=-1), np.nan)
    return depth, normals, mask


def render(
    normals: np.ndarray,
    mask: np.ndarray,
    *,
    light=(0.0, 0.0, 1.0),
    albedo: float = 1.0,
    noise: float = 0.0,
    seed: int = 0,
    specular: float = 0.0,
    shininess: float = 50.0,
) -> np.ndarray:
    """Render a Lambertian image under orthographic projection and one distant light.

    ``I = albedo * max(0, N . L)`` inside ``mask`` (attached shadows are 0, cast shadows are
    not modelled), 0 outside. With ``specular > 0`` a Blinn-Phong highlight
    ``specular * (N . H)^shininess`` is added where ``N . L > 0`` (``H`` the half vector between
    the light and the viewer, +z), for testing methods that must reject highlights. With
    ``noise > 0``, gaussian noise of standard deviation ``noise * albedo`` is added to the object
    pixels. The result is clipped to [0, 1] like a camera would (a no-op without noise or
    highlights when ``albedo <= 1``).

    Parameters
    ----------
    normals : (H, W, 3) array_like
        Unit normals in the camera frame; only pixels in ``mask`` are read.
    mask : (H, W) array_like of bool
        Object pixels.
    light : (3,) array_like, optional
        Direction toward the light; normalised here. Must have z > 0.
    albedo : float, optional
        Positive albedo (``k * albedo`` of the image model).
    noise : float, optional
        Noise standard deviation as a fraction of ``albedo``; 0 for none.
    seed : int, optional
        Seed of :func:`numpy.random.default_rng`; the same seed gives the same image.
    specular : float, optional
        Strength of the Blinn-Phong highlight; 0 (default) for a purely Lambertian image.
    shininess : float, optional
        Blinn-Phong exponent: larger gives a smaller, sharper highlight.

    Returns
    -------
    image : (H, W) float64
        Rendered intensities in [0, 1], 0 outside ``mask``.

    Raises
    ------
    InputError
        Mismatched shapes, non-finite normals in the mask, a light with z <= 0, a non-positive
        albedo, a negative noise level, specular strength or shininess.

    References
    ----------
    .. [1] J. F. Blinn, "Models of light reflection for computer synthesized pictures",
       SIGGRAPH 1977.
    """
    normals = np.asarray(normals, dtype=np.float64)
    mask = np.asarray(mask)
    if normals.ndim != 3 or normals.shape[-1] != 3:
        raise InputError(f"normals must have shape (H, W, 3), got {normals.shape}")
    if mask.shape != normals.shape[:2]:
        raise InputError(
            f"mask shape {mask.shape} does not match normals shape {normals.shape[:2]}; "
            "pass the mask of the same scene"
        )
    mask = mask.astype(bool)
    if not np.isfinite(normals[mask]).all():
        raise InputError("normals contain NaN or inf inside the mask; fix them or shrink the mask")
    direction = _unit_light(light)
    albedo = _finite_float(albedo, "albedo")
    if albedo <= 0:
        raise InputError(f"albedo must be > 0, got {albedo}")
    noise = _finite_float(noise, "noise")
    if noise < 0:
        raise InputError(f"noise must be >= 0 (a fraction of the albedo), got {noise}")
    specular = _finite_float(specular, "specular")
    shininess = _finite_float(shininess, "shininess")
    if specular < 0 or shininess < 0:
        raise InputError(f"specular and shininess must be >= 0, got {specular} and {shininess}")

    shading = np.zeros(mask.shape, dtype=np.float64)
    shading[mask] = normals[mask] @ direction
    image = albedo * np.maximum(shading, 0.0)
    if specular > 0:
        half = direction + np.array([0.0, 0.0, 1.0])
        half /= np.linalg.norm(half)
        facing = np.zeros(mask.shape, dtype=np.float64)
        facing[mask] = np.maximum(normals[mask] @ half, 0.0)
        image += np.where(shading > 0, specular * facing**shininess, 0.0)
    if noise > 0:
        # A full-frame draw keeps each pixel's noise independent of the mask's shape.
        field = np.random.default_rng(seed).normal(0.0, noise * albedo, size=mask.shape)
        image[mask] += field[mask]
    return np.clip(image, 0.0, 1.0)


def chrome_sphere(
    light,
    *,
    size: int = 128,
    centre=None,
    radius=None,
    strength: float = 1.0,
    sharpness: float = 2000.0,
    background: float = 0.5,
    noise: float = 0.0,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """A mirror sphere on a matte table under one distant light, as light calibration sees it.

    The table faces the camera and reads ``background * max(0, l_z)``; the sphere mirrors a dark
    room and the light: ``strength * max(0, r . l)^sharpness``, ``r = 2 (n . v) n - v`` the
    direction the pixel sees by reflection (``v = +z``), so the highlight sits where the normal
    halves the angle between the viewer and the light. Orthographic, ``size x size``.

    Parameters
    ----------
    light : (3,) array_like
        Direction toward the light (normalised; z > 0).
    size : int
        Image side in pixels.
    centre : (2,) array_like, optional
        The sphere's centre (column, row); the image's centre by default.
    radius : float, optional
        The sphere's radius in pixels; ``0.3 size`` by default.
    strength : float
        The light's strength (scales the highlight; the table reads ``background`` at any
        strength, as a camera's exposure would keep it).
    sharpness : float
        Phong exponent of the mirror's lobe: a light of small angular size.
    background : float
        The table's albedo.
    noise : float
        Gaussian noise's standard deviation, added everywhere; 0 for none.
    seed : int
        Seed of :func:`numpy.random.default_rng`.

    Returns
    -------
    image : (size, size) float64
        In [0, 1].
    circle : (3,) float64
        The sphere's centre column, centre row and radius.
    """
    size = _check_size(size)
    direction = _unit_light(light)
    column, row = (size / 2 - 0.5, size / 2 - 0.5) if centre is None else map(float, centre)
    radius = 0.3 * size if radius is None else _finite_float(radius, "radius")
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    nx, ny = (cols - column) / radius, -(rows - row) / radius
    inside = nx * nx + ny * ny < 1.0
    nz = np.sqrt(np.maximum(0.0, 1.0 - nx * nx - ny * ny))
    # reflected view direction r = 2 (n . v) n - v with v = (0, 0, 1)
    reflected = np.stack([2 * nz * nx, 2 * nz * ny, 2 * nz * nz - 1.0], axis=-1)
    lobe = np.maximum(reflected @ direction, 0.0) ** _finite_float(sharpness, "sharpness")
    image = np.where(inside, strength * lobe, background * max(direction[2], 0.0))
    if noise > 0:
        image = image + np.random.default_rng(seed).normal(0.0, noise, size=image.shape)
    return np.clip(image, 0.0, 1.0), np.array([column, row, radius])


def scene(
    name: str,
    *,
    size: int = 256,
    light=(0.0, 0.0, 1.0),
    albedo: float = 1.0,
    noise: float = 0.0,
    seed: int = 0,
) -> Scene:
    """Build a synthetic scene: analytic geometry plus its Lambertian rendering.

    Parameters
    ----------
    name : str
        One of :data:`SCENES`.
    size : int, optional
        Image height and width in pixels, at least 16.
    light : (3,) array_like, optional
        Direction toward the light (normalised; z > 0).
    albedo : float, optional
        Positive albedo.
    noise : float, optional
        Gaussian noise standard deviation as a fraction of ``albedo``.
    seed : int, optional
        Noise seed.

    Returns
    -------
    Scene
        Image, mask, analytic depth and normals, unit light and albedo (read-only arrays).

    Raises
    ------
    InputError
        Unknown ``name``, ``size`` below 16, or a bad light, albedo or noise level.

    Examples
    --------
    >>> s = scene("sphere", size=64)
    >>> s.image.shape, s.normals.shape
    ((64, 64), (64, 64, 3))
    """
    _check_name(name)
    depth, normals, mask = surface(name, size=size)
    image = render(normals, mask, light=light, albedo=albedo, noise=noise, seed=seed)
    direction = _unit_light(light)
    for array in (image, mask, depth, normals, direction):
        array.flags.writeable = False
    return Scene(
        name=name,
        image=image,
        mask=mask,
        depth=depth,
        normals=normals,
        light=direction,
        albedo=float(albedo),
    )


# --- shapes: each takes pixel coordinates x, y and the image size and returns
# --- (depth, (n_x, n_y, n_z), mask); values outside the mask are discarded by surface().


def concave_regions(name: str, *, size: int = 256) -> dict:
    """The concave regions a user would draw on a scene, in the JSON format of the conventions.

    Derived from each scene's geometry: the bowl is concave along both axes everywhere; the vase's
    neck, where its profile curves outward (``F'' > 0``), is concave along y while it stays convex
    across; the bumps' dent is concave along both axes; the saddle is concave along x everywhere.
    The other scenes are convex: no regions.

    Parameters
    ----------
    name : str
        One of :data:`SCENES`.
    size : int
        Image side in pixels, as given to :func:`scene`.

    Returns
    -------
    dict
        ``{"regions": [{"polygon": [[x, y], ...], "axis": ...}, ...]}``, x = column, y = row.
    """
    _check_name(name)
    size = _check_size(size)
    centre = (size - 1) / 2

    def box(x0, y0, x1, y1, axis):
        # scene coordinates (y up, origin at the centre) -> pixel polygon (x = column, y = row)
        corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        return {"polygon": [[float(centre + x), float(centre - y)] for x, y in corners], "axis": axis}

    whole = size / 2 + 1
    if name == "bowl":
        regions = [box(-whole, -whole, whole, whole, "both")]
    elif name == "saddle":
        regions = [box(-whole, -whole, whole, whole, "x")]
    elif name == "vase":
        curvature = _VASE_PROFILE.deriv(2)
        roots = sorted(r.real for r in curvature.roots() if abs(r.imag) < 1e-9 and 0 < r.real < 1)
        # the neck: the last interval of (0, 1) where the profile curves outward
        edges = [0.0, *roots, 1.0]
        neck = [(a, b) for a, b in zip(edges[:-1], edges[1:]) if curvature((a + b) / 2) > 0][-1]
        height = 0.9 * size
        u = np.linspace(*neck, 64)
        half_width = height * _VASE_PROFILE(u).max() + 1
        y0, y1 = (neck[0] - 0.5) * height, (neck[1] - 0.5) * height
        regions = [box(-half_width, y0, half_width, y1, "y")]
    elif name == "bumps":
        regions = []
        for x0, y0, height, sigma in _BUMPS:
            if height < 0:
                half = 1.7 * sigma * size
                regions.append(
                    box(x0 * size - half, y0 * size - half, x0 * size + half, y0 * size + half, "both")
                )
    else:
        regions = []
    return {"regions": regions}


def _sphere(x, y, size):
    radius = 0.42 * size
    rho2 = x * x + y * y
    mask = rho2 < radius * radius
    z = np.sqrt(radius * radius - rho2)
    return z, (x / radius, y / radius, z / radius), mask


def _ellipsoid(x, y, size):
    a, b, c = 0.45 * size, 0.30 * size, 0.25 * size
    q = 1.0 - (x / a) ** 2 - (y / b) ** 2
    mask = q > 0
    z = c * np.sqrt(q)
    # Gradient of the implicit function x^2/a^2 + y^2/b^2 + z^2/c^2.
    return z, _normalise(x / a**2, y / b**2, z / c**2), mask


def _cylinder(x, y, size):
    radius, half_length = 0.35 * size, 0.42 * size
    mask = (np.abs(x) < radius) & (np.abs(y) < half_length)
    z = np.sqrt(radius * radius - x * x)
    return z, (x / radius, np.zeros_like(x), z / radius), mask


def _vase(x, y, size):
    # Survey units: u in [0, 1] bottom to top, radius f(u); scaled so the vase is 0.9 tall.
    height = 0.9 * size
    u = y / height + 0.5
    radius = height * _VASE_PROFILE(u)
    slope = _VASE_SLOPE(u)  # dF/dy, dimensionless (the scale cancels)
    mask = (np.abs(y) < height / 2) & (np.abs(x) < radius)
    z = np.sqrt(radius * radius - x * x)
    # n ~ (x, -F F', z); its length is F sqrt(1 + F'^2) exactly, even on the silhouette.
    length = radius * np.sqrt(1.0 + slope * slope)
    return z, (x / length, -radius * slope / length, z / length), mask


def _bowl(x, y, size):
    rim = 0.42 * size
    radius = rim / 0.9
    rho2 = x * x + y * y
    mask = rho2 < rim * rim
    w = np.sqrt(radius * radius - rho2)
    # Concave cap, rim at z = 0; its convex twin (x, y, w) / R has the same n_z.
    z = np.sqrt(radius * radius - rim * rim) - w
    return z, (-x / radius, -y / radius, w / radius), mask


def _saddle(x, y, size):
    rim = 0.42 * size
    s = rim / 1.5  # |grad z| = rho / s reaches 1.5 on the rim
    mask = x * x + y * y < rim * rim
    z = (x * x - y * y) / (2.0 * s)
    return z, _normalise(-x / s, y / s, np.ones_like(x)), mask


def _bumps(x, y, size):
    half = 0.45 * size
    mask = (np.abs(x) < half) & (np.abs(y) < half)
    z = np.zeros_like(x)
    zx = np.zeros_like(x)
    zy = np.zeros_like(x)
    for x0, y0, height, sigma in _BUMPS:
        dx, dy, s = x - x0 * size, y - y0 * size, sigma * size
        g = height * size * np.exp(-(dx * dx + dy * dy) / (2.0 * s * s))
        z += g
        zx -= g * dx / (s * s)
        zy -= g * dy / (s * s)
    return z, _normalise(-zx, -zy, np.ones_like(x)), mask


_BUILDERS = {
    "sphere": _sphere,
    "ellipsoid": _ellipsoid,
    "cylinder": _cylinder,
    "vase": _vase,
    "bowl": _bowl,
    "saddle": _saddle,
    "bumps": _bumps,
}


def _normalise(a, b, c):
    length = np.sqrt(a * a + b * b + c * c)
    return a / length, b / length, c / length


def _check_name(name) -> None:
    if name not in _BUILDERS:
        raise InputError(f"unknown scene {name!r}; choose one of: {', '.join(SCENES)}")


def _check_size(size) -> int:
    if isinstance(size, bool) or not isinstance(size, numbers.Integral) or not _MIN_SIZE <= size <= _MAX_SIZE:
        raise InputError(f"size must be a whole number from {_MIN_SIZE} to {_MAX_SIZE}, got {size!r}")
    return int(size)


def _unit_light(light, *, front: bool = True) -> np.ndarray:
    """``light`` as a unit vector; with ``front``, it must point toward the viewer (z > 0)."""
    try:
        direction = np.asarray(light, dtype=np.float64)
    except (TypeError, ValueError):
        direction = None
    if direction is None or direction.shape != (3,) or not np.isfinite(direction).all():
        raise InputError(f"light must be 3 finite numbers (x, y, z), got {light!r}")
    if front and direction[2] <= 0:
        raise InputError(f"light must point toward the viewer (z > 0), got {tuple(direction.tolist())}")
    norm = np.linalg.norm(direction)
    if norm == 0:
        raise InputError("light must be a nonzero direction, got (0, 0, 0)")
    return direction / norm


def _finite_float(value, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = np.nan
    if isinstance(value, bool) or not np.isfinite(number):
        raise InputError(f"{what} must be a finite number, got {value!r}")
    return number


# --- closed objects: implicit surfaces seen from turntable angles (several views -> one model)

CLOSED_OBJECTS = ("ellipsoid", "pebble", "waisted", "lumpy")

TURNTABLE_ANGLES = (0.0, 90.0, 180.0, 270.0)

# Dimensions in units of the image size (see the module docstring).
_ELLIPSOID_AXES = (0.40, 0.30, 0.22)
_PEBBLE_AXES = (0.38, 0.20, 0.28)
_PEBBLE_EXPONENT = 2.6
_WAIST_OFFSET, _WAIST_RADIUS, _WAIST_BLEND = 0.17, 0.22, 0.08
_LUMPY_RADIUS, _LUMPY_AMPLITUDE = 0.36, 0.10
# Weights of five low-order spherical harmonics (as polynomials of the unit direction u):
# (5 u_y^3 - 3 u_y) / 2, 3 u_x u_z, u_x^3 - 3 u_x u_z^2, 3 u_x u_y, (3 u_z^2 - 1) / 2;
# their sum h(u) lies in [-0.86, 0.98], so the radius stays within about 10 % of its mean.
_LUMPY_WEIGHTS = (0.35, 0.30, 0.30, 0.25, 0.20)

_MARCH_STEP = 0.5  # pixels between samples along a ray
_BLOCK = 16  # samples per ray evaluated at once
_BISECTIONS = 48
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
        One of :data:`CLOSED_OBJECTS` (dimensions in the module docstring).
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


def first_crossing(
    implicit, origin, heading, length, *, refine: bool = True, step: float = _MARCH_STEP
) -> np.ndarray:
    """Distance along ``heading`` from each origin to the first point with F < 0, NaN if none.

    Samples every ``step`` (pixels) up to ``length`` (per ray), in blocks of ``_BLOCK`` samples,
    then (with ``refine``) bisects the bracketing step to rounding. ``F(origin)`` must be > 0.
    A part of the object thinner than ``step`` along the ray may be missed.

    Parameters
    ----------
    implicit : callable
        ``F(points)`` for points ``(..., 3)``, negative inside.
    origin : (N, 3) float64
    heading : (3,) float64
        Unit direction of every ray.
    length : (N,) float64
        How far to look along each ray.

    Returns
    -------
    (N,) float64
    """
    count = origin.shape[0]
    found = np.full(count, np.nan)
    alive = np.arange(count)
    offsets = step * np.arange(1, _BLOCK + 1)
    base = 0.0
    while alive.size:
        steps = base + offsets  # (B,)
        samples = origin[alive, None, :] + steps[None, :, None] * heading
        inside = (implicit(samples) < 0) & (steps[None, :] <= length[alive, None] + step)
        any_inside = inside.any(axis=1)
        first = np.argmax(inside, axis=1)
        found[alive[any_inside]] = steps[first[any_inside]]
        base += _BLOCK * step
        alive = alive[~any_inside & (base < length[alive] + step)]
    if not refine:
        return found
    hit = np.nonzero(np.isfinite(found))[0]
    lo, hi = found[hit] - step, found[hit]
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        inside = implicit(origin[hit] + mid[:, None] * heading) < 0
        lo, hi = np.where(inside, lo, mid), np.where(inside, mid, hi)
    found[hit] = 0.5 * (lo + hi)
    return found


def _blocked(implicit, origin, heading, bound) -> np.ndarray:
    """Whether the ray from each origin along ``heading`` meets F < 0 before leaving the bound."""
    along = origin @ heading
    exit_distance = -along + np.sqrt(
        np.maximum(along**2 - np.einsum("ij,ij->i", origin, origin) + bound**2, 0)
    )
    return np.isfinite(first_crossing(implicit, origin, heading, exit_distance, refine=False))


def _radial(implicit, directions, reach: float) -> np.ndarray:
    """Distance from the origin to the surface along each unit direction (bisection on [0, reach])."""
    lo = np.zeros(directions.shape[0])
    hi = np.full(directions.shape[0], reach)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        inside = implicit(mid[:, None] * directions) < 0
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    return 0.5 * (lo + hi)


def _fibonacci_sphere(count: int) -> np.ndarray:
    """``count`` nearly evenly spread unit vectors (the Fibonacci lattice)."""
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    rho = np.sqrt(1.0 - z * z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=-1)


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


def _ellipsoid_f(p, size):
    a, b, c = (size * axis for axis in _ELLIPSOID_AXES)
    return (p[..., 0] / a) ** 2 + (p[..., 1] / b) ** 2 + (p[..., 2] / c) ** 2 - 1.0


def _ellipsoid_grad(p, size):
    axes = size * np.asarray(_ELLIPSOID_AXES)
    return 2.0 * p / axes**2


def _ellipsoid_volume(implicit, size):
    a, b, c = (size * axis for axis in _ELLIPSOID_AXES)
    return 4.0 / 3.0 * np.pi * a * b * c


def _pebble_f(p, size):
    a, b, c = (size * axis for axis in _PEBBLE_AXES)
    e = _PEBBLE_EXPONENT
    return np.abs(p[..., 0] / a) ** e + np.abs(p[..., 1] / b) ** e + np.abs(p[..., 2] / c) ** e - 1.0


def _pebble_grad(p, size):
    axes = size * np.asarray(_PEBBLE_AXES)
    q = p / axes
    return _PEBBLE_EXPONENT * np.sign(q) * np.abs(q) ** (_PEBBLE_EXPONENT - 1.0) / axes


def _pebble_volume(implicit, size):
    # The unit ball of the p-norm in 3D has volume (2 Gamma(1 + 1/p))^3 / Gamma(1 + 3/p).
    a, b, c = (size * axis for axis in _PEBBLE_AXES)
    e = _PEBBLE_EXPONENT
    return a * b * c * (2.0 * math.gamma(1.0 + 1.0 / e)) ** 3 / math.gamma(1.0 + 3.0 / e)


def _waist_parts(p, size):
    """Distances to the two spheres' centres, the smooth minimum's weight h, and the blend width."""
    offset, radius, blend = (size * v for v in (_WAIST_OFFSET, _WAIST_RADIUS, _WAIST_BLEND))
    x = p[..., 0]
    across = p[..., 1] * p[..., 1] + p[..., 2] * p[..., 2]
    right = np.sqrt((x - offset) ** 2 + across)
    left = np.sqrt((x + offset) ** 2 + across)
    # Polynomial smooth minimum (Quilez) of the spheres' signed distances d1 = right - radius,
    # d2 = left - radius: C1, equal to min(d1, d2) where they differ by more than the blend.
    h = np.clip(0.5 + 0.5 * (left - right) / blend, 0.0, 1.0)
    return right - radius, left - radius, h, blend, right, left, offset


def _waisted_f(p, size):
    d1, d2, h, blend, *_ = _waist_parts(p, size)
    return h * d1 + (1.0 - h) * d2 - blend * h * (1.0 - h)


def _waisted_grad(p, size):
    _, _, h, _, right, left, offset = _waist_parts(p, size)
    # dF/dd1 = h and dF/dd2 = 1 - h for this smooth minimum; grad d = (p - centre) / |p - centre|.
    shift = np.array([offset, 0.0, 0.0])
    return (h / right)[..., None] * (p - shift) + ((1.0 - h) / left)[..., None] * (p + shift)


def _waisted_volume(implicit, size):
    # A solid of revolution about x: V = (2 pi / 3) * integral over t in [-1, 1] of r(t)^3,
    # r(t) the radius along (t, sqrt(1 - t^2), 0); composite 8-point Gauss-Legendre on 512 panels.
    nodes, weights = np.polynomial.legendre.leggauss(8)
    edges = np.linspace(-1.0, 1.0, 513)
    half = 0.5 * np.diff(edges)
    t = ((edges[:-1] + edges[1:]) / 2)[:, None] + half[:, None] * nodes
    t = t.ravel()
    directions = np.stack([t, np.sqrt(1.0 - t * t), np.zeros_like(t)], axis=-1)
    r = _radial(implicit, directions, 0.5 * size)
    return 2.0 * np.pi / 3.0 * np.sum((half[:, None] * weights).ravel() * r**3)


def _lumpy_h(u):
    """The bump pattern h(u), a sum of low-order spherical harmonics (products, not powers: fast)."""
    ux, uy, uz = u[..., 0], u[..., 1], u[..., 2]
    w0, w1, w2, w3, w4 = _LUMPY_WEIGHTS
    return (
        w0 * uy * (2.5 * uy * uy - 1.5)
        + ux * (3.0 * w1 * uz + w2 * (ux * ux - 3.0 * uz * uz) + 3.0 * w3 * uy)
        + w4 * (1.5 * uz * uz - 0.5)
    )


def _lumpy_dh(u):
    """The gradient of h as a polynomial of (u_x, u_y, u_z)."""
    ux, uy, uz = u[..., 0], u[..., 1], u[..., 2]
    w0, w1, w2, w3, w4 = _LUMPY_WEIGHTS
    return np.stack(
        [
            3.0 * w1 * uz + 3.0 * w2 * (ux * ux - uz * uz) + 3.0 * w3 * uy,
            w0 * (7.5 * uy * uy - 1.5) + 3.0 * w3 * ux,
            3.0 * w1 * ux - 6.0 * w2 * ux * uz + 3.0 * w4 * uz,
        ],
        axis=-1,
    )


def _lumpy_radius(u, size):
    return size * _LUMPY_RADIUS * (1.0 + _LUMPY_AMPLITUDE * _lumpy_h(u))


def _lumpy_f(p, size):
    norm = np.sqrt(np.einsum("...i,...i->...", p, p))
    u = p / np.maximum(norm, 1e-300)[..., None]
    return norm - _lumpy_radius(u, size)


def _lumpy_grad(p, size):
    # F = |p| - R (1 + a h(u)), u = p / |p|: grad F = u - R a (I - u u^T) grad_u h / |p|.
    norm = np.sqrt(np.sum(p * p, axis=-1))[..., None]
    u = p / norm
    dh = _lumpy_dh(u)
    tangential = dh - np.sum(dh * u, axis=-1, keepdims=True) * u
    return u - size * _LUMPY_RADIUS * _LUMPY_AMPLITUDE * tangential / norm


def _lumpy_volume(implicit, size):
    # V = (1/3) * integral over the sphere of r(u)^3; r^3 is a polynomial of degree 9 in u, which
    # a 16-node Gauss-Legendre rule in u_y times a 32-point uniform rule in longitude integrates
    # exactly.
    nodes, weights = np.polynomial.legendre.leggauss(16)
    phi = 2.0 * np.pi * np.arange(32) / 32
    ring = np.sqrt(1.0 - nodes * nodes)[:, None]
    u = np.stack(np.broadcast_arrays(ring * np.cos(phi), nodes[:, None], ring * np.sin(phi)), axis=-1)
    radius = _lumpy_radius(u, size)
    return np.sum(weights[:, None] * (2.0 * np.pi / 32) * radius**3) / 3.0


_CLOSED = {
    "ellipsoid": (_ellipsoid_f, _ellipsoid_grad, _ellipsoid_volume),
    "pebble": (_pebble_f, _pebble_grad, _pebble_volume),
    "waisted": (_waisted_f, _waisted_grad, _waisted_volume),
    "lumpy": (_lumpy_f, _lumpy_grad, _lumpy_volume),
}


def material_surface(size: int = 256, *, seed: int = 0, slope: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """A rough, periodic surface filling the frame (stone, plaster): for material-mode maps.

    Gaussian noise filtered to a ``1 / f^1.8`` amplitude spectrum (a fractal roughness) below a
    quarter of the sampling frequency, scaled so that the slopes' root mean square is ``slope``.

    Parameters
    ----------
    size : int, optional
        Side in pixels.
    seed : int, keyword-only
        Random seed.
    slope : float, keyword-only
        Root mean square of the height's gradient.

    Returns
    -------
    height : (size, size) float64
        Height in pixels, mean 0, periodic.
    normals : (size, size, 3) float64
        Its unit normals (spectral derivatives, so periodic too).
    """
    from shadeform.texture import spectral_normals, spectral_slopes

    size = _check_size(size)
    slope = _finite_float(slope, "slope")
    if not slope > 0:
        raise InputError(f"slope must be positive, got {slope!r}")
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(size)
    radius = np.hypot(f[:, None], f[None, :])
    amplitude = np.where(radius < 0.25, np.maximum(radius, 1.0 / size) ** -1.8, 0.0)
    amplitude[0, 0] = 0.0
    height = np.fft.ifft2(
        amplitude * (rng.normal(size=(size, size)) + 1j * rng.normal(size=(size, size)))
    ).real
    dx, dy = spectral_slopes(height)
    height = height * slope / np.sqrt(np.mean(dx * dx + dy * dy))
    return height, spectral_normals(height)


def bump_relief(
    shape: tuple[int, int],
    *,
    window: tuple[int, int, int, int] | None = None,
    spacing: float = 64.0,
    width: tuple[float, float] = (0.06, 0.09),
    seed: int = 0,
) -> Scene:
    """Gaussian bumps on a flat plate, one per cell of a jittered grid: a relief of any size.

    The relief fills the frame (every pixel is on the object) and is lit from +z. Each cell of a
    ``spacing``-pixel grid holds one bump whose top (on the pixel nearest a point within 0.1
    ``spacing`` of the cell's centre), width ``sigma`` (``width`` times ``spacing``) and height (0.5 to 1.2
    ``sigma``, slopes up to about 0.7) come from a hash of the cell and ``seed``. A bump is cut off 0.6
    ``spacing`` from its centre (6.7 ``sigma`` or more: below ``exp(-22)`` of its height), so only
    the bumps of a pixel's own and neighbouring cells reach it.
    Any ``window`` of the relief is therefore made on its own, with the same values the whole
    would have there: huge test images are written tile by tile (``benchmarks/bench_tiled.py``).

    Parameters
    ----------
    shape : (int, int)
        Rows and columns of the whole relief.
    window : (row, col, rows, cols), optional
        The part to make; the whole relief by default.
    spacing : float, keyword-only
        Grid cell size in pixels, >= 16.
    width : (float, float), keyword-only
        Least and largest ``sigma`` as fractions of ``spacing``, at most 0.09 (sparser bumps for
        smaller fractions).
    seed : int, keyword-only
        Seed of the bumps' hash.

    Returns
    -------
    Scene
        Named ``"bump_relief"``, the window's image ``n_z`` (light +z, albedo 1), an all-true
        mask, the analytic depth (z = 0 on the plate) and normals, all float64.
    """
    rows, cols = (int(v) for v in shape)
    if rows < 1 or cols < 1:
        raise InputError(f"shape must be two positive whole numbers, got {shape!r}")
    r0, c0, h, w = (0, 0, rows, cols) if window is None else (int(v) for v in window)
    if h < 1 or w < 1 or r0 < 0 or c0 < 0 or r0 + h > rows or c0 + w > cols:
        raise InputError(f"window {window!r} must lie inside the relief of shape {shape!r}")
    spacing = _finite_float(spacing, "spacing")
    if spacing < 16:
        raise InputError(f"spacing must be at least 16 pixels, got {spacing}")
    low, high = (_finite_float(v, "width") for v in width)
    if not 0 < low <= high <= 0.09:
        raise InputError(f"width must be two fractions 0 < least <= largest <= 0.09, got {width!r}")
    r = np.arange(r0, r0 + h, dtype=np.float64)[:, None]
    c = np.arange(c0, c0 + w, dtype=np.float64)[None, :]
    z = np.zeros((h, w))
    zr = np.zeros((h, w))  # dz / d row
    zc = np.zeros((h, w))  # dz / d col
    # the cells whose bumps reach the window (a bump ends, for our purpose, 0.5 spacing out)
    i_lo, i_hi = int(np.floor(r0 / spacing)) - 1, int(np.floor((r0 + h) / spacing)) + 1
    j_lo, j_hi = int(np.floor(c0 / spacing)) - 1, int(np.floor((c0 + w) / spacing)) + 1
    for i in range(i_lo, i_hi + 1):
        for j in range(j_lo, j_hi + 1):
            u = _cell_uniforms(i, j, seed)
            # tops on pixel centres: a top between pixels is seen below full brightness and the
            # eikonal solver's tolerance (1e-3) would miss narrow ones; the bump itself is made exactly
            centre_r = float(np.rint((i + 0.5 + 0.2 * (u[0] - 0.5)) * spacing))
            centre_c = float(np.rint((j + 0.5 + 0.2 * (u[1] - 0.5)) * spacing))
            sigma = (low + (high - low) * u[2]) * spacing
            height = (0.5 + 0.7 * u[3]) * sigma
            reach = 0.6 * spacing
            rs = slice(max(int(centre_r - reach) - r0, 0), min(int(centre_r + reach) + 1 - r0, h))
            cs = slice(max(int(centre_c - reach) - c0, 0), min(int(centre_c + reach) + 1 - c0, w))
            if rs.start >= rs.stop or cs.start >= cs.stop:
                continue
            dr, dc = r[rs] - centre_r, c[:, cs] - centre_c
            g = height * np.exp(-(dr * dr + dc * dc) / (2.0 * sigma * sigma))
            z[rs, cs] += g
            zr[rs, cs] -= g * dr / (sigma * sigma)
            zc[rs, cs] -= g * dc / (sigma * sigma)
    # x = col, y = -row: dz/dx = zc, dz/dy = -zr
    nx, ny, nz = _normalise(-zc, zr, np.ones_like(z))
    normals = np.stack([nx, ny, nz], axis=-1)
    mask = np.ones((h, w), dtype=bool)
    light = np.array([0.0, 0.0, 1.0])
    return Scene("bump_relief", nz.copy(), mask, z, normals, light, 1.0)


def _cell_uniforms(i: int, j: int, seed: int) -> np.ndarray:
    """Four uniform numbers in [0, 1) fixed by the cell ``(i, j)`` and ``seed``."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, int(i) & 0xFFFFFFFF, int(j) & 0xFFFFFFFF]).random(4)
