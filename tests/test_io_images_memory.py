"""Tests for reading images from memory (bytes) and picking channels later (the app's needs).

``load_image(bytes)`` must be ``load_image(path)`` for the same file, ``select_channel`` over
``load_pixels`` must be ``load_image`` with that channel, and too many pixels must raise the
:class:`ImageTooLargeError` subclass so a caller can tell it from a file that is not an image.
"""

from __future__ import annotations

import numpy as np
import pytest
import tifffile
from PIL import Image

from helpers.pngs import GRAY8, GRAY16, RGB8, RGB16, png_with_ihdr, unit8, write_png16
from shadeform.errors import InputError
from shadeform.io.images import (
    CHANNELS,
    ImageTooLargeError,
    load_image,
    load_image_rgb,
    load_pixels,
    select_channel,
)


def files(tmp_path):
    """One file per decoder path: 8-bit PNG (Pillow), 16-bit PNG (pypng), TIFF, JPEG, BMP."""
    made = {}
    made["rgb8.png"] = tmp_path / "rgb8.png"
    Image.fromarray(RGB8).save(made["rgb8.png"])
    made["gray8.png"] = tmp_path / "gray8.png"
    Image.fromarray(GRAY8).save(made["gray8.png"])
    made["rgb16.png"] = write_png16(tmp_path / "rgb16.png", RGB16)
    made["gray16.tif"] = tmp_path / "gray16.tif"
    tifffile.imwrite(made["gray16.tif"], GRAY16)
    made["rgb8.jpg"] = tmp_path / "rgb8.jpg"
    Image.fromarray(RGB8).save(made["rgb8.jpg"], quality=95)
    made["rgb8.bmp"] = tmp_path / "rgb8.bmp"
    Image.fromarray(RGB8).save(made["rgb8.bmp"])
    return made


class TestBytes:
    def test_same_as_path(self, tmp_path):
        for name, path in files(tmp_path).items():
            data = path.read_bytes()
            for channel in CHANNELS:
                np.testing.assert_array_equal(
                    load_image(data, channel=channel), load_image(path, channel=channel), err_msg=name
                )
            np.testing.assert_array_equal(load_image_rgb(bytearray(data)), load_image_rgb(path))
            np.testing.assert_array_equal(load_pixels(memoryview(data)), load_pixels(path))

    def test_values(self, tmp_path):
        data = files(tmp_path)["rgb8.png"].read_bytes()
        np.testing.assert_array_equal(load_image(data, channel="g", linear=True), unit8(RGB8[:, :, 1]))

    def test_empty(self):
        with pytest.raises(InputError, match="empty file: 'image data' has 0 bytes"):
            load_image(b"")

    def test_not_an_image(self):
        with pytest.raises(InputError, match="^not an image: 'image data'"):
            load_pixels(b"hello, this is text and not a picture")

    def test_truncated(self, tmp_path):
        data = files(tmp_path)["rgb16.png"].read_bytes()
        with pytest.raises(InputError, match="truncated or damaged PNG"):
            load_pixels(data[: len(data) // 2])


class TestTooLarge:
    def test_declared_size(self):
        with pytest.raises(ImageTooLargeError, match="image too large"):
            load_pixels(png_with_ihdr(5000, 5000), max_pixels=1_000_000)

    def test_is_input_error(self):
        assert issubclass(ImageTooLargeError, InputError)

    def test_other_errors_are_not(self):
        with pytest.raises(InputError) as caught:
            load_pixels(png_with_ihdr(2, 2))  # too small, not too large
        assert not isinstance(caught.value, ImageTooLargeError)


class TestLoadPixels:
    def test_shapes(self, tmp_path):
        made = files(tmp_path)
        assert load_pixels(made["rgb8.png"]).shape == RGB8.shape
        assert load_pixels(made["gray8.png"]).shape == GRAY8.shape + (1,)
        assert load_pixels(made["gray16.tif"]).dtype == np.float32


class TestSelectChannel:
    def test_same_as_load_image(self, tmp_path):
        for name, path in files(tmp_path).items():
            pixels = load_pixels(path)
            for channel in CHANNELS:
                np.testing.assert_array_equal(
                    select_channel(pixels, channel), load_image(path, channel=channel), err_msg=name
                )

    def test_gray_any_channel(self):
        gray = unit8(GRAY8)
        for channel in CHANNELS:
            np.testing.assert_array_equal(select_channel(gray[:, :, None], channel), gray)
            np.testing.assert_array_equal(select_channel(gray, channel), gray)

    def test_hand_values(self):
        pixels = np.array([[[1.0, 0.0, 0.0], [0.2, 0.6, 0.4]]], dtype=np.float32)
        np.testing.assert_allclose(
            select_channel(pixels, "luma"), [[0.299, 0.0598 + 0.3522 + 0.0456]], rtol=1e-6
        )
        np.testing.assert_array_equal(select_channel(pixels, "max"), np.float32([[1.0, 0.6]]))
        np.testing.assert_array_equal(select_channel(pixels, "b"), np.float32([[0.0, 0.4]]))

    def test_errors(self):
        with pytest.raises(InputError, match="unknown channel 'green'"):
            select_channel(np.zeros((4, 4, 3), np.float32), "green")
        with pytest.raises(InputError, match=r"shape \(H, W\), \(H, W, 1\) or \(H, W, 3\)"):
            select_channel(np.zeros((4, 4, 2), np.float32), "luma")
