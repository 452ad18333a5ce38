"""The student page's PID panel in a real headless Chromium turns the robot to a heading.

The test also writes the README's ``docs/screenshot.png`` when it is missing or
``UPDATE_SCREENSHOT=1`` is set, so an ordinary run leaves the committed picture alone.
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

from page_helpers import (
    ROOT,
    Bridge,
    driving_page,
    latest_odom,
    needs_browser,
    page_url,
    screenshot,
    twist_pairs,
    wait_until_still,
    x_of,
    yaw_of,
)

from server_process import ServerProcess, wait_for

DEG = math.pi / 180
DOCS_SCREENSHOT = ROOT / "docs" / "screenshot.png"


@needs_browser
def test_pid_panel_turns_the_robot_to_90_degrees(server: ServerProcess, bridge: Bridge,
                                                 browser: Any) -> None:
    with driving_page(browser, bridge, page_url(server),
                      viewport={"width": 1280, "height": 860}) as (page, log):
        page.keyboard.down("ArrowUp")  # a short drive first: the screenshot shows a trail
        wait_for(lambda: x_of(latest_odom(bridge)) > 0.3, what="a short drive")
        page.keyboard.up("ArrowUp")
        wait_until_still(bridge)
        page.fill("#pid-kp", "2")
        page.fill("#pid-ki", "0")
        page.fill("#pid-kd", "0")
        page.fill("#pid-setpoint", "90")
        page.click("#pid-toggle")
        settled = wait_for(lambda: abs(yaw_of(latest_odom(bridge)) - 90 * DEG) < 1 * DEG,
                           timeout_s=15, what="the heading to reach 90°")
        assert settled
        time.sleep(1.5)  # stay there: the heading plot shows the settled step response
        headings = [yaw_of(m) for m in bridge.messages("/odom")[-20:]]
        linear = [c[0] for c in twist_pairs(bridge.messages("/cmd_vel")[-20:])]
        page.click("#pid-toggle")
        wait_until_still(bridge)
        assert twist_pairs(bridge.messages("/cmd_vel"))[-1] == (0.0, 0.0)
        screenshot(page, "main-pid.png")
        if not DOCS_SCREENSHOT.exists() or os.environ.get("UPDATE_SCREENSHOT") == "1":
            DOCS_SCREENSHOT.parent.mkdir(exist_ok=True)
            page.screenshot(path=str(DOCS_SCREENSHOT), full_page=True)
        assert log.console_errors == [] and log.page_errors == []
    assert all(abs(h - 90 * DEG) < 2 * DEG for h in headings)
    assert linear == [0.0] * len(linear)  # the PID only turns
