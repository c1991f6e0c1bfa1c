"""The command line's shell: the typer app, the one error handler, and the helpers its commands
share (printing, timing, output files written together or not at all); the options they share are
in :mod:`shadeform.cli.options`."""

from __future__ import annotations

import json
import logging
import math
import os
import sys
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup

from shadeform.errors import InputError
from shadeform.io.atomic import OutputSet, target_name

#: Exit code of every user error (the same as a command-line usage error).
USAGE_EXIT = 2

# File kinds the side outputs accept (docs/conventions.md: normal maps are 16-bit PNG; depth maps
# float32 TIFF or .npy, see shadeform.io.maps.save_depth).
NORMAL_SUFFIXES = (".png",)
DEPTH_SUFFIXES = (".tif", ".tiff", ".npy")


# the base of click's usage errors, whichever click typer runs on (its own copy, or click itself)
_CLICK_ERROR = next(c for c in typer.BadParameter.__mro__ if c.__name__ == "ClickException")
#: click's "no arguments: the help was shown" (a usage error with no message of its own).
_NO_ARGS = getattr(sys.modules[_CLICK_ERROR.__module__], "NoArgsIsHelpError", ())


#: The order of ``shadeform --help``'s command list: the main job first, the tools last.
COMMAND_ORDER = (
    "reconstruct", "stereo", "fuse", "relief", "maps", "lights", "rti", "batch", "app", "demo",
    "synth", "evaluate", "solvers", "formats", "warm",
)  # fmt: skip


class _Group(TyperGroup):
    """The app's command group; the one place where errors become ``error: ...`` and exit 2."""

    def main(self, *args, **kwargs):
        """Run the command line; a usage error (a missing or malformed option, an unknown
        command, a number out of range) is one line on stderr and exit code 2, like every other
        user mistake, instead of click's boxed block."""
        import sys

        kwargs["standalone_mode"] = False  # click's exceptions reach us instead of its printer
        # the libraries' warnings and log records never reach stderr raw (see _warning_notes)
        if not logging.getLogger().handlers:
            logging.getLogger().addHandler(logging.NullHandler())
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")  # each once per place
            try:
                code = super().main(*args, **kwargs)
            except typer.Abort:
                typer.echo("error: stopped", err=True)
                sys.exit(1)
            except _NO_ARGS as err:  # a bare ``shadeform``: the help is the answer, not an error line
                sys.exit(err.exit_code)
            except _CLICK_ERROR as err:
                where = err.ctx.command_path if getattr(err, "ctx", None) is not None else "shadeform"
                message = " ".join(err.format_message().split()).rstrip(".")
                typer.echo(f"error: {message}; see '{where} --help'", err=True)
                sys.exit(err.exit_code)
        code = code if isinstance(code, int) else 0
        if code == 0:  # a refusal stays one line
            for note in _warning_notes(caught):
                typer.echo(f"note: {note}", err=True)
        sys.exit(code)

    def list_commands(self, ctx):
        """The commands in ``--help`` in the order a user reaches for them, not the order their
        modules register them (``warm`` came first)."""
        names = super().list_commands(ctx)
        return sorted(
            names, key=lambda name: COMMAND_ORDER.index(name) if name in COMMAND_ORDER else len(COMMAND_ORDER)
        )

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


#: What a damaged EXIF block (Pillow parses it with its TIFF tag reader) means to the user.
_EXIF_NOTE = (
    "the photo's EXIF data is damaged and was ignored: it is taken as stored, not turned "
    "upright; save it again if it looks rotated"
)


def _warning_notes(caught) -> list[str]:
    """What the warnings caught during a command say to its user, each once, in their words:
    Pillow's about a damaged EXIF block (its TIFF tag reader's, or any naming EXIF). Any other
    warning is an internal matter (a bug to fix where it arises, not something the user can act
    on): it goes to the ``shadeform`` logger at debug level, for a developer, not to stderr."""
    notes = []
    for caught_warning in caught:
        text = str(caught_warning.message)
        if "EXIF" in text or Path(caught_warning.filename).name == "TiffImagePlugin.py":
            notes += [_EXIF_NOTE] if _EXIF_NOTE not in notes else []
        else:
            where = f"{caught_warning.filename}:{caught_warning.lineno}"
            logging.getLogger("shadeform").debug("warning at %s: %s", where, text)
    return notes


def _os_error_message(err: OSError) -> str:
    # an output's hidden temporary is named as the file the user asked for, in its folder
    where = f" '{Path(err.filename).with_name(target_name(err.filename))}'" if err.filename else ""
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
    import gc

    from shadeform.io.atomic import exit_on_signals

    exit_on_signals()  # a kill or a closed terminal still removes the temporary files
    # Most of a command's allocations are its imports (numpy, scipy, numba), which live to its
    # end: a young collection every 10,000 allocations instead of Python's 700 finds the same
    # garbage at a fraction of the cost (about 0.1 s of a 1.6 s one-photo command). Cycles are
    # still collected. 10,000 was measured on bench_scale's 1 Mpx vase only, against 100,000
    # and no collection at all (within 0.05 s of both): a round order of magnitude, not a tuning.
    gc.set_threshold(10_000)
    try:
        app(prog_name="shadeform")
    finally:
        # The command is over and its files are written. Freezing the heap spares the exit's
        # garbage collections a walk over every object of numpy, scipy and numba: 0.25-0.3 s of
        # a 2 s one-photo command (benchmarks/results/scale.md). Nothing is left undone: the
        # frozen objects are only no longer searched for cycles, and the process is ending.
        gc.freeze()


@app.command()
def warm() -> None:
    """Compile the numba kernels now, so that the first reconstruction does not wait for them.

    Set-up does it; the kernels of the common paths are cached where the package is installed."""
    from shadeform.pipeline import warm as warm_kernels

    err = stderr_console()
    timings: dict[str, float] = {}
    with stage(err, "compiling the kernels (once per install: a minute or two)", timings, "warm"):
        seconds = warm_kernels()
    paths = ", ".join(f"{name} {format_seconds(value)}" for name, value in seconds.items())
    typer.echo(f"kernels ready in {format_seconds(timings['warm'])} ({paths})")


# --- small helpers -----------------------------------------------------------------------------


def stdout_console() -> Console:
    # soft wrap: lines (paths!) are never cut or broken by rich; the terminal wraps them
    console = Console(highlight=False, soft_wrap=True)
    if not console.is_terminal and "COLUMNS" not in os.environ:
        console.width = 120  # piped or captured: rich would assume 80 columns and wrap the tables
    return console


def stderr_console() -> Console:
    return Console(stderr=True, highlight=False)


def progress_bar(console: Console, label: str = "{task.description}"):
    """The commands' progress bar on ``console``: the label, the bar, how many of how many, the
    time taken; gone once done, shown on a terminal only (rich's Progress, imported only when a
    command shows one)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn(label),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
        # not on a terminal (a pipe, a log) there is nothing to redraw: no bar, and no blank line
        disable=not console.is_terminal,
    )


@contextmanager
def stage(console: Console, text: str, timings: dict[str, float], name: str) -> Iterator[None]:
    """Show a spinner on stderr while a long step runs and record its wall time."""
    start = time.perf_counter()
    with console.status(text, spinner="dots"):
        yield
    timings[name] = time.perf_counter() - start


def refuse_options(given: dict[str, bool], reason: str) -> None:
    """One line naming the options the user gave (``{"--flag": given, ...}``) that do not apply
    here: ``"--a, --b are <reason>"``; nothing when none was given."""
    named = [flag for flag, on in given.items() if on]
    if named:
        raise InputError(f"{', '.join(named)} {'is' if len(named) == 1 else 'are'} {reason}")


def resolve_light(light: str | None, slant: float | None, tilt: float | None) -> np.ndarray | str:
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


def parse_reference(text: str) -> tuple:
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


def check_suffix(path: Path, allowed, what: str) -> None:
    if path.suffix.lower() not in allowed:
        given = f"suffix '{path.suffix}'" if path.suffix else "no suffix"
        raise InputError(f"cannot write {what} '{path.name}': {given}; use one of {', '.join(allowed)}")


def write_rgb_png(pixels: np.ndarray, path: Path) -> None:
    """An (H, W, 3) uint8 picture as a PNG, written atomically."""
    from PIL import Image

    from shadeform.io.atomic import atomic_write

    with atomic_write(path) as file_obj:
        Image.fromarray(pixels, mode="RGB").save(file_obj, format="PNG", optimize=True)


def jsonable(value: Any) -> Any:
    """Plain JSON types (tuples -> lists, numpy scalars -> numbers, non-finite -> null)."""
    if isinstance(value, dict):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [jsonable(item) for item in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def print_json(document: dict) -> None:
    typer.echo(json.dumps(jsonable(document), indent=2))


def format_seconds(value: float) -> str:
    return f"{value:.2f} s" if value >= 0.01 else f"{value * 1000:.1f} ms"


def format_vector(values) -> str:
    """``(x, y, z)`` to three digits; rounding noise (cos 90 degrees = 6e-17) reads as 0."""
    return "(" + ", ".join(f"{float(v) if abs(v) >= 5e-4 else 0.0:.3g}" for v in values) + ")"


def describe_photo(info: dict) -> str:
    """What was decided in reading a photo (``Photo.info`` or ``PhotoSet.info``), in a few words."""
    told = {"file": "", "set": " (calibrated set)", "user": " (as told)"}[info["encoding_from"]]
    encoding = "sRGB, made linear" if info["encoding"] == "srgb" else "linear"
    channel = info["channel"]
    chosen = " (least clipped)" if info["channel_from"] == "auto" and channel in ("r", "g", "b") else ""
    return f"{info['bits']}-bit {encoding}{told}, channel {channel}{chosen}"


def note_channel(console: Console, info: dict) -> None:
    """One line on stderr when the channel was switched from luma because another clips less."""
    if info["channel_from"] != "auto" or info["channel"] not in ("r", "g", "b"):
        return
    clipped = info["clipped"]
    shares = ", ".join(f"{name} {100 * clipped[name]:.1f} %" for name in "rgb")
    console.print(
        f"note: pixels at the white level: {shares}; solving on {info['channel']} "
        "(--channel luma to solve on luma)",
        soft_wrap=True,
        highlight=False,
    )


def print_notes(console: Console, photo_info: dict, info: dict) -> None:
    """The notes on stderr of a photo (or a photo set) solved: the channel chosen, a doubtful mask,
    a set's depth that no photo shows, an unsure light estimate, a depth pulled back within its
    outline's reach, the areas the shading cannot settle."""
    note_channel(console, photo_info)
    if info.get("mask_warning"):  # a doubtful automatic mask (shadeform.masks.FoundObject.warning)
        console.print(f"warning: {info['mask_warning']}", soft_wrap=True, highlight=False)
    if info.get("quality", {}).get("warning"):  # a photo set's depth no photo shows (a slab)
        console.print(f"warning: {info['quality']['warning']}", soft_wrap=True, highlight=False)
    note_light(console, info)
    note_bounded(console, info)
    note_unsure(console, info)


def note_bounded(console: Console, info: dict) -> None:
    """One line on stderr when the solver's depth ran past what the outline allows and was pulled
    back (``info["depth_bounded"]``, :func:`shadeform.solvers.bounds.bound_depth`)."""
    bounded = info.get("depth_bounded")
    if not bounded:
        return
    console.print(
        f"note: the depth strayed up to {bounded['max_over']:.1f} times as far as the object's outline "
        f"allows, on {100 * bounded['pixels']:.1f} % of it; that part was pulled back smoothly",
        soft_wrap=True,
        highlight=False,
    )


def note_light(console: Console, info: dict) -> None:
    """One line on stderr when the light read from the photo is unsure (``info["light_estimate"]``)."""
    estimate = info.get("light_estimate")
    if not estimate or not estimate["unsure"]:
        return
    from shadeform.light import CONFIDENCE_ANGLE  # the estimator's modules only when it ran

    console.print(
        f"warning: the light read from the photo is unsure (slant {estimate['slant']:.0f}°, tilt "
        f"{estimate['tilt']:.0f}°, a {100 * estimate['confidence']:.0f} % chance of being within "
        f"{CONFIDENCE_ANGLE:.0f}°); if you know where the light was, give --slant and --tilt (or --light X,Y,Z)",
        soft_wrap=True,
        highlight=False,
    )


def read_light(info: dict) -> str:
    """ " read from the photo (slant, tilt, confidence)" when the light was estimated, else ""."""
    estimate = info.get("light_estimate")
    if not estimate:
        return ""
    return (
        f" read from the photo (slant {estimate['slant']:.0f}°, tilt {estimate['tilt']:.0f}°, "
        f"confidence {estimate['confidence']:.2f})"
    )


def note_unsure(console: Console, info: dict) -> None:
    """One line on stderr when part of the shape rests on a convex/concave guess the photo cannot
    settle (``info["unsure"]``, the area that matters most first; ``info["unsure_others"]``, the
    lesser ones left unnamed)."""
    areas = info.get("unsure") or []
    if not areas:
        return
    first = areas[0]
    x, y = (round(v) for v in first["centre"])
    others = info.get("unsure_others") or {"areas": 0, "share": 0.0}
    named = f" and {len(areas) - 1} more area(s)" if len(areas) > 1 else ""
    lesser = f" (and {others['areas']} lesser one(s))" if others["areas"] else ""
    share = sum(a["share"] for a in areas) + others["share"]
    more = f"{named}{lesser}, {100 * share:.0f} % in all" if named or lesser else ""
    console.print(
        f"warning: the shading cannot tell convex from concave around x={x}, y={y} "
        f"({100 * first['share']:.0f} % of the object){more}; if it is concave there, draw it as a "
        f'region with axis "{first["axis"]}" (--concave regions.json; --json lists the areas)',
        soft_wrap=True,
        highlight=False,
    )


def print_files(console: Console, rows: list[tuple[Path, str]]) -> None:
    """One line per file, path first; never wrapped or shortened, so it can be copied."""
    width = max(len(str(path)) for path, _ in rows)
    for path, what in rows:
        console.print(f"  [bold]{escape(str(path).ljust(width))}[/]  {escape(what)}")


# --- reconstruct -------------------------------------------------------------------------------


def check_outputs(output: Path, depth: Path | None, normals: Path | None) -> None:
    """The suffixes of the mesh and of the optional depth and normal maps."""
    from shadeform.io.exporters import available_formats

    check_suffix(output, tuple(available_formats()), "a mesh to")
    if depth is not None:
        check_suffix(depth, DEPTH_SUFFIXES, "a depth map to")
    if normals is not None:
        check_suffix(normals, NORMAL_SUFFIXES, "a normal map to")


def output_temps(outputs: OutputSet, *targets: Path | None) -> dict[Path, Path]:
    """Temporary paths for the mesh and the optional maps, taken before any work so that a bad
    output path fails first."""
    return {target: outputs.temp(target) for target in targets if target is not None}


def write_maps(rec, temps: dict[Path, Path], *, depth: Path | None, normals: Path | None) -> list:
    """Write the reconstruction's depth and normal maps that were asked for to their temporaries;
    returns their (file, description) rows to print."""
    from shadeform.io.maps import save_depth, save_normal_map

    written = []
    if depth is not None:
        save_depth(rec.depth, temps[depth])
        written.append((depth, "depth map, pixel units, NaN off the object"))
    if normals is not None:
        save_normal_map(rec.normals, temps[normals])
        written.append((normals, "normal map, 16-bit, RGB = (n + 1) / 2"))
    return written


def write_model(
    outputs: OutputSet,
    err: Console,
    timings: dict[str, float],
    rec,
    temps: dict[Path, Path],
    *,
    step: int,
    output: Path,
    depth: Path | None,
    normals: Path | None,
):
    """Mesh a reconstruction, write it and the depth and normal maps asked for to their
    temporaries, and put them all in place together; returns the mesh, the (file, description) rows
    to print and the entries every command's JSON report shares."""
    import shadeform

    with stage(err, "building the mesh", timings, "mesh"):
        mesh = shadeform.to_mesh(rec, step=step)
    with stage(err, "writing files", timings, "write"):
        shadeform.export(mesh, temps[output])
        written = [(output, shadeform.available_formats()[output.suffix.lower()])]
        written += write_maps(rec, temps, depth=depth, normals=normals)
    outputs.commit()
    report = {
        "files": {"mesh": output, "depth": depth, "normals": normals},
        "mesh": {"vertices": mesh.n_vertices, "faces": mesh.n_faces, "step": step},
        "object_pixels": int(rec.mask.sum()),
    }
    return mesh, written, report
