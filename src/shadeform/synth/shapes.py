"""The closed objects' implicit functions, analytic gradients and volumes, in pixel units.

Their shapes and dimensions are tabled in :mod:`shadeform.synth`.
"""

from __future__ import annotations

import math

import numpy as np

from shadeform.synth.rays import _radial

CLOSED_OBJECTS = ("ellipsoid", "pebble", "waisted", "lumpy")

# Dimensions in units of the image size (see the docstring of shadeform.synth).
_ELLIPSOID_AXES = (0.40, 0.30, 0.22)
_PEBBLE_AXES = (0.38, 0.20, 0.28)
_PEBBLE_EXPONENT = 2.6
_WAIST_OFFSET, _WAIST_RADIUS, _WAIST_BLEND = 0.17, 0.22, 0.08
_LUMPY_RADIUS, _LUMPY_AMPLITUDE = 0.36, 0.10
# Weights of five low-order spherical harmonics (as polynomials of the unit direction u):
# (5 u_y^3 - 3 u_y) / 2, 3 u_x u_z, u_x^3 - 3 u_x u_z^2, 3 u_x u_y, (3 u_z^2 - 1) / 2;
# their sum h(u) lies in [-0.86, 0.98], so the radius stays within about 10 % of its mean.
_LUMPY_WEIGHTS = (0.35, 0.30, 0.30, 0.25, 0.20)


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
