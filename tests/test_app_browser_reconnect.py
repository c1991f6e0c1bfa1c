"""The client reconnects after a server restart, and says so (issue 14, point 4), in a real browser.

The browser and a fresh page per test are those of ``tests/helpers/browser.py``; the server is
its ``RestartableServer`` (the ``app_server`` fixture): the real app under uvicorn in a thread
on a free loopback port, stopped and started again as a new ``create_app`` ON THE SAME PORT, as a
user's ``shadeform app`` is restarted. A request made while it is stopped fails at the network level
(connection refused), which the page must say (a message that stays, the test hook's
``connection()`` "lost", the model failed and not exportable) until the server answers again;
then it must say "Reconnected" and make the model current again by itself. With the sessions
file the restarted server knows the page's image id (nothing is sent again); without one (as
``--no-sessions``) the page sends the image again from its own copy and says so.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from helpers import browser as ui
from helpers.browser import (
    BOWL,
    FIRST_RESULT_MS,
    RESULT_MS,
    open_example,
    record_requests,
    toast_texts,
    wait_for_result,
)

# Chromium and a fresh page per test: the fixtures of tests/helpers/browser.py (the page opens
# ``server``, which is this module's)
browser, page = ui.browser, ui.page

LOST = "Lost the connection to the server; retrying…"
RECONNECTED = "Reconnected to the server"
UNREACHABLE = "server not reachable (retrying…)"
# the client polls 2 s after the failure, backing off to 10 s; the brief allows ~15 s
RECONNECT_MS = 15_000


@pytest.fixture
def server(app_server):
    """The address the ``page`` fixture opens (``app_server``: tests/conftest.py)."""
    return app_server.url


# ----------------------------------------------------------------------------- helpers


def shown(page) -> dict:
    return page.evaluate("window.shadeform.shownModelState()")


def lose_the_server(page, app_server, change: Callable[[], None], tmp_path: Path) -> None:
    """Stop the server, make a change in the page, and check the page says the truth meanwhile."""
    app_server.stop()
    change()  # its request is refused at the network level
    page.wait_for_function("window.shadeform.connection() === 'lost'", timeout=RESULT_MS)
    page.wait_for_function(
        f"window.shadeform.shownModelState().message === {UNREACHABLE!r}", timeout=RESULT_MS
    )
    state = shown(page)
    assert state["status"] == "failed" and state["badge"] == f"Failed: {UNREACHABLE}"
    assert LOST in toast_texts(page, "error")
    assert page.is_visible("#toast") and page.is_visible("#model-badge")
    assert page.is_disabled("#export-button")
    # the older model stays on screen, dimmed
    assert page.evaluate("document.getElementById('view-host').classList.contains('outdated')")
    page.wait_for_timeout(4_500)  # polls fail meanwhile (2 s, then 3 s): still lost, still said
    assert page.evaluate("window.shadeform.connection()") == "lost"
    assert toast_texts(page, "error") == [LOST]
    page.screenshot(path=str(tmp_path / "lost.png"))


def wait_for_reconnection(page) -> None:
    """Within ~15 s: "Reconnected" said (information fades, so caught while shown), the lost
    message gone, the hook online."""
    page.wait_for_function(
        f"window.shadeform.toasts().some((t) => t.kind === 'info' && t.text === {RECONNECTED!r})",
        timeout=RECONNECT_MS,
    )
    assert page.evaluate("window.shadeform.connection()") == "online"
    assert LOST not in toast_texts(page, "error")


# ------------------------------------------------------------------------------- tests


def test_a_restarted_server_with_the_sessions_is_reconnected_and_the_model_made_again(
    page, app_server, tmp_path
):
    from shadeform.app.server import create_app

    open_example(page, BOWL)
    before = page.evaluate("window.shadeform.state()")
    assert before["model"] == "current" and page.evaluate("window.shadeform.connection()") == "online"
    applied = page.evaluate("window.shadeform.applied()")

    log = record_requests(page)
    lose_the_server(page, app_server, lambda: page.select_option("#filter-kind", "gaussian"), tmp_path)
    assert page.evaluate("window.shadeform.applied()") == applied  # nothing came back
    polls = [entry for entry in log if entry == ("GET", "api/options")]
    assert 1 <= len(polls) <= 3, f"one poll at a time, 2 s and then longer apart: {polls}"

    # a new server on the same port, with the same sessions file
    restarted = len(log)
    app_server.start(lambda: create_app(sessions=tmp_path / "s.sqlite3"))
    wait_for_reconnection(page)
    page.screenshot(path=str(tmp_path / "reconnected.png"))

    # the last solve goes again by itself: the model is current, of the same image, with the change
    wait_for_result(page, applied)
    page.wait_for_function("window.shadeform.shownModelState().status === 'current'", timeout=RESULT_MS)
    after = page.evaluate("window.shadeform.state()")
    assert after["image"] == before["image"]  # the same id: the server knew it from its sessions
    assert after["params"]["filter"]["kind"] == "gaussian"
    assert shown(page)["badge"] == "Up to date" and page.is_enabled("#export-button")
    since = log[restarted:]
    assert ("POST", "api/reconstruct") in since
    opened = [
        entry for entry in since if entry[0] == "POST" and entry[1].startswith(("api/images", "api/examples"))
    ]
    assert not opened, f"the image was sent or opened again: {opened}"
    assert toast_texts(page, "error") == []


def test_a_server_restarted_without_sessions_gets_the_upload_again_and_the_page_says_so(
    page, app_server, tmp_path
):
    from PIL import Image

    from shadeform.app.server import create_app
    from shadeform.examples import load_example

    image, _ = load_example("synth:sphere", size=96)
    png = tmp_path / "ball.png"
    Image.fromarray((image * 255).round().astype(np.uint8)).save(png)
    page.set_input_files("#file-image", str(png))
    wait_for_result(page, 0, timeout=FIRST_RESULT_MS)
    before = page.evaluate("window.shadeform.state()")
    applied = page.evaluate("window.shadeform.applied()")

    log = record_requests(page)
    lose_the_server(page, app_server, lambda: page.select_option("#filter-kind", "gaussian"), tmp_path)
    restarted = len(log)
    app_server.start(lambda: create_app())  # as `shadeform app --no-sessions`: it forgot the upload
    wait_for_reconnection(page)

    # the solve goes again, is told the image is unknown, and the page sends its copy and says so
    page.wait_for_function(
        "window.shadeform.toasts().some((t) => t.kind === 'info' && t.text.includes('sent it again'))",
        timeout=RESULT_MS,
    )
    said = [text for text in toast_texts(page, "info") if "sent it again" in text][0]
    assert "ball.png" in said and "restarted without its sessions" in said
    wait_for_result(page, applied)
    page.wait_for_function("window.shadeform.shownModelState().status === 'current'", timeout=RESULT_MS)
    after = page.evaluate("window.shadeform.state()")
    assert after["image"]["name"] == "ball.png"
    assert after["image"]["image_id"] != before["image"]["image_id"]
    assert after["params"]["filter"]["kind"] == "gaussian"
    assert ("POST", "api/images") in log[restarted:]
    assert toast_texts(page, "error") == []
