"""``shadeform maps``: the files, their bit depths and conventions, and its errors."""

from __future__ import annotations

import numpy as np
import png
import pytest

import shadeform
from shadeform import synth
from shadeform.cli.maps import LEGEND
from shadeform.io.maps import load_normal_map, save_gray
from shadeform.metrics import angular_error


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    path = tmp_path_factory.mktemp("photo") / "sphere.png"
    save_gray(synth.scene("sphere", size=80).image, path)
    return path


def read_png(path):
    width, height, rows, info = png.Reader(filename=str(path)).read()
    planes = info["planes"]
    return np.array([np.array(row) for row in rows]).reshape(height, width, planes), info["bitdepth"]


def test_every_map_is_written_with_its_legend(photo, tmp_path, cli):
    out = tmp_path / "maps"
    result = cli("maps", photo, "--out", out)
    assert result.exit_code == 0, result.output
    rec = shadeform.reconstruct(shadeform.load_image(photo))
    for name, (bits, _) in LEGEND.items():
        path = out / f"sphere_{name}.png"
        assert path.name in result.output
        pixels, depth = read_png(path)
        assert depth == bits and pixels.shape[:2] == (80, 80)
    # the OpenGL map reads back as the reconstruction's normals; DirectX has green flipped
    normals = load_normal_map(out / "sphere_normal_opengl.png", mask=rec.mask)
    # by the angle's atan2 form: arccos of a float32 dot product near 1 is only good to ~0.02 degrees
    assert np.nanmax(angular_error(normals, rec.normals, rec.mask, reduce="none")) < 0.01
    gl, _ = read_png(out / "sphere_normal_opengl.png")
    dx, _ = read_png(out / "sphere_normal_directx.png")
    assert np.abs(gl[..., 1].astype(int) + dx[..., 1] - 65535).max() <= 1
    np.testing.assert_array_equal(gl[..., [0, 2]], dx[..., [0, 2]])
    assert sorted(p.name for p in out.iterdir()) == sorted(f"sphere_{name}.png" for name in LEGEND)


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (("--reach", "0.5"), "--reach"),
        (("--light", "1,2"), "light"),
        (("--maps", "height,albedo"), "albedo map is made by --material"),
    ],
)
def test_bad_options_are_one_line_and_nothing_is_written(photo, tmp_path, cli, args, fragment):
    out = tmp_path / "maps"
    result = cli("maps", photo, "--out", out, *args)
    assert result.exit_code == 2
    assert fragment in result.output and "Traceback" not in result.output
    assert not out.exists() or list(out.iterdir()) == []


def test_material_mode_writes_an_albedo_too_and_says_where_the_light_was_read(tmp_path, cli):
    from shadeform.light import light_from_slant_tilt

    _, normals = synth.material_surface(96, seed=2)
    photo = tmp_path / "stone.png"
    save_gray(
        synth.render(normals, np.ones((96, 96), dtype=bool), light=light_from_slant_tilt(45, 120)), photo
    )
    out = tmp_path / "maps"
    result = cli("maps", photo, "--out", out, "--material", "--tile")
    assert result.exit_code == 0, result.output
    assert "read from the photo" in result.output and "--tilt" in result.output
    assert sorted(p.name for p in out.iterdir()) == sorted(
        f"stone_{name}.png" for name in [*LEGEND, "albedo"]
    )
    given = cli("maps", photo, "--out", tmp_path / "given", "--material", "--slant", "45", "--tilt", "120")
    assert given.exit_code == 0 and "read from the photo" not in given.output
    # the note's advice, as given, is a command line the tool takes
    (note,) = [line for line in result.stderr.splitlines() if "looks inverted" in line]
    assert note.startswith("note: ")
    advice = note.split("give ", 1)[1].split(" (", 1)[0].split()
    assert advice[0] == "--slant" and advice[2] == "--tilt"
    followed = cli("maps", photo, "--out", tmp_path / "followed", "--material", *advice)
    assert followed.exit_code == 0, followed.output


def test_tile_needs_material(photo, tmp_path, cli):
    result = cli("maps", photo, "--out", tmp_path / "maps", "--tile")
    assert result.exit_code == 2 and "--material" in result.output


def test_only_the_maps_asked_for(photo, tmp_path, cli):
    out = tmp_path / "maps"
    result = cli("maps", photo, "--out", out, "--maps", "height, normal_directx")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["sphere_height.png", "sphere_normal_directx.png"]
