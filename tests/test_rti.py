"""RTI files for heritage users: PTM and HSH fitted to a photo set, written as RTIViewer reads
them, and read back by an independent reader (``helpers.rti``) written from the formats'
descriptions."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from helpers.cli import refused
from helpers.photosets import SIX_LIGHTS, write_photo_set
from helpers.rti import DOME, HELD_OUT, hsh_weights, light_up, read_file, read_hsh, read_ptm, write_dome_set
from shadeform import photoset, synth
from shadeform.errors import InputError
from shadeform.light import light_from_slant_tilt
from shadeform.rti import (
    FORMATS,
    RelightModel,
    display_values,
    encode,
    file_size,
    fit,
    hsh_basis,
    ptm_basis,
    relight,
    rms_error,
)

KINDS = tuple(FORMATS)


def _lambertian(name, lights, *, size=40):
    """A colour Lambertian scene under each light: (N, H, W, 3), its mask, and the photo under
    the held-out light. The colour drifts across the frame (each pixel has its own chroma)."""
    scene = synth.scene(name, size=size)
    ramp = np.linspace(0.0, 1.0, size)
    colour = np.stack(np.broadcast_arrays(0.9 - 0.3 * ramp[None, :], 0.5 + 0.3 * ramp[:, None], 0.4), axis=-1)

    def shot(light):
        return synth.render(scene.normals, scene.mask, light=light, albedo=0.8)[..., None] * colour

    return np.stack([shot(light) for light in lights]), scene.mask, shot(HELD_OUT)


@pytest.mark.parametrize("kind", KINDS)
def test_the_fit_reproduces_a_lambertian_set_and_a_photo_it_did_not_see(kind):
    photos, mask, held = _lambertian("bumps", DOME)
    model = fit(photos, DOME, kind=kind)
    assert model.kind == kind and model.shape == photos.shape[1:3]
    # within 2 % of full scale (the object reaches 0.72) on the photos and on an unseen light
    assert rms_error(model, photos, DOME, mask=mask) < 0.02
    assert np.sqrt(np.mean((relight(model, HELD_OUT) - held)[mask] ** 2)) < 0.02
    assert np.abs(relight(model, HELD_OUT)[~mask]).max() < 1e-5  # black stays black


@pytest.mark.parametrize("kind", ("ptm-rgb", "hsh2", "hsh3"))
def test_data_the_model_can_hold_are_fitted_exactly(kind):
    rng = np.random.default_rng(3)
    terms = FORMATS[kind]
    truth = rng.normal(size=(terms, 5, 7, 3)).astype(np.float32)
    design = ptm_basis(DOME) if kind.startswith("ptm") else hsh_basis(DOME, terms)
    photos = np.einsum("nt,thwc->nhwc", design, truth)
    model = fit(photos, DOME, kind=kind)
    assert np.allclose(model.coefficients, truth, atol=1e-4)


def test_the_hsh_basis_is_rtiviewers():
    for light in (*DOME, HELD_OUT, (0.3, -0.2, 0.1)):
        assert np.allclose(hsh_basis(np.array([light]), 9)[0], hsh_weights(light, 9), atol=1e-12)
        assert np.allclose(hsh_basis(np.array([light]), 4)[0], hsh_weights(light, 4), atol=1e-12)


def test_lrgb_keeps_each_pixels_colour_and_grey_sets_fit_too():
    photos, mask, _ = _lambertian("sphere", DOME)
    model = fit(photos, DOME, kind="ptm-lrgb")
    assert model.coefficients.shape == (6, *photos.shape[1:3]) and model.chroma.shape == photos.shape[1:]
    assert np.allclose(model.chroma[mask].max(axis=1), 1.0) and not model.chroma[~mask].any()
    grey = fit(photos[..., 1], DOME, kind="hsh3")
    assert grey.coefficients.shape == (9, *photos.shape[1:3], 3)
    assert np.array_equal(grey.coefficients[..., 0], grey.coefficients[..., 2])
    grey_lrgb = fit(photos[..., 1], DOME, kind="ptm-lrgb")
    assert np.array_equal(grey_lrgb.chroma[mask], np.ones((mask.sum(), 3), np.float32))


@pytest.mark.parametrize("kind", KINDS)
def test_a_file_read_back_by_the_independent_reader_relights_as_the_model(kind):
    photos, mask, held = _lambertian("vase", DOME, size=24)
    model = fit(photos, DOME, kind=kind)
    read = read_ptm(encode(model)) if kind.startswith("ptm") else read_hsh(encode(model))
    assert read.kind == kind and (read.height, read.width) == model.shape
    for light, photo in zip((*DOME, HELD_OUT), (*photos, held)):
        shown = light_up(read, light)
        # 8-bit coefficients: within a few levels of the unquantised model, a few % of the photo
        assert np.abs(shown - relight(model, light)).max() < 6 / 255
        assert np.sqrt(np.mean((shown - photo)[mask] ** 2)) < 0.03


def _corner_model(kind, height=3, width=4):
    """A model black everywhere but at the top-left pixel, whose constant term is 0.5 (red only
    in the per-channel kinds; LRGB with a pure-green chroma there)."""
    terms = FORMATS[kind]
    if kind == "ptm-lrgb":
        coefficients = np.zeros((terms, height, width), np.float32)
        coefficients[5, 0, 0] = 0.5
        chroma = np.zeros((height, width, 3), np.float32)
        chroma[0, 0, 1] = 1.0
        return RelightModel(kind, coefficients, chroma)
    coefficients = np.zeros((terms, height, width, 3), np.float32)
    coefficients[5 if kind == "ptm-rgb" else 0, 0, 0, 0] = 0.5
    return RelightModel(kind, coefficients)


@pytest.mark.parametrize("kind", KINDS)
def test_the_byte_layout(kind):
    height, width = 3, 4
    data = encode(_corner_model(kind, height, width))
    read = read_file_bytes(data)
    header = data[: read.data_offset].decode("ascii")
    assert len(data) == read.data_offset + file_size(kind, width, height)
    if kind.startswith("ptm"):
        name = "PTM_FORMAT_LRGB" if kind == "ptm-lrgb" else "PTM_FORMAT_RGB"
        lines = header.split("\n")
        assert lines[:4] == ["PTM_1.2", name, "4", "3"] and lines[6] == ""
        scale = [float(v) for v in lines[4].split(" ")]
        bias = [int(v) for v in lines[5].split(" ")]
        # the top-left pixel is the first of the last row (rows from the bottom), its 6th byte a5
        at = read.data_offset + (height - 1) * width * 6 + 5
        assert (data[at] - bias[5]) * scale[5] == pytest.approx(0.5 * 255, abs=scale[5])
        assert data[read.data_offset + 5] == bias[5]  # the bottom-left pixel's a5 is 0
        if kind == "ptm-lrgb":  # then the colours, rows from the bottom too
            colours = read.data_offset + width * height * 6 + (height - 1) * width * 3
            assert list(data[colours : colours + 3]) == [0, 255, 0]
    else:
        terms = FORMATS[kind]
        assert header == f"#HSH1.2\n3\n{width} {height} 3\n{terms} 2 1\n"
        scale = np.frombuffer(data, "<f4", terms, read.data_offset)
        bias = np.frombuffer(data, "<f4", terms, read.data_offset + 4 * terms)
        first = read.data_offset + 8 * terms  # the top-left pixel first: its red terms, green, blue
        assert data[first] / 255 * scale[0] + bias[0] == pytest.approx(0.5, abs=1e-6)
        assert data[first + terms] / 255 * scale[0] + bias[0] == pytest.approx(0.0, abs=1e-6)
    lit = light_up(read, (0.0, 0.0, 1.0))
    assert lit[0, 0].max() > 0.1 and np.abs(lit[1:]).max() < 2 / 255


def read_file_bytes(data: bytes):
    return read_ptm(data) if data.startswith(b"PTM_") else read_hsh(data)


def test_too_few_photos_or_lights_too_alike_are_refused():
    photos, _, _ = _lambertian("sphere", DOME, size=16)
    with pytest.raises(InputError, match="at least 6 photos"):
        fit(photos[:5], DOME[:5], kind="ptm-rgb")
    with pytest.raises(InputError, match="at least 9 photos"):
        fit(photos[:8], DOME[:8], kind="hsh3")
    ring = np.array([light_from_slant_tilt(40, t) for t in range(0, 360, 30)])  # one slant: lu^2 + lv^2 fixed
    with pytest.raises(InputError, match="too alike"):
        fit(photos[:12], ring, kind="ptm-lrgb")
    with pytest.raises(InputError, match="unknown RTI format"):
        fit(photos, DOME, kind="ptm")
    with pytest.raises(InputError, match="one light direction"):
        fit(photos, DOME[:4], kind="hsh2")
    photos[3, 2, 2] = np.nan
    with pytest.raises(InputError, match="NaN"):
        fit(photos, DOME, kind="hsh2")


# --- the command line -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def dome_set(tmp_path_factory):
    return write_dome_set(tmp_path_factory.mktemp("rti") / "dome")


@pytest.mark.parametrize(
    ("name", "options", "kind"),
    [
        ("out.ptm", (), "ptm-lrgb"),
        ("out.ptm", ("--format", "ptm-rgb"), "ptm-rgb"),
        ("out.rti", (), "hsh3"),
        ("out.RTI", ("--format", "hsh2"), "hsh2"),
    ],
)
def test_the_command_writes_each_format(dome_set, cli, tmp_path, name, options, kind):
    output = tmp_path / name
    result = cli("rti", dome_set, "-o", output, *options)
    assert result.exit_code == 0, result.output
    line = result.stdout.strip()
    assert "\n" not in line and line.startswith(f"wrote {output}") and "RMS" in line and "17 photos" in line
    read = read_file(output)
    assert read.kind == kind and (read.width, read.height) == (32, 32)
    # the file shows the photos as they look (display values), with the error the line reports
    photos = photoset.load_photo_set([dome_set])
    shown = display_values(photos.images, photos.intensities)
    error = np.sqrt(
        np.mean([np.mean((light_up(read, light) - photo) ** 2) for light, photo in zip(DOME, shown)])
    )
    reported = float(re.search(r"RMS ([0-9.]+)%", line).group(1)) / 100
    assert error < 0.05 and abs(error - reported) < 0.002, (error, reported)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # nothing else left behind


def test_the_command_reports_json(dome_set, cli, tmp_path):
    result = cli("rti", dome_set, "-o", tmp_path / "out.rti", "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["format"] == "hsh3" and report["bytes"] == (tmp_path / "out.rti").stat().st_size
    assert 0 < report["rms"] < 0.04 and report["input"]["photos"] == 17


def test_a_folder_with_an_lp_file(dome_set, cli, tmp_path):
    folder = tmp_path / "lp"
    folder.mkdir()
    names = sorted(path.name for path in dome_set.glob("*.png"))
    for name in reversed(names):  # the .lp names the photos; its order is not the folder's
        (folder / name).write_bytes((dome_set / name).read_bytes())
    photoset.write_lights(folder / "dome.lp", DOME[::-1], names=names[::-1])
    lp = cli("rti", folder, "-o", tmp_path / "lp.ptm", "--json")
    txt = cli("rti", dome_set, "-o", tmp_path / "txt.ptm", "--json")
    assert lp.exit_code == 0 and txt.exit_code == 0, lp.output + txt.output
    # the same model (the .lp holds the directions to 6 decimals: a byte may differ by one)
    from_lp, from_txt = read_file(tmp_path / "lp.ptm"), read_file(tmp_path / "txt.ptm")
    for light in (*DOME, HELD_OUT):
        assert np.abs(light_up(from_lp, light) - light_up(from_txt, light)).max() < 3 / 255


def test_user_mistakes_are_one_line_and_exit_2(dome_set, cli, tmp_path):
    refused(cli("rti", dome_set, "-o", tmp_path / "out.png"), "out.png", ".ptm, .rti")
    refused(cli("rti", dome_set, "-o", tmp_path / "out.ptm", "--format", "hsh3"), "hsh3", ".rti")
    refused(cli("rti", dome_set, "-o", tmp_path / "out.rti", "--format", "ptm"), "unknown --format")
    refused(cli("rti", dome_set / "000.png", "-o", tmp_path / "out.ptm"), "not a folder")
    one = tmp_path / "one"
    write_photo_set(one, *_sphere(), lights=SIX_LIGHTS[:1])
    refused(cli("rti", one, "-o", tmp_path / "out.ptm"), "at least 6 photos", "has 1")
    bad = tmp_path / "bad"
    write_photo_set(bad, *_sphere(), lights=DOME)
    (bad / "light_directions.txt").write_text("up and to the left\n" * len(DOME))
    refused(cli("rti", bad, "-o", tmp_path / "out.ptm"), "light_directions.txt", "numbers")
    (bad / "light_directions.txt").unlink()
    refused(cli("rti", bad, "-o", tmp_path / "out.ptm"), "no light_directions.txt")
    assert not list(tmp_path.glob("out.*")) and not list(tmp_path.glob(".out*"))


def _sphere():
    scene = synth.scene("sphere", size=16)
    return scene.normals, scene.mask


def test_display_values_even_out_the_lights_and_encode_srgb():
    photos = np.full((3, 2, 2, 3), 0.2, np.float32)
    photos[1] *= 2  # the second light was twice as strong, and said so
    for strengths in (np.array([1.0, 2.0, 1.0]), np.array([[1.0, 2.0, 1.0]] * 3).T):
        shown = display_values(photos, strengths)
        assert np.allclose(shown, shown[0, 0, 0, 0]) and shown[0, 0, 0, 0] == pytest.approx(0.4845, abs=1e-3)
    assert display_values(photos * 9, None).max() == pytest.approx(1.0, abs=1e-6)  # clipped before encoding
    with pytest.raises(InputError, match="finite positive"):
        display_values(photos, np.array([1.0, 0.0, 1.0]))
    # a grey set: its photos keep their shape, with one strength or one per channel
    for strengths in (np.array([1.0, 2.0, 1.0]), np.array([[1.0, 2.0, 1.0]] * 3).T):
        shown = display_values(photos[..., 0], strengths)
        assert shown.shape == (3, 2, 2) and np.allclose(shown, 0.4845, atol=1e-3)
