"""A photo set where one photo goes (``shadeform.cli.sets``): ``relief``, ``maps`` and each view of
``fuse`` take a folder of photos under several lights and make their model from its photometric
stereo. Scored against the synthetic truth: the relief's size and closedness, the normal maps
against the stereo normals, the fused model against the true surface and its views' outlines."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from PIL import Image

from helpers.cli import refused
from helpers.fusion import scores
from helpers.photosets import SIX_LIGHTS, write_photo_set
from shadeform import photoset, synth
from shadeform.io.maps import load_normal_map
from shadeform.photometric import reconstruct_stereo

SIZE = 64


@pytest.fixture(scope="module")
def sphere_set(tmp_path_factory):
    """A sphere under six lights, as a folder (16-bit photos and light_directions.txt)."""
    folder = tmp_path_factory.mktemp("sets") / "sphere"
    scene = synth.scene("sphere", size=SIZE)
    write_photo_set(folder, scene.normals, scene.mask)
    return folder


def test_relief_of_a_photo_set_is_its_stereo_model_closed_and_sized(sphere_set, cli, tmp_path):
    solid = tmp_path / "sphere.stl"
    result = cli("relief", sphere_set, "-o", solid, "--width", "60", "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["info"]["solver"] == "photometric stereo (bivariate)"
    assert report["input"]["width"] == report["input"]["height"] == SIZE
    mesh = trimesh.load(solid)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    extent = mesh.bounds[1] - mesh.bounds[0]
    assert abs(max(extent[:2]) - 60) < 1e-3 and abs(extent[2] - 6) < 1e-3  # base 2 + relief 4
    # the closed object from the same set
    closed = cli("relief", sphere_set, "-o", tmp_path / "closed.stl", "--closed", "--json")
    assert closed.exit_code == 0, closed.output
    assert json.loads(closed.stdout)["closed"]["watertight"]


def test_maps_of_a_photo_set_are_its_stereo_normals_and_albedo(sphere_set, cli, tmp_path):
    result = cli("maps", sphere_set, "--out", tmp_path, "--json")
    assert result.exit_code == 0, result.output
    files = {name: entry["path"] for name, entry in json.loads(result.stdout)["maps"].items()}
    assert set(files) == {
        "normal_opengl",
        "normal_directx",
        "height",
        "ambient_occlusion",
        "curvature",
        "albedo",
    }
    photos = photoset.load_photo_set([sphere_set])
    truth = reconstruct_stereo(photos.images, photos.lights, photos.mask, intensities=photos.intensities)
    gl = load_normal_map(files["normal_opengl"])
    on = truth.mask
    angle = np.degrees(np.arccos(np.clip(np.sum(gl[on] * truth.normals[on], axis=1), -1, 1)))
    assert angle.max() < 0.5, angle.max()  # 16 bits a channel: far finer than half a degree
    dx = load_normal_map(files["normal_directx"])  # read as OpenGL: green (y) mirrored
    assert np.allclose(dx[on][:, 1], -gl[on][:, 1], atol=1e-4) and np.allclose(dx[on][:, ::2], gl[on][:, ::2])
    # one grey albedo everywhere (0.8 under every light): the map is white on the object
    albedo = np.asarray(Image.open(files["albedo"]), dtype=np.float64)
    assert albedo.ndim == 2 and np.median(albedo[on]) / albedo.max() > 0.97 and albedo[~on].max() == 0


def test_a_photo_sets_folder_with_an_lp_file(sphere_set, cli, tmp_path):
    folder = tmp_path / "rti"
    folder.mkdir()
    names = sorted(path.name for path in sphere_set.glob("*.png"))
    for name in names:
        (folder / name).write_bytes((sphere_set / name).read_bytes())
    photoset.write_lights(folder / "dome.lp", SIX_LIGHTS, names=names)
    result = cli("maps", folder, "--out", tmp_path / "maps", "--maps", "normal_opengl", "--json")
    assert result.exit_code == 0, result.output
    photoset.write_lights(folder / "other.lp", SIX_LIGHTS, names=names)
    refused(cli("maps", folder, "--out", tmp_path / "maps"), "2 .lp files")


def test_one_photo_options_and_a_set_without_lights_are_refused(sphere_set, cli, tmp_path):
    refused(cli("relief", sphere_set, "-o", tmp_path / "x.stl", "--light", "0,0,1", "--solver", "eikonal"),
           "--light, --solver are for one photo")  # fmt: skip
    refused(cli("maps", sphere_set, "--out", tmp_path, "--material"), "--material")
    bare = tmp_path / "bare"
    bare.mkdir()
    for path in sphere_set.glob("*.png"):
        (bare / path.name).write_bytes(path.read_bytes())
    refused(cli("relief", bare, "-o", tmp_path / "x.stl"), "no light_directions.txt and no .lp file")
    assert not list(tmp_path.glob("x*"))  # nothing written


@pytest.mark.parametrize("name", ["waisted"])
def test_fused_views_each_a_photo_set_keep_the_waist_and_the_outlines(name, cli, tmp_path):
    """The waisted object whose single photos read the waist as a hill (a quarter of the volume
    lost): four views, each under six lights, fused as the true surface (the bars of the
    shapes' true depths) and every view's outline kept."""
    angles = (0, 90, 180, 270)
    folders = []
    for view in synth.render_views(name, angles, size=128):
        folders.append(tmp_path / f"view{int(view.angle)}")
        write_photo_set(folders[-1], np.nan_to_num(view.normals), view.mask)
    model = tmp_path / "model.ply"
    result = cli("fuse", *folders, "--angles", "0,90,180,270", "-o", model, "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert min(report["outline_iou"]) >= 0.95, report["outline_iou"]
    chamfer, fscore, volume, closed = scores(trimesh.load(model), name, size=128)
    assert closed and chamfer <= 0.5 and fscore >= 95 and volume <= 3, (chamfer, fscore, volume)
    # a set tells convex from concave itself: regions drawn for it are refused
    views = {"views": [{"photo": str(f), "angle": a} for f, a in zip(folders, angles)]}
    views["views"][0]["concave"] = {"regions": [{"polygon": [[1, 1], [9, 1], [9, 9]], "axis": "x"}]}
    (tmp_path / "views.json").write_text(json.dumps(views))
    refused(cli("fuse", "--views", tmp_path / "views.json", "-o", tmp_path / "b.ply"), "photo set", "concave")


def test_fuse_reads_photos_as_told_linear_or_srgb(cli, tmp_path):
    """``fuse --linear/--srgb`` as every command reading photos: 8-bit files are sRGB unless told."""
    angles = (0, 180)
    photos = []
    for view in synth.render_views("ellipsoid", angles, size=48):
        photos.append(tmp_path / f"v{int(view.angle)}.png")
        Image.fromarray(np.rint(255 * np.asarray(view.image)).astype(np.uint8)).save(photos[-1])
    readings = {}
    for flag in ((), ("--linear",), ("--srgb",)):
        result = cli("fuse", *photos, "--angles", "0,180", "-o", tmp_path / "m.ply", "--json", *flag)
        assert result.exit_code == 0, result.output
        readings[flag] = [view["reading"]["encoding"] for view in json.loads(result.stdout)["views"]]
    assert readings == {(): ["srgb"] * 2, ("--linear",): ["linear"] * 2, ("--srgb",): ["srgb"] * 2}
