"""Tests for the ``shadeform`` command line (shadeform.cli) and the shipped examples.

Every bad input must end the same way: exit code 2, one line ``error: ...`` on stderr (no
traceback), nothing on stdout, and no file left in the output folder (not even a temporary).
The happy paths check what the files hold, not only that they exist.
"""

from __future__ import annotations

import errno
import json
import os
import re
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
import tifffile
import trimesh
from PIL import Image
from typer.testing import CliRunner

import shadeform
from helpers.photosets import write_photo_set
from shadeform import metrics, synth
from shadeform.cli import app
from shadeform.errors import InputError
from shadeform.examples import EXAMPLES, load_example
from shadeform.io.maps import load_depth, load_normal_map, save_gray

FORMATS = tuple(shadeform.available_formats())
SIZE = 40  # side of the synthetic test image: small, so each run takes milliseconds


def invoke(*args: str):
    # a wide console, whatever the terminal running the tests: tables are not wrapped
    return CliRunner(env={"COLUMNS": "200"}).invoke(app, [str(arg) for arg in args])


def assert_fails(result, out_dir: Path, *fragments: str) -> str:
    """Exit 2 with one ``error:`` line naming the problem, and ``out_dir`` left empty."""
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    assert "Traceback" not in result.output
    assert result.stdout == ""
    lines = result.stderr.splitlines()  # exactly one line: no blank line before it either
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for fragment in fragments:
        assert fragment.lower() in lines[0].lower(), lines[0]
    assert sorted(p.name for p in out_dir.iterdir()) == []
    return lines[0]


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_file(width: int, height: int, idat: bytes) -> bytes:
    """A PNG whose IHDR declares ``width`` x ``height`` 8-bit grey, with the given IDAT payload."""
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", header) + png_chunk(b"IDAT", idat) + png_chunk(b"IEND", b"")
    )


@pytest.fixture(scope="module")
def sphere(tmp_path_factory) -> dict[str, Path]:
    """A synthetic sphere and its truth, written by ``shadeform synth`` (tested below)."""
    folder = tmp_path_factory.mktemp("sphere")
    result = invoke("synth", "sphere", "-o", folder / "sphere.png", "--size", SIZE)
    assert result.exit_code == 0, result.output
    return {
        "image": folder / "sphere.png",
        "mask": folder / "sphere_mask.png",
        "depth": folder / "sphere_depth.npy",
        "normals": folder / "sphere_normals.png",
    }


@pytest.fixture
def inputs(tmp_path) -> Path:
    folder = tmp_path / "in"
    folder.mkdir()
    return folder


def reconstruct_args(image, out: Path, *extra) -> list:
    """A reconstruction that writes three files, so a failure has three chances to leave one."""
    return [
        "reconstruct",
        image,
        "-o",
        out / "model.wrl",
        "--depth",
        out / "depth.tiff",
        "--normals",
        out / "normals.png",
        "--refine",
        "0",
        *extra,
    ]


# --- bad inputs: one test each ------------------------------------------------------------------


class TestBadImages:
    def test_not_an_image(self, inputs, out):
        path = inputs / "notes.png"
        path.write_text("these are my notes, not a picture\n")
        assert_fails(invoke(*reconstruct_args(path, out)), out, "not an image")

    def test_truncated_png(self, sphere, inputs, out):
        data = sphere["image"].read_bytes()
        path = inputs / "cut.png"
        path.write_bytes(data[: len(data) // 2])
        assert_fails(invoke(*reconstruct_args(path, out)), out, "truncated")

    def test_empty_file(self, inputs, out):
        path = inputs / "empty.png"
        path.write_bytes(b"")
        assert_fails(invoke(*reconstruct_args(path, out)), out)

    def test_one_pixel_image(self, inputs, out):
        path = inputs / "dot.png"
        Image.new("L", (1, 1), 200).save(path)
        assert_fails(invoke(*reconstruct_args(path, out)), out, "too small")

    def test_zero_pixel_image(self, inputs, out):
        path = inputs / "nothing.png"
        path.write_bytes(png_file(0, 0, zlib.compress(b"")))
        assert_fails(invoke(*reconstruct_args(path, out)), out, "too small")

    def test_all_black_image(self, inputs, out):
        path = inputs / "black.png"
        Image.new("L", (32, 32), 0).save(path)
        assert_fails(invoke(*reconstruct_args(path, out)), out, "black")

    def test_all_white_image(self, inputs, out):
        path = inputs / "white.png"
        Image.new("L", (32, 32), 255).save(path)
        message = assert_fails(invoke(*reconstruct_args(path, out)), out)
        assert "constant" in message or "saturated" in message

    def test_mostly_clipped_image(self, inputs, out):
        # a bright disk on black, 95 % of it clipped at white: no shading left to read
        rows, cols = np.mgrid[:64, :64]
        radius = np.hypot(rows - 31.5, cols - 31.5)
        image = np.where(radius < 28, 255, 0).astype(np.uint8)
        image[(radius >= 27) & (radius < 28)] = 180
        assert (image == 255).sum() > 0.9 * (image > 0).sum()
        path = inputs / "clipped.png"
        Image.fromarray(image).save(path)
        assert_fails(invoke(*reconstruct_args(path, out)), out, "saturated")

    def test_nan_in_float_tiff(self, inputs, out):
        image = np.full((32, 32), 0.5, dtype=np.float32)
        image[10, 12] = np.nan
        path = inputs / "nan.tiff"
        tifffile.imwrite(path, image)
        assert_fails(invoke(*reconstruct_args(path, out)), out, "NaN")

    def test_nan_in_mask_tiff(self, sphere, inputs, out):
        mask = np.ones((SIZE, SIZE), dtype=np.float32)
        mask[3, 4] = np.nan
        path = inputs / "mask.tiff"
        tifffile.imwrite(path, mask)
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--mask", path)), out, "NaN")

    def test_huge_declared_dimensions(self, inputs, out):
        # a few hundred bytes that claim 100000 x 100000 pixels: refused before decoding
        path = inputs / "bomb.png"
        path.write_bytes(png_file(100_000, 100_000, zlib.compress(b"\x00" * 100_001)))
        assert path.stat().st_size < 1000
        assert_fails(invoke(*reconstruct_args(path, out)), out, "too large")

    def test_missing_image(self, inputs, out):
        assert_fails(invoke(*reconstruct_args(inputs / "nowhere.png", out)), out, "nowhere.png")

    def test_mask_of_another_size(self, inputs, sphere, out):
        path = inputs / "small_mask.png"
        Image.new("L", (SIZE - 1, SIZE), 255).save(path)
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--mask", path)), out, "mask")


class TestBadOutputs:
    def test_unknown_export_suffix(self, sphere, out):
        result = invoke("reconstruct", sphere["image"], "-o", out / "model.xyz")
        message = assert_fails(result, out, ".xyz")
        assert all(suffix in message for suffix in FORMATS)  # says what would work

    def test_no_suffix(self, sphere, out):
        assert_fails(invoke("reconstruct", sphere["image"], "-o", out / "model"), out, "no suffix")

    def test_bad_depth_suffix(self, sphere, out):
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--depth", out / "d.jpg")), out, ".npy")

    def test_bad_normal_map_suffix(self, sphere, out):
        result = invoke("reconstruct", sphere["image"], "-o", out / "m.wrl", "--normals", out / "n.jpg")
        assert_fails(result, out, ".png")

    def test_missing_output_folder(self, sphere, out):
        result = invoke("reconstruct", sphere["image"], "-o", out / "sub" / "m.wrl")
        assert_fails(result, out, "does not exist")

    def test_same_file_twice(self, sphere, out):
        result = invoke(
            "reconstruct",
            sphere["image"],
            "-o",
            out / "m.wrl",
            "--normals",
            out / "x.png",
            "--depth",
            out / "x.png",
        )
        assert_fails(result, out)

    def test_existing_file_is_kept_on_failure(self, sphere, out):
        (out / "model.wrl").write_text("my old model\n")
        result = invoke(*reconstruct_args(sphere["image"], out, "--light", "0,0,-1"))
        assert result.exit_code == 2
        assert sorted(p.name for p in out.iterdir()) == ["model.wrl"]
        assert (out / "model.wrl").read_text() == "my old model\n"

    def test_failing_last_write_removes_the_others(self, sphere, out, monkeypatch):
        # the mesh and depth map are written, then the normal map hits a full disk
        def full_disk(normals, path):
            Path(path).write_bytes(b"\x89PNG half")
            raise OSError(errno.ENOSPC, "No space left on device", str(path))

        monkeypatch.setattr("shadeform.io.maps.save_normal_map", full_disk)
        assert_fails(invoke(*reconstruct_args(sphere["image"], out)), out, "no space left")

    def test_failing_rename_removes_the_renamed(self, sphere, out, monkeypatch):
        # the second of the three final renames fails: the first target must go again
        real_replace = os.replace
        finals = []

        def flaky_replace(src, dst):
            if ".partial" not in Path(dst).name:  # a final rename, not a writer's own
                finals.append(dst)
                if len(finals) == 2:
                    raise PermissionError(errno.EACCES, "Permission denied", str(dst))
            return real_replace(src, dst)

        monkeypatch.setattr(os, "replace", flaky_replace)
        assert_fails(invoke(*reconstruct_args(sphere["image"], out)), out, "permission denied")
        assert len(finals) == 2


class TestBadRegions:
    @pytest.mark.parametrize(
        ("text", "fragment"),
        [
            ('{"regions": [', "not valid JSON"),
            ("", "not valid JSON"),
            ("[1, 2]", "must be an object"),
            ("{}", "'regions'"),
            ('{"regions": {"polygon": []}}', "must be a list"),
            ('{"regions": [{"polygon": [[0, 0], [5, 5]], "axis": "x"}]}', "at least 3 points"),
            ('{"regions": [{"polygon": [[0, 0], [5, 0], [5, 5]], "axis": "z"}]}', "axis"),
            ('{"regions": [{"polygon": [[0, 0], ["five", 0], [5, 5]], "axis": "x"}]}', "non-numeric"),
            ('{"regions": [{"axis": "both"}]}', "missing 'polygon'"),
        ],
        ids=[
            "cut-off",
            "empty",
            "list",
            "no-regions",
            "regions-not-list",
            "two-points",
            "bad-axis",
            "text-coordinate",
            "no-polygon",
        ],
    )
    def test_malformed_concave_json(self, sphere, inputs, out, text, fragment):
        path = inputs / "regions.json"
        path.write_text(text)
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--concave", path)), out, fragment)

    def test_concave_file_not_utf8(self, sphere, inputs, out):
        path = inputs / "regions.json"
        path.write_bytes(b'\xff\xfe{"regions": []}')
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--concave", path)), out, "UTF-8")

    def test_concave_file_missing(self, sphere, inputs, out):
        result = invoke(*reconstruct_args(sphere["image"], out, "--concave", inputs / "none.json"))
        assert_fails(result, out, "not found")


class TestBadReferencesAndLights:
    @pytest.mark.parametrize("reference", ["0,0", "39,0", "500,500", "-3,20"])
    def test_reference_outside_the_mask(self, sphere, out, reference):
        result = invoke(
            *reconstruct_args(sphere["image"], out, "--reference", "20,20", "--reference", reference)
        )
        assert_fails(result, out, "not on the object")

    @pytest.mark.parametrize("reference", ["20", "20,x", "1,2,3", "20,20,0,0,one", ""])
    def test_malformed_reference(self, sphere, out, reference):
        assert_fails(
            invoke(*reconstruct_args(sphere["image"], out, "--reference", reference)), out, "--reference"
        )

    def test_light_from_behind(self, sphere, out):
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--light", "0,0,-1")), out, "z <= 0")

    @pytest.mark.parametrize("light", ["0,1", "a,b,c", "0,0,0", "0,0,nan"])
    def test_malformed_light(self, sphere, out, light):
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--light", light)), out, "light")

    def test_light_and_slant_together(self, sphere, out):
        result = invoke(*reconstruct_args(sphere["image"], out, "--light", "0,0,1", "--slant", "20"))
        assert_fails(result, out, "not both")

    def test_tilt_without_slant(self, sphere, out):
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--tilt", "30")), out, "--slant")

    def test_slant_past_the_horizon(self, sphere, out):
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, "--slant", "95")), out, "slant")

    @pytest.mark.parametrize(
        ("option", "value"),
        [("--channel", "alpha"), ("--solver", "magic"), ("--integrator", "guess"), ("--filter", "blur:2")],
    )
    def test_unknown_names(self, sphere, out, option, value):
        assert_fails(invoke(*reconstruct_args(sphere["image"], out, option, value)), out, value)


class TestUsage:
    def test_usage_errors_exit_2(self, sphere, out):
        for args in (
            ["reconstruct", sphere["image"]],
            ["reconstruct", sphere["image"], "-o", out / "m.wrl", "--step", "0"],
            ["nonsense"],
        ):
            result = invoke(*args)
            assert result.exit_code == 2
            assert "Traceback" not in result.output
        assert list(out.iterdir()) == []

    @pytest.mark.parametrize("tiles", ["auto", "512"])
    def test_a_damaged_tiff_is_one_line_whatever_the_tiling(self, inputs, out, tiles):
        """``--tiles auto`` reads a TIFF's header to choose; a damaged one is the loader's to
        refuse (it was a traceback and exit 1 from the tile check)."""
        (inputs / "bad.tif").write_bytes(b"II*\x00")
        result = invoke("reconstruct", inputs / "bad.tif", "-o", out / "m.glb", "--tiles", tiles)
        assert_fails(result, out, "truncated or damaged TIFF", "bad.tif")

    def test_a_command_with_a_progress_bar_fails_in_one_line(self, inputs, out):
        """Off a terminal the progress bar is not drawn: its blank line came before the error."""
        views = inputs / "views.json"
        views.write_text(
            json.dumps({"views": [{"photo": "gone.png", "angle": 0}, {"photo": "gone2.png", "angle": 90}]})
        )
        assert_fails(invoke("fuse", "--views", views, "-o", out / "f.glb"), out, "not found", "gone.png")

    def test_help_names_the_extras_to_install(self):
        # rich reads "[fusion]" as markup and drops it unless escaped
        assert "'shadeform[fusion]'" in invoke("fuse", "--help").output
        assert "'shadeform[print]'" in invoke("relief", "--help").output

    def test_bare_command_shows_the_commands_main_job_first(self):
        result = invoke()
        assert "error:" not in result.output and "Traceback" not in result.output
        listed = [
            line.split()[1]
            for line in result.output.splitlines()
            if line.startswith("│ ") and len(line.split()) > 2
        ]
        names = [name for name in listed if name.isalpha()]
        assert names[:3] == ["reconstruct", "stereo", "fuse"] and names[-1] == "warm", names
        # each command's summary is whole sentences, however its docstring wraps
        assert "does not wait for them." in result.output

    def test_console_script_end_to_end(self, inputs, out):
        script = Path(sys.executable).parent / "shadeform"
        if not script.exists():
            pytest.skip("console script not installed (pip install -e .)")
        (inputs / "notes.txt").write_text("not an image")
        done = subprocess.run(
            [script, "reconstruct", inputs / "notes.txt", "-o", out / "m.glb"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 2
        assert done.stdout == ""
        assert done.stderr.startswith("error: not an image") and done.stderr.count("\n") == 1
        assert list(out.iterdir()) == []


# --- happy paths ------------------------------------------------------------------------------


def face_lines(text: str) -> int:
    """Triangles in the coordIndex of a .wrl or .iv: lines 'a b c -1,' (Inventor: 'a, b, c, -1,')."""
    block = text.split("coordIndex [", 1)[1].split("]", 1)[0]
    return len(re.findall(r"^\s*\d+,?\s+\d+,?\s+\d+,?\s+-1,?\s*$", block, flags=re.MULTILINE))


class TestReconstruct:
    @pytest.mark.parametrize("suffix", FORMATS)
    def test_every_format(self, sphere, out, suffix):
        target = out / f"model{suffix}"
        result = invoke(
            "reconstruct", sphere["image"], "-o", target, "--refine", "0", "--step", "2", "--json"
        )
        assert result.exit_code == 0, result.output
        report = json.loads(result.stdout)
        assert [p.name for p in out.iterdir()] == [target.name]  # no temporaries left
        faces = report["mesh"]["faces"]
        assert faces > 100
        if suffix in (".wrl", ".iv"):
            text = target.read_text()
            assert text.startswith("#VRML V2.0 utf8" if suffix == ".wrl" else "#Inventor V2.1 ascii")
            assert face_lines(text) == faces
        else:
            loaded = trimesh.load(target, file_type=suffix[1:], force="mesh", process=False)
            assert len(loaded.faces) == faces

    def test_json_lists_the_files(self, sphere, out):
        result = invoke(
            "reconstruct",
            sphere["image"],
            "-o",
            out / "m.glb",
            "--depth",
            out / "d.npy",
            "--normals",
            out / "n.png",
            "--json",
        )
        assert result.exit_code == 0, result.output
        report = json.loads(result.stdout)  # stdout holds the JSON object and nothing else
        files = report["files"]
        assert {Path(files[key]).name for key in ("mesh", "depth", "normals")} == {"m.glb", "d.npy", "n.png"}
        assert sorted(p.name for p in out.iterdir()) == ["d.npy", "m.glb", "n.png"]
        assert report["info"]["solver_requested"] == "auto" and report["info"]["solver"] == "eikonal"
        assert report["timings"]["total"] > 0
        assert report["mesh"]["vertices"] == len(trimesh.load(out / "m.glb", force="mesh").vertices)

    def test_estimated_light_and_eikonal(self, sphere, out):
        for extra in (["--light", "estimate"], ["--solver", "eikonal"]):
            result = invoke(
                "reconstruct",
                sphere["image"],
                "-o",
                out / "m.glb",
                "--mask",
                sphere["mask"],
                "--json",
                *extra,
            )
            assert result.exit_code == 0, result.output
            info = json.loads(result.stdout)["info"]
            if extra[0] == "--light":
                assert info["light_estimate"]["slant"] < 3  # the sphere is lit from +z
            else:
                assert info["solver"] == "eikonal" and info["singular_points"]

    def test_the_summary_says_what_ran(self, sphere, out):
        """The refinement is named only where it ran, and a light of slant 30 and tilt 90 reads
        (0, 0.5, 0.866), not with cos(90 degrees)'s rounding noise."""
        lines = {}
        for method in ("eikonal", "propagation"):
            extra = ["--slant", "30", "--tilt", "90"] if method == "propagation" else []
            result = invoke(
                "reconstruct", sphere["image"], "-o", out / f"{method}.glb", "--solver", method, *extra
            )
            assert result.exit_code == 0, result.output
            lines[method] = result.stdout.splitlines()[1]
        assert lines["eikonal"].startswith("  solver eikonal, depth by ") and "refine" not in lines["eikonal"]
        assert lines["propagation"].startswith("  solver propagation, refined 3 times, depth by ")
        assert "light (0, 0.5, 0.866)" in lines["propagation"]

    def test_an_unsure_light_estimate_is_said_and_a_sure_one_is_not(self, sphere, out, tmp_path):
        """A cylinder seen side-on shows only the light's component across its axis (every light
        in the plane of the axis and the viewer gives the same image): its estimate is unsure."""
        result = invoke("synth", "cylinder", "-o", tmp_path / "cylinder.png", "--size", 64)
        assert result.exit_code == 0, result.output
        said = {}
        for name, image in (("sphere", sphere["image"]), ("cylinder", tmp_path / "cylinder.png")):
            result = invoke("reconstruct", image, "-o", out / f"{name}.glb", "--light", "estimate")
            assert result.exit_code == 0, result.output
            said[name] = [line for line in result.stderr.splitlines() if "light read from the photo" in line]
            assert "read from the photo" in result.stdout  # the summary says where the light came from
        assert said["sphere"] == []
        assert len(said["cylinder"]) == 1 and "--slant and --tilt" in said["cylinder"][0], said
        result = invoke(
            "reconstruct", tmp_path / "cylinder.png", "-o", out / "c.glb", "--light", "estimate", "--json"
        )
        estimate = json.loads(result.stdout)["info"]["light_estimate"]
        assert estimate["unsure"] and estimate["confidence"] < 0.5

    @pytest.mark.parametrize("depth_name", ["depth.tiff", "depth.npy"])
    def test_depth_and_normals_are_readable_and_right(self, sphere, out, depth_name):
        result = invoke(
            "reconstruct",
            sphere["image"],
            "-o",
            out / "m.obj",
            "--depth",
            out / depth_name,
            "--normals",
            out / "normals.png",
            "--mask",
            sphere["mask"],
        )
        assert result.exit_code == 0, result.output
        depth = load_depth(out / depth_name)
        normals = load_normal_map(out / "normals.png")
        truth_depth = load_depth(sphere["depth"])
        truth_normals = load_normal_map(sphere["normals"])
        mask = np.isfinite(truth_depth)
        assert np.array_equal(np.isfinite(depth), mask)
        assert np.array_equal(np.isfinite(normals[..., 0]), mask)
        assert metrics.angular_error(normals, truth_normals, mask) < 3
        assert metrics.depth_error(depth, truth_depth, mask) < 5

    def test_options_reach_the_library(self, sphere, inputs, out):
        regions = inputs / "regions.json"
        regions.write_text('{"regions": [{"polygon": [[0, 0], [8, 0], [8, 8]], "axis": "x"}]}')
        result = invoke(
            "reconstruct",
            sphere["image"],
            "-o",
            out / "m.stl",
            "--filter",
            "gaussian:1",
            "--slant",
            "10",
            "--tilt",
            "90",
            "--reference",
            "20,20",
            "--reference",
            "12,18,0,0.4,0.9",
            "--concave",
            regions,
            "--integrator",
            "poisson",
            "--refine",
            "1",
            "--solver",
            "propagation",
            "--json",
        )
        assert result.exit_code == 0, result.output
        info = json.loads(result.stdout)["info"]
        assert info["references"] == [[20, 20], [12, 18]]
        assert (info["filter"], info["integrator"], info["refine"]) == ("gaussian", "poisson", 1)
        light = json.loads(result.stdout)["light"]
        assert np.allclose(light, [0, np.sin(np.radians(10)), np.cos(np.radians(10))])

    def test_summary(self, sphere, out):
        result = invoke("reconstruct", sphere["image"], "-o", out / "m.ply", "--refine", "0")
        assert result.exit_code == 0, result.output
        assert "m.ply" in result.stdout and "triangles" in result.stdout
        assert [p.name for p in out.iterdir()] == ["m.ply"]


class TestUnsure:
    def test_a_guessed_neck_gets_one_warning_line(self, tmp_path):
        """The vase lit from the upper right: its neck rests on a convex guess the shading cannot
        settle (``shadeform.confidence``); the run succeeds and says so in one line."""
        made = invoke("synth", "vase", "-o", tmp_path / "vase.png", "--size", 128, "--light", "5,5,7")
        assert made.exit_code == 0, made.output
        args = ["reconstruct", tmp_path / "vase.png", "--mask", tmp_path / "vase_mask.png"]
        result = invoke(*args, "-o", tmp_path / "m.ply", "--light", "5,5,7", "--json")
        assert result.exit_code == 0, result.output
        lines = result.stderr.strip().splitlines()
        warnings = [line for line in lines if line.startswith("warning: ")]
        assert len(warnings) == 1 and 'axis "y"' in warnings[0], result.stderr
        (area,) = json.loads(result.stdout)["info"]["unsure"]
        assert area["axis"] == "y" and area["centre"][1] < 64  # the neck, in the upper half
        # the mirrored neck was marched 170 pixels behind the body: pulled back, in one note line
        (note,) = [line for line in lines if not line.startswith("warning: ")]
        bounded = json.loads(result.stdout)["info"]["depth_bounded"]
        assert note.startswith("note: the depth strayed") and f"{100 * bounded['pixels']:.1f} %" in note
        assert bounded["max_over"] > 1 and 0 < bounded["pixels"] < 0.2

    def test_the_lesser_areas_are_counted_and_a_bounded_depth_noted(self):
        import io

        from rich.console import Console

        from shadeform.cli._shell import print_notes

        area = {"polygon": [[0, 0], [4, 0], [0, 4]], "axis": "both", "share": 0.05, "centre": [10.4, 20.6]}
        info = {
            "unsure": [area, {**area, "share": 0.04}, {**area, "share": 0.03}],
            "unsure_others": {"areas": 10, "share": 0.3},
            "depth_bounded": {"pixels": 0.066, "max_over": 2.94},
        }
        out = io.StringIO()
        print_notes(Console(file=out, width=80), {"channel_from": "user", "channel": "luma"}, info)
        note, warning = out.getvalue().strip().splitlines()  # one line each, however narrow
        assert note == (
            "note: the depth strayed up to 2.9 times as far as the object's outline allows, on 6.6 % "
            "of it; that part was pulled back smoothly"
        )
        assert (
            "around x=10, y=21 (5 % of the object) and 2 more area(s) (and 10 lesser one(s)), 42 % in all"
            in warning
        )


class TestSynth:
    def test_writes_image_and_truth(self, sphere):
        scene = synth.scene("sphere", size=SIZE)
        assert sorted(p.name for p in sphere["image"].parent.iterdir()) == sorted(
            p.name for p in sphere.values()
        )
        image = shadeform.load_image(sphere["image"])
        assert np.abs(image - scene.image).max() <= 0.5 / 65535 + 1e-7  # all 16 bits kept
        assert np.array_equal(shadeform.load_mask(sphere["mask"]), scene.mask)
        assert np.array_equal(np.load(sphere["depth"]), scene.depth, equal_nan=True)
        normals = load_normal_map(sphere["normals"])
        assert metrics.angular_error(normals, scene.normals) < 0.01

    def test_light_noise_and_tiff_depth(self, tmp_path):
        result = invoke(
            "synth",
            "bowl",
            "-o",
            tmp_path / "b.png",
            "--size",
            "24",
            "--slant",
            "30",
            "--tilt",
            "45",
            "--noise",
            "0.02",
            "--seed",
            "3",
            "--depth-format",
            "tiff",
        )
        assert result.exit_code == 0, result.output
        scene = synth.scene(
            "bowl",
            size=24,
            light=[np.sin(np.radians(30)) * np.cos(np.radians(45))] * 2 + [np.cos(np.radians(30))],
            noise=0.02,
            seed=3,
        )
        assert np.abs(shadeform.load_image(tmp_path / "b.png") - scene.image).max() < 1e-4
        assert np.allclose(load_depth(tmp_path / "b_depth.tiff"), scene.depth, equal_nan=True, atol=1e-4)

    def test_unknown_scene(self, out):
        assert_fails(invoke("synth", "teapot", "-o", out / "t.png"), out, "teapot")

    def test_light_from_behind(self, out):
        assert_fails(invoke("synth", "sphere", "-o", out / "s.png", "--light", "0,0,-1"), out, "z <= 0")


def test_formats_lists_the_registry():
    result = invoke("formats")
    assert result.exit_code == 0
    for suffix in FORMATS:
        assert suffix in result.stdout
    assert ".wrl" in result.stdout and ".iv" in result.stdout
    listed = json.loads(invoke("formats", "--json").stdout)["formats"]
    assert listed == shadeform.available_formats()


class TestEvaluate:
    def test_table_has_every_scene(self):
        result = invoke("evaluate", "--size", "64", "--solvers", "propagation,eikonal")
        assert result.exit_code == 0, result.output
        for name in synth.SCENES:
            assert name in result.stdout
        assert "bowl, concave regions drawn" in result.stdout and "eikonal" in result.stdout

    def test_numbers(self):
        result = invoke(
            "evaluate",
            "--size",
            "64",
            "--scenes",
            "sphere,bowl",
            "--solvers",
            "propagation",
            "--solvers",
            "eikonal",
            "--json",
        )
        assert result.exit_code == 0, result.output
        rows = json.loads(result.stdout)["rows"]
        # sphere: 3 methods; bowl: 3 methods x without/with its region
        assert [(r["scene"], r["concave_region"], r["label"]) for r in rows] == [
            ("sphere", False, "propagation"),
            ("sphere", False, "propagation (2002, no refinement)"),
            ("sphere", False, "eikonal"),
            ("bowl", False, "propagation"),
            ("bowl", True, "propagation"),
            ("bowl", False, "propagation (2002, no refinement)"),
            ("bowl", True, "propagation (2002, no refinement)"),
            ("bowl", False, "eikonal"),
            ("bowl", True, "eikonal"),
        ]
        error = {(r["scene"], r["concave_region"], r["label"]): r["angular_error_deg"] for r in rows}
        assert error["sphere", False, "propagation"] < 3 and error["sphere", False, "eikonal"] < 3
        assert error["bowl", True, "propagation"] < 3 < 10 < error["bowl", False, "propagation"]

    def test_unknown_scene(self, out):
        assert_fails(invoke("evaluate", "--scenes", "sphere,teapot"), out, "teapot")


class TestDemo:
    def test_writes_its_files(self, tmp_path):
        folder = tmp_path / "demo" / "nested"
        result = invoke("demo", "--out", folder)
        assert result.exit_code == 0, result.output
        names = {"input.png", "normals.png", "model.wrl", "model.iv", "model.glb", "result.png"}
        assert {p.name for p in folder.iterdir()} == names
        for name in names:
            assert name in result.stdout
        mesh = trimesh.load(folder / "model.glb", force="mesh")
        assert len(mesh.faces) > 1000
        picture = np.asarray(Image.open(folder / "result.png").convert("RGB"))
        assert picture.shape[1] > 2.5 * picture.shape[0]  # three panels side by side
        view = picture[:, 2 * picture.shape[1] // 3 :]
        assert (view.std(axis=2) > 10).mean() > 0.2  # the clay-coloured mesh covers the third panel

    def test_synthetic_example_and_step(self, tmp_path):
        result = invoke("demo", "--out", tmp_path, "--example", "synth:sphere", "--size", "32", "--step", "2")
        assert result.exit_code == 0, result.output
        assert "step 2" in result.stdout
        assert (tmp_path / "model.wrl").read_text().startswith("#VRML V2.0")

    def test_unknown_example_leaves_no_folder(self, tmp_path):
        result = invoke("demo", "--out", tmp_path / "demo", "--example", "teapot")
        assert_fails(result, tmp_path, "teapot")


class TestExamples:
    def test_coin(self):
        image, info = load_example("coin")
        assert image.dtype == np.float32 and image.ndim == 2 and min(image.shape) >= 64
        assert image.min() >= 0 and image.max() <= 1
        assert info["mask"] is None and info["light"] == "estimate" and info["step"] >= 1
        # a bright coin on a dark background: the border is dark, the centre bright
        border = np.concatenate([image[0], image[-1], image[:, 0], image[:, -1]])
        assert border.mean() < 0.35 < image[30:50, 30:50].mean()

    def test_every_synthetic_scene_is_an_example(self):
        for name in synth.SCENES:
            assert f"synth:{name}" in EXAMPLES
        image, info = load_example("synth:bowl", size=32)
        assert image.shape == (32, 32) and image.dtype == np.float32
        assert np.array_equal(info["mask"], synth.scene("bowl", size=32).mask)

    @pytest.mark.parametrize("name", ["teapot", "synth:teapot", ""])
    def test_unknown_name(self, name):
        with pytest.raises(InputError, match="unknown"):
            load_example(name)

    def test_size_is_for_synthetic_examples_only(self):
        with pytest.raises(InputError, match="size"):
            load_example("coin", size=64)


# --- stereo --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def photo_set(tmp_path_factory) -> dict:
    """A sphere under six lights: 16-bit photos, a light file and the truth."""
    folder = tmp_path_factory.mktemp("stereo")
    scene = synth.scene("sphere", size=SIZE)
    photos = write_photo_set(folder, scene.normals, scene.mask)
    return {"folder": folder, "photos": photos, "lights": folder / "light_directions.txt", "scene": scene}


class TestStereo:
    def test_folder(self, photo_set, out):
        result = invoke(
            "stereo",
            photo_set["folder"],
            "-o",
            out / "m.ply",
            "--normals",
            out / "n.png",
            "--depth",
            out / "d.npy",
        )
        assert result.exit_code == 0, result.output
        assert "6 photos" in result.stdout
        scene = photo_set["scene"]
        normals = load_normal_map(out / "n.png")
        inner = scene.mask & (scene.normals[..., 2] > 0.3)
        assert metrics.angular_error(normals, scene.normals, inner) < 0.1
        depth = load_depth(out / "d.npy")
        assert metrics.depth_error(depth, scene.depth, inner) < 2.0
        mesh = trimesh.load(out / "m.ply", force="mesh")
        assert len(mesh.vertices) == np.isfinite(depth).sum()

    def test_a_photo_brighter_than_said_is_named_and_rescaled(self, photo_set, inputs, out):
        scene = photo_set["scene"]
        lights = np.loadtxt(photo_set["lights"])
        photos = []
        for i, path in enumerate(photo_set["photos"]):
            photos.append(inputs / path.name)
            strength = 1.3 if i == 3 else 1.0  # its lamp was brighter than the others
            image = synth.render(scene.normals, scene.mask, light=lights[i], albedo=0.6 * strength)
            save_gray(image, photos[-1], bitdepth=16)
        result = invoke("stereo", *photos, "--lights", photo_set["lights"], "-o", out / "m.glb")
        assert result.exit_code == 0, result.output
        said = [line for line in result.stdout.splitlines() if "rescaled" in line]
        assert len(said) == 1 and said[0].rstrip().endswith("003.png x1.30"), said

    def test_files_and_json(self, photo_set, out):
        result = invoke(
            "stereo",
            *photo_set["photos"],
            "--lights",
            photo_set["lights"],
            "-o",
            out / "m.glb",
            "--model",
            "least_squares",
            "--json",
        )
        assert result.exit_code == 0, result.output
        report = json.loads(result.stdout)
        assert report["command"] == "stereo" and report["info"]["photos"] == 6
        assert report["info"]["solver"] == "photometric stereo (least_squares)"
        assert report["info"]["model"] == "least_squares"
        assert sorted(p.name for p in out.iterdir()) == ["m.glb"]

    def test_the_old_option_method_still_names_the_model(self, photo_set, out):
        args = ("stereo", *photo_set["photos"], "--lights", photo_set["lights"], "--json")
        old = invoke(*args, "-o", out / "a.ply", "--method", "robust")
        new = invoke(*args, "-o", out / "b.ply", "--model", "robust")
        assert old.exit_code == new.exit_code == 0, old.output + new.output
        assert json.loads(old.stdout)["info"]["model"] == json.loads(new.stdout)["info"]["model"] == "robust"
        assert (out / "a.ply").read_bytes() == (out / "b.ply").read_bytes()

    def test_light_file_with_comments_and_commas(self, photo_set, inputs, out):
        rows = np.loadtxt(photo_set["lights"])
        path = inputs / "lights.csv"
        path.write_text(
            "# x, y, z toward each light\n\n"
            # a comment after the numbers too (MIT-Berkeley's light_intensities.txt has them)
            + "\n".join(", ".join(f"{v:.17g}" for v in row) + f"  # photo {i}" for i, row in enumerate(rows))
            + "\n"
        )
        result = invoke(
            "stereo", *photo_set["photos"], "--lights", path, "-o", out / "a.ply", "--normals", out / "a.png"
        )
        assert result.exit_code == 0, result.output
        plain = invoke("stereo", photo_set["folder"], "-o", out / "b.ply", "--normals", out / "b.png")
        assert plain.exit_code == 0, plain.output
        np.testing.assert_array_equal(load_normal_map(out / "a.png"), load_normal_map(out / "b.png"))

    def test_a_slant_error_in_the_light_file_is_refined_unless_kept(self, photo_set, inputs, out):
        from shadeform.photometric.lambertian import scaled_lights

        path = inputs / "short.txt"  # every light's tan(slant) 10 % short
        np.savetxt(path, scaled_lights(np.loadtxt(photo_set["lights"]), 1 / 1.1))
        refined = invoke("stereo", *photo_set["photos"], "--lights", path, "-o", out / "a.ply", "--json")
        assert refined.exit_code == 0, refined.output
        assert json.loads(refined.stdout)["info"]["light_scale"] == pytest.approx(1.1, rel=0.01)
        shown = invoke("stereo", *photo_set["photos"], "--lights", path, "-o", out / "b.ply")
        assert "slant was refined" in shown.stdout
        kept = invoke(
            "stereo", *photo_set["photos"], "--lights", path, "-o", out / "c.ply", "--keep-lights", "--json"
        )
        assert kept.exit_code == 0, kept.output
        assert json.loads(kept.stdout)["info"]["light_scale"] == 1.0

    def test_needs_lights(self, photo_set, out):
        assert_fails(invoke("stereo", *photo_set["photos"], "-o", out / "m.glb"), out, "--lights")

    @pytest.mark.parametrize(
        "option, value",
        [("--model", "magic"), ("--method", "magic"), ("--integrator", "magic"), ("--channel", "magic")],
    )
    def test_unknown_choice_before_any_work(self, photo_set, out, monkeypatch, option, value):
        from shadeform import photoset

        monkeypatch.setattr(photoset, "read_photo", lambda *a, **k: pytest.fail("photos read"))
        result = invoke("stereo", photo_set["folder"], "-o", out / "m.glb", option, value)
        assert_fails(result, out, "unknown", value)

    def test_too_few_photos(self, photo_set, out):
        result = invoke(
            "stereo", *photo_set["photos"][:2], "--lights", photo_set["lights"], "-o", out / "m.glb"
        )
        assert_fails(result, out, "at least 3 photos")
        # too few photos is said first, whatever else is missing
        assert_fails(
            invoke("stereo", *photo_set["photos"][:2], "-o", out / "m.glb"), out, "at least 3 photos"
        )

    def test_photos_and_a_folder_together_are_refused(self, photo_set, out):
        result = invoke("stereo", photo_set["photos"][0], photo_set["folder"], "-o", out / "m.glb")
        assert_fails(result, out, "the photos, or one folder holding them, not both")

    def test_no_lights_names_every_way_to_give_them(self, photo_set, out):
        message = assert_fails(invoke("stereo", *photo_set["photos"], "-o", out / "m.glb"), out, "lights")
        assert all(option in message for option in ("--lights", "--sphere", "--unknown-lights")), message

    @pytest.mark.parametrize(
        "text, fragment",
        [
            ("0 0 1\n0.5 0 0.8\n", "6 rows"),
            ("up\n" * 6, "numbers only"),
            ("1 0 1\n0 1 1\n1 1 2\n2 1 3\n1 2 3\n3 1 4\n", "one plane"),
        ],
    )
    def test_bad_light_file(self, photo_set, inputs, out, text, fragment):
        path = inputs / "lights.txt"
        path.write_text(text)
        result = invoke("stereo", *photo_set["photos"], "--lights", path, "-o", out / "m.glb")
        assert_fails(result, out, fragment)

    def test_photos_of_different_sizes(self, photo_set, inputs, out):
        odd = inputs / "odd.png"
        save_gray(np.ones((SIZE, SIZE + 3)) * 0.5, odd, bitdepth=8)
        result = invoke(
            "stereo", *photo_set["photos"][:5], odd, "--lights", photo_set["lights"], "-o", out / "m.glb"
        )
        assert_fails(result, out, "one still camera")


class TestEncoding:
    """8-bit photos are sRGB and are made linear by default (shading needs linear light); 16-bit
    ones are linear; --linear / --srgb say otherwise; what was decided is in the info."""

    @staticmethod
    def encoded(image):
        return np.where(image <= 0.0031308, 12.92 * image, 1.055 * image ** (1 / 2.4) - 0.055)

    def test_reconstruct(self, tmp_path, out):
        scene = synth.scene("sphere", size=64)
        path, mask = tmp_path / "photo.png", tmp_path / "mask.png"
        save_gray(self.encoded(scene.image), path, bitdepth=8)
        save_gray(scene.mask.astype(float), mask, bitdepth=8)
        errors, infos = {}, {}
        for flag in ((), ("--linear",), ("--srgb",)):
            normals = out / f"n{len(flag)}{''.join(flag)}.png"
            result = invoke(
                "reconstruct",
                path,
                "-o",
                out / "m.ply",
                "--normals",
                normals,
                "--mask",
                mask,
                "--json",
                *flag,
            )
            assert result.exit_code == 0, result.output
            infos[flag] = json.loads(result.stdout)["info"]["photo"]
            errors[flag] = metrics.angular_error(load_normal_map(normals), scene.normals, scene.mask)
        # measured: 1.4 degrees decoded (by default or --srgb), 13.1 read as linear (--linear)
        assert errors[()] == errors[("--srgb",)] < 2.0
        assert errors[("--linear",)] > 5 * errors[()]
        clipped = infos[()].pop("clipped")
        assert infos[()] == {
            "bits": 8,
            "encoding": "srgb",
            "encoding_from": "file",
            "channel": "gray",
            "channel_from": "auto",
        }
        assert list(clipped) == ["gray"] and 0 < clipped["gray"] < 0.01  # the sphere's brightest pixels
        assert (infos[("--linear",)]["encoding"], infos[("--linear",)]["encoding_from"]) == ("linear", "user")
        assert (infos[("--srgb",)]["encoding"], infos[("--srgb",)]["encoding_from"]) == ("srgb", "user")

    def test_16_bit_stays_linear_and_the_summary_says_so(self, sphere, out):
        result = invoke("reconstruct", sphere["image"], "-o", out / "m.ply")
        assert result.exit_code == 0, result.output
        assert "16-bit linear, channel gray" in result.stdout
        assert result.stderr == ""  # nothing decided that needs a note
        decoded = invoke("reconstruct", sphere["image"], "-o", out / "d.ply", "--srgb")
        assert "16-bit sRGB, made linear (as told)" in decoded.stdout

    def test_channel_of_a_colour_photo(self, tmp_path, out):
        scene = synth.scene("sphere", size=48)
        path = tmp_path / "red.png"
        linear = np.stack([np.clip(1.5 * scene.image, 0, 1), 0.7 * scene.image, 0.4 * scene.image], axis=2)
        Image.fromarray(np.rint(self.encoded(linear) * 255).astype(np.uint8)).save(path)
        result = invoke("reconstruct", path, "-o", out / "m.ply", "--json")
        assert result.exit_code == 0, result.output
        report = json.loads(result.stdout)
        photo = report["info"]["photo"]
        assert (photo["channel"], photo["channel_from"]) == ("g", "auto") and report["input"][
            "channel"
        ] == "g"
        assert photo["clipped"]["r"] > 0.25 and photo["clipped"]["g"] == 0.0
        # the one decision worth a note: a channel other than luma
        note = result.stderr.strip().splitlines()
        assert len(note) == 1 and note[0].startswith("note: ") and "solving on g" in note[0]
        summary = invoke("reconstruct", path, "-o", out / "s.ply")
        assert "8-bit sRGB, made linear, channel g (least clipped)" in summary.stdout
        told = invoke("reconstruct", path, "-o", out / "l.ply", "--channel", "luma", "--json")
        assert json.loads(told.stdout)["info"]["photo"]["channel_from"] == "user"
        assert told.stderr == ""

    def test_stereo(self, photo_set, tmp_path, out):
        folder = tmp_path / "srgb"
        folder.mkdir()
        for photo in photo_set["photos"]:
            linear = shadeform.load_image(photo)
            save_gray(self.encoded(linear), folder / photo.name, bitdepth=8)
        errors, infos = {}, {}
        scene = photo_set["scene"]
        inner = scene.mask & (scene.normals[..., 2] > 0.3)
        for flag in ((), ("--linear",), ("--srgb",)):
            normals = out / f"n{len(flag)}{''.join(flag)}.png"
            result = invoke(
                "stereo",
                *sorted(folder.iterdir()),
                "--lights",
                photo_set["lights"],
                "-o",
                out / "m.ply",
                "--normals",
                normals,
                "--json",
                *flag,
            )
            assert result.exit_code == 0, result.output
            infos[flag] = json.loads(result.stdout)["info"]["photo"]
            errors[flag] = metrics.angular_error(load_normal_map(normals), scene.normals, inner)
        assert errors[()] == errors[("--srgb",)] < 1.0 < errors[("--linear",)]
        assert infos[()] == {
            "bits": 8,
            "encoding": "srgb",
            "encoding_from": "file",
            "channel": "gray",
            "channel_from": "auto",
        }
        assert infos[("--linear",)]["encoding_from"] == "user"

    def test_a_calibrated_set_is_linear(self, photo_set, tmp_path, out):
        folder = tmp_path / "calibrated"
        folder.mkdir()
        for photo in photo_set["photos"]:
            save_gray(shadeform.load_image(photo), folder / photo.name, bitdepth=8)  # linear 8-bit
        (folder / "light_directions.txt").write_bytes(photo_set["lights"].read_bytes())
        np.savetxt(folder / "light_intensities.txt", np.ones(len(photo_set["photos"])))
        result = invoke("stereo", folder, "-o", out / "m.ply", "--normals", out / "n.png", "--json")
        assert result.exit_code == 0, result.output
        photo = json.loads(result.stdout)["info"]["photo"]
        assert (photo["encoding"], photo["encoding_from"]) == ("linear", "set")
        scene = photo_set["scene"]
        inner = scene.mask & (scene.normals[..., 2] > 0.3)
        assert metrics.angular_error(load_normal_map(out / "n.png"), scene.normals, inner) < 1.0
        # one photo of the set, on its own, is linear too
        single = invoke("reconstruct", folder / "000.png", "-o", out / "one.ply", "--json")
        assert json.loads(single.stdout)["info"]["photo"]["encoding_from"] == "set"
