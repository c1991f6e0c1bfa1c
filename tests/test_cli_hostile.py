"""Every user mistake on the command line is one line on stderr and exit code 2, checked before
any work, and nothing is written."""

from __future__ import annotations

import pytest

from shadeform import synth
from shadeform.io.maps import save_gray


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("inputs")
    save_gray(synth.scene("sphere", size=48).image, folder / "photo.png")
    (folder / "nested.json").write_text("[" * 100_000 + "]" * 100_000)
    (folder / "deep_views.json").write_text('{"views": ' + "[" * 100_000 + "]" * 100_000 + "}")
    (folder / "empty.png").write_bytes(b"")
    (folder / "notes.png").write_text("these are notes, not a photo")
    return folder


CASES = [
    ("missing output", ["reconstruct", "{photo}"], "--output"),
    ("unknown command", ["reconstrut", "{photo}"], "No such command"),
    ("step 0", ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--step", "0"], "--step"),
    (
        "step beyond the image",
        ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--step", "1000000000"],
        "step",
    ),
    ("slant 1e308", ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--slant", "1e308"], "slant"),
    ("slant not a number", ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--slant", "abc"], "--slant"),
    ("light with NaN", ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--light", "nan,0,1"], "light"),
    (
        "filter radius 1e20",
        ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--filter", "median:1e20"],
        "filter",
    ),
    ("refine 1e9", ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--refine", "1000000000"], "--refine"),
    (
        "nested regions",
        ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--concave", "{inputs}/nested.json"],
        "deeply",
    ),
    ("max pixels 0", ["reconstruct", "{photo}", "-o", "{out}/m.glb", "--max-pixels", "0"], "--max-pixels"),
    ("unknown mesh suffix", ["reconstruct", "{photo}", "-o", "{out}/m.xyz"], "suffix"),
    ("missing folder", ["reconstruct", "{photo}", "-o", "{out}/no/such/m.glb"], "does not exist"),
    ("empty photo", ["reconstruct", "{inputs}/empty.png", "-o", "{out}/m.glb"], "empty"),
    ("text as photo", ["reconstruct", "{inputs}/notes.png", "-o", "{out}/m.glb"], "notes.png"),
    ("folder as photo", ["reconstruct", "{inputs}", "-o", "{out}/m.glb"], "folder"),
    ("synth size 1e9", ["synth", "sphere", "-o", "{out}/s.png", "--size", "1000000000"], "size"),
    ("fuse angle 1e309", ["fuse", "{photo}", "{photo}", "--angles", "0,1e309", "-o", "{out}/f.glb"], "angle"),
    ("deep views file", ["fuse", "--views", "{inputs}/deep_views.json", "-o", "{out}/f.glb"], "views"),
    ("maps reach 0.5", ["maps", "{photo}", "--out", "{out}/maps", "--reach", "0.5"], "--reach"),
    ("maps tile alone", ["maps", "{photo}", "--out", "{out}/maps", "--tile"], "--material"),
    (
        "unknown map name",
        ["maps", "{photo}", "--out", "{out}/maps", "--maps", "height,glossiness"],
        "glossiness",
    ),
    (
        "relief width 0",
        ["relief", "{photo}", "-o", "{out}/r.stl", "--width", "0", "--height", "3", "--base", "2"],
        "width",
    ),
    (
        "relief negative height",
        ["relief", "{photo}", "-o", "{out}/r.stl", "--width", "50", "--height", "-3", "--base", "2"],
        "height",
    ),
    (
        "relief base thinner than a wall",
        ["relief", "{photo}", "-o", "{out}/r.stl", "--width", "50", "--height", "3", "--base", "0.1"],
        "base",
    ),
    (
        "relief budget 0",
        [
            "relief",
            "{photo}",
            "-o",
            "{out}/r.stl",
            "--width",
            "50",
            "--height",
            "3",
            "--base",
            "2",
            "--max-triangles",
            "0",
        ],
        "triangles",
    ),
]


@pytest.mark.parametrize(("args", "fragment"), [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_one_line_exit_2_nothing_written(files, tmp_path, cli, args, fragment):
    out = tmp_path / "out"
    out.mkdir()
    names = {"photo": files / "photo.png", "inputs": files, "out": out}
    result = cli(*(arg.format(**names) for arg in args))
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert fragment in lines[0]
    assert list(out.iterdir()) == []
