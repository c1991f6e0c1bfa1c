"""``shadeform stereo``: several photos of an object under different lights -> a mesh (photometric
stereo), with its albedo and confidence maps; ``shadeform lights``: the lights read from a shiny
sphere in the photos (light calibration)."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.markup import escape
from rich.table import Table

from shadeform.cli._shell import (
    app,
    check_outputs,
    check_suffix,
    describe_photo,
    format_seconds,
    output_temps,
    print_files,
    print_json,
    print_notes,
    stage,
    stderr_console,
    stdout_console,
    write_model,
)
from shadeform.cli.options import (
    MAX_PIXELS,
    JsonOption,
    LinearOption,
    MaxPixelsOption,
    NormalsFileOption,
    StepOption,
)
from shadeform.errors import InputError
from shadeform.integration import available_integrators
from shadeform.io.atomic import OutputSet


@app.command()
def stereo(
    sources: Annotated[
        list[Path],
        typer.Argument(
            help="Three or more photos under different lights, or one folder holding "
            "them with light_directions.txt (and optionally filenames.txt, "
            "light_intensities.txt, mask.png), or an RTIBuilder project folder (jpeg-exports/ and the "
            ".lp in assembly-files/).",
            show_default=False,
        ),
    ],
    output: Annotated[
        Path,
        typer.Option(
            "-o", "--output", help="Mesh file; the suffix picks the format (see `shadeform formats`)."
        ),
    ],
    lights: Annotated[
        Path | None,
        typer.Option(help="Text file: one direction toward the light per photo (x y z, camera frame)."),
    ] = None,
    intensities: Annotated[
        Path | None,
        typer.Option(help="Text file: each photo's light strength (one number, or R G B, per photo)."),
    ] = None,
    mask: Annotated[
        Path | None,
        typer.Option(help="Mask image: non-zero pixels are the object; found automatically if not given."),
    ] = None,
    sphere: Annotated[
        str | None,
        typer.Option(
            metavar="X,Y,R|auto",
            help="Read the lights from a shiny sphere in the photos instead of a light file: its "
            "centre column, row and radius in pixels, or auto to find it.",
        ),
    ] = None,
    unknown_lights: Annotated[
        bool,
        typer.Option(
            "--unknown-lights",
            help="No light file and no sphere: read the lights from the object's own shading "
            "(uncalibrated; far less accurate than known lights).",
        ),
    ] = False,
    model: Annotated[
        str,
        typer.Option(
            "--model",
            "--method",  # its old name, still taken
            help="The photometric model: bivariate (a reflectance model per pixel: gloss, falloff, "
            "shadows weighted out), robust (Lambertian, shadows and highlights left out) or "
            "least_squares (Woodham). --method is its old name.",
        ),
    ] = "bivariate",
    keep_lights: Annotated[
        bool,
        typer.Option(
            "--keep-lights",
            help="Take the lights exactly as given; by default a slant error common to all of them "
            "(a calibration sphere read slightly too large or small) is corrected from the photos.",
        ),
    ] = False,
    integrator: Annotated[
        str, typer.Option(help="Depth from normals: poisson, bilateral, fourier or paths.")
    ] = "poisson",
    step: StepOption = 1,
    channel: Annotated[
        str,
        typer.Option(
            help="Image channel: auto (colour photos are solved on all three channels), luma, r, g, b or max."
        ),
    ] = "auto",
    linear: LinearOption = None,
    depth: Annotated[
        Path | None, typer.Option(help="Also write the depth map (.tif, .tiff or .npy).")
    ] = None,
    normals: NormalsFileOption = None,
    albedo: Annotated[
        Path | None,
        typer.Option(
            help="Also write the albedo (16-bit .png, colour for colour photos, linear, its 99.5th percentile white)."
        ),
    ] = None,
    confidence: Annotated[
        Path | None,
        typer.Option(help="Also write each normal's confidence (16-bit grey .png, 0 to 1)."),
    ] = None,
    as_json: JsonOption = False,
    max_pixels: MaxPixelsOption = MAX_PIXELS,
) -> None:
    """Reconstruct a mesh from several photos of an object under different lights (photometric stereo).

    The lights come from a light file (``--lights``, also RTI ``.lp``), a shiny sphere in the
    photos (``--sphere``), or are found from the photos themselves (``--unknown-lights``)."""
    from shadeform._checks import check_choice
    from shadeform.photometric import STEREO_MODELS, reconstruct_stereo
    from shadeform.photoset import load_photo_set

    # everything the user typed is checked before the photos are read
    check_outputs(output, depth, normals)
    for path, what in ((albedo, "an albedo map to"), (confidence, "a confidence map to")):
        if path is not None:
            check_suffix(path, (".png",), what)
    STEREO_MODELS.get(model)  # an unknown name is refused here, listing the registered
    check_choice(integrator, tuple(available_integrators()), "integrator")
    err = stderr_console()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    with OutputSet() as outputs:
        temps = output_temps(outputs, output, depth, normals, albedo, confidence)
        if unknown_lights and (sphere is not None or lights is not None):
            raise InputError("give --unknown-lights alone: not with --lights or --sphere")
        circle = "unknown" if unknown_lights else parse_sphere(sphere) if sphere is not None else None
        with stage(err, "loading the photos", timings, "load"):
            photos = load_photo_set(
                sources,
                lights=lights,
                intensities=intensities,
                mask=mask,
                linear=linear,
                channel=channel,
                sphere=circle,
                max_pixels=max_pixels,
            )
        with stage(err, f"photometric stereo ({model}) and depth ({integrator})", timings, "reconstruct"):
            rec = reconstruct_stereo(
                photos.images,
                photos.lights,
                photos.mask,
                intensities=photos.intensities,
                model=model,
                integrator=integrator,
                sphere=photos.sphere,
                refine_lights=not keep_lights,
            )
        rec = replace(rec, info={**rec.info, "photo": photos.info})
        maps = _stereo_maps(rec, temps, albedo, confidence, gray=photos.channel != "rgb")
        mesh, written, report = write_model(
            outputs, err, timings, rec, temps, step=step, output=output, depth=depth, normals=normals
        )
        written += maps
        report["files"].update(albedo=albedo, confidence=confidence)
    timings["total"] = time.perf_counter() - total

    height, width = rec.shape
    print_notes(err, photos.info, rec.info)
    if as_json:
        print_json(
            {
                "command": "stereo",
                "input": {"photos": [str(p) for p in photos.paths], "width": width, "height": height},
                **report,
                "info": rec.info,
                "timings": timings,
            }
        )
        return
    out = stdout_console()
    out.print(
        f"[bold]reconstructed[/] {len(photos.paths)} photos ({width}x{height}, {describe_photo(photos.info)}) "
        f"by {rec.info['solver']}, {integrator} integration"
    )
    out.print(
        f"  object {int(rec.mask.sum()):,} pixels, median {rec.info['lights_used']:g} lights used per pixel, "
        f"depth {rec.info['quality']['depth_span']:.2f} x the outline's longest side"
        + _settled(rec.info["quality"])
    )
    names = [Path(path).name for path in photos.paths]  # the user's names for the photos, not indices
    if rec.info["photos_rescaled"]:
        listed = ", ".join(f"{escape(names[i])} x{f:.2f}" for i, f in rec.info["photos_rescaled"])
        out.print(f"  photos whose light was brighter or dimmer than its strength said, rescaled: {listed}")
    if rec.info["light_scale"] != 1.0:
        out.print(
            f"  the lights' slant was refined: tan(slant) x{rec.info['light_scale']:.3f} "
            "(--keep-lights takes them as given)"
        )
    if rec.info["photos_dropped"]:
        listed = ", ".join(escape(names[i]) for i in rec.info["photos_dropped"])
        out.print(f"  photos left out because they contradict the others: {listed}")
    out.print(f"  mesh {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles (step {step})")
    out.print(
        f"  time {format_seconds(timings['total'])}: load {format_seconds(timings['load'])}, "
        f"reconstruct {format_seconds(timings['reconstruct'])}, mesh {format_seconds(timings['mesh'])}, "
        f"write {format_seconds(timings['write'])}"
    )
    out.print("[bold]wrote[/]")
    print_files(out, written)


def _stereo_maps(rec, temps, albedo, confidence, *, gray):
    """Write the albedo and confidence maps asked for to their temporaries (committed with the
    mesh); the (file, description) rows to print. ``gray``: the photos were (or were made) one
    channel, so the albedo is written grey."""
    from shadeform.io.maps import save_gray
    from shadeform.texture import ALBEDO_WHITE_PERCENTILE, albedo_map

    rows = []
    if albedo is not None:
        image, top = albedo_map(
            rec.albedo[..., 0] if gray and np.ndim(rec.albedo) == 3 else rec.albedo, rec.mask
        )
        save_gray(image, temps[albedo])
        kind = "grey" if image.ndim == 2 else "colour"
        rows.append(
            (
                albedo,
                f"albedo, 16-bit {kind}, linear, white = {top:.4g} ({ALBEDO_WHITE_PERCENTILE:g}th percentile)",
            )
        )
    if confidence is not None:
        save_gray(np.nan_to_num(rec.confidence), temps[confidence])
        rows.append((confidence, "confidence of each normal, 16-bit, 0 to 1"))
    return rows


def parse_sphere(text: str):
    """``"X,Y,R"`` or ``"auto"`` -> what :func:`shadeform.photoset.load_photo_set` takes."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3:
        raise InputError(
            f"bad --sphere {text!r}: give X,Y,R (the sphere's centre column and row and its radius, "
            "in pixels from the top left) or auto"
        )
    return values


@app.command()
def lights(
    sources: Annotated[
        list[Path],
        typer.Argument(
            help="Photos with a shiny (chrome or black glossy) sphere in view, or one folder of them.",
            show_default=False,
        ),
    ],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            help="Light file to write: .lp (RTI: name x y z per photo) or .txt (x y z per photo).",
        ),
    ],
    sphere: Annotated[
        str,
        typer.Option(
            metavar="X,Y,R|auto",
            help="The sphere's centre column, row and radius in pixels, or auto to find it.",
        ),
    ] = "auto",
    intensities: Annotated[
        Path | None,
        typer.Option(
            help="Also write each light's strength, relative to the median photo's (one number per photo)."
        ),
    ] = None,
    linear: LinearOption = None,
    as_json: JsonOption = False,
    max_pixels: MaxPixelsOption = MAX_PIXELS,
) -> None:
    """Read each photo's light direction and strength from the highlight on a shiny sphere (light calibration, as for RTI)."""
    from shadeform.io.atomic import atomic_write
    from shadeform.light import slant_tilt
    from shadeform.light.sphere import calibrate_lights
    from shadeform.photoset import photo_files, read_photos, write_lights

    check_suffix(output, (".lp", ".txt"), "lights to")
    circle = parse_sphere(sphere)
    paths = photo_files(sources)
    if not paths:
        raise InputError("no photos given; give the photos of the sphere, or their folder")
    err = stderr_console()
    timings: dict[str, float] = {}
    with stage(err, "loading the photos", timings, "load"):
        images = read_photos(paths, linear=linear, max_pixels=max_pixels)[0]
    with stage(err, "finding the sphere and its highlights", timings, "calibrate"):
        found = calibrate_lights(images, sphere=None if circle == "auto" else circle)
    with OutputSet() as outputs:
        write_lights(outputs.temp(output), found.directions, names=[p.name for p in paths])
        if intensities is not None:
            with atomic_write(outputs.temp(intensities), mode="w") as handle:
                handle.write("# each light's strength, relative to the median photo's\n")
                handle.write("".join(f"{value:.6f}\n" for value in found.strengths))
        outputs.commit()
    column, row, radius = found.sphere
    if as_json:
        print_json(
            {
                "command": "lights",
                "sphere": {"column": column, "row": row, "radius": radius},
                "photos": [
                    {"photo": str(p), "direction": d, "strength": k, "highlight": h, "saturated": bool(c)}
                    for p, d, k, h, c in zip(
                        paths, found.directions, found.strengths, found.highlights, found.saturated
                    )
                ],
                "files": {"lights": output, "intensities": intensities},
                "timings": timings,
            }
        )
        return
    out = stdout_console()
    out.print(
        f"[bold]read[/] {len(paths)} lights from the sphere at column {column:.1f}, row {row:.1f}, radius {radius:.1f} px"
    )
    table = Table(box=None, pad_edge=False)
    for heading in ("photo", "x", "y", "z", "slant", "tilt", "strength"):
        table.add_column(heading, justify="left" if heading == "photo" else "right")
    for path, direction, strength, clipped in zip(paths, found.directions, found.strengths, found.saturated):
        s, t = slant_tilt(direction)
        table.add_row(
            escape(path.name), *(f"{v:.3f}" for v in direction), f"{s:.1f}", f"{t:.1f}",
            f"{strength:.3f}" + (" (clipped)" if clipped else ""),
        )  # fmt: skip
    out.print(table)
    if found.saturated.any():
        out.print(
            f"  {int(found.saturated.sum())} highlight(s) reach the photo's top value: those strengths are lower bounds"
        )
    out.print("[bold]wrote[/]")
    print_files(
        out,
        [(output, "light directions" + (" (RTI .lp)" if output.suffix.lower() == ".lp" else ""))]
        + ([(intensities, "relative light strengths")] if intensities is not None else []),
    )


def _settled(quality: dict) -> str:
    """With lights read from the photos: whether the photos settled the relief, in words."""
    if "relief_settled" not in quality:
        return ""
    rise = quality["entropy_rise"]
    if quality["relief_settled"]:
        return f", relief settled by the photos (albedo entropy's minimum {rise:g} spreads deep)"
    return f", relief NOT settled by the photos (albedo entropy's minimum {rise:g} spreads deep)"
