"""``--max-pixels`` on every command that reads photos: one option, the loader's one limit.

A photo whose header declares more pixels than the limit ends the command with exit code 2 and
one ``error:`` line naming it, before it is decoded; the option raises (or lowers) the limit, and
reaches the loader in every command (``shadeform.io.images.MAX_PIXELS`` by default; ``app``
hands it to the server, whose own limit is the default there).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import typer
from PIL import Image

from shadeform.cli import app
from shadeform.errors import InputError
from shadeform.io.images import MAX_PIXELS

PHOTO_COMMANDS = ("reconstruct", "stereo", "lights", "batch", "fuse", "maps", "relief", "app")
SIDE = 40  # the small photo: 1,600 pixels
BIG = (8192, 8193)  # a header one row past MAX_PIXELS


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_claiming(width: int, height: int) -> bytes:
    """A PNG whose header declares any size; its data holds almost nothing."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + png_chunk(b"IHDR", ihdr)
        + png_chunk(b"IDAT", zlib.compress(b"\0" * 64))
        + png_chunk(b"IEND", b"")
    )


@pytest.fixture
def photos(tmp_path) -> list[Path]:
    """Three small gray photos (a lit disc), 40x40."""
    rows, cols = np.mgrid[0:SIDE, 0:SIDE] - SIDE / 2 + 0.5
    disc = np.clip(1 - (rows**2 + cols**2) / (SIDE / 2.5) ** 2, 0, 1)
    paths = []
    for k in range(3):
        path = tmp_path / f"photo{k}.png"
        Image.fromarray((255 * np.sqrt(disc) * (0.8 + 0.1 * k)).astype(np.uint8)).save(path)
        paths.append(path)
    return paths


@pytest.fixture
def big(tmp_path) -> list[Path]:
    """Three files whose headers claim 8192x8193 pixels."""
    paths = []
    for k in range(3):
        path = tmp_path / f"big{k}.png"
        path.write_bytes(png_claiming(*BIG))
        paths.append(path)
    return paths


def command_args(command: str, photos: list[Path], out: Path) -> list:
    """Arguments that make ``command`` read ``photos`` first thing."""
    if command == "reconstruct":
        return ["reconstruct", photos[0], "-o", out / "model.glb"]
    if command == "stereo":
        lights = out.parent / "lights.txt"
        lights.write_text("0 0 1\n0.3 0 0.95\n0 0.3 0.95\n")
        return ["stereo", *photos, "--lights", lights, "-o", out / "model.glb"]
    if command == "lights":
        return ["lights", *photos, "-o", out / "lights.txt"]
    if command == "batch":
        return ["batch", photos[0], "--out", out / "models", "--workers", "1"]
    if command == "fuse":
        return ["fuse", photos[0], photos[1], "--angles", "0,180", "-o", out / "model.glb"]
    if command == "maps":
        return ["maps", photos[0], "--out", out / "maps"]
    if command == "relief":
        return [
            "relief",
            photos[0],
            "-o",
            out / "relief.stl",
            "--width",
            "50",
            "--height",
            "3",
            "--base",
            "2",
        ]
    raise AssertionError(command)


def one_error_line(result) -> str:
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    assert "Traceback" not in result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


# The commands that read no photo or mask of the user's (a new command reading one must take
# --max-pixels, or be listed here knowingly).
NO_PHOTOS = {"synth", "evaluate", "formats", "solvers", "methods", "demo", "warm"}


def test_every_photo_command_takes_it():
    """Every command reading a photo takes ``--max-pixels``, its default the loader's limit (the
    command line writes the number out, to keep start-up light: one limit all the same)."""
    commands = typer.main.get_command(app).commands
    assert set(PHOTO_COMMANDS) <= set(commands)
    for name, command in commands.items():
        option = next((p for p in command.params if p.name == "max_pixels"), None)
        if name in NO_PHOTOS:
            assert option is None, f"{name} reads no photo but has --max-pixels"
            continue
        assert option is not None, f"{name} has no --max-pixels"
        assert option.opts == ["--max-pixels"]
        assert option.default == (None if name == "app" else MAX_PIXELS), name


@pytest.mark.parametrize("command", PHOTO_COMMANDS[:-1])
def test_too_large_by_default(cli, command, big, out):
    line = one_error_line(cli(*command_args(command, big, out)))
    assert "image too large" in line and str(big[0]) in line and f"max_pixels={MAX_PIXELS:,}" in line
    assert "--max-pixels" in line  # says how to raise it


@pytest.mark.parametrize("command", PHOTO_COMMANDS[:-1])
def test_raised_limit_reaches_the_loader(cli, command, big, out):
    """With the limit raised past the header's claim, the file gets past the size check and is
    refused for what it is: a PNG that holds almost none of its pixels."""
    line = one_error_line(cli(*command_args(command, big, out), "--max-pixels", BIG[0] * BIG[1]))
    assert "image too large" not in line and "truncated or damaged PNG" in line, line


@pytest.mark.parametrize("command", PHOTO_COMMANDS[:-1])
def test_lowered_limit(cli, command, photos, out):
    line = one_error_line(cli(*command_args(command, photos, out), "--max-pixels", SIDE * SIDE - 1))
    assert "image too large" in line and f"max_pixels={SIDE * SIDE - 1:,}" in line, line
    if command != "batch":  # batch keeps its folder of results
        assert list(out.iterdir()) == []


def test_limit_at_the_photo_size_reads_it(cli, photos, out):
    result = cli("reconstruct", photos[0], "-o", out / "model.glb", "--max-pixels", SIDE * SIDE)
    assert result.exit_code == 0, result.output
    assert (out / "model.glb").is_file()


@pytest.mark.parametrize("bad", ["0", "-3", "many"])
def test_not_a_positive_number(cli, photos, out, bad):
    result = cli("reconstruct", photos[0], "-o", out / "model.glb", "--max-pixels", bad)
    assert result.exit_code == 2
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("given", [None, 5000])
def test_app_hands_it_to_the_server(cli, monkeypatch, given):
    pytest.importorskip("fastapi")
    from shadeform.app import server
    from shadeform.app.guard import AppLimits

    seen = {}

    def fake_create_app(**kwargs):
        seen.update(kwargs)
        raise InputError("stopped before serving; a test")

    monkeypatch.setattr(server, "create_app", fake_create_app)
    args = ["app", "--no-browser"] + ([] if given is None else ["--max-pixels", given])
    assert "stopped before serving" in one_error_line(cli(*args))
    expected = AppLimits().max_pixels if given is None else given
    assert seen["limits"].max_pixels == expected


@pytest.mark.parametrize("bad", [0, 2.5, True])
def test_batch_checks_max_pixels_before_reading(tmp_path, bad):
    pytest.importorskip("dask")
    from shadeform.batch import reconstruct_files

    with pytest.raises(InputError, match="max_pixels must be a whole number >= 1"):
        reconstruct_files([tmp_path / "never-read.png"], tmp_path, max_pixels=bad)


def test_every_command_reading_photos_files_says_how_they_are_encoded():
    """``--linear/--srgb`` wherever a photo file is read (the app decides per upload: it reads no
    file of the user's path)."""
    commands = typer.main.get_command(app).commands
    for name in PHOTO_COMMANDS:
        option = next((p for p in commands[name].params if p.name == "linear"), None)
        if name == "app":
            assert option is None
            continue
        assert option is not None and option.opts == ["--linear"] and option.secondary_opts == ["--srgb"], (
            name
        )
        assert option.default is None, name  # decided by the file (and a calibrated set's folder)
