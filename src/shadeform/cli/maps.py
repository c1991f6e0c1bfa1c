"""``shadeform maps``: one photo -> texture maps (normal, height, ambient occlusion, curvature);
with ``--material``, of a textured surface filling the frame (and its albedo); of a photo set's
folder, its photometric stereo's (and its albedo)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.markup import escape

from shadeform.cli._shell import (
    app,
    format_seconds,
    print_files,
    print_json,
    print_notes,
    resolve_light,
    stderr_console,
    stdout_console,
)
from shadeform.cli.options import PHOTO_DEFAULTS, JsonOption, PhotoOptions, takes_photo_options
from shadeform.cli.sets import PhotoOrSetArgument, is_photo_set, reconstruct_source
from shadeform.io.atomic import OutputSet
from shadeform.texture import LEGEND, albedo_map, legend


@app.command()
@takes_photo_options
def maps(
    image: PhotoOrSetArgument,
    out: Annotated[Path, typer.Option("--out", help="Folder for the maps (created if missing).")],
    only: Annotated[
        str | None,
        typer.Option(
            "--maps",
            metavar="NAMES",
            help="Write only these maps, comma-separated: normal_opengl, normal_directx, height, "
            "ambient_occlusion, curvature (and albedo with --material). Default: all.",
            show_default=False,
        ),
    ] = None,
    reach: Annotated[
        float | None,
        typer.Option(
            min=1.0,
            metavar="PIXELS",
            help="How far the ambient occlusion looks for occluders; default the object's half-width.",
        ),
    ] = None,
    material: Annotated[
        bool,
        typer.Option(
            "--material",
            help="The photo shows a textured surface filling the frame (stone, bark, fabric), not an object: "
            "uneven lighting removed, shape from the fine shading, an albedo map too.",
        ),
    ] = False,
    tile: Annotated[
        bool, typer.Option("--tile", help="With --material: make the albedo map tile seamlessly too.")
    ] = False,
    given: PhotoOptions = PHOTO_DEFAULTS,
    as_json: JsonOption = False,
) -> None:
    """Make texture maps of one photo: normals, height, ambient occlusion and curvature as PNGs.

    Normal maps in both the OpenGL and the DirectX convention; each file is named after the photo.
    A folder holding a photo set gives its photometric stereo's maps, with its albedo."""
    import shadeform
    from shadeform.errors import InputError
    from shadeform.io.maps import save_gray

    if tile and not material:
        raise InputError(
            "--tile makes material maps tile; add --material (a photo of a surface filling the frame)"
        )
    photo_set = is_photo_set(image)
    if photo_set:
        given.refuse_for_set()
        if material:
            raise InputError(
                "--material is for one photo of a surface filling the frame; leave it out for a photo set"
            )
    wanted = _wanted(only, [*LEGEND, "albedo"] if material or photo_set else list(LEGEND))
    if material:
        return _material(image, out, wanted, reach=reach, tile=tile, given=given, as_json=as_json)
    options = given.arguments()

    err = stderr_console()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    with OutputSet() as outputs:
        outputs.make_folder(out)
        files = {name: out / f"{image.stem}_{name}.png" for name in wanted}
        temps = {name: outputs.temp(path) for name, path in files.items()}
        reading, shape, rec = reconstruct_source(err, timings, image, **options)
        start = time.perf_counter()
        with err.status("making the maps", spinner="dots"):
            made = shadeform.maps(rec, reach=reach)
        timings["maps"] = time.perf_counter() - start
        start = time.perf_counter()
        relief = float(np.nanmax(rec.depth[rec.mask]) - np.nanmin(rec.depth[rec.mask]))
        white = albedo_map(rec.albedo, rec.mask)[1] if photo_set else None
        lines = legend(relief, albedo="stereo" if photo_set else None, white=white)
        for name in wanted:
            save_gray(made[name], temps[name], bitdepth=lines[name][0])
        outputs.commit()
        timings["write"] = time.perf_counter() - start
    timings["total"] = time.perf_counter() - total

    print_notes(err, reading, rec.info)
    rows = [(files[name], lines[name][1]) for name in wanted]
    if as_json:
        print_json(
            {
                "command": "maps",
                "input": {"path": image, "width": shape[1], "height": shape[0]},
                "maps": {name: {"path": files[name], "bits": lines[name][0]} for name in wanted},
                "height_range_px": relief,
                "info": rec.info,
                "timings": timings,
            }
        )
        return
    console = stdout_console()
    console.print(
        f"[bold]maps of[/] {escape(str(image))} ({shape[1]}x{shape[0]}), "
        f"{rec.info['solver']}, in {format_seconds(timings['total'])}"
    )
    print_files(console, rows)


def _wanted(only: str | None, names: list[str]) -> list[str]:
    """The maps ``--maps`` asks for, in the legend's order; every map without it."""
    if only is None:
        return names
    from shadeform.errors import InputError

    asked = [name.strip() for name in only.split(",") if name.strip()]
    unknown = [name for name in asked if name not in names]
    if unknown == ["albedo"]:
        raise InputError("the albedo map is made by --material only (a photo of a surface filling the frame)")
    if unknown or not asked:
        what = f"unknown map {unknown[0]!r} in --maps" if unknown else "--maps names no map"
        raise InputError(f"{what}; choose from {', '.join(names)}")
    return [name for name in names if name in asked]


def _material(image, out, wanted, *, reach, tile, given, as_json):
    """``maps --material``: the maps of a photo of a surface filling the frame."""
    from shadeform.io.images import read_photo
    from shadeform.io.maps import save_gray
    from shadeform.texture import material

    light = None
    if (
        not (given.light is None or given.light.strip().lower() == "estimate")
        or given.slant is not None
        or given.tilt is not None
    ):
        light = resolve_light(given.light, given.slant, given.tilt)
    err = stderr_console()
    total = time.perf_counter()
    lines = legend(albedo="material")
    with OutputSet() as outputs:
        outputs.make_folder(out)
        files = {name: out / f"{image.stem}_{name}.png" for name in wanted}
        temps = {name: outputs.temp(path) for name, path in files.items()}
        with err.status(f"loading {escape(str(image))}", spinner="dots"):
            photo = read_photo(image, channel=given.channel, linear=given.linear, max_pixels=given.max_pixels)
        colour = photo.pixels if photo.pixels.shape[2] == 3 else photo.image
        with err.status("making the maps", spinner="dots"):
            result = material(colour, light=light, tile=tile, reach=reach)
        for name in wanted:
            save_gray(result.maps[name], temps[name], bitdepth=lines[name][0])
        outputs.commit()
    seconds = time.perf_counter() - total
    height = result.maps["height"]
    tilt_read = float(np.degrees(np.arctan2(result.light[1], result.light[0])) % 360)
    if result.light_estimated:
        slant_read = float(np.degrees(np.arccos(np.clip(result.light[2], -1.0, 1.0))))
        err.print(
            f"note: the light's tilt was read from the photo as {tilt_read:.0f} degrees, on the side nearer "
            f"above; if the relief looks inverted, give --slant {slant_read:.0f} --tilt "
            f"{(tilt_read + 180) % 360:.0f} (--slant sets the shading's strength)",
            soft_wrap=True,
            highlight=False,
        )
    if as_json:
        print_json(
            {
                "command": "maps",
                "material": True,
                "input": {"path": image, "width": height.shape[1], "height": height.shape[0]},
                "maps": {name: {"path": files[name], "bits": lines[name][0]} for name in wanted},
                "light": result.light,
                "light_estimated": result.light_estimated,
                "seconds": seconds,
            }
        )
        return
    console = stdout_console()
    console.print(
        f"[bold]material maps of[/] {escape(str(image))} ({height.shape[1]}x{height.shape[0]}), light tilt "
        f"{tilt_read:.0f} degrees{' (read from the photo)' if result.light_estimated else ''}, in "
        f"{format_seconds(seconds)}"
    )
    rows = [(files[name], lines[name][1]) for name in wanted]
    print_files(console, rows)
