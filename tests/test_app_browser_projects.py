"""Projects kept by the server outlive a server restart and a browser without storage (issue 14,
point 4), in a real browser.

The browser and a fresh page per test are those of ``tests/helpers/browser.py``; the server is
its restartable one (``RestartableServer``, the ``app_server`` fixture), with a sessions file.
The page autosaves its work (a second after the last change); the server is then stopped and
started again as a new ``create_app`` with the same file, and a new browser profile (empty
storage: another browser, or storage cleared) is offered the newest project and reopens it from
Project ▸ Open recent…, its image from the server's session store (nothing sent again), its
parameters and regions as they were.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import browser as ui
from helpers.browser import (
    ARTIFACTS,
    FIRST_RESULT_MS,
    RESULT_MS,
    click_image,
    open_example,
    record_requests,
    toast_texts,
    wait_for_result,
)

# Chromium and a fresh page per test: the fixtures of tests/helpers/browser.py (the page opens
# ``server``, which is this module's)
browser, page = ui.browser, ui.page

#: The autosave waits 1 s after the last change; a save takes milliseconds.
SAVED_MS = 10_000


@pytest.fixture
def server(app_server):
    """The address the ``page`` fixture opens (``app_server``: tests/conftest.py)."""
    return app_server.url


def saves(page) -> int:
    """How many saves the server has taken from this page."""
    return page.evaluate("window.shadeform.projects().saves")


def wait_for_autosave(page, since: int | None = None) -> dict:
    """Wait until the server took a save after ``since`` saves (default: now) and none is due; the
    autosave's state. Count before a change whose save may be taken while its result is awaited."""
    taken = saves(page) if since is None else since
    page.wait_for_function(
        f"(() => {{ const p = window.shadeform.projects(); return p.saves > {taken} && !p.pending; }})()",
        timeout=SAVED_MS,
    )
    return page.evaluate("window.shadeform.projects()")


def new_profile(browser, url: str):
    """A new browser profile (empty storage) on the app's page; (context, page, errors)."""
    context = browser.new_context(viewport={"width": 1440, "height": 860})
    other = context.new_page()
    errors: list[str] = []
    other.on("pageerror", lambda error: errors.append(str(error)))
    other.goto(url)
    other.evaluate("window.shadeform.ready")
    return context, other, errors


def test_a_project_outlives_a_restart_and_an_empty_browser_and_reopens_from_open_recent(
    page, browser, app_server, tmp_path
):
    from PIL import Image

    from shadeform.app.server import create_app
    from shadeform.examples import load_example

    # an example first (one project), then an upload (another): the upload's bytes are only in
    # this profile's storage and the server's session store
    open_example(page, "synth:sphere")
    image, _ = load_example("synth:bowl", size=128)
    png = tmp_path / "my bowl.png"
    Image.fromarray((image * 255).round().astype(np.uint8)).save(png)
    before = page.evaluate("window.shadeform.applied()")
    page.set_input_files("#file-image", str(png))
    wait_for_result(page, before, timeout=FIRST_RESULT_MS)

    # change the parameters and draw a concave region
    before = page.evaluate("window.shadeform.applied()")
    page.select_option("#filter-kind", "gaussian")
    wait_for_result(page, before)
    before = page.evaluate("window.shadeform.applied()")
    page.click('#tools [data-tool="polygon"]')
    page.click('#axis [data-axis="both"]')
    for x, y in [(30, 30), (100, 30), (100, 100), (30, 100)]:
        click_image(page, x, y)
    page.keyboard.press("Enter")
    wait_for_result(page, before)
    saved = page.evaluate("window.shadeform.state()")
    assert len(saved["params"]["concave"]["regions"]) == 1
    autosave = wait_for_autosave(page, 0)  # the first save: whenever it came
    assert autosave["error"] is None and not autosave["off"]
    project_id = autosave["ids"]["photo"]
    assert project_id

    # the server restarted with the same sessions file
    app_server.stop()
    app_server.start(lambda: create_app(sessions=tmp_path / "s.sqlite3"))

    # another browser profile: nothing in its storage
    context, other, errors = new_profile(browser, app_server.url)
    try:
        log = record_requests(other)
        # offered, not forced: the empty page names the newest project, nothing is opened
        other.wait_for_selector("#resume", state="visible", timeout=RESULT_MS)
        assert other.text_content("#resume-name") == "my bowl.png"
        assert other.text_content("#resume-detail") == "photo · just now"
        assert other.evaluate("window.shadeform.state().image") is None
        other.screenshot(path=str(tmp_path / "offer.png"))

        other.click("#project-menu > button")
        other.click('#project-menu [data-action="open-recent"]')
        other.wait_for_selector("#recent-list li", timeout=RESULT_MS)
        rows = other.eval_on_selector_all(
            "#recent-list li",
            "items => items.map((li) => [li.dataset.project, li.querySelector('b').textContent, "
            "li.querySelector('small').textContent])",
        )
        assert [row[1] for row in rows] == ["my bowl.png", "synth:sphere"]  # newest first
        assert rows[0][0] == project_id and rows[0][2] == "photo"
        ARTIFACTS.mkdir(exist_ok=True)
        other.screenshot(path=str(ARTIFACTS / "app-open-recent.png"))

        other.click(f'#recent-list li[data-project="{project_id}"] .recent-open')
        wait_for_result(other, 0)
        assert not other.is_visible("#recent-dialog") and not other.is_visible("#resume")
        state = other.evaluate("window.shadeform.state()")
        assert state["image"] == saved["image"]  # the same id: made again from the session store
        assert state["params"] == saved["params"]
        assert state["params"]["filter"]["kind"] == "gaussian"
        assert state["params"]["concave"]["regions"][0]["axis"] == "both"
        assert other.evaluate("window.shadeform.shownModelState().status") == "current"
        sent = [
            entry
            for entry in log
            if entry[0] == "POST" and (entry[1] == "api/images" or entry[1].startswith("api/examples"))
        ]
        assert not sent, f"the image was sent or opened again: {sent}"

        # going on there saves to the same project (the save may come before the new result)
        before, taken = other.evaluate("window.shadeform.applied()"), saves(other)
        other.select_option("#filter-kind", "median")
        wait_for_result(other, before)
        assert wait_for_autosave(other, taken)["ids"]["photo"] == project_id
        listed = other.evaluate("fetch('/api/projects').then((r) => r.json())")["projects"]
        assert [p["id"] for p in listed][0] == project_id and len(listed) == 2
        document = other.evaluate(f"fetch('/api/projects/{project_id}').then((r) => r.json())")["document"]
        assert document["params"]["filter"]["kind"] == "median"
        assert toast_texts(other, "error") == []
    finally:
        context.close()
    assert not errors, f"uncaught errors in the page: {errors}"


def test_a_server_without_sessions_says_it_keeps_no_projects(page, browser, app_server):
    from shadeform.app.server import create_app

    app_server.stop()
    app_server.start(lambda: create_app())  # as `shadeform app --no-sessions`
    context, other, errors = new_profile(browser, app_server.url)
    try:
        open_example(other, "synth:sphere")
        other.wait_for_function("window.shadeform.projects().off", timeout=SAVED_MS)
        assert not other.is_visible("#resume")
        other.click("#project-menu > button")
        other.click('#project-menu [data-action="open-recent"]')
        other.wait_for_function(
            "document.getElementById('recent-note').textContent.includes('keeps no projects')",
            timeout=RESULT_MS,
        )
        assert other.text_content("#recent-note") == (
            "This server keeps no projects; start it without --no-sessions."
        )
        other.keyboard.press("Escape")
        assert not other.is_visible("#recent-dialog")
        # the autosave stopped quietly: no message, and the next change sends nothing
        assert toast_texts(other, "error") == []
        log = record_requests(other)
        before = other.evaluate("window.shadeform.applied()")
        other.select_option("#filter-kind", "gaussian")
        wait_for_result(other, before)
        other.wait_for_timeout(1_500)
        assert not [entry for entry in log if entry[1].startswith("api/projects")]
    finally:
        context.close()
    assert not errors, f"uncaught errors in the page: {errors}"


def test_photo_set_and_views_projects_reopen_in_another_browser(page, browser, app_server):
    # a photo set with a setting changed, then views with one: two more projects
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-photo-set="stereo:vase"]')
    page.wait_for_function("window.shadeform.stereo.applied() > 0", timeout=FIRST_RESULT_MS)
    taken = saves(page)
    page.select_option("#stereo-model", "robust")
    set_id = wait_for_autosave(page, taken)["ids"]["photo_set"]
    info = page.evaluate("window.shadeform.stereo.info()")
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-view-set="views:lumpy"]')
    page.wait_for_function("window.shadeform.views.applied() > 0", timeout=FIRST_RESULT_MS)
    taken = saves(page)
    page.click("#parts-toggle")  # the partial models hidden: a setting of the views' project
    views_id = wait_for_autosave(page, taken)["ids"]["views"]
    views = page.evaluate("window.shadeform.views.views()")

    context, other, errors = new_profile(browser, app_server.url)
    try:
        other.click("#resume-more")
        other.wait_for_selector("#recent-list li", timeout=RESULT_MS)
        rows = other.eval_on_selector_all(
            "#recent-list li",
            "items => items.map((li) => [li.dataset.project, li.querySelector('b').textContent, "
            "li.querySelector('small').textContent])",
        )
        names = [view["name"] for view in views]
        assert rows[:2] == [
            [views_id, f"views of {names[0]}", f"views · 4 views: {', '.join(names[:3])} and 1 more"],
            [
                set_id,
                info["name"],
                f"photo set · {info['count']} photos: {', '.join(info['names'][:3])} and 9 more",
            ],
        ]
        other.screenshot(path=str(ARTIFACTS / "app-open-recent-kinds.png"))
        other.click(f'#recent-list li[data-project="{set_id}"] .recent-open')
        other.wait_for_function("window.shadeform.stereo.applied() > 0", timeout=RESULT_MS)
        assert other.evaluate("document.body.classList.contains('stereo-mode')")
        assert other.evaluate("window.shadeform.stereo.info()") == info
        assert other.evaluate("window.shadeform.stereo.params().model") == "robust"
        assert other.input_value("#stereo-model") == "robust"

        other.click("#project-menu > button")
        other.click('#project-menu [data-action="open-recent"]')
        other.click(f'#recent-list li[data-project="{views_id}"] .recent-open')
        other.wait_for_function("window.shadeform.views.applied() > 0", timeout=RESULT_MS)
        assert other.evaluate("window.shadeform.views.open()")
        assert other.evaluate("window.shadeform.views.views()") == views
        assert other.evaluate("window.shadeform.views.partsShown()") == 0
        assert other.evaluate("window.shadeform.projects().ids") == {
            "photo": None,
            "photo_set": set_id,
            "views": views_id,
        }
        assert toast_texts(other, "error") == []
    finally:
        context.close()
    assert not errors, f"uncaught errors in the page: {errors}"


def put_project(page, project_id: str, document: dict) -> int:
    return page.evaluate(
        """([id, doc]) => fetch(`/api/projects/${id}`, {
            method: 'PUT', headers: {'Content-Type': 'application/json'}, body: JSON.stringify(doc),
        }).then((r) => r.status)""",
        [project_id, document],
    )


def test_a_project_whose_image_the_server_forgot_opens_it_again_or_says_why(page):
    from helpers.projects import photo_document

    # an example the server no longer has under that id: opened again by name
    example = photo_document("synth:sphere", step=3)
    example["image"]["source"] = {"kind": "example", "name": "synth:sphere", "type": None, "index": None}
    example["image"]["info"] = {**example["image"]["info"], "image_id": "forgotten", "name": "synth:sphere"}
    example["params"]["concave"]["regions"][0]["polygon"] = [[20, 20], [60, 20], [40, 60]]
    assert put_project(page, "example", example) == 200
    # an upload without a copy: nothing to send again
    assert put_project(page, "upload", photo_document("gone.png")) == 200

    page.click("#project-menu > button")
    page.click('#project-menu [data-action="open-recent"]')
    page.click('#recent-list li[data-project="example"] .recent-open')
    wait_for_result(page, 0, timeout=FIRST_RESULT_MS)
    state = page.evaluate("window.shadeform.state()")
    assert state["image"]["name"] == "synth:sphere" and state["image"]["image_id"] != "forgotten"
    assert state["params"] == example["params"]
    assert page.evaluate("window.shadeform.projects().ids.photo") == "example"

    page.click("#project-menu > button")
    page.click('#project-menu [data-action="open-recent"]')
    page.click('#recent-list li[data-project="upload"] .recent-open')
    page.wait_for_function(
        "window.shadeform.toasts().some((t) => t.kind === 'error' && t.text.includes('gone.png'))",
        timeout=RESULT_MS,
    )
    said = toast_texts(page, "error")[-1]
    assert "the project has no copy of it: open the image again" in said
    # what was open stays open, and its project the page's
    assert page.evaluate("window.shadeform.state().image") == state["image"]
    assert page.evaluate("window.shadeform.projects().ids.photo") == "example"
