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

References
----------
.. [1] R. Zhang, P.-S. Tsai, J. E. Cryer and M. Shah, "Shape from shading: a survey",
   IEEE Trans. PAMI 21(8), 690-706, 1999 (the synthetic vase).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import Polynomial

from shadeform.errors import InputError

SCENES = ("sphere", "ellipsoid", "cylinder", "vase", "bowl", "saddle", "bumps")

_MIN_SIZE = 16

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
    if isinstance(size, bool) or not isinstance(size, numbers.Integral) or size < _MIN_SIZE:
        raise InputError(f"size must be an integer >= {_MIN_SIZE}, got {size!r}")
    return int(size)


def _unit_light(light) -> np.ndarray:
    try:
        direction = np.asarray(light, dtype=np.float64)
    except (TypeError, ValueError):
        direction = None
    if direction is None or direction.shape != (3,) or not np.isfinite(direction).all():
        raise InputError(f"light must be 3 finite numbers (x, y, z), got {light!r}")
    if direction[2] <= 0:
        raise InputError(f"light must point toward the viewer (z > 0), got {tuple(direction.tolist())}")
    return direction / np.linalg.norm(direction)


def _finite_float(value, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = np.nan
    if isinstance(value, bool) or not np.isfinite(number):
        raise InputError(f"{what} must be a finite number, got {value!r}")
    return number
