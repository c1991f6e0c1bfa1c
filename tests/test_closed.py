"""A closed object from one photo (:func:`shadeform.fusion.close`): the photo is the front, the
back the front mirrored (a guess), fused as a photo and one from behind are.

The objects are synth's closed ones seen from the front, light at the camera, 96 px; the truth
is their exact depth from the front and from behind (``render_views`` at 0 and 180 degrees).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from PIL import Image

import shadeform
from shadeform import synth
from shadeform.errors import InputError
from shadeform.fusion import Closed, close
from shadeform.fusion.closed import in_millimetres, mirrored
from shadeform.reconstruction import Reconstruction

SIZE = 96


def _closed(name: str):
    """The object's front view, its true thickness along z, and the photo's closed model."""
    front, back = synth.render_views(name, (0, 180), size=SIZE)
    # the front's nearest point plus the back's (seen from behind, z is turned)
    thickness = float(np.nanmax(front.depth) + np.nanmax(back.depth))
    rec = shadeform.reconstruct(front.image, mask=front.mask, light=(0.0, 0.0, 1.0))
    return front, thickness, close(rec)


def _mask_extent(mask: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return np.array([np.ptp(cols) + 1, np.ptp(rows) + 1], float)


def test_a_symmetric_object_closes_to_its_true_thickness():
    """The ellipsoid is symmetric front to back, so its mirrored front is its true back: the
    closed model is watertight, keeps the outline (IoU 0.986 measured), its width and height
    within 2 % of the mask's and its thickness within 4 % of the truth (+1.4 % measured at 96 px,
    -1.8 % at 128: the photo's depth error, doubled)."""
    front, thickness, model = _closed("ellipsoid")
    assert isinstance(model, Closed) and model.watertight
    assert trimesh.Trimesh(model.vertices, model.faces).is_watertight
    assert model.outline_iou >= 0.95
    extent = np.ptp(model.vertices, axis=0)
    np.testing.assert_allclose(extent[:2], _mask_extent(front.mask), rtol=0.02)
    assert abs(extent[2] / thickness - 1) <= 0.04
    assert "guess" in model.back and model.back.startswith("mirror")


def test_an_asymmetric_object_gets_a_guessed_back():
    """The lumpy sphere is not symmetric front to back (its harmonics in ``u_x u_z``): the
    mirrored back is a guess, and its thickness is off by the asymmetry (+2 % measured at 96 px,
    +4 % at 128; the exact front mirrored gives the same, so it is the guess, not the photo).
    The outline is still kept (IoU 0.984 measured)."""
    front, thickness, model = _closed("lumpy")
    assert model.watertight and model.outline_iou >= 0.95
    extent = np.ptp(model.vertices, axis=0)
    np.testing.assert_allclose(extent[:2], _mask_extent(front.mask), rtol=0.03)
    assert abs(extent[2] / thickness - 1) <= 0.10


def test_the_mirror_turns_the_front_about_the_vertical_axis():
    (front,) = synth.render_views("pebble", (0,), size=32)
    rec = Reconstruction(front.normals, front.depth, front.mask, np.array([0.0, 0.0, 1.0]), 0.8)
    back = mirrored(rec)
    np.testing.assert_array_equal(back.mask, front.mask[:, ::-1])
    np.testing.assert_array_equal(back.depth, front.depth[:, ::-1])
    np.testing.assert_allclose(back.normals[..., 0], -front.normals[:, ::-1, 0])
    np.testing.assert_allclose(back.normals[..., 1:], front.normals[:, ::-1, 1:])


def test_in_millimetres_scales_the_outline_to_the_width():
    (front,) = synth.render_views("ellipsoid", (0,), size=48)
    rec = Reconstruction(front.normals, front.depth, front.mask, np.array([0.0, 0.0, 1.0]), 0.8)
    model = close(rec)
    printed = in_millimetres(model, width_mm=50.0)
    extent = np.ptp(printed.vertices, axis=0)
    assert printed.unit == "millimeter" and max(extent[:2]) == pytest.approx(50.0)
    np.testing.assert_allclose(
        extent * np.ptp(model.vertices[:, 0]), np.ptp(model.vertices, axis=0) * extent[0]
    )
    np.testing.assert_allclose(printed.vertices.min(axis=0), 0.0, atol=1e-9)
    scale = 50.0 / max(np.ptp(model.vertices[:, :2], axis=0))
    assert printed.volume == pytest.approx(model.volume * scale**3)
    with pytest.raises(InputError, match="back"):
        close(rec, back="inflate")


@pytest.fixture
def photo(tmp_path):
    """The ellipsoid's front as a 16-bit PNG (linear) and its mask."""
    (front,) = synth.render_views("ellipsoid", (0,), size=SIZE)
    path, mask = tmp_path / "front.png", tmp_path / "mask.png"
    Image.fromarray((front.image * 65535).round().astype(np.uint16)).save(path)
    Image.fromarray(front.mask.astype(np.uint8) * 255).save(mask)
    return path, mask


def test_cli_writes_a_closed_model_and_says_its_back_is_a_guess(cli, photo, tmp_path):
    path, mask = photo
    out = tmp_path / "model.stl"
    result = cli("reconstruct", path, "-o", out, "--closed", "--mask", mask, "--light", "0,0,1")
    assert result.exit_code == 0, result.output
    assert "guess" in result.output and "watertight" in result.output and "IoU" in result.output
    assert trimesh.load(out).is_watertight
    report = json.loads(cli("reconstruct", path, "-o", out, "--closed", "--mask", mask, "--json").output)
    assert report["closed"]["back_is_guess"] and report["closed"]["watertight"]
    assert report["closed"]["outline_iou"] >= 0.95


def test_cli_relief_closed_is_in_millimetres(cli, photo, tmp_path):
    path, mask = photo
    out = tmp_path / "print.stl"
    result = cli("relief", path, "-o", out, "--closed", "--width", "40", "--mask", mask, "--light", "0,0,1")
    assert result.exit_code == 0, result.output
    assert "guess" in result.output and "mm" in result.output
    printed = trimesh.load(out)
    assert printed.is_watertight and max(printed.extents[:2]) == pytest.approx(40.0, rel=1e-4)


@pytest.mark.parametrize(
    "args, flag",
    [
        (("reconstruct", "--tiles", "64"), "--tiles"),
        (("relief", "--height", "3"), "--height"),
    ],
)
def test_cli_refuses_what_a_closed_model_cannot_take_in_one_line(cli, photo, tmp_path, args, flag):
    path, _ = photo
    command, *rest = args
    result = cli(command, path, "-o", tmp_path / "x.stl", "--closed", *rest)
    assert result.exit_code == 2
    assert flag in result.output and len(result.output.strip().splitlines()) == 1
