"""Batch reconstruction with Dask: the same models as one at a time, failures stay alone."""

from __future__ import annotations

import builtins
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

import shadeform
from shadeform import synth
from shadeform.batch import reconstruct_files
from shadeform.errors import InputError
from shadeform.io.maps import load_depth, save_gray


@pytest.fixture(scope="module")
def photos(tmp_path_factory) -> list[Path]:
    folder = tmp_path_factory.mktemp("photos")
    paths = []
    for name in ("sphere", "ellipsoid", "vase"):
        path = folder / f"{name}.png"
        save_gray(synth.scene(name, size=48).image, path, bitdepth=16)
        paths.append(path)
    return paths


class TestReconstructFiles:
    @pytest.mark.parametrize("workers", [1, 2])
    def test_same_models_as_one_at_a_time(self, photos, out, workers):
        seen = []
        results = reconstruct_files(
            photos,
            out,
            suffix=".ply",
            step=2,
            depth=True,
            workers=workers,
            progress=lambda done, total: seen.append((done, total)),
            solver="eikonal",
        )
        assert [r.photo for r in results] == photos
        assert seen[-1] == (3, 3) and len(seen) == 3
        for photo, result in zip(photos, results):
            assert result.error is None
            assert [p.name for p in result.files] == [f"{photo.stem}.ply", f"{photo.stem}_depth.tiff"]
            rec = shadeform.reconstruct(shadeform.load_image(photo), solver="eikonal")
            mesh = shadeform.to_mesh(rec, step=2)
            assert (result.vertices, result.faces) == (mesh.n_vertices, mesh.n_faces)
            written = trimesh.load(out / f"{photo.stem}.ply", force="mesh")
            assert len(written.vertices) == mesh.n_vertices
            np.testing.assert_allclose(
                load_depth(out / f"{photo.stem}_depth.tiff"), rec.depth, atol=1e-4, equal_nan=True
            )  # float32 file

    def test_encoding(self, out, tmp_path):
        """Each photo is read as reconstruct reads it: 8-bit sRGB made linear, 16-bit linear,
        ``linear=`` overriding; the result says what was decided."""
        from shadeform.io.images import read_photo

        scene = synth.scene("sphere", size=48)
        encoded = np.where(
            scene.image <= 0.0031308, 12.92 * scene.image, 1.055 * scene.image ** (1 / 2.4) - 0.055
        )
        eight, deep = tmp_path / "eight.png", tmp_path / "deep.png"
        save_gray(encoded, eight, bitdepth=8)
        save_gray(encoded, deep, bitdepth=16)
        for linear, expected in ((None, ("srgb", "linear")), (False, ("srgb", "srgb"))):
            results = reconstruct_files(
                [eight, deep], out, suffix=".ply", depth=True, linear=linear, workers=1
            )
            assert [r.photo_info["encoding"] for r in results] == list(expected)
            assert results[0].photo_info["encoding_from"] == ("file" if linear is None else "user")
            for photo in (eight, deep):
                rec = shadeform.reconstruct(read_photo(photo, linear=linear).image)
                np.testing.assert_allclose(
                    load_depth(out / f"{photo.stem}_depth.tiff"), rec.depth, atol=1e-4, equal_nan=True
                )

    def test_a_bad_photo_fails_alone(self, photos, out, tmp_path):
        bad = tmp_path / "black.png"
        save_gray(np.zeros((20, 20)), bad, bitdepth=8)
        old = out / "black.glb"
        old.write_bytes(b"a good model from before")
        results = reconstruct_files([photos[0], bad], out, workers=1)
        assert results[0].error is None and results[0].files == (out / "sphere.glb",)
        assert results[1].files == () and "black" in results[1].error.lower()
        assert "\n" not in results[1].error
        assert old.read_bytes() == b"a good model from before"  # nothing clobbered
        assert sorted(p.name for p in out.iterdir()) == ["black.glb", "sphere.glb"]

    def test_errors(self, photos, out, tmp_path, monkeypatch):
        with pytest.raises(InputError, match="no photos"):
            reconstruct_files([], out)
        twin = tmp_path / "again"
        twin.mkdir()
        with pytest.raises(InputError, match="named 'sphere'"):
            reconstruct_files([photos[0], twin / "sphere.png"], out)
        with pytest.raises(InputError, match="does not exist"):
            reconstruct_files(photos, tmp_path / "missing")
        with pytest.raises(InputError, match="suffix"):
            reconstruct_files(photos, out, suffix=".xyz")
        with pytest.raises(InputError, match="workers"):
            reconstruct_files(photos, out, workers=0)
        for options, match in (
            ({"solver": "magic"}, "solver"),
            ({"integrator": "x"}, "integrator"),
            ({"filter": "blur:2"}, "filter"),
            ({"channel": "green"}, "channel"),
            ({"linear": "yes"}, "linear"),
        ):
            with pytest.raises(InputError, match=match):
                reconstruct_files([tmp_path / "never-read.png"], out, **options)
        real_import = builtins.__import__

        def no_dask(name, *args, **kwargs):
            if name == "dask" or name.startswith("dask."):
                raise ImportError(name)
            return real_import(name, *args, **kwargs)

        monkeypatch.setattr(builtins, "__import__", no_dask)
        with pytest.raises(InputError, match=r"shadeform\[dask\]"):
            reconstruct_files(photos, out)


class TestBatchCommand:
    def test_json_and_folder_created(self, photos, tmp_path, cli):
        folder = tmp_path / "models"
        result = cli(
            "batch", *photos, "--out", folder, "--format", "obj", "--normals", "--workers", "1", "--json"
        )
        assert result.exit_code == 0, result.output
        report = json.loads(result.stdout)
        assert [Path(p["photo"]).name for p in report["photos"]] == [p.name for p in photos]
        assert all(p["error"] is None for p in report["photos"])
        assert len(list(folder.iterdir())) == 6
        assert [p["photo_info"]["encoding"] for p in report["photos"]] == ["linear"] * 3  # 16-bit

    def test_srgb_flag_and_table(self, photos, tmp_path, cli):
        result = cli(
            "batch", photos[0], "--out", tmp_path / "m", "--workers", "1", "--srgb", "--channel", "g"
        )
        assert result.exit_code == 0, result.output
        assert "16-bit sRGB, made linear (as told), channel gray" in result.stdout

    def test_failures_exit_2_with_one_line_each(self, photos, tmp_path, cli):
        bad = tmp_path / "notes.png"
        bad.write_text("not a photo")
        result = cli("batch", photos[0], bad, "--out", tmp_path / "m", "--workers", "1")
        assert result.exit_code == 2
        assert "1 of 2 photos" in result.stdout
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and "notes.png" in lines[0]
        assert "Traceback" not in result.output

    @pytest.mark.parametrize(
        "option, value, fragment",
        [
            ("--format", "xyz", "format"),
            ("--solver", "magic", "solver"),
            ("--integrator", "magic", "integrator"),
            ("--filter", "blur:2", "filter"),
            ("--channel", "green", "channel"),
        ],
    )
    def test_bad_option_is_one_line(self, photos, tmp_path, option, value, fragment, cli):
        result = cli("batch", *photos, "--out", tmp_path / "m", option, value)
        assert result.exit_code == 2 and "Traceback" not in result.output
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and fragment in lines[0], result.stderr
        assert result.stdout == ""
        assert not (tmp_path / "m").exists()  # refused before the folder was made
