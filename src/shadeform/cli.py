"""The ``shadeform`` command: a thin shell over the library.

Commands::

    shadeform reconstruct IMAGE -o OUT.wrl   photo -> mesh (+ depth map, normal map)
    shadeform synth SCENE -o image.png       a synthetic image and its ground truth
    shadeform evaluate                       error table of the methods on the synthetic scenes
    shadeform formats                        the mesh formats -o understands
    shadeform methods                        the solvers and integrators --method / --integrator take
    shadeform demo                           the main job on a shipped photograph
    shadeform app [IMAGE]                    the browser app, served on 127.0.0.1

Everything here is input parsing, file I/O, printing and progress display; the work is done by
the library (``shadeform.reconstruct``, ``shadeform.to_mesh``, ``shadeform.export``, ...).

Errors are handled in one place (:class:`_Group`): a user mistake (:class:`InputError`), a file
that cannot be read or written, or bad JSON prints ``error: <one line>`` on stderr and exits with
code 2, like a usage error. Output files are first written to hidden temporary files beside their
targets and renamed only once all of them are complete (:class:`OutputSet`), so a failing command
leaves no file behind.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table
from typer.core import TyperGroup

from shadeform.errors import InputError
from shadeform.integration import available_integrators
from shadeform.io.atomic import OutputSet
from shadeform.solvers import available_methods

__all__ = ["app", "main"]

#: Exit code of every user error (the same as a command-line usage error).
USAGE_EXIT = 2

# File kinds the side outputs accept (docs/conventions.md: normal maps are 16-bit PNG; depth maps
# float32 TIFF or .npy, see shadeform.io.maps.save_depth).
_NORMAL_SUFFIXES = (".png",)
_DEPTH_SUFFIXES = (".tif", ".tiff", ".npy")


class _Group(TyperGroup):
    """The app's command group; the one place where errors become ``error: ...`` and exit 2."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except InputError as err:
            message = str(err)
        except json.JSONDecodeError as err:
            message = f"invalid JSON: {err.msg} at line {err.lineno}, column {err.colno}"
        except OSError as err:
            message = _os_error_message(err)
        typer.echo(f"error: {' '.join(message.split())}", err=True)
        raise typer.Exit(USAGE_EXIT)


def _os_error_message(err: OSError) -> str:
    where = f" '{err.filename}'" if err.filename else ""
    if isinstance(err, FileNotFoundError):
        return f"no such file or folder{where}; check the path"
    if isinstance(err, PermissionError):
        return f"permission denied{where}; check the file's and folder's permissions"
    if isinstance(err, IsADirectoryError):
        return f"{where.strip()} is a folder; give a file name"
    reason = err.strerror or type(err).__name__
    return f"{reason}{where}"


app = typer.Typer(
    cls=_Group,
    name="shadeform",
    help="Recover 3D shape from a photo by shading: normals, depth map, mesh.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)


def main() -> None:
    """Console-script entry point (``[project.scripts] shadeform``)."""
    app(prog_name="shadeform")


# --- small helpers -----------------------------------------------------------------------------


def _stdout() -> Console:
    # soft wrap: lines (paths!) are never cut or broken by rich; the terminal wraps them
    console = Console(highlight=False, soft_wrap=True)
    if not console.is_terminal and "COLUMNS" not in os.environ:
        console.width = 120  # piped or captured: rich would assume 80 columns and wrap the tables
    return console


def _stderr() -> Console:
    return Console(stderr=True, highlight=False)


@contextmanager
def _step(console: Console, text: str, timings: dict[str, float], name: str) -> Iterator[None]:
    """Show a spinner on stderr while a long step runs and record its wall time."""
    start = time.perf_counter()
    with console.status(text, spinner="dots"):
        yield
    timings[name] = time.perf_counter() - start


def _resolve_light(light: str | None, slant: float | None, tilt: float | None) -> np.ndarray | str:
    from shadeform.light import as_light, light_from_slant_tilt, parse_light

    if light is not None and (slant is not None or tilt is not None):
        raise InputError("give the light either as --light X,Y,Z or as --slant/--tilt, not both")
    if light is not None:
        return "estimate" if light.strip().lower() == "estimate" else parse_light(light)
    if tilt is not None and slant is None:
        raise InputError("--tilt needs --slant too (the angle of the light from the viewing direction)")
    if slant is not None:
        return light_from_slant_tilt(slant, 0.0 if tilt is None else tilt)
    return as_light((0.0, 0.0, 1.0))


def _parse_reference(text: str) -> tuple:
    """``"ROW,COL"`` or ``"ROW,COL,NX,NY,NZ"`` -> a reference for :func:`shadeform.reconstruct`."""
    usage = (
        "give ROW,COL (pixel row and column counted from 0 at the top left, e.g. '40,52'), "
        "or ROW,COL,NX,NY,NZ to give its normal too"
    )
    parts = [part.strip() for part in text.split(",")]
    if len(parts) not in (2, 5):
        raise InputError(f"bad --reference {text!r}: {usage}")
    try:
        row, col = int(parts[0]), int(parts[1])
    except ValueError:
        raise InputError(f"bad --reference {text!r}: row and column must be whole numbers; {usage}") from None
    if len(parts) == 2:
        return (row, col)
    try:
        normal = tuple(float(part) for part in parts[2:])
    except ValueError:
        raise InputError(f"bad --reference {text!r}: the normal must be three numbers; {usage}") from None
    return (row, col, normal)


def _check_suffix(path: Path, allowed, what: str) -> None:
    if path.suffix.lower() not in allowed:
        given = f"suffix '{path.suffix}'" if path.suffix else "no suffix"
        raise InputError(f"cannot write {what} '{path.name}': {given}; use one of {', '.join(allowed)}")


def _write_rgb_png(pixels: np.ndarray, path: Path) -> None:
    """An (H, W, 3) uint8 picture as a PNG, written atomically."""
    from PIL import Image

    from shadeform.io.atomic import atomic_write

    with atomic_write(path) as file_obj:
        Image.fromarray(pixels, mode="RGB").save(file_obj, format="PNG", optimize=True)


def _jsonable(value: Any) -> Any:
    """Plain JSON types (tuples -> lists, numpy scalars -> numbers, non-finite -> null)."""
    if isinstance(value, dict):
        return {str(key): _jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_jsonable(item) for item in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def _print_json(document: dict) -> None:
    typer.echo(json.dumps(_jsonable(document), indent=2))


def _seconds(value: float) -> str:
    return f"{value:.2f} s" if value >= 0.01 else f"{value * 1000:.1f} ms"


def _vector(values) -> str:
    return "(" + ", ".join(f"{float(v):.3g}" for v in values) + ")"


def _print_files(console: Console, rows: list[tuple[Path, str]]) -> None:
    """One line per file, path first; never wrapped or shortened, so it can be copied."""
    width = max(len(str(path)) for path, _ in rows)
    for path, what in rows:
        console.print(f"  [bold]{escape(str(path).ljust(width))}[/]  {escape(what)}")


# --- reconstruct -------------------------------------------------------------------------------


def _check_outputs(output: Path, depth: Path | None, normals: Path | None) -> None:
    """The suffixes of the mesh and of the optional depth and normal maps."""
    from shadeform.io.exporters import available_formats

    _check_suffix(output, tuple(available_formats()), "a mesh to")
    if depth is not None:
        _check_suffix(depth, _DEPTH_SUFFIXES, "a depth map to")
    if normals is not None:
        _check_suffix(normals, _NORMAL_SUFFIXES, "a normal map to")


def _output_temps(outputs: OutputSet, *targets: Path | None) -> dict[Path, Path]:
    """Temporary paths for the mesh and the optional maps, taken before any work so that a bad
    output path fails first."""
    return {target: outputs.temp(target) for target in targets if target is not None}


def _write_model(err: Console, timings: dict[str, float], rec, temps: dict[Path, Path], *,
                 step: int, output: Path, depth: Path | None, normals: Path | None):
    """Mesh a reconstruction and write it, and the depth and normal maps asked for, to their
    temporaries; returns the mesh and the (file, description) rows to print."""
    import shadeform
    from shadeform.io.maps import save_depth, save_normal_map

    with _step(err, "building the mesh", timings, "mesh"):
        mesh = shadeform.to_mesh(rec, step=step)
    with _step(err, "writing files", timings, "write"):
        shadeform.export(mesh, temps[output])
        written = [(output, shadeform.available_formats()[output.suffix.lower()])]
        if depth is not None:
            save_depth(rec.depth, temps[depth])
            written.append((depth, "depth map, pixel units, NaN off the object"))
        if normals is not None:
            save_normal_map(rec.normals, temps[normals])
            written.append((normals, "normal map, 16-bit, RGB = (n + 1) / 2"))
    return mesh, written


# options shared by the commands that build meshes
_StepOption = Annotated[int, typer.Option(min=1, help="Mesh granularity: pixels per vertex.")]
_MethodOption = Annotated[
    str,
    typer.Option(help=f"Solver: {', '.join(available_methods())} (`shadeform methods` says what each does)."),
]
_IntegratorOption = Annotated[
    str | None,
    typer.Option(help=f"Depth from normals: {', '.join(available_integrators())} (default: the solver's own)."),
]
_RefineOption = Annotated[int, typer.Option(min=0, help="Integrability refinement iterations (0: the 2002 field).")]
_SrgbOption = Annotated[
    bool, typer.Option("--srgb", help="Undo the sRGB encoding of 8-bit photos (JPEG) first: shading needs linear light."),
]
_FilterOption = Annotated[
    str | None,
    typer.Option("--filter", metavar="KIND:SIZE",
                 help="Smoothing: gaussian:SIGMA, mean:R, median:R, minimum:R or none."),
]


@app.command()
def reconstruct(
    image: Annotated[Path, typer.Argument(help="Photo of the object (PNG, JPEG, TIFF, BMP).", show_default=False)],
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Mesh file; the suffix picks the format (see `shadeform formats`).")
    ],
    step: _StepOption = 1,
    filter: _FilterOption = None,
    light: Annotated[
        str | None,
        typer.Option(metavar="X,Y,Z", help="Direction toward the light in the camera frame, or \"estimate\" to estimate it from the image; 0,0,1 if not given."),
    ] = None,
    slant: Annotated[
        float | None, typer.Option(metavar="DEGREES", help="Light slant: angle from the viewing direction.")
    ] = None,
    tilt: Annotated[
        float | None, typer.Option(metavar="DEGREES", help="Light tilt: from +x toward +y (up); needs --slant.")
    ] = None,
    channel: Annotated[str, typer.Option(help="Image channel: luma, r, g, b or max.")] = "luma",
    srgb: _SrgbOption = False,
    concave: Annotated[
        Path | None, typer.Option(help="JSON file of concave regions (docs/conventions.md).", show_default=False)
    ] = None,
    reference: Annotated[
        list[str] | None,
        typer.Option(
            "--reference",
            metavar="ROW,COL",
            help="Reference pixel ROW,COL (or ROW,COL,NX,NY,NZ with its normal); repeat for several.",
            show_default=False,
        ),
    ] = None,
    mask: Annotated[
        Path | None, typer.Option(help="Mask image: non-zero pixels are the object; found automatically if not given.")
    ] = None,
    depth: Annotated[Path | None, typer.Option(help="Also write the depth map (.tif, .tiff or .npy).")] = None,
    normals: Annotated[Path | None, typer.Option(help="Also write the normal map (16-bit .png).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the summary.")] = False,
    method: _MethodOption = "auto",
    integrator: _IntegratorOption = None,
    refine: _RefineOption = 3,
) -> None:
    """Reconstruct a mesh from one photo of a matte object under one light."""
    import shadeform
    from shadeform.preprocess import srgb_to_linear
    from shadeform.regions import parse_regions

    # everything the user typed is checked before any work
    _check_outputs(output, depth, normals)
    light_vector = _resolve_light(light, slant, tilt)
    references = [_parse_reference(text) for text in reference or ()]
    regions = parse_regions(concave) if concave is not None else None

    err = _stderr()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    with OutputSet() as outputs:
        temps = _output_temps(outputs, output, depth, normals)
        with _step(err, f"loading {escape(str(image))}", timings, "load"):
            pixels = shadeform.load_image(image, channel=channel)
            if srgb:
                pixels = srgb_to_linear(pixels)
            object_mask = shadeform.load_mask(mask, shape=pixels.shape) if mask is not None else None
        with _step(err, f"reconstructing ({method})", timings, "reconstruct"):
            rec = shadeform.reconstruct(
                pixels, light=light_vector, method=method, mask=object_mask, filter=filter,
                references=references or None, concave=regions, integrator=integrator, refine=refine,
            )
        mesh, written = _write_model(err, timings, rec, temps, step=step, output=output,
                                     depth=depth, normals=normals)
        outputs.commit()
    timings["total"] = time.perf_counter() - total

    height, width = pixels.shape
    if as_json:
        _print_json({
            "command": "reconstruct",
            "input": {"path": image, "width": width, "height": height, "channel": channel},
            "files": {"mesh": output, "depth": depth, "normals": normals},
            "mesh": {"vertices": mesh.n_vertices, "faces": mesh.n_faces, "step": step},
            "object_pixels": int(rec.mask.sum()),
            "light": rec.light,
            "info": rec.info,
            "timings": timings,
        })
        return

    out = _stdout()
    info = rec.info
    refs = ", ".join(f"({r}, {c})" for r, c in info["references"])
    stages = ", ".join(f"{name} {_seconds(t)}" for name, t in info["timings"].items())
    out.print(f"[bold]reconstructed[/] {escape(str(image))} ({width}x{height}, {channel})")
    out.print(
        f"  {info['method']} (refine {info['refine']}), {info['integrator']} integration, "
        f"filter {info['filter']}, light {_vector(rec.light)}"
    )
    out.print(
        f"  object {int(rec.mask.sum()):,} pixels in {info['parts']} part(s), reference pixel(s) {refs}"
    )
    out.print(f"  mesh {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles (step {step})")
    out.print(
        f"  time {_seconds(timings['total'])}: load {_seconds(timings['load'])}, "
        f"reconstruct {_seconds(timings['reconstruct'])} ({stages}), mesh {_seconds(timings['mesh'])}, "
        f"write {_seconds(timings['write'])}"
    )
    out.print("[bold]wrote[/]")
    _print_files(out, written)


# --- stereo ------------------------------------------------------------------------------------

@app.command()
def stereo(
    sources: Annotated[
        list[Path],
        typer.Argument(help="Three or more photos under different lights, or one folder holding "
                            "them with light_directions.txt (and optionally filenames.txt, "
                            "light_intensities.txt, mask.png).", show_default=False),
    ],
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Mesh file; the suffix picks the format (see `shadeform formats`).")
    ],
    lights: Annotated[
        Path | None, typer.Option(help="Text file: one direction toward the light per photo (x y z, camera frame).")
    ] = None,
    intensities: Annotated[
        Path | None, typer.Option(help="Text file: each photo's light strength (one number, or R G B, per photo).")
    ] = None,
    mask: Annotated[
        Path | None, typer.Option(help="Mask image: non-zero pixels are the object; found automatically if not given.")
    ] = None,
    method: Annotated[str, typer.Option(help="robust (leaves shadows and highlights out) or least_squares.")] = "robust",
    integrator: Annotated[str, typer.Option(help="Depth from normals: poisson, bilateral, fourier or paths.")] = "poisson",
    step: _StepOption = 1,
    srgb: _SrgbOption = False,
    depth: Annotated[Path | None, typer.Option(help="Also write the depth map (.tif, .tiff or .npy).")] = None,
    normals: Annotated[Path | None, typer.Option(help="Also write the normal map (16-bit .png).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the summary.")] = False,
) -> None:
    """Reconstruct a mesh from several photos of an object under known lights (photometric stereo)."""
    from shadeform._checks import check_choice
    from shadeform.io.photoset import load_photo_set
    from shadeform.photometric import METHODS, reconstruct_stereo

    # everything the user typed is checked before the photos are read
    _check_outputs(output, depth, normals)
    check_choice(method, METHODS, "method")
    check_choice(integrator, tuple(available_integrators()), "integrator")
    err = _stderr()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    with OutputSet() as outputs:
        temps = _output_temps(outputs, output, depth, normals)
        with _step(err, "loading the photos", timings, "load"):
            photos = load_photo_set(sources, lights=lights, intensities=intensities, mask=mask,
                                    srgb=srgb)
        with _step(err, f"photometric stereo ({method}) and depth ({integrator})", timings, "reconstruct"):
            rec = reconstruct_stereo(photos.images, photos.lights, photos.mask,
                                     intensities=photos.intensities, method=method,
                                     integrator=integrator)
        mesh, written = _write_model(err, timings, rec, temps, step=step, output=output,
                                     depth=depth, normals=normals)
        outputs.commit()
    timings["total"] = time.perf_counter() - total

    height, width = rec.shape
    if as_json:
        _print_json({
            "command": "stereo",
            "input": {"photos": [str(p) for p in photos.paths], "width": width, "height": height},
            "files": {"mesh": output, "depth": depth, "normals": normals},
            "mesh": {"vertices": mesh.n_vertices, "faces": mesh.n_faces, "step": step},
            "object_pixels": int(rec.mask.sum()),
            "info": rec.info,
            "timings": timings,
        })
        return
    out = _stdout()
    out.print(f"[bold]reconstructed[/] {len(photos.paths)} photos ({width}x{height}) by {rec.info['method']}, "
              f"{integrator} integration")
    out.print(f"  object {int(rec.mask.sum()):,} pixels, median {rec.info['lights_used']:g} lights used per pixel")
    out.print(f"  mesh {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles (step {step})")
    out.print(
        f"  time {_seconds(timings['total'])}: load {_seconds(timings['load'])}, "
        f"reconstruct {_seconds(timings['reconstruct'])}, mesh {_seconds(timings['mesh'])}, "
        f"write {_seconds(timings['write'])}"
    )
    out.print("[bold]wrote[/]")
    _print_files(out, written)


# --- batch -------------------------------------------------------------------------------------


@app.command()
def batch(
    photos: Annotated[list[Path], typer.Argument(help="Photos to reconstruct, each on its own.", show_default=False)],
    out: Annotated[Path, typer.Option("--out", help="Folder for the models (created if missing).")],
    format: Annotated[str, typer.Option("--format", help="Mesh format: a suffix from `shadeform formats`.")] = ".glb",
    step: _StepOption = 1,
    filter: _FilterOption = None,
    light: Annotated[
        str | None,
        typer.Option(metavar="X,Y,Z", help="Direction toward the light, or \"estimate\" (per photo); 0,0,1 if not given."),
    ] = None,
    slant: Annotated[float | None, typer.Option(metavar="DEGREES", help="Light slant.")] = None,
    tilt: Annotated[float | None, typer.Option(metavar="DEGREES", help="Light tilt; needs --slant.")] = None,
    channel: Annotated[str, typer.Option(help="Image channel: luma, r, g, b or max.")] = "luma",
    srgb: _SrgbOption = False,
    method: _MethodOption = "auto",
    integrator: _IntegratorOption = None,
    refine: _RefineOption = 3,
    depth: Annotated[bool, typer.Option("--depth", help="Also write NAME_depth.tiff per photo.")] = False,
    normals: Annotated[bool, typer.Option("--normals", help="Also write NAME_normals.png per photo.")] = False,
    workers: Annotated[int | None, typer.Option(min=1, help="Worker processes (default: one per CPU).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the table.")] = False,
) -> None:
    """Reconstruct many photos with the same options, in parallel (needs the dask extra)."""
    from shadeform.batch import reconstruct_files

    suffix = format if format.startswith(".") else f".{format}"
    light_vector = _resolve_light(light, slant, tilt)
    err = _stderr()
    total = time.perf_counter()
    # the folder is made for the run and removed again if the run is refused (bad options)
    with OutputSet() as outputs, Progress(
            TextColumn("reconstructing"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
            console=err, transient=True) as bar:
        outputs.make_folder(out)
        task = bar.add_task("photos", total=len(photos))
        results = reconstruct_files(
            photos, out, suffix=suffix, step=step, channel=channel, srgb=srgb, depth=depth,
            normals=normals, workers=workers,
            progress=lambda done, _: bar.update(task, completed=done),
            light=light_vector, method=method, filter=filter, integrator=integrator, refine=refine)
    seconds = time.perf_counter() - total
    failed = [r for r in results if r.error is not None]
    if as_json:
        _print_json({"command": "batch", "seconds": seconds, "photos": [
            {"photo": r.photo, "files": list(r.files), "vertices": r.vertices, "faces": r.faces,
             "seconds": r.seconds, "error": r.error} for r in results]})
    else:
        table = Table("photo", "vertices", "triangles", "seconds", "written")
        for r in results:
            table.add_row(escape(str(r.photo)), f"{r.vertices:,}", f"{r.faces:,}",
                          _seconds(r.seconds),
                          escape(", ".join(p.name for p in r.files)) if r.files else "[red]failed[/]")
        out_console = _stdout()
        out_console.print(table)
        out_console.print(f"{len(results) - len(failed)} of {len(results)} photos in "
                          f"{_seconds(seconds)}, models in {escape(str(out))}")
    for r in failed:
        err.print(f"error: {escape(str(r.photo))}: {escape(r.error)}", soft_wrap=True)
    if failed:
        raise typer.Exit(2)


# --- synth -------------------------------------------------------------------------------------


@app.command()
def synth(
    scene: Annotated[str, typer.Argument(help="Scene: sphere, ellipsoid, cylinder, vase, bowl, saddle, bumps.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="The image, a .png (written 16-bit).")],
    light: Annotated[
        str | None, typer.Option(metavar="X,Y,Z", help="Direction toward the light; 0,0,1 if not given.")
    ] = None,
    slant: Annotated[float | None, typer.Option(metavar="DEGREES", help="Light slant.")] = None,
    tilt: Annotated[float | None, typer.Option(metavar="DEGREES", help="Light tilt; needs --slant.")] = None,
    noise: Annotated[float, typer.Option(help="Gaussian noise sigma, as a fraction of the albedo.")] = 0.0,
    size: Annotated[int, typer.Option(help="Image side in pixels.")] = 256,
    seed: Annotated[int, typer.Option(help="Noise seed.")] = 0,
    depth_format: Annotated[str, typer.Option(help="File type of the true depth: npy or tiff.")] = "npy",
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the summary.")] = False,
) -> None:
    """Render a synthetic scene and write its ground truth next to it.

    Writes IMAGE (16-bit grey PNG) and, beside it, STEM_mask.png, STEM_depth.npy (or .tiff) and
    STEM_normals.png (16-bit normal map).
    """
    from shadeform import synth as synth_module
    from shadeform.io.maps import save_depth, save_gray, save_normal_map

    _check_suffix(output, (".png",), "the image to")
    if depth_format not in ("npy", "tiff"):
        raise InputError(f"bad --depth-format {depth_format!r}; choose npy or tiff")
    light_vector = _resolve_light(light, slant, tilt)
    rendered = synth_module.scene(scene, size=size, light=light_vector, noise=noise, seed=seed)

    stem = output.with_suffix("")
    targets = {
        "image": output,
        "mask": Path(f"{stem}_mask.png"),
        "depth": Path(f"{stem}_depth.{depth_format}"),
        "normals": Path(f"{stem}_normals.png"),
    }
    with OutputSet() as outputs:
        temps = {key: outputs.temp(path) for key, path in targets.items()}
        save_gray(rendered.image, temps["image"], bitdepth=16)
        save_gray(rendered.mask.astype(np.float64), temps["mask"], bitdepth=8)
        save_depth(rendered.depth, temps["depth"])
        save_normal_map(rendered.normals, temps["normals"])
        outputs.commit()

    if as_json:
        _print_json({"command": "synth", "scene": scene, "size": size, "light": rendered.light,
                     "noise": noise, "seed": seed, "files": targets})
        return
    out = _stdout()
    out.print(f"[bold]rendered[/] {scene} ({size}x{size}, light {_vector(rendered.light)}, noise {noise:g})")
    _print_files(out, [
        (targets["image"], "image, 16-bit grey"),
        (targets["mask"], "true mask (white = object)"),
        (targets["depth"], "true depth, pixel units, NaN off the object"),
        (targets["normals"], "true normals, 16-bit normal map"),
    ])


# --- evaluate ----------------------------------------------------------------------------------


#: (label, keyword arguments of reconstruct) of every method the table compares.
_METHODS = (
    ("propagation", {"method": "propagation", "refine": 3, "integrator": "paths"}),
    ("propagation (2002, no refinement)", {"method": "propagation", "refine": 0, "integrator": "paths"}),
    ("eikonal", {"method": "eikonal"}),
)


@app.command()
def evaluate(
    size: Annotated[int, typer.Option(help="Side of the synthetic images in pixels.")] = 256,
    scenes: Annotated[
        list[str] | None,
        typer.Option("--scenes", metavar="NAMES", help="Scenes to run, comma-separated or repeated; all if not given."),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the table.")] = False,
) -> None:
    """Run the methods on the synthetic scenes (light +z, no noise) and print their errors."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    import shadeform
    from shadeform import metrics, synth as synth_module

    names = [name.strip() for item in scenes or () for name in item.split(",") if name.strip()]
    names = names or list(synth_module.SCENES)
    for name in names:
        if name not in synth_module.SCENES:
            raise InputError(f"unknown scene {name!r}; choose from: {', '.join(synth_module.SCENES)}")

    runs = []  # (scene name, concave regions given, method label, reconstruct kwargs)
    for name in names:
        marked = bool(synth_module.concave_regions(name, size=size)["regions"])
        for label, kwargs in _METHODS:
            runs.append((name, False, label, kwargs))
            if marked:
                runs.append((name, True, label, kwargs))

    rows = []
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=_stderr(), transient=True) as progress:
        task = progress.add_task("compiling", total=len(runs))
        # one tiny run first, so the compile/cache-load time is not billed to the first row
        warm = synth_module.scene("sphere", size=16)
        shadeform.reconstruct(warm.image, mask=warm.mask)
        for name, with_region, label, kwargs in runs:
            progress.update(task, description=f"{name}: {label}")
            scene = synth_module.scene(name, size=size)
            concave = synth_module.concave_regions(name, size=size) if with_region else None
            start = time.perf_counter()
            rec = shadeform.reconstruct(scene.image, mask=scene.mask, light=scene.light, concave=concave, **kwargs)
            seconds = time.perf_counter() - start
            rows.append({
                "scene": name,
                "concave_region": with_region,
                "label": label,
                **kwargs,
                "angular_error_deg": metrics.angular_error(rec.normals, scene.normals),
                "depth_error_pct": metrics.depth_error(rec.depth, scene.depth, fit="offset"),
                "seconds": seconds,
            })
            progress.advance(task)

    if as_json:
        _print_json({"command": "evaluate", "size": size, "light": [0, 0, 1], "noise": 0, "rows": rows})
        return
    table = Table(
        title=f"Synthetic scenes, {size}x{size}, light +z, no noise",
        caption="angle: mean angular error of the normals; depth: RMSE as % of the true depth range, "
                "after fitting the free offset",
    )
    table.add_column("scene")
    table.add_column("method")
    table.add_column("angle (°)", justify="right", no_wrap=True, min_width=9)
    table.add_column("depth (%)", justify="right", no_wrap=True, min_width=9)
    table.add_column("time", justify="right", no_wrap=True, min_width=7)
    for row in rows:
        scene_label = row["scene"]
        if row["concave_region"]:
            scene_label += ", concave regions drawn"
        table.add_row(scene_label, row["label"], f"{row['angular_error_deg']:.2f}",
                      f"{row['depth_error_pct']:.2f}", _seconds(row["seconds"]))
    _stdout().print(table)


# --- formats -----------------------------------------------------------------------------------


@app.command()
def formats(
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the table.")] = False,
) -> None:
    """List the mesh formats `reconstruct -o` can write."""
    from shadeform import available_formats

    registry = available_formats()
    if as_json:
        _print_json({"command": "formats", "formats": registry})
        return
    table = Table(title="Mesh formats (picked by the -o suffix)")
    table.add_column("suffix", style="bold")
    table.add_column("format")
    for suffix, description in registry.items():
        table.add_row(suffix, description)
    _stdout().print(table)


# --- methods -----------------------------------------------------------------------------------


@app.command()
def methods(
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the tables.")] = False,
) -> None:
    """List the solvers `reconstruct --method` takes and the integrators of `--integrator`."""
    from shadeform.integration import available_integrators
    from shadeform.solvers import AUTO, available_methods, get_solver, solver_names

    rows = [{"name": AUTO, "lights": "any", "depth": "the chosen solver's", "description": available_methods()[AUTO]}]
    rows += [{"name": s.name, "lights": s.lights, "depth": s.integrator or s.depth, "description": s.description}
             for s in map(get_solver, solver_names())]
    if as_json:
        _print_json({"command": "methods", "methods": rows, "integrators": available_integrators()})
        return
    table = Table(title="Solvers (--method)")
    for column in ("method", "lights", "depth by", "what it does"):
        table.add_column(column, style="bold" if column == "method" else None)
    for row in rows:
        table.add_row(row["name"], row["lights"], row["depth"], row["description"])
    out = _stdout()
    out.print(table)
    table = Table(title="Integrators (--integrator)")
    table.add_column("integrator", style="bold")
    table.add_column("what it does")
    for name, text in available_integrators().items():
        table.add_row(name, text)
    out.print(table)


# --- demo --------------------------------------------------------------------------------------


@app.command()
def demo(
    out: Annotated[Path, typer.Option("--out", help="Folder for the results (created if missing).")] = Path("out/demo"),
    example: Annotated[str, typer.Option(help="Example to run: coin, or synth:SCENE.")] = "coin",
    step: Annotated[int | None, typer.Option(min=1, help="Mesh step in pixels; the example's own if not given.")] = None,
    size: Annotated[int | None, typer.Option(help="Image side for synth: examples.")] = None,
) -> None:
    """Reconstruct a shipped example photo: writes meshes, the normal map and result.png."""
    import shadeform
    from shadeform.examples import load_example
    from shadeform.io.maps import save_gray, save_normal_map
    from shadeform.render import result_picture

    err = _stderr()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    image, info = load_example(example, size=size)
    mesh_step = info["step"] if step is None else step
    with _step(err, f"reconstructing the example '{escape(example)}' (the very first run also compiles the numba kernels: about a minute)", timings, "reconstruct"):
        rec = shadeform.reconstruct(image, light=info["light"], mask=info["mask"], filter=info["filter"],
                                    method=info["method"])
    with _step(err, "building the mesh", timings, "mesh"):
        mesh = shadeform.to_mesh(rec, step=mesh_step)
    with _step(err, "drawing result.png", timings, "picture"):
        picture = result_picture(image, rec.normals, mesh)

    files = [
        ("input.png", "the input photo (16-bit grey)"),
        ("normals.png", "recovered normal map (16-bit, RGB = (n + 1) / 2)"),
        ("model.wrl", "mesh, VRML 2.0"),
        ("model.iv", "mesh, Open Inventor 2.1"),
        ("model.glb", "mesh, glTF 2.0 binary"),
        ("result.png", "input | normal map | shaded 3D view"),
    ]
    with _step(err, "writing files", timings, "write"), OutputSet() as outputs:
        outputs.make_folder(out)
        temps = {name: outputs.temp(out / name) for name, _ in files}
        save_gray(image, temps["input.png"], bitdepth=16)
        save_normal_map(rec.normals, temps["normals.png"])
        for name in ("model.wrl", "model.iv", "model.glb"):
            shadeform.export(mesh, temps[name])
        _write_rgb_png(picture, temps["result.png"])
        outputs.commit()
    timings["total"] = time.perf_counter() - total

    console = _stdout()
    console.print(f"[bold]demo[/] {escape(info['description'])}")
    console.print(f"  source {escape(info['source'])}")
    console.print(
        f"  {int(rec.mask.sum()):,} object pixels -> {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles "
        f"(step {mesh_step}) in {_seconds(timings['total'])}"
    )
    console.print(f"[bold]wrote[/] to {escape(str(out))}/")
    _print_files(console, [(out / name, what) for name, what in files])
    console.print(
        "  open result.png to see it; view the .glb in any glTF viewer (e.g. Blender) or the .wrl in a "
        "VRML viewer; try your own photo with: shadeform reconstruct PHOTO -o model.glb"
    )


# --- app ---------------------------------------------------------------------------------------


@app.command("app")
def app_command(
    image: Annotated[
        str | None,
        typer.Argument(help="Photo to open at start, or a shipped example (coin, synth:bowl, ...).", show_default=False),
    ] = None,
    port: Annotated[int, typer.Option(min=0, max=65535, help="Port to serve on (0: any free port).")] = 8000,
    host: Annotated[str, typer.Option(help="Address to bind; loopback unless --allow-remote.")] = "127.0.0.1",
    allow_remote: Annotated[
        bool, typer.Option("--allow-remote", help="Allow binding a non-loopback address: anyone who can reach it can use the app.")
    ] = False,
    no_browser: Annotated[bool, typer.Option("--no-browser", help="Do not open a web browser.")] = False,
) -> None:
    """Start the browser app: open a photo, draw concave regions, see and export the 3D model."""
    import ipaddress
    import socket
    import threading
    import webbrowser

    try:
        import uvicorn

        from shadeform.app.server import LOOPBACK_HOSTS, create_app
    except ImportError as missing:
        raise InputError(f"the app needs {missing.name or 'its web server'}, which is not installed; "
                         "install shadeform with its app extra: pip install 'shadeform[app]'") from None
    from shadeform.examples import EXAMPLES

    try:
        loopback = host == "localhost" or ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        loopback = False
    if not loopback and not allow_remote:
        raise InputError(f"--host {host} is not a loopback address; other machines could use the app. "
                         "Add --allow-remote if that is what you want")
    initial = None
    if image is not None:
        # the user's own argument: a file, else an example name
        if Path(image).exists() or image not in EXAMPLES:
            initial = Path(image)
            if not initial.is_file():
                raise InputError(f"no such image file or example: '{image}'; give a photo's path or one "
                                 f"of: {', '.join(EXAMPLES)}")
        else:
            initial = image
    err = _stderr()
    with err.status("opening the image", spinner="dots"):
        # warm: the numba kernels compile (or load) in the background, so the first click does not wait
        application = create_app(initial_image=initial, allowed_hosts=None if allow_remote else LOOPBACK_HOSTS,
                                 warm=True)
    # bind first, so that the printed address (and port 0's pick) is the one that answers
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host.strip("[]"), port))
    except OSError as error:
        sock.close()
        raise InputError(f"cannot listen on {host}:{port} ({error.strerror}); choose another --port") from None
    bound_port = sock.getsockname()[1]
    shown_host = f"[{host.strip('[]')}]" if ":" in host else host
    url = f"http://{shown_host}:{bound_port}/"
    if not loopback:
        err.print(f"[bold yellow]warning:[/] serving on {escape(host)}, not loopback: anyone who can reach "
                  "this address can use the app and read the images opened in it")
    _stdout().print(f"[bold]shadeform app[/] at {escape(url)}  (Ctrl+C stops it)")
    if not no_browser and _has_display():
        threading.Timer(0.5, webbrowser.open, args=(url,)).start()
    config = uvicorn.Config(application, log_level="warning")
    uvicorn.Server(config).run(sockets=[sock])


def _has_display() -> bool:
    """Whether a browser could show a window here (a desktop session, or macOS/Windows)."""
    import sys

    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
