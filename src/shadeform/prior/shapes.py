"""Random objects with exact depth and normals: the geometry of the shape prior's training photos.

An object is the union of a few parts seen orthographically from the front. Each part's visible
surface is known in closed form, with its normal (the gradient of its implicit function, not a
finite difference), so the union's depth is the nearest part's and its normal is that part's:

=========== ==================================================================================
ellipsoid   any size, any 3D orientation: the front root of the quadric along the ray
superquadric ``(|x/a|^p + |y/b|^p) + |z/c|^q = 1`` turned in the image plane: rounded boxes,
            cushions, coins and pills (p, q from 2 to 10)
solid       ``(|x/a|^s + |y/b|^s)^(t/s) + |z/c|^t = 1`` turned any way in 3D, ray cast: boxes
            seen corner-on, cylinders and tins seen from above (s = 2 or 2-12, t 2-12)
tube        a sphere swept along a straight or bent centre line in the image plane with a
            varying radius and round ends: solids of revolution lying down, legs, handles, stems,
            thin parts (a radius of 2 px)
slab        a flat 2D outline (polygon, star, rounded rectangle, letter) extruded with a round
            bevel and a domed top: coins, phones, boxes seen from the front, cookies, badges
blob        an implicit sum of anisotropic Gaussians (some negative: dents), ray cast: animals,
            fruit, organic bodies
sheet       a height field over an outline, folded along random creases and bent: paper, bags,
            cloth (what is not a closed body but is photographed as much)
=========== ==================================================================================

Dents are then pressed into the union where it faces the camera (Gaussian pits whose normals
follow the depth exactly). Coordinates follow ``docs/conventions.md``: x = column, y = -row
(centred on the canvas), z toward the viewer, pixel units.

Everything is drawn from one ``numpy.random.Generator``, so a seed gives the same object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

__all__ = ["KINDS", "Shape", "random_shape"]

#: The kinds of main body an object is built around (the parts table above), and how often each
#: is drawn: bodies with round parts most (people photograph figurines, fruit, toys). Set by
#: judgement, not swept. The "solid" kind was added after a first network, trained without it,
#: read MIT-Berkeley's box (a benchmark object) as a dome: that test object shaped the generator
#: (docs/prior.md), though no number of it was tuned.
KINDS = ("ellipsoid", "superquadric", "solid", "tube", "slab", "blob", "sheet")
ODDS = (0.15, 0.1, 0.15, 0.15, 0.1, 0.2, 0.15)


@dataclass(frozen=True)
class Shape:
    """One object seen from the front.

    Attributes
    ----------
    depth : (S, S) float64
        z of the visible surface, NaN off the object.
    normals : (S, S, 3) float64
        Unit normals, NaN off the object.
    mask : (S, S) bool
    part : (S, S) int16
        Which part each pixel shows (-1 off the object): parts are painted apart.
    kind : str
        The main body's kind (:data:`KINDS`).
    """

    depth: np.ndarray
    normals: np.ndarray
    mask: np.ndarray
    part: np.ndarray
    kind: str


def random_shape(rng: np.random.Generator, size: int, *, kind: str | None = None) -> Shape:
    """A random object filling most of a ``size x size`` canvas.

    Parameters
    ----------
    rng : numpy.random.Generator
    size : int
        Canvas side in pixels.
    kind : str, optional
        The main body's kind (:data:`KINDS`); drawn at random when None.

    Returns
    -------
    Shape
    """
    kind = kind or KINDS[rng.choice(len(KINDS), p=ODDS)]
    grid = _Canvas(size)
    r = 0.25 * size  # room around the body for its attachments
    parts = [_BODIES[kind](rng, grid, r)]
    # attachments: legs, handles, heads, knobs (sheets and slabs take fewer)
    extra = rng.choice(
        [0, 1, 2, 3], p=[0.35, 0.3, 0.2, 0.15] if kind not in ("sheet", "slab") else [0.7, 0.2, 0.1, 0.0]
    )
    for _ in range(extra):
        attach = rng.choice(["tube", "ellipsoid", "solid", "blob"], p=[0.45, 0.3, 0.15, 0.1])
        parts.append(_BODIES[attach](rng, grid, r * rng.uniform(0.25, 0.6), near=parts[0]))
    depth, normals, part = _union(parts)
    mask = np.isfinite(depth)
    edge = mask[[0, -1]].any() or mask[:, [0, -1]].any()
    if mask.sum() < 0.02 * size * size or edge:  # the parts fell off the canvas: draw again
        return random_shape(rng, size, kind=kind)
    depth, normals = _dents(rng, grid, depth, normals, mask, r)
    # keep the largest connected piece only: a photo's mask is one object
    labels, count = ndimage.label(mask)
    if count > 1:
        keep = labels == 1 + np.argmax(ndimage.sum(mask, labels, range(1, count + 1)))
        depth[~keep], normals[~keep], part[~keep] = np.nan, np.nan, -1
        mask = keep
    return Shape(depth, normals, mask, part, kind)


class _Canvas:
    """Pixel-centre coordinates of a canvas: ``x`` (columns) and ``y = -row``, centred."""

    def __init__(self, size):
        self.size = size
        c = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
        self.x, self.y = np.meshgrid(c, -c)


@dataclass
class _Part:
    z: np.ndarray  # (S, S), -inf off the part
    n: np.ndarray  # (S, S, 3) unit normals where z is finite


def _unit(a, b, c):
    n = np.stack([a, b, c], axis=-1)
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)


def _centre(rng, grid, r, near):
    """A part's centre: the canvas centre, or a point of ``near``'s outline region."""
    if near is None:
        return rng.normal(0, 0.05 * grid.size, 2), 0.0
    rows, cols = np.nonzero(np.isfinite(near.z))
    i = rng.integers(rows.size)
    x, y = grid.x[rows[i], cols[i]], grid.y[rows[i], cols[i]]
    return np.array([x, y]), float(near.z[rows[i], cols[i]]) - rng.uniform(0.2, 0.8) * r


def _rotation(rng):
    q = rng.normal(size=4)
    a, b, c, d = q / np.linalg.norm(q)
    return np.array(
        [
            [a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)],
            [2 * (b * c + a * d), a * a - b * b + c * c - d * d, 2 * (c * d - a * b)],
            [2 * (b * d - a * c), 2 * (c * d + a * b), a * a - b * b - c * c + d * d],
        ]
    )


def _ellipsoid(rng, grid, r, near=None):
    (cx, cy), cz = _centre(rng, grid, r, near)
    radii = r * rng.uniform(0.45, 1.0, 3) * np.array([1.0, rng.uniform(0.5, 1.0), 1.0])
    rot = _rotation(rng)
    a = rot @ np.diag(radii**-2.0) @ rot.T
    dx, dy = grid.x - cx, grid.y - cy
    b = a[0, 2] * dx + a[1, 2] * dy
    c = a[0, 0] * dx * dx + 2 * a[0, 1] * dx * dy + a[1, 1] * dy * dy - 1.0
    disc = b * b - a[2, 2] * c
    inside = disc > 0
    w = (-b + np.sqrt(np.where(inside, disc, 0.0))) / a[2, 2]
    g = np.stack([dx, dy, w], axis=-1) @ a  # the quadric's gradient: a symmetric
    return _Part(np.where(inside, cz + w, -np.inf), _unit(g[..., 0], g[..., 1], g[..., 2]))


def _superquadric(rng, grid, r, near=None):
    (cx, cy), cz = _centre(rng, grid, r, near)
    a, b = r * rng.uniform(0.5, 1.0), r * rng.uniform(0.3, 1.0)
    c = r * rng.uniform(0.15, 0.9)
    p, q = rng.uniform(2.0, 10.0), rng.uniform(2.0, 10.0)
    t = rng.uniform(0, np.pi)
    u = np.cos(t) * (grid.x - cx) + np.sin(t) * (grid.y - cy)
    v = -np.sin(t) * (grid.x - cx) + np.cos(t) * (grid.y - cy)
    fu, fv = np.abs(u / a), np.abs(v / b)
    rest = 1.0 - (fu**p + fv**p)
    inside = rest > 0
    rest = np.where(inside, rest, 0.0)
    h = rest ** (1.0 / q)  # |z / c|
    gu = p * fu ** (p - 1) * np.sign(u) / a
    gv = p * fv ** (p - 1) * np.sign(v) / b
    gz = q * rest ** ((q - 1) / q) / c
    gx, gy = np.cos(t) * gu - np.sin(t) * gv, np.sin(t) * gu + np.cos(t) * gv
    return _Part(np.where(inside, cz + c * h, -np.inf), _unit(gx, gy, gz))


def _tube(rng, grid, r, near=None):
    """A sphere of radius rad(s) swept along a polyline: z = zc + sqrt(rad^2 - t^2)."""
    (cx, cy), cz = _centre(rng, grid, r, near)
    length = r * rng.uniform(0.8, 2.4) if near is None else r * rng.uniform(1.0, 2.5)
    start_angle = rng.uniform(0, 2 * np.pi)
    bend = rng.uniform(-1.0, 1.0) * rng.choice([0.0, 1.0, 3.0], p=[0.5, 0.3, 0.2])
    segments = 12
    angles = start_angle + bend * np.linspace(-0.5, 0.5, segments + 1)
    step = length / segments
    pts = np.cumsum(np.stack([np.cos(angles), np.sin(angles)], axis=1) * step, axis=0)
    pts = pts - (pts[0] if near is not None else pts.mean(axis=0)) + [cx, cy]
    base = (r if near is None else r * 1.6) * rng.uniform(0.12, 0.5)
    if near is not None and rng.random() < 0.3:
        base = rng.uniform(1.5, 4.0) * grid.size / 128  # a thin part
    amps = rng.uniform(-0.25, 0.25, 3) * (rng.random() < 0.7)
    phases = rng.uniform(0, 2 * np.pi, 3)

    def radius(s):  # s in [0, 1] along the line; positive by construction
        k = np.arange(1, 4)
        wave = np.sum(amps * np.sin(np.pi * k * s[..., None] + phases), axis=-1)
        slope = np.sum(amps * np.pi * k * np.cos(np.pi * k * s[..., None] + phases), axis=-1)
        return base * (1 + wave), base * slope

    best = np.full(grid.x.shape, np.inf)
    near_s = np.zeros_like(best)
    tx = np.zeros_like(best)
    ty = np.zeros_like(best)
    along_x = np.zeros_like(best)
    along_y = np.zeros_like(best)
    clamped = np.zeros(best.shape, bool)
    for i in range(segments):
        p0, p1 = pts[i], pts[i + 1]
        d = p1 - p0
        dx, dy = grid.x - p0[0], grid.y - p0[1]
        f = (dx * d[0] + dy * d[1]) / (d @ d)
        lo = f < 0 if i == 0 else np.zeros_like(f, bool)
        hi = f > 1 if i == segments - 1 else np.zeros_like(f, bool)
        fc = np.clip(f, 0.0, 1.0)
        ox, oy = dx - fc * d[0], dy - fc * d[1]
        dist = ox * ox + oy * oy
        better = dist < best
        best = np.where(better, dist, best)
        near_s = np.where(better, (i + fc) / segments, near_s)
        tx, ty = np.where(better, ox, tx), np.where(better, oy, ty)
        unit = d / np.linalg.norm(d)
        along_x, along_y = np.where(better, unit[0], along_x), np.where(better, unit[1], along_y)
        clamped = np.where(better, lo | hi | (f < 0) | (f > 1), clamped)
    rad, drad = radius(near_s)
    drad = np.where(clamped, 0.0, drad / length)  # d rad / d (pixels along the line)
    h2 = rad * rad - best
    inside = h2 > 0
    h = np.sqrt(np.where(inside, h2, 0.0))
    # z = zc + h with h^2 = rad(s)^2 - t^2: n ~ (t - rad rad' s_hat, h)
    nx = tx - rad * drad * along_x
    ny = ty - rad * drad * along_y
    return _Part(np.where(inside, cz + h, -np.inf), _unit(nx, ny, h))


def _outline(rng, grid, r):
    """A random flat outline (bool canvas): polygon, star, rounded rectangle or letter."""
    from PIL import Image, ImageDraw, ImageFont

    size = grid.size
    image = Image.new("L", (size, size), 0)
    draw = ImageDraw.Draw(image)
    c = size / 2 + rng.normal(0, 0.04 * size, 2)
    choice = rng.integers(4)
    if choice == 0 or choice == 1:  # polygon or star
        k = rng.integers(3, 9) if choice == 0 else 2 * rng.integers(4, 7)
        angles = (
            np.sort(rng.uniform(0, 2 * np.pi, k))
            if choice == 0
            else np.linspace(0, 2 * np.pi, k, endpoint=False)
        )
        radii = r * (
            rng.uniform(0.7, 1.1, k)
            if choice == 0
            else np.where(np.arange(k) % 2, rng.uniform(0.4, 0.7), 1.0)
        )
        draw.polygon([(c[0] + q * np.cos(a), c[1] + q * np.sin(a)) for a, q in zip(angles, radii)], fill=255)
    elif choice == 2:  # rounded rectangle, turned
        w, h = r * rng.uniform(0.5, 1.0), r * rng.uniform(0.3, 1.0)
        draw.rounded_rectangle(
            [c[0] - w, c[1] - h, c[0] + w, c[1] + h], radius=rng.uniform(0, min(w, h)), fill=255
        )
        image = image.rotate(rng.uniform(0, 180), resample=Image.BILINEAR, center=tuple(c))
    else:  # a letter or digit
        font = ImageFont.load_default(size=float(2.2 * r))
        text = "ABCDEFGHKLMNOPRSTUVWXYZ02345689&#@"[rng.integers(34)]
        draw.text(tuple(c), text, fill=255, font=font, anchor="mm")
        image = image.rotate(rng.uniform(-40, 40), resample=Image.BILINEAR, center=tuple(c))
    inside = np.asarray(image) > 127
    return ndimage.binary_opening(inside, iterations=1) if inside.sum() > 50 else inside


def _slab(rng, grid, r, near=None):
    """An extruded outline with a quarter-round bevel of radius b and a domed top."""
    inside = _outline(rng, grid, r)
    (cx, cy), cz = _centre(rng, grid, r, near)
    if near is not None:  # a badge or a knob on the body
        inside = ndimage.shift(inside.astype(np.float32), (-cy, cx), order=0) > 0.5
        cz += r
    # smoothed a little, so that the bevel's normals (from its gradient) have no pixel steps
    d = ndimage.gaussian_filter(ndimage.distance_transform_edt(inside), 0.7)
    g_row, g_col = np.gradient(d)
    gx, gy = g_col, -g_row
    deepest = float(d.max()) or 1.0  # an outline shifted off the canvas leaves nothing
    b = max(deepest * rng.uniform(0.15, 0.8), 1.0)
    dome = rng.uniform(0, 0.3) * deepest
    u = np.clip(1 - d / b, 0, 1)
    z = b * np.sqrt(1 - u * u) + dome * (1 - (1 - d / deepest) ** 2)
    slope = np.where(u > 0, u, 0.0)  # dz/dd * sqrt(1 - u^2) of the bevel
    cap = np.sqrt(1 - u * u)
    dslope = slope + cap * dome * 2 * (1 - d / deepest) / deepest
    return _Part(np.where(inside, cz + z, -np.inf), _unit(-dslope * gx, -dslope * gy, cap))


def _blob(rng, grid, r, near=None):
    """``F(p) = T - sum_i w_i exp(-|A_i (p - c_i)|^2)`` ray cast from the front."""
    (cx, cy), cz = _centre(rng, grid, r, near)
    k = rng.integers(2, 7)
    centres = np.c_[rng.normal(0, 0.45 * r, (k, 2)), rng.normal(0, 0.15 * r, k)] + [cx, cy, cz]
    spreads = []
    for _ in range(k):
        rot = _rotation(rng)
        spreads.append(rot @ np.diag((r * rng.uniform(0.25, 0.6, 3)) ** -2.0) @ rot.T)
    spreads = np.array(spreads)
    weights = np.where(rng.random(k) < 0.15, -0.6, 1.0)
    weights[0] = 1.0
    level = 0.4

    def implicit(p):
        total = level
        for c, a, w in zip(centres, spreads, weights):
            dx, dy, dz = p[..., 0] - c[0], p[..., 1] - c[1], p[..., 2] - c[2]
            q = a[0, 0] * dx * dx + a[1, 1] * dy * dy + a[2, 2] * dz * dz
            q += 2 * (a[0, 1] * dx * dy + a[0, 2] * dx * dz + a[1, 2] * dy * dz)
            total = total - w * np.exp(-q)
        return total

    # rays only where some Gaussian reaches: within 3 of its widest spread of its centre
    reach = 3.0 * np.sqrt(1.0 / np.linalg.eigvalsh(spreads)[:, 0])

    def gradient(p):
        grad = np.zeros_like(p)
        for c, a, w in zip(centres, spreads, weights):
            ad = (p - c) @ a
            grad += 2 * w * np.exp(-np.sum((p - c) * ad, axis=-1))[..., None] * ad
        return grad

    return _cast(implicit, gradient, grid, centres, reach)


def _cast(implicit, gradient, grid, centres, reach):
    """The front surface of ``implicit`` < 0 seen along -z: rays from above the highest of the
    spheres ``(centres, reach)`` that bound it, sampled every 1.5 px, then bisected."""
    from shadeform.synth import first_crossing

    near_any = np.zeros(grid.x.shape, bool)
    for (px, py, _), q in zip(centres, reach):
        near_any |= (grid.x - px) ** 2 + (grid.y - py) ** 2 < q * q
    top = np.max(centres[:, 2] + reach)
    rows, cols = np.nonzero(near_any)
    origin = np.stack([grid.x[rows, cols], grid.y[rows, cols], np.full(rows.size, top)], axis=-1)
    depth_range = np.full(rows.size, top - np.min(centres[:, 2] - reach))
    hit = first_crossing(implicit, origin, np.array([0.0, 0.0, -1.0]), depth_range, step=1.5)
    z = np.full(grid.x.shape, np.nan)
    z[rows, cols] = top - hit
    grad = gradient(np.stack([grid.x, grid.y, np.nan_to_num(z)], axis=-1))
    return _Part(np.where(np.isfinite(z), z, -np.inf), _unit(grad[..., 0], grad[..., 1], grad[..., 2]))


def _solid(rng, grid, r, near=None):
    """A superquadric ``(|x/a|^s + |y/b|^s)^(t/s) + |z/c|^t = 1`` turned any way in 3D and ray
    cast: boxes and dice seen corner-on, cylinders (s = 2) seen from above, tins, pills."""
    (cx, cy), cz = _centre(rng, grid, r, near)
    centre = np.array([cx, cy, cz])
    radii = r * rng.uniform(0.45, 1.0, 3)
    s = 2.0 if rng.random() < 0.4 else rng.uniform(2.0, 12.0)
    t = rng.uniform(2.0, 12.0)
    rot = _rotation(rng)

    def parts(p):
        q = (p - centre) @ rot / radii  # the object's frame, scaled to the unit shape
        a = np.abs(q)
        u = a[..., 0] ** s + a[..., 1] ** s
        return q, a, u

    def implicit(p):
        _, a, u = parts(p)
        return u ** (t / s) + a[..., 2] ** t - 1.0

    def gradient(p):
        q, a, u = parts(p)
        common = t * np.maximum(u, 1e-300) ** (t / s - 1.0)
        g = np.stack(
            [
                common * a[..., 0] ** (s - 1) * np.sign(q[..., 0]),
                common * a[..., 1] ** (s - 1) * np.sign(q[..., 1]),
                t * a[..., 2] ** (t - 1) * np.sign(q[..., 2]),
            ],
            axis=-1,
        )
        return (g / radii) @ rot.T  # back to the camera frame

    return _cast(implicit, gradient, grid, centre[None], np.array([1.8 * radii.max()]))


def _sheet(rng, grid, r, near=None):
    """Paper or a bag: a folded, bent height field over an outline."""
    if rng.random() < 0.5:
        inside = _outline(rng, grid, r * 1.1)
    else:  # a bag: a soft rectangle with a wavy edge
        w, h = r * rng.uniform(0.6, 1.0), r * rng.uniform(0.6, 1.1)
        wave = 0.04 * r * np.sin(grid.x / r * rng.uniform(4, 12) + rng.uniform(0, 6))
        inside = (np.abs(grid.x) < w) & (np.abs(grid.y + wave) < h)
    x, y = grid.x, grid.y
    z = np.zeros_like(x)
    zx = np.zeros_like(x)
    zy = np.zeros_like(x)
    for _ in range(rng.integers(0, 5)):  # creases: mountain or valley folds, softened
        a = rng.uniform(0, np.pi)
        ux, uy = np.cos(a), np.sin(a)
        s = ux * x + uy * y - rng.normal(0, 0.4 * r)
        amp = rng.uniform(-0.35, 0.35)
        soft = rng.uniform(1.0, 0.15 * r)
        root = np.sqrt(s * s + soft * soft)
        z += amp * root
        zx += amp * s / root * ux
        zy += amp * s / root * uy
    curve = rng.normal(0, 0.6 / r, 3)  # a bend, a pillow's bulge
    z += 0.5 * (curve[0] * x * x + curve[1] * y * y) + curve[2] * x * y
    zx += curve[0] * x + curve[2] * y
    zy += curve[1] * y + curve[2] * x
    if rng.random() < 0.5:  # soft wrinkles
        kx, ky = rng.normal(0, 6.0 / r, 2)
        amp = rng.uniform(0, 0.04) * r
        ph = kx * x + ky * y + rng.uniform(0, 6)
        z += amp * np.sin(ph)
        zx += amp * np.cos(ph) * kx
        zy += amp * np.cos(ph) * ky
    pillow = ndimage.distance_transform_edt(inside)
    height = rng.uniform(0, 0.5) * np.sqrt(np.maximum(pillow, 0) * pillow.max())
    g_row, g_col = np.gradient(height)
    return _Part(np.where(inside, z + height, -np.inf), _unit(-zx - g_col, -zy + g_row, np.ones_like(z)))


_BODIES = {
    "ellipsoid": _ellipsoid,
    "superquadric": _superquadric,
    "tube": _tube,
    "slab": _slab,
    "solid": _solid,
    "blob": _blob,
    "sheet": _sheet,
}


def _union(parts):
    zs = np.stack([p.z for p in parts])
    which = np.argmax(zs, axis=0)
    depth = np.take_along_axis(zs, which[None], 0)[0]
    normals = np.take_along_axis(np.stack([p.n for p in parts]), which[None, ..., None], 0)[0]
    mask = np.isfinite(depth)
    depth = np.where(mask, depth, np.nan)
    normals[~mask] = np.nan
    return depth, normals, np.where(mask, which, -1).astype(np.int16)


def _dents(rng, grid, depth, normals, mask, r):
    """Press Gaussian pits (or raise bumps) where the surface faces the camera."""
    candidates = np.flatnonzero(mask & (normals[..., 2] > 0.8))
    count = rng.choice([0, 1, 2, 4], p=[0.5, 0.2, 0.2, 0.1])
    if candidates.size == 0 or count == 0:
        return depth, normals
    slope_x = -normals[..., 0] / normals[..., 2]
    slope_y = -normals[..., 1] / normals[..., 2]
    pressed = np.zeros_like(depth)
    for i in rng.choice(candidates, count):
        cx, cy = grid.x.flat[i], grid.y.flat[i]
        sigma = r * rng.uniform(0.05, 0.2)
        amp = sigma * rng.uniform(-0.8, 0.4)  # mostly dents
        dx, dy = grid.x - cx, grid.y - cy
        g = amp * np.exp(-(dx * dx + dy * dy) / (2 * sigma * sigma))
        depth = depth + g
        pressed += np.abs(g)
        slope_x = slope_x - g * dx / sigma**2
        slope_y = slope_y - g * dy / sigma**2
    touched = mask & (pressed > 1e-6 * r)
    dented = _unit(-slope_x, -slope_y, np.ones_like(slope_x))
    normals = np.where(touched[..., None], dented, normals)
    return depth, normals
