"""A set of photos under known lights, for photometric stereo: files in, arrays out.

One folder in the DiLiGenT layout (``filenames.txt``, ``light_directions.txt``,
``light_intensities.txt``, ``mask.png``; all optional but the lights), or the photos themselves
with a light file. Light and intensity files: ``docs/conventions.md`` ("Light").

Encoding: a folder that holds ``light_intensities.txt`` is radiometrically calibrated data, linear
whatever its bit depth (light strengths divide only linear values), so its photos are kept as
stored; otherwise the first photo decides for the whole set as :func:`shadeform.io.images.read_photo`
does for one photo (8-bit sRGB, decoded to linear; 16-bit and float linear); ``linear=`` overrides.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shadeform.errors import InputError
from shadeform.io.images import CALIBRATED_SET_FILE, CHANNELS, load_mask, read_photo, select_channel

#: Files a folder's photos may be, when it has no filenames.txt.
PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")


@dataclass(frozen=True)
class PhotoSet:
    """Photos of one still object and what is known of their lights.

    Attributes
    ----------
    paths : tuple of Path
        The photos, in the order of the rows below.
    images : (N, H, W, 3) or (N, H, W) float32
        The photos, linear, in [0, 1]: all three channels (gray photos repeated in each), or the
        one channel asked for.
    lights : (N, 3) float64
        Direction toward each photo's light, as written in the file.
    intensities : (N,) or (N, 3) float64 or None
        Each photo's light strength, if a file gave them; None also when one channel was asked
        for and the strengths were per channel (``R G B``): the photos were divided by them first.
    mask : (H, W) bool or None
        The object, if a mask was given or found in the folder.
    bits : int
        Bits per sample of the photos' files (the same for all).
    encoding : {"srgb", "linear"}
        How the files hold their values; ``"srgb"`` ones were decoded to linear.
    encoding_from : {"file", "set", "user"}
        Decided by the first photo's bit depth, by the set being radiometrically calibrated (a
        ``light_intensities.txt`` beside the photos), or given by the caller (``linear=``).
    channel : str
        ``"rgb"`` (all three channels), ``"gray"`` (gray photos) or the channel asked for.
    """

    paths: tuple[Path, ...]
    images: np.ndarray
    lights: np.ndarray
    intensities: np.ndarray | None
    mask: np.ndarray | None
    bits: int
    encoding: str
    encoding_from: str
    channel: str

    @property
    def info(self) -> dict:
        """The decisions made in reading the photos, as plain values (``Reconstruction.info``)."""
        return {
            "bits": self.bits,
            "encoding": self.encoding,
            "encoding_from": self.encoding_from,
            "channel": self.channel,
            "channel_from": "auto" if self.channel in ("rgb", "gray") else "user",
        }


def load_photo_set(
    sources,
    *,
    lights: str | os.PathLike | None = None,
    intensities: str | os.PathLike | None = None,
    mask: str | os.PathLike | None = None,
    linear: bool | None = None,
    channel: str | None = None,
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
    linear : bool or None
        None: decide (see the module's notes: a folder with ``light_intensities.txt`` is linear,
        else the first photo's bit depth decides for the set). True: the photos hold linear
        values; keep them. False: they are sRGB-encoded; decode them.
    channel : {None, "auto", "luma", "r", "g", "b", "max"}
        None or ``"auto"``: keep the colour (photometric stereo solves colour photos on all three
        channels). Otherwise that one channel (:func:`shadeform.io.images.select_channel`), taken
        after dividing by per-channel light strengths.

    Returns
    -------
    PhotoSet

    Raises
    ------
    InputError
        No light file, fewer than three photos, a light or intensity file that is not one row of
        numbers per photo, a photo that cannot be read or differs in size or bit depth from the
        first, a mask of another size, or an unknown ``channel`` or ``linear``.
    """
    from shadeform._checks import check_choice

    if channel == "auto":
        channel = None
    if channel is not None:
        check_choice(channel, CHANNELS, "channel")  # before any photo is read
    sources = list(map(Path, sources))
    photos, lights, intensities, mask = _find(sources, lights, intensities, mask)
    directions = read_rows(lights, "lights", len(photos), (3,))
    strengths = read_rows(intensities, "intensities", len(photos), (1, 3)) if intensities else None
    decided = "user"
    if linear is None and len(sources) == 1 and (sources[0] / CALIBRATED_SET_FILE).is_file():
        linear, decided = True, "set"
    images = None
    colour = False
    for i, photo in enumerate(photos):
        read = read_photo(photo, linear=linear)
        height, width, planes = read.pixels.shape
        if images is None:
            # the first photo decides for the set, and sets the size and bit depth of the rest
            first, bits, encoding = read, read.bits, read.encoding
            if linear is None:
                linear, decided = encoding == "linear", read.encoding_from
            images = np.empty((len(photos), height, width, 3), dtype=np.float32)
        elif (height, width) != first.image.shape:
            raise InputError(
                f"photo '{photo}' is {width}x{height} but '{photos[0]}' is "
                f"{first.image.shape[1]}x{first.image.shape[0]}; give photos from one still camera"
            )
        elif read.bits != bits:
            raise InputError(
                f"photo '{photo}' is {read.bits}-bit but '{photos[0]}' is {bits}-bit; give photos "
                "from one camera, saved alike"
            )
        images[i] = read.pixels  # a gray photo fills all three channels
        colour = colour or planes == 3
    if channel is not None:
        if strengths is not None and strengths.ndim == 2:
            if not (np.isfinite(strengths).all() and (strengths > 0).all()):
                raise InputError(
                    f"intensities file '{intensities}' must hold finite positive numbers (each light's strength)"
                )
            images /= strengths[:, None, None, :].astype(np.float32)
            strengths = None
        images = np.stack([select_channel(image, channel) for image in images])
    found_mask = load_mask(mask, shape=images.shape[1:3]) if mask is not None else None
    return PhotoSet(
        tuple(photos),
        images,
        directions,
        strengths,
        found_mask,
        bits=bits,
        encoding=encoding,
        encoding_from=decided,
        channel=channel or ("rgb" if colour else "gray"),
    )


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
