"""Another client on the same robot, as the student page in a real headless Chromium shows it:
a reset it did not ask for is announced, and another driver gets a badge.
"""

from __future__ import annotations

import time
from typing import Any

from page_helpers import (
    ROBOT,
    Bridge,
    driving_page,
    latest_odom,
    needs_browser,
    page_url,
    reset_robot,
    screenshot,
    wait_until_still,
    x_of,
)

from server_process import ServerProcess, wait_for

OTHER_DRIVER_SHOWS = """() => {
    const badge = document.querySelector('#other-driver');
    window.otherDriverShown = 0;
    new MutationObserver(() => { if (!badge.hidden) window.otherDriverShown += 1; })
      .observe(badge, {attributes: true, attributeFilter: ['hidden']});
}"""
"""Counts, in window.otherDriverShown, every time the page shows its "another client" badge."""


@needs_browser
def test_a_reset_by_another_client_is_announced_and_breaks_the_trail(
        server: ServerProcess, bridge: Bridge, browser: Any) -> None:
    with driving_page(browser, bridge, page_url(server),
                      viewport={"width": 1280, "height": 860}) as (page, log):
        deadline = time.monotonic() + 10.0
        while x_of(latest_odom(bridge)) < 0.7 and time.monotonic() < deadline:
            bridge.send(op="publish", topic="/cmd_vel", msg={  # another client drives away
                "linear": {"x": 0.5, "y": 0.0, "z": 0.0},
                "angular": {"x": 0.0, "y": 0.0, "z": 0.0}})
            time.sleep(0.1)
        assert page.is_hidden("#reset-notice")
        reset_robot(bridge)  # and resets it: this page did not ask
        page.wait_for_selector("#reset-notice:not([hidden])", timeout=5000)
        assert page.evaluate("window.websim.state.trail.points.at(-1).gap")  # no line back
        assert log.page_errors == []


@needs_browser
def test_another_client_driving_shows_a_badge_the_pages_own_driving_does_not(
        server: ServerProcess, bridge: Bridge, browser: Any) -> None:
    cmd_vel = ROBOT["topics"]["cmd_vel"]
    with driving_page(browser, bridge, page_url(server),
                      viewport={"width": 1280, "height": 860}) as (page, log):
        page.evaluate(OTHER_DRIVER_SHOWS)
        assert page.is_hidden("#other-driver")
        # The page's own commands come back to it from the bridge: they are not foreign.
        odoms_before = len(bridge.messages("/odom"))
        page.keyboard.down("ArrowUp")
        wait_for(lambda: [m for m in bridge.messages("/odom")[odoms_before:] if x_of(m) > 0],
                 what="the page to drive the robot")
        time.sleep(1.0)
        page.keyboard.up("ArrowUp")
        wait_until_still(bridge)
        time.sleep(0.5)  # the zero Twist's echo has come back too
        assert page.evaluate("window.otherDriverShown") == 0

        other = Bridge(server.ws_url)  # another student on the same robot
        try:
            for linear in (0.1, 0.1, 0.1, 0.1, 0.0):
                other.send(op="publish", topic=cmd_vel["name"], type=cmd_vel["type"],
                           msg={"linear": {"x": linear}, "angular": {"z": 0}})
                time.sleep(0.1)
            last_sent = time.monotonic()
            badge = page.wait_for_selector("#other-driver:not([hidden])", timeout=2000)
            assert badge.text_content() == "Another client is driving this robot"
            screenshot(page, "main-other-driver.png", full_page=False)
            page.wait_for_selector("#other-driver[hidden]", state="attached", timeout=3000)
            gone_after_s = time.monotonic() - last_sent
        finally:
            other.close()
        wait_until_still(bridge)
        assert log.console_errors == [] and log.page_errors == []
    # Shown for 1 s after the last foreign command reached the page, which was after it was sent.
    assert 0.9 < gone_after_s < 2.5
