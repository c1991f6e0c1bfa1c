"""The real photographs of ``../shared/data/real`` as single-photo shape-from-shading cases.

One case per object: the photo whose calibrated (DiLiGenT) or fitted (MIT-Berkeley) light is
nearest the viewing direction, as the baselines of ``../shared/data/README.md`` were measured:

- DiLiGenT (cat, pot1, bear, buddha, reading, cow; ball kept apart as a sanity check): the 8-bit
  *linear* crop, each channel divided by its light intensity, then Rec. 601 luma. The objects keep
  their painted albedo, highlights and shadows.
- MIT-Berkeley (12 objects): the 16-bit linear photo's luma divided by the reflectance's luma
  (the set's shading, with the photo's highlights and noise), as in the README's table; and, apart,
  the raw photo (``raw=True``), albedo and all.

Ground-truth normals are in the project frame (x right, y up, z toward the viewer). Used by
``bench_real.py`` and by the tests that hold real objects to bars of their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io

from shadeform.io.images import load_mask, load_pixels

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real"
DILIGENT = ("cat", "pot1", "bear", "buddha", "reading", "cow")
MIT = (
    "apple", "box", "cup1", "deer", "dinosaur", "frog1",
    "panther", "paper1", "pear", "phone", "raccoon", "sun",
)  # fmt: skip
LUMA = np.array([0.299, 0.587, 0.114])


@dataclass(frozen=True, eq=False)
class Case:
    """One photo with its truth.

    Attributes
    ----------
    name, set : str
        Object and data set ("diligent" or "mit").
    image : (H, W) float64
        Linear intensities (luma), >= 0.
    mask : (H, W) bool
    light : (3,) float64
        Unit direction toward the light (calibrated or fitted).
    normals : (H, W, 3) float64
        Ground-truth unit normals, NaN where unknown.
    valid : (H, W) bool
        Mask pixels with a ground-truth normal.
    """

    name: str
    set: str
    image: np.ndarray
    mask: np.ndarray
    light: np.ndarray
    normals: np.ndarray
    valid: np.ndarray


def available() -> bool:
    """Whether ``../shared/data/real`` is there."""
    return DATA.is_dir()


def _photo(folder: Path, slant: float) -> tuple[str, np.ndarray, int]:
    """The photo whose light is nearest ``slant`` degrees off the camera (0: the most frontal)."""
    lights = np.loadtxt(folder / "light_directions.txt", comments="#", ndmin=2)
    names = (folder / "filenames.txt").read_text().split()
    slants = np.degrees(np.arccos(np.clip(lights[:, 2] / np.linalg.norm(lights, axis=1), -1.0, 1.0)))
    index = int(np.argmin(np.abs(slants - slant)))
    return names[index], lights[index] / np.linalg.norm(lights[index]), index


def _valid(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(np.nan_to_num(normals), axis=-1)
    return mask & np.isfinite(normals).all(axis=-1) & (length > 0.5)


def diligent(name: str, *, slant: float = 0.0) -> Case:
    """The DiLiGenT object ``name``: its photo lit nearest ``slant`` degrees off the camera (0:
    the most frontal)."""
    folder = DATA / "diligent" / name
    file, light, index = _photo(folder, slant)
    strength = np.loadtxt(folder / "light_intensities.txt", ndmin=2)[index]
    rgb = load_pixels(folder / file).astype(np.float64) / strength
    image = rgb @ LUMA
    mask = load_mask(folder / "mask.png", shape=image.shape)
    normals = scipy.io.loadmat(folder / "Normal_gt.mat")["Normal_gt"].astype(np.float64)
    valid = _valid(normals, mask)
    normals[~valid] = np.nan
    return Case(name, "diligent", image, mask, light, normals, valid)


def mit(name: str, *, raw: bool = False, slant: float = 0.0) -> Case:
    """The MIT-Berkeley object ``name`` (its photo lit nearest ``slant`` degrees off the camera),
    divided by its reflectance unless ``raw``."""
    folder = DATA / "mit-berkeley" / name
    file, light, _ = _photo(folder, slant)
    image = load_pixels(folder / file).astype(np.float64) @ LUMA
    mask = load_mask(folder / "mask.png", shape=image.shape)
    if not raw:
        albedo = load_pixels(folder / "reflectance.png").astype(np.float64) @ LUMA
        mask = mask & (albedo > 0)
        image = np.where(mask, image / np.where(albedo > 0, albedo, 1.0), 0.0)
    normals = normals_of_height(scipy.io.loadmat(folder / "Z.mat")["depth"].astype(np.float64))
    valid = _valid(normals, mask)
    normals[~valid] = np.nan
    return Case(name + ("-raw" if raw else ""), "mit", image, mask, light, normals, valid)


def normals_of_height(z: np.ndarray) -> np.ndarray:
    """Unit normals ``(-dz/dcol, +dz/drow, 1)`` of a height map in pixels (``np.gradient``)."""
    d_row, d_col = np.gradient(z)
    normals = np.dstack([-d_col, d_row, np.ones_like(z)])
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def cases(*, raw_mit: bool = False, slant: float = 0.0) -> list[Case]:
    """Every case: the six DiLiGenT objects, then the twelve MIT-Berkeley ones, each with its
    photo lit nearest ``slant`` degrees off the camera."""
    return [diligent(name, slant=slant) for name in DILIGENT] + [
        mit(name, raw=raw_mit, slant=slant) for name in MIT
    ]


def angular_error(normals: np.ndarray, case: Case) -> float:
    """Mean angle (degrees) between ``normals`` and the truth over the case's valid pixels."""
    a = normals[case.valid]
    b = case.normals[case.valid]
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    cos = np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)
    return float(np.degrees(np.arccos(cos)).mean())


def light_error(light, case: Case) -> float:
    """Angle (degrees) between an estimated light and the case's."""
    light = np.asarray(light, dtype=np.float64)
    cos = float(light @ case.light / np.linalg.norm(light))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
