"""A photo set where one photo goes: ``relief``, ``maps`` and each view of ``fuse`` take a folder
holding photos of one object under several lights and make their model from its photometric
stereo (:func:`shadeform.photometric.reconstruct_stereo`), whose normals are far better than one
photo's shading gives (``benchmarks/results/stereo.md``). One :class:`Reconstruction` whatever
made it: the relief, the maps and the fusion do not know the difference."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from shadeform.cli._shell import stage
from shadeform.errors import InputError
from shadeform.reconstruction import Reconstruction

#: The input of the commands that take a photo or a photo set.
PhotoOrSetArgument = Annotated[
    Path,
    typer.Argument(
        help="Photo of the object (PNG, JPEG, TIFF, BMP), or a folder holding a photo set (photos under "
        "several lights with their light_directions.txt or .lp file, or an RTIBuilder project folder): "
        "its photometric stereo, as `shadeform stereo` makes it, far better normals than one photo's.",
        show_default=False,
    ),
]

#: The lights a set's folder may hold: the DiLiGenT layout's file, else one RTI ``.lp`` file.
LIGHT_FILE = "light_directions.txt"


def is_photo_set(path: Path) -> bool:
    """Whether the command line named a folder (a photo set) rather than a photo."""
    return Path(path).is_dir()


def set_lights(folder: Path) -> Path | None:
    """The folder's light file: ``light_directions.txt`` (read by the set's loader itself: None
    here), else an RTIBuilder project's ``.lp`` (:func:`shadeform.photoset.rtibuilder_project`),
    else the folder's one ``.lp`` file (RTI)."""
    from shadeform.photoset import rtibuilder_project

    if (folder / LIGHT_FILE).is_file():
        return None
    project = rtibuilder_project(folder)
    if project is not None:
        return project[0]
    found = sorted(path for path in folder.iterdir() if path.suffix.lower() == ".lp" and path.is_file())
    if len(found) == 1:
        return found[0]
    if not found:
        raise InputError(
            f"folder '{folder}' has no {LIGHT_FILE} and no .lp file: a photo set needs its lights "
            "(one direction per photo); add the file, or make the model with `shadeform stereo`, which "
            "also reads the lights from a shiny sphere (--sphere) or the photos (--unknown-lights)"
        )
    raise InputError(
        f"folder '{folder}' has {len(found)} .lp files ({', '.join(p.name for p in found)}); keep the one "
        "that belongs to these photos"
    )


def load_set(folder: Path, *, mask, linear, channel, max_pixels):
    """A photo set's folder read (:func:`shadeform.photoset.load_photo_set`), its lights from the
    folder's light file (:func:`set_lights`)."""
    from shadeform.photoset import load_photo_set

    folder = Path(folder)
    return load_photo_set(
        [folder], lights=set_lights(folder), mask=mask, linear=linear, channel=channel, max_pixels=max_pixels
    )


def solve_set(photos, *, integrator=None) -> Reconstruction:
    """A photo set's photometric stereo with the default model; ``integrator`` None is the
    stereo's own (Poisson). The reconstruction's ``info`` holds the photos' reading under
    ``"photo"``."""
    from shadeform.photometric import reconstruct_stereo

    options = {} if integrator is None else {"integrator": integrator}
    rec = reconstruct_stereo(
        photos.images, photos.lights, photos.mask, intensities=photos.intensities, **options
    )
    return replace(rec, info={**rec.info, "photo": photos.info})


def reconstruct_set(
    err, timings, folder: Path, *, mask, linear, channel, max_pixels, integrator=None
) -> tuple[dict, Reconstruction]:
    """:func:`load_set` and :func:`solve_set`, each under a spinner: the photos' reading
    (``PhotoSet.info``) and the reconstruction."""
    with stage(err, f"loading the photo set {escape(str(folder))}", timings, "load"):
        photos = load_set(folder, mask=mask, linear=linear, channel=channel, max_pixels=max_pixels)
    with stage(err, f"photometric stereo of {len(photos.paths)} photos", timings, "reconstruct"):
        rec = solve_set(photos, integrator=integrator)
    return photos.info, rec


def reconstruct_source(
    err, timings, source: Path, *, channel, linear, max_pixels, mask, grid=None, **options
) -> tuple[dict, tuple[int, int], Reconstruction]:
    """A photo (:func:`shadeform.cli.photos.reconstruct_photo`, ``options`` and ``grid`` its) or a
    photo set's folder (:func:`reconstruct_set`; of ``options`` only ``integrator`` applies, the
    others refused before by :func:`refuse_one_photo_options`) reconstructed: the reading's info,
    the input's (rows, cols) and the reconstruction."""
    from shadeform.cli.photos import reconstruct_photo

    if is_photo_set(source):
        reading, rec = reconstruct_set(
            err,
            timings,
            source,
            mask=mask,
            linear=linear,
            channel=channel,
            max_pixels=max_pixels,
            integrator=options.get("integrator"),
        )
        return reading, rec.shape, rec
    photo, rec = reconstruct_photo(
        err,
        timings,
        source,
        channel=channel,
        linear=linear,
        max_pixels=max_pixels,
        mask=mask,
        grid=grid,
        **options,
    )
    return photo.info, photo.image.shape, rec
