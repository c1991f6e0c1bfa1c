"""The app tells the truth, in a real browser: what the model on screen is, errors that stay,
shortcuts wherever the focus is, a refused polygon said, a layout that fits.

The server, the browser and a fresh page per test are those of
``tests/helpers/browser.py``: the real server under uvicorn on a free loopback port serving the
built client, Debian's Chromium driven by Playwright with clicks and keys. A refused request is
a real refusal: Playwright's ``page.route`` rewrites one field of the client's request to a value
the server rejects and passes the server's own 422 back. Facts come from the test hook
(``window.shadeform.modelState()``, ``shownModelState()``, ``notice()``, ``toasts()``, and the
photo set's and views' ``modelState()``) and from the page itself (the badge, the export button,
bounding boxes). Screenshots at 1024 x 768 and 1920 x 1080 go to the test's tmp folder.
"""

from __future__ import annotations

import json

import pytest

from helpers import browser as ui
from helpers.browser import (
    BOWL,
    FIRST_RESULT_MS,
    RESULT_MS,
    applied,
    click_image,
    open_example,
    wait_for_result,
)

# the real server, Chromium and a fresh page per test: the fixtures of tests/helpers/browser.py
server, browser, page = ui.server, ui.browser, ui.page


def model(page) -> dict:
    """The state of the model the 3D view shows, with the badge's words."""
    return page.evaluate("window.shadeform.shownModelState()")


def wait_for_status(page, status: str, timeout=RESULT_MS) -> dict:
    page.wait_for_function(f"window.shadeform.shownModelState().status === {status!r}", timeout=timeout)
    return model(page)


def refuse(page, pattern: str, tweak) -> list[str]:
    """Send the requests matching ``pattern`` with ``tweak`` applied to their JSON body, to the real
    server, and hand its answers back; returns the server's ``detail`` of each refusal."""
    refusals: list[str] = []

    def handle(route):
        body = json.loads(route.request.post_data)
        tweak(body)
        response = route.fetch(post_data=json.dumps(body))
        if response.status >= 400:
            refusals.append(response.json()["detail"])
        route.fulfill(response=response)

    page.route(pattern, handle)
    return refusals


def assert_refused(page, refusals: list[str]) -> str:
    """The model is failed with the server's message; the older model stays, dimmed, and cannot
    be exported."""
    state = wait_for_status(page, "failed")
    assert refusals and state["message"] == refusals[-1]
    assert state["badge"] == f"Failed: {refusals[-1]}"
    assert page.is_visible("#model-badge") and page.inner_text("#model-badge") == state["badge"]
    assert page.is_disabled("#export-button")
    assert page.evaluate("document.getElementById('view-host').classList.contains('has-model')")
    assert page.evaluate("document.getElementById('view-host').classList.contains('outdated')")
    return refusals[-1]


def error_toasts(page) -> list[str]:
    return [t["text"] for t in page.evaluate("window.shadeform.toasts()") if t["kind"] == "error"]


# ----------------------------------------------------------------- the model's state, refusals


def test_a_refused_request_fails_the_model_and_its_message_stays_until_dismissed(page, tmp_path):
    open_example(page, BOWL)
    state = model(page)
    assert state["status"] == "current" and state["badge"] == "Up to date"
    assert page.is_enabled("#export-button")
    assert not page.evaluate("document.getElementById('view-host').classList.contains('outdated')")

    # the server refuses 101 refinement iterations (at most 100): a 422 with its one-line detail
    refusals = refuse(page, "**/api/reconstruct", lambda body: body["params"].update(refine=101))
    page.click('#light-mode [data-mode="estimate"]')
    message = assert_refused(page, refusals)
    assert "refine" in message and "\n" not in message
    page.wait_for_timeout(700)  # the dimming starts after a moment
    page.screenshot(path=str(tmp_path / "refused.png"))
    assert page.evaluate("window.shadeform.state().model") == "failed"

    # the message is still there after 10 s (the audit saw it vanish after 7)
    page.wait_for_timeout(10_000)
    assert page.is_visible("#toast") and error_toasts(page) == [message]
    assert model(page)["status"] == "failed" and page.is_disabled("#export-button")

    # dismissed with its close button
    page.click("#toast .toast-close")
    assert not page.is_visible("#toast") and error_toasts(page) == []
    assert model(page)["status"] == "failed"  # dismissing a message changes nothing else

    # another refusal: Escape on the message (focus on it) dismisses it, and is no shortcut then
    page.click('#light-mode [data-mode="z"]')
    page.wait_for_function("window.shadeform.toasts().length === 1", timeout=RESULT_MS)
    assert_refused(page, refusals)
    page.focus("#toast .toast-close")
    page.keyboard.press("Escape")
    assert not page.is_visible("#toast") and error_toasts(page) == []

    # the server takes the next change again: the model is current, and exportable
    page.unroute("**/api/reconstruct")
    page.click('#light-mode [data-mode="estimate"]')
    state = wait_for_status(page, "current")
    assert state["badge"] == "Up to date" and state["message"] is None
    assert page.is_enabled("#export-button")
    assert not page.evaluate("document.getElementById('view-host').classList.contains('outdated')")


def test_a_failures_message_goes_once_a_model_for_the_inputs_is_drawn(page):
    """An error stays until dismissed while it holds; once the next change's model is drawn (up
    to date) the failure is outlived and its message goes with it."""
    open_example(page, BOWL)
    refusals = refuse(page, "**/api/reconstruct", lambda body: body["params"].update(refine=101))
    page.click('#light-mode [data-mode="estimate"]')
    message = assert_refused(page, refusals)
    assert error_toasts(page) == [message]
    page.unroute("**/api/reconstruct")
    page.click('#light-mode [data-mode="z"]')
    wait_for_status(page, "current")
    assert error_toasts(page) == []


def test_a_parameter_change_makes_the_model_stale_then_computing_then_current(page, tmp_path):
    open_example(page, BOWL)
    assert model(page)["status"] == "current"

    # a slider moved (an input event: a drag): out of date until its pause has passed
    shown = page.evaluate(
        """() => {
            const tilt = document.getElementById('tilt');
            tilt.value = '40';
            tilt.dispatchEvent(new Event('input', { bubbles: true }));
            return window.shadeform.shownModelState();
        }"""
    )
    assert shown["status"] == "stale" and shown["badge"] == "Out of date: parameters changed"
    assert page.is_disabled("#export-button")
    state = wait_for_status(page, "current")
    assert state["history"][-3:] == ["stale", "computing", "current"]

    # a click sends at once: held on its way, the model is being computed, dimmed, not exportable
    held, holding = [], [True]
    page.route("**/api/reconstruct", lambda route: held.append(route) if holding[0] else route.continue_())
    page.click('#light-mode [data-mode="estimate"]')
    state = wait_for_status(page, "computing")
    assert state["history"][-3:] == ["current", "stale", "computing"]
    assert state["badge"] == "Computing…" and page.is_disabled("#export-button")
    assert page.evaluate("document.getElementById('view-host').dataset.modelStatus") == "computing"
    assert page.evaluate("document.getElementById('view-host').classList.contains('outdated')")
    page.wait_for_timeout(500)  # the dimming starts after a moment
    page.screenshot(path=str(tmp_path / "computing.png"))
    assert (
        float(page.evaluate("getComputedStyle(document.querySelector('#view-host .viewer-canvas')).opacity"))
        < 0.6
    )

    # let it through: current, exportable, not dimmed
    holding[0] = False
    for route in held:
        route.continue_()
    state = wait_for_status(page, "current")
    assert state["badge"] == "Up to date" and page.is_enabled("#export-button")
    assert page.evaluate("window.shadeform.lastResult().preview") is False


def test_the_photo_sets_model_fails_on_a_refusal_and_exports_only_when_current(page):
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-photo-set="stereo:vase"]')
    page.wait_for_function(
        "window.shadeform.stereo.modelState().status === 'current'", timeout=FIRST_RESULT_MS
    )
    assert model(page)["badge"] == "Up to date" and page.is_enabled("#export-button")

    refusals = refuse(page, "**/api/stereo", lambda body: body["params"].update(step=0))
    page.select_option("#stereo-integrator", index=1)
    message = assert_refused(page, refusals)
    state = page.evaluate("window.shadeform.stereo.modelState()")
    assert state["status"] == "failed" and state["message"] == message
    assert page.evaluate("window.shadeform.stereo.error()") == message  # the panel says it too

    page.unroute("**/api/stereo")
    page.select_option("#stereo-integrator", index=0)
    wait_for_status(page, "current", timeout=FIRST_RESULT_MS)
    assert page.is_enabled("#export-button") and page.evaluate("window.shadeform.stereo.error()") is None


def test_the_views_fused_model_is_out_of_date_below_two_views_and_fails_on_a_refusal(page):
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-view-set="views:lumpy"]')
    page.wait_for_function(
        "window.shadeform.views.modelState().status === 'current'", timeout=FIRST_RESULT_MS
    )
    assert model(page)["badge"] == "Up to date" and page.is_enabled("#export-button")

    refusals = refuse(page, "**/api/fuse", lambda body: body.update(resolution=0.1))
    page.select_option("#views-resolution", "3")
    message = assert_refused(page, refusals)
    assert page.evaluate("window.shadeform.views.modelState().message") == message
    page.unroute("**/api/fuse")

    # down to one view: the fused model on screen is no longer the views', and says so
    for _ in range(3):
        page.click('#views-list [data-index="0"] [data-act="remove"]')
    state = wait_for_status(page, "stale")
    assert state["badge"] == "Out of date: fusing needs at least two views"
    assert page.is_disabled("#export-button")


# ------------------------------------------------------------------------------ shortcuts


def view(page) -> dict:
    return page.evaluate("window.shadeform.state().view")


def test_shortcuts_work_after_clicking_a_checkbox_a_button_a_select_or_a_slider(page):
    open_example(page, BOWL)

    # a checkbox clicked keeps the focus: the keys still act
    page.click("#wire-toggle")
    assert page.evaluate("document.activeElement.id") == "wire-toggle" and view(page)["wireframe"]
    page.keyboard.press("n")
    assert view(page)["normalColours"]
    page.keyboard.press("w")
    assert not view(page)["wireframe"]
    front = page.evaluate("window.shadeform.cameraOffset()")
    page.keyboard.press("ArrowRight")  # turns the view, not anything of the checkbox
    assert page.evaluate("window.shadeform.cameraOffset()") != front

    # a button
    page.click("#fit-image")
    texture = view(page)["texture"]
    page.keyboard.press("t")
    assert view(page)["texture"] is not texture

    # a select: a letter is a shortcut, not a choice by its first letter ("Filtered")
    page.focus("#display")
    page.keyboard.press("f")
    assert page.evaluate("window.shadeform.state().tool") == "reference"
    assert page.input_value("#display") == "photo"
    page.keyboard.press("v")
    assert page.evaluate("window.shadeform.state().tool") == "select"

    # a slider: its arrows are its own, letters are shortcuts
    page.focus("#step")
    step = page.evaluate("window.shadeform.state().params.step")
    turned = page.evaluate("window.shadeform.cameraOffset()")
    before = applied(page)
    page.keyboard.press("ArrowRight")
    assert page.evaluate("window.shadeform.state().params.step") == step + 1
    assert page.evaluate("window.shadeform.cameraOffset()") == turned
    arrow = view(page)["lightArrow"]
    page.keyboard.press("l")
    assert view(page)["lightArrow"] is not arrow
    page.wait_for_function(f"window.shadeform.applied() > {before} && !window.shadeform.state().busy")


def test_keys_typed_in_a_text_field_are_not_shortcuts(page):
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-photo-set="stereo:vase"]')
    page.wait_for_function("window.shadeform.stereo.modelState().status !== 'none'", timeout=FIRST_RESULT_MS)
    page.click('#stereo-lights [data-lights="sphere"]')
    wireframe = view(page)["wireframe"]
    page.click("#stereo-sphere")
    page.keyboard.type("w 1")
    assert page.input_value("#stereo-sphere") == "w 1" and view(page)["wireframe"] is wireframe


# ------------------------------------------------------------------------- polygons


NOTICE = "A region needs at least three points; click more points or press Escape"
MASK_NOTICE = "A mask polygon needs at least three points; click more points or press Escape"


def notice(page):
    return page.evaluate("window.shadeform.notice()")


def test_a_polygon_of_two_points_is_refused_with_a_message(page, tmp_path):
    open_example(page, BOWL)
    sent = page.evaluate("window.shadeform.requests()")

    # a region closed on two corners (Enter, or a click on the first corner): said, not dropped
    page.click('#tools [data-tool="polygon"]')
    click_image(page, 60, 60)
    click_image(page, 190, 70)
    assert notice(page) is None
    page.keyboard.press("Enter")
    assert notice(page) == NOTICE and page.is_visible("#image-notice")
    page.screenshot(path=str(tmp_path / "two-points.png"))
    click_image(page, 60, 60)
    assert notice(page) == NOTICE
    assert page.evaluate("window.shadeform.state().params.concave.regions") == []
    assert page.evaluate("window.shadeform.requests()") == sent
    # a third corner takes the message away, and the region closes
    click_image(page, 128, 190)
    assert notice(page) is None
    before = applied(page)
    page.keyboard.press("Enter")
    wait_for_result(page, before)
    assert len(page.evaluate("window.shadeform.state().params.concave.regions")) == 1

    # the same for a mask polygon; Escape drops its corners and the message
    page.keyboard.press("k")
    page.click('#mask-mode [data-mask-mode="polygon"]')
    mask = page.evaluate("window.shadeform.state().params.mask")
    click_image(page, 40, 40)
    click_image(page, 80, 40)
    page.keyboard.press("Enter")
    assert notice(page) == MASK_NOTICE and page.is_visible("#image-notice")
    assert page.evaluate("window.shadeform.state().params.mask") == mask
    page.keyboard.press("Escape")
    assert notice(page) is None and not page.is_visible("#image-notice")


# --------------------------------------------------------------------------------- layout

# every control of the top bar, the panes' tool bars, the 3D view's buttons and the side panel
CONTROLS = """() => {
    const selector = ['.topbar', '.pane-toolbar', '.nav', '.panel']
        .map((bar) => `${bar} button, ${bar} select, ${bar} input`).join(', ');
    const problems = [];
    let checked = 0;
    for (const control of document.querySelectorAll(selector)) {
        if (!control.checkVisibility()) continue;  // another mode's, a closed menu's
        control.scrollIntoView({ block: 'nearest', inline: 'nearest' });  // the panel scrolls
        const box = control.getBoundingClientRect();
        const name = control.id || control.dataset.tool || control.textContent.trim().slice(0, 24) || control.outerHTML.slice(0, 60);
        checked += 1;
        // a pixel's leeway: boxes lie on fractions of a pixel
        if (box.left < -1 || box.top < -1 || box.right > innerWidth + 1 || box.bottom > innerHeight + 1) {
            problems.push(`${name}: outside the window`);
        }
        for (let above = control.parentElement; above; above = above.parentElement) {
            const style = getComputedStyle(above);
            if (style.overflowX === 'visible' && style.overflowY === 'visible') continue;
            const clip = above.getBoundingClientRect();
            if (box.left < clip.left - 1 || box.right > clip.right + 1 || box.top < clip.top - 1 || box.bottom > clip.bottom + 1) {
                problems.push(`${name}: clipped by ${above.id || above.className}`);
            }
        }
        // (a control that takes no pointer, as a disabled row's, is passed through by any hit test)
        const hit = document.elementFromPoint((box.left + box.right) / 2, (box.top + box.bottom) / 2);
        if (getComputedStyle(control).pointerEvents !== 'none' && (!hit || !(hit === control || control.contains(hit)))) {
            problems.push(`${name}: covered by ${hit ? hit.id || hit.className || hit.tagName : 'nothing'}`);
        }
        if (control.tagName === 'BUTTON' && (control.scrollWidth > control.clientWidth + 1 || control.scrollHeight > control.clientHeight + 1)) {
            problems.push(`${name}: its label overflows it`);
        }
    }
    if (document.documentElement.scrollWidth > innerWidth) problems.push('the page is wider than the window');
    return { checked, problems };
}"""


def check_layout(page, width: int, height: int, picture, at_least: int = 40) -> None:
    page.set_viewport_size({"width": width, "height": height})
    if page.is_visible("#fit-image"):
        page.click("#fit-image")  # the image and the model framed in the new size, as a user would
    page.keyboard.press("r")
    page.wait_for_timeout(300)  # resize observers, a frame drawn
    page.mouse.move(width // 2, height // 2)  # no hover highlight over a tool bar
    page.screenshot(path=str(picture))
    found = page.evaluate(CONTROLS)
    assert found["checked"] >= at_least, found  # the bars and the panel were seen
    assert found["problems"] == [], f"at {width} x {height}: {found['problems']}"
    page.evaluate("document.getElementById('panel').scrollTop = 0")


@pytest.mark.parametrize("size", [(1024, 768), (1400, 860), (1920, 1080)], ids=["1024", "1400", "1920"])
def test_the_layout_fits_the_window(page, tmp_path, size):
    open_example(page, BOWL)
    width, height = size
    check_layout(page, width, height, tmp_path / f"app-{width}x{height}.png")
    assert page.is_visible("#fit-image")  # the button the audit found clipped at 1400 px


def test_the_layout_of_the_photo_set_and_views_fits_at_1024(page, tmp_path):
    page.set_viewport_size({"width": 1024, "height": 768})
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-photo-set="stereo:vase"]')
    page.wait_for_function(
        "window.shadeform.stereo.modelState().status === 'current'", timeout=FIRST_RESULT_MS
    )
    check_layout(page, 1024, 768, tmp_path / "photo-set-1024x768.png", at_least=20)
    page.click("#examples-menu > button")
    page.click('#examples-menu [data-view-set="views:lumpy"]')
    page.wait_for_function(
        "window.shadeform.views.modelState().status === 'current'", timeout=FIRST_RESULT_MS
    )
    check_layout(page, 1024, 768, tmp_path / "views-1024x768.png", at_least=20)
