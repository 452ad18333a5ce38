"""Driving from the student page in a real headless Chromium: the arrow keys (never from a
text field; focus loss stops), and the joystick on a phone, as seen on the bridge.
"""

from __future__ import annotations

import time
from typing import Any

import pytest
from page_helpers import (
    ROBOT,
    Bridge,
    drag_up,
    driving_page,
    latest_odom,
    needs_browser,
    page_url,
    screenshot,
    speed_of,
    twist_pairs,
    wait_until_still,
    x_of,
    yaw_of,
)

from server_process import ServerProcess, wait_for


@needs_browser
def test_holding_arrow_up_drives_and_releasing_stops(server: ServerProcess, bridge: Bridge,
                                                     browser: Any) -> None:
    with driving_page(browser, bridge, page_url(server),
                      viewport={"width": 1280, "height": 860}) as (page, log):
        speed_mps = float(page.input_value("#speed-linear"))  # a share of the robot's limit
        assert 0 < speed_mps < ROBOT["robot"]["max_linear_mps"]  # scaled down
        commands_before = len(bridge.messages("/cmd_vel"))
        odoms_before = len(bridge.messages("/odom"))
        page.keyboard.down("ArrowUp")
        moving = wait_for(lambda: [m for m in bridge.messages("/odom")[odoms_before:]
                                   if x_of(m) > 0], what="the robot to move")[0]
        time.sleep(1.0)  # holding the key is the point of this test
        page.keyboard.up("ArrowUp")
        stopped = wait_until_still(bridge)
        commands = twist_pairs(bridge.messages("/cmd_vel")[commands_before:])
        screenshot(page, "main-after-drive.png")
        assert log.console_errors == [] and log.page_errors == []
        # The press and the release were timed to the odometry showing them: a tick or so.
        command_ms = float(wait_for(lambda: (text := page.text_content(
            'output[data-readout="cmdLatency"]')) not in (None, "–") and text,
            what="the cmd -> odom readout"))
        assert 1 <= command_ms <= 500, command_ms
    assert speed_of(moving) == pytest.approx(speed_mps)
    # About 1 s at that speed: the key was held 1 s after the first motion, plus latency.
    assert 0.8 * speed_mps < x_of(stopped) < 1.7 * speed_mps
    assert abs(yaw_of(stopped)) < 1e-9
    assert commands[-1] == (0.0, 0.0)  # a zero Twist on release
    assert sum(1 for c in commands if c == (speed_mps, 0.0)) >= 5  # 10 Hz while held


@needs_browser
def test_no_driving_from_a_text_field_and_focus_loss_stops(server: ServerProcess,
                                                          bridge: Bridge,
                                                          browser: Any) -> None:
    with driving_page(browser, bridge, page_url(server)) as (page, _):
        commands_before = len(bridge.messages("/cmd_vel"))
        page.focus("#pid-kp")
        page.keyboard.down("ArrowUp")
        time.sleep(0.5)
        page.keyboard.up("ArrowUp")
        assert bridge.messages("/cmd_vel")[commands_before:] == []
        page.focus("#follow")  # a button: keys drive again
        page.keyboard.down("w")
        wait_for(lambda: speed_of(latest_odom(bridge)) > 0, what="driving with W")
        page.evaluate("window.dispatchEvent(new Event('blur'))")  # the tab loses focus
        stopped = wait_until_still(bridge)
        assert twist_pairs(bridge.messages("/cmd_vel"))[-1] == (0.0, 0.0)
        page.keyboard.up("w")
    assert x_of(stopped) > 0


@needs_browser
def test_phone_shows_the_joystick_and_dragging_it_drives(server: ServerProcess,
                                                         bridge: Bridge,
                                                         browser: Any) -> None:
    with driving_page(browser, bridge, page_url(server), viewport={"width": 390, "height": 844},
                      has_touch=True, is_mobile=True, device_scale_factor=3) as (page, log):
        layout = page.evaluate(
            "({page: document.documentElement.scrollWidth,"
            " view: document.querySelector('#view').getBoundingClientRect().width})")
        assert layout["page"] <= 390  # nothing sticks out sideways
        assert layout["view"] >= 390 - 40  # the view fills the width
        assert page.is_visible("#joystick")
        assert page.is_hidden('[data-drive="forward"]')
        screenshot(page, "phone.png", full_page=False)
        zone = page.locator("#joystick")
        zone.scroll_into_view_if_needed()
        box = zone.bounding_box()
        x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        moving, lift = drag_up(page, bridge, x, y)
        screenshot(page, "phone-joystick.png", full_page=False)
        lift()
        stopped = wait_until_still(bridge)
        assert twist_pairs(bridge.messages("/cmd_vel"))[-1] == (0.0, 0.0)
        assert log.console_errors == [] and log.page_errors == []
    assert speed_of(moving) > 0.1  # forward, at the joystick's deflection
    assert abs(yaw_of(stopped)) < 0.05  # straight up: hardly any turning
    assert x_of(stopped) > 0.05


@needs_browser
def test_space_stops_and_never_presses_the_focused_button(server: ServerProcess, bridge: Bridge,
                                                          browser: Any) -> None:
    """Space is the page's stop key: after the PID's Start and Stop (the button keeps the
    focus) it stops, and does not press Start again; it stops a running PID too. Typed into a
    text field, a space stays text."""
    with driving_page(browser, bridge, page_url(server),
                      viewport={"width": 1280, "height": 800}) as (page, log):
        page.fill("#pid-setpoint", "45")
        page.click("#pid-toggle")
        page.wait_for_selector("#pid-toggle[aria-pressed=true]")
        page.click("#pid-toggle")
        page.wait_for_selector("#pid-toggle[aria-pressed=false]")
        assert page.evaluate("document.activeElement.id") == "pid-toggle"
        wait_until_still(bridge)
        commands_before = len(bridge.messages("/cmd_vel"))
        page.keyboard.press(" ")
        time.sleep(1.0)  # a restarted PID would have published ~10 commands by now
        assert page.get_attribute("#pid-toggle", "aria-pressed") == "false"
        after = twist_pairs(bridge.messages("/cmd_vel")[commands_before:])
        assert after == [(0.0, 0.0)] * len(after) and len(after) <= 1, after

        page.click("#pid-toggle")  # running, and Space (the button focused) stops it
        page.wait_for_selector("#pid-toggle[aria-pressed=true]")
        page.keyboard.press(" ")
        page.wait_for_selector("#pid-toggle[aria-pressed=false]", timeout=2000)
        wait_until_still(bridge)
        assert twist_pairs(bridge.messages("/cmd_vel"))[-1] == (0.0, 0.0)

        page.fill("#ws-url", "")
        page.type("#ws-url", "ws://a b")  # keys typed into a text field stay text
        assert page.input_value("#ws-url") == "ws://a b"
        assert log.page_errors == []
