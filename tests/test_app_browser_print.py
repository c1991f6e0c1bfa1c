"""The Print and Maps panels in a real browser: build a solid of a given size, see its measures,
download it; preview the texture maps, download them as a zip.

The server, the browser and a fresh page per test are those of ``tests/helpers/browser.py``: the
real server under uvicorn on a free loopback port serving the built client, Debian's Chromium
driven by Playwright with clicks and typing. Facts come from the test hook
(``window.shadeform.print`` and ``.maps``), from the page (the measures' text, the buttons) and
from the downloaded files, read back with trimesh and PyPNG. Screenshots of both panels go to
``tests/artifacts/app-print.png`` and ``app-maps.png``.
"""

from __future__ import annotations

import zipfile

import png
import pytest

from helpers import browser as ui
from helpers.browser import ARTIFACTS, BOWL, RESULT_MS, applied, open_example, wait_for_result

# the real server, Chromium and a fresh page per test: the fixtures of tests/helpers/browser.py
server, browser, page = ui.server, ui.browser, ui.page

trimesh = pytest.importorskip("trimesh")

MAP_BITS = {"normal_opengl": 16, "normal_directx": 16, "height": 16, "ambient_occlusion": 8, "curvature": 8}


def print_state(page) -> dict:
    return page.evaluate("window.shadeform.print.modelState()")


def wait_for(page, hook: str, status: str, timeout=RESULT_MS) -> dict:
    page.wait_for_function(f"window.shadeform.{hook}.modelState().status === {status!r}", timeout=timeout)
    return page.evaluate(f"window.shadeform.{hook}.modelState()")


def build_print(page, width: str) -> dict:
    page.fill("#print-width", width)
    page.click("#print-build")
    return wait_for(page, "print", "current")


def test_print_a_solid_of_the_size_asked(page, tmp_path):
    open_example(page, BOWL)
    page.locator("#print-group").scroll_into_view_if_needed()
    assert print_state(page)["status"] == "none"
    assert page.evaluate("window.shadeform.print.downloads()") == {"stl": False, "3mf": False}

    build_print(page, "80")
    result = page.evaluate("window.shadeform.print.lastResult()")
    assert max(result["size_mm"][:2]) == pytest.approx(80.0, abs=1e-4)
    assert result["volume_mm3"] > 0 and result["triangle_count"] > 0
    assert page.evaluate("window.shadeform.print.shown()") is True
    # the measures beside the solid, in mm
    width, depth, height = (f"{value:.1f}" for value in result["size_mm"])
    text = page.inner_text("#print-dims")
    assert text == page.evaluate("window.shadeform.print.dimensions()")
    assert f"{width} × {depth} × {height} mm" in text and "80.0" in text
    labels = [page.inner_text(f".dim-label.dim-{axis}") for axis in "xyz"]
    assert labels == [f"{width} mm", f"{depth} mm", f"{height} mm"]
    assert page.evaluate("window.shadeform.print.downloads()") == {"stl": True, "3mf": True}
    page.screenshot(path=str(ARTIFACTS / "app-print.png"))

    with page.expect_download() as info:
        page.click("#print-stl")
    download = info.value
    assert download.suggested_filename.endswith("-relief.stl")
    path = tmp_path / download.suggested_filename
    download.save_as(path)
    solid = trimesh.load(path, force="mesh")
    assert solid.is_watertight and solid.volume > 0
    assert max(solid.extents[:2]) == pytest.approx(80.0, abs=1e-3)  # float32 in the file
    assert solid.extents[2] == pytest.approx(result["size_mm"][2], abs=1e-3)

    # a print setting changed: the solid is out of date and cannot be downloaded until rebuilt
    page.fill("#print-width", "60")
    state = print_state(page)
    assert state["status"] == "stale" and state["message"] == "print settings changed"
    assert page.evaluate("window.shadeform.print.downloads()") == {"stl": False, "3mf": False}
    assert page.inner_text("#print-dims").endswith("out of date")
    assert page.inner_text("#print-status").startswith("Out of date: print settings changed")
    build_print(page, "60")
    assert max(page.evaluate("window.shadeform.print.lastResult().size_mm")[:2]) == pytest.approx(
        60.0, abs=1e-4
    )

    # back to the model, and the solid again, without asking the server
    page.click("#print-switch")
    assert page.evaluate("window.shadeform.print.shown()") is False
    assert page.evaluate("window.shadeform.print.dimensions()") is None
    page.click("#print-switch")
    assert page.evaluate("window.shadeform.print.shown()") is True

    # a model setting changed: the new model takes the view, the solid is out of date
    before = applied(page)
    page.select_option("#filter-kind", "gaussian")
    state = print_state(page)
    assert state["status"] == "stale" and state["message"] == "the model's settings changed"
    wait_for_result(page, before)
    assert page.evaluate("window.shadeform.print.shown()") is False
    assert page.evaluate("window.shadeform.print.downloads()") == {"stl": False, "3mf": False}


def test_a_bad_print_setting_is_said_in_one_line(page):
    open_example(page, BOWL)
    page.fill("#print-base", "0.2")
    page.click("#print-build")
    state = wait_for(page, "print", "failed")
    assert "base" in state["message"] and "thinnest wall" in state["message"]
    assert page.evaluate("window.shadeform.print.error()") == state["message"]
    assert page.evaluate("window.shadeform.print.downloads()") == {"stl": False, "3mf": False}


def test_maps_previewed_and_downloaded_as_a_zip(page, tmp_path):
    open_example(page, BOWL)
    page.locator("#maps-group").scroll_into_view_if_needed()
    assert page.evaluate("window.shadeform.maps.zipEnabled()") is False
    page.click("#maps-make")
    wait_for(page, "maps", "current")
    page.wait_for_function(
        "window.shadeform.maps.maps().length === 5 && window.shadeform.maps.maps().every((m) => m.loaded)"
    )
    shown = page.evaluate("window.shadeform.maps.maps()")
    assert [m["name"] for m in shown] == list(MAP_BITS)
    assert all(0 < m["width"] <= 256 and 0 < m["height"] <= 256 and m["legend"] for m in shown)
    assert {m["name"]: m["bits"] for m in shown} == MAP_BITS
    assert page.locator("#maps-grid img").count() == 5
    page.locator("#maps-group").scroll_into_view_if_needed()
    page.screenshot(path=str(ARTIFACTS / "app-maps.png"))

    with page.expect_download() as info:
        page.click("#maps-zip")
    download = info.value
    assert download.suggested_filename.endswith("-maps.zip")
    path = tmp_path / download.suggested_filename
    download.save_as(path)
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        assert "README.txt" in names
        readme = archive.read("README.txt").decode()
        for name, bits in MAP_BITS.items():
            (member,) = [n for n in names if n.endswith(f"_{name}.png")]
            width, height, _, meta = png.Reader(bytes=archive.read(member)).read()
            assert (width, height) == (256, 256) and meta["bitdepth"] == bits, member
            assert member in readme

    # a model setting changed: the previews are out of date and the zip is off
    page.select_option("#filter-kind", "gaussian")
    page.wait_for_function("window.shadeform.maps.modelState().status === 'stale'")
    assert page.evaluate("window.shadeform.maps.zipEnabled()") is False


def test_a_refused_maps_request_is_said_and_the_next_one_supersedes_it(page):
    """The server's one-line refusal fails the previews and stays in the panel; of two requests
    only the latest one's answer is shown."""
    open_example(page, BOWL)
    page.locator("#maps-group").scroll_into_view_if_needed()
    detail = "the maps cannot be made: test refusal"
    page.route(
        "**/api/maps",
        lambda route: route.fulfill(
            status=422, content_type="application/json", body=f'{{"detail": "{detail}"}}'
        ),
    )
    page.click("#maps-make")
    state = wait_for(page, "maps", "failed")
    assert state["message"] == detail and page.evaluate("window.shadeform.maps.error()") == detail
    assert page.evaluate("window.shadeform.maps.zipEnabled()") is False
    # held, then superseded: only the second request's answer makes the previews current
    page.unroute("**/api/maps")
    held = []
    page.route("**/api/maps", lambda route: held.append(route))
    page.click("#maps-make")
    page.wait_for_function("window.shadeform.maps.modelState().status === 'computing'")
    assert page.evaluate("window.shadeform.maps.error()") is None  # the old message goes with a new request
    page.unroute("**/api/maps")
    page.click("#maps-make")
    wait_for(page, "maps", "current")
    assert page.evaluate("window.shadeform.maps.maps().length") == 5


def test_a_photo_sets_model_printed_and_mapped(page, tmp_path):
    """In photo-set mode the Print and Maps panels take the set's photometric stereo: a solid of
    the width asked, downloaded; the maps with the set's albedo, in the zip too; a change of the
    set's settings makes both out of date."""
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-photo-set="stereo:vase"]')
    page.wait_for_function("window.shadeform.stereo.applied() > 0", timeout=RESULT_MS)
    assert page.is_visible("#print-group") and page.is_visible("#maps-group")
    result = build_print(page, "50")
    assert result["status"] == "current"
    solid = page.evaluate("window.shadeform.print.lastResult()")
    assert max(solid["size_mm"][:2]) == pytest.approx(50.0, abs=1e-4)
    assert page.evaluate("window.shadeform.print.shown()") is True
    with page.expect_download() as info:
        page.click("#print-stl")
    path = tmp_path / info.value.suggested_filename
    info.value.save_as(path)
    mesh = trimesh.load(path, force="mesh")
    assert mesh.is_watertight and max(mesh.extents[:2]) == pytest.approx(50.0, abs=1e-3)
    page.click("#print-switch")  # the set's model again
    assert page.evaluate("window.shadeform.print.shown()") is False

    page.locator("#maps-group").scroll_into_view_if_needed()
    page.click("#maps-make")
    wait_for(page, "maps", "current")
    page.wait_for_function("window.shadeform.maps.maps().length === 6")
    shown = {m["name"]: m["bits"] for m in page.evaluate("window.shadeform.maps.maps()")}
    assert shown == {**MAP_BITS, "albedo": 16}
    page.screenshot(path=str(ARTIFACTS / "app-maps-photo-set.png"))
    with page.expect_download() as info:
        page.click("#maps-zip")
    zipped = tmp_path / info.value.suggested_filename
    info.value.save_as(zipped)
    with zipfile.ZipFile(zipped) as archive:
        (albedo,) = [n for n in archive.namelist() if n.endswith("_albedo.png")]
        assert png.Reader(bytes=archive.read(albedo)).read()[3]["bitdepth"] == 16

    # the set's settings changed: the solid and the maps are out of date
    page.select_option("#stereo-model", "robust")
    page.wait_for_function("window.shadeform.print.modelState().status === 'stale'")
    page.wait_for_function("window.shadeform.maps.modelState().status === 'stale'")
