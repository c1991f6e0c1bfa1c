"""A set of photos under known lights, for photometric stereo: files in, arrays out.

One folder in the DiLiGenT layout (``filenames.txt``, ``light_directions.txt``,
``light_intensities.txt``, ``mask.png``; all optional but the lights), or the photos themselves
with a light file. Light and intensity files: ``docs/conventions.md`` ("Light").
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shadeform.errors import InputError
from shadeform.io.images import load_image_rgb, load_mask

#: Files a folder's photos may be, when it has no filenames.txt.
PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")


@dataclass(frozen=True)
class PhotoSet:
    """Photos of one still object and what is known of their lights.

    Attributes
    ----------
    paths : tuple of Path
        The photos, in the order of the rows below.
    images : (N, H, W, 3) float32
        The photos in [0, 1] (linear if ``srgb`` was asked for when loading).
    lights : (N, 3) float64
        Direction toward each photo's light, as written in the file.
    intensities : (N,) or (N, 3) float64 or None
        Each photo's light strength, if a file gave them.
    mask : (H, W) bool or None
        The object, if a mask was given or found in the folder.
    """

    paths: tuple[Path, ...]
    images: np.ndarray
    lights: np.ndarray
    intensities: np.ndarray | None
    mask: np.ndarray | None


def load_photo_set(
    sources,
    *,
    lights: str | os.PathLike | None = None,
    intensities: str | os.PathLike | None = None,
    mask: str | os.PathLike | None = None,
    srgb: bool = False,
) -> PhotoSet:
    """Read photos and their light files.

    Parameters
    ----------
    sources : sequence of path-like
        One folder (DiLiGenT layout), or three or more photos.
    lights, intensities, mask : path-like, optional
        Light file (``x y z`` per photo), intensity file (one number or ``R G B`` per photo) and
        mask image; for a folder they default to its ``light_directions.txt``,
        ``light_intensities.txt`` and ``mask.png`` when present.
    srgb : bool
        Undo the sRGB encoding of the photos (:func:`shadeform.preprocess.srgb_to_linear`).

    Returns
    -------
    PhotoSet

    Raises
    ------
    InputError
        No light file, fewer than three photos, a light or intensity file that is not one row of
        numbers per photo, a photo that cannot be read or differs in size from the first, or a
        mask of another size.
    """
    from shadeform.preprocess import srgb_to_linear

    photos, lights, intensities, mask = _find(list(map(Path, sources)), lights, intensities, mask)
    directions = read_rows(lights, "lights", len(photos), (3,))
    strengths = read_rows(intensities, "intensities", len(photos), (1, 3)) if intensities else None
    first = None
    images = None
    for i, photo in enumerate(photos):
        image = load_image_rgb(photo)
        if srgb:
            image = srgb_to_linear(image).astype(np.float32)
        if first is None:
            first = image.shape
            images = np.empty((len(photos),) + first, dtype=np.float32)
        elif image.shape != first:
            raise InputError(
                f"photo '{photo}' is {image.shape[1]}x{image.shape[0]} but "
                f"'{photos[0]}' is {first[1]}x{first[0]}; give photos from one still "
                "camera"
            )
        images[i] = image
    found_mask = load_mask(mask, shape=first) if mask is not None else None
    return PhotoSet(tuple(photos), images, directions, strengths, found_mask)


def read_rows(path: str | os.PathLike, what: str, count: int, columns: tuple[int, ...]) -> np.ndarray:
    """A text file of ``count`` rows of numbers (whitespace or commas; blank lines and ``#``
    lines skipped) as ``(count, columns)``, or ``(count,)`` for one column."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8").replace(",", " ")
        values = np.array(
            [
                [float(v) for v in line.split()]
                for line in text.splitlines()
                if line.strip() and not line.lstrip().startswith("#")
            ]
        )
    except FileNotFoundError:
        raise InputError(f"{what} file '{path}' does not exist; check the path") from None
    except (ValueError, UnicodeDecodeError):
        raise InputError(f"{what} file '{path}' must hold numbers only, one row per photo") from None
    if values.ndim != 2 or values.shape[0] != count or values.shape[1] not in columns:
        shape = "x".join(str(n) for n in values.shape) or "empty"
        wanted = " or ".join(str(c) for c in columns)
        raise InputError(
            f"{what} file '{path}' must have {count} rows (one per photo) of {wanted} numbers, found {shape}"
        )
    return values[:, 0] if values.shape[1] == 1 else values


def _find(sources: list[Path], lights, intensities, mask):
    """The photos and the files that describe them."""
    if len(sources) == 1 and sources[0].is_dir():
        folder = sources[0]
        listing = folder / "filenames.txt"
        if listing.is_file():
            photos = [folder / name for name in listing.read_text(encoding="utf-8").split()]
        else:
            photos = sorted(
                p
                for p in folder.iterdir()
                if p.suffix.lower() in PHOTO_SUFFIXES
                and p.stem.lower() not in ("mask", "normal_gt", "normal_map")
            )
        found = {
            name: folder / name
            for name in ("light_directions.txt", "light_intensities.txt", "mask.png")
            if (folder / name).is_file()
        }
        lights = lights or found.get("light_directions.txt")
        intensities = intensities or found.get("light_intensities.txt")
        mask = mask or found.get("mask.png")
        if lights is None:
            raise InputError(f"folder '{folder}' has no light_directions.txt; give --lights FILE")
    else:
        photos = sources
        if lights is None:
            raise InputError("give --lights FILE: one direction toward the light per photo (x y z)")
    if len(photos) < 3:
        raise InputError(f"photometric stereo needs at least 3 photos, got {len(photos)}")
    return photos, lights, intensities, mask
