"""The instructor is never throttled as a student (issue 20, section 7).

The real dashboard (``/class``) in headless Chromium on a 200-robot class: it subscribes to
three topics per robot on its one root connection at once (600 subscriptions in a burst,
which a student's budget of 200 messages/s closed for "rate limit") and polls every robot's
``/websim/status``. The root view's limits are sized for the class
(``class_server.class_view_limits``): every card must show its robot's pose within 5 s of
the root connection opening, every card its first status within one more round of the
page's status poller (``class-poller.js``: at most one call per 20 ms, 4 s for 200 robots),
and no connection of the page may close.
"""

from __future__ import annotations

import time
from typing import Any

import pytest
from test_dashboard import needs_browser, page_says

from server_process import ADMIN_TOKEN, start_server

CLASS_SIZE = 200
LIVE_WITHIN_S = 5.0
"""Every card showing its robot's pose, counted from the root connection opening."""
STATUS_ROUND_S = CLASS_SIZE * 0.020
"""The page's status poller asks one robot per 20 ms at most (``MIN_POLL_GAP_MS``)."""
MARGIN_S = 2.0
"""For a loaded 2-core machine: the browser's timers run late there."""

COUNT = """(field) => [...document.querySelectorAll(`.robot-card [data-field=${field}]`)]
    .filter((el) => el.textContent !== '–').length"""


@pytest.mark.slow
@pytest.mark.browser
@needs_browser
def test_a_200_robot_dashboard_is_live_within_5_s_and_never_closed(browser: Any) -> None:
    big = start_server(["--class", str(CLASS_SIZE)])
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    try:
        page = context.new_page()
        opened: list[float] = []
        closed: list[str] = []
        errors: list[str] = []

        def watch(websocket: Any) -> None:
            opened.append(time.monotonic())
            websocket.on("close", lambda ws: closed.append(ws.url))

        page.on("websocket", watch)
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto(f"{big.http_url}/class?token={ADMIN_TOKEN}")
        poses_s = statuses_s = None
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and statuses_s is None:
            now = time.monotonic()
            if poses_s is None and page.evaluate(COUNT, "pose") == CLASS_SIZE:
                poses_s = now - opened[0]
            if page.evaluate(COUNT, "clients") == CLASS_SIZE:
                statuses_s = now - opened[0]
            time.sleep(0.1)
        assert poses_s is not None and statuses_s is not None, \
            f"not every card came alive in 60 s; the page says {page_says(page)}"
        time.sleep(2.0)  # anything the burst closed would show by now
        assert closed == [], f"the page's connections closed: {closed}"
        assert errors == []
        assert poses_s <= LIVE_WITHIN_S, f"{CLASS_SIZE} poses after {poses_s:.1f} s"
        assert statuses_s <= LIVE_WITHIN_S + STATUS_ROUND_S + MARGIN_S, \
            f"{CLASS_SIZE} statuses after {statuses_s:.1f} s"
    finally:
        context.close()
        big.stop()
    assert "rate limit" not in "".join(big.output)
