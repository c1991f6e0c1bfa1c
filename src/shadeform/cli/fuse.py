"""``shadeform fuse``: photos of one object from several sides -> one closed model."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, NamedTuple

import numpy as np
import typer

from shadeform.cli._shell import (
    app,
    check_outputs,
    format_seconds,
    output_temps,
    print_files,
    print_json,
    progress_bar,
    resolve_light,
    stage,
    stderr_console,
    stdout_console,
)
from shadeform.cli.options import (
    MAX_PIXELS,
    ChannelOption,
    FilterOption,
    IntegratorOption,
    JsonOption,
    LinearOption,
    MaxPixelsOption,
    SlantOption,
    SolverOption,
    TiltOption,
)
from shadeform.cli.sets import is_photo_set, load_set, solve_set
from shadeform.errors import InputError
from shadeform.io.atomic import OutputSet


@app.command()
def fuse(
    photos: Annotated[
        list[Path] | None,
        typer.Argument(
            help="Photos of the object from several sides (or give --views); a view may be a folder "
            "holding a photo set under several lights (photometric stereo per view, the better route).",
            show_default=False,
        ),
    ] = None,
    output: Annotated[
        Path,
        typer.Option(
            "-o", "--output", help="Mesh file; the suffix picks the format (see `shadeform formats`)."
        ),
    ] = Path("model.glb"),
    angles: Annotated[
        str | None,
        typer.Option(
            metavar="A,B,...",
            help="Turntable angle of each photo in degrees (the object turned about the vertical "
            "axis, right-handed about +y; docs/conventions.md).",
            show_default=False,
        ),
    ] = None,
    views: Annotated[
        Path | None,
        typer.Option(
            help='JSON file of the views instead: {"views": [{"photo": "a.png", "angle": 0, '
            '"mask": "a_mask.png", "concave": "a_regions.json"}, {"photo": "b.png", "pose": '
            "[[4x4 object -> camera]]}, ...]}; paths relative to the file; concave regions as a file "
            "or inline (docs/conventions.md).",
            show_default=False,
        ),
    ] = None,
    mask: Annotated[
        list[Path] | None,
        typer.Option(
            help="Mask of each photo, in order (repeat once per photo); found automatically if not given."
        ),
    ] = None,
    light: Annotated[
        str | None,
        typer.Option(
            metavar="X,Y,Z", help="Direction toward the light in each camera's frame; 0,0,1 if not given."
        ),
    ] = None,
    slant: SlantOption = None,
    tilt: TiltOption = None,
    channel: ChannelOption = "auto",
    linear: LinearOption = None,
    filter: FilterOption = None,
    solver: SolverOption = "auto",
    integrator: IntegratorOption = None,
    resolution: Annotated[
        float | None,
        typer.Option(min=0.25, max=64, help="Voxel edge in pixels (default: 1, or coarser for big objects)."),
    ] = None,
    refine_poses: Annotated[
        bool,
        typer.Option(
            "--refine-poses/--keep-poses",
            "--refine/--no-refine",  # their old names, still taken
            help="Correct the poses and offsets so that the views agree, or keep them as given "
            "(--refine/--no-refine: the old names).",
        ),
    ] = True,
    axis: Annotated[
        float | None,
        typer.Option(
            metavar="COLUMN", help="The turntable axis's column (default: found from the silhouettes)."
        ),
    ] = None,
    surface: Annotated[
        str,
        typer.Option(
            metavar="volume|poisson",
            help="The surface: volume (signed distance in the visual hull, marching cubes) or poisson "
            "(screened Poisson reconstruction; needs pip install 'shadeform\\[fusion]').",
        ),
    ] = "volume",
    settle: Annotated[
        bool,
        typer.Option(
            "--settle/--no-settle",
            help="Where a photo cannot tell convex from concave, let the other views' silhouettes "
            "decide (each such area is solved again as concave and kept if it fits them better).",
        ),
    ] = True,
    as_json: JsonOption = False,
    max_pixels: MaxPixelsOption = MAX_PIXELS,
) -> None:
    """Fuse photos of one object from several sides into one closed, watertight model.

    A view given as a folder holding a photo set (its lights in light_directions.txt or an .lp
    file) is solved by photometric stereo, which needs no light, solver or concave regions."""
    import shadeform
    from shadeform._checks import check_choice
    from shadeform.fusion import SURFACES, place, solid
    from shadeform.fusion.outlines import OUTLINE_KEPT, outline_iou
    from shadeform.io.images import read_photo
    from shadeform.masks import find_object
    from shadeform.mesh import solid_measures
    from shadeform.regions import as_regions

    check_outputs(output, None, None)
    entries = _views(photos, angles, views, mask)
    # before the views are solved: a missing extra must not cost the user the wait
    if check_choice(surface, SURFACES, "surface") == "poisson":
        from shadeform.fusion.poisson import require_open3d

        require_open3d(load=False)
    light_vector = resolve_light(light, slant, tilt)
    err = stderr_console()
    timings: dict[str, float] = {}
    start = time.perf_counter()
    with OutputSet() as outputs:
        temps = output_temps(outputs, output)
        images, object_masks, drawn, recs, readings = [], [], [], [], []

        def solve(i: int, extra=()):
            """View ``i`` solved, with ``extra`` concave regions besides the ones drawn for it (a
            photo set's is unambiguous: its photometric stereo, solved once)."""
            if is_photo_set(entries[i].photo):
                return recs[i]
            return shadeform.reconstruct(
                images[i],
                light=light_vector,
                solver=solver,
                mask=object_masks[i],
                filter=filter,
                integrator=integrator,
                concave=[*drawn[i], *extra] or None,
            )

        with progress_bar(err, "reconstructing each view") as bar:
            task = bar.add_task("views", total=len(entries))
            lap = time.perf_counter()
            for i, entry in enumerate(entries):
                if is_photo_set(entry.photo):
                    if entry.concave is not None:
                        raise InputError(
                            f"view {i + 1} ({entry.photo.name}) is a photo set: its photometric stereo "
                            "tells convex from concave itself; drop its concave regions"
                        )
                    photos = load_set(
                        entry.photo, mask=entry.mask, linear=linear, channel=channel, max_pixels=max_pixels
                    )
                    rec = solve_set(photos, integrator=integrator)
                    images.append(None)
                    readings.append(photos.info)
                    object_masks.append(rec.mask)
                    drawn.append([])
                    recs.append(rec)
                    bar.advance(task)
                    continue
                photo = read_photo(entry.photo, channel=channel, linear=linear, max_pixels=max_pixels)
                images.append(photo.image)
                readings.append(photo.info)
                object_masks.append(
                    shadeform.load_mask(entry.mask, shape=photo.image.shape, max_pixels=max_pixels)
                    if entry.mask
                    else find_object(photo.pixels)  # on the photo's colours, which find it best
                )
                try:
                    drawn.append(list(as_regions(entry.concave)))
                except InputError as error:
                    raise InputError(f"view {i + 1} ({entry.photo.name}): {error}") from None
                recs.append(solve(i))
                bar.advance(task)
            timings["reconstruct"] = time.perf_counter() - lap
        with stage(err, f"fusing {len(recs)} views", timings, "fuse"):
            placement = place(
                list(zip(recs, [entry.pose for entry in entries])),
                resolution=resolution,
                refine_poses=refine_poses,
                axis=axis,
                resolve=solve if settle else None,
            )
            mesh = solid(placement, surface=surface)
        with stage(err, "writing the model", timings, "write"):
            shadeform.export(mesh, temps[output])
        outputs.commit()
    timings["total"] = time.perf_counter() - start
    measures = solid_measures(mesh)
    outlines = outline_iou(mesh, placement)
    settled = [
        [{"centre": area["centre"], "axis": area["axis"], "polygon": area["polygon"]} for area in areas]
        for areas in placement.concave
    ]
    if as_json:
        print_json(
            {
                "command": "fuse",
                "views": [
                    {
                        "photo": entry.photo,
                        "pose": _plain_pose(entry.pose),
                        "settled_concave": areas,
                        "reading": reading,  # how the file was read: bits, encoding, channel
                    }
                    for entry, areas, reading in zip(entries, settled, readings)
                ],
                "surface": surface,
                "rivals": [{"turns": list(rival.turns), "ratio": rival.ratio} for rival in placement.rivals],
                "depth_fixed": placement.depth_fixed,
                "files": {"mesh": output},
                "mesh": {"vertices": mesh.n_vertices, "faces": mesh.n_faces, **measures},
                "outline_iou": outlines,
                "timings": timings,
            }
        )
        return
    out = stdout_console()
    out.print(f"[bold]fused[/] {len(entries)} views into one closed model")
    low, high = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    size = " x ".join(f"{v:.0f}" for v in high - low)
    out.print(
        f"  {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles, {size} pixels, volume "
        f"{measures['volume']:,.0f} cubic pixels, "
        f"{'watertight' if measures['watertight'] else 'NOT watertight'}"
    )
    out.print(
        "  outlines kept (IoU of the model's projection with each view's mask): "
        + ", ".join(f"view {i + 1} {value:.3f}" for i, value in enumerate(outlines)),
        highlight=False,
    )
    for i, value in enumerate(outlines):
        if value < OUTLINE_KEPT:
            err.print(
                f"warning: the model covers view {i + 1}'s outline poorly (IoU {value:.2f}): parts it "
                "shows are missing or the model reaches past it; check that view's mask and angle",
                soft_wrap=True,
                highlight=False,
            )
    for i, areas in enumerate(settled):
        for area in areas:
            x, y = (round(v) for v in area["centre"])
            out.print(
                f"  view {i + 1} ({entries[i].photo.name}): the area around x={x}, y={y} is read as concave "
                f"(along {area['axis']}), as the other views' silhouettes show",
                highlight=False,
            )
    if not placement.depth_fixed:
        err.print(
            "warning: the views look along one line only (from opposite sides), so they cannot tell "
            "how deep the object is: the model's depth rests on each photo's shading alone, the two joined at their shared outline; add a photo from the side "
            "(e.g. at 90 degrees)",
            soft_wrap=True,
            highlight=False,
        )
    for rival in placement.rivals:
        turned = [f"view {i + 1} turned {turn:.0f} degrees" for i, turn in enumerate(rival.turns) if turn > 0]
        err.print(
            f"warning: the photos fit another placement about as well ({', '.join(turned)}), and the "
            "model may be wrong there; add a photo between two views (e.g. at 45 degrees) or give "
            "the angles exactly (--keep-poses keeps them)",
            soft_wrap=True,
            highlight=False,
        )
    out.print(
        f"  time {format_seconds(timings['total'])}: reconstruct {format_seconds(timings['reconstruct'])}, "
        f"fuse {format_seconds(timings['fuse'])}, write {format_seconds(timings['write'])}"
    )
    out.print("[bold]wrote[/]")
    print_files(out, [(output, shadeform.available_formats()[output.suffix.lower()])])


class ViewEntry(NamedTuple):
    """One view as the user gave it: photo, turntable angle or 4x4 pose, mask file, concave
    regions (a regions file, or the regions themselves as JSON data)."""

    photo: Path
    pose: object
    mask: Path | None = None
    concave: object = None


def _views(photos, angles, views_file, masks) -> list[ViewEntry]:
    """One entry per view, from the arguments or the views file, checked."""
    if views_file is not None:
        if photos or angles is not None or masks:
            raise InputError(
                "give the views either as photos with --angles (and --mask) or as --views FILE, not both"
            )
        return _views_file(views_file)
    photos = list(photos or [])
    if len(photos) < 2:
        raise InputError(f"fusing needs photos from at least two sides, got {len(photos)}")
    if angles is None:
        raise InputError("give each photo's turntable angle: --angles 0,90,180,270 (or --views FILE)")
    try:
        values = [float(text) for text in angles.split(",")]
    except ValueError:
        raise InputError(f"--angles must be numbers separated by commas, got {angles!r}") from None
    if len(values) != len(photos):
        raise InputError(f"--angles gives {len(values)} angles for {len(photos)} photos; give one per photo")
    if masks and len(masks) != len(photos):
        raise InputError(f"{len(masks)} --mask files for {len(photos)} photos; give one per photo, or none")
    return [
        ViewEntry(photo, angle, masks[i] if masks else None)
        for i, (photo, angle) in enumerate(zip(photos, values))
    ]


def _views_file(path: Path) -> list[ViewEntry]:
    from shadeform._checks import regular_file
    from shadeform.regions import loads_json

    try:
        text = regular_file(path, "views file").read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"views file '{path}' does not exist; check the path") from None
    except UnicodeDecodeError as err:
        raise InputError(f"views file '{path}' is not valid JSON ({err})") from None
    document = loads_json(text, f"views file '{path}'")
    items = document.get("views") if isinstance(document, dict) else None
    if not isinstance(items, list) or not all(isinstance(item, dict) for item in items):
        raise InputError(
            f'views file \'{path}\' must hold {{"views": [{{"photo": ..., "angle": ...}}, ...]}}'
        )
    entries = []
    for i, item in enumerate(items):
        if "photo" not in item or ("angle" in item) == ("pose" in item):
            raise InputError(f"views file '{path}': view {i + 1} needs a photo and either an angle or a pose")
        pose = item.get("angle", item.get("pose"))
        mask = path.parent / item["mask"] if item.get("mask") else None
        concave = item.get("concave")
        if isinstance(concave, str):  # a regions file, relative to the views file
            concave = path.parent / concave
        entries.append(ViewEntry(path.parent / item["photo"], pose, mask, concave))
    if len(entries) < 2:
        raise InputError(f"views file '{path}' has {len(entries)} view(s); fusing needs at least two")
    return entries


def _plain_pose(pose):
    return np.asarray(pose, dtype=float).tolist() if np.ndim(pose) else float(pose)
