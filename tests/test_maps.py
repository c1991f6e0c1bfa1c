"""Tests for shadeform.io.maps: 16-bit normal maps and float depth maps, in and out."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import png
import pytest
import tifffile
from PIL import Image

from shadeform.errors import InputError
from shadeform.io.images import load_image
from shadeform.io.maps import load_depth, load_normal_map, save_depth, save_gray, save_normal_map

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
CAT = DATA / "diligent-normals" / "cat"


def sphere_normals(height=24, width=32):
    """Unit normals of a sphere cap filling part of the image, NaN elsewhere."""
    rows, cols = np.mgrid[:height, :width].astype(float)
    x = (cols - width / 2 + 0.25) / (0.45 * width)
    y = -(rows - height / 2 + 0.25) / (0.45 * width)
    z2 = 1 - x**2 - y**2
    normals = np.stack([x, y, np.sqrt(np.clip(z2, 0, None))], axis=-1)
    normals[z2 <= 0.01] = np.nan
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def read_png_raw(path):
    width, height, rows, info = png.Reader(filename=str(path)).read()
    return np.array([np.asarray(r) for r in rows]).reshape(height, width, -1), info


def angle_degrees(a, b):
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


class TestSaveNormalMap:
    def test_smoke(self, tmp_path):
        out = save_normal_map(sphere_normals(), tmp_path / "n.png")
        assert out == tmp_path / "n.png" and out.is_file()

    def test_shapes_and_format(self, tmp_path):
        save_normal_map(sphere_normals(24, 32), tmp_path / "n.png")
        pixels, info = read_png_raw(tmp_path / "n.png")
        assert pixels.shape == (24, 32, 3)
        assert info["bitdepth"] == 16 and not info["greyscale"] and not info["alpha"]

    def test_hand_computed_values(self, tmp_path):
        normals = np.array([[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [np.nan, np.nan, np.nan]]])
        save_normal_map(normals, tmp_path / "n.png")
        pixels, _ = read_png_raw(tmp_path / "n.png")
        # (n + 1) / 2 * 65535, rounded: 0 -> 32768 (32767.5 rounds to even), 1 -> 65535
        np.testing.assert_array_equal(
            pixels[0],
            [[32768, 32768, 65535], [65535, 32768, 32768], [32768, 0, 32768], [0, 0, 0]],
        )

    def test_independent_decoder_sees_the_same_picture(self, tmp_path):
        # Pillow reads 16-bit RGB PNGs as 8-bit: it must see our high bytes
        normals = sphere_normals()
        save_normal_map(normals, tmp_path / "n.png")
        pixels, _ = read_png_raw(tmp_path / "n.png")
        with Image.open(tmp_path / "n.png") as image:
            assert image.size == (32, 24)
            eight_bit = np.asarray(image.convert("RGB"))
        np.testing.assert_array_equal(eight_bit, pixels >> 8)

    def test_non_unit_normals_are_input_error(self, tmp_path):
        with pytest.raises(InputError, match="unit vectors"):
            save_normal_map(sphere_normals() * 2, tmp_path / "n.png")
        assert list(tmp_path.iterdir()) == []

    @pytest.mark.parametrize("shape", [(4, 4), (4, 4, 2), (0, 4, 3)])
    def test_bad_shape_is_input_error(self, tmp_path, shape):
        with pytest.raises(InputError, match="shape"):
            save_normal_map(np.ones(shape), tmp_path / "n.png")

    def test_wrong_suffix_is_input_error(self, tmp_path):
        with pytest.raises(InputError, match=r"\.png"):
            save_normal_map(sphere_normals(), tmp_path / "n.tif")
        assert list(tmp_path.iterdir()) == []

    def test_missing_folder_is_input_error(self, tmp_path):
        with pytest.raises(InputError, match="does not exist"):
            save_normal_map(sphere_normals(), tmp_path / "nope" / "n.png")


class TestLoadNormalMap:
    def test_smoke(self, tmp_path):
        save_normal_map(sphere_normals(), tmp_path / "n.png")
        assert load_normal_map(tmp_path / "n.png").shape == (24, 32, 3)

    def test_round_trip_within_a_hundredth_of_a_degree(self, tmp_path):
        normals = sphere_normals(48, 64)
        save_normal_map(normals, tmp_path / "n.png")
        loaded = load_normal_map(tmp_path / "n.png")
        assert loaded.dtype == np.float64
        present = ~np.isnan(normals[..., 0])
        np.testing.assert_array_equal(~np.isnan(loaded[..., 0]), present)
        assert angle_degrees(loaded[present], normals[present]).max() < 0.01
        np.testing.assert_allclose(np.linalg.norm(loaded[present], axis=-1), 1.0)

    def test_mask_sets_outside_to_nan(self, tmp_path):
        normals = sphere_normals()
        save_normal_map(normals, tmp_path / "n.png")
        mask = np.zeros(normals.shape[:2], dtype=bool)
        mask[8:16, 10:20] = True
        loaded = load_normal_map(tmp_path / "n.png", mask=mask)
        assert np.isnan(loaded[~mask]).all()
        assert np.isfinite(loaded[mask]).all()

    def test_mask_of_other_shape_is_input_error(self, tmp_path):
        save_normal_map(sphere_normals(), tmp_path / "n.png")
        with pytest.raises(InputError, match="must match"):
            load_normal_map(tmp_path / "n.png", mask=np.ones((3, 3), dtype=bool))

    def test_eight_bit_maps_are_read(self, tmp_path):
        # the usual 8-bit picture of a normal map: (0, 0, 1) is (128, 128, 255)
        rgb = np.array([[[128, 128, 255], [255, 128, 128], [0, 0, 0]]], dtype=np.uint8)
        Image.fromarray(rgb).save(tmp_path / "n8.png")
        loaded = load_normal_map(tmp_path / "n8.png")
        assert angle_degrees(loaded[0, 0], np.array([0.0, 0.0, 1.0])) < 0.5
        assert angle_degrees(loaded[0, 1], np.array([1.0, 0.0, 0.0])) < 0.5
        assert np.isnan(loaded[0, 2]).all()

    def test_grey_png_is_input_error(self, tmp_path):
        Image.fromarray(np.zeros((4, 4), dtype=np.uint8)).save(tmp_path / "grey.png")
        with pytest.raises(InputError, match="grey"):
            load_normal_map(tmp_path / "grey.png")

    def test_missing_or_broken_file_is_input_error(self, tmp_path):
        with pytest.raises(InputError, match="does not exist"):
            load_normal_map(tmp_path / "none.png")
        (tmp_path / "broken.png").write_bytes(b"not a png at all")
        with pytest.raises(InputError, match="not a readable PNG"):
            load_normal_map(tmp_path / "broken.png")

    @pytest.mark.skipif(not CAT.is_dir(), reason=f"real data folder {CAT} is absent")
    def test_diligent_cat(self):
        with Image.open(CAT / "mask.png") as image:
            mask = np.asarray(image) > 0
        normals = load_normal_map(CAT / "normal_map.png", mask=mask)
        assert normals.shape == mask.shape + (3,)
        inside = normals[mask]
        assert np.isfinite(inside).all()
        assert np.isnan(normals[~mask]).all()
        np.testing.assert_allclose(np.linalg.norm(inside, axis=-1), 1.0, atol=1e-12)
        assert (inside[:, 2] > 0).mean() > 0.95
        # a closed object seen from the front: normals point left and right, up and down
        assert inside[:, 0].min() < -0.5 < 0.5 < inside[:, 0].max()
        assert inside[:, 1].min() < -0.5 < 0.5 < inside[:, 1].max()


class TestSaveDepth:
    def test_smoke(self, tmp_path):
        assert save_depth(np.zeros((3, 4)), tmp_path / "d.tif") == tmp_path / "d.tif"

    def test_tiff_is_float32_for_an_independent_reader(self, tmp_path):
        depth = np.arange(12, dtype=float).reshape(3, 4) / 7
        save_depth(depth, tmp_path / "d.tiff")
        with Image.open(tmp_path / "d.tiff") as image:
            assert image.mode == "F" and image.size == (4, 3)
            np.testing.assert_array_equal(np.asarray(image), depth.astype(np.float32))

    @pytest.mark.parametrize("name", ["d.png", "d.exr", "d"])
    def test_unknown_suffix_is_input_error(self, tmp_path, name):
        with pytest.raises(InputError, match=r"\.tif, \.tiff or \.npy"):
            save_depth(np.zeros((3, 4)), tmp_path / name)
        assert list(tmp_path.iterdir()) == []

    def test_bad_shape_is_input_error(self, tmp_path):
        with pytest.raises(InputError, match=r"\(H, W\)"):
            save_depth(np.zeros((3, 4, 1)), tmp_path / "d.npy")

    def test_existing_file_survives_a_failed_write(self, tmp_path, monkeypatch):
        target = tmp_path / "d.tif"
        target.write_bytes(b"previous")

        def write_half_then_fail(file_obj, data, **kwargs):
            file_obj.write(b"II*\x00 half a tiff")
            raise OSError("disk full")

        monkeypatch.setattr(tifffile, "imwrite", write_half_then_fail)
        with pytest.raises(OSError, match="disk full"):
            save_depth(np.zeros((3, 4)), target)
        assert target.read_bytes() == b"previous"
        assert sorted(p.name for p in tmp_path.iterdir()) == ["d.tif"]


class TestLoadDepth:
    def test_smoke(self, tmp_path):
        save_depth(np.ones((2, 2)), tmp_path / "d.npy")
        assert load_depth(tmp_path / "d.npy").shape == (2, 2)

    def test_round_trip_npy_is_exact(self, tmp_path):
        depth = np.random.default_rng(0).normal(size=(5, 6)) * 100
        depth[0, 0] = np.nan
        save_depth(depth, tmp_path / "d.npy")
        loaded = load_depth(tmp_path / "d.npy")
        assert loaded.dtype == np.float64
        np.testing.assert_array_equal(loaded, depth)

    @pytest.mark.parametrize("suffix", [".tif", ".TIFF"])
    def test_round_trip_tiff_is_float32(self, tmp_path, suffix):
        depth = np.random.default_rng(1).normal(size=(5, 6)) * 100
        depth[2, 3] = np.nan
        save_depth(depth, tmp_path / f"d{suffix}")
        loaded = load_depth(tmp_path / f"d{suffix}")
        assert loaded.dtype == np.float64 and loaded.shape == (5, 6)
        np.testing.assert_array_equal(loaded, depth.astype(np.float32).astype(np.float64))

    def test_errors_are_input_errors(self, tmp_path):
        with pytest.raises(InputError, match="does not exist"):
            load_depth(tmp_path / "none.tif")
        with pytest.raises(InputError, match="use a name ending"):
            load_depth(tmp_path / "d.png")
        (tmp_path / "junk.tif").write_bytes(b"junk")
        with pytest.raises(InputError, match="not a readable depth map"):
            load_depth(tmp_path / "junk.tif")
        np.save(tmp_path / "cube.npy", np.zeros((2, 2, 2)))
        with pytest.raises(InputError, match=r"shape \(2, 2, 2\)"):
            load_depth(tmp_path / "cube.npy")


class TestSaveGray:
    @pytest.mark.parametrize("bitdepth", [8, 16])
    def test_round_trip_through_an_independent_reader(self, tmp_path, bitdepth):
        ramp = np.linspace(0.0, 1.0, 40 * 30).reshape(30, 40)
        path = save_gray(ramp, tmp_path / "ramp.png", bitdepth=bitdepth)
        stored = np.asarray(Image.open(path), dtype=np.float64) / (2**bitdepth - 1)
        np.testing.assert_allclose(stored, ramp, atol=0.5 / (2**bitdepth - 1) + 1e-12)
        np.testing.assert_allclose(load_image(path, linear=True), ramp, atol=0.5 / (2**bitdepth - 1) + 1e-6)

    def test_clips_and_takes_a_mask(self, tmp_path):
        values = np.array([[-1.0, 0.5], [2.0, 1.0]])
        stored = np.asarray(Image.open(save_gray(values, tmp_path / "c.png", bitdepth=8)))
        np.testing.assert_array_equal(stored, [[0, 128], [255, 255]])
        mask = np.array([[True, False], [False, True]])
        stored = np.asarray(Image.open(save_gray(mask, tmp_path / "m.png", bitdepth=8)))
        np.testing.assert_array_equal(stored, [[255, 0], [0, 255]])

    def test_colour_round_trip(self, tmp_path):
        import png

        colour = np.random.default_rng(1).random((5, 7, 3))
        width, height, rows, info = png.Reader(filename=str(save_gray(colour, tmp_path / "c.png"))).read()
        assert (width, height, info["planes"], info["bitdepth"]) == (7, 5, 3, 16)
        stored = np.array([list(row) for row in rows], dtype=np.float64).reshape(5, 7, 3) / 65535
        np.testing.assert_allclose(stored, colour, atol=0.5 / 65535)

    @pytest.mark.parametrize(
        ("image", "name", "bitdepth", "message"),
        [
            (np.zeros((4, 4)), "x.jpg", 8, ".png"),
            (np.zeros((4, 4)), "x.png", 12, "bitdepth must be 8 or 16"),
            (np.zeros((4, 4, 2)), "x.png", 8, "must be (H, W) or (H, W, 3)"),
        ],
    )
    def test_bad_input_writes_nothing(self, tmp_path, image, name, bitdepth, message):
        with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
            save_gray(image, tmp_path / name, bitdepth=bitdepth)
        assert list(tmp_path.iterdir()) == []
