"""RTI for the web and RTIBuilder's projects: a model written in Relight's web format (info.json
and JPEG planes, read back by ``helpers.rti.read_web``, written from OpenLIME's and Relight's
loaders), atomically as a folder; and an RTIBuilder project folder (``jpeg-exports/`` and
``assembly-files/*.lp``) read as a photo set."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from PIL import Image

from helpers.cli import refused
from helpers.rti import DOME, HELD_OUT, light_up, light_up_web, read_file, read_web, write_dome_set
from shadeform import photoset, synth
from shadeform.cli.sets import load_set
from shadeform.errors import InputError
from shadeform.rti import fit, relight, write_web

#: Coefficient planes and JPEGs of each model, as Relight's format counts them (three planes a
#: JPEG): HSH 3 x terms; PTM RGB 3 x 6; PTM LRGB the colour and the six luminance terms.
PLANES = {"hsh3": 27, "hsh2": 12, "ptm-rgb": 18, "ptm-lrgb": 9}

#: The JPEG error a plane may have, in levels of its 8 bits (RMS over the plane). A quality-95
#: JPEG quantises each 8x8 block's lowest frequencies in steps of 2-3 levels, so smooth areas
#: come back within about a level, while the object's outline on the black background, a step
#: across much of a plane's range, rings: measured 0.9-1.0 levels RMS on these 40-pixel planes
#: (RGB JPEGs; 2.2-2.9 were they YCbCr, whose colour channels are quantised coarser). Twice that.
JPEG_LEVELS = 2.0


def _colour_scene(size=40):
    """A colour Lambertian bumpy object under the dome's lights, (N, H, W, 3), its colour
    drifting across the frame."""
    scene = synth.scene("bumps", size=size)
    ramp = np.linspace(0.0, 1.0, size)
    colour = np.stack(np.broadcast_arrays(0.9 - 0.3 * ramp[None, :], 0.5 + 0.3 * ramp[:, None], 0.4), axis=-1)
    return np.stack(
        [synth.render(scene.normals, scene.mask, light=l, albedo=0.8)[..., None] * colour for l in DOME]
    )


@pytest.fixture(scope="module")
def photos():
    return _colour_scene()


@pytest.mark.parametrize("kind", tuple(PLANES))
def test_the_web_set_holds_the_files_and_fields_the_viewer_reads(photos, tmp_path, kind):
    model = fit(photos, DOME, kind=kind)
    folder = tmp_path / "web"
    size = write_web(folder, model, lights=DOME)
    jpegs = PLANES[kind] // 3
    names = ["info.json"] + [f"plane_{j}.jpg" for j in range(jpegs)]
    assert sorted(p.name for p in folder.iterdir()) == sorted(names)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["web"]  # no temporary left beside it
    assert size == sum((folder / name).stat().st_size for name in names)
    info = json.loads((folder / "info.json").read_text(encoding="utf-8"))
    assert (info["width"], info["height"], info["format"]) == (40, 40, "jpg")
    assert info["type"] == ("hsh" if kind.startswith("hsh") else "ptm")
    assert info["colorspace"] == ("lrgb" if kind == "ptm-lrgb" else "rgb")
    assert info["nplanes"] == PLANES[kind] and math.ceil(info["nplanes"] / 3) == jpegs
    material = info["materials"][0]
    assert len(material["scale"]) == len(material["bias"]) == PLANES[kind]
    assert all(s > 0 for s in material["scale"])
    assert np.allclose(np.reshape(info["lights"], (-1, 3)), DOME, atol=1e-6)
    for j in range(jpegs):
        with Image.open(folder / f"plane_{j}.jpg") as image:
            assert (image.format, image.mode, image.size) == ("JPEG", "RGB", (40, 40))
    if kind == "ptm-lrgb":  # the colour plane is not scaled
        assert material["scale"][:3] == [1, 1, 1] and material["bias"][:3] == [0, 0, 0]


@pytest.mark.parametrize("kind", tuple(PLANES))
def test_the_planes_read_back_relight_as_the_model_within_the_jpegs_error(photos, tmp_path, kind):
    model = fit(photos, DOME, kind=kind)
    write_web(tmp_path / "web", model, lights=DOME)
    read = read_web(tmp_path / "web")
    # each plane's bytes against the model's coefficients quantised over the plane's scale/bias
    material = read.info["materials"][0]
    scale, bias = np.array(material["scale"]), np.array(material["bias"])
    exact = _planes_of(model)
    ideal = (exact / scale[:, None, None] + bias[:, None, None]) * 255.0
    assert ideal.min() > -0.5 and ideal.max() < 255.5  # the range fits a byte
    levels = np.sqrt(np.mean((read.bytes - ideal) ** 2, axis=(1, 2)))
    assert levels.max() < JPEG_LEVELS, levels
    # lit by the viewer's formula: within 0.5 % of full scale of the model (measured 0.25 %: the
    # planes' level of error over the terms' ranges, weighted by the light's terms), under the
    # photos' lights and one it did not see; the background, 0 on a byte of its own, stays black
    background = ~photos.any(axis=(0, 3))
    for light in (*DOME, HELD_OUT):
        shown, wanted = light_up_web(read, light), relight(model, light)
        assert shown.shape == wanted.shape == (40, 40, 3)
        assert np.sqrt(np.mean((shown - wanted) ** 2)) < 0.005
        assert np.sqrt(np.mean(shown[background] ** 2)) < 1 / 255  # but where the outline rings


def _planes_of(model):
    """The model's coefficients as Relight's planes, written here from the format's description:
    PTM terms reordered to 1, x, y, x^2, xy, y^2 (a model holds x^2, y^2, xy, x, y, 1)."""
    values = model.coefficients.astype(np.float64)
    if model.kind.startswith("ptm"):
        a0, a1, a2, a3, a4, a5 = values
        values = np.stack([a5, a3, a4, a0, a2, a1])
    if model.kind == "ptm-lrgb":
        return np.concatenate([np.moveaxis(model.chroma, -1, 0), values])
    return np.moveaxis(values, -1, 1).reshape(-1, *model.shape)  # term j: its R, G, B


def test_a_web_set_replaces_an_earlier_one_and_refuses_a_folder_of_other_files(photos, tmp_path):
    folder = tmp_path / "web"
    write_web(folder, fit(photos, DOME, kind="hsh3"))
    write_web(folder, fit(photos, DOME, kind="ptm-lrgb"))  # 9 JPEGs replaced by 3
    assert sorted(p.name for p in folder.iterdir()) == [
        "info.json",
        "plane_0.jpg",
        "plane_1.jpg",
        "plane_2.jpg",
    ]
    assert json.loads((folder / "info.json").read_text())["colorspace"] == "lrgb"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["web"]
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    with pytest.raises(InputError, match="notes.txt"):
        write_web(mine, fit(photos, DOME, kind="hsh2"))
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]


@pytest.mark.parametrize("earlier", [False, True])
def test_a_write_stopped_midway_leaves_nothing_and_the_earlier_set_intact(
    photos, tmp_path, monkeypatch, earlier
):
    folder = tmp_path / "web"
    if earlier:
        write_web(folder, fit(photos, DOME, kind="hsh2"))
    before = {p.name: p.read_bytes() for p in folder.iterdir()} if earlier else None
    saved = Image.Image.save
    calls = []

    def interrupted(self, *args, **kwargs):  # Ctrl-C while the third plane is written
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return saved(self, *args, **kwargs)

    monkeypatch.setattr(Image.Image, "save", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_web(folder, fit(photos, DOME, kind="hsh3"))
    assert len(calls) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == (["web"] if earlier else [])
    if earlier:
        assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


# --- the command line -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def dome_set(tmp_path_factory):
    return write_dome_set(tmp_path_factory.mktemp("rtiweb") / "dome")


@pytest.mark.parametrize(
    ("format", "kind", "jpegs", "same"), [("web-hsh", "hsh", 9, "hsh3"), ("web-ptm-rgb", "ptm", 6, "ptm-rgb")]
)
def test_the_command_writes_a_web_set(dome_set, cli, tmp_path, format, kind, jpegs, same):
    output = tmp_path / "dome_web"
    result = cli("rti", dome_set, "-o", output, "--format", format)
    assert result.exit_code == 0, result.output
    line = result.stdout.strip()
    assert "\n" not in line and line.startswith(f"wrote {output}/") and "Relight web set" in line, line
    assert f"{jpegs + 1} files" in line and "17 photos" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dome_web"]
    read = read_web(output)
    assert read.info["type"] == kind and len(list(output.iterdir())) == jpegs + 1
    # shows the photos as the .rti/.ptm of the same set does: both quantise each term to 8 bits
    # (the .rti's black background lands within half a step of 0, not on it) and the JPEGs ring at
    # the sphere's outline; measured 1.0-1.3 % RMS on this 32-pixel sphere
    file = tmp_path / ("dome.rti" if kind == "hsh" else "dome.ptm")
    assert cli("rti", dome_set, "-o", file, "--format", same).exit_code == 0
    for light in (*DOME, HELD_OUT):
        assert np.sqrt(np.mean((light_up_web(read, light) - light_up(read_file(file), light)) ** 2)) < 0.02


def test_the_command_reports_a_web_set_in_json(dome_set, cli, tmp_path):
    result = cli("rti", dome_set, "-o", tmp_path / "web", "--format", "web-hsh2", "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["format"] == "web-hsh2"
    assert report["bytes"] == sum(p.stat().st_size for p in (tmp_path / "web").iterdir())


def test_web_mistakes_are_one_line_and_exit_2(dome_set, cli, tmp_path):
    refused(cli("rti", dome_set, "-o", tmp_path / "out.rti", "--format", "web-hsh3"), "folder", "out.rti")
    refused(cli("rti", dome_set, "-o", tmp_path / "out", "--format", "web"), "unknown --format", "web-hsh3")
    refused(cli("rti", dome_set, "-o", tmp_path / "out"), "no suffix", "--format web-hsh3")
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "photo.png").write_bytes(b"")
    refused(
        cli("rti", dome_set, "-o", tmp_path / "taken", "--format", "web-hsh3"), "photo.png", "new folder name"
    )
    (tmp_path / "file").write_text("")
    refused(cli("rti", dome_set, "-o", tmp_path / "file", "--format", "web-hsh3"), "is a file")
    refused(
        cli("rti", dome_set, "-o", tmp_path / "nowhere" / "web", "--format", "web-hsh3"), "does not exist"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "taken"]


# --- RTIBuilder's project layout ----------------------------------------------------------------


def _rtibuilder_project(root, photos_folder, *, drop=None):
    """``root`` laid out as RTIBuilder's: the set's photos (as 8-bit JPEGs, RTIBuilder's) in
    ``jpeg-exports/`` named IMG_0001.jpg... (one in upper case on disk), and the light file in
    ``assembly-files/`` naming them by absolute Windows paths (with a space), in another order than
    the files'; also the same JPEGs with light_directions.txt in ``root/plain``, the lights to the
    .lp's 6 decimals. ``drop``: a photo the .lp names that is not copied."""
    source = photoset.load_photo_set([photos_folder])
    exports, assembly, plain = root / "jpeg-exports", root / "assembly-files", root / "plain"
    for folder in (exports, assembly, plain):
        folder.mkdir(parents=True)
    names = [f"IMG_{i + 1:04d}.jpg" for i in range(len(source.paths))]
    for i, name in enumerate(names):
        pixels = np.clip(np.rint(source.images[i] * 255), 0, 255).astype(np.uint8)
        on_disk = name.upper() if i == 2 else name
        if name != drop:
            Image.fromarray(pixels).save(exports / on_disk, quality=95)
        Image.fromarray(pixels).save(plain / name, quality=95)
    order = list(range(len(names)))[::-1]
    lines = [str(len(names))] + [
        f"C:\\My RTI\\proj\\jpeg-exports\\{names[i]} {x:.6f} {y:.6f} {z:.6f}"
        for i, (x, y, z) in ((i, source.lights[i]) for i in order)
    ]
    (assembly / "proj.lp").write_text("\r\n".join(lines) + "\r\n")
    np.savetxt(plain / "light_directions.txt", np.round(source.lights, 6), fmt="%.6f")
    return names


def test_an_rtibuilder_project_loads_as_the_same_photos_with_light_directions(dome_set, tmp_path):
    project = tmp_path / "proj"
    names = _rtibuilder_project(project, dome_set)
    assert photoset.rtibuilder_project(project) == (
        project / "assembly-files" / "proj.lp",
        project / "jpeg-exports",
    )
    plain = photoset.load_photo_set([project / "plain"])
    for source in (project, project / "jpeg-exports"):  # the project, or its photo folder
        found = photoset.load_photo_set([source])
        assert [p.name.lower() for p in found.paths] == [n.lower() for n in names[::-1]]  # the .lp's order
        order = np.argsort([p.name.lower() for p in found.paths])
        assert np.array_equal(found.images[order], plain.images)
        assert np.allclose(found.lights[order], plain.lights / np.linalg.norm(plain.lights, axis=1)[:, None])
        for kind in ("hsh3", "ptm-lrgb"):
            ours, theirs = (
                fit(found.images, found.lights, kind=kind),
                fit(plain.images, plain.lights, kind=kind),
            )
            assert np.allclose(ours.coefficients, theirs.coefficients, atol=1e-5)
    # the set commands' loader (relief, maps, fuse views) finds the same lights
    assert np.allclose(
        load_set(project, mask=None, linear=None, channel=None, max_pixels=10**8).lights, found.lights
    )


def test_the_command_reads_an_rtibuilder_project(dome_set, cli, tmp_path):
    project = tmp_path / "proj"
    _rtibuilder_project(project, dome_set)
    ours = cli("rti", project, "-o", tmp_path / "proj.rti")
    theirs = cli("rti", project / "plain", "-o", tmp_path / "plain.rti")
    assert ours.exit_code == 0 and theirs.exit_code == 0, ours.output + theirs.output
    assert "17 photos" in ours.stdout
    # the same model (the lights normalised in another order: a byte may differ by one)
    from_project, from_plain = read_file(tmp_path / "proj.rti"), read_file(tmp_path / "plain.rti")
    for light in (*DOME, HELD_OUT):
        assert np.abs(light_up(from_project, light) - light_up(from_plain, light)).max() < 2 / 255


def test_an_lp_naming_a_missing_photo_is_refused_in_one_line(dome_set, cli, tmp_path):
    project = tmp_path / "proj"
    _rtibuilder_project(project, dome_set, drop="IMG_0005.jpg")
    with pytest.raises(InputError, match=r"names 1 photo that .*jpeg-exports.* \(IMG_0005\.jpg\)"):
        photoset.load_photo_set([project])
    refused(cli("rti", project, "-o", tmp_path / "out.rti"), "IMG_0005.jpg", "jpeg-exports", "proj.lp")
    refused(cli("stereo", project, "-o", tmp_path / "out.ply"), "IMG_0005.jpg", "jpeg-exports")
    (project / "assembly-files" / "other.lp").write_text("0\n")
    refused(cli("rti", project, "-o", tmp_path / "out.rti"), "2 .lp files", "other.lp", "proj.lp")
    assert not list(tmp_path.glob("out*")) and not list(tmp_path.glob(".out*"))


def test_lp_names_may_hold_spaces_but_not_a_fourth_number(tmp_path):
    names, directions = photoset.parse_lp("1\nC:\\My RTI\\a b.jpg 0 0 1\n", "x.lp")
    assert names == ["a b.jpg"] and np.allclose(directions, [[0, 0, 1]])
    with pytest.raises(InputError, match="not 'name x y z'"):
        photoset.parse_lp("1\na.jpg 0 0 1 0.5\n", "x.lp")
