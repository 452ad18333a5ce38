"""A class spread over two worker processes behind the real nginx, routed by robot name.

``websim nginx-config`` writes the configuration; the real nginx binary runs it in front of
two ``websim serve --class ROSTER --worker`` processes on loopback. Every robot of a
20-student roster is reachable through nginx at its URL, lives on exactly one worker, and
the same name always lands on the same worker; the pages come through nginx too and name
nginx's port as their bridge. Each worker's root view (the instructor's) is reachable through
nginx at ``/workers/K/``, listed by ``/workers.json``, and the dashboard at ``/class`` behind
nginx (in a real headless Chromium) shows the robots of both workers and resets a robot on
the second one.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import socket
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from deployment import NGINX, running_nginx
from websockets.exceptions import InvalidStatus
from websockets.sync.client import ClientConnection
from websockets.sync.client import connect as connect_sync
from websockets.typing import Origin

from classroom.nginx_config import Worker

from chromium import skip_reason
from server_process import ADMIN_TOKEN, ServerProcess, free_port, start_server, wait_for

pytestmark = pytest.mark.skipif(NGINX is None, reason="nginx not installed")

NAMES = [f"student{index:02d}" for index in range(1, 21)]
SPARES = ["spare01", "spare02"]
"""On the roster too, but nobody connects to them: no worker makes them."""

WEB_DIR = Path(__file__).resolve().parent.parent / "web-interface"
BROWSER_SKIP = skip_reason([WEB_DIR / "node_modules" / "roslib" / "build" / "roslib.min.js"])
needs_browser = pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")


def token_of(name: str) -> str:
    """Student ``name``'s token, as the roster gives it."""
    return f"Token-of-{name}-2026"


@dataclass
class Proxy:
    http_port: int
    ws_port: int
    workers: list[ServerProcess]


@pytest.fixture(scope="module")
def proxy(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Proxy]:
    directory = tmp_path_factory.mktemp("scale")
    roster = directory / "roster.txt"
    # each worker keeps its own class secret: tokens the same whichever worker hosts a robot
    # come from the roster (name,,token)
    roster.write_text("\n".join(f"{name},,{token_of(name)}" for name in NAMES + SPARES)
                      + "\n")
    http_port, ws_port = free_port(), free_port()
    workers = [start_server(["--class", str(roster), "--worker", "--public-ws-port",
                             str(ws_port), "--public-http-port", str(http_port)])
               for _ in range(2)]
    try:
        with running_nginx(directory, [Worker("127.0.0.1", w.http_port, w.ws_port)
                                       for w in workers], http_port, ws_port):
            yield Proxy(http_port, ws_port, workers)
    finally:
        for worker in workers:
            worker.stop()


def odom_through(proxy: Proxy, name: str) -> dict[str, Any]:
    """One /odom message of robot ``name``, read through nginx.

    Synchronous (websockets' sync client): Playwright's sync API, once the browser runs,
    holds an event loop in this thread, where ``asyncio.run`` would refuse to start.
    """
    with connect_sync(f"ws://127.0.0.1:{proxy.ws_port}/robots/{name}", open_timeout=5) as ws:
        ws.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
        while True:
            message = json.loads(ws.recv(timeout=5))
            if message.get("topic") == "/odom":
                return dict(message["msg"])


def hosted(proxy: Proxy) -> list[set[str]]:
    return [set(worker.health()["robots"]) for worker in proxy.workers]


def test_every_robot_is_reachable_through_nginx_on_exactly_one_worker(proxy: Proxy) -> None:
    def frames() -> list[str]:
        return [odom_through(proxy, name)["header"]["frame_id"] for name in NAMES]

    assert frames() == ["odom"] * len(NAMES)
    first, second = hosted(proxy)
    assert first | second == set(NAMES)
    assert not first & second, "a robot lives on one worker only"
    assert first and second, "consistent hashing spread the class over both workers"
    frames()  # again: the same names land on the same workers
    assert hosted(proxy) == [first, second]


def test_a_robots_page_through_nginx_names_nginx_as_its_bridge(proxy: Proxy) -> None:
    base = f"http://127.0.0.1:{proxy.http_port}/robots/student07/"
    with urllib.request.urlopen(base, timeout=5) as response:
        assert response.status == 200
    with urllib.request.urlopen(base + "config.json", timeout=5) as response:
        config = json.load(response)
    assert config["ws"] == f"ws://127.0.0.1:{proxy.ws_port}/robots/student07"
    with urllib.request.urlopen(base + "robot.json", timeout=5) as response:
        assert json.load(response)["topics"]["odom"]["name"] == "/odom"


# --- the instructor's view of every worker, and the dashboard behind nginx ------------------

def visit_all(proxy: Proxy) -> list[set[str]]:
    """Connect to every robot once through nginx (each worker makes the ones routed to it);
    the robots each worker then hosts, by its own /healthz."""
    for name in NAMES:
        odom_through(proxy, name)
    return hosted(proxy)


class Root:
    """A rosbridge client on one synchronous WebSocket; ``call()`` reads until its answer."""

    def __init__(self, url: str) -> None:
        self._stack = contextlib.ExitStack()
        self.ws: ClientConnection = self._stack.enter_context(
            connect_sync(url, open_timeout=5, max_size=None))
        self._ids = itertools.count()

    def call(self, service: str, args: dict[str, Any] | None = None,
             timeout_s: float = 5.0) -> dict[str, Any]:
        call_id = f"call:{next(self._ids)}"
        self.ws.send(json.dumps({"op": "call_service", "id": call_id, "service": service,
                                 "args": args or {}}))
        while True:
            message = json.loads(self.ws.recv(timeout=timeout_s))
            if message.get("op") == "service_response" and message.get("id") == call_id:
                return dict(message)

    def close(self) -> None:
        self._stack.close()


def listed_through_nginx(proxy: Proxy, path: str) -> list[str]:
    """The names ``/websim/robots`` gives on the root view at ``path`` through nginx."""
    root = Root(f"ws://127.0.0.1:{proxy.ws_port}{path}?token={ADMIN_TOKEN}")
    try:
        answer = root.call("/websim/robots")
    finally:
        root.close()
    assert answer["result"] is True, answer
    return list(answer["values"]["names"])


def test_workers_json_lists_the_workers_and_each_root_lists_its_own_robots(
        proxy: Proxy) -> None:
    with urllib.request.urlopen(f"http://127.0.0.1:{proxy.http_port}/workers.json",
                                timeout=5) as response:
        assert response.status == 200
        assert response.headers["Content-Type"] == "application/json"
        assert response.headers["Cache-Control"] == "no-store"
        workers = json.load(response)["workers"]
    assert workers == ["/workers/0/", "/workers/1/"]
    on_worker = visit_all(proxy)
    assert on_worker[0] and on_worker[1], "consistent hashing spread the class over both"
    listed = [set(listed_through_nginx(proxy, path)) for path in workers]
    assert listed == on_worker, "each root lists the robots living on its worker"
    assert not listed[0] & listed[1]
    assert listed[0] | listed[1] == set(NAMES), "not the spares nobody connected to"
    assert hosted(proxy) == on_worker, "listing made no robot on another worker"


def test_a_workers_root_through_nginx_needs_the_instructors_token(proxy: Proxy) -> None:
    """The query string reaches the worker: without the right ``?token=`` its root refuses,
    with its own reason (nginx's 404 for an unknown path names /robots/NAME instead)."""
    for query in ("", "?token=not-the-token"):
        with pytest.raises(InvalidStatus) as refused:
            connect_sync(f"ws://127.0.0.1:{proxy.ws_port}/workers/1/{query}", open_timeout=5)
        assert b"needs the instructor's token" in refused.value.response.body, query
    with pytest.raises(InvalidStatus) as unknown:
        connect_sync(f"ws://127.0.0.1:{proxy.ws_port}/workers/2/?token={ADMIN_TOKEN}",
                     open_timeout=5)
    assert unknown.value.response.status_code == 404
    assert b"/robots/NAME" in unknown.value.response.body


def test_a_students_page_through_nginx_at_the_name_they_typed_may_connect(
        proxy: Proxy) -> None:
    """A student's browser on another machine opens http://HOST:8080/robots/NAME/ (its
    Origin is not this machine's loopback): the worker, bound to 127.0.0.1 behind nginx,
    accepts that page's WebSocket (it refused it, 403, before --public-http-port counted as
    the pages' port); another site's page is still refused."""
    def handshake(origin: str) -> ClientConnection:
        sock = socket.create_connection(("127.0.0.1", proxy.ws_port), timeout=5)
        return connect_sync(f"ws://class.example:{proxy.ws_port}/robots/student01",
                            sock=sock, origin=Origin(origin), open_timeout=5)

    with handshake(f"http://class.example:{proxy.http_port}") as ws:
        ws.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
        while json.loads(ws.recv(timeout=5)).get("topic") != "/odom":
            pass
    for origin in (f"http://evil.example:{proxy.http_port}", "http://class.example:1"):
        with pytest.raises(InvalidStatus) as refused:
            handshake(origin)
        assert refused.value.response.status_code == 403, origin


def robot_odom_x(proxy: Proxy, name: str) -> float:
    """Robot ``name``'s odometry x (m) now, read through nginx."""
    return float(odom_through(proxy, name)["pose"]["pose"]["position"]["x"])


@needs_browser
def test_the_dashboard_behind_nginx_shows_both_workers_and_resets_on_the_second(
        proxy: Proxy, browser: Any) -> None:
    first, second = visit_all(proxy)
    assert first and second
    name = sorted(second)[0]
    with connect_sync(f"ws://127.0.0.1:{proxy.ws_port}/robots/{name}?token={token_of(name)}",
                      open_timeout=5) as student:  # drive it away from the spawn pose
        student.send(json.dumps({"op": "publish", "topic": "/cmd_vel",
                                 "type": "geometry_msgs/msg/Twist",
                                 "msg": {"linear": {"x": 0.5}, "angular": {"z": 0.0}}}))
        wait_for(lambda: robot_odom_x(proxy, name) > 0.1, timeout_s=10.0,
                 what=f"{name} to drive off")
        student.send(json.dumps({"op": "publish", "topic": "/cmd_vel",
                                 "type": "geometry_msgs/msg/Twist",
                                 "msg": {"linear": {"x": 0.0}, "angular": {"z": 0.0}}}))

    context = browser.new_context(viewport={"width": 1280, "height": 800})
    try:
        page = context.new_page()
        sockets: list[str] = []
        errors: list[str] = []
        page.on("websocket", lambda websocket: sockets.append(websocket.url))
        page.on("console", lambda msg: errors.append(msg.text) if msg.type == "error" else None)
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto(f"http://127.0.0.1:{proxy.http_port}/class?token={ADMIN_TOKEN}")
        page.wait_for_function(
            """(count) => {
                const cards = document.querySelectorAll('.robot-card');
                return cards.length === count && [...cards].every((card) =>
                    card.querySelector('[data-field=pose]').textContent !== '–');
            }""", arg=len(NAMES), timeout=30000)
        shown = page.eval_on_selector_all(".robot-card", "cards => cards.map(c => c.dataset.robot)")
        assert set(shown) == first | second == set(NAMES)
        assert shown == sorted(shown), "cards by name, not by worker"
        assert sorted(sockets) == [f"ws://127.0.0.1:{proxy.ws_port}/workers/{k}/?token="
                                   f"{ADMIN_TOKEN}" for k in (0, 1)]
        assert page.text_content("#conn-status") == "connected"
        assert float(page.text_content(f'[data-robot="{name}"] [data-field=pose]')
                     .split(",")[0]) > 0.1

        page.click(f'[data-robot="{name}"] [data-action=reset]')
        wait_for(lambda: abs(robot_odom_x(proxy, name)) < 1e-6, timeout_s=10.0,
                 what=f"{name}, on the second worker, to be reset")
        page.wait_for_function(
            "(name) => document.querySelector(`[data-robot=\"${name}\"] [data-field=pose]`)"
            ".textContent === '0.00, 0.00, 0°'", arg=name, timeout=10000)
        assert page.text_content(f'[data-robot="{name}"] [data-field=error]') == ""
        assert hosted(proxy) == [first, second], "the dashboard made no robot anywhere"
        assert errors == []
    finally:
        context.close()


@needs_browser
def test_a_worker_out_of_reach_is_named_and_the_other_workers_robots_show(
        proxy: Proxy, browser: Any) -> None:
    """The page is told (its workers.json answered by the test) of a third worker whose path
    nginx does not proxy, so its handshake fails as a stopped worker's does (the browser sees
    neither the 404 nor nginx's 502): its line names it, the token is not asked again, and
    the two real workers' robots are all there."""
    first, second = visit_all(proxy)
    paths = ["/workers/0/", "/workers/1/", "/workers/9/"]
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    context.route(f"http://127.0.0.1:{proxy.http_port}/workers.json", lambda route: route.fulfill(
        status=200, content_type="application/json", body=json.dumps({"workers": paths})))
    try:
        page = context.new_page()
        page.goto(f"http://127.0.0.1:{proxy.http_port}/class?token={ADMIN_TOKEN}")
        page.wait_for_function(
            """(count) => document.querySelectorAll('.robot-card').length === count
                && document.querySelector('#class-message').textContent
                    .includes('Cannot reach the class worker')""", arg=len(NAMES), timeout=30000)
        message = page.text_content("#class-message")
        assert message.startswith("Worker 2 (/workers/9/): Cannot reach the class worker at "
                                  f"ws://127.0.0.1:{proxy.ws_port}/workers/9/"), message
        assert "Worker 0" not in message and "Worker 1" not in message
        assert ADMIN_TOKEN not in message
        assert page.get_attribute("#class-message", "data-kind") == "warn"
        assert page.is_hidden("#token-card")
        assert page.text_content("#conn-status") == "connected 2/3"
        shown = page.eval_on_selector_all(".robot-card", "cards => cards.map(c => c.dataset.robot)")
        assert set(shown) == first | second
    finally:
        context.close()
