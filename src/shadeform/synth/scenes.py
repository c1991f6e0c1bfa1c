"""Height-field scenes with analytic ground truth, and the concave regions a user would draw.

The scenes' shapes and dimensions are tabled in :mod:`shadeform.synth`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import Polynomial

from shadeform.errors import InputError
from shadeform.synth.checks import _check_size, _unit_light
from shadeform.synth.shading import render

SCENES = ("sphere", "ellipsoid", "cylinder", "vase", "bowl", "saddle", "bumps")

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
        One of :data:`SCENES` (see :mod:`shadeform.synth` for the shapes and their dimensions).
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


# --- shapes: each takes pixel coordinates x, y and the image size and returns
# --- (depth, (n_x, n_y, n_z), mask); values outside the mask are discarded by surface().


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
