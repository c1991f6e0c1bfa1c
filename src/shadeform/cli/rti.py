"""``shadeform rti``: a photo set (one still camera, one light per photo) -> the relightable file
RTIViewer opens: a polynomial texture map (``.ptm``) or hemispherical harmonics (``.rti``); or
the folder of JPEG planes Relight's web viewer and OpenLIME show in a browser (``--format web-*``)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from shadeform.cli._shell import (
    app,
    describe_photo,
    format_seconds,
    print_json,
    stage,
    stderr_console,
    stdout_console,
)
from shadeform.cli.options import MAX_PIXELS, JsonOption, LinearOption, MaxPixelsOption
from shadeform.errors import InputError
from shadeform.io.atomic import OutputSet

#: What each file suffix holds by default: RTIBuilder's usual choices.
DEFAULT_FORMAT = {".ptm": "ptm-lrgb", ".rti": "hsh3"}

#: The formats in the user's words.
DESCRIBE = {
    "ptm-lrgb": "PTM 1.2, LRGB (luminance polynomial and colour)",
    "ptm-rgb": "PTM 1.2, RGB (a polynomial per channel)",
    "hsh2": "HSH .rti, order 2 (4 terms per channel)",
    "hsh3": "HSH .rti, order 3 (9 terms per channel)",
    "web-hsh3": "Relight web set, HSH order 3",
    "web-hsh2": "Relight web set, HSH order 2",
    "web-ptm-lrgb": "Relight web set, PTM LRGB",
    "web-ptm-rgb": "Relight web set, PTM RGB",
}

#: Short names of the web formats: the model each file suffix holds by default.
WEB_ALIASES = {"web-hsh": "web-hsh3", "web-ptm": "web-ptm-lrgb"}


@app.command()
def rti(
    folder: Annotated[
        Path,
        typer.Argument(
            help="Folder of the photo set: photos of one still camera under one light each, with "
            "light_directions.txt or an RTI .lp file (light_intensities.txt, if there, evens out the lights); "
            "or an RTIBuilder project folder (jpeg-exports/ and the .lp in assembly-files/).",
            show_default=False,
        ),
    ],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            help="File to write: .ptm (polynomial texture map) or .rti (hemispherical harmonics), "
            "as RTIViewer opens them; with --format web-*, a folder (Relight's web format).",
        ),
    ],
    format: Annotated[
        str | None,
        typer.Option(
            "--format",
            metavar="FORMAT",
            help="ptm-lrgb (default for .ptm), ptm-rgb, hsh3 (default for .rti) or hsh2; or web-hsh3 "
            "(web-hsh), web-hsh2, web-ptm-lrgb (web-ptm) or web-ptm-rgb: -o is then a folder of "
            "info.json and JPEG planes that Relight's web viewer and OpenLIME show in a browser (an "
            "earlier web set there is replaced, a folder holding other files refused).",
            show_default=False,
        ),
    ] = None,
    linear: LinearOption = None,
    as_json: JsonOption = False,
    max_pixels: MaxPixelsOption = MAX_PIXELS,
) -> None:
    """Fit a relightable image (RTI) to a photo set and write it for RTIViewer (PTM or HSH) or
    for the web (Relight's format).

    The file holds display (sRGB) values, as RTIBuilder's do from JPEG photos, whatever the photos'
    encoding; the fit's RMS error against the photos is printed in percent of full scale.
    The output's kind is the format's: a .ptm or .rti file, or with --format web-* a folder."""
    from shadeform.cli.sets import load_set
    from shadeform.photoset import photo_files
    from shadeform.rti import (
        FORMATS,
        check_web_folder,
        display_values,
        fit,
        rms_error,
        web_files,
        write_rti,
        write_web,
    )

    format = _check_format(output, format)
    web = format.startswith("web-")
    kind = format.removeprefix("web-")
    if web:
        check_web_folder(output)
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(
            f"'{folder}' is not a folder; give the folder of the photo set (its photos with "
            "light_directions.txt or an .lp file)"
        )
    count = len(photo_files([folder]))
    if count < FORMATS[kind]:
        raise InputError(
            f"a {kind} file fits {FORMATS[kind]} terms per pixel and needs at least {FORMATS[kind]} "
            f"photos under different lights; folder '{folder}' has {count}"
        )
    err = stderr_console()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    with OutputSet() as outputs:
        temp = outputs.temp_folder(output) if web else outputs.temp(output)
        with stage(err, f"loading the photo set {escape(str(folder))}", timings, "load"):
            photos = load_set(folder, mask=None, linear=linear, channel=None, max_pixels=max_pixels)
            shown = display_values(photos.images, photos.intensities)
        with stage(err, f"fitting {kind} to {count} photos", timings, "fit"):
            model = fit(shown, photos.lights, kind=kind)
            rms = rms_error(model, shown, photos.lights)
        with stage(err, f"writing {escape(output.name)}", timings, "write"):
            size = write_web(temp, model, lights=photos.lights) if web else write_rti(temp, model)
        outputs.commit()
    timings["total"] = time.perf_counter() - total
    height, width = model.shape
    if as_json:
        print_json(
            {
                "command": "rti",
                "input": {"folder": folder, "photos": count, "width": width, "height": height},
                "format": format,
                "files": {"output": output},
                "bytes": size,
                "rms": rms,
                "photo": photos.info,
                "timings": timings,
            }
        )
        return
    shown = f"{output}/ ({len(web_files(kind))} files)" if web else str(output)
    stdout_console().print(
        f"[bold]wrote[/] {escape(shown)}: {DESCRIBE[format]}, {width}x{height}, {_size(size)}, "
        f"from {count} photos ({describe_photo(photos.info)}); fit RMS {100 * rms:.2f}% of full scale, "
        f"in {format_seconds(timings['total'])}"
    )


def _check_format(output: Path, format: str | None) -> str:
    """The format the user asked for (a web one's short name resolved), or the one the file
    suffix implies; refused if the output cannot hold it: a web set is a folder, not a .ptm or
    .rti file."""
    format = WEB_ALIASES.get(format, format)
    if format is not None and format not in DESCRIBE:
        raise InputError(
            f"unknown --format {format!r}; choose one of {', '.join(DESCRIBE)} (or {', '.join(WEB_ALIASES)})"
        )
    if format is not None and format.startswith("web-"):
        if output.suffix.lower() in DEFAULT_FORMAT:
            raise InputError(
                f"--format {format} writes a folder (Relight's web format), not the file '{output.name}'; "
                "give -o a folder name"
            )
        return format
    suffix = output.suffix.lower()
    if suffix not in DEFAULT_FORMAT:
        given = f"suffix '{output.suffix}'" if output.suffix else "no suffix"
        raise InputError(
            f"cannot write an RTI file to '{output.name}': {given}; use one of {', '.join(DEFAULT_FORMAT)}, "
            "or --format web-hsh3 to write a folder for the web"
        )
    if format is None:
        return DEFAULT_FORMAT[suffix]
    wanted = ".ptm" if format.startswith("ptm") else ".rti"
    if wanted != suffix:
        raise InputError(
            f"--format {format} is written to a {wanted} file, not '{output.name}'; name it {wanted}"
        )
    return format


def _size(count: int) -> str:
    """A file size in the units a user reads."""
    for unit, step in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= step:
            return f"{count / step:.1f} {unit}"
    return f"{count} bytes"
