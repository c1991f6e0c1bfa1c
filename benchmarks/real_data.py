"""The real photographs of ``../shared/data/real`` as single-photo shape-from-shading cases.

One case per object: the photo whose calibrated (DiLiGenT) or fitted (MIT-Berkeley) light is
nearest the viewing direction, as the baselines of ``../shared/data/README.md`` were measured:

- DiLiGenT (cat, pot1, bear, buddha, reading, cow; ball kept apart as a sanity check): the 8-bit
  *linear* crop, each channel divided by its light intensity, then Rec. 601 luma. The objects keep
  their painted albedo, highlights and shadows.
- MIT-Berkeley (12 objects): the 16-bit linear photo's luma divided by the reflectance's luma
  (the set's shading, with the photo's highlights and noise), as in the README's older table; and,
  apart, the raw photo (``raw=True``), albedo and all.
- MIT-Berkeley as a user photographs it (:func:`mit_photo`, SIRFS's protocol): the luma of
  ``original.png``, albedo, print and gloss kept, scaled by its 99.9th percentile in the mask, with
  the light of ``shading_light.txt``.

Ground-truth normals are in the project frame (x right, y up, z toward the viewer); MIT cases also
carry the true height (``Z.mat``). The scores of SIRFS's benchmark (Barron & Malik, TPAMI 2015) are
:func:`n_mae` and :func:`z_mae`, summarised over objects by :func:`geometric_mean`. Used by
``bench_real.py`` and by the tests that hold real objects to bars of their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io

from shadeform.io.images import load_mask, load_pixels
from shadeform.metrics import angular_error as _angles
from shadeform.metrics import normals_of_height

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
    depth : (H, W) float64 or None
        Ground-truth height in pixels (larger = nearer the viewer), NaN off ``valid``; None where
        the set has none aligned with the photo (the DiLiGenT crops).
    """

    name: str
    set: str
    image: np.ndarray
    mask: np.ndarray
    light: np.ndarray
    normals: np.ndarray
    valid: np.ndarray
    depth: np.ndarray | None = None


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
    return _mit_case(name + ("-raw" if raw else ""), folder, image, mask, light)


def mit_photo(name: str, *, slant: float | None = None) -> Case:
    """The MIT-Berkeley object ``name`` as a user photographs it (SIRFS's protocol).

    Parameters
    ----------
    name : str
        One of :data:`MIT`.
    slant : float or None
        None: ``original.png`` (the object's albedo, print and gloss under the lab light) with the
        light of ``shading_light.txt``; a number: the light photo lit nearest that many degrees
        off the camera, with its fitted light.

    Returns
    -------
    Case
        The photo's luma divided by its 99.9th percentile inside the mask (so about ``[0, 1]``
        whatever the exposure), albedo kept.
    """
    folder = DATA / "mit-berkeley" / name
    if slant is None:
        file = "original.png"
        light = np.loadtxt(folder / "shading_light.txt", comments="#")
        light = light / np.linalg.norm(light)
    else:
        file, light, _ = _photo(folder, slant)
    image = load_pixels(folder / file).astype(np.float64) @ LUMA
    mask = load_mask(folder / "mask.png", shape=image.shape)
    image = image / np.percentile(image[mask], 99.9)
    return _mit_case(name, folder, image, mask, light)


def _mit_case(name: str, folder: Path, image: np.ndarray, mask: np.ndarray, light: np.ndarray) -> Case:
    """A case of ``image`` with the truth of the MIT-Berkeley ``folder`` (normals and height of ``Z.mat``)."""
    depth = scipy.io.loadmat(folder / "Z.mat")["depth"].astype(np.float64)
    normals = normals_of_height(depth)
    valid = _valid(normals, mask)
    normals[~valid] = np.nan
    return Case(name, "mit", image, mask, light, normals, valid, np.where(valid, depth, np.nan))


def cases(*, raw_mit: bool = False, slant: float = 0.0) -> list[Case]:
    """Every case: the six DiLiGenT objects, then the twelve MIT-Berkeley ones, each with its
    photo lit nearest ``slant`` degrees off the camera."""
    return [diligent(name, slant=slant) for name in DILIGENT] + [
        mit(name, raw=raw_mit, slant=slant) for name in MIT
    ]


def angular_error(normals: np.ndarray, case: Case) -> float:
    """Mean angle (degrees) between ``normals`` and the truth over the case's valid pixels
    (:func:`n_mae` in degrees)."""
    return float(np.degrees(n_mae(normals, case.normals, case.valid)))


def n_mae(normals: np.ndarray, truth: np.ndarray, where: np.ndarray) -> float:
    """SIRFS's N-MAE: the mean angle in radians between ``normals`` and ``truth``.

    Parameters
    ----------
    normals, truth : (H, W, 3) array_like
        Estimated and true normals (any length).
    where : (H, W) bool
        The pixels to measure; those where either normal is not finite are left out.

    Returns
    -------
    float
        Radians, in ``[0, pi]``.
    """
    normals = np.asarray(normals, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    both = where & np.isfinite(normals).all(axis=-1) & np.isfinite(truth).all(axis=-1)
    return float(np.radians(_angles(normals, truth, both)))


def z_mae(depth: np.ndarray, truth: np.ndarray, where: np.ndarray) -> float:
    """SIRFS's Z-MAE: the mean absolute height error after the best (median) offset.

    Parameters
    ----------
    depth, truth : (H, W) array_like
        Estimated and true heights, in pixels.
    where : (H, W) bool
        The pixels to measure; those where either height is not finite are left out.

    Returns
    -------
    float
        ``mean |d - median(d)|`` of ``d = depth - truth``, in pixels (orthographic shape from
        shading knows the height only up to an offset; the median is the offset that minimises
        the mean absolute error).
    """
    depth = np.asarray(depth, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    both = where & np.isfinite(depth) & np.isfinite(truth)
    difference = depth[both] - truth[both]
    return float(np.mean(np.abs(difference - np.median(difference))))


def geometric_mean(values) -> float:
    """The geometric mean of positive ``values`` (how SIRFS's benchmark averages errors over
    objects: one easy object does not hide a failed one)."""
    return float(np.exp(np.mean(np.log(np.asarray(values, dtype=np.float64)))))


def light_error(light, case: Case) -> float:
    """Angle (degrees) between an estimated light and the case's."""
    light = np.asarray(light, dtype=np.float64)
    cos = float(light @ case.light / np.linalg.norm(light))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
