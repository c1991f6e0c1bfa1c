"""The commands that turn photos into models: ``reconstruct`` (one photo), ``stereo`` (several
photos under different lights), ``lights`` (lights from a shiny sphere) and ``batch`` (many photos
in parallel)."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.markup import escape
from rich.table import Column, Table

from shadeform.cli._shell import (
    MAX_PIXELS,
    ChannelOption,
    ConcaveOption,
    FilterOption,
    IntegratorOption,
    JsonOption,
    LightOption,
    LinearOption,
    MaskFileOption,
    MaxPixelsOption,
    MethodOption,
    ReferenceOption,
    RefineOption,
    SlantOption,
    StepOption,
    TiltOption,
    app,
    check_outputs,
    check_suffix,
    describe_photo,
    format_seconds,
    format_vector,
    output_temps,
    parse_reference,
    print_files,
    print_json,
    print_notes,
    progress_bar,
    read_light,
    resolve_light,
    stage,
    stderr_console,
    stdout_console,
    write_model,
)
from shadeform.cli.tiles import tile_size, tiled_reconstruct
from shadeform.errors import InputError
from shadeform.integration import available_integrators
from shadeform.io.atomic import OutputSet


@app.command()
def reconstruct(
    image: Annotated[
        Path, typer.Argument(help="Photo of the object (PNG, JPEG, TIFF, BMP).", show_default=False)
    ],
    output: Annotated[
        Path,
        typer.Option(
            "-o", "--output", help="Mesh file; the suffix picks the format (see `shadeform formats`)."
        ),
    ],
    step: StepOption = 1,
    filter: FilterOption = None,
    light: LightOption = None,
    slant: SlantOption = None,
    tilt: TiltOption = None,
    channel: ChannelOption = "auto",
    linear: LinearOption = None,
    concave: ConcaveOption = None,
    reference: ReferenceOption = None,
    mask: MaskFileOption = None,
    depth: Annotated[
        Path | None, typer.Option(help="Also write the depth map (.tif, .tiff or .npy).")
    ] = None,
    normals: Annotated[Path | None, typer.Option(help="Also write the normal map (16-bit .png).")] = None,
    as_json: JsonOption = False,
    method: MethodOption = "auto",
    integrator: IntegratorOption = None,
    refine: RefineOption = 3,
    max_pixels: MaxPixelsOption = MAX_PIXELS,
    tiles: Annotated[
        str,
        typer.Option(
            metavar="auto|N|off",
            help="Solve in overlapping tiles of N pixels (shadeform.tiled): for images too large to "
            "solve whole; auto: a TIFF over --max-pixels is tiled (tiles of 512). The object is found "
            "on the whole photo (or --mask; --mask whole: every pixel, a relief). The depth goes to a "
            "tiled BigTIFF (--depth, or NAME_depth.tif beside the mesh), the mesh is decimated.",
        ),
    ] = "auto",
    scheduler: Annotated[
        str | None,
        typer.Option(
            metavar="ADDRESS",
            help="With tiles: a Dask cluster (tcp://host:8786) or processes, threads, synchronous; "
            "default worker processes on this machine.",
        ),
    ] = None,
    keep_tiles: Annotated[
        bool,
        typer.Option(
            help="With tiles: keep the solved tiles (DEPTH.tiles/) even if the run fails or is "
            "stopped, so that the same command again solves only the missing ones.",
        ),
    ] = False,
) -> None:
    """Reconstruct a mesh from one photo of a matte object under one light."""

    # everything the user typed is checked before any work
    check_outputs(output, depth, normals)
    tile = tile_size(tiles, image, max_pixels)
    if tile is not None:
        tiled_reconstruct(
            image, output, tile=tile, scheduler=scheduler, depth=depth, as_json=as_json, mask=mask,
            keep_tiles=keep_tiles,
            refused={"--reference": reference, "--concave": concave, "--normals": normals},
            light=resolve_light(light, slant, tilt), method=method, filter=filter, integrator=integrator,
            refine=refine, channel=channel, linear=linear, max_pixels=max_pixels,
        )  # fmt: skip
        return
    if scheduler is not None or keep_tiles:
        raise InputError(
            f"{'--scheduler' if scheduler is not None else '--keep-tiles'} is for tiles, and this "
            "image is solved whole (--tiles off, or within --max-pixels); add --tiles N to solve it "
            "in tiles of N pixels"
        )
    options = reconstruct_options(
        light=light, slant=slant, tilt=tilt, reference=reference, concave=concave,
        method=method, filter=filter, integrator=integrator, refine=refine,
    )  # fmt: skip

    err = stderr_console()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    with OutputSet() as outputs:
        temps = output_temps(outputs, output, depth, normals)
        photo, rec = reconstruct_photo(
            err, timings, image, channel=channel, linear=linear, max_pixels=max_pixels, mask=mask, **options
        )
        pixels = photo.image
        mesh, written, report = write_model(
            outputs, err, timings, rec, temps, step=step, output=output, depth=depth, normals=normals
        )
    timings["total"] = time.perf_counter() - total

    height, width = pixels.shape
    print_notes(err, photo.info, rec.info)
    if as_json:
        print_json(
            {
                "command": "reconstruct",
                "input": {"path": image, "width": width, "height": height, "channel": photo.channel},
                **report,
                "light": rec.light,
                "info": rec.info,
                "timings": timings,
            }
        )
        return

    out = stdout_console()
    info = rec.info
    # where depth 0 is, in the x=, y= of the other notes (column, row); the rest by count
    (main_row, main_col), *more_refs = info["references"]
    origin = f"depth 0 at x={main_col}, y={main_row}"
    if more_refs:
        origin += f" (and {len(more_refs)} more starting point{'s' if len(more_refs) > 1 else ''})"
    parts = f"{info['parts']} part{'s' if info['parts'] != 1 else ''}"
    stages = ", ".join(f"{name} {format_seconds(t)}" for name, t in info["timings"].items())
    out.print(f"[bold]reconstructed[/] {escape(str(image))} ({width}x{height}, {describe_photo(photo.info)})")
    # the refinement iterations that ran (the marching and photo solvers take none)
    refined = f", refined {info['refine']} times" if info["refine"] else ""
    out.print(
        f"  solver {info['method']}{refined}, depth by {info['integrator']}, "
        f"filter {info['filter']}, light {format_vector(rec.light)}{read_light(info)}"
    )
    out.print(f"  object {int(rec.mask.sum()):,} pixels in {parts}, {origin}")
    out.print(f"  mesh {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles (step {step})")
    out.print(
        f"  time {format_seconds(timings['total'])}: load {format_seconds(timings['load'])}, "
        f"reconstruct {format_seconds(timings['reconstruct'])} ({stages}), mesh {format_seconds(timings['mesh'])}, "
        f"write {format_seconds(timings['write'])}"
    )
    out.print("[bold]wrote[/]")
    print_files(out, written)


def reconstruct_options(*, light, slant, tilt, reference, concave, **rest) -> dict:
    """The keyword arguments of :func:`shadeform.reconstruct` from what the user typed (the light
    as ``--light`` or ``--slant``/``--tilt``, references, a regions file), checked before any
    work; ``rest`` (method, filter, integrator, refine) passes through."""
    from shadeform.regions import parse_regions

    references = [parse_reference(text) for text in reference or ()]
    return {
        "light": resolve_light(light, slant, tilt),
        "references": references or None,
        "concave": parse_regions(concave) if concave is not None else None,
        **rest,
    }


def reconstruct_photo(err, timings, image: Path, *, channel, linear, max_pixels, mask, grid=None, **options):
    """Load a photo (and its mask file, if given) and reconstruct it, each under a spinner: the
    part of ``reconstruct`` that the commands making other things from one photo share.

    ``grid``, if given, maps the object's mask to a grid spacing: the photo is then solved on
    that grid only (:func:`shadeform.coarse.reconstruct_on_grid`; the reconstruction has the
    grid's shape). Returns the :class:`~shadeform.io.images.Photo` and the reconstruction, whose
    ``info`` holds the photo's under ``"photo"``; ``options`` go to :func:`shadeform.reconstruct`."""
    import shadeform
    from shadeform.coarse import reconstruct_on_grid
    from shadeform.io.images import read_photo
    from shadeform.masks import find_object

    with stage(err, f"loading {escape(str(image))}", timings, "load"):
        photo = read_photo(image, channel=channel, linear=linear, max_pixels=max_pixels)
        object_mask = (
            shadeform.load_mask(mask, shape=photo.image.shape, max_pixels=max_pixels)
            if mask is not None
            else None
        )
    with stage(err, f"reconstructing ({options.get('method', 'auto')})", timings, "reconstruct"):
        if object_mask is None:  # found on the photo's colours, which tell an object from its table best
            object_mask = find_object(photo.pixels)
        if grid is None:
            rec = shadeform.reconstruct(photo.image, mask=object_mask, **options)
        else:
            step = grid(getattr(object_mask, "mask", object_mask))
            rec = reconstruct_on_grid(photo.image, step=step, mask=object_mask, **options)
    return photo, replace(rec, info={**rec.info, "photo": photo.info})


# --- stereo ------------------------------------------------------------------------------------


@app.command()
def stereo(
    sources: Annotated[
        list[Path],
        typer.Argument(
            help="Three or more photos under different lights, or one folder holding "
            "them with light_directions.txt (and optionally filenames.txt, "
            "light_intensities.txt, mask.png).",
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
    method: Annotated[
        str,
        typer.Option(
            help="bivariate (a reflectance model per pixel: gloss, falloff, shadows weighted out), "
            "robust (Lambertian, shadows and highlights left out) or least_squares (Woodham)."
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
    normals: Annotated[Path | None, typer.Option(help="Also write the normal map (16-bit .png).")] = None,
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
    from shadeform.io.photoset import load_photo_set
    from shadeform.photometric import METHODS, reconstruct_stereo

    # everything the user typed is checked before the photos are read
    check_outputs(output, depth, normals)
    for path, what in ((albedo, "an albedo map to"), (confidence, "a confidence map to")):
        if path is not None:
            check_suffix(path, (".png",), what)
    check_choice(method, METHODS, "method")
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
        with stage(err, f"photometric stereo ({method}) and depth ({integrator})", timings, "reconstruct"):
            rec = reconstruct_stereo(
                photos.images,
                photos.lights,
                photos.mask,
                intensities=photos.intensities,
                method=method,
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
        f"by {rec.info['method']}, {integrator} integration"
    )
    out.print(
        f"  object {int(rec.mask.sum()):,} pixels, median {rec.info['lights_used']:g} lights used per pixel"
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

    rows = []
    if albedo is not None:
        values = rec.albedo[..., 0] if gray and np.ndim(rec.albedo) == 3 else rec.albedo
        values = np.where(rec.mask if values.ndim == 2 else rec.mask[..., None], values, 0.0)
        top = float(np.percentile(values[rec.mask], 99.5)) if rec.mask.any() else 0.0
        save_gray(values / top if top > 0 else values, temps[albedo])
        kind = "grey" if values.ndim == 2 else "colour"
        rows.append((albedo, f"albedo, 16-bit {kind}, linear, white = {top:.4g} (99.5th percentile)"))
    if confidence is not None:
        save_gray(np.nan_to_num(rec.confidence), temps[confidence])
        rows.append((confidence, "confidence of each normal, 16-bit, 0 to 1"))
    return rows


def parse_sphere(text: str):
    """``"X,Y,R"`` or ``"auto"`` -> what :func:`shadeform.io.photoset.load_photo_set` takes."""
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
    from shadeform.io.photoset import photo_files, read_photos, write_lights
    from shadeform.light import slant_tilt
    from shadeform.light.sphere import calibrate_lights

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


# --- batch -------------------------------------------------------------------------------------


@app.command()
def batch(
    photos: Annotated[
        list[Path], typer.Argument(help="Photos to reconstruct, each on its own.", show_default=False)
    ],
    out: Annotated[Path, typer.Option("--out", help="Folder for the models (created if missing).")],
    format: Annotated[
        str, typer.Option("--format", help="Mesh format: a suffix from `shadeform formats`.")
    ] = ".glb",
    step: StepOption = 1,
    filter: FilterOption = None,
    light: Annotated[
        str | None,
        typer.Option(
            metavar="X,Y,Z", help='Direction toward the light, or "estimate" (per photo); 0,0,1 if not given.'
        ),
    ] = None,
    slant: SlantOption = None,
    tilt: TiltOption = None,
    channel: ChannelOption = "auto",
    linear: LinearOption = None,
    method: MethodOption = "auto",
    integrator: IntegratorOption = None,
    refine: RefineOption = 3,
    depth: Annotated[bool, typer.Option("--depth", help="Also write NAME_depth.tiff per photo.")] = False,
    normals: Annotated[
        bool, typer.Option("--normals", help="Also write NAME_normals.png per photo.")
    ] = False,
    workers: Annotated[
        int | None, typer.Option(min=1, help="Worker processes (default: one per CPU).")
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object instead of the table.")
    ] = False,
    max_pixels: MaxPixelsOption = MAX_PIXELS,
) -> None:
    """Reconstruct many photos with the same options, in parallel (needs the dask extra)."""
    from shadeform.batch import reconstruct_files, worker_count

    suffix = format if format.startswith(".") else f".{format}"
    light_vector = resolve_light(light, slant, tilt)
    err = stderr_console()
    total = time.perf_counter()
    # the folder is made for the run and removed again if the run is refused (bad options)
    with (
        OutputSet() as outputs,
        progress_bar(err, "reconstructing") as bar,
    ):
        outputs.make_folder(out)
        task = bar.add_task("photos", total=len(photos))
        results = reconstruct_files(
            photos,
            out,
            suffix=suffix,
            step=step,
            channel=channel,
            linear=linear,
            depth=depth,
            normals=normals,
            workers=workers,
            max_pixels=max_pixels,
            progress=lambda done, _: bar.update(task, completed=done),
            light=light_vector,
            method=method,
            filter=filter,
            integrator=integrator,
            refine=refine,
        )
    seconds = time.perf_counter() - total
    failed = [r for r in results if r.error is not None]
    if as_json:
        print_json(
            {
                "command": "batch",
                "seconds": seconds,
                "photos": [
                    {
                        "photo": r.photo,
                        "files": list(r.files),
                        "vertices": r.vertices,
                        "faces": r.faces,
                        "seconds": r.seconds,
                        "photo_info": r.photo_info,
                        "error": r.error,
                    }
                    for r in results
                ],
            }
        )
    else:
        # a path is folded onto more lines, never cut: its end names the photo
        table = Table(
            Column("photo", overflow="fold"), "read as", "vertices", "triangles", "seconds", "written"
        )
        for r in results:
            table.add_row(
                escape(str(r.photo)),
                describe_photo(r.photo_info) if r.photo_info else "",
                f"{r.vertices:,}",
                f"{r.faces:,}",
                format_seconds(r.seconds),
                escape(", ".join(p.name for p in r.files)) if r.files else "[red]failed[/]",
            )
        out_console = stdout_console()
        out_console.print(table)
        out_console.print(
            f"{len(results) - len(failed)} of {len(results)} photos in "
            f"{format_seconds(seconds)}, models in {escape(str(out))}"
        )
    if not failed and workers is not None and worker_count(workers, len(photos)) < workers:
        err.print(f"note: --workers {workers} lowered to {worker_count(workers, len(photos))}, "
                  "one per photo and at most one per CPU (more would only wait)", soft_wrap=True)  # fmt: skip
    if failed:  # one line: the first photo's reason, the others counted (--json has each)
        more = f" (and {len(failed) - 1} more photo(s) failed; --json lists each)" if len(failed) > 1 else ""
        err.print(f"error: {escape(str(failed[0].photo))}: {escape(failed[0].error)}{more}", soft_wrap=True)
        raise typer.Exit(2)
