"""End-to-end tests of ``shadeform app`` in a real browser: the server, the built client, Chromium.

The real server (:func:`shadeform.app.server.create_app` under uvicorn, in a thread, on a free
loopback port) serves the client built into ``src/shadeform/app/static/`` (``make web``), and
Playwright drives Debian's Chromium (``/usr/bin/chromium``) with mouse clicks and key presses as
a person would. Facts are read from the page's read-only test hook ``window.shadeform`` (the
parameters, the mesh on screen) and from the files the export buttons download, which are
validated by the same independent readers as the exporter tests (``ivinfo``/``ivcat``,
three.js's ``VRMLLoader``).

Without ``/usr/bin/chromium`` these tests skip, saying so; when ``CI`` is set they fail instead.
A full-page screenshot of the app is kept in ``tests/artifacts/app.png``.
"""

from __future__ import annotations

import base64
import io
import json
import math

import numpy as np
import pytest

from helpers import browser as ui
from helpers.browser import (
    ARTIFACTS,
    BOWL,
    FIRST_RESULT_MS,
    RESULT_MS,
    applied,
    click_image,
    download,
    open_example,
    wait_for_result,
)
from helpers.readers import check_inventor, check_vrml, inventor_numbers, run_tool
from shadeform.mesh import Mesh, to_mesh

# the synthetic bowl at its default size (256 px): its object is a disk of radius ~108 px
CENTRE = (128, 128)
RING_RADIUS = 70  # inside the disk, inside the polygon drawn below


# the real server, Chromium and a fresh page per test (tests/helpers/browser.py)
server, browser, page = ui.server, ui.browser, ui.page


# ----------------------------------------------------------------------------- helpers


def depth(page, row: int, col: int) -> float:
    value = page.evaluate(f"window.shadeform.depthAt({row}, {col})")
    assert value is not None, f"no mesh vertex near pixel ({row}, {col})"
    return value


def ring_points(radius: float, count: int = 8):
    """(row, col) pixels on a circle about the bowl's centre."""
    angles = np.linspace(0, 2 * np.pi, count, endpoint=False)
    return [(round(CENTRE[0] + radius * np.sin(a)), round(CENTRE[1] + radius * np.cos(a))) for a in angles]


def centre_minus_ring(zs_at) -> float:
    """Height of the centre above the mean of a ring inside the object: > 0 bulges toward the viewer."""
    return zs_at(*CENTRE) - float(np.mean([zs_at(r, c) for r, c in ring_points(RING_RADIUS)]))


def shown_mesh(page) -> Mesh:
    """The mesh the 3D view shows, as the library's Mesh (float32 values widened)."""
    data = page.evaluate("window.shadeform.mesh()")
    return Mesh(
        vertices=np.array(data["positions"], dtype=np.float64).reshape(-1, 3),
        faces=np.array(data["indices"], dtype=np.int64).reshape(-1, 3),
        normals=np.array(data["normals"], dtype=np.float64).reshape(-1, 3),
        uv=np.array(data["uvs"], dtype=np.float64).reshape(-1, 2),
    )


def nearest_z(points: np.ndarray, row: int, col: int) -> float:
    """z of the vertex in (V, 3) ``points`` nearest pixel (row, col) (mesh convention: y = -row)."""
    return float(points[np.argmin((points[:, 0] - col) ** 2 + (points[:, 1] + row) ** 2), 2])


# ------------------------------------------------------------------------------- tests


def test_bowl_flips_after_drawing_a_concave_region_and_exports_it(page, tmp_path):
    open_example(page, BOWL)
    # the convexity assumption makes the bowl a dome: the centre bulges toward the viewer
    assert centre_minus_ring(lambda r, c: depth(page, r, c)) > 10

    # draw an octagon over the bowl, corner by corner, and close it on its first corner
    before = applied(page)
    page.click('#tools [data-tool="polygon"]')
    page.click('#axis [data-axis="both"]')
    corners = [
        (CENTRE[1] + 90 * math.cos(a), CENTRE[0] + 90 * math.sin(a))
        for a in np.linspace(0, 2 * math.pi, 8, endpoint=False)
    ]
    for x, y in corners:
        click_image(page, x, y)
    click_image(page, *corners[0])
    wait_for_result(page, before)
    regions = page.evaluate("window.shadeform.state().params.concave.regions")
    assert len(regions) == 1 and regions[0]["axis"] == "both"
    np.testing.assert_allclose(regions[0]["polygon"], corners, atol=0.6)  # clicks land on the pixel grid

    # inside the region the depth flips: the centre is now the lowest part
    assert centre_minus_ring(lambda r, c: depth(page, r, c)) < -10
    mesh = shown_mesh(page)

    wrl = download(page, '[data-format=".wrl"]', "#export-menu", tmp_path)
    iv = download(page, '[data-format=".iv"]', "#export-menu", tmp_path)
    assert (wrl.suffix, iv.suffix) == (".wrl", ".iv")
    check_vrml(wrl, mesh)
    check_inventor(iv, mesh)
    # and read back from the exported file itself: the centre is lower than the ring
    points = inventor_numbers(run_tool("ivcat", str(iv)).stdout, "Coordinate3", "point").reshape(-1, 3)
    assert centre_minus_ring(lambda r, c: nearest_z(points, r, c)) < -10

    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "app.png"), full_page=True)


def test_export_a_closed_model_whose_back_is_said_to_be_a_guess(page, tmp_path):
    """The Export menu's "Closed" toggle stays set while the menu is open; the download is the
    watertight closed model and a toast says its back is a guess."""
    import trimesh

    open_example(page, "synth:ellipsoid")
    page.click("#export-menu > button")
    page.click("#export-closed-row")
    assert page.is_checked("#export-closed") and page.is_visible('[data-format=".stl"]')
    with page.expect_download(timeout=RESULT_MS) as started:
        page.click('[data-format=".stl"]')
    target = tmp_path / started.value.suggested_filename
    started.value.save_as(target)
    assert target.name.endswith("_closed.stl") and trimesh.load(target).is_watertight
    page.wait_for_function("window.shadeform.toasts().some((t) => t.text.includes('a guess'))")
    ARTIFACTS.mkdir(exist_ok=True)
    page.click("#export-menu > button")
    page.screenshot(path=str(ARTIFACTS / "export-closed.png"))


def test_regions_file_load_move_delete_and_save(page, tmp_path):
    from shadeform.regions import parse_regions

    open_example(page, BOWL)
    octagon = [
        [round(CENTRE[1] + 90 * math.cos(a), 2), round(CENTRE[0] + 90 * math.sin(a), 2)]
        for a in np.linspace(0, 2 * math.pi, 8, endpoint=False)
    ]
    regions_file = tmp_path / "bowl.regions.json"
    regions_file.write_text(json.dumps({"regions": [{"polygon": octagon, "axis": "both"}]}))
    before = applied(page)
    page.set_input_files("#file-regions", str(regions_file))
    wait_for_result(page, before)
    assert page.evaluate("window.shadeform.state().params.concave.regions") == [
        {"polygon": octagon, "axis": "both"}
    ]
    assert centre_minus_ring(lambda r, c: depth(page, r, c)) < -10

    # select it and drag it 10 pixels to the right
    before = applied(page)
    page.click('#tools [data-tool="select"]')
    start = page.evaluate(f"window.shadeform.pagePoint({CENTRE[1]}, {CENTRE[0]})")
    end = page.evaluate(f"window.shadeform.pagePoint({CENTRE[1] + 10}, {CENTRE[0]})")
    page.mouse.move(start["x"], start["y"])
    page.mouse.down()
    page.mouse.move(end["x"], end["y"], steps=5)
    page.mouse.up()
    wait_for_result(page, before)
    assert page.evaluate("window.shadeform.state().selectedRegion") == 0
    moved = np.array(page.evaluate("window.shadeform.state().params.concave.regions[0].polygon"))
    np.testing.assert_allclose(moved - np.array(octagon), [[10, 0]] * 8, atol=0.5)

    # the saved file is the CLI's format: the library's own parser reads it back
    saved = download(page, '[data-action="save-regions"]', "#project-menu", tmp_path)
    (region,) = parse_regions(saved)
    np.testing.assert_allclose(region.polygon, moved)
    assert region.axis == "both"

    # Delete removes the selected region: the bowl is a dome again
    before = applied(page)
    page.keyboard.press("Delete")
    wait_for_result(page, before)
    assert page.evaluate("window.shadeform.state().params.concave.regions") == []
    assert centre_minus_ring(lambda r, c: depth(page, r, c)) > 10


def test_an_unsure_light_estimate_says_so_and_a_sure_one_does_not(page, tmp_path):
    """The sphere's light is read from its outline (sure); a cylinder seen side-on shows only the
    light's component across its axis, so its estimate is unsure, and the panel says what to do."""
    open_example(page, SPHERE)
    before = applied(page)
    page.click('#light-mode [data-mode="estimate"]')
    wait_for_result(page, before)
    assert "confidence 1.00" in page.inner_text("#light-readout")
    assert not page.is_visible("#light-unsure")
    open_example(page, "synth:cylinder")  # a new image starts from the default light, +z
    assert not page.is_visible("#light-unsure")
    before = applied(page)
    page.click('#light-mode [data-mode="estimate"]')
    wait_for_result(page, before)
    estimate = page.evaluate("window.shadeform.lastResult().info.light_estimate")
    assert estimate["unsure"] and estimate["confidence"] < 0.5
    assert f"confidence {estimate['confidence']:.2f}" in page.inner_text("#light-readout")
    assert page.is_visible("#light-unsure") and "Slant / tilt" in page.inner_text("#light-unsure")
    page.locator("#light-unsure").scroll_into_view_if_needed()
    page.screenshot(path=str(tmp_path / "light-unsure.png"))
    ARTIFACTS.mkdir(exist_ok=True)
    page.locator("section.group", has=page.locator("#light-mode")).screenshot(
        path=str(ARTIFACTS / "light-unsure.png")
    )
    # a light given by its angles: nothing is estimated, nothing to be unsure of
    before = applied(page)
    page.click('#light-mode [data-mode="slant_tilt"]')
    wait_for_result(page, before)
    assert not page.is_visible("#light-unsure") and "confidence" not in page.inner_text("#light-readout")


def test_slant_and_tilt_start_at_the_estimate(page):
    """From Estimate to Slant / tilt the sliders start where the estimate was (the coin's light,
    read from the photo), to be corrected from there, not at their last manual values."""
    open_example(page, "coin")
    before = applied(page)
    page.click('#light-mode [data-mode="estimate"]')
    wait_for_result(page, before)
    estimate = page.evaluate("window.shadeform.lastResult().info.light_estimate")
    assert estimate["slant"] > 5  # a light off the camera's axis, or the test says nothing
    before = applied(page)
    page.click('#light-mode [data-mode="slant_tilt"]')
    wait_for_result(page, before)
    light = page.evaluate("window.shadeform.state().params.light")
    assert light["mode"] == "slant_tilt"
    assert (light["slant"], light["tilt"]) == (round(estimate["slant"]), round(estimate["tilt"]))
    assert page.input_value("#slant") == str(round(estimate["slant"]))


def test_a_new_photo_that_fails_shows_nothing_of_the_last_one(page, tmp_path):
    """A photo whose first solve fails (all black: no object) leaves no model of the photo before
    it on screen, nor its mask's description; the message says what failed."""
    from PIL import Image

    open_example(page, "coin")
    assert page.evaluate("window.shadeform.views.shownVertexCount()") > 0
    assert "pixels" in page.evaluate("window.shadeform.mask().note")  # the coin's automatic mask
    black = tmp_path / "black.png"
    Image.fromarray(np.zeros((64, 80), np.uint8)).save(black)
    page.set_input_files("#file-image", str(black))
    page.wait_for_function("window.shadeform.modelState().status === 'failed'", timeout=RESULT_MS)
    assert page.evaluate("window.shadeform.state().image.name") == "black.png"
    assert page.evaluate("window.shadeform.views.shownVertexCount()") == 0
    assert page.is_visible("#view-empty") and page.inner_text("#mesh-info") == ""
    assert page.evaluate("window.shadeform.mesh()") is None
    note = page.evaluate("window.shadeform.mask().note")
    assert "pixels" not in note, note  # not the bowl's automatic mask
    assert "object" in page.evaluate("window.shadeform.modelState().message")


def test_the_model_never_covers_the_corner_inset(page, tmp_path):
    """The bumps fill the 3D view down to its bottom-left corner, where the inset (the camera
    frame's axes and the light) sits: the inset shows its own dark frame, not the model's clay."""
    from PIL import Image

    open_example(page, "synth:bumps")
    page.wait_for_timeout(300)  # the render worker's frame
    shot = tmp_path / "inset.png"
    page.locator(".gizmo-frame").screenshot(path=str(shot))
    pixels = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    clay = (r > 120) & (g > 120) & (b > 120) & (abs(r - b) < 40)  # the lit model's warm grey
    assert clay.mean() < 0.01, f"{100 * clay.mean():.1f} % of the inset is the model"


def test_whatever_is_hidden_is_not_shown(page):
    """The page hides with the ``hidden`` attribute; no class's display may override it (a .btn's
    inline-flex showed the hidden "Downsample and open" button as an empty blue button)."""
    open_example(page, BOWL)
    shown = page.evaluate(
        """() => {
          document.getElementById('fit-accept').hidden = true;  // as when no downsample is offered
          return [...document.querySelectorAll('[hidden]')]
            .filter((e) => getComputedStyle(e).display !== 'none')
            .map((e) => e.id || e.className);
        }"""
    )
    assert shown == []


def test_reference_clicks_add_and_remove_the_depth_origin(page):
    open_example(page, BOWL)
    auto = page.evaluate("window.shadeform.lastResult().references")
    assert len(auto) == 1  # the brightest pixel, chosen automatically

    before = applied(page)
    page.click('#tools [data-tool="reference"]')
    click_image(page, 128, 60)  # x = col, y = row
    wait_for_result(page, before)
    assert page.evaluate("window.shadeform.state().params.references") == [[60, 128]]
    assert page.evaluate("window.shadeform.lastResult().references")[0] == [60, 128]
    # the main reference is the depth origin (docs/conventions.md)
    assert depth(page, 60, 128) == pytest.approx(0, abs=1e-4)

    before = applied(page)
    click_image(page, 128, 60)  # clicking it again removes it
    wait_for_result(page, before)
    assert page.evaluate("window.shadeform.state().params.references") == []
    assert page.evaluate("window.shadeform.lastResult().references") == auto


def test_a_newer_request_supersedes_older_ones(page, server):
    open_example(page, BOWL)
    before = applied(page)
    # six step changes in quick succession, as a fast slider drag sends them
    page.evaluate(
        """() => {
            const step = document.getElementById('step');
            for (const value of [1, 2, 3, 4, 5, 6]) {
                step.value = String(value);
                step.dispatchEvent(new Event('change'));
            }
        }"""
    )
    wait_for_result(page, before)
    page.wait_for_timeout(300)  # a stale response would land here
    assert page.evaluate("window.shadeform.state().params.step") == 6
    result = page.evaluate("window.shadeform.lastResult()")
    assert result["request_id"] == page.evaluate("window.shadeform.requests()")  # the newest one sent
    # the mesh on screen is the step-6 mesh of the library's own reconstruction
    from shadeform import reconstruct
    from shadeform.examples import load_example

    image, info = load_example(BOWL)
    expected_rec = reconstruct(image, mask=info["mask"], light=info["light"])
    expected = to_mesh(expected_rec, step=6)
    assert result["vertex_count"] == expected.n_vertices
    assert result["triangle_count"] == expected.n_faces

    # a drag: moves 6 -> 1 (input events), then the release on 3 (a change event)
    before = applied(page)
    page.evaluate(
        """async () => {
            const step = document.getElementById('step');
            for (const value of [5, 4, 3, 2, 1]) {
                step.value = String(value);
                step.dispatchEvent(new Event('input'));
                await new Promise((resolve) => setTimeout(resolve, 15));
            }
            step.value = '3';
            step.dispatchEvent(new Event('change'));
        }"""
    )
    wait_for_result(page, before)
    page.wait_for_timeout(300)
    result = page.evaluate("window.shadeform.lastResult()")
    assert page.evaluate("window.shadeform.state().params.step") == 3
    assert result["request_id"] == page.evaluate("window.shadeform.requests()")
    assert result["vertex_count"] == to_mesh(expected_rec, step=3).n_vertices


def test_a_new_solve_shows_a_quick_look_then_the_full_resolution_model(page):
    from shadeform import reconstruct
    from shadeform.examples import load_example

    open_example(page, BOWL)
    before = applied(page)
    page.evaluate(
        """() => {
            const kind = document.getElementById('filter-kind');
            kind.value = 'gaussian';
            kind.dispatchEvent(new Event('change'));
        }"""
    )
    wait_for_result(page, before)
    timeline = page.evaluate("window.shadeform.timeline()")
    result = page.evaluate("window.shadeform.lastResult()")
    params = page.evaluate("window.shadeform.state().params")
    assert params["step"] == 2 and params["filter"]["kind"] == "gaussian"
    # two models drawn for the one change: the quick look, then the full solve
    assert applied(page) == before + 2
    assert timeline["firstRendered"] < timeline["rendered"] and timeline["preview"] is False
    assert result["preview"] is False and "preview_step" not in result["info"]
    # what stays on screen is the library's full-resolution model
    image, info = load_example(BOWL)
    expected = to_mesh(
        reconstruct(
            image, mask=info["mask"], light=info["light"], filter=f"gaussian:{params['filter']['size']}"
        ),
        step=2,
    )
    positions = np.array(page.evaluate("window.shadeform.mesh().positions")).reshape(-1, 3)
    np.testing.assert_allclose(positions, expected.vertices, atol=1e-3)


def test_reload_keeps_the_image_parameters_and_regions_even_when_the_server_forgot(page, tmp_path):
    # an upload, so a reload must send the bytes again once the server has forgotten the image
    from PIL import Image

    from shadeform.examples import load_example

    image, _ = load_example("synth:sphere", size=96)
    png = tmp_path / "ball.png"
    Image.fromarray((image * 255).round().astype(np.uint8)).save(png)
    before = applied(page)
    page.set_input_files("#file-image", str(png))
    wait_for_result(page, before, timeout=FIRST_RESULT_MS)

    before = applied(page)
    page.select_option("#filter-kind", "gaussian")
    wait_for_result(page, before)
    before = applied(page)
    page.click('#tools [data-tool="polygon"]')
    page.click('#axis [data-axis="x"]')
    for x, y in [(30, 30), (60, 30), (45, 60)]:
        click_image(page, x, y)
    page.keyboard.press("Enter")
    wait_for_result(page, before)
    saved = page.evaluate("window.shadeform.state()")
    page.wait_for_function("window.shadeform.sessionSaved()", timeout=RESULT_MS)

    # make the stored image id unknown to the server, as after a restart
    page.evaluate(
        """() => {
            const key = 'shadeform.session.v1';
            const session = JSON.parse(localStorage.getItem(key));
            session.image.image_id = 'forgotten';
            localStorage.setItem(key, JSON.stringify(session));
        }"""
    )
    page.reload()
    page.evaluate("window.shadeform.ready")
    wait_for_result(page, 0)
    state = page.evaluate("window.shadeform.state()")
    assert state["image"]["name"] == "ball.png"
    assert state["image"]["image_id"] not in ("forgotten", saved["image"]["image_id"])
    assert state["params"] == saved["params"]
    assert state["params"]["filter"]["kind"] == "gaussian"
    assert state["params"]["concave"]["regions"][0]["axis"] == "x"


def test_project_file_round_trip(page, browser, server, tmp_path):
    open_example(page, BOWL)
    before = applied(page)
    page.click("#light-mode [data-mode=slant_tilt]")
    wait_for_result(page, before)
    before = applied(page)
    page.fill("#slant", "20")  # a range input: fill sets the value and fires input + change
    wait_for_result(page, before)
    project = download(page, '[data-action="save-project"]', "#project-menu", tmp_path)
    document = json.loads(project.read_text())
    assert document["format"] == "shadeform-project"
    assert document["image"]["example"] == BOWL
    assert document["params"]["light"] == {"mode": "slant_tilt", "slant": 20, "tilt": 0}

    # a new profile (empty storage) opens the project file and gets the same session
    context = browser.new_context(viewport={"width": 1440, "height": 860})
    try:
        other = context.new_page()
        other.goto(server)
        other.evaluate("window.shadeform.ready")
        other.set_input_files("#file-project", str(project))
        wait_for_result(other, 0)
        state = other.evaluate("window.shadeform.state()")
        assert state["image"]["name"] == BOWL
        assert state["params"] == page.evaluate("window.shadeform.state().params")
        light = other.evaluate("window.shadeform.lastResult().light")
        np.testing.assert_allclose(
            light, [math.sin(math.radians(20)), 0, math.cos(math.radians(20))], atol=1e-6
        )
    finally:
        context.close()


def test_view_keys_and_buttons_turn_zoom_and_recenter(page):
    open_example(page, BOWL)
    front = page.evaluate("window.shadeform.cameraOffset()")
    assert front[0] == pytest.approx(0, abs=1e-6) and front[2] > 0  # looking down -z at the front

    page.click("#view-host canvas")  # focus the view; a click without a drag does not turn it
    page.keyboard.press("ArrowRight")
    turned = page.evaluate("window.shadeform.cameraOffset()")
    assert math.degrees(math.atan2(turned[0], turned[2])) == pytest.approx(15, abs=0.5)
    page.keyboard.press("+")
    zoomed = page.evaluate("window.shadeform.cameraOffset()")
    assert np.linalg.norm(zoomed) == pytest.approx(np.linalg.norm(turned) / 1.2, rel=1e-3)
    page.click('.nav [data-nav="zoom-out"]')
    assert np.linalg.norm(page.evaluate("window.shadeform.cameraOffset()")) == pytest.approx(
        np.linalg.norm(turned), rel=1e-3
    )
    page.keyboard.press("r")
    np.testing.assert_allclose(page.evaluate("window.shadeform.cameraOffset()"), front, atol=1e-6)


def drop_file(page, name: str, mime: str, data: bytes) -> None:
    """Drop a file on the app's window, as dragging one from the desktop does."""
    page.evaluate(
        """([name, mime, base64]) => {
            const bytes = Uint8Array.from(atob(base64), (ch) => ch.charCodeAt(0));
            const transfer = new DataTransfer();
            transfer.items.add(new File([bytes], name, { type: mime }));
            document.getElementById('image-host').dispatchEvent(
                new DragEvent('drop', { dataTransfer: transfer, bubbles: true, cancelable: true }));
        }""",
        [name, mime, base64.b64encode(data).decode()],
    )


def test_a_dropped_image_opens_and_a_dropped_non_image_shows_the_servers_message(page, tmp_path):
    from PIL import Image

    from shadeform.examples import load_example

    image, _ = load_example("synth:ellipsoid", size=64)
    png = tmp_path / "egg.png"
    Image.fromarray((image * 255).round().astype(np.uint8)).save(png)
    drop_file(page, "egg.png", "image/png", png.read_bytes())
    wait_for_result(page, 0, timeout=FIRST_RESULT_MS)
    assert page.evaluate("window.shadeform.state().image") | {"image_id": None} == {
        "image_id": None,
        "name": "egg.png",
        "width": 64,
        "height": 64,
        "channels": 1,
        "suggested": None,
    }

    drop_file(page, "notes.png", "image/png", b"not a picture")
    toast = page.locator("#toast")
    toast.wait_for(state="visible", timeout=RESULT_MS)
    assert "not an image" in toast.inner_text()
    # the open image and its model stay
    assert page.evaluate("window.shadeform.state().image.name") == "egg.png"


# ------------------------------------------------------------------------------- the mask tool


def mask_state(page) -> dict:
    return page.evaluate("window.shadeform.mask()")


def params_mask(page) -> np.ndarray | None:
    """The user's mask the client sends with every solve (params.mask), decoded."""
    from PIL import Image

    text = page.evaluate("window.shadeform.state().params.mask")
    if text is None:
        return None
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(text))).convert("L")) > 0


def shown_cells(page) -> np.ndarray:
    """(row, col) of every vertex of the mesh on screen."""
    positions = np.array(page.evaluate("window.shadeform.mesh().positions")).reshape(-1, 3)
    return np.column_stack([-positions[:, 1], positions[:, 0]]).round().astype(int)


def drag(page, points) -> None:
    """Press at the first image point (x, y), move through the others, release."""
    start = page.evaluate(f"window.shadeform.pagePoint({points[0][0]}, {points[0][1]})")
    page.mouse.move(start["x"], start["y"])
    page.mouse.down()
    for x, y in points[1:]:
        at = page.evaluate(f"window.shadeform.pagePoint({x}, {y})")
        page.mouse.move(at["x"], at["y"], steps=6)
    page.mouse.up()


SPHERE = "synth:sphere"  # 256 px, its true mask a disk of radius ~108 about (127.5, 127.5)


def test_mask_brush_polygon_invert_drive_the_solve(page):
    from shadeform.examples import load_example

    open_example(page, SPHERE)
    _, info = load_example(SPHERE)
    truth = info["mask"]
    # the mask a result was solved with is decoded in the mask worker beside the model's drawing:
    # it may show a frame after the model (0 pixels once, in a CI run under load)
    page.wait_for_function(f"window.shadeform.mask().pixels === {int(truth.sum())}", timeout=RESULT_MS)
    state = mask_state(page)
    assert state["user"] is False and state["pixels"] == truth.sum()
    full = page.evaluate("window.shadeform.lastResult().vertex_count")

    # K: the mask tool; erase a band across the sphere with a 12-pixel brush
    page.keyboard.press("k")
    page.click('#mask-op [data-mask-op="erase"]')
    page.fill("#mask-radius", "12")
    before = applied(page)
    drag(page, [(40, 128), (128, 128), (216, 128)])
    wait_for_result(page, before)
    mask = params_mask(page)
    assert mask is not None and mask_state(page)["user"] is True
    assert not mask[118:139, 40:217].any() and mask[60, 128] and mask[196, 128]
    assert not page.evaluate("window.shadeform.maskAt(128, 128)")
    # the solve used it: no vertex in the erased band, and fewer of them
    cells = shown_cells(page)
    band = (np.abs(cells[:, 0] - 128) <= 10) & (cells[:, 1] >= 45) & (cells[:, 1] <= 211)
    assert not band.any()
    assert page.evaluate("window.shadeform.lastResult().vertex_count") < 0.9 * full

    # a polygon in Add mode puts a square of the band back
    page.click('#mask-mode [data-mask-mode="polygon"]')
    page.click('#mask-op [data-mask-op="add"]')
    before = applied(page)
    for x, y in [(100, 110), (156, 110), (156, 146)]:
        click_image(page, x, y)
    click_image(page, 100, 146)
    page.keyboard.press("Enter")
    wait_for_result(page, before)
    mask = params_mask(page)
    assert mask[128, 128] and mask[111:146, 101:156].all() and not mask[128, 60]
    assert (np.abs(shown_cells(page) - [128, 128]).max(axis=1) <= 2).any()  # vertices there again

    # Invert swaps object and background; inverting again gives the same mask and model back
    edited, vertices = mask, page.evaluate("window.shadeform.lastResult().vertex_count")
    sent = page.evaluate("window.shadeform.requests()")
    page.click("#mask-invert")
    page.wait_for_function(f"window.shadeform.requests() > {sent}")
    np.testing.assert_array_equal(params_mask(page), ~edited)
    before = applied(page)
    page.click("#mask-invert")
    wait_for_result(page, before)
    np.testing.assert_array_equal(params_mask(page), edited)
    assert page.evaluate("window.shadeform.lastResult().vertex_count") == vertices

    # a dab of the eraser inside the object makes one more hole; Fill holes closes them all
    # (the band stops short of the rim: its two parts are holes too)
    page.click('#mask-mode [data-mask-mode="brush"]')
    page.click('#mask-op [data-mask-op="erase"]')
    before = applied(page)
    drag(page, [(128, 70), (129, 70)])
    wait_for_result(page, before)
    assert not params_mask(page)[70, 128]
    before = applied(page)
    page.click("#mask-fill")
    wait_for_result(page, before)
    np.testing.assert_array_equal(params_mask(page), truth)
    assert page.evaluate("window.shadeform.lastResult().vertex_count") == full

    # Automatic goes back to the example's own mask
    before = applied(page)
    page.click("#mask-auto")
    wait_for_result(page, before)
    assert page.evaluate("window.shadeform.state().params.mask") is None
    page.wait_for_function(f"window.shadeform.mask().pixels === {int(truth.sum())}", timeout=RESULT_MS)
    assert mask_state(page)["user"] is False and mask_state(page)["pixels"] == truth.sum()
    assert page.evaluate("window.shadeform.lastResult().vertex_count") == full


def test_mask_threshold_slider_outlines_live_and_solves_on_release(page):
    from shadeform.examples import load_example
    from shadeform.masks import threshold_object

    open_example(page, SPHERE)
    image, _ = load_example(SPHERE)
    page.click('#tools [data-tool="mask"]')
    before, sent = applied(page), page.evaluate("window.shadeform.requests()")
    # a drag: input events only; the outline follows, nothing is solved
    page.evaluate(
        """async () => {
            const slider = document.getElementById('mask-threshold');
            for (const value of [300, 400, 500, 600]) {
                slider.value = String(value);
                slider.dispatchEvent(new Event('input'));
                await new Promise((resolve) => setTimeout(resolve, 30));
            }
        }"""
    )
    expected = threshold_object(image, 0.36)  # position 600 of 1000 on the square-root scale
    page.wait_for_function(f"window.shadeform.mask().pixels === {int(expected.sum())}")
    assert page.evaluate("window.shadeform.requests()") == sent and applied(page) == before
    assert "release to use it" in mask_state(page)["note"]
    # the release: that mask is the user's, and solved
    page.evaluate(
        """() => {
            const slider = document.getElementById('mask-threshold');
            slider.value = '600';
            slider.dispatchEvent(new Event('change'));
        }"""
    )
    wait_for_result(page, before)
    np.testing.assert_array_equal(params_mask(page), expected)
    cells = shown_cells(page)
    assert expected[cells[:, 0], cells[:, 1]].all()  # every vertex on the thresholded disk
    assert mask_state(page)["note"].startswith("Your mask")


def test_mask_click_the_object(page, tmp_path):
    from PIL import Image

    # two lit spheres: the automatic mask takes the larger; a click takes the other
    rows, cols = np.mgrid[0:100, 0:220]
    image = np.zeros((100, 220))
    for (row, col), radius in (((50, 55), 35), ((50, 160), 45)):
        distance = np.hypot(rows - row, cols - col)
        image += np.sqrt(np.clip(1 - (distance / radius) ** 2, 0, 1))
    png = tmp_path / "two.png"
    Image.fromarray(np.rint(image * 65535).astype(np.uint16)).save(png)  # 16-bit: linear
    before = applied(page)
    page.set_input_files("#file-image", str(png))
    wait_for_result(page, before, timeout=FIRST_RESULT_MS)
    assert page.evaluate("window.shadeform.maskAt(50, 160)") and not page.evaluate(
        "window.shadeform.maskAt(50, 55)"
    )

    page.keyboard.press("k")
    page.click('#mask-mode [data-mask-mode="object"]')
    before = applied(page)
    click_image(page, 55, 50)
    wait_for_result(page, before)
    mask = params_mask(page)
    left = np.hypot(rows - 50, cols - 55) < 34
    assert mask[left].all() and not mask[:, 110:].any()
    assert mask_state(page)["clicks"] == {"inside": 1, "outside": 0}
    assert (shown_cells(page)[:, 1] < 100).all()  # the model is the left sphere

    # Esc forgets the clicks; an "object" click on the black background is refused, and the
    # message stays; the mask and the model stay too
    page.keyboard.press("Escape")
    assert mask_state(page)["clicks"] == {"inside": 0, "outside": 0}
    click_image(page, 108, 5)
    page.wait_for_function("window.shadeform.mask().error !== null")
    assert "look like the background" in mask_state(page)["error"]
    page.wait_for_timeout(7500)  # longer than a toast lasts
    assert page.locator("#mask-error").is_visible()
    assert mask_state(page)["clicks"] == {"inside": 0, "outside": 0}  # the failed click is taken back
    np.testing.assert_array_equal(params_mask(page), mask)


def test_mask_box_round_the_object(page, tmp_path):
    from PIL import Image

    # a grey disk on a warm wood-like stripe pattern: a box round it finds the disk inside, on its
    # colours (the stripes are as bright as the disk's edge)
    rows, cols = np.mgrid[0:120, 0:200]
    stripes = 0.5 + 0.2 * np.sin(cols / 3.0)
    image = np.stack([stripes * 0.9, stripes * 0.5, stripes * 0.2], axis=-1)
    disk = np.hypot(rows - 60, cols - 100) < 35
    shade = np.sqrt(np.clip(1 - (np.hypot(rows - 60, cols - 100) / 35) ** 2, 0, 1))
    image[disk] = (0.25 + 0.6 * shade[disk])[:, None] * np.array([0.6, 0.7, 0.9])
    png = tmp_path / "disk-on-stripes.png"
    Image.fromarray(np.rint(np.clip(image, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)).save(png)
    before = applied(page)
    page.set_input_files("#file-image", str(png))
    wait_for_result(page, before, timeout=FIRST_RESULT_MS)

    page.keyboard.press("k")
    page.click('#mask-mode [data-mask-mode="box"]')
    assert mask_state(page)["mode"] == "box"
    before = applied(page)
    start = page.evaluate("window.shadeform.pagePoint(55, 15)")
    end = page.evaluate("window.shadeform.pagePoint(145, 105)")
    page.mouse.move(start["x"], start["y"])
    page.mouse.down()
    page.mouse.move((start["x"] + end["x"]) / 2, (start["y"] + end["y"]) / 2, steps=4)
    page.mouse.move(end["x"], end["y"], steps=4)
    page.screenshot(path=str(tmp_path / "box-drag.png"))
    page.mouse.up()
    wait_for_result(page, before)
    mask = params_mask(page)
    union = (mask | disk).sum()
    assert (mask & disk).sum() / union >= 0.9
    assert not mask[:, :50].any() and not mask[:, 150:].any()  # nothing outside the box
    assert "box" in mask_state(page)["note"]

    # a box too small to hold anything is refused in words, and the mask stays
    start = page.evaluate("window.shadeform.pagePoint(10, 10)")
    page.mouse.move(start["x"], start["y"])
    page.mouse.down()
    page.mouse.up()
    page.wait_for_function("window.shadeform.mask().error !== null")
    assert "drag a box round the object" in mask_state(page)["error"]
    np.testing.assert_array_equal(params_mask(page), mask)


def test_mask_save_load_and_reload(page, tmp_path):
    from PIL import Image

    from shadeform import load_mask
    from shadeform.examples import load_example

    open_example(page, SPHERE)
    _, info = load_example(SPHERE)
    page.click('#tools [data-tool="mask"]')
    with page.expect_download(timeout=RESULT_MS) as started:
        page.click("#mask-save")
    saved = tmp_path / started.value.suggested_filename
    started.value.save_as(saved)
    assert saved.name == "synth_sphere.mask.png"
    np.testing.assert_array_equal(load_mask(saved), info["mask"])  # what the CLI's --mask reads

    # Clear empties the mask to paint on; nothing is solved until the next edit
    sent = page.evaluate("window.shadeform.requests()")
    page.click("#mask-clear")
    assert mask_state(page)["pixels"] == 0 and mask_state(page)["user"] is True
    assert page.evaluate("window.shadeform.state().params.mask") is None
    assert page.evaluate("window.shadeform.requests()") == sent
    # the model on screen was solved with the mask that is gone: out of date, not exportable
    state = page.evaluate("window.shadeform.modelState()")
    assert state["status"] == "stale" and "mask was cleared" in state["message"]
    assert page.is_disabled("#export-button")

    # load the right half of it: the solve follows
    half = info["mask"].copy()
    half[:, :128] = False
    half_file = tmp_path / "half.png"
    Image.fromarray(np.where(half, 255, 0).astype(np.uint8)).save(half_file)
    before = applied(page)
    page.set_input_files("#file-mask", str(half_file))
    wait_for_result(page, before)
    np.testing.assert_array_equal(params_mask(page), half)
    assert (shown_cells(page)[:, 1] >= 128).all()
    assert "half.png" in mask_state(page)["note"]

    # a mask of another size is refused with a message that stays; the model stays
    small = tmp_path / "small.png"
    Image.fromarray(np.full((10, 12), 255, dtype=np.uint8)).save(small)
    page.set_input_files("#file-mask", str(small))
    page.wait_for_function("window.shadeform.mask().error !== null")
    assert "mask is 12x10 but the image is 256x256" in mask_state(page)["error"]
    np.testing.assert_array_equal(params_mask(page), half)

    # a reload keeps the user's mask (and solves with it)
    page.wait_for_function("window.shadeform.sessionSaved()", timeout=RESULT_MS)
    page.reload()
    page.evaluate("window.shadeform.ready")
    wait_for_result(page, 0)
    np.testing.assert_array_equal(params_mask(page), half)
    page.wait_for_function(f"window.shadeform.mask().pixels === {int(half.sum())}")
    assert mask_state(page)["user"] is True
    assert (shown_cells(page)[:, 1] >= 128).all()


def test_unsure_areas_are_outlined_and_one_click_marks_them_concave(page):
    # the vase lit from (5, 5, 7): slant 45 deg, tilt 45 deg; its neck could be a bump or a dent
    open_example(page, "synth:vase")
    page.click("#light-mode [data-mode=slant_tilt]")
    for slider in ("#slant", "#tilt"):
        before = applied(page)
        page.fill(slider, "45")
        wait_for_result(page, before)
    assert page.evaluate("window.shadeform.state().params.light") == {
        "mode": "slant_tilt",
        "slant": 45,
        "tilt": 45,
    }
    # (0.5, 0.5, 0.71): (5, 5, 7) normalised to within the sliders' whole degrees
    np.testing.assert_allclose(
        page.evaluate("window.shadeform.lastResult().light"), np.array([5, 5, 7]) / math.sqrt(99), atol=5e-3
    )

    # the result's unsure areas, largest first, are outlined on the image and offered in the panel
    shown = page.evaluate("window.shadeform.unsure()")
    assert shown and shown == page.evaluate("window.shadeform.lastResult().info.unsure")
    neck = shown[0]
    assert neck["axis"] == "y"
    assert abs(neck["centre"][0] - 128) < 20 and neck["centre"][1] < 110  # the vase's upper part
    note = page.locator("#unsure .unsure-note")
    count = len(shown)
    assert note.inner_text() == f"Unsure: {count} area{'' if count == 1 else 's'} the shading cannot settle"
    buttons = page.locator("#unsure li button")
    assert buttons.count() == count
    mark = buttons.first
    assert mark.inner_text() == "Mark concave (y)" and mark.is_enabled()
    # numbered as on the image (the tag there is "?1"): the list says what each one asks
    assert page.locator("#unsure li .what").first.inner_text() == "?1 Concave along y?"
    assert page.get_by_role("button", name="Mark concave (y)").first.is_visible()
    note.scroll_into_view_if_needed()
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "unsure.png"))
    depth_before = page.evaluate("window.shadeform.lastResult().depth_range")
    status_before = page.inner_text("#mesh-info")

    # one click: the area becomes a concave region along y, and the model is solved again
    before = applied(page)
    mark.click()
    wait_for_result(page, before)
    regions = page.evaluate("window.shadeform.state().params.concave.regions")
    assert len(regions) == 1 and regions[0]["axis"] == "y"
    np.testing.assert_allclose(regions[0]["polygon"], neck["polygon"])
    assert page.locator("#regions-list li").count() == 1
    assert page.inner_text("#regions-list li .meta").startswith("y")
    # the neck now curves the other way: the depth range and the status bar follow
    assert page.evaluate("window.shadeform.lastResult().depth_range") != depth_before
    assert page.inner_text("#mesh-info") != status_before
    # the outlines are the new result's; an area still reported with that outline cannot be added twice
    after = page.evaluate("window.shadeform.unsure()")
    assert after == page.evaluate("window.shadeform.lastResult().info.unsure")
    assert page.locator("#unsure li").count() == len(after)
    assert page.locator("#unsure").is_hidden() == (not after)
    for i, area in enumerate(after):
        marked = area["axis"] == "y" and area["polygon"] == neck["polygon"]
        assert page.locator("#unsure li button").nth(i).is_enabled() == (not marked)
    page.screenshot(path=str(ARTIFACTS / "unsure-marked.png"))


# --------------------------------------------------------------------- photo sets


def srgb8(linear: float) -> float:
    linear = min(max(linear, 0.0), 1.0)
    encoded = 12.92 * linear if linear <= 0.0031308 else 1.055 * linear ** (1 / 2.4) - 0.055
    return 255 * encoded


def stereo(page, what: str):
    return page.evaluate(f"window.shadeform.stereo.{what}")


def wait_for_stereo(page, after: int) -> None:
    page.wait_for_function(
        f"window.shadeform.stereo.applied() > {after} || window.shadeform.stereo.error() !== null",
        timeout=FIRST_RESULT_MS,
    )
    assert stereo(page, "error()") is None, stereo(page, "error()")


def relit_matches_the_maps(page, row: int, col: int) -> None:
    """The pane's pixel is the albedo times the cosine to the user's light, sRGB-encoded."""
    maps = stereo(page, f"mapsAt({row}, {col})")
    light = np.array(stereo(page, "light()"))
    shade = max(0.0, float(np.dot(maps["normal"], light)))
    expected = [srgb8(a * shade) for a in maps["albedo"]]
    np.testing.assert_allclose(stereo(page, f"shownAt({row}, {col})"), expected, atol=2.5)


def test_photo_set_relights_live_under_a_dragged_light_and_exports(page, tmp_path):
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-photo-set="stereo:vase"]')
    wait_for_stereo(page, 0)
    assert page.evaluate("document.body.classList.contains('stereo-mode')")
    assert page.is_visible("#stereo-group") and not page.is_visible("#mask-group")
    assert stereo(page, "info().count") == 12 and "12 lights from the light file" in stereo(page, "note()")
    # the pane starts relit, and its button says so
    assert page.eval_on_selector_all("#stereo-show button.on", "(bs) => bs.map((b) => b.dataset.show)") == [
        "relight"
    ]
    result = stereo(page, "lastResult()")
    assert len(shown_mesh(page).vertices) == result["vertex_count"]
    # the vase's left and right flanks at mid height; the light the pane starts with
    row = 150
    on = [col for col in range(256) if stereo(page, f"mapsAt({row}, {col})")]
    left, right = on[3], on[-4]
    page.wait_for_timeout(100)  # one animation frame
    for col in (left, right, (left + right) // 2):
        relit_matches_the_maps(page, row, col)
    # drag the light far to the left over the image: the left flank lights up, the right goes dark
    start = stereo(page, f"pagePoint({row}, {(left + right) // 2})")
    end = stereo(page, f"pagePoint({row}, 0)")
    page.mouse.move(start["x"], start["y"])
    page.mouse.down()
    page.mouse.move(end["x"], end["y"], steps=5)
    page.mouse.up()
    page.wait_for_timeout(100)
    light = stereo(page, "light()")
    assert light[0] < -0.9 and abs(light[1]) < 0.3 and light[2] > 0
    for col in (left, right):
        relit_matches_the_maps(page, row, col)
    assert (
        sum(stereo(page, f"shownAt({row}, {left})")) > 3 * 100 > sum(stereo(page, f"shownAt({row}, {right})"))
    )
    # the normals view shows (n + 1) / 2
    page.click('#stereo-show [data-show="normals"]')
    page.wait_for_timeout(100)
    normal = np.array(stereo(page, f"mapsAt({row}, {left})")["normal"])
    np.testing.assert_allclose(stereo(page, f"shownAt({row}, {left})"), (normal + 1) / 2 * 255, atol=1.5)
    # the photos themselves: photo 4's light is the fourth of the set
    page.click('#stereo-show [data-show="photo"]')
    page.wait_for_function("document.getElementById('stereo-photo-out').textContent === '1 / 12'")
    ARTIFACTS.mkdir(exist_ok=True)
    page.click('#stereo-show [data-show="relight"]')
    page.screenshot(path=str(ARTIFACTS / "app-photo-set.png"))
    # export: the mesh on screen, as a file
    path = download(page, '#export-menu [data-format=".obj"]', "#export-menu", tmp_path)
    assert path.name == "stereo_vase.obj"
    vertices = sum(1 for line in path.read_text().splitlines() if line.startswith("v "))
    assert vertices == result["vertex_count"]


def test_a_whole_folder_opens_as_its_filenames_txt_lists_it(page, tmp_path):
    """A whole MIT-Berkeley-style folder selected at once: filenames.txt names the photos (the
    folder's other pictures, of other bit depths and sizes, are not photos), light_directions.txt
    is the light file among other text files, and its strengths carry comments after the numbers."""
    from PIL import Image

    from shadeform import synth
    from shadeform.light import light_from_slant_tilt

    scene = synth.scene("sphere", size=96)
    lights = np.array([light_from_slant_tilt(30, t) for t in range(0, 360, 60)])
    names = [f"light{i + 1:02d}.png" for i in range(len(lights))][::-1]  # listed in reverse
    for name, light in zip(names, lights, strict=True):
        image = synth.render(scene.normals, scene.mask, light=light, albedo=0.8)
        Image.fromarray(np.rint(image * 65535).astype(np.uint16)).save(tmp_path / name)
    Image.fromarray(np.full((40, 50), 255, np.uint8)).save(tmp_path / "original.png")  # not a photo
    Image.fromarray(np.zeros((96, 96), bool)).save(tmp_path / "depth_valid.png")  # 1-bit, not a photo
    (tmp_path / "filenames.txt").write_text("\n".join(names) + "\n")
    (tmp_path / "light_directions.txt").write_text(
        "\n".join(" ".join(f"{v:.8f}" for v in row) for row in lights)
    )
    (tmp_path / "light_intensities.txt").write_text("# strength\n" + "1.0  # residual 0.1\n" * len(lights))
    (tmp_path / "shading_light.txt").write_text("0 0 1\n")  # another text file: not the lights
    page.set_input_files("#file-photos", sorted(str(p) for p in tmp_path.iterdir()))
    wait_for_stereo(page, 0)
    result = stereo(page, "lastResult()")
    np.testing.assert_allclose(result["lights"], lights, atol=1e-6)  # each photo with its own light
    normal = np.array(stereo(page, "mapsAt(48, 48)")["normal"])
    assert np.degrees(np.arccos(min(1.0, normal[2]))) < 2


def test_photos_opened_with_their_light_file_and_errors_that_stay(page, tmp_path):
    from PIL import Image

    from shadeform import synth
    from shadeform.light import light_from_slant_tilt

    scene = synth.scene("sphere", size=96)
    lights = np.array([light_from_slant_tilt(30, t) for t in range(0, 360, 60)])
    files = []
    for i, light in enumerate(lights):
        image = synth.render(scene.normals, scene.mask, light=light, albedo=0.8)
        files.append(tmp_path / f"shot{i + 1}.png")
        Image.fromarray(np.rint(image * 65535).astype(np.uint16)).save(files[-1])
    light_file = tmp_path / "lights.txt"
    light_file.write_text("\n".join(" ".join(f"{v:.8f}" for v in row) for row in lights))
    # too few photos: said at once, nothing sent
    page.set_input_files("#file-photos", [str(p) for p in files[:2]])
    page.wait_for_selector("#toast:not([hidden])")
    assert "at least 3 photos" in page.inner_text("#toast")
    page.set_input_files("#file-photos", [str(p) for p in files] + [str(light_file)])
    wait_for_stereo(page, 0)
    result = stereo(page, "lastResult()")
    np.testing.assert_allclose(result["lights"], lights, atol=1e-6)
    normal = np.array(stereo(page, "mapsAt(48, 48)")["normal"])
    assert np.degrees(np.arccos(min(1.0, normal[2]))) < 2  # the sphere's centre faces the camera
    # the same photos without the light file: unknown lights; asking for the file says why not,
    # and the message stays
    page.set_input_files("#file-photos", [str(p) for p in files])
    wait_for_stereo(page, 1)
    assert stereo(page, "params().lights") == "unknown"
    page.click('#stereo-lights [data-lights="file"]')
    page.wait_for_timeout(300)
    assert "without a light file" in stereo(page, "error()")
    assert page.get_attribute("#stereo-error", "role") == "alert" and page.is_visible("#stereo-error")
    # one photo again: back to the one-photo app, the photo-set panel gone
    page.set_input_files("#file-image", str(files[0]))
    page.wait_for_function("window.shadeform.state().image !== null", timeout=RESULT_MS)
    assert not page.evaluate("document.body.classList.contains('stereo-mode')")
    assert page.is_visible("#mask-group") and not page.is_visible("#stereo-group")


def test_a_reload_shows_the_photo_set_again_with_its_settings(page, server):
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-photo-set="stereo:vase"]')
    wait_for_stereo(page, 0)
    # a reload at once after a change: the change is stored as the page goes, not lost
    page.select_option("#stereo-model", "robust")
    assert not page.evaluate("window.shadeform.sessionSaved()")
    page.reload()
    page.evaluate("window.shadeform.ready")
    wait_for_stereo(page, 0)
    assert stereo(page, "params().model") == "robust"
    assert stereo(page, "lastResult().info.solver") == "photometric stereo (robust)"
    assert stereo(page, "lastResult().info.model") == "robust"
    assert page.input_value("#stereo-model") == "robust"
    # a session saved before the photometric model's rename holds it as "method": read as the model
    page.wait_for_function("window.shadeform.sessionSaved()", timeout=RESULT_MS)
    page.evaluate(
        """() => {
        const session = JSON.parse(localStorage.getItem('shadeform.session.v1'));
        session.photoSet.params.method = session.photoSet.params.model;
        delete session.photoSet.params.model;
        localStorage.setItem('shadeform.session.v1', JSON.stringify(session));
    }"""
    )
    page.reload()
    page.evaluate("window.shadeform.ready")
    wait_for_stereo(page, 0)
    assert stereo(page, "params().model") == "robust" and "method" not in stereo(page, "params()")
    assert stereo(page, "lastResult().info.model") == "robust"
    assert page.input_value("#stereo-model") == "robust"
    # a server that forgot the set: the page says so, and stays usable. The reopened set's own
    # save is waited for: it would otherwise store the real id over the edited one
    page.wait_for_function("window.shadeform.sessionSaved()", timeout=RESULT_MS)
    page.evaluate(
        """() => {
        const session = JSON.parse(localStorage.getItem('shadeform.session.v1'));
        session.photoSet.info.photoset_id = 'forgotten';
        localStorage.setItem('shadeform.session.v1', JSON.stringify(session));
    }"""
    )
    page.reload()
    page.evaluate("window.shadeform.ready")
    page.wait_for_function("window.shadeform.stereo.error() !== null", timeout=RESULT_MS)
    assert "open them again" in stereo(page, "error()")
