"""The web interface in a real headless Chromium against a real ``websim serve``.

The browser is Debian's ``/usr/bin/chromium`` driven by Python Playwright (never
``playwright install``: no browser downloads). What the robot did is checked on the bridge with
a raw rosbridge WebSocket client (``/odom``, ``/cmd_vel``, services), not in the page's DOM. The
pure frontend modules (PID, message conversions, connection, teleop, who else drives) are
unit-tested under Node's own test runner (``tests/web/*.test.mjs``).

The page takes every robot fact (topics, limits, parameters) from ``web-interface/robot.json``;
these tests read the same file rather than restating it. The admin token goes only to the
page's own bridge (config.json's, else ws://<page host>:9090): since the test servers listen on
free ports, the admin tests answer config.json naming the test server's bridge, as an
instructor's config.json would.

Screenshots go to ``test-artifacts/`` (gitignored). The PID test also writes the README's
``docs/screenshot.png`` when it is missing or ``UPDATE_SCREENSHOT=1`` is set, so an ordinary
run leaves the committed picture alone.
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import json
import math
import os
import shutil
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import quote, urlsplit

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect
from websockets.sync.server import Request, ServerConnection, serve

from chromium import skip_reason
from server_process import ADMIN_TOKEN, ServerProcess, free_port, start_server, wait_for

ROOT = Path(__file__).resolve().parent.parent
WEB_DIR = ROOT / "web-interface"
ROBOT = json.loads((WEB_DIR / "robot.json").read_text())
"""The robot description the page loads (written by ``websim robot-json``)."""
NODE_TESTS = sorted((Path(__file__).parent / "web").glob("*.test.mjs"))
ARTIFACTS = ROOT / "test-artifacts"
DOCS_SCREENSHOT = ROOT / "docs" / "screenshot.png"

LOCAL_HOSTS = {"127.0.0.1", "localhost"}

NODE = shutil.which("node")
LIBRARIES = [WEB_DIR / "node_modules" / path for path in (
    "roslib/build/roslib.min.js", "uplot/dist/uPlot.esm.js", "nipplejs/dist/index.js")]

SCAN_RGB = (225, 29, 72)
"""view.js COLORS.scan (#e11d48)."""
WALL_RGB = (30, 41, 59)
"""view.js COLORS.wall (#1e293b)."""
DEG = math.pi / 180


BROWSER_SKIP = skip_reason(LIBRARIES)
needs_browser = pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")


# --- A raw rosbridge client: the robot's side of every check -------------------------------

class Bridge:
    """A rosbridge v2 client on one WebSocket, read by a thread: records topics, answers calls."""

    def __init__(self, url: str) -> None:
        self._stack = contextlib.ExitStack()
        self._ws = self._stack.enter_context(connect(url, max_size=None))
        self._lock = threading.Lock()
        self._messages: dict[str, list[dict[str, Any]]] = collections.defaultdict(list)
        self._responses: dict[str, dict[str, Any]] = {}
        self._ids = itertools.count()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        try:
            for frame in self._ws:
                msg = json.loads(frame)
                with self._lock:
                    if msg.get("op") == "publish":
                        self._messages[msg["topic"]].append(msg["msg"])
                    elif msg.get("op") == "service_response":
                        self._responses[msg["id"]] = msg
        except ConnectionClosed:
            pass

    def send(self, **msg: Any) -> None:
        self._ws.send(json.dumps(msg))

    def subscribe(self, topic: str, queue_length: int = 50) -> None:
        self.send(op="subscribe", topic=topic, queue_length=queue_length)

    def messages(self, topic: str) -> list[dict[str, Any]]:
        with self._lock:
            return list(self._messages[topic])

    def call(self, service: str, args: dict[str, Any] | None = None,
             timeout_s: float = 5.0) -> dict[str, Any]:
        call_id = f"call:{next(self._ids)}"
        self.send(op="call_service", id=call_id, service=service, args=args or {})

        def answered() -> dict[str, Any] | None:
            with self._lock:
                return self._responses.pop(call_id, None)

        return dict(wait_for(answered, timeout_s=timeout_s, what=f"the answer of {service}"))

    def parameter(self, name: str) -> Any:
        response = self.call("/virtual_robot/get_parameters", {"names": [name]})
        value = response["values"]["values"][0]
        return value["string_value"] if value["type"] == 4 else value["double_value"]

    def close(self) -> None:
        self._stack.close()
        self._reader.join(timeout=5)


@pytest.fixture(scope="module")
def bridge(server: ServerProcess) -> Iterator[Bridge]:
    client = Bridge(server.ws_url)
    client.subscribe("/odom")
    client.subscribe("/cmd_vel")
    yield client
    client.close()


def latest_odom(bridge: Bridge) -> dict[str, Any]:
    return wait_for(lambda: bridge.messages("/odom")[-1:], what="/odom")[0]


HISTORY_PLOTTED_S = 20.0
"""Seconds the live plots show (state.js HISTORY_S)."""



def drag_up(page: Any, bridge: Bridge, x: float, y: float) -> tuple[dict[str, Any],
                                                                 Callable[[], None]]:
    """Put a finger on the joystick at (x, y) and drag it straight up past the rim.

    Chrome's own touch events (DevTools protocol), as a phone sends them. Returns the first
    /odom that moved forward and what lifts the finger.
    """
    touch = page.context.new_cdp_session(page)

    def finger(kind: str, points: list[dict[str, float]]) -> None:
        touch.send("Input.dispatchTouchEvent", {"type": kind, "touchPoints": points})

    odoms_before = len(bridge.messages("/odom"))
    finger("touchStart", [{"x": x, "y": y}])
    for step in range(1, 11):
        finger("touchMove", [{"x": x, "y": y - 8 * step}])
    moving = wait_for(lambda: [m for m in bridge.messages("/odom")[odoms_before:]
                               if x_of(m) > 0.05], what="the joystick to drive the robot")[0]
    return moving, lambda: finger("touchEnd", [])

def x_of(odom: dict[str, Any]) -> float:
    return float(odom["pose"]["pose"]["position"]["x"])


def yaw_of(odom: dict[str, Any]) -> float:
    q = odom["pose"]["pose"]["orientation"]
    return 2.0 * math.atan2(q["z"], q["w"])


def speed_of(odom: dict[str, Any]) -> float:
    return float(odom["twist"]["twist"]["linear"]["x"])


def reset_robot(bridge: Bridge) -> None:
    """Back to the spawn pose, command zeroed, and wait until odometry shows it."""
    assert bridge.call("/reset_simulation")["result"] is True
    def at_spawn() -> bool:
        odom = latest_odom(bridge)
        return x_of(odom) == 0.0 and yaw_of(odom) == 0.0 and speed_of(odom) == 0.0

    wait_for(at_spawn, what="the reset in /odom")


def wait_until_still(bridge: Bridge, timeout_s: float = 5.0) -> dict[str, Any]:
    """The first /odom at zero speed whose pose the next 0.3 s of odometry does not change."""
    def still() -> dict[str, Any] | None:
        odoms = bridge.messages("/odom")
        last = odoms[-1]
        recent = odoms[-7:]  # 0.3 s at 20 Hz
        if len(recent) == 7 and all(speed_of(m) == 0.0 and x_of(m) == x_of(last)
                                    and yaw_of(m) == yaw_of(last) for m in recent):
            return last
        return None

    return dict(wait_for(still, timeout_s=timeout_s, what="the robot to stand still"))


def twist_pairs(messages: list[dict[str, Any]]) -> list[tuple[float, float]]:
    return [(m["linear"]["x"], m["angular"]["z"]) for m in messages]


# --- The browser ---------------------------------------------------------------------------

@dataclass
class PageLog:
    """What a page did: every request URL (WebSockets too), console errors, uncaught errors."""

    requests: list[str] = field(default_factory=list)
    console_errors: list[str] = field(default_factory=list)
    page_errors: list[str] = field(default_factory=list)

    def foreign_requests(self) -> list[str]:
        return [url for url in self.requests
                if urlsplit(url).scheme not in ("data", "blob", "about")
                and urlsplit(url).hostname not in LOCAL_HOSTS]


def open_page(context: Any, url: str) -> tuple[Any, PageLog]:
    page = context.new_page()
    log = PageLog()
    page.on("request", lambda request: log.requests.append(request.url))
    page.on("websocket", lambda websocket: log.requests.append(websocket.url))
    page.on("console", lambda msg: log.console_errors.append(msg.text)
            if msg.type == "error" else None)
    page.on("pageerror", lambda error: log.page_errors.append(str(error)))
    page.goto(url)
    return page, log


def page_url(server: ServerProcess, path: str = "/", **query: str) -> str:
    params = "&".join(f"{key}={value}" for key, value in {"ws": server.ws_url, **query}.items())
    return f"{server.http_url}{path}?{params}"


def admin_context(browser: Any, server: ServerProcess, **context_options: Any) -> Any:
    """A browser context whose pages get a config.json naming ``server``'s bridge as the
    admin page's own (``adminWs``), as an instructor's config.json would: the admin token
    goes to no other bridge."""
    context = browser.new_context(**context_options)
    config = {"ws": None, "adminWs": server.ws_url}
    context.route(f"{server.http_url}/config.json", lambda route: route.fulfill(
        status=200, content_type="application/json", body=json.dumps(config)))
    return context


@contextlib.contextmanager
def recording_listener() -> Iterator[tuple[str, list[str]]]:
    """A plain WebSocket server on a free port: records the path (with its query) of every
    handshake and holds each connection open, answering nothing. Yields (its URL, the paths)."""
    paths: list[str] = []

    def record(connection: ServerConnection, request: Request) -> None:
        paths.append(request.path)

    def hold(connection: ServerConnection) -> None:
        for _ in connection:
            pass

    port = free_port()
    with serve(hold, "127.0.0.1", port, process_request=record) as listener:
        thread = threading.Thread(target=listener.serve_forever, daemon=True)
        thread.start()
        try:
            yield f"ws://127.0.0.1:{port}/", paths
        finally:
            listener.shutdown()
            thread.join(timeout=5)

@contextlib.contextmanager
def driving_page(browser: Any, bridge: Bridge, url: str,
                 **context_options: Any) -> Iterator[tuple[Any, PageLog]]:
    """The robot back at spawn, the page open in a fresh context, connected and showing
    odometry; the context is closed afterwards."""
    reset_robot(bridge)
    context = browser.new_context(**context_options)
    try:
        page, log = open_page(context, url)
        wait_connected(page)
        wait_for_odom_in_page(page)
        yield page, log
    finally:
        context.close()



def wait_connected(page: Any, timeout_s: float = 15.0) -> None:
    page.wait_for_selector('#conn-status[data-status="connected"]', timeout=timeout_s * 1000)


def wait_for_odom_in_page(page: Any) -> None:
    """The page has odometry: its x readout shows a number."""
    page.wait_for_function(
        "/^-?\\d+\\.\\d{3}$/.test(document.querySelector('[data-readout=x]').textContent)",
        timeout=10000)


def screenshot(page: Any, name: str, full_page: bool = True) -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / name
    page.screenshot(path=str(path), full_page=full_page)
    return path


# --- Tests ---------------------------------------------------------------------------------

@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_frontend_modules_pass_their_node_unit_tests() -> None:
    assert NODE is not None and NODE_TESTS
    result = subprocess.run([NODE, "--test", *map(str, NODE_TESTS)], capture_output=True,
                            text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "# fail 0" in result.stdout


@needs_browser
def test_page_loads_locally_without_errors_and_connects(server: ServerProcess,
                                                        bridge: Bridge, browser: Any) -> None:
    admin = Bridge(server.admin_ws_url)
    limit = admin.call("/virtual_robot/set_parameters", {"parameters": [
        {"name": "max_linear_mps", "value": {"type": 3, "double_value": 0.45}}]})
    assert limit["values"]["results"][0]["successful"] is True
    context = browser.new_context(viewport={"width": 1280, "height": 860},
                                  device_scale_factor=2)
    try:
        page, log = open_page(context, page_url(server))
        wait_connected(page)
        wait_for_odom_in_page(page)
        page.wait_for_function(  # the speed slider is bounded by the robot's own limit
            "document.querySelector('#speed-linear').max === '0.45'", timeout=10000)
        assert page.input_value("#ws-url") == server.ws_url  # ?ws= honoured
        assert page.is_hidden("#fatal")
        assert page.is_hidden("#view-message")
        canvas = page.evaluate(
            "(() => { const c = document.querySelector('#view'), r = c.getBoundingClientRect();"
            " return [c.width, r.width, c.height, r.height]; })()")
        # HiDPI: the backing store has devicePixelRatio (2) pixels per CSS pixel.
        assert canvas[0] == round(2 * canvas[1]) and canvas[2] == round(2 * canvas[3])
        screenshot(page, "main-connected.png")
        assert log.console_errors == [] and log.page_errors == []
        assert any(url.endswith("/node_modules/uplot/dist/uPlot.esm.js") for url in log.requests)
        assert f"{server.http_url}/robot.json" in log.requests
        assert log.foreign_requests() == []
    finally:
        context.close()
        admin.call("/virtual_robot/set_parameters", {"parameters": [
            {"name": "max_linear_mps", "value": {"type": 3, "double_value": 0.5}}]})
        admin.close()


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
def test_plots_pause_zoom_and_save_their_samples_as_csv(server: ServerProcess, bridge: Bridge,
                                                     browser: Any) -> None:
    with driving_page(browser, bridge, page_url(server),
                      viewport={"width": 1280, "height": 860}) as (page, log):
        plotted = "window.websim.plots.charts[0].plot.data[0].length"
        page.wait_for_function(f"{plotted} > 10", timeout=10000)
        page.click("#plots .plot-tools button:text('Pause')")
        frozen = page.evaluate(plotted)
        samples = page.evaluate("window.websim.state.history.t.length")
        page.wait_for_function(f"window.websim.state.history.t.length > {samples + 10}",
                               timeout=10000)
        assert page.evaluate(plotted) == frozen  # paused: the samples go on, the chart not
        chart = page.locator("#plots .plot .u-over").first  # uPlot's drag-to-zoom surface
        box = chart.bounding_box()
        assert box is not None
        page.mouse.move(box["x"] + 0.5 * box["width"], box["y"] + box["height"] / 2)
        page.mouse.down()
        page.mouse.move(box["x"] + 0.9 * box["width"], box["y"] + box["height"] / 2, steps=5)
        page.mouse.up()
        x_min, x_max = page.evaluate("[window.websim.plots.charts[0].plot.scales.x.min, "
                                     "window.websim.plots.charts[0].plot.scales.x.max]")
        assert x_max - x_min < 0.6 * HISTORY_PLOTTED_S, (x_min, x_max)  # zoomed: 40 % of it
        assert x_min > -0.6 * HISTORY_PLOTTED_S, (x_min, x_max)
        with page.expect_download() as download:
            page.click("#plots .plot-tools button:text('CSV')")
        text = Path(download.value.path()).read_text()
        rows = text.strip().splitlines()
        assert rows[0].startswith("stamp_s,v_cmd_mps,v_mps")
        assert len(rows) > samples
        page.click("#plots .plot-tools button:text('Resume')")
        page.wait_for_function(f"{plotted} > {frozen}", timeout=10000)
        assert log.page_errors == []


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
def test_dead_bridge_shows_a_message_and_the_default_url(server: ServerProcess,
                                                         browser: Any) -> None:
    context = browser.new_context()
    try:
        dead = f"ws://127.0.0.1:{free_port()}"
        page, log = open_page(context, f"{server.http_url}/?ws={dead}")
        page.wait_for_selector('#conn-status[data-status="error"]', timeout=10000)
        message = page.wait_for_selector("#view-message:not([hidden])", timeout=5000)
        assert f"Cannot reach the bridge at {dead}." in message.text_content()
        assert page.is_hidden("#fatal") and page.is_visible("#view")
        assert log.page_errors == []
        screenshot(page, "main-dead-bridge.png", full_page=False)
        page.goto(f"{server.http_url}/")
        # The field is filled once config.json and robot.json have loaded: without ?ws=, the
        # bridge of the server that served the page (its config.json), not 9090.
        page.wait_for_function("document.querySelector('#ws-url').value !== ''", timeout=5000)
        assert page.input_value("#ws-url") == server.ws_url
    finally:
        context.close()


@needs_browser
def test_ws_parameter_and_reconnect_after_a_server_restart(browser: Any) -> None:
    first = start_server()
    ws_port, http_port = first.ws_port, first.http_port
    second: ServerProcess | None = None
    context = browser.new_context()
    try:
        page, _ = open_page(context, page_url(first))
        wait_connected(page)
        wait_for_odom_in_page(page)
        first.stop()
        page.wait_for_selector('#conn-status:is([data-status="closed"], [data-status="error"])',
                               timeout=10000)
        second = start_server(ws_port=ws_port, http_port=http_port)
        wait_connected(page, timeout_s=20)
        back_ms = page.evaluate("performance.now()")
        page.wait_for_function(  # odometry flows again: the subscriptions came back
            "t => window.websim.state.odomAtMs > t", arg=back_ms, timeout=10000)
        check = Bridge(second.ws_url)
        try:
            check.subscribe("/odom")
            page.keyboard.down("ArrowUp")  # and the page's publisher works on the new bridge
            wait_for(lambda: check.messages("/odom")
                     and x_of(check.messages("/odom")[-1]) > 0.05, what="motion after restart")
            page.keyboard.up("ArrowUp")
            wait_until_still(check)
        finally:
            check.close()
    finally:
        context.close()
        first.stop()
        if second is not None:
            second.stop()


@needs_browser
def test_a_page_without_ws_drives_the_robot_of_the_server_that_served_it(browser: Any) -> None:
    """Two servers on one host, neither on 9090: each page dials its own server's bridge
    (config.json, filled by that server), and its Admin link keeps a ?ws= it was given."""
    first, second = start_server(), start_server()
    context = browser.new_context()
    watch_first, watch_second = Bridge(first.ws_url), Bridge(second.ws_url)
    try:
        watch_first.subscribe("/odom")
        watch_second.subscribe("/odom")
        page, log = open_page(context, f"{second.http_url}/")
        wait_connected(page)
        page.keyboard.down("ArrowUp")
        wait_for(lambda: watch_second.messages("/odom")
                 and x_of(watch_second.messages("/odom")[-1]) > 0.05, what="second robot moving")
        page.keyboard.up("ArrowUp")
        assert watch_first.messages("/odom") and abs(x_of(watch_first.messages("/odom")[-1])) \
            < 1e-6, "the page drove the other server's robot"
        page.goto(page_url(first))  # given a ?ws=: the Admin link keeps it
        wait_connected(page)
        page.click("nav a")
        page.wait_for_url("**/admin?ws=*", timeout=10000)
        assert urlsplit(page.url).query == f"ws={quote(first.ws_url, safe='')}"
        assert not log.page_errors, log.page_errors
    finally:
        watch_first.close()
        watch_second.close()
        context.close()
        first.stop()
        second.stop()


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


def runtime_parameters() -> list[dict[str, Any]]:
    return [spec for spec in ROBOT["parameters"] if spec["runtime"]]


@needs_browser
def test_admin_changes_mass_with_the_token(server: ServerProcess, bridge: Bridge,
                                           browser: Any) -> None:
    context = admin_context(browser, server, viewport={"width": 1280, "height": 860})
    try:
        page, log = open_page(context, f"{server.http_url}/admin?token={ADMIN_TOKEN}")
        wait_connected(page)
        assert "token" not in page.url  # stored, then taken out of the address bar
        assert page.evaluate("sessionStorage.getItem('websim.adminToken')") == ADMIN_TOKEN
        assert f"{server.ws_url}?token={ADMIN_TOKEN}" in log.requests  # its own bridge got it
        assert page.is_visible('#token-state[data-kind="ok"]')
        page.wait_for_selector("#params-form[data-loaded]")
        # The form is robot.json's runtime parameters, each bounded by its range.
        fields = page.eval_on_selector_all("[data-param]", """inputs => inputs.map(
            (input) => [input.dataset.param, input.min ?? '', input.max ?? ''])""")
        assert [name for name, _, _ in fields] == [s["name"] for s in runtime_parameters()]
        for (_, low, high), spec in zip(fields, runtime_parameters(), strict=True):
            assert (float(low) if low else None) == spec["minimum"], spec["name"]
            assert (float(high) if high else None) == spec["maximum"], spec["name"]
        assert page.input_value("#param-mass_kg") == "1.2"
        assert page.input_value("#param-mode") == "kinematic"
        # Out of range: the browser refuses it, and nothing is sent.
        page.evaluate("""() => {
            const connection = window.websim.connection, call = connection.callService;
            window.calls = [];
            connection.callService = (name, ...rest) => {
                window.calls.push(name);
                return call.call(connection, name, ...rest);
            };
        }""")
        mass = next(s for s in runtime_parameters() if s["name"] == "mass_kg")
        page.fill("#param-mass_kg", str(mass["maximum"] * 10))
        page.click("#params-apply")
        assert page.evaluate("document.querySelector('#param-mass_kg').validity.rangeOverflow")
        assert page.evaluate("window.calls") == []
        page.fill("#param-mass_kg", "2.5")
        page.click("#params-apply")
        notice = page.wait_for_selector('#params-notice[data-kind="ok"]', timeout=10000)
        assert "mass_kg = 2.5" in notice.text_content()
        assert page.evaluate("window.calls")[0] == ROBOT["services"]["set_parameters"]["name"]
        assert bridge.parameter("mass_kg") == 2.5
        page.reload()  # the token is asked once per tab: it is still there
        wait_connected(page)
        assert page.is_hidden("#token-form")
        page.wait_for_selector("#params-form[data-loaded]")
        assert page.input_value("#param-mass_kg") == "2.5"
        wait_for_odom_in_page(page)
        screenshot(page, "admin.png")
        page.fill("#param-mass_kg", "1.2")
        page.click("#params-apply")
        page.wait_for_selector('#params-notice[data-kind="ok"]', timeout=10000)
        assert log.console_errors == [] and log.page_errors == []
        assert log.foreign_requests() == []
    finally:
        context.close()
    assert bridge.parameter("mass_kg") == 1.2


@needs_browser
def test_admin_without_the_token_shows_the_refusal(server: ServerProcess, bridge: Bridge,
                                                   browser: Any) -> None:
    context = admin_context(browser, server, viewport={"width": 1280, "height": 860})
    try:
        page, _ = open_page(context, f"{server.http_url}/admin")
        wait_connected(page)
        assert page.is_visible("#token-form")
        page.wait_for_selector("#params-form[data-loaded]")
        page.fill("#param-mass_kg", "3")
        page.click("#params-apply")
        notice = page.wait_for_selector('#params-notice[data-kind="error"]', timeout=10000)
        assert "set_parameters needs admin rights" in notice.text_content()
        page.fill("#token-input", "not-the-token")  # a wrong token: refused the same way
        page.click("#token-form button[type=submit]")
        wait_connected(page)
        page.wait_for_selector("#params-form[data-loaded]")
        page.evaluate("document.querySelector('#params-notice').hidden = true")
        page.fill("#param-mass_kg", "3")
        page.click("#params-apply")
        notice = page.wait_for_selector('#params-notice[data-kind="error"]', timeout=10000)
        assert "needs admin rights" in notice.text_content()
        assert page.is_visible('#token-state[data-kind="error"]')  # says the token is wrong
        assert page.is_visible("#token-form")  # and asks again
        screenshot(page, "admin-refused.png")
    finally:
        context.close()
    assert bridge.parameter("mass_kg") == 1.2


@needs_browser
def test_admin_sends_no_token_to_a_bridge_named_by_a_link(server: ServerProcess,
                                                           browser: Any) -> None:
    with recording_listener() as (other_url, paths):
        context = admin_context(browser, server, viewport={"width": 1280, "height": 860})
        try:
            page, log = open_page(context, f"{server.http_url}/admin?token={ADMIN_TOKEN}")
            wait_connected(page)  # the instructor's tab holds the token now
            page.goto(f"{server.http_url}/admin?ws={other_url}")  # then follows a link
            wait_connected(page)
            notice = page.wait_for_selector('#token-state[data-kind="warn"]', timeout=5000)
            text = notice.text_content() or ""
            assert f"Connected to {other_url} from the link" in text
            assert "your admin token is only sent to this page's own server" in text
            assert server.ws_url in text
            page.click("#token-forget")  # a token typed into the form is not sent there either
            wait_for(lambda: len(paths) >= 2, what="the reconnect without a token")
            page.fill("#token-input", "typed-token")
            page.click("#token-form button[type=submit]")
            wait_for(lambda: len(paths) >= 3, what="the reconnect after typing a token")
            wait_connected(page)
            assert page.is_visible('#token-state[data-kind="warn"]')
            screenshot(page, "admin-linked-bridge.png")
            page.fill("#ws-url", server.ws_url)  # the own bridge, typed: it gets the token
            page.click("#connect-form button[type=submit]")
            wait_connected(page)
            page.wait_for_selector('#token-state[data-kind="ok"]', timeout=5000)
            assert f"{server.ws_url}?token=typed-token" in log.requests
        finally:
            context.close()
    assert len(paths) >= 3
    assert [path for path in paths if "token=" in path] == []
    assert [url for url in log.requests if url.startswith(other_url) and "token=" in url] == []


@needs_browser
def test_pages_without_robot_json_say_so_and_guess_nothing(server: ServerProcess,
                                                           browser: Any) -> None:
    context = browser.new_context()
    context.route(f"{server.http_url}/robot.json",
                  lambda route: route.fulfill(status=404, body="missing"))
    try:
        for path in ("/", "/admin"):
            page, log = open_page(context, page_url(server, path))
            banner = page.wait_for_selector("#fatal:not([hidden])", timeout=10000)
            assert "robot.json" in (banner.text_content() or ""), path
            assert "HTTP 404" in (banner.text_content() or ""), path
            assert [url for url in log.requests if url.startswith("ws")] == [], path
            assert log.page_errors == [], path
    finally:
        context.close()


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
