"""Real objects pasted on generated backgrounds: photos whose true mask is known.

The objects are the real photographs of ``../shared/data/real`` (DiLiGenT's frontal crop and
MIT-Berkeley's ``original.png``, both linear camera data) cut out with their true masks; the
backgrounds are generated here, seeded, in linear light, one function per family:

- ``table``: a grey table top, a brightness gradient and a vignette, mottling and sensor noise;
- ``paper``: a white sheet under a lamp (a smooth fall-off), fibres, a faint fold;
- ``wood``: wood grain, warped growth rings and fine streaks along the grain, any direction;
- ``cloth``: woven cloth, a thread pattern under a plaid of two or three colours;
- ``granite`` (held out: no rule or constant was chosen looking at it): a speckled stone counter,
  chips of several sizes and tones;
- ``tiles`` and ``newsprint`` (held out, written in session 24 after every choice of the mask was
  made, and run once): glazed ceramic tiles with grout lines and a sheen, and a newspaper page,
  columns of printed lines and a photo block;
- ``marble`` and ``carpet`` (held out, written in session 27 before the texture features of the
  cut were tried on any background and not looked at until the features were chosen): a pale
  polished stone with soft clouds and thin dark veins, and a low-pile carpet of two or three yarn
  colours mixed at the pixel scale in a large pattern.

:func:`composite` pastes the object's own pixels (its light, albedo, highlights) with an
anti-aliased edge and an optional soft shadow, and :func:`as_file` saves the picture as an 8-bit
sRGB PNG or JPEG and reads it back as the package reads a user's photo. Used by
``bench_masks.py`` and ``tests/test_masks_composites.py``.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image
from scipy import ndimage as ndi

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real"
DILIGENT = ("ball", "bear", "buddha", "cat", "cow", "pot1", "reading")
MIT = (
    "apple", "box", "cup1", "deer", "dinosaur", "frog1",
    "panther", "paper1", "pear", "phone", "raccoon", "sun",
)  # fmt: skip
TRAINING = ("table", "paper", "wood", "cloth")
HELD_OUT = ("granite", "tiles", "newsprint", "marble", "carpet")
FAMILIES = TRAINING + HELD_OUT


@dataclass(frozen=True, eq=False)
class Cutout:
    """An object's photo cut to its mask's bounding box: linear RGB (H, W, 3) and its mask."""

    name: str
    rgb: np.ndarray
    mask: np.ndarray


def available() -> bool:
    """Whether ``../shared/data/real`` is there."""
    return DATA.is_dir()


def cutout(name: str, *, size: int = 240) -> Cutout:
    """A real object (DiLiGenT's photo lit nearest the camera, or MIT-Berkeley's
    ``original.png``), exposed so that its 99th luma percentile is 0.8, its longer side ``size``."""
    from shadeform.io.images import load_mask, load_pixels

    if name in DILIGENT:
        folder = DATA / "diligent" / name
        lights = np.loadtxt(folder / "light_directions.txt")
        photo = folder / f"{int(np.argmax(lights[:, 2])) + 1:03d}.png"
    else:
        folder = DATA / "mit-berkeley" / name
        photo = folder / "original.png"
    rgb = load_pixels(photo, linear=True)[..., :3].astype(np.float64)
    mask = load_mask(folder / "mask.png")
    rows, cols = np.nonzero(mask)
    rgb = rgb[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    mask = mask[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    scale = size / max(mask.shape)
    shape = (max(1, round(mask.shape[1] * scale)), max(1, round(mask.shape[0] * scale)))
    rgb = np.stack(
        [
            np.asarray(Image.fromarray(rgb[..., c].astype(np.float32)).resize(shape, Image.BILINEAR))
            for c in range(3)
        ],
        axis=-1,
    ).astype(np.float64)
    cover = np.asarray(Image.fromarray(mask.astype(np.float32)).resize(shape, Image.BILINEAR))
    mask = cover >= 0.5
    luma = rgb @ np.array([0.299, 0.587, 0.114])
    rgb = np.clip(rgb * 0.8 / max(float(np.percentile(luma[mask], 99)), 1e-6), 0, 1)
    return Cutout(name, rgb, mask)


# --- backgrounds --------------------------------------------------------------------------------


def _noise(rng, shape, sigma) -> np.ndarray:
    """Smooth noise of unit standard deviation at a scale of ``sigma`` pixels."""
    field = ndi.gaussian_filter(rng.standard_normal(shape), sigma, mode="wrap")
    return field / (field.std() + 1e-12)


def _grid(shape):
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return rows / max(shape), cols / max(shape)


def _light(rng, shape, gradient, vignette) -> np.ndarray:
    """A smooth light fall-off: a gradient in a random direction and a vignette."""
    y, x = _grid(shape)
    angle = rng.uniform(0, 2 * np.pi)
    ramp = (x - x.mean()) * np.cos(angle) + (y - y.mean()) * np.sin(angle)
    centre = (rng.uniform(0.3, 0.7) * y.max(), rng.uniform(0.3, 0.7) * x.max())
    radius2 = ((y - centre[0]) ** 2 + (x - centre[1]) ** 2) / max(y.max(), x.max()) ** 2
    return (1 + gradient * ramp / (np.abs(ramp).max() + 1e-12)) * (1 - vignette * radius2)


def table(rng, shape) -> np.ndarray:
    level = rng.uniform(0.08, 0.3)
    tint = 1 + rng.uniform(-0.06, 0.06, 3)
    mottle = 1 + 0.05 * _noise(rng, shape, 12) + 0.03 * _noise(rng, shape, 2)
    grey = level * _light(rng, shape, rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.6)) * mottle
    return grey[..., None] * tint + rng.normal(0, 0.006, shape + (3,))


def paper(rng, shape) -> np.ndarray:
    level = rng.uniform(0.6, 0.9)
    tint = 1 + rng.uniform(-0.03, 0.03, 3)
    fibres = 1 + 0.015 * ndi.gaussian_filter(rng.standard_normal(shape), (0.6, 2.5))
    y, x = _grid(shape)
    fold_at = rng.uniform(0.2, 0.8) * x.max()
    fold = 1 - 0.06 * np.exp(-(((x - fold_at) * max(shape)) ** 2) / 18)
    white = level * _light(rng, shape, rng.uniform(0.1, 0.35), rng.uniform(0.1, 0.4)) * fibres * fold
    return white[..., None] * tint + rng.normal(0, 0.008, shape + (3,))


def wood(rng, shape) -> np.ndarray:
    y, x = _grid(shape)
    angle = rng.uniform(0, np.pi)
    along = x * np.cos(angle) + y * np.sin(angle)
    across = -x * np.sin(angle) + y * np.cos(angle)
    warp = 0.04 * _noise(rng, shape, 40) + 0.01 * _noise(rng, shape, 10)
    rings = np.sin(2 * np.pi * (across * rng.uniform(6, 14) + warp * 8 + 0.15 * along)) * 0.5 + 0.5
    rings = rings ** rng.uniform(1.5, 4)
    streak_sigma = (0.7, 25.0) if abs(np.cos(angle)) > abs(np.sin(angle)) else (25.0, 0.7)
    streaks = ndi.gaussian_filter(rng.standard_normal(shape), streak_sigma)
    streaks /= streaks.std() + 1e-12
    base = np.array([0.42, 0.22, 0.09]) * rng.uniform(0.5, 1.2)
    dark = base * rng.uniform(0.35, 0.6)
    tone = np.clip(rings + 0.15 * streaks, 0, 1)[..., None]
    wood_rgb = base + (dark - base) * tone
    light = _light(rng, shape, rng.uniform(0.1, 0.3), rng.uniform(0.1, 0.3))
    return wood_rgb * light[..., None] * (1 + 0.04 * streaks[..., None]) + rng.normal(0, 0.006, shape + (3,))


def cloth(rng, shape) -> np.ndarray:
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    period = rng.uniform(3, 6)
    warp = np.sin(2 * np.pi * cols / period)
    weft = np.sin(2 * np.pi * rows / period)
    threads = 0.5 + 0.25 * np.where(
        np.sin(np.pi * (rows // (period / 2) + cols // (period / 2))) >= 0, warp, weft
    )
    colours = rng.uniform(0.04, 0.6, (3, 3))
    stripe = rng.uniform(15, 60)
    band_x = (np.floor(cols / stripe) % 3).astype(int)
    band_y = (np.floor(rows / (stripe * rng.uniform(0.7, 1.3))) % 3).astype(int)
    plaid = 0.5 * (colours[band_x] + colours[band_y])
    light = _light(rng, shape, rng.uniform(0.1, 0.4), rng.uniform(0.1, 0.4))
    weave = plaid * (0.75 + 0.5 * threads)[..., None] * light[..., None]
    return weave + rng.normal(0, 0.008, shape + (3,))


def granite(rng, shape) -> np.ndarray:
    base = rng.uniform(0.1, 0.45) * (1 + rng.uniform(-0.1, 0.1, 3))
    stone = np.ones(shape + (3,)) * base
    for sigma, share, tone in ((0.8, 0.25, 0.4), (1.6, 0.12, 1.8), (3.0, 0.05, 0.25)):
        field = _noise(rng, shape, sigma)
        chips = field > np.quantile(field, 1 - share)
        colour = base * tone * (1 + rng.uniform(-0.2, 0.2, 3))
        stone[chips] = colour
    light = _light(rng, shape, rng.uniform(0.1, 0.4), rng.uniform(0.1, 0.4))
    return stone * light[..., None] + rng.normal(0, 0.006, shape + (3,))


def tiles(rng, shape) -> np.ndarray:
    size = rng.uniform(20, 60)
    angle = rng.uniform(-0.15, 0.15)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    u = cols * np.cos(angle) + rows * np.sin(angle)
    v = -cols * np.sin(angle) + rows * np.cos(angle)
    cell_u, cell_v = np.floor(u / size), np.floor(v / size)
    base = rng.uniform(0.1, 0.7) * (1 + rng.uniform(-0.25, 0.25, 3))
    # each tile its own glaze: a small shift of tone; the grout a line of another colour
    shift = np.sin(cell_u * 12.9898 + cell_v * 78.233 + rng.uniform(0, 6)) * 0.06
    colour = base[None, None, :] * (1 + shift[..., None])
    grout_width = rng.uniform(1.0, 3.0)
    grout = (np.minimum(u % size, v % size) < grout_width)[..., None]
    grout_colour = base * rng.uniform(0.3, 1.6) * np.array([1.0, 1.0, 1.0])
    picture = np.where(grout, grout_colour, colour)
    y, x = _grid(shape)
    sheen = 0.25 * np.exp(
        -(((x - rng.uniform(0.2, 0.8) * x.max()) ** 2 + (y - rng.uniform(0.2, 0.8) * y.max()) ** 2) / 0.05)
    )
    light = _light(rng, shape, rng.uniform(0.1, 0.4), rng.uniform(0.1, 0.4))
    return picture * light[..., None] + sheen[..., None] + rng.normal(0, 0.006, shape + (3,))


def newsprint(rng, shape) -> np.ndarray:
    paper = rng.uniform(0.5, 0.8) * np.array([1.0, 0.97, 0.9])
    ink = np.full(shape, 1.0)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    line = rng.uniform(5, 9)  # the line pitch of the print, pixels
    column = rng.uniform(60, 140)
    in_text = ((rows % line) < line * 0.55) & ((cols % column) < column * 0.9)
    words = ndi.gaussian_filter(rng.standard_normal(shape), (0.5, 2.0)) > 0.1  # letters and word gaps
    ink[in_text & words] = rng.uniform(0.15, 0.35)
    top, left = int(rng.uniform(0, 0.6) * shape[0]), int(rng.uniform(0, 0.6) * shape[1])
    photo = _noise(rng, shape, 6) * 0.25 + 0.5  # a halftone-less photo block
    block = (slice(top, top + shape[0] // 3), slice(left, left + shape[1] // 3))
    ink[block] = np.clip(photo[block], 0.1, 0.9)
    light = _light(rng, shape, rng.uniform(0.1, 0.35), rng.uniform(0.1, 0.4))
    return paper * (ink * light)[..., None] + rng.normal(0, 0.008, shape + (3,))


def marble(rng, shape) -> np.ndarray:
    """A polished stone: a pale ground, soft clouds and thin dark veins that wander across it."""
    y, x = _grid(shape)
    ground = rng.uniform(0.45, 0.85) * (1 + rng.uniform(-0.08, 0.08, 3))
    clouds = 1 + 0.06 * _noise(rng, shape, 25)
    veins = np.zeros(shape)
    for _ in range(int(rng.integers(2, 5))):
        angle = rng.uniform(0, np.pi)
        along = x * np.cos(angle) + y * np.sin(angle) + 0.08 * _noise(rng, shape, 30)
        offset = rng.uniform(along.min(), along.max())
        width = rng.uniform(0.002, 0.008)
        veins = np.maximum(veins, np.exp(-((along - offset) ** 2) / (2 * width**2)))
    vein_colour = ground * rng.uniform(0.3, 0.7) * (1 + rng.uniform(-0.1, 0.1, 3))
    stone = ground * clouds[..., None] * (1 - veins[..., None]) + vein_colour * veins[..., None]
    light = _light(rng, shape, rng.uniform(0.1, 0.3), rng.uniform(0.1, 0.3))
    return stone * light[..., None] + rng.normal(0, 0.006, shape + (3,))


def carpet(rng, shape) -> np.ndarray:
    """A low-pile carpet: fibres of two or three yarn colours mixed at the pixel scale, in
    patches of a pattern a few hundred pixels across."""
    yarns = rng.uniform(0.05, 0.6, (3, 3))
    pattern = _noise(rng, shape, rng.uniform(20, 50))
    which = np.digitize(pattern, [-0.4, 0.4])  # three regions of the pattern
    fibres = rng.integers(0, 3, shape)
    mix = np.where(rng.uniform(size=shape) < 0.6, which, fibres)  # most fibres follow the pattern
    colour = yarns[mix] * (0.8 + 0.4 * rng.uniform(size=shape))[..., None]
    pile = ndi.gaussian_filter(colour, (0.7, 0.7, 0))
    light = _light(rng, shape, rng.uniform(0.1, 0.4), rng.uniform(0.1, 0.4))
    return pile * light[..., None] + rng.normal(0, 0.006, shape + (3,))


BACKGROUNDS = {
    "table": table,
    "paper": paper,
    "wood": wood,
    "cloth": cloth,
    "granite": granite,
    "tiles": tiles,
    "newsprint": newsprint,
    "marble": marble,
    "carpet": carpet,
}


# --- the picture --------------------------------------------------------------------------------


def composite(obj: Cutout, family: str, seed: int, *, shadow: bool | None = None):
    """``obj`` pasted on a background of ``family``: linear RGB (H, W, 3) in [0, 1] and the true
    mask. The margin round the object (20-50 % of its longer side on each side), its place, the
    background's draw and the shadow (half the cases when ``shadow`` is None) follow ``seed``."""
    rng = np.random.default_rng(seed)
    height, width = obj.mask.shape
    side = max(height, width)
    top, bottom, left, right = (int(rng.uniform(0.2, 0.5) * side) for _ in range(4))
    shape = (height + top + bottom, width + left + right)
    background = BACKGROUNDS[family](rng, shape)
    mask = np.zeros(shape, dtype=bool)
    mask[top : top + height, left : left + width] = obj.mask
    rgb = np.zeros(shape + (3,))
    rgb[top : top + height, left : left + width] = obj.rgb
    if shadow if shadow is not None else rng.uniform() < 0.5:
        offset = rng.uniform(0.02, 0.06, 2) * side * rng.choice([-1, 1], 2)
        cast = ndi.shift(mask.astype(np.float64), offset, order=1)
        cast = ndi.gaussian_filter(cast, rng.uniform(0.03, 0.08) * side)
        background = background * (1 - rng.uniform(0.2, 0.45) * cast)[..., None]
    alpha = ndi.gaussian_filter(mask.astype(np.float64), 0.6)  # an anti-aliased edge
    alpha[mask] = np.maximum(alpha[mask], 0.5)
    alpha[~mask] = np.minimum(alpha[~mask], 0.49)
    picture = alpha[..., None] * rgb + (1 - alpha[..., None]) * background
    return np.clip(picture, 0, 1), mask


def as_file(rgb: np.ndarray, kind: str, *, quality: int = 90) -> np.ndarray:
    """``rgb`` (linear) saved as an 8-bit sRGB ``kind`` ("png" or "jpeg") in memory and read back
    as the package reads a user's photo: linear RGB (H, W, 3)."""
    from shadeform.io.images import load_pixels, srgb_encode

    encoded = np.round(np.clip(srgb_encode(rgb), 0, 1) * 255).astype(np.uint8)
    buffer = io.BytesIO()
    if kind == "jpeg":
        Image.fromarray(encoded).save(buffer, format="JPEG", quality=quality)
    else:
        Image.fromarray(encoded).save(buffer, format="PNG")
    return load_pixels(buffer.getvalue())[..., :3].astype(np.float64)


def interior_point(mask: np.ndarray) -> tuple[int, int]:
    """The mask's pixel farthest from its outline: where a user clicks the object."""
    distance = ndi.distance_transform_edt(np.pad(mask, 1))[1:-1, 1:-1]
    row, col = np.unravel_index(int(np.argmax(distance)), mask.shape)
    return int(row), int(col)


def padded_box(mask: np.ndarray, pad: float = 0.05) -> tuple[int, int, int, int]:
    """The mask's bounding box ``(top, left, bottom, right)`` (bottom and right exclusive), padded
    by ``pad`` of its size on each side and kept in the picture: a user's drawn box."""
    rows, cols = np.nonzero(mask)
    dr = int(round(pad * (np.ptp(rows) + 1)))
    dc = int(round(pad * (np.ptp(cols) + 1)))
    return (
        max(0, rows.min() - dr),
        max(0, cols.min() - dc),
        min(mask.shape[0], rows.max() + 1 + dr),
        min(mask.shape[1], cols.max() + 1 + dc),
    )
