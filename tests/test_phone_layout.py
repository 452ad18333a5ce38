"""The student page and /admin on a phone, upright and sideways, in a real headless Chromium
against a real ``websim serve``.

Each phone is a Playwright context with a touch screen (``has_touch``, ``is_mobile``: the page
sees ``pointer: coarse``) at a common phone's size in CSS px. On each: the joystick is on the
first screen (sideways, Stop and the speed sliders beside it too), every control a finger can
use is at least ``TOUCH_TARGET_PX`` square, the PID panel's status is never cut off, and nothing
sticks out sideways; sideways, a drag on the joystick drives the robot, as seen on the bridge
(``/odom``, ``/cmd_vel``). The bridge client and page helpers come from page_helpers.py.

Screenshots go to ``test-artifacts/phone-*.png``. They show the screen only (not the full page):
for a full-page picture Playwright resizes the viewport, which then is neither sideways nor, in
this Chromium, a touch screen any more.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from page_helpers import (
    LIBRARIES,
    Bridge,
    admin_context,
    drag_up,
    driving_page,
    page_url,
    screenshot,
    speed_of,
    twist_pairs,
    wait_connected,
    wait_until_still,
    x_of,
    yaw_of,
)

from chromium import skip_reason
from server_process import ServerProcess

BROWSER_SKIP = skip_reason(LIBRARIES)
pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")]

TOUCH_TARGET_PX = 44.0
"""The smallest touch target, CSS px square (WCAG 2.5.5, Apple's Human Interface Guidelines)."""
SUBPIXEL_PX = 0.01
"""Layout rounding allowed in a measured size, CSS px."""


@dataclass(frozen=True)
class Phone:
    """A phone's screen in CSS px, as its browser lays the page out."""

    name: str
    width_px: int
    height_px: int

    @property
    def sideways(self) -> bool:
        return self.width_px > self.height_px

    def context_options(self) -> dict[str, Any]:
        return {"viewport": {"width": self.width_px, "height": self.height_px},
                "has_touch": True, "is_mobile": True, "device_scale_factor": 3}


PHONES = [Phone("portrait-390x844", 390, 844), Phone("portrait-360x740", 360, 740),
          Phone("landscape-844x390", 844, 390), Phone("landscape-740x360", 740, 360)]
SIDEWAYS = [phone for phone in PHONES if phone.sideways]

INTERACTIVE = ", ".join([
    "a[href]", "button", "input", "select", "textarea", "summary", "[role=button]",
    "[tabindex]:not([tabindex='-1'])",
    ".u-legend .u-series th",  # uPlot's legend: a tap hides or shows that line
    "#joystick",
])
"""Everything on the pages a finger can use."""

FIRST_SCREEN = {False: ["#joystick"],
                True: ["#joystick", ".pad-stop", "#speed-linear", "#speed-angular"]}
"""What must be on the first screen, unscrolled: upright, sideways."""

BOXES_JS = """(selector) => [...document.querySelectorAll(selector)].flatMap((el) => {
  const r = el.getBoundingClientRect();
  if (!el.getClientRects().length || r.width === 0 || r.height === 0
      || getComputedStyle(el).visibility === 'hidden') return [];
  const text = (el.getAttribute('aria-label') || el.textContent || '').trim().slice(0, 24);
  const name = el.tagName.toLowerCase() + (el.id ? '#' + el.id : '')
    + (el.type ? `[type=${el.type}]` : '') + (text ? ` "${text}"` : '');
  return [{name, x: r.x, y: r.y, width: r.width, height: r.height}];
})"""
"""The visible elements matching a selector: {name, x, y, width, height} (CSS px, viewport)."""

STATUS_JS = """(el) => ({
  text: el.textContent,
  scrollWidth: el.scrollWidth, clientWidth: el.clientWidth,
  scrollHeight: el.scrollHeight, clientHeight: el.clientHeight,
  clipping: [el, el.parentElement].map((e) => getComputedStyle(e))
    .filter((s) => s.overflowX !== 'visible' || s.overflowY !== 'visible'
                   || s.textOverflow === 'ellipsis')
    .map((s) => `${s.overflowX}/${s.overflowY}/${s.textOverflow}`),
})"""
"""How the PID status element holds its text: sizes (CSS px) and any clipping style on it or
its container."""


@pytest.fixture(scope="module")
def bridge(server: ServerProcess) -> Iterator[Bridge]:
    client = Bridge(server.ws_url)
    client.subscribe("/odom")
    client.subscribe("/cmd_vel")
    yield client
    client.close()


def boxes(page: Any, selector: str) -> list[dict[str, Any]]:
    return list(page.evaluate(BOXES_JS, selector))


def small_targets(page: Any) -> list[str]:
    """Each visible control under TOUCH_TARGET_PX in either side, as 'name: W x H'."""
    return [f"{box['name']}: {box['width']:.1f} x {box['height']:.1f}"
            for box in boxes(page, INTERACTIVE)
            if min(box["width"], box["height"]) < TOUCH_TARGET_PX - SUBPIXEL_PX]


def off_screen(page: Any, phone: Phone, selectors: list[str]) -> list[str]:
    """Of ``selectors``' elements, each not wholly inside the screen, with its box."""
    outside = []
    for selector in selectors:
        found = boxes(page, selector)
        assert found, f"{selector} is not shown"
        for box in found:
            if (box["x"] < -SUBPIXEL_PX or box["y"] < -SUBPIXEL_PX
                    or box["x"] + box["width"] > phone.width_px + SUBPIXEL_PX
                    or box["y"] + box["height"] > phone.height_px + SUBPIXEL_PX):
                outside.append(f"{box['name']} at ({box['x']:.0f}, {box['y']:.0f}) "
                               f"{box['width']:.0f} x {box['height']:.0f}")
    return outside


def overflow_px(page: Any, phone: Phone) -> float:
    """How far (CSS px) the page is wider than the screen: 0 when nothing sticks out."""
    width = page.evaluate("Math.max(document.documentElement.scrollWidth,"
                          " document.body.scrollWidth)")
    return max(0.0, float(width) - phone.width_px)


def status_when(page: Any, part: str) -> dict[str, Any]:
    """STATUS_JS of #pid-status, measured the moment its text contains ``part``."""
    handle = page.wait_for_function(
        f"""() => {{ const s = document.querySelector('#pid-status');
                    return s.textContent.includes({json.dumps(part)}) && ({STATUS_JS})(s); }}""",
        timeout=15000)
    return dict(handle.json_value())


def assert_status_not_cut(status: dict[str, Any]) -> None:
    assert status["clipping"] == [], status
    assert status["scrollWidth"] <= status["clientWidth"], status
    assert status["scrollHeight"] <= status["clientHeight"], status


def first_screen(page: Any) -> None:
    page.evaluate("window.scrollTo(0, 0)")
    page.wait_for_function("window.scrollY === 0 && window.scrollX === 0")


# --- Tests ---------------------------------------------------------------------------------

@pytest.mark.parametrize("phone", PHONES, ids=[phone.name for phone in PHONES])
def test_main_page_fits_a_phone(server: ServerProcess, bridge: Bridge, browser: Any,
                                phone: Phone) -> None:
    with driving_page(browser, bridge, page_url(server),
                      **phone.context_options()) as (page, log):
        assert page.is_visible("#joystick") and page.is_hidden('[data-drive="forward"]')
        assert page.evaluate("window.scrollY") == 0
        assert off_screen(page, phone, FIRST_SCREEN[phone.sideways]) == []
        screenshot(page, f"phone-main-{phone.name}.png", full_page=False)

        page.fill("#pid-setpoint", "")  # a form error: the longest status, a sentence
        page.tap("#pid-toggle")
        assert_status_not_cut(status_when(page, "the setpoint must be a number"))
        page.fill("#pid-kp", "30")  # a half turn at this gain: saturated most of the way
        page.fill("#pid-setpoint", "180")
        page.tap("#pid-toggle")
        assert_status_not_cut(status_when(page, "running (saturated)"))
        page.locator("#pid-status").scroll_into_view_if_needed()
        screenshot(page, f"phone-main-pid-{phone.name}.png", full_page=False)
        page.tap("#pid-toggle")
        page.wait_for_selector("#pid-toggle[aria-pressed=false]")

        assert small_targets(page) == [], f"under {TOUCH_TARGET_PX:.0f} x " \
            f"{TOUCH_TARGET_PX:.0f} CSS px on a {phone.name} phone"
        assert overflow_px(page, phone) == 0
        first_screen(page)  # the tap scrolled: the first screen again, as it was
        assert off_screen(page, phone, FIRST_SCREEN[phone.sideways]) == []
        assert log.console_errors == [] and log.page_errors == []
    wait_until_still(bridge)


@pytest.mark.parametrize("phone", SIDEWAYS, ids=[phone.name for phone in SIDEWAYS])
def test_sideways_the_joystick_beside_the_view_drives_without_scrolling(
        server: ServerProcess, bridge: Bridge, browser: Any, phone: Phone) -> None:
    with driving_page(browser, bridge, page_url(server),
                      **phone.context_options()) as (page, log):
        assert page.evaluate("window.scrollY") == 0
        assert off_screen(page, phone, FIRST_SCREEN[True]) == []
        view, = boxes(page, "#view")
        zone, = boxes(page, "#joystick")
        assert zone["x"] >= view["x"] + view["width"]  # beside the view, not under it
        x, y = zone["x"] + zone["width"] / 2, zone["y"] + zone["height"] / 2
        moving, lift = drag_up(page, bridge, x, y)
        assert page.evaluate("window.scrollY") == 0  # the drag moved the robot, not the page
        screenshot(page, f"phone-joystick-{phone.name}.png", full_page=False)
        lift()
        stopped = wait_until_still(bridge)
        assert twist_pairs(bridge.messages("/cmd_vel"))[-1] == (0.0, 0.0)
        assert log.console_errors == [] and log.page_errors == []
    assert speed_of(moving) > 0.1  # forward
    assert abs(yaw_of(stopped)) < 0.05  # straight up: hardly any turning
    assert x_of(stopped) > 0.05


@pytest.mark.parametrize("phone", PHONES, ids=[phone.name for phone in PHONES])
def test_admin_page_fits_a_phone(server: ServerProcess, browser: Any, phone: Phone) -> None:
    context = admin_context(browser, server, **phone.context_options())
    try:
        page = context.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto(f"{server.http_url}/admin")
        wait_connected(page)
        page.wait_for_selector("#params-form[data-loaded]")
        assert page.is_visible("#token-form")
        screenshot(page, f"phone-admin-{phone.name}.png", full_page=False)
        assert small_targets(page) == [], f"under {TOUCH_TARGET_PX:.0f} x " \
            f"{TOUCH_TARGET_PX:.0f} CSS px on a {phone.name} phone"
        assert overflow_px(page, phone) == 0
        assert errors == []
    finally:
        context.close()
