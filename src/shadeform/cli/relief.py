"""``shadeform relief``: one photo -> a print-ready solid in millimetres (STL, 3MF, ...)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.markup import escape

from shadeform.cli._shell import (
    app,
    check_outputs,
    describe_photo,
    format_seconds,
    output_temps,
    print_files,
    print_json,
    print_notes,
    refuse_options,
    stage,
    stderr_console,
    stdout_console,
    write_maps,
)
from shadeform.cli.options import (
    PHOTO_DEFAULTS,
    JsonOption,
    NormalsFileOption,
    PhotoOptions,
    takes_photo_options,
)
from shadeform.cli.sets import PhotoOrSetArgument, is_photo_set, reconstruct_source
from shadeform.io.atomic import OutputSet
from shadeform.solid import MIN_WALL_MM, grid_step

#: The flags of relief()'s options, for the messages of check_options.
_FLAGS = {
    "width_mm": "--width",
    "height_mm": "--height",
    "base_mm": "--base",
    "outline": "--outline",
    "compress": "--compress",
    "border_mm": "--border",
    "min_wall_mm": "--min-wall",
    "max_triangles": "--max-triangles",
}


@app.command("relief")
@takes_photo_options
def relief_command(
    image: PhotoOrSetArgument,
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            help="Solid's file: .stl (binary), .3mf, .obj, .glb, ... (see `shadeform formats`); "
            "coordinates in millimetres.",
        ),
    ] = Path("relief.stl"),
    width: Annotated[
        float, typer.Option("--width", metavar="MM", help="Longest side of the outline (rim included), mm.")
    ] = 100.0,
    height: Annotated[
        float,
        typer.Option(
            "--height", metavar="MM", help="Relief depth, lowest to highest point of the surface, mm."
        ),
    ] = 4.0,
    base: Annotated[
        float, typer.Option("--base", metavar="MM", help="Thickness of the flat base under the relief, mm.")
    ] = 2.0,
    compress: Annotated[
        float,
        typer.Option(
            metavar="0..1",
            help="Bas-relief compression: flatten steep slopes and depth jumps, keep fine detail "
            "(0: scale the depth linearly).",
        ),
    ] = 0.0,
    invert: Annotated[bool, typer.Option("--invert", help="Engrave instead of emboss.")] = False,
    border: Annotated[
        float, typer.Option("--border", metavar="MM", help="A flat rim around the outline, mm wide.")
    ] = 0.0,
    outline: Annotated[
        str,
        typer.Option(
            metavar="mask|frame",
            help="The solid's sides follow the object's outline (mask) or the image frame (frame: a plaque).",
        ),
    ] = "mask",
    min_wall: Annotated[
        float,
        typer.Option(
            "--min-wall", metavar="MM", help="Thinnest wall the printer makes; a thinner base is refused."
        ),
    ] = MIN_WALL_MM,
    max_triangles: Annotated[
        int | None,
        typer.Option(
            "--max-triangles",
            metavar="N",
            help="Triangle budget (quadric simplification; needs pip install 'shadeform\\[print]'). "
            "Default: two triangles per pixel on top and on the base.",
            show_default=False,
        ),
    ] = None,
    full_resolution: Annotated[
        bool,
        typer.Option(
            "--full-resolution",
            help="With --max-triangles, solve every pixel anyway (slower); by default only the grid "
            "the budget samples is solved, since the simplified surface keeps nothing finer.",
        ),
    ] = False,
    given: PhotoOptions = PHOTO_DEFAULTS,
    depth: Annotated[
        Path | None, typer.Option(help="Also write the depth map (.tif, .tiff or .npy), pixel units.")
    ] = None,
    normals: NormalsFileOption = None,
    as_json: JsonOption = False,
    closed: Annotated[
        bool,
        typer.Option(
            "--closed",
            help="A closed object instead of a relief: the photo is the front, the back a guess (the "
            "front mirrored, seen from behind), scaled so that the outline's longest side is --width "
            "mm, its depth in proportion; the relief's own options (--height, --base, ...) do not apply.",
        ),
    ] = False,
) -> None:
    """Make a print-ready relief from one photo: a closed solid in millimetres with a flat base."""
    import shadeform
    from shadeform.solid import check_options

    # everything the user typed is checked before any work
    check_outputs(output, depth, normals)
    if closed:
        # --closed has no flat base, no relief depth and no top to compress
        refuse_options(
            {
                "--height": height != 4.0,
                "--base": base != 2.0,
                "--compress": compress != 0.0,
                "--invert": invert,
                "--border": border != 0.0,
                "--outline": outline != "mask",
                "--min-wall": min_wall != MIN_WALL_MM,
                "--max-triangles": max_triangles is not None,
                "--full-resolution": full_resolution,
            },
            "for a relief on a flat base; --closed makes a closed object sized by --width alone (its "
            "depth in proportion)",
        )
    options = check_options(
        width_mm=width,
        height_mm=height,
        base_mm=base,
        outline=outline,
        compress=compress,
        invert=invert,
        border_mm=border,
        min_wall_mm=min_wall,
        max_triangles=max_triangles,
        names=_FLAGS,
    )
    if is_photo_set(image):
        given.refuse_for_set()
    solve_options = given.arguments()

    # a budget samples the surface every few pixels: solve only that grid, unless a per-pixel
    # map is asked for too
    grid = None
    if options["max_triangles"] is not None and not full_resolution and depth is None and normals is None:

        def grid(mask):
            pixels = int(mask.sum()) if options["outline"] == "mask" else mask.size
            return grid_step(pixels, options["max_triangles"])

    err = stderr_console()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    if closed:
        _closed_solid(
            err, timings, image, output, depth, normals, options["width_mm"], as_json, solve_options
        )
        return
    with OutputSet() as outputs:
        temps = output_temps(outputs, output, depth, normals)
        reading, shape, rec = reconstruct_source(err, timings, image, grid=grid, **solve_options)
        with stage(err, "building the solid", timings, "relief"):
            solid = shadeform.relief(rec, **options)
        with stage(err, "writing files", timings, "write"):
            shadeform.export(solid, temps[output])
            written = [(output, shadeform.available_formats()[output.suffix.lower()] + ", millimetres")]
            written += write_maps(rec, temps, depth=depth, normals=normals)
        outputs.commit()
    timings["total"] = time.perf_counter() - total

    size = [float(v) for v in solid.size_mm]
    volume = solid.volume_mm3
    print_notes(err, reading, rec.info)
    if as_json:
        print_json(
            {
                "command": "relief",
                "input": {"path": image, "width": shape[1], "height": shape[0]},
                "files": {"mesh": output, "depth": depth, "normals": normals},
                "solid": {
                    "size_mm": size,
                    "volume_mm3": volume,
                    "triangles": solid.n_faces,
                    "vertices": solid.n_vertices,
                    "deviation_mm": solid.deviation_mm,
                    "pixel_mm": solid.pixel_mm / rec.info.get("grid_step", 1),
                    "solved_step": rec.info.get("grid_step", 1),
                    **options,
                },
                "light": rec.light,
                "info": rec.info,
                "timings": timings,
            }
        )
        return

    out = stdout_console()
    rows, cols = shape
    out.print(f"[bold]relief[/] of {escape(str(image))} ({cols}x{rows}, {describe_photo(reading)})")
    out.print(
        f"  size {size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} mm (x y z: base {options['base_mm']:g} + "
        f"relief {options['height_mm']:g}), volume {volume:,.0f} mm^3, {solid.n_faces:,} triangles"
    )
    solved_step = rec.info.get("grid_step", 1)
    details = [
        f"one pixel = {solid.pixel_mm / solved_step:.4g} mm",
        f"outline {options['outline']}",
    ]
    if solved_step > 1:
        details.append(f"solved every {solved_step} pixels (the grid the triangle budget samples)")
    if options["compress"] > 0:
        details.append(f"compressed {options['compress']:g}")
    if options["invert"]:
        details.append("engraved")
    if options["border_mm"] > 0:
        details.append(f"rim {options['border_mm']:g} mm")
    if options["max_triangles"] is not None:
        details.append(
            f"simplified: surface within {solid.deviation_mm:.3g} mm of the "
            + ("solved surface" if solved_step > 1 else "full-resolution relief")
        )
    out.print("  " + ", ".join(details))
    out.print(
        f"  time {format_seconds(timings['total'])}: load {format_seconds(timings['load'])}, "
        f"reconstruct {format_seconds(timings['reconstruct'])}, solid {format_seconds(timings['relief'])}, "
        f"write {format_seconds(timings['write'])}"
    )
    out.print("[bold]wrote[/]")
    print_files(out, written)


def _closed_solid(err, timings, image, output, depth, normals, width_mm, as_json, solve) -> None:
    """``relief --closed``: the photo's closed model (:func:`shadeform.fusion.close`) in
    millimetres (:func:`shadeform.fusion.closed.in_millimetres`), written and reported."""
    import shadeform
    from shadeform.cli.photos import closed_report, print_closed
    from shadeform.fusion import close
    from shadeform.fusion.closed import in_millimetres

    total = time.perf_counter()
    with OutputSet() as outputs:
        temps = output_temps(outputs, output, depth, normals)
        reading, shape, rec = reconstruct_source(err, timings, image, **solve)
        with stage(err, "closing the model (the back mirrored from the front)", timings, "relief"):
            model = in_millimetres(close(rec), width_mm=width_mm)
        with stage(err, "writing files", timings, "write"):
            shadeform.export(model, temps[output])
            written = [
                (output, shadeform.available_formats()[output.suffix.lower()] + ", millimetres, closed")
            ]
            written += write_maps(rec, temps, depth=depth, normals=normals)
        outputs.commit()
    timings["total"] = time.perf_counter() - total
    print_notes(err, reading, rec.info)
    size = [float(v) for v in np.ptp(model.vertices, axis=0)]
    if as_json:
        print_json(
            {
                "command": "relief",
                "input": {"path": image, "width": shape[1], "height": shape[0]},
                "files": {"mesh": output, "depth": depth, "normals": normals},
                "solid": {"size_mm": size, "volume_mm3": model.volume, "triangles": model.n_faces,
                          "vertices": model.n_vertices, "width_mm": width_mm},
                "closed": closed_report(model),
                "light": rec.light,
                "info": rec.info,
                "timings": timings,
            }
        )  # fmt: skip
        return
    out = stdout_console()
    rows, cols = shape
    out.print(f"[bold]closed solid[/] of {escape(str(image))} ({cols}x{rows}, {describe_photo(reading)})")
    out.print(f"  volume {model.volume:,.0f} mm^3, {model.n_faces:,} triangles", highlight=False)
    print_closed(out, err, model, unit="mm")
    out.print(
        f"  time {format_seconds(timings['total'])}: load {format_seconds(timings['load'])}, "
        f"reconstruct {format_seconds(timings['reconstruct'])}, close {format_seconds(timings['relief'])}, "
        f"write {format_seconds(timings['write'])}"
    )
    out.print("[bold]wrote[/]")
    print_files(out, written)
