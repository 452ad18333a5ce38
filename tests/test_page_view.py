"""The student page's view (the canvas) in a real headless Chromium: the scan is drawn on
the walls, also while the robot turns. Checked by the colours of the canvas's pixels.
"""

from __future__ import annotations

import threading
from typing import Any

from page_helpers import (
    Bridge,
    latest_odom,
    needs_browser,
    open_page,
    page_url,
    reset_robot,
    screenshot,
    wait_connected,
)

from server_process import ServerProcess, start_server, wait_for

SCAN_RGB = (225, 29, 72)
"""view.js COLORS.scan (#e11d48)."""
WALL_RGB = (30, 41, 59)
"""view.js COLORS.wall (#1e293b)."""


def _pixel_boxes(page: Any) -> dict[str, Any]:
    """Counts and bounding boxes (device px) of the scan's and the walls' colours."""
    return dict(page.evaluate(
        """([scan, wall]) => {
          const c = document.querySelector('#view');
          const data = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
          const boxes = {scan: {n: 0, x0: 1e9, y0: 1e9, x1: -1, y1: -1},
                         wall: {n: 0, x0: 1e9, y0: 1e9, x1: -1, y1: -1}};
          const near = (i, rgb) => Math.abs(data[i] - rgb[0]) <= 12
            && Math.abs(data[i + 1] - rgb[1]) <= 12 && Math.abs(data[i + 2] - rgb[2]) <= 12;
          for (let i = 0; i < data.length; i += 4) {
            for (const [name, rgb] of [['scan', scan], ['wall', wall]]) {
              if (!near(i, rgb)) continue;
              const b = boxes[name], p = i / 4, x = p % c.width, y = Math.floor(p / c.width);
              b.n += 1; b.x0 = Math.min(b.x0, x); b.x1 = Math.max(b.x1, x);
              b.y0 = Math.min(b.y0, y); b.y1 = Math.max(b.y1, y);
            }
          }
          return boxes;
        }""", [list(SCAN_RGB), list(WALL_RGB)]))


@needs_browser
def test_scan_points_are_drawn_on_the_walls(server: ServerProcess, bridge: Bridge,
                                            browser: Any) -> None:
    reset_robot(bridge)
    context = browser.new_context(viewport={"width": 1280, "height": 860})
    try:
        page, _ = open_page(context, page_url(server))
        wait_connected(page)
        boxes = wait_for(lambda: (b := _pixel_boxes(page))["scan"]["n"] > 300
                         and b["wall"]["n"] > 300 and b, timeout_s=10,
                         what="scan and wall pixels on the canvas")
    finally:
        context.close()
    scan, wall = boxes["scan"], boxes["wall"]
    # The robot is at the centre of the 6 m square; every return lies on a wall, and the
    # returns reach all four walls (only the corners, beyond 3.5 m, are out of range).
    tolerance_px = 4
    assert scan["x0"] >= wall["x0"] - tolerance_px and scan["x1"] <= wall["x1"] + tolerance_px
    assert scan["y0"] >= wall["y0"] - tolerance_px and scan["y1"] <= wall["y1"] + tolerance_px
    assert scan["x1"] - scan["x0"] > 0.9 * (wall["x1"] - wall["x0"])
    assert scan["y1"] - scan["y0"] > 0.9 * (wall["y1"] - wall["y0"])


def _scan_pixels_on_walls(page: Any, tolerance_px: int) -> dict[str, float]:
    """Of the scan-coloured pixels, the share within ``tolerance_px`` of the walls' bounding
    box's edges (the empty arena: its four walls are that box)."""
    return dict(page.evaluate(
        """([scan, wall, tol]) => {
          const c = document.querySelector('#view');
          const data = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
          const near = (i, rgb) => Math.abs(data[i] - rgb[0]) <= 12
            && Math.abs(data[i + 1] - rgb[1]) <= 12 && Math.abs(data[i + 2] - rgb[2]) <= 12;
          const box = {x0: 1e9, y0: 1e9, x1: -1, y1: -1};
          const points = [];
          for (let i = 0; i < data.length; i += 4) {
            const p = i / 4, x = p % c.width, y = Math.floor(p / c.width);
            if (near(i, wall)) {
              box.x0 = Math.min(box.x0, x); box.x1 = Math.max(box.x1, x);
              box.y0 = Math.min(box.y0, y); box.y1 = Math.max(box.y1, y);
            } else if (near(i, scan)) points.push([x, y]);
          }
          const onWall = points.filter(([x, y]) => Math.min(Math.abs(x - box.x0),
            Math.abs(x - box.x1), Math.abs(y - box.y0), Math.abs(y - box.y1)) <= tol).length;
          return {n: points.length, share: points.length ? onWall / points.length : 0};
        }""", [list(SCAN_RGB), list(WALL_RGB), tolerance_px]))


@needs_browser
def test_a_turning_robots_scan_is_drawn_on_the_walls(server: ServerProcess, bridge: Bridge,
                                                     browser: Any) -> None:
    """At 2 rad/s a scan drawn at the robot's pose of the moment would swing off the walls
    (the scan is up to a tenth of a second old: ~10 degrees, tens of pixels); drawn at the pose
    of its stamp, it stays on them."""
    reset_robot(bridge)
    context = browser.new_context(viewport={"width": 1280, "height": 860})
    turning = threading.Event()

    def turn() -> None:
        while not turning.is_set():
            bridge.send(op="publish", topic="/cmd_vel", msg={
                "linear": {"x": 0.0, "y": 0.0, "z": 0.0},
                "angular": {"x": 0.0, "y": 0.0, "z": 2.0}})
            turning.wait(0.1)

    driver = threading.Thread(target=turn, daemon=True)
    try:
        page, _ = open_page(context, page_url(server))
        wait_connected(page)
        driver.start()
        wait_for(lambda: abs(latest_odom(bridge)["twist"]["twist"]["angular"]["z"] - 2.0) < 1e-6,
                 what="the robot turning at 2 rad/s")
        samples = []
        for _ in range(12):  # frames at different phases of the scan's age
            page.wait_for_timeout(70)
            sample = _scan_pixels_on_walls(page, tolerance_px=6)
            if sample["n"] > 200:
                samples.append(sample["share"])
    finally:
        turning.set()
        driver.join(timeout=5)
        bridge.send(op="publish", topic="/cmd_vel", msg={
            "linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}})
        context.close()
    assert len(samples) >= 8, samples
    assert min(samples) >= 0.9, samples


@needs_browser
def test_while_the_bridge_is_down_the_view_keeps_the_last_world_and_says_it_is_stale(
        browser: Any) -> None:
    """The ground truth stops with the bridge: the view keeps the map frame, its walls and
    its zoom, and says the picture is stale, instead of re-zooming onto odometry alone."""
    server = start_server()
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    try:
        page, log = open_page(context, page_url(server))
        wait_connected(page)
        live = wait_for(lambda: (b := _pixel_boxes(page))["wall"]["n"] > 300 and b,
                        timeout_s=10, what="the walls on the canvas")["wall"]
        scale = page.evaluate("window.websim.view.camera.scale")
        assert page.is_hidden("#view-stale")
        server.stop()
        page.wait_for_selector('#conn-status:is([data-status="closed"], [data-status="error"],'
                               ' [data-status="connecting"])', timeout=10000)
        page.wait_for_timeout(2500)  # ground truth is stale after 1 s
        down = _pixel_boxes(page)["wall"]
        # the walls are still drawn where they were (before: none); how many of their pixels
        # the kept scan's points cover varies with the moment the picture was kept
        assert down["n"] > 0.4 * live["n"], (live, down)
        assert (down["x0"], down["y0"], down["x1"], down["y1"]) == (
            live["x0"], live["y0"], live["x1"], live["y1"])
        assert page.evaluate("window.websim.view.camera.scale") == scale
        note = page.wait_for_selector("#view-stale:not([hidden])", timeout=2000)
        assert "stale" in (note.text_content() or "").lower()
        screenshot(page, "main-bridge-down.png", full_page=False)
        assert log.page_errors == []
    finally:
        context.close()
        server.stop()
