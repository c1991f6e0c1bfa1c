"""Photos of the generated objects as people take them: paint, print, gloss, shadows, a camera.

:func:`random_photo` lights a :class:`~shadeform.prior.shapes.Shape` and photographs it:

- **albedo** that varies over the object: each part its own paint, then stripes, patches,
  printed text and logos, painted dots and strokes, fine grain;
- **light** over the range real photos have (slant 0-75 degrees off the camera, any tilt), a
  Lambertian term with its attached shadow, an ambient term (sky, walls, interreflections), a
  gloss lobe (Blinn-Phong, white), shadows cast by the object on itself;
- **background**: black, a flat colour, a gradient or a texture, seen where the mask is off;
- **camera**: exposure with clipped highlights, shot and read noise, then either linear data
  (16-bit, as a lab camera) or an sRGB 8-bit file, sometimes JPEG-compressed, read back as the
  loader reads it (sRGB decoded, so a camera's tone curve other than sRGB stays in);
- **mask** as a user gives it: often exact, sometimes grown or shrunk by a pixel or two.

Everything is drawn from one ``numpy.random.Generator``: a seed gives the same photo.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from shadeform.io.images import srgb_encode
from shadeform.preprocess import srgb_to_linear
from shadeform.prior.shapes import Shape

__all__ = ["Photo", "random_light", "random_photo"]

_LETTERS = "ABCDEFGHIJKLMNOPQRSTUVWXYZ abcdefghijklmnopqrstuvwxyz 0123456789 &%-."


@dataclass(frozen=True)
class Photo:
    """One generated photo and its truth.

    Attributes
    ----------
    image : (S, S) float32
        Linear brightness as :func:`shadeform.load_image` would give it (>= 0).
    mask : (S, S) bool
        The mask a user would give (not always exact).
    normals : (S, S, 3) float32
        True unit normals, NaN off the object.
    light : (3,) float64
        Unit vector toward the light.
    """

    image: np.ndarray
    mask: np.ndarray
    normals: np.ndarray
    light: np.ndarray


def random_light(rng: np.random.Generator) -> np.ndarray:
    """A direction toward the light: slant 0-75 degrees (a third of them near the camera)."""
    slant = np.radians(rng.uniform(0, 15) if rng.random() < 0.3 else rng.uniform(10, 75))
    tilt = rng.uniform(0, 2 * np.pi)
    return np.array([np.sin(slant) * np.cos(tilt), np.sin(slant) * np.sin(tilt), np.cos(slant)])


def random_photo(rng: np.random.Generator, shape: Shape) -> Photo:
    """Light, paint and photograph ``shape`` (see the module docstring).

    Parameters
    ----------
    rng : numpy.random.Generator
    shape : Shape

    Returns
    -------
    Photo
    """
    mask = shape.mask
    n = np.nan_to_num(shape.normals)
    light = random_light(rng)
    albedo = _albedo(rng, shape)
    lambert = np.maximum(n @ light, 0.0)
    seen = _lit(shape.depth, light) if rng.random() < 0.8 else np.ones(mask.shape)
    ambient = rng.uniform(0.0, 0.3) ** 1.5
    image = albedo * (lambert * seen + ambient)
    if rng.random() < 0.5:  # gloss
        half = light + [0.0, 0.0, 1.0]
        half /= np.linalg.norm(half)
        shine = rng.uniform(5, 150)
        image = image + rng.uniform(0.05, 0.8) * (np.maximum(n @ half, 0) ** shine) * seen * (lambert > 0)
    image = np.where(mask, image, _background(rng, mask.shape, light))
    image = _camera(rng, image, mask)
    return Photo(image.astype(np.float32), _user_mask(rng, mask), shape.normals.astype(np.float32), light)


def _lit(depth, light):
    """1 where the surface sees the light, 0 in the shadow the object casts on itself.

    March from every pixel toward the light over the depth map, one pixel at a time: a point is
    shadowed where a surface further along stands above the ray (a height field's shadow).
    """
    flat = np.hypot(light[0], light[1])
    if flat < 1e-3:
        return np.ones(depth.shape)
    # per pixel of the march: columns +lx/flat, rows -ly/flat, the ray rises lz/flat
    step_col, step_row, rise = light[0] / flat, -light[1] / flat, light[2] / flat
    height, width = depth.shape
    z = np.where(np.isfinite(depth), depth, -np.inf)
    rows, cols = np.nonzero(np.isfinite(depth))
    start = z[rows, cols]
    alive = np.arange(rows.size)
    shadow = np.zeros(depth.shape, bool)
    top = np.nanmax(depth)
    k = 1
    while alive.size:
        k += 1
        r = np.rint(rows[alive] + k * step_row).astype(int)
        c = np.rint(cols[alive] + k * step_col).astype(int)
        ray = start[alive] + k * rise
        inside = (r >= 0) & (r < height) & (c >= 0) & (c < width) & (ray < top)
        alive, r, c, ray = alive[inside], r[inside], c[inside], ray[inside]
        blocked = z[r, c] > ray + 1.0
        shadow[rows[alive[blocked]], cols[alive[blocked]]] = True
        alive = alive[~blocked]
    soft = ndimage.gaussian_filter((~shadow).astype(np.float64), 0.7)
    return soft


def _albedo(rng, shape):
    """Paint: a colour per part, then patterns, print and grain; linear albedo in [0.02, 1]."""
    size = shape.mask.shape
    parts = max(int(shape.part.max()) + 1, 1)
    base = rng.uniform(0.15, 0.95, parts) ** 1.5
    if rng.random() < 0.3:  # one paint over the whole object
        base[:] = base[0]
    albedo = np.where(shape.part >= 0, base[np.maximum(shape.part, 0)], base[0])
    rows, cols = np.indices(size)
    for _ in range(rng.choice([0, 1, 2, 3], p=[0.25, 0.35, 0.25, 0.15])):
        pattern = rng.integers(5)
        if pattern == 0:  # stripes
            a = rng.uniform(0, np.pi)
            period = rng.uniform(4, 0.5 * size[0])
            wave = np.sin(2 * np.pi * (np.cos(a) * cols + np.sin(a) * rows) / period + rng.uniform(0, 6))
            where = wave > rng.uniform(-0.5, 0.8)
        elif pattern == 1:  # patches
            noise = ndimage.gaussian_filter(rng.standard_normal(size), rng.uniform(2, 0.15 * size[0]))
            where = noise > np.quantile(noise, rng.uniform(0.4, 0.9))
        elif pattern == 2:  # printed text
            where = _print(rng, size)
        elif pattern == 3:  # logos: discs, rings, polygons
            where = _logos(rng, size)
        else:  # painted dots and strokes (eyes, spots, lines)
            where = _dots(rng, size)
        albedo = np.where(where, rng.uniform(0.02, 1.0) ** 1.5, albedo)
    if rng.random() < 0.6:  # grain: paper, wood, skin, fabric
        grain = ndimage.gaussian_filter(rng.standard_normal(size), rng.uniform(0.5, 3))
        albedo = albedo * np.exp(rng.uniform(0, 0.25) * grain / max(grain.std(), 1e-9))
    return np.clip(albedo, 0.02, 1.0)


def _print(rng, size):
    """Lines of text at random sizes and angles (bool canvas)."""
    from PIL import Image, ImageDraw, ImageFont

    image = Image.new("L", (size[1], size[0]), 0)
    draw = ImageDraw.Draw(image)
    height = rng.uniform(5, 0.2 * size[0])
    font = ImageFont.load_default(size=float(height))
    for _ in range(rng.integers(1, 5)):
        text = "".join(rng.choice(list(_LETTERS), rng.integers(3, 14)))
        xy = (rng.uniform(0, size[1] * 0.7), rng.uniform(0, size[0] * 0.9))
        draw.text(xy, text, fill=255, font=font)
    image = image.rotate(rng.uniform(-30, 30) if rng.random() < 0.7 else rng.uniform(0, 360))
    return np.asarray(image) > 127


def _logos(rng, size):
    from PIL import Image, ImageDraw

    image = Image.new("L", (size[1], size[0]), 0)
    draw = ImageDraw.Draw(image)
    for _ in range(rng.integers(1, 4)):
        cx, cy = rng.uniform(0.2, 0.8) * size[1], rng.uniform(0.2, 0.8) * size[0]
        r = rng.uniform(3, 0.2 * size[0])
        kind = rng.integers(3)
        if kind == 0:
            draw.ellipse([cx - r, cy - r, cx + r, cy + r], fill=255)
        elif kind == 1:
            draw.ellipse([cx - r, cy - r, cx + r, cy + r], outline=255, width=max(1, int(r / 4)))
        else:
            k = rng.integers(3, 7)
            angles = rng.uniform(0, 2 * np.pi) + np.arange(k) * 2 * np.pi / k
            draw.polygon([(cx + r * np.cos(a), cy + r * np.sin(a)) for a in angles], fill=255)
    return np.asarray(image) > 127


def _dots(rng, size):
    from PIL import Image, ImageDraw

    image = Image.new("L", (size[1], size[0]), 0)
    draw = ImageDraw.Draw(image)
    for _ in range(rng.integers(1, 12)):
        x, y = rng.uniform(0, size[1]), rng.uniform(0, size[0])
        if rng.random() < 0.6:
            r = rng.uniform(1, 6)
            draw.ellipse([x - r, y - r, x + r, y + r], fill=255)
        else:
            points = [(x, y)]
            for _ in range(rng.integers(2, 6)):
                x, y = x + rng.normal(0, 8), y + rng.normal(0, 8)
                points.append((x, y))
            draw.line(points, fill=255, width=int(rng.integers(1, 4)))
    return np.asarray(image) > 127


def _background(rng, size, light):
    rows, cols = np.indices(size) / max(size)
    kind = rng.integers(4)
    if kind == 0:
        return np.zeros(size)
    level = rng.uniform(0, 0.8) ** 2
    if kind == 1:
        return np.full(size, level)
    if kind == 2:
        return level * (1 + rng.uniform(-0.8, 0.8) * (rows - 0.5) + rng.uniform(-0.8, 0.8) * (cols - 0.5))
    texture = ndimage.gaussian_filter(rng.standard_normal(size), rng.uniform(1, 10))
    return np.clip(level * (1 + texture / max(texture.std(), 1e-9) * 0.3) * light[2], 0, None)


def _camera(rng, image, mask):
    """Exposure, noise and the file: linear 16-bit, or sRGB 8-bit (maybe JPEG) read back."""
    bright = np.percentile(image[mask], 99) if mask.any() else 1.0
    image = image * rng.uniform(0.6, 1.3) / max(bright, 1e-6)
    gain = rng.uniform(0, 0.02) ** 2 * 10  # shot noise: variance proportional to the signal
    read = rng.uniform(0, 0.01)
    image = image + rng.standard_normal(image.shape) * np.sqrt(gain * np.maximum(image, 0) + read**2)
    image = np.clip(image, 0.0, 1.0)
    if rng.random() < 0.5:
        return image  # linear camera data (16-bit, or 8-bit linear as the benchmark sets)
    from PIL import Image

    tone = rng.uniform(0.8, 1.25)  # a camera's curve is sRGB only roughly
    encoded = srgb_encode(image**tone)
    file = io.BytesIO()
    picture = Image.fromarray(np.round(encoded * 255).astype(np.uint8))
    if rng.random() < 0.6:
        picture.save(file, format="JPEG", quality=int(rng.integers(50, 96)))
    else:
        picture.save(file, format="PNG")
    read_back = np.asarray(Image.open(file), dtype=np.float64) / 255.0
    return srgb_to_linear(read_back)


def _user_mask(rng, mask):
    """The mask as a user gives it: exact half the time, else grown or shrunk by 1-2 pixels."""
    if rng.random() < 0.5:
        return mask.copy()
    steps = int(rng.integers(1, 3))
    if rng.random() < 0.5:
        return ndimage.binary_dilation(mask, iterations=steps)
    shrunk = ndimage.binary_erosion(mask, iterations=steps)
    return shrunk if shrunk.sum() > 0.5 * mask.sum() else mask.copy()
