"""``shadeform batch``: many photos reconstructed with the same options, each on its own, in
parallel (:mod:`shadeform.batch`)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Column, Table

from shadeform.cli._shell import (
    app,
    describe_photo,
    format_seconds,
    print_json,
    progress_bar,
    resolve_light,
    stderr_console,
    stdout_console,
)
from shadeform.cli.options import (
    MAX_PIXELS,
    ChannelOption,
    FilterOption,
    IntegratorOption,
    LinearOption,
    MaxPixelsOption,
    RefineOption,
    SlantOption,
    SolverOption,
    StepOption,
    TableJsonOption,
    TiltOption,
)
from shadeform.io.atomic import OutputSet


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
    solver: SolverOption = "auto",
    integrator: IntegratorOption = None,
    refine: RefineOption = 3,
    depth: Annotated[bool, typer.Option("--depth", help="Also write NAME_depth.tiff per photo.")] = False,
    normals: Annotated[
        bool, typer.Option("--normals", help="Also write NAME_normals.png per photo.")
    ] = False,
    workers: Annotated[
        int | None, typer.Option(min=1, help="Worker processes (default: one per CPU).")
    ] = None,
    as_json: TableJsonOption = False,
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
            solver=solver,
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
