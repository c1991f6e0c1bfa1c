"""Tests for shadeform.io.images: every format and bit depth in, every kind of bad file refused."""

from __future__ import annotations

import importlib.util
import struct
import zlib
from pathlib import Path

import numpy as np
import png
import pytest
import tifffile
from PIL import Image, ImageFile, ImageOps

from helpers.pngs import GRAY8, GRAY16, RGB8, RGB16, RNG, png_with_ihdr, unit8, unit16, write_png16
from shadeform.errors import InputError
from shadeform.io.images import (
    CALIBRATED_SET_FILE,
    CHANNELS,
    CLIP_MARGIN,
    ImageTooLargeError,
    load_image,
    load_image_rgb,
    load_mask,
    load_pixels,
    read_photo,
    select_channel,
)
from shadeform.preprocess import srgb_to_linear

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def bmp_header(width, height):
    """A 54-byte 24-bit BMP header declaring width x height, with no pixel data behind it."""
    file_header = b"BM" + struct.pack("<IHHI", 54, 0, 0, 54)
    info_header = struct.pack("<IiiHHIIiiII", 40, width, height, 1, 24, 0, 0, 2835, 2835, 0, 0)
    return file_header + info_header


def luma(rgb):
    return rgb @ np.array([0.299, 0.587, 0.114], dtype=np.float32)


def srgb_encode(linear):
    """Linear values in [0, 1] -> sRGB-encoded (IEC 61966-2-1), written out here independently."""
    linear = np.clip(linear, 0.0, 1.0)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def png8(path, linear):
    """Save linear values (H, W) or (H, W, 3) as an 8-bit sRGB-encoded PNG, as a camera would."""
    Image.fromarray(np.rint(srgb_encode(linear) * 255).astype(np.uint8)).save(path)
    return path


class TestLoadImage:
    """Decoding: the values as the file stores them (``linear=True`` for 8-bit files, which are
    otherwise decoded from sRGB: TestEncoding)."""

    def test_smoke(self, tmp_path):
        path = tmp_path / "rgb.png"
        Image.fromarray(RGB8).save(path)
        image = load_image(path)
        assert image.shape == (12, 17)
        assert image.dtype == np.float32

    @pytest.mark.parametrize("channel", CHANNELS)
    def test_shapes(self, tmp_path, channel):
        path = tmp_path / "rgb.png"
        Image.fromarray(RGB8).save(path)
        image = load_image(str(path), channel=channel)
        assert image.shape == (12, 17) and image.dtype == np.float32
        assert image.flags.c_contiguous
        assert image.min() >= 0.0 and image.max() <= 1.0

    def test_channels_hand_computed(self, tmp_path):
        path = tmp_path / "rgb.png"
        Image.fromarray(RGB8).save(path)
        rgb = unit8(RGB8)
        np.testing.assert_array_equal(load_image(path, channel="r", linear=True), rgb[:, :, 0])
        np.testing.assert_array_equal(load_image(path, channel="g", linear=True), rgb[:, :, 1])
        np.testing.assert_array_equal(load_image(path, channel="b", linear=True), rgb[:, :, 2])
        np.testing.assert_array_equal(load_image(path, channel="max", linear=True), rgb.max(axis=2))
        np.testing.assert_allclose(load_image(path, channel="luma", linear=True), luma(rgb), atol=1e-6)

    def test_luma_of_one_pixel_by_hand(self, tmp_path):
        values = np.zeros((3, 3, 3), np.uint8)
        values[1, 1] = (255, 0, 0)
        values[0, 0] = (0, 255, 0)
        values[2, 2] = (0, 0, 255)
        path = tmp_path / "primaries.png"
        Image.fromarray(values).save(path)
        image = load_image(path, channel="luma", linear=True)
        assert image[1, 1] == pytest.approx(0.299, abs=1e-6)
        assert image[0, 0] == pytest.approx(0.587, abs=1e-6)
        assert image[2, 2] == pytest.approx(0.114, abs=1e-6)
        assert image[0, 1] == 0.0

    @pytest.mark.parametrize("channel", CHANNELS)
    def test_gray_image_every_channel_is_the_gray(self, tmp_path, channel):
        path = tmp_path / "gray.png"
        Image.fromarray(GRAY8).save(path)
        np.testing.assert_array_equal(load_image(path, channel=channel, linear=True), unit8(GRAY8))

    def test_palette_png_goes_through_its_palette(self, tmp_path):
        index = RNG.integers(0, 4, size=(6, 7), dtype=np.uint8)
        palette = np.array([[10, 20, 30], [200, 0, 0], [0, 255, 0], [5, 5, 250]], np.uint8)
        image = Image.fromarray(index, mode="P")
        image.putpalette(palette.ravel().tolist())
        path = tmp_path / "palette.png"
        image.save(path)
        assert Image.open(path).mode == "P"
        expected = unit8(palette[index])
        np.testing.assert_array_equal(load_image_rgb(path, linear=True), expected)
        np.testing.assert_array_equal(load_image(path, channel="r", linear=True), expected[:, :, 0])

    def test_gray_alpha_ignores_alpha(self, tmp_path):
        values = np.stack([GRAY8, 255 - GRAY8], axis=2)
        path = tmp_path / "la.png"
        Image.fromarray(values, mode="LA").save(path)
        np.testing.assert_array_equal(load_image(path, channel="g", linear=True), unit8(GRAY8))

    def test_rgba_ignores_alpha(self, tmp_path):
        alpha = np.zeros((12, 17, 1), np.uint8)  # fully transparent: the colour must survive
        path = tmp_path / "rgba.png"
        Image.fromarray(np.concatenate([RGB8, alpha], axis=2), mode="RGBA").save(path)
        np.testing.assert_array_equal(load_image_rgb(path, linear=True), unit8(RGB8))

    def test_one_bit(self, tmp_path):
        bits = RNG.random((9, 11)) > 0.5
        path = tmp_path / "bits.png"
        Image.fromarray(bits).save(path)
        assert Image.open(path).mode == "1"
        np.testing.assert_array_equal(load_image(path), bits.astype(np.float32))

    def test_bmp(self, tmp_path):
        path = tmp_path / "rgb.bmp"
        Image.fromarray(RGB8).save(path)
        np.testing.assert_array_equal(load_image_rgb(path, linear=True), unit8(RGB8))

    def test_jpeg(self, tmp_path):
        # A smooth picture survives JPEG with small errors.
        rows, cols = np.mgrid[0:32, 0:40]
        values = np.stack([rows * 6, cols * 5, 255 - rows * 4], axis=2).astype(np.uint8)
        path = tmp_path / "photo.jpg"
        Image.fromarray(values).save(path, quality=95)
        np.testing.assert_allclose(load_image_rgb(path, linear=True), unit8(values), atol=0.04)

    def test_name_does_not_matter(self, tmp_path):
        path = tmp_path / "really_a_png.jpg"
        Image.fromarray(GRAY8).save(path, format="PNG")
        np.testing.assert_array_equal(load_image(path, linear=True), unit8(GRAY8))

    def test_png16_gray_exact(self, tmp_path):
        path = write_png16(tmp_path / "gray16.png", GRAY16)
        image = load_image(path)
        np.testing.assert_array_equal(image, unit16(GRAY16))
        np.testing.assert_array_equal(np.round(image.astype(np.float64) * 65535), GRAY16)

    def test_png16_rgb_round_trip_keeps_16_bits(self, tmp_path):
        path = write_png16(tmp_path / "rgb16.png", RGB16)
        rgb = load_image_rgb(path)
        np.testing.assert_array_equal(rgb, unit16(RGB16))
        back = np.round(rgb.astype(np.float64) * 65535).astype(np.int64)
        np.testing.assert_array_equal(back, RGB16)
        # 8-bit data widened to 16 bits would be multiples of 257.
        assert np.any(back % 257 != 0)
        np.testing.assert_array_equal(load_image(path, channel="b"), unit16(RGB16[:, :, 2]))

    def test_png16_rgba_ignores_alpha(self, tmp_path):
        values = np.concatenate([RGB16, np.zeros((12, 17, 1), np.uint16)], axis=2)
        writer = png.Writer(17, 12, greyscale=False, alpha=True, bitdepth=16)
        path = tmp_path / "rgba16.png"
        with open(path, "wb") as fh:
            writer.write(fh, values.reshape(12, -1).tolist())
        np.testing.assert_array_equal(load_image_rgb(path), unit16(RGB16))

    def test_tiff16_gray_and_rgb_exact(self, tmp_path):
        tifffile.imwrite(tmp_path / "gray.tif", GRAY16)
        tifffile.imwrite(tmp_path / "rgb.tif", RGB16, photometric="rgb")
        np.testing.assert_array_equal(load_image(tmp_path / "gray.tif"), unit16(GRAY16))
        np.testing.assert_array_equal(load_image_rgb(tmp_path / "rgb.tif"), unit16(RGB16))

    def test_tiff_planar_and_deflate(self, tmp_path):
        planar = np.moveaxis(RGB16, 2, 0)
        tifffile.imwrite(tmp_path / "planar.tif", planar, photometric="rgb", planarconfig="separate")
        tifffile.imwrite(tmp_path / "zip.tif", RGB16, photometric="rgb", compression="zlib")
        np.testing.assert_array_equal(load_image_rgb(tmp_path / "planar.tif"), unit16(RGB16))
        np.testing.assert_array_equal(load_image_rgb(tmp_path / "zip.tif"), unit16(RGB16))

    def test_tiff_float_is_clipped(self, tmp_path):
        values = np.array([[-0.5, 0.25, 0.5], [0.75, 1.0, 1.5], [0.1, 0.2, 0.3]], np.float32)
        tifffile.imwrite(tmp_path / "float.tif", values)
        np.testing.assert_array_equal(load_image(tmp_path / "float.tif"), np.clip(values, 0, 1))

    def test_tiff_palette_and_miniswhite(self, tmp_path):
        index = RNG.integers(0, 256, size=(5, 6), dtype=np.uint8)
        colormap = RNG.integers(0, 65536, size=(3, 256), dtype=np.uint16)
        tifffile.imwrite(tmp_path / "pal.tif", index, photometric="palette", colormap=colormap)
        expected = unit16(colormap[:, index].transpose(1, 2, 0))
        np.testing.assert_array_equal(load_image_rgb(tmp_path / "pal.tif", linear=True), expected)
        tifffile.imwrite(tmp_path / "white.tif", GRAY8, photometric="miniswhite")
        np.testing.assert_allclose(
            load_image(tmp_path / "white.tif", linear=True), 1 - unit8(GRAY8), atol=1e-7
        )

    def test_tiff_orientation_tag(self, tmp_path):
        path = tmp_path / "rotated.tif"
        tifffile.imwrite(path, GRAY16, extratags=[(274, "H", 1, 6, True)])
        np.testing.assert_array_equal(load_image(path), np.rot90(unit16(GRAY16), -1))

    def test_tiff_lzw(self, tmp_path):
        # LZW needs 'imagecodecs' in tifffile: 8-bit goes through Pillow, 16-bit is refused.
        path8, path16 = tmp_path / "lzw8.tif", tmp_path / "lzw16.tif"
        Image.fromarray(RGB8).save(path8, compression="tiff_lzw")
        Image.fromarray(GRAY16).save(path16, compression="tiff_lzw")
        np.testing.assert_array_equal(load_image_rgb(path8, linear=True), unit8(RGB8))
        if importlib.util.find_spec("imagecodecs") is not None:
            np.testing.assert_array_equal(load_image(path16, linear=True), unit16(GRAY16))
        else:
            with pytest.raises(InputError, match="imagecodecs"):
                load_image(path16, linear=True)

    def test_exif_rotated_jpeg(self, tmp_path):
        # Stored 16 rows x 24 cols with a bright block at the top-left corner; orientation 6
        # means "rotate 90 degrees clockwise to display", so the block ends up top-right.
        stored = np.full((16, 24), 40, np.uint8)
        stored[:8, :8] = 230
        exif = Image.Exif()
        exif[0x0112] = 6
        path = tmp_path / "rotated.jpg"
        Image.fromarray(stored).save(path, exif=exif, quality=95)
        image = load_image(path, linear=True)
        assert image.shape == (24, 16)
        assert image[:8, -8:].mean() > 0.8 and image[:8, :8].mean() < 0.25
        assert image[-8:, -8:].mean() < 0.25
        raw = unit8(np.asarray(Image.open(path).convert("L")))
        np.testing.assert_array_equal(image, np.rot90(raw, -1))

    @pytest.mark.parametrize("orientation", range(1, 9))
    def test_every_exif_orientation_matches_pillow(self, tmp_path, orientation):
        exif = Image.Exif()
        exif[0x0112] = orientation
        path = tmp_path / f"o{orientation}.png"
        Image.fromarray(RGB8).save(path, exif=exif)
        expected = unit8(np.asarray(ImageOps.exif_transpose(Image.open(path)).convert("RGB")))
        np.testing.assert_array_equal(load_image_rgb(path, linear=True), expected)

    def test_real_16bit_png(self):
        path = DATA / "diligent-ball" / "001.png"
        if not path.is_file():
            pytest.skip(f"real data {path} not found")
        rgb = load_image_rgb(path)
        assert rgb.shape == (512, 612, 3) and rgb.dtype == np.float32
        values = np.round(rgb.astype(np.float64) * 65535).astype(np.int64)
        np.testing.assert_array_equal(rgb, unit16(values))
        # Genuine 16-bit data: many values are not 8-bit values widened by 257.
        assert np.mean(np.unique(values) % 257 != 0) > 0.5
        # Pillow, an independent decoder, reads the same file's high bytes.
        high = np.asarray(Image.open(path))
        assert high.dtype == np.uint8
        np.testing.assert_array_equal(values >> 8, high)
        np.testing.assert_allclose(load_image(path), luma(rgb), atol=1e-6)


class TestLoadImageErrors:
    def assert_one_line(self, err):
        message = str(err.value)
        assert "\n" not in message and len(message) > 20

    def test_damaged_16bit_image_data(self, tmp_path):
        """Chunks intact (CRCs match) but the compressed pixels are not: the decoder's error
        becomes a one-line InputError."""
        path = tmp_path / "bad16.png"
        with open(path, "wb") as fh:
            png.Writer(width=8, height=4, greyscale=True, bitdepth=16).write(
                fh, (np.arange(32).reshape(4, 8) * 1000).tolist()
            )
        data = bytearray(path.read_bytes())
        at = data.index(b"IDAT")
        (size,) = struct.unpack(">I", data[at - 4 : at])
        payload = bytes(data[at + 4 : at + 6]) + b"\xff\xff\xff\xff" + bytes(data[at + 10 : at + 4 + size])
        data[at + 4 : at + 4 + size] = payload
        data[at + 4 + size : at + 8 + size] = struct.pack(">I", zlib.crc32(b"IDAT" + payload))
        path.write_bytes(bytes(data))
        with pytest.raises(InputError, match="damaged PNG") as err:
            load_image(path)
        self.assert_one_line(err)

    def test_missing_file(self, tmp_path):
        with pytest.raises(InputError, match="file not found") as err:
            load_image(tmp_path / "nope.png")
        self.assert_one_line(err)

    def test_folder(self, tmp_path):
        with pytest.raises(InputError, match="not a file"):
            load_image(tmp_path)

    def test_empty_file(self, tmp_path):
        path = tmp_path / "empty.png"
        path.write_bytes(b"")
        with pytest.raises(InputError, match="0 bytes"):
            load_image(path)

    def test_text_file(self, tmp_path):
        path = tmp_path / "notes.txt"
        path.write_text("this is not a picture\n" * 20)
        with pytest.raises(InputError, match="not an image: .*notes.txt") as err:
            load_image(path)
        self.assert_one_line(err)

    @pytest.mark.parametrize("cut", [0.1, 0.5, 0.9, -12, -1])
    @pytest.mark.parametrize("bits", [8, 16])
    def test_truncated_png(self, tmp_path, cut, bits):
        full = tmp_path / "full.png"
        if bits == 8:
            Image.fromarray(RGB8).save(full)
        else:
            write_png16(full, RGB16)
        data = full.read_bytes()
        end = int(len(data) * cut) if cut > 0 else len(data) + cut  # -12: only IEND missing
        path = tmp_path / "short.png"
        path.write_bytes(data[:end])
        with pytest.raises(InputError, match="truncated or damaged") as err:
            load_image(path)
        self.assert_one_line(err)

    def test_png_with_bad_crc(self, tmp_path):
        path = tmp_path / "bad.png"
        Image.fromarray(RGB8).save(path)
        data = bytearray(path.read_bytes())
        data[data.index(b"IDAT") + 10] ^= 0xFF
        path.write_bytes(bytes(data))
        with pytest.raises(InputError, match="truncated or damaged"):
            load_image(path)

    @pytest.mark.parametrize("cut", [0.05, 0.3, 0.6, 0.95])
    def test_truncated_jpeg(self, tmp_path, cut):
        full = tmp_path / "full.jpg"
        Image.fromarray(np.repeat(np.repeat(RGB8, 4, axis=0), 4, axis=1)).save(full)
        data = full.read_bytes()
        path = tmp_path / "short.jpg"
        path.write_bytes(data[: int(len(data) * cut)])
        with pytest.raises(InputError) as err:
            load_image(path)
        assert "truncated or damaged" in str(err.value) or "not an image" in str(err.value)
        self.assert_one_line(err)

    def test_truncated_tiff(self, tmp_path):
        full = tmp_path / "full.tif"
        tifffile.imwrite(full, RGB16, photometric="rgb")
        data = full.read_bytes()
        path = tmp_path / "short.tif"
        path.write_bytes(data[: len(data) * 2 // 3])
        with pytest.raises(InputError, match="truncated or damaged TIFF"):
            load_image(path)

    @pytest.mark.parametrize("size", [(1, 1), (2, 2), (2, 40), (40, 1)])
    def test_too_small(self, tmp_path, size):
        path = tmp_path / "tiny.png"
        Image.fromarray(np.full(size, 128, np.uint8)).save(path)
        with pytest.raises(InputError, match="at least 3x3"):
            load_image(path)

    def test_three_by_three_is_enough(self, tmp_path):
        path = tmp_path / "three.png"
        Image.fromarray(np.full((3, 3), 128, np.uint8)).save(path)
        assert load_image(path).shape == (3, 3)

    def test_zero_pixels(self, tmp_path):
        path = tmp_path / "zero.png"
        path.write_bytes(png_with_ihdr(0, 0))
        with pytest.raises(InputError, match="0x0 pixels"):
            load_image(path)

    def test_decompression_bomb_png(self, tmp_path):
        path = tmp_path / "bomb.png"
        path.write_bytes(png_with_ihdr(100_000, 100_000))
        assert path.stat().st_size < 100
        with pytest.raises(InputError, match="100000x100000 = 10,000,000,000 pixels") as err:
            load_image(path)
        self.assert_one_line(err)

    def test_max_pixels(self, tmp_path):
        png_path, jpg_path = tmp_path / "a.png", tmp_path / "a.jpg"
        Image.fromarray(RGB8).save(png_path)
        Image.fromarray(RGB8).save(jpg_path)
        assert load_image(png_path, max_pixels=12 * 17).shape == (12, 17)
        for path in (png_path, jpg_path):
            with pytest.raises(InputError, match="max_pixels=203"):
                load_image(path, max_pixels=12 * 17 - 1)
        with pytest.raises(InputError, match="max_pixels must be"):
            load_image(png_path, max_pixels=0)

    # max_pixels is the one limit (Pillow's own, about 89 and 179 Mpx, is not used); past it, a
    # header whose file cannot hold the pixels it declares is still refused before decoding.
    @pytest.mark.parametrize("side", [10_000, 20_000])
    def test_bmp_header_bomb(self, tmp_path, side):
        path = tmp_path / "bomb.bmp"
        path.write_bytes(bmp_header(side, side))
        with pytest.raises(ImageTooLargeError, match=f"{side}x{side}"):
            load_image(path)
        with pytest.raises(InputError, match="truncated or damaged BMP: .* 54 bytes cannot hold them") as err:
            load_image(path, max_pixels=10**12)
        self.assert_one_line(err)

    @pytest.mark.parametrize("bad", [np.nan, np.inf])
    def test_nan_in_float_tiff(self, tmp_path, bad):
        values = np.full((4, 5), 0.5, np.float32)
        values[2, 3] = bad
        tifffile.imwrite(tmp_path / "nan.tif", values)
        with pytest.raises(InputError, match="NaN or infinite"):
            load_image(tmp_path / "nan.tif")

    def test_unknown_channel(self, tmp_path):
        path = tmp_path / "rgb.png"
        Image.fromarray(RGB8).save(path)
        with pytest.raises(InputError, match="'luma', 'r', 'g', 'b', 'max'") as err:
            load_image(path, channel="green")
        self.assert_one_line(err)

    def test_truncated_images_stay_refused(self):
        # Setting this True anywhere would let Pillow return half-decoded pictures.
        assert ImageFile.LOAD_TRUNCATED_IMAGES is False


class TestLoadImageRgb:
    def test_smoke(self, tmp_path):
        path = tmp_path / "rgb.png"
        Image.fromarray(RGB8).save(path)
        rgb = load_image_rgb(path, linear=True)
        assert rgb.shape == (12, 17, 3) and rgb.dtype == np.float32
        np.testing.assert_array_equal(rgb, unit8(RGB8))

    def test_gray_is_replicated(self, tmp_path):
        path = tmp_path / "gray.png"
        Image.fromarray(GRAY8).save(path)
        rgb = load_image_rgb(path, linear=True)
        assert rgb.shape == (12, 17, 3)
        for c in range(3):
            np.testing.assert_array_equal(rgb[:, :, c], unit8(GRAY8))

    def test_same_decoder_as_load_image(self, tmp_path):
        path = write_png16(tmp_path / "rgb16.png", RGB16)
        rgb = load_image_rgb(path)
        for c, name in enumerate("rgb"):
            np.testing.assert_array_equal(load_image(path, channel=name), rgb[:, :, c])

    def test_errors(self, tmp_path):
        with pytest.raises(InputError, match="file not found"):
            load_image_rgb(tmp_path / "nope.png")
        path = tmp_path / "bomb.png"
        path.write_bytes(png_with_ihdr(100_000, 100_000))
        with pytest.raises(InputError, match="image too large"):
            load_image_rgb(path)


class TestLoadMask:
    def test_smoke(self, tmp_path):
        values = np.zeros((10, 12), np.uint8)
        values[2:6, 3:9] = 255
        path = tmp_path / "mask.png"
        Image.fromarray(values).save(path)
        mask = load_mask(path, shape=(10, 12))
        assert mask.dtype == bool and mask.shape == (10, 12)
        np.testing.assert_array_equal(mask, values > 0)

    def test_label_values_and_colour(self, tmp_path):
        labels = np.zeros((8, 9), np.uint8)
        labels[1:4, 1:4] = 1  # a mask saved from a 0/1 array
        Image.fromarray(labels).save(tmp_path / "labels.png")
        np.testing.assert_array_equal(load_mask(tmp_path / "labels.png"), labels > 0)
        colour = np.zeros((8, 9, 3), np.uint8)
        colour[5, 6, 2] = 7  # non-zero in blue only
        Image.fromarray(colour).save(tmp_path / "colour.png")
        mask = load_mask(tmp_path / "colour.png", shape=(8, 9, 3))
        assert mask.sum() == 1 and mask[5, 6]

    def test_shape_mismatch(self, tmp_path):
        path = tmp_path / "mask.png"
        Image.fromarray(np.full((80, 100), 255, np.uint8)).save(path)
        with pytest.raises(InputError, match=r"mask .*mask\.png' is 100x80 but the image is 256x256") as err:
            load_mask(path, shape=(256, 256))
        assert "\n" not in str(err.value)

    def test_empty_mask(self, tmp_path):
        path = tmp_path / "black.png"
        Image.fromarray(np.zeros((5, 5), np.uint8)).save(path)
        with pytest.raises(InputError, match="empty mask"):
            load_mask(path)

    def test_bad_file(self, tmp_path):
        path = tmp_path / "mask.txt"
        path.write_text("0 1 1 0")
        with pytest.raises(InputError, match="not an image"):
            load_mask(path)


class TestEncoding:
    """8-bit files are sRGB and are made linear; 16-bit and float files are linear; a calibrated
    photo set's folder says linear; ``linear=`` overrides; the decision is recorded."""

    def test_8bit_is_decoded_from_srgb(self, tmp_path):
        path = tmp_path / "gray.png"
        Image.fromarray(GRAY8).save(path)
        photo = read_photo(path)
        assert (photo.bits, photo.encoding, photo.encoding_from) == (8, "srgb", "file")
        assert photo.image.dtype == np.float32 and photo.pixels.dtype == np.float32
        np.testing.assert_allclose(photo.image, srgb_to_linear(unit8(GRAY8)), rtol=1e-6, atol=1e-7)
        np.testing.assert_array_equal(load_image(path), photo.image)
        # 0 and 1 stay where they are: the ends of the curve
        assert srgb_to_linear(np.array([0.0, 1.0])).tolist() == [0.0, 1.0]

    def test_jpeg_and_colour(self, tmp_path):
        path = tmp_path / "photo.jpg"
        Image.fromarray(RGB8).save(path, quality=100)
        stored = load_image_rgb(path, linear=True)
        photo = read_photo(path, channel="r")
        assert photo.encoding == "srgb" and photo.pixels.shape == (12, 17, 3)
        np.testing.assert_allclose(photo.pixels, srgb_to_linear(stored), rtol=1e-6, atol=1e-7)
        np.testing.assert_array_equal(load_image_rgb(path), photo.pixels)

    def test_16bit_and_float_stay_linear(self, tmp_path):
        tifffile.imwrite(tmp_path / "rgb.tif", RGB16, photometric="rgb")
        values = np.linspace(0, 1, 30, dtype=np.float32).reshape(5, 6)
        tifffile.imwrite(tmp_path / "float.tif", values)
        cases = [
            (write_png16(tmp_path / "gray16.png", GRAY16), 16, unit16(GRAY16)[:, :, None]),
            (tmp_path / "rgb.tif", 16, unit16(RGB16)),
            (tmp_path / "float.tif", 32, values[:, :, None]),
        ]
        for path, bits, stored in cases:
            photo = read_photo(path)
            assert (photo.bits, photo.encoding, photo.encoding_from) == (bits, "linear", "file"), path
            np.testing.assert_array_equal(photo.pixels, stored)

    def test_overrides(self, tmp_path):
        path8 = tmp_path / "gray.png"
        Image.fromarray(GRAY8).save(path8)
        kept = read_photo(path8, linear=True)
        assert (kept.encoding, kept.encoding_from) == ("linear", "user")
        np.testing.assert_array_equal(kept.image, unit8(GRAY8))
        path16 = write_png16(tmp_path / "gray16.png", GRAY16)
        decoded = read_photo(path16, linear=False)
        assert (decoded.encoding, decoded.encoding_from) == ("srgb", "user")
        np.testing.assert_allclose(decoded.image, srgb_to_linear(unit16(GRAY16)), rtol=1e-6, atol=1e-7)
        np.testing.assert_array_equal(load_image(path16, linear=False), decoded.image)

    @pytest.mark.parametrize("bad", ["yes", 1, 0.0])
    def test_bad_linear(self, tmp_path, bad):
        path = tmp_path / "gray.png"
        Image.fromarray(GRAY8).save(path)
        with pytest.raises(InputError, match="linear must be True .* or None") as err:
            load_image(path, linear=bad)
        assert "\n" not in str(err.value)

    def test_a_calibrated_set_is_linear(self, tmp_path):
        path = tmp_path / "001.png"
        Image.fromarray(GRAY8).save(path)
        (tmp_path / CALIBRATED_SET_FILE).write_text("1\n")
        photo = read_photo(path)
        assert (photo.encoding, photo.encoding_from) == ("linear", "set")
        np.testing.assert_array_equal(photo.image, unit8(GRAY8))
        assert read_photo(path, linear=False).encoding == "srgb"  # the user still decides
        # the same file's bytes have no folder: decided by the bit depth
        assert read_photo(path.read_bytes()).encoding == "srgb"

    def test_pixels_and_channels_agree(self, tmp_path):
        path = png8(tmp_path / "rgb.png", unit8(RGB8))
        photo = read_photo(path, channel="luma")
        np.testing.assert_array_equal(load_pixels(path), photo.pixels)
        for channel in CHANNELS:
            np.testing.assert_array_equal(
                select_channel(load_pixels(path), channel), load_image(path, channel=channel)
            )

    def test_info_is_plain(self, tmp_path):
        import json

        path = png8(tmp_path / "rgb.png", unit8(RGB8) * 0.5)
        info = read_photo(path).info
        assert json.loads(json.dumps(info)) == info
        assert info == {
            "bits": 8,
            "encoding": "srgb",
            "encoding_from": "file",
            "channel": "luma",
            "channel_from": "auto",
            "clipped": {"r": 0.0, "g": 0.0, "b": 0.0, "any": 0.0},
        }

    def test_real_diligent_photos_are_linear(self):
        folder = DATA / "real" / "diligent"
        if not folder.is_dir():
            pytest.skip(f"real DiLiGenT photos not found at {folder}")
        objects = sorted(p for p in folder.iterdir() if p.is_dir())
        assert len(objects) == 7
        for obj in objects:
            photo = read_photo(obj / "001.png")
            # 8-bit PNGs without colour chunks, yet linear camera data: the set says so
            assert (photo.bits, photo.encoding, photo.encoding_from) == (8, "linear", "set"), obj.name
            np.testing.assert_array_equal(photo.pixels, load_image_rgb(obj / "001.png", linear=True))


class TestChannelChoice:
    """``channel=None`` / ``"auto"``: luma, unless one colour channel clips on clearly fewer pixels."""

    @staticmethod
    def sphere_photo(tmp_path, gains):
        from shadeform import synth

        scene = synth.scene("sphere", size=64)
        linear = np.stack([np.clip(gain * scene.image, 0, 1) for gain in gains], axis=2)
        return scene, png8(tmp_path / "colour.png", linear)

    def test_gray_photo(self, tmp_path):
        path = tmp_path / "gray.png"
        Image.fromarray(GRAY8).save(path)
        photo = read_photo(path)
        assert (photo.channel, photo.channel_from) == ("gray", "auto")
        assert photo.clipped == {"gray": np.count_nonzero(GRAY8 == 255) / GRAY8.size}
        assert read_photo(path, channel="r").channel == "gray"  # a gray photo has only gray

    def test_unclipped_colour_is_luma(self, tmp_path):
        _, path = self.sphere_photo(tmp_path, (0.9, 0.7, 0.4))
        photo = read_photo(path)
        assert (photo.channel, photo.channel_from, photo.clipped["any"]) == ("luma", "auto", 0.0)
        np.testing.assert_array_equal(photo.image, load_image(path, channel="luma"))

    def test_the_unclipped_channel_of_a_red_object(self, tmp_path):
        from shadeform import metrics, reconstruct

        scene, path = self.sphere_photo(tmp_path, (1.5, 0.7, 0.4))  # red saturates on the bright part
        photo = read_photo(path)
        assert photo.clipped["r"] > 0.25 and photo.clipped["g"] == photo.clipped["b"] == 0.0
        # green and blue are both unclipped: green, which weighs most in luma, wins the tie
        assert (photo.channel, photo.channel_from) == ("g", "auto")
        np.testing.assert_array_equal(load_image(path), load_image(path, channel="g"))
        np.testing.assert_array_equal(load_image(path, channel="auto"), photo.image)
        errors = {
            channel: metrics.angular_error(
                reconstruct(load_image(path, channel=channel), mask=scene.mask).normals,
                scene.normals,
                scene.mask,
            )
            for channel in ("g", "luma", "r")
        }
        # measured: 1.4 degrees on the chosen green, 7.0 on luma, 25.1 on the clipped red
        assert errors["g"] < 2.0 and errors["luma"] > 3 * errors["g"] and errors["r"] > 15

    def test_a_white_highlight_keeps_luma(self, tmp_path):
        # every channel clips at the same pixels: no channel is better than luma there
        _, path = self.sphere_photo(tmp_path, (1.3, 1.3, 1.3))
        photo = read_photo(path)
        assert photo.clipped["any"] > 0.1 and photo.channel == "luma"

    def test_a_few_clipped_pixels_keep_luma(self, tmp_path):
        values = np.full((40, 50, 3), 0.5)
        values[:2, :4, 0] = 1.0  # 8 of 2,000 pixels: 0.4 %, under the margin
        path = png8(tmp_path / "speck.png", values)
        photo = read_photo(path)
        assert photo.clipped["r"] == pytest.approx(0.004) and photo.clipped["r"] < CLIP_MARGIN
        assert photo.channel == "luma"
        values[:4, :4, 0] = 1.0  # 16 pixels: 0.8 %
        assert read_photo(png8(tmp_path / "patch.png", values)).channel == "g"

    def test_near_equals_go_to_green(self, tmp_path):
        # blue clips on 10 % of the photo, green on 0.2 %, red on none: red is least clipped, but
        # green is within the margin of it, and green goes first (as on DiLiGenT's reading)
        values = np.full((40, 50, 3), 0.5)
        values[:4, :, 2] = 1.0
        values[0, :4, 1] = 1.0
        photo = read_photo(png8(tmp_path / "bluish.png", values))
        assert photo.clipped["r"] == 0.0 < photo.clipped["g"] < CLIP_MARGIN < photo.clipped["b"]
        assert photo.channel == "g"
        values[0, :, 1] = 1.0  # green now clips on 2.5 %: red, clearly fewer
        assert read_photo(png8(tmp_path / "green.png", values)).channel == "r"

    def test_the_user_decides(self, tmp_path):
        _, path = self.sphere_photo(tmp_path, (1.5, 0.7, 0.4))
        photo = read_photo(path, channel="luma")
        assert (photo.channel, photo.channel_from) == ("luma", "user")

    def test_unknown_channel(self, tmp_path):
        path = tmp_path / "gray.png"
        Image.fromarray(GRAY8).save(path)
        with pytest.raises(InputError, match="unknown channel 'green'; choose one of 'auto', 'luma'"):
            read_photo(path, channel="green")
