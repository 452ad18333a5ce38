"""The web interface's tests' helpers: a raw rosbridge client and the page in Chromium.

The browser is Debian's ``/usr/bin/chromium`` driven by Python Playwright (never
``playwright install``: no browser downloads). What the robot did is checked on the bridge with
a raw rosbridge WebSocket client (``Bridge``: ``/odom``, ``/cmd_vel``, services), not in the
page's DOM; conftest.py's ``bridge`` fixture is one on the module's server.

The page takes every robot fact (topics, limits, parameters) from ``web-interface/robot.json``;
the tests read the same file (``ROBOT``) rather than restating it. The admin token goes only to
the page's own bridge (config.json's, else ws://<page host>:9090): since the test servers listen
on free ports, the admin tests answer config.json naming the test server's bridge
(``admin_context``), as an instructor's config.json would.

Screenshots go to ``test-artifacts/`` (gitignored).
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import json
import math
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from chromium import skip_reason
from server_process import ServerProcess, wait_for

ROOT = Path(__file__).resolve().parent.parent
WEB_DIR = ROOT / "web-interface"
ROBOT = json.loads((WEB_DIR / "robot.json").read_text())
"""The robot description the page loads (written by ``websim robot-json``)."""
ARTIFACTS = ROOT / "test-artifacts"

LOCAL_HOSTS = {"127.0.0.1", "localhost"}

LIBRARIES = [WEB_DIR / "node_modules" / path for path in (
    "roslib/build/roslib.min.js", "uplot/dist/uPlot.esm.js", "nipplejs/dist/index.js")]

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


def latest_odom(bridge: Bridge) -> dict[str, Any]:
    return wait_for(lambda: bridge.messages("/odom")[-1:], what="/odom")[0]


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
