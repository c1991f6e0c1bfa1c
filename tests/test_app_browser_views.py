"""End-to-end tests of the app's Views panel in a real browser: photos of one object from several
sides, each reconstructed with its own settings, fused into one closed model on the server.

The server, the browser and a fresh page per test are those of
``tests/helpers/browser.py``: the real server under uvicorn on a free loopback port serving the
built client, Debian's Chromium driven by Playwright with clicks and keys. Facts are read from
the page's test hook ``window.shadeform.views`` (the views, the newest fused result, what the 3D
view draws) and from the file the export menu downloads. A screenshot of the panel is kept in
``tests/artifacts/app-views.png``.
"""

from __future__ import annotations

import numpy as np
from PIL import Image

from helpers import browser as ui
from helpers.browser import ARTIFACTS, FIRST_RESULT_MS, RESULT_MS, download
from helpers.photosets import write_photo_set
from shadeform import synth
from shadeform.examples import load_view_set_example

# the real server, Chromium and a fresh page per test: the fixtures of tests/helpers/browser.py
server, browser, page = ui.server, ui.browser, ui.page

SET = "views:lumpy"


def views(page, what: str):
    return page.evaluate(f"window.shadeform.views.{what}")


def wait_for_views(page, after: int, timeout=FIRST_RESULT_MS) -> None:
    """Wait until a fused model newer than the ``after``-th is drawn (or an error is shown)."""
    page.wait_for_function(
        f"window.shadeform.views.applied() > {after} || window.shadeform.views.error() !== null",
        timeout=timeout,
    )
    assert views(page, "error()") is None, views(page, "error()")


def open_view_set(page) -> dict:
    page.click("#examples-menu > button")
    page.click(f'#examples-menu [data-view-set="{SET}"]')
    wait_for_views(page, 0)
    return views(page, "lastResult()")


def wait_for_single_result(page, after: int) -> None:
    page.wait_for_function(
        f"window.shadeform.applied() > {after} && !window.shadeform.state().busy", timeout=FIRST_RESULT_MS
    )


def test_example_view_set_is_fused_with_its_partial_models_and_exports(page, tmp_path):
    result = open_view_set(page)
    assert page.evaluate("document.body.classList.contains('views-mode')")
    assert page.is_visible("#views-group") and not page.is_visible("#mask-group")
    assert page.locator("#views-list .view-card").count() == 4
    assert [view["angle"] for view in views(page, "views()")] == [0, 90, 180, 270]
    assert page.input_value('#views-list [data-index="1"] input') == "90"
    # the fused model on screen is the server's, closed; each partial model drawn with it
    assert result["watertight"] and len(result["part_vertex_counts"]) == 4
    assert views(page, "rival()") is None and not page.is_visible("#views-rival")  # the photos decide
    assert views(page, "shownVertexCount()") == result["vertex_count"]
    assert len(page.evaluate("window.shadeform.mesh().positions")) == 3 * result["vertex_count"]
    assert views(page, "partsShown()") == 4
    page.click("#parts-toggle")
    assert views(page, "partsShown()") == 0 and views(page, "shownVertexCount()") == result["vertex_count"]
    page.click("#parts-toggle")
    assert views(page, "partsShown()") == 4
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "app-views.png"))
    # export: the fused model, as a file
    path = download(page, '#export-menu [data-format=".obj"]', "#export-menu", tmp_path)
    assert path.name == "lumpy_0-fused.obj"
    vertices = sum(1 for line in path.read_text().splitlines() if line.startswith("v "))
    assert vertices == result["vertex_count"]


def test_editing_a_views_mask_updates_the_fused_model(page, tmp_path):
    before = open_view_set(page)
    second = views(page, "views()")[1]
    page.click('#views-list [data-index="1"] [data-act="edit"]')
    wait_for_single_result(page, 0)
    # single-photo mode on the view's photo, with its settings, saying which view it edits
    assert not page.evaluate("document.body.classList.contains('views-mode')")
    assert page.evaluate("window.shadeform.state().image.image_id") == second["image_id"]
    assert page.is_visible("#view-editing") and "view 2" in page.inner_text("#view-editing")
    assert views(page, "editing()") == 1
    # a mask without the object's top (the mask tool's Load…)
    _, masks, _, _ = load_view_set_example(SET)
    rows = np.arange(256)[:, None]
    Image.fromarray(np.where(masks[1] & (rows >= 110), 255, 0).astype(np.uint8)).save(tmp_path / "cut.png")
    solved = page.evaluate("window.shadeform.applied()")
    page.set_input_files("#file-mask", str(tmp_path / "cut.png"))
    wait_for_single_result(page, solved)
    assert page.evaluate("window.shadeform.mask().user")
    # back in the Views panel: the view kept its mask, and the fused model follows it
    applied = views(page, "applied()")
    page.click("#view-back")
    wait_for_views(page, applied, timeout=RESULT_MS)
    after = views(page, "lastResult()")
    assert views(page, "editing()") is None and views(page, "views()")[1]["params"]["mask"]
    assert after["volume"] < 0.8 * before["volume"] and after["watertight"]
    assert views(page, "shownVertexCount()") == after["vertex_count"] != before["vertex_count"]
    assert "your mask" in page.inner_text('#views-list [data-index="1"] .settings')
    assert "automatic mask" in page.inner_text('#views-list [data-index="0"] .settings')


def test_view_photos_a_bad_angle_that_stays_and_a_reload(page, tmp_path):
    files = []
    for view in synth.render_views("lumpy", (0, 90, 180, 270), size=96):
        files.append(tmp_path / f"lumpy-{view.angle:03.0f}.png")
        Image.fromarray(np.rint(view.image * 65535).astype(np.uint16)).save(files[-1])
    # one photo is not a set: said at once, nothing sent
    page.set_input_files("#file-views", str(files[0]))
    page.wait_for_selector("#toast:not([hidden])")
    assert "at least two sides" in page.inner_text("#toast")
    page.set_input_files("#file-views", [str(p) for p in files])
    wait_for_views(page, 0)
    shown = views(page, "views()")
    assert [view["name"] for view in shown] == [p.name for p in files]
    assert [view["angle"] for view in shown] == [0, 90, 180, 270]  # evenly spaced
    assert views(page, "lastResult().watertight")
    # a bad angle: said in the panel, and the message stays
    page.fill('#views-list [data-index="1"] input', "ninety")
    page.press('#views-list [data-index="1"] input', "Enter")
    page.wait_for_function("window.shadeform.views.error() !== null")
    assert '"ninety" is not an angle' in views(page, "error()")
    assert page.get_attribute("#views-error", "role") == "alert"
    page.wait_for_timeout(1500)
    assert page.is_visible("#views-error") and views(page, "views()")[1]["angle"] == 90
    # a good one: fused again, the message gone
    applied = views(page, "applied()")
    page.fill('#views-list [data-index="1"] input', "95")
    page.press('#views-list [data-index="1"] input', "Enter")
    page.wait_for_function(f"window.shadeform.views.applied() > {applied}", timeout=RESULT_MS)
    assert not page.is_visible("#views-error")
    page.wait_for_function("window.shadeform.sessionSaved()", timeout=RESULT_MS)
    # a reload shows the views again, fused
    page.reload()
    page.evaluate("window.shadeform.ready")
    wait_for_views(page, 0)
    assert views(page, "open()") and [view["angle"] for view in views(page, "views()")] == [0, 95, 180, 270]
    assert page.input_value('#views-list [data-index="1"] input') == "95"
    # a server that forgot an uploaded view's photo: the page says which, and stays usable
    page.wait_for_function("window.shadeform.sessionSaved()", timeout=RESULT_MS)  # the reload's own save
    assert page.is_checked("#views-refine-poses")
    # (and saved before the rename: the poses' refinement as "refine", here off)
    page.evaluate(
        """() => {
        const session = JSON.parse(localStorage.getItem('shadeform.session.v1'));
        session.views.views[2].image.image_id = 'forgotten';
        delete session.views.refine_poses;
        session.views.refine = false;
        localStorage.setItem('shadeform.session.v1', JSON.stringify(session));
    }"""
    )
    page.reload()
    page.evaluate("window.shadeform.ready")
    page.wait_for_function("window.shadeform.views.error() !== null", timeout=RESULT_MS)
    assert "no longer has view 3's photo" in views(page, "error()")
    assert not page.is_checked("#views-refine-poses")


def test_the_open_photo_is_added_as_a_view_with_its_settings(page):
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-example="synth:sphere"]')
    wait_for_single_result(page, 0)
    page.click('#light-mode [data-mode="estimate"]')
    wait_for_single_result(page, 1)
    page.click("#add-view")
    assert "Added as view 1 at 0°" in page.inner_text("#toast")
    assert page.inner_text("#views-count") == "1"
    added = views(page, "views()")
    assert added[0]["params"] == page.evaluate("window.shadeform.state().params")
    assert added[0]["params"]["light"]["mode"] == "estimate"
    # one view is not enough to fuse: the panel says so and asks the server nothing
    page.click("#open-views")
    assert views(page, "open()") and "at least two views" in views(page, "note()")
    assert views(page, "applied()") == 0 and views(page, "error()") is None
    assert "light estimated" in page.inner_text('#views-list [data-index="0"] .settings')


def test_views_from_opposite_sides_only_say_the_depth_is_a_guess(page, tmp_path):
    """Two photos, front and back (evenly spaced: 0 and 180 degrees): the panel says the views
    cannot tell the object's depth; turning one to the side fixes it and the note goes."""
    files = []
    for view in synth.render_views("lumpy", (0, 180), size=96):
        files.append(tmp_path / f"lumpy-{view.angle:03.0f}.png")
        Image.fromarray(np.rint(view.image * 65535).astype(np.uint16)).save(files[-1])
    page.set_input_files("#file-views", [str(p) for p in files])
    wait_for_views(page, 0)
    assert [view["angle"] for view in views(page, "views()")] == [0, 180]
    assert views(page, "lastResult().depth_fixed") is False
    assert "cannot tell how deep the object is" in views(page, "rival()")
    applied = views(page, "applied()")
    page.fill('#views-list [data-index="1"] input', "90")
    page.press('#views-list [data-index="1"] input', "Enter")
    page.wait_for_function(f"window.shadeform.views.applied() > {applied}", timeout=RESULT_MS)
    assert views(page, "lastResult().depth_fixed") is True and views(page, "rival()") is None


def test_photo_sets_added_as_views_are_fused_and_kept_by_a_reload(page, tmp_path):
    """Two sides of the waisted object, each a photo set under six lights: each opened in the
    photo-set mode and added with Add this set as a view; the Views panel shows them as set
    cards (first photo, "set · 6 photos", no Edit) and fuses them into a closed model that keeps
    both outlines; a reload keeps them as sets."""
    for i, view in enumerate(synth.render_views("waisted", (0, 90), size=96)):
        folder = tmp_path / f"view{i}"
        photos = write_photo_set(folder, np.nan_to_num(view.normals), view.mask)
        solved = page.evaluate("window.shadeform.stereo.applied()")
        page.set_input_files(
            "#file-photos", [str(p) for p in photos] + [str(folder / "light_directions.txt")]
        )
        page.wait_for_function(
            f"window.shadeform.stereo.applied() > {solved} || window.shadeform.stereo.error() !== null",
            timeout=FIRST_RESULT_MS,
        )
        assert page.evaluate("window.shadeform.stereo.error()") is None
        page.click("#add-set-view")
        assert f"Added as view {i + 1} at {90 * i}°" in page.inner_text("#toast")
    page.click("#open-views")
    wait_for_views(page, 0)
    shown = views(page, "views()")
    assert [view["angle"] for view in shown] == [0, 90] and all(view["photo_set_id"] for view in shown)
    result = views(page, "lastResult()")
    assert result["watertight"] and min(result["outline_iou"]) >= 0.95, result["outline_iou"]
    assert result["settled"] == [0, 0] and len(result["part_vertex_counts"]) == 2
    for index in (0, 1):
        card = f'#views-list [data-index="{index}"]'
        assert page.inner_text(f"{card} .set-badge") == "set · 6 photos"
        assert not page.is_visible(f'{card} [data-act="edit"]')  # nothing to draw on a set
        assert "photometric stereo" in page.inner_text(f"{card} .settings")
        assert page.get_attribute(f"{card} img", "src").endswith("/photos/0.png")
    ARTIFACTS.mkdir(exist_ok=True)
    page.evaluate("window.shadeform.rendered()")  # the worker's frame, not the one before the model
    page.screenshot(path=str(ARTIFACTS / "app-views-sets.png"))
    # a reload: the same sets as views, fused again from the server's kept solves
    page.wait_for_function("window.shadeform.sessionSaved()", timeout=RESULT_MS)
    page.reload()
    page.evaluate("window.shadeform.ready")
    wait_for_views(page, 0)
    assert [view["photo_set_id"] for view in views(page, "views()")] == [
        view["photo_set_id"] for view in shown
    ]
    assert page.inner_text('#views-list [data-index="1"] .set-badge') == "set · 6 photos"
    assert views(page, "lastResult().cached") == [True, True]
