"""``shadeform reconstruct``: one photo -> a mesh (and its depth and normal maps), and the loading
and solving of one photo that ``relief`` and ``maps`` share. ``stereo`` and ``lights`` are in
:mod:`shadeform.cli.stereo`, ``batch`` in :mod:`shadeform.cli.batch` (still importable from here)."""

from __future__ import annotations

import time
from dataclasses import replace
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
    format_vector,
    output_temps,
    print_files,
    print_json,
    print_notes,
    read_light,
    resolve_light,
    stage,
    stderr_console,
    stdout_console,
    write_model,
)

# batch, stereo and lights moved to their own modules and are still importable from here (F401)
from shadeform.cli.batch import batch  # noqa: F401
from shadeform.cli.options import (
    PHOTO_DEFAULTS,
    JsonOption,
    NormalsFileOption,
    PhotoOptions,
    StepOption,
    takes_photo_options,
)
from shadeform.cli.stereo import lights, parse_sphere, stereo  # noqa: F401
from shadeform.cli.tiles import tile_size, tiled_reconstruct
from shadeform.errors import InputError
from shadeform.io.atomic import OutputSet

# a solver's own options (its registry entry's): the solver is chosen by --solver, so these are read
# by name and type only once it is known (shadeform.reconstruct(solver_options=...))
SolverOptionsOption = Annotated[
    list[str] | None,
    typer.Option(
        "--option",
        metavar="NAME=VALUE",
        help="An option of the solver's own (`shadeform solvers` lists them); repeat for several.",
        show_default=False,
    ),
]


def parse_solver_options(texts: list[str] | None) -> dict[str, str] | None:
    """``--option NAME=VALUE`` texts as ``{NAME: VALUE}`` (the values still text: the solver's
    registry entry reads them as their types); None when none were given."""
    options = {}
    for text in texts or ():
        name, equals, value = text.partition("=")
        if not equals or not name.strip():
            raise InputError(f"--option takes NAME=VALUE, got {text!r}")
        options[name.strip()] = value.strip()
    return options or None


@app.command()
@takes_photo_options
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
    given: PhotoOptions = PHOTO_DEFAULTS,
    depth: Annotated[
        Path | None, typer.Option(help="Also write the depth map (.tif, .tiff or .npy).")
    ] = None,
    normals: NormalsFileOption = None,
    as_json: JsonOption = False,
    option: SolverOptionsOption = None,
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
    closed: Annotated[
        bool,
        typer.Option(
            "--closed",
            help="A closed, watertight model: the photo is the front, the back a guess (the front "
            "mirrored, seen from behind: right only for an object symmetric front to back). --step "
            "is then the voxel edge in pixels. For a print in millimetres: shadeform relief --closed.",
        ),
    ] = False,
) -> None:
    """Reconstruct a mesh from one photo of a matte object under one light."""

    # everything the user typed is checked before any work
    check_outputs(output, depth, normals)
    tile = tile_size(tiles, image, given.max_pixels)
    if closed and tile is not None:
        raise InputError(
            "--closed fuses the whole photo's model with its guessed back in one volume, and tiles "
            "are for photos too large to solve whole; give --tiles off (or a smaller photo)"
        )
    if tile is not None:
        tiled_reconstruct(
            image, output, tile=tile, scheduler=scheduler, depth=depth, as_json=as_json, mask=given.mask,
            keep_tiles=keep_tiles,
            refused={"--reference": given.reference, "--concave": given.concave, "--normals": normals,
                     "--option": option},
            light=resolve_light(given.light, given.slant, given.tilt), solver=given.solver,
            filter=given.filter, integrator=given.integrator, refine=given.refine, channel=given.channel,
            linear=given.linear, max_pixels=given.max_pixels,
        )  # fmt: skip
        return
    if scheduler is not None or keep_tiles:
        raise InputError(
            f"{'--scheduler' if scheduler is not None else '--keep-tiles'} is for tiles, and this "
            "image is solved whole (--tiles off, or within --max-pixels); add --tiles N to solve it "
            "in tiles of N pixels"
        )
    options = given.arguments(solver_options=parse_solver_options(option))

    err = stderr_console()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    with OutputSet() as outputs:
        temps = output_temps(outputs, output, depth, normals)
        photo, rec = reconstruct_photo(err, timings, image, **options)
        pixels = photo.image
        if closed:
            mesh, written, report = write_closed(
                outputs, err, timings, rec, temps, step=step, output=output, depth=depth, normals=normals
            )
        else:
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
        f"  solver {info['solver']}{refined}, depth by {info['integrator']}, "
        f"filter {info['filter']}, light {format_vector(rec.light)}{read_light(info)}"
    )
    out.print(f"  object {int(rec.mask.sum()):,} pixels in {parts}, {origin}")
    if closed:
        voxel = f"voxel edge {step} pixels" if step > 1 else "voxel edge 1 pixel or coarser for big objects"
        out.print(f"  mesh {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles ({voxel})")
        print_closed(out, err, mesh)
    else:
        out.print(f"  mesh {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles (step {step})")
    out.print(
        f"  time {format_seconds(timings['total'])}: load {format_seconds(timings['load'])}, "
        f"reconstruct {format_seconds(timings['reconstruct'])} ({stages}), mesh {format_seconds(timings['mesh'])}, "
        f"write {format_seconds(timings['write'])}"
    )
    out.print("[bold]wrote[/]")
    print_files(out, written)


def write_closed(outputs, err, timings, rec, temps, *, step, output, depth, normals):
    """:func:`~shadeform.cli._shell.write_model` for ``--closed``: the closed model
    (:func:`shadeform.fusion.close`, ``step`` its voxel edge) written with the maps asked for;
    the report says what the back is, the outline kept and whether it is watertight."""
    import shadeform
    from shadeform.cli._shell import write_maps
    from shadeform.fusion import close

    with stage(err, "closing the model (the back mirrored from the front)", timings, "mesh"):
        mesh = close(rec, resolution=step if step > 1 else None)
    with stage(err, "writing files", timings, "write"):
        shadeform.export(mesh, temps[output])
        written = [(output, shadeform.available_formats()[output.suffix.lower()] + ", closed")]
        written += write_maps(rec, temps, depth=depth, normals=normals)
    outputs.commit()
    report = {
        "files": {"mesh": output, "depth": depth, "normals": normals},
        "mesh": {"vertices": mesh.n_vertices, "faces": mesh.n_faces, "step": step},
        "closed": closed_report(mesh),
        "object_pixels": int(rec.mask.sum()),
    }
    return mesh, written, report


def closed_report(model) -> dict:
    """What a closed model (:class:`shadeform.fusion.Closed`) says of itself, for ``--json``."""
    return {
        "back": model.back,
        "back_is_guess": True,
        "outline_iou": model.outline_iou,
        "watertight": model.watertight,
        "volume": model.volume,
    }


def print_closed(out, err, model, unit: str = "pixels") -> None:
    """The summary lines of a closed model: its back a guess, the outline kept, watertight."""
    from shadeform.fusion.outlines import OUTLINE_KEPT

    size = " x ".join(f"{v:.4g}" for v in np.ptp(model.vertices, axis=0))
    out.print(
        f"  closed model {size} {unit}, "
        f"{'watertight' if model.watertight else 'NOT watertight'}, outline kept (IoU of its "
        f"projection with the photo's mask) {model.outline_iou:.3f}",
        highlight=False,
    )
    out.print(f"  back {model.back}", highlight=False)
    if model.outline_iou < OUTLINE_KEPT:
        err.print(
            f"warning: the closed model covers the photo's outline poorly (IoU {model.outline_iou:.2f}); "
            "check the mask",
            soft_wrap=True,
            highlight=False,
        )


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
    with stage(err, f"reconstructing ({options.get('solver', 'auto')})", timings, "reconstruct"):
        if object_mask is None:  # found on the photo's colours, which tell an object from its table best
            object_mask = find_object(photo.pixels)
        if grid is None:
            rec = shadeform.reconstruct(photo.image, mask=object_mask, **options)
        else:
            step = grid(getattr(object_mask, "mask", object_mask))
            rec = reconstruct_on_grid(photo.image, step=step, mask=object_mask, **options)
    return photo, replace(rec, info={**rec.info, "photo": photo.info})
