"""Renderings of given normals: the Lambertian (optionally Blinn-Phong) image, and a chrome sphere."""

from __future__ import annotations

import numpy as np

from shadeform.errors import InputError
from shadeform.synth.checks import _check_size, _finite_float, _unit_light


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
