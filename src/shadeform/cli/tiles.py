"""``reconstruct --tiles``: huge photos solved in overlapping tiles (:mod:`shadeform.tiled`), with
a progress bar, its warnings and its summary."""

from __future__ import annotations

import stat
from pathlib import Path

from rich.markup import escape

from shadeform.cli._shell import (
    format_seconds,
    print_files,
    print_json,
    progress_bar,
    refuse_options,
    stderr_console,
    stdout_console,
)
from shadeform.errors import InputError
from shadeform.io.images import TIFF_MAGICS

__all__ = ["is_tiff", "tile_size", "tiled_reconstruct"]


def tile_size(tiles: str, image: Path, max_pixels: int | None) -> int | None:
    """The tile side for ``--tiles`` (None: solve whole): ``off``; a number; ``auto``, tiles of
    :data:`shadeform.tiled.DEFAULT_TILE` for a TIFF whose header declares more than
    ``max_pixels`` pixels (other formats are read whole, and refused there if too large)."""
    text = tiles.strip().lower()
    if text == "off":
        return None
    if text == "auto":
        if max_pixels is None or not is_tiff(image):
            return None
        from shadeform.tiled import DEFAULT_TILE, TiffWindows

        try:
            height, width = TiffWindows(image).shape[:2]
        except InputError:  # not a readable TIFF: the whole-image loader says what is wrong with it
            return None
        return DEFAULT_TILE if height * width > max_pixels else None
    try:
        return int(text)
    except ValueError:
        raise InputError(f"--tiles must be auto, off or a tile size in pixels, got {tiles!r}") from None


def is_tiff(path: Path) -> bool:
    """Whether ``path`` is a regular file that starts as a TIFF or BigTIFF does (never opens a pipe)."""
    if not path.is_file():  # a folder, or a pipe or device that could block forever
        return False
    try:
        if not stat.S_ISREG(path.stat().st_mode):
            return False  # a pipe or device could block forever: the loader refuses it
        with open(path, "rb") as handle:
            return handle.read(4) in TIFF_MAGICS
    except OSError:
        return False


def tiled_reconstruct(
    image: Path,
    output: Path,
    *,
    tile,
    scheduler,
    depth,
    as_json,
    refused,
    mask,
    keep_tiles,
    channel,
    linear,
    max_pixels,
    **options,
) -> None:
    """``reconstruct --tiles``: :func:`shadeform.tiled.reconstruct` with a progress bar on stderr."""
    from shadeform import tiled

    refuse_options(refused, "not available with tiles; use --tiles off")
    if isinstance(options["light"], str):
        raise InputError("tiles need the light as --light X,Y,Z or --slant/--tilt, not estimated")
    depth = depth if depth is not None else output.with_name(f"{output.stem}_depth.tif")
    if depth.suffix.lower() not in (".tif", ".tiff"):
        raise InputError(f"with tiles the depth map is a BigTIFF: name it .tif or .tiff, not '{depth.name}'")
    if is_tiff(image):
        source = image  # read lazily, window by window
    else:
        from shadeform.io.images import read_photo

        source = read_photo(image, channel=channel, linear=linear, max_pixels=max_pixels).image
    err = stderr_console()
    if mask is not None and str(mask) == "whole" and not mask.exists():
        mask = "whole"  # every pixel is the object: a relief filling the frame
    words = {
        "mask": "finding the object",
        "tiles": "solving tiles",
        "join": "joining tiles",
        "write": "writing depth",
    }
    with progress_bar(err) as bar:
        task = bar.add_task("reading", total=None)

        def progress(stage: str, done: int, total: int) -> None:
            bar.update(task, description=words[stage], completed=done, total=total)

        result = tiled.reconstruct(
            source, tile=tile, scheduler=scheduler, out=depth, mesh=output, progress=progress,
            mask=mask, keep_work=keep_tiles, **options,
        )  # fmt: skip
    for warning in (result.info["seam_warning"], _unsolved(result.info)):
        if warning:
            err.print(f"warning: {escape(warning)}", highlight=False, soft_wrap=True)
    height, width = result.shape
    if as_json:
        print_json(
            {
                "command": "reconstruct",
                "input": {"path": image, "width": width, "height": height},
                "tiles": {"count": result.tiles, "solved": result.solved, "skipped": result.skipped},
                "seam": result.seam,
                "files": {"mesh": output, "depth": depth},
                "info": result.info,
            }
        )
        return
    out = stdout_console()
    out.print(
        f"[bold]reconstructed[/] {escape(str(image))} ({width}x{height}) in {result.tiles} tiles of {tile}"
    )
    out.print(f"  object: {escape(result.info['mask'])}")
    out.print(
        f"  {result.solved} solved, {result.skipped} found finished; largest seam between tiles "
        f"{result.seam:.3g} px; time {format_seconds(result.info['timings']['total'])}"
    )
    out.print("[bold]wrote[/]")
    print_files(out, [(output, "mesh"), (depth, "depth map (tiled BigTIFF)")])


def _unsolved(info: dict) -> str | None:
    """A line for the tiles whose part of the object the pipeline refused, if any."""
    if not info["unsolved_tiles"]:
        return None
    return (
        f"{info['unsolved_tiles']} tile(s) left without depth, their part of the object refused: "
        f"{info['unsolved_reason']}"
    )
