"""The photo set's viewing modes in a real browser (web/src/relightModes.ts, relightPanel.ts):
each mode draws its own picture of the shipped vase set and its sliders change it, a second light
adds its light where both fall, the settings come back after a reload, and Save picture downloads
the pane as a PNG of the photos' size. The per-pixel formulas themselves are checked under Node
(tests/test_relight_modes.py); the pictures each mode draws are kept in ``tests/artifacts/``."""

from __future__ import annotations

import base64
import io

import numpy as np
from PIL import Image

from helpers import browser as ui
from helpers.browser import ARTIFACTS, RESULT_MS

server, browser, page = ui.server, ui.browser, ui.page

BACKGROUND = (24, 26, 31)  # what the pane shows off the object
SLIDERS = {
    "default": [],
    "diffuse-gain": ["relight-gain"],
    "specular-enhancement": ["relight-diffuse", "relight-specular", "relight-exponent"],
    "unsharp-masking": ["relight-radius", "relight-amount"],
}


def stereo(page, what: str):
    return page.evaluate(f"window.shadeform.stereo.{what}")


def open_vase(page) -> None:
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-photo-set="stereo:vase"]')
    page.wait_for_function(
        "window.shadeform.stereo.applied() > 0 || window.shadeform.stereo.error() !== null",
        timeout=ui.FIRST_RESULT_MS,
    )
    assert stereo(page, "error()") is None, stereo(page, "error()")


def drawn(page) -> np.ndarray:
    """The pane's picture as drawn once the next frames have gone: (rows, cols, 3) uint8."""
    page.evaluate("new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")
    url = page.evaluate("document.getElementById('stereo-canvas').toDataURL('image/png')")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"))


def on_object(picture: np.ndarray) -> np.ndarray:
    return np.any(picture != BACKGROUND, axis=2)


def srgb_to_linear(code: np.ndarray) -> np.ndarray:
    v = np.asarray(code, dtype=float) / 255
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def test_each_viewing_mode_draws_its_own_picture_and_its_sliders_change_it(page):
    open_vase(page)
    plain = drawn(page)
    mask = on_object(plain)
    assert mask.sum() > 5000
    assert page.input_value("#relight-mode") == "default"
    ARTIFACTS.mkdir(exist_ok=True)
    pictures = {"default": plain}
    for mode, sliders in SLIDERS.items():
        page.select_option("#relight-mode", mode)
        # the mode's own sliders, and only they, are shown
        for other in {s for ss in SLIDERS.values() for s in ss}:
            assert page.is_visible(f"#{other}") is (other in sliders), (mode, other)
        picture = drawn(page)
        assert stereo(page, "viewing().mode") == mode
        assert (on_object(picture) == mask).all()  # the same object, nothing drawn off it
        grey = picture[mask].mean(axis=1)
        assert grey.std() > 15 and grey.mean() > 20  # not blank
        if mode != "default":
            assert np.abs(picture[mask].astype(int) - plain[mask]).mean() > 4, mode
        Image.fromarray(picture).save(ARTIFACTS / f"relight-{mode}.png")
        pictures[mode] = picture
        # each of its sliders, moved to its end by the keyboard, changes the picture
        for slider in sliders:
            page.focus(f"#{slider}")
            page.keyboard.press("End")
            moved = drawn(page)
            assert (moved != picture).any(axis=2)[mask].mean() > 0.01, slider
            picture = moved
    # the modes differ from one another
    modes = list(pictures)
    for i, a in enumerate(modes):
        for b in modes[i + 1 :]:
            assert np.abs(pictures[a][mask].astype(int) - pictures[b][mask]).mean() > 2, (a, b)
    # specular enhancement is grey whatever the vase's colour
    page.select_option("#relight-mode", "specular-enhancement")
    picture = drawn(page)[mask].astype(int)
    assert np.abs(picture - picture[:, :1]).max() == 0


def test_a_second_light_adds_its_light_where_both_fall_and_reset_leaves_one(page):
    open_vase(page)
    one = drawn(page)
    mask = on_object(one)
    first = np.array(stereo(page, "light()"))
    page.click("#relight-add")
    lights = np.array(stereo(page, "lights()"))
    assert len(lights) == 2 and np.allclose(lights[0], first)
    assert "2 lights" in page.inner_text("#relight-lights-out")
    two = drawn(page)
    # where both lights fall on the object, each pixel's linear light is the two lights' sum
    rows, cols = np.nonzero(mask)
    both = [
        (r, c)
        for r, c in zip(rows[::97], cols[::97], strict=True)
        if (m := stereo(page, f"mapsAt({r}, {c})"))
        and min(np.dot(m["normal"], lights[0]), np.dot(m["normal"], lights[1])) > 0.3
    ]
    assert len(both) > 20
    for r, c in both:
        assert two[r, c].sum() > one[r, c].sum() + 10, (r, c)
        m = stereo(page, f"mapsAt({r}, {c})")
        linear = np.array(m["albedo"]) * sum(max(0.0, float(np.dot(m["normal"], light))) for light in lights)
        if linear.max() < 0.95:  # not clipped
            np.testing.assert_allclose(srgb_to_linear(two[r, c]), linear, atol=0.01)
    # the disc: a drag from the second handle moves the second light only
    dome = page.locator("#light-dome").bounding_box()
    half = dome["width"] / 2
    radius = half - 6

    def disc_point(x, y):
        return dome["x"] + half + x * radius, dome["y"] + half - y * radius

    page.mouse.move(*disc_point(lights[1][0], lights[1][1]))
    page.mouse.down()
    page.mouse.move(*disc_point(-0.1, -0.6), steps=4)
    page.mouse.up()
    moved = np.array(stereo(page, "lights()"))
    assert np.allclose(moved[0], lights[0]) and np.allclose(moved[1][:2], [-0.1, -0.6], atol=0.03)
    assert stereo(page, "light()") == stereo(page, "lights()[1]")  # the one a drag on the image moves
    page.click("#relight-add")
    assert len(stereo(page, "lights()")) == 3 and page.is_disabled("#relight-add")
    page.screenshot(path=str(ARTIFACTS / "relight-three-lights.png"))
    page.click("#relight-reset")
    assert len(stereo(page, "lights()")) == 1 and page.is_enabled("#relight-add")


def test_the_viewing_mode_and_lights_come_back_after_a_reload(page):
    open_vase(page)
    page.select_option("#relight-mode", "unsharp-masking")
    page.focus("#relight-amount")
    page.keyboard.press("End")
    page.click("#relight-add")
    kept = stereo(page, "viewing()")
    assert kept["mode"] == "unsharp-masking" and kept["amount"] == 10 and len(kept["lights"]) == 2
    page.wait_for_function("window.shadeform.sessionSaved()", timeout=RESULT_MS)
    page.reload()
    page.evaluate("window.shadeform.ready")
    page.wait_for_function("window.shadeform.stereo.applied() > 0", timeout=ui.FIRST_RESULT_MS)
    assert stereo(page, "viewing()") == kept
    assert page.input_value("#relight-mode") == "unsharp-masking" and page.is_visible("#relight-amount")
    assert page.input_value("#relight-amount") == "10"


def test_save_picture_downloads_the_pane_as_a_png_of_the_photos_size(page, tmp_path):
    open_vase(page)
    info = stereo(page, "info()")
    page.select_option("#relight-mode", "specular-enhancement")
    for show, name in [
        ("relight", "relight-specular-enhancement"),
        ("normals", "normals"),
        ("confidence", "confidence"),
    ]:
        page.click(f'#stereo-show [data-show="{show}"]')
        shown = drawn(page)
        with page.expect_download(timeout=RESULT_MS) as started:
            page.click("#stereo-picture")
        done = started.value
        assert done.suggested_filename == f"stereo_vase-{name}.png"  # as its model exports: stereo_vase.obj
        path = tmp_path / done.suggested_filename
        done.save_as(path)
        saved = Image.open(path)
        assert saved.format == "PNG" and saved.size == (info["width"], info["height"])
        np.testing.assert_array_equal(np.asarray(saved.convert("RGB")), shown)
