"""A set of photos under known lights, for photometric stereo: files in, arrays out.

One folder in the DiLiGenT layout (``filenames.txt``, ``light_directions.txt``,
``light_intensities.txt``, ``mask.png``; all optional but the lights), or the photos themselves
with a light file: the project's (``x y z`` per photo) or an RTI ``.lp`` file (a count, then
``name x y z`` per photo; its names are matched to the photos'). Light and intensity files:
``docs/conventions.md`` ("Light"). An RTIBuilder project folder is a set too: its photos in
``jpeg-exports/``, named by the one ``.lp`` file in ``assembly-files/`` (:func:`rtibuilder_project`).

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

from shadeform._checks import regular_file
from shadeform.errors import InputError
from shadeform.io.images import (
    CALIBRATED_SET_FILE,
    CHANNELS,
    MAX_PIXELS,
    load_mask,
    read_photo,
    reading_info,
    select_channel,
)

#: Files a folder's photos may be, when it has no filenames.txt.
PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")

#: RTIBuilder's project layout: the folder of the photos it fits, and the folder of its light
#: file (the ``.lp``, whose photo paths are often absolute Windows paths into the first).
RTIBUILDER_PHOTOS = "jpeg-exports"
RTIBUILDER_LIGHTS = "assembly-files"


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
    lights : (N, 3) float64 or None
        Direction toward each photo's light, as written in the file (None: unknown).
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
    sphere : (3,) float64 or None
        The shiny sphere the lights were read from (column, row, radius), when they were.
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
    sphere: np.ndarray | None = None

    @property
    def info(self) -> dict:
        """The decisions made in reading the photos, as plain values (``Reconstruction.info``)."""
        return reading_info(self, "auto" if self.channel in ("rgb", "gray") else "user")


def load_photo_set(
    sources,
    *,
    lights: str | os.PathLike | None = None,
    intensities: str | os.PathLike | None = None,
    mask: str | os.PathLike | None = None,
    linear: bool | None = None,
    channel: str | None = None,
    sphere=None,
    max_pixels: int = MAX_PIXELS,
) -> PhotoSet:
    """Read photos and their light files, or read their lights from a shiny sphere in them.

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
    sphere : "auto", "unknown" or (3,) array_like, optional
        Read the lights and their relative strengths from a shiny sphere in the photos
        (:func:`shadeform.light.sphere.calibrate_lights`): ``"auto"`` finds it, or its circle
        ``(column, row, radius)``; ``"unknown"``: no light file and no sphere, the lights are left
        to the photometric stereo (``lights`` is then None). Not with ``lights`` or
        ``intensities``; a folder's light files are then ignored, and its mask (or the caller's)
        is kept.
    max_pixels : int
        Refuse a photo or mask that declares more pixels than this, before decoding it
        (:func:`shadeform.io.images.read_photo`).

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
    if sphere is not None and (lights is not None or intensities is not None):
        raise InputError("give the lights either as a file or as a sphere in the photos, not both")
    photos, lights, intensities, mask = _find(sources, lights, intensities, mask, need_lights=sphere is None)
    if sphere is not None:
        directions = strengths = None  # read from the photos below
    elif Path(lights).suffix.lower() == ".lp":
        directions = match_lp(photos, *read_lp(lights), lights)
    else:
        directions = read_rows(lights, "lights", len(photos), (3,))
    if sphere is None:
        strengths = read_rows(intensities, "intensities", len(photos), (1, 3)) if intensities else None
    decided = "user"
    if linear is None and len(sources) == 1 and (sources[0] / CALIBRATED_SET_FILE).is_file():
        linear, decided = True, "set"
    images, bits, encoding, read_from, colour = read_photos(photos, linear=linear, max_pixels=max_pixels)
    decided = read_from if linear is None else decided
    circle = None
    if sphere is not None and not (isinstance(sphere, str) and sphere == "unknown"):
        from shadeform.light.sphere import calibrate_lights

        found = calibrate_lights(
            images, sphere=None if isinstance(sphere, str) and sphere == "auto" else sphere
        )
        directions, strengths, circle = found.directions, found.strengths, found.sphere
    if channel is not None:
        if strengths is not None and strengths.ndim == 2:
            if not (np.isfinite(strengths).all() and (strengths > 0).all()):
                raise InputError(
                    f"intensities file '{intensities}' must hold finite positive numbers (each light's strength)"
                )
            images /= strengths[:, None, None, :].astype(np.float32)
            strengths = None
        images = np.stack([select_channel(image, channel) for image in images])
    found_mask = load_mask(mask, shape=images.shape[1:3], max_pixels=max_pixels) if mask is not None else None
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
        sphere=circle,
    )


def read_photos(photos, *, linear: bool | None = None, names=None, max_pixels: int | None = None):
    """Photos of one still camera as one (N, H, W, 3) float32 array (gray photos in all three
    channels), linear: the first photo decides the encoding for all when ``linear`` is None
    (:func:`shadeform.io.images.read_photo`), and sets the size and bit depth the rest must have.

    Returns
    -------
    images : (N, H, W, 3) float32
    bits : int
    encoding : {"srgb", "linear"}
        How the files hold their values.
    encoding_from : {"file", "user"}
    colour : bool
        Whether any photo has colour.

    ``photos`` are paths, or files' contents (bytes) named in messages by ``names``;
    ``max_pixels`` is :func:`shadeform.io.images.read_photo`'s (its default when None).

    Raises
    ------
    InputError
        A photo that cannot be read, or one of another size or bit depth than the first.
    """
    from shadeform.io.images import naming

    limit = {} if max_pixels is None else {"max_pixels": max_pixels}
    shown = list(photos) if names is None else list(names)
    images = None
    colour = False
    decided = "user"
    for i, photo in enumerate(photos):
        try:
            read = read_photo(photo, linear=linear, **limit)
        except InputError as err:
            if names is None:
                raise
            raise type(err)(naming(str(err), names[i])) from None
        height, width, planes = read.pixels.shape
        if images is None:
            first, bits, encoding = read, read.bits, read.encoding
            if linear is None:
                linear, decided = encoding == "linear", read.encoding_from
            images = np.empty((len(photos), height, width, 3), dtype=np.float32)
        elif (height, width) != first.image.shape:
            raise InputError(
                f"photo '{shown[i]}' is {width}x{height} but '{shown[0]}' is "
                f"{first.image.shape[1]}x{first.image.shape[0]}; give photos from one still camera"
            )
        elif read.bits != bits:
            raise InputError(
                f"photo '{shown[i]}' is {read.bits}-bit but '{shown[0]}' is {bits}-bit; give photos "
                "from one camera, saved alike"
            )
        images[i] = read.pixels  # a gray photo fills all three channels
        colour = colour or planes == 3
    return images, bits, encoding, decided, colour


def photo_files(sources) -> list[Path]:
    """The photos named by ``sources``: the files themselves, or one folder's photos (in
    ``filenames.txt``'s order when it has one, else sorted by name; masks and normal maps left
    out; an RTIBuilder project's in its ``.lp`` file's order, :func:`project_photos`)."""
    sources = list(map(Path, sources))
    if len(sources) > 1 and any(source.is_dir() for source in sources):
        raise InputError("give the photos, or one folder holding them, not both")
    if len(sources) == 1 and sources[0].is_dir():
        folder = sources[0]
        project = rtibuilder_project(folder)
        if project is not None:
            return project_photos(*project)
        listing = folder / "filenames.txt"
        if listing.is_file():
            return [folder / name for name in listing.read_text(encoding="utf-8").split()]
        return sorted(
            p
            for p in folder.iterdir()
            if p.suffix.lower() in PHOTO_SUFFIXES
            and p.stem.lower() not in ("mask", "normal_gt", "normal_map")
        )
    return sources


def read_rows(path: str | os.PathLike, what: str, count: int, columns: tuple[int, ...]) -> np.ndarray:
    """A text file of ``count`` rows of numbers (whitespace or commas; blank lines and ``#``
    comments skipped) as ``(count, columns)``, or ``(count,)`` for one column."""
    path = Path(path)
    try:
        text = regular_file(path, f"{what} file").read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{what} file '{path}' does not exist; check the path") from None
    except UnicodeDecodeError:
        raise InputError(f"{what} file '{path}' must hold numbers only, one row per photo") from None
    return parse_rows(text, what, str(path), count, columns)


def parse_rows(text: str, what: str, name: str, count: int, columns: tuple[int, ...]) -> np.ndarray:
    """:func:`read_rows` on a file's text; ``name`` is the file's name for messages. A ``#``
    starts a comment, on a line of its own or after the numbers."""
    rows = (line.split("#", 1)[0].replace(",", " ").split() for line in text.splitlines())
    try:
        values = np.array([[float(v) for v in row] for row in rows if row])
    except ValueError:
        raise InputError(f"{what} file '{name}' must hold numbers only, one row per photo") from None
    if values.ndim != 2 or values.shape[0] != count or values.shape[1] not in columns:
        shape = "x".join(str(n) for n in values.shape) or "empty"
        wanted = " or ".join(str(c) for c in columns)
        raise InputError(
            f"{what} file '{name}' must have {count} rows (one per photo) of {wanted} numbers, found {shape}"
        )
    return values[:, 0] if values.shape[1] == 1 else values


def read_lp(path: str | os.PathLike) -> tuple[list[str], np.ndarray]:
    """An RTI light-position (``.lp``) file: its photo names and their light directions (N, 3),
    normalised.

    The format: the number of photos on the first line, then one line per photo, its file name
    and ``x y z`` (x right, y up, z toward the camera, as in ``docs/conventions.md``); names may
    hold a folder (a Windows one too, as RTIBuilder writes them, spaces and all), which is
    ignored. Blank lines are skipped.

    Raises
    ------
    InputError
        A file that is missing or not in that format, or a direction that is zero or not finite.
    """
    path = Path(path)
    try:
        text = regular_file(path, "light file").read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"light file '{path}' does not exist; check the path") from None
    except UnicodeDecodeError:
        raise InputError(
            f"light file '{path}' is not text; give an .lp file (a count, then 'name x y z' per photo)"
        ) from None
    return parse_lp(text, str(path))


def parse_lp(text: str, name: str) -> tuple[list[str], np.ndarray]:
    """:func:`read_lp` on a file's text; ``name`` is the file's name for messages."""
    # the name is all but the last three fields: a Windows path may hold spaces
    lines = [line.rsplit(None, 3) for line in text.splitlines() if line.strip()]
    usage = "an .lp file holds the number of photos, then one line 'name x y z' per photo"
    try:
        count = int(lines[0][0]) if lines and len(lines[0]) == 1 else -1
        rows = [(line[0], [float(v) for v in line[1:4]]) for line in lines[1:] if len(line) == 4]
        if any(_is_number(row[0].split()[-1]) for row in rows if " " in row[0].strip()):
            raise ValueError("a fourth number, not a name with spaces")
    except ValueError:
        raise InputError(f"light file '{name}' has a line that is not 'name x y z'; {usage}") from None
    if count < 1 or len(rows) != count or len(lines) != count + 1:
        raise InputError(f"light file '{name}' does not match its own count of photos; {usage}")
    directions = np.array([row[1] for row in rows], dtype=np.float64)
    lengths = np.linalg.norm(directions, axis=1)
    if not (np.isfinite(directions).all() and (lengths > 0).all()):
        raise InputError(f"light file '{name}' has a direction that is zero or not a number")
    return [Path(row[0].replace("\\", "/")).name for row in rows], directions / lengths[:, None]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def write_lights(path: str | os.PathLike, directions, *, names=None) -> None:
    """Write light directions (N, 3), atomically: an RTI ``.lp`` file when ``path`` ends in
    ``.lp`` (``names`` are the photos' file names, in order), else the project's light file (one
    ``x y z`` row per photo)."""
    from shadeform.io.atomic import atomic_write

    directions = np.asarray(directions, dtype=np.float64)
    if Path(path).suffix.lower() == ".lp":
        if names is None or len(names) != len(directions):
            raise InputError("an .lp file names each photo; give as many names as lights")
        lines = [str(len(directions))] + [
            f"{Path(name).name} {x:.6f} {y:.6f} {z:.6f}" for name, (x, y, z) in zip(names, directions)
        ]
    else:
        lines = ["# direction toward each photo's light: x y z (x right, y up, z toward the camera)"]
        lines += [f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in directions]
    with atomic_write(path, mode="w") as handle:
        handle.write("\n".join(lines) + "\n")


def match_lp(photos, names, directions, path) -> np.ndarray:
    """The ``.lp`` file's directions in the order of ``photos`` (paths, or file names): by file
    name where every photo is named in it, else in the file's order when the counts agree."""
    photos = [Path(photo) for photo in photos]
    where = {name: i for i, name in enumerate(names)}
    if all(photo.name in where for photo in photos):
        return directions[[where[photo.name] for photo in photos]]
    if len(names) == len(photos):
        return directions
    raise InputError(
        f"light file '{path}' has {len(names)} lights for {len(photos)} photos and does not name them all; "
        "give one line per photo"
    )


def rtibuilder_project(folder: str | os.PathLike) -> tuple[Path, Path] | None:
    """An RTIBuilder project's light file and photo folder, if ``folder`` is one (or its
    ``jpeg-exports/``): ``(assembly-files/<name>.lp, jpeg-exports/)``; None for any other folder.

    Raises
    ------
    InputError
        A project whose ``assembly-files/`` holds no ``.lp`` file, or several.
    """
    folder = Path(folder)
    if folder.name.lower() == RTIBUILDER_PHOTOS and (folder.parent / RTIBUILDER_LIGHTS).is_dir():
        folder = folder.parent
    photos, assembly = folder / RTIBUILDER_PHOTOS, folder / RTIBUILDER_LIGHTS
    if not (photos.is_dir() and assembly.is_dir()):
        return None
    found = sorted(path for path in assembly.iterdir() if path.suffix.lower() == ".lp" and path.is_file())
    if len(found) == 1:
        return found[0], photos
    if not found:
        raise InputError(
            f"RTIBuilder project '{folder}' has no .lp file in {RTIBUILDER_LIGHTS}/; put the light file "
            "there (a count, then 'name x y z' per photo)"
        )
    raise InputError(
        f"RTIBuilder project '{folder}' has {len(found)} .lp files in {RTIBUILDER_LIGHTS}/ "
        f"({', '.join(p.name for p in found)}); keep the one that belongs to the photos in {RTIBUILDER_PHOTOS}/"
    )


def project_photos(lp: str | os.PathLike, folder: str | os.PathLike) -> list[Path]:
    """The photos an ``.lp`` file names, found in ``folder`` by file name (its own folders, a
    Windows machine's ones included, ignored; the case too where only that differs), in the
    file's order.

    Raises
    ------
    InputError
        A photo the file names that ``folder`` does not hold (the first few named).
    """
    folder = Path(folder)
    names, _ = read_lp(lp)
    present = {path.name: path for path in folder.iterdir() if path.is_file()}
    folded = {name.lower(): path for name, path in present.items()}
    photos = [present.get(name) or folded.get(name.lower()) for name in names]
    missing = [name for name, photo in zip(names, photos) if photo is None]
    if missing:
        shown = ", ".join(missing[:3]) + (f" and {len(missing) - 3} more" if len(missing) > 3 else "")
        raise InputError(
            f"light file '{lp}' names {len(missing)} photo{'s' if len(missing) > 1 else ''} that "
            f"'{folder}' does not hold ({shown}); copy them there or remove their lines from the .lp"
        )
    return photos


#: The ways to give a photo set's lights, in the words of the command line.
_LIGHTS_FROM = (
    "give --lights FILE (one direction toward the light per photo, x y z, or an RTI .lp file), "
    "--sphere X,Y,R or --sphere auto (a shiny sphere in the photos), or --unknown-lights"
)


def _find(sources: list[Path], lights, intensities, mask, *, need_lights=True):
    """The photos and the files that describe them."""
    photos = photo_files(sources)
    if len(photos) < 3:
        raise InputError(f"photometric stereo needs at least 3 photos, got {len(photos)}")
    if len(sources) == 1 and sources[0].is_dir():
        folder = sources[0]
        found = {
            name: folder / name
            for name in ("light_directions.txt", "light_intensities.txt", "mask.png")
            if (folder / name).is_file()
        }
        if need_lights:
            project = rtibuilder_project(folder)
            lights = lights or found.get("light_directions.txt") or (project and project[0])
            intensities = intensities or found.get("light_intensities.txt")
        mask = mask or found.get("mask.png")
        if lights is None and need_lights:
            raise InputError(f"folder '{folder}' has no light_directions.txt; {_LIGHTS_FROM}")
    elif lights is None and need_lights:
        raise InputError(f"the lights are not given; {_LIGHTS_FROM}")
    return photos, lights, intensities, mask
