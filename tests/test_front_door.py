"""Routes, handshakes and public endpoints (issue 20, section 8), on a real ``websim serve``.

Public ``/healthz`` says status and counts, names and addresses only with the instructor's
token; every page carries a CSP, frame-ancestors, X-Frame-Options and Referrer-Policy; a
handshake refused for its Origin changes nothing; a client's refusals and errors are logged
once per kind per interval with a count; behind nginx, ``/workers/K/`` is the instructor's
view only.
"""

from __future__ import annotations

import asyncio
import json
import logging
import urllib.request
from collections.abc import Iterator
from typing import Any

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from classroom.nginx_config import Worker, nginx_config
from rosbridge.core.clock import ManualClock
from rosbridge.transport.log_limits import LogThrottle

from server_process import ADMIN_TOKEN, ServerProcess, start_server


@pytest.fixture(scope="module")
def server() -> Iterator[ServerProcess]:
    running = start_server(["--class", "3"])
    yield running
    running.stop()


def get(url: str) -> tuple[int, dict[str, str], bytes]:
    with urllib.request.urlopen(url, timeout=5) as response:
        return response.status, dict(response.headers), response.read()


def test_public_healthz_has_counts_only_and_the_token_adds_names_and_says_it_is_accepted(
        server: ServerProcess) -> None:
    for base in (server.http_url, f"http://127.0.0.1:{server.ws_port}"):
        _, _, body = get(f"{base}/healthz")
        public = json.loads(body)
        assert public["status"] == "ok" and public["robot_count"] == 3
        assert "clients" in public and "tick_jitter_p99_ms" in public
        assert "tick_delivery_p99_ms" in public
        assert "robots" not in public and "degraded_robots" not in public
        assert "robot01" not in body.decode()
        assert public["token_accepted"] is False
        _, _, body = get(f"{base}/healthz?token={ADMIN_TOKEN}")
        full = json.loads(body)
        assert set(full["robots"]) == {"robot01", "robot02", "robot03"}
        assert full["token_accepted"] is True  # how the dashboard tells a wrong token
        _, _, body = get(f"{base}/healthz?token=wrong-token")
        wrong = json.loads(body)
        assert "robots" not in wrong and wrong["token_accepted"] is False


def test_a_single_robots_public_healthz_names_no_driver() -> None:
    single = start_server([])
    try:
        _, _, body = get(f"{single.http_url}/healthz")
        report = json.loads(body)
        assert "ticks" in report and "last_driver" not in report
        assert "last_driver" in single.health()
    finally:
        single.stop()


@pytest.mark.parametrize("path", ["/", "/class", "/admin", "/robots/robot01/",
                                  "/robots/robot01/admin", "/js/main.js", "/healthz",
                                  "/no-such-file"])
def test_every_answer_forbids_framing_and_referrers(server: ServerProcess, path: str) -> None:
    try:
        _, headers, _ = get(f"{server.http_url}{path}")
    except urllib.error.HTTPError as error:
        headers = dict(error.headers)
    csp = headers["Content-Security-Policy"]
    assert "frame-ancestors 'none'" in csp and "script-src 'self'" in csp
    assert "default-src 'self'" in csp
    assert headers["X-Frame-Options"] == "DENY"
    assert headers["Referrer-Policy"] == "no-referrer"


def test_a_handshake_refused_for_its_origin_makes_no_robot() -> None:
    open_class = start_server(["--class", "1", "--open-class"])
    try:
        async def try_it() -> Any:
            url = f"ws://127.0.0.1:{open_class.ws_port}/robots/decoy"
            with pytest.raises(InvalidStatus) as refused:
                await connect(url, additional_headers={"Origin": "http://evil.example"})
            return refused.value.response.status_code
        assert asyncio.run(try_it()) == 403
        health = open_class.health()
        assert health["robot_count"] == 1 and "decoy" not in health["robots"]
    finally:
        open_class.stop()


def test_refusals_are_logged_once_per_kind_and_address_with_a_count(
        caplog: pytest.LogCaptureFixture) -> None:
    clock = ManualClock()
    logger = logging.getLogger("websim.test_front_door")
    throttle = LogThrottle(logger, clock, interval_s=10.0)
    bridge_log = logging.getLogger("websim.bridge")
    throttle.install()
    try:
        with caplog.at_level(logging.WARNING):
            for _ in range(50):
                throttle.note("10.0.0.9", "origin", "refused a WebSocket (403): origin x")
                bridge_log.warning("client %s: %s", "10.0.0.9:5000", "invalid JSON: oops")
            throttle.note("10.0.0.8", "origin", "refused a WebSocket (403): origin x")
            assert len(caplog.records) == 3
            clock.advance(10.5)
            throttle.note("10.0.0.9", "origin", "refused a WebSocket (403): origin x")
            bridge_log.warning("client %s: %s", "10.0.0.9:5001", "invalid JSON: again")
        messages = [record.getMessage() for record in caplog.records]
        assert "and 49 more like it in the last 10 s" in messages[-2]
        assert "and 49 more like it in the last 10 s" in messages[-1]
    finally:
        throttle.uninstall()


def test_an_invalid_message_flood_writes_a_line_not_a_line_a_message() -> None:
    """150 invalid messages in under 2 s (within the rate): one warning, not 150."""
    single = start_server([])
    try:
        async def flood() -> None:
            async with connect(single.ws_url) as client:
                for _ in range(150):
                    await client.send("{not json")
                    await asyncio.sleep(0.01)
        asyncio.run(flood())
    finally:
        single.stop()
    lines = [line for line in "".join(single.output).splitlines() if "WARNING" in line
             and "127.0.0.1" in line]
    assert 1 <= len(lines) <= 3, lines


def test_nginx_routes_workers_k_to_the_root_view_only() -> None:
    conf = nginx_config([Worker("127.0.0.1", 8081, 9091), Worker("127.0.0.1", 8082, 9092)],
                        "8080", "9090")
    assert "location = /workers/0/ {" in conf and "location = /workers/1/ {" in conf
    assert "location /workers/" not in conf
    assert conf.count("proxy_set_header X-Real-IP $remote_addr;") == 5


@pytest.mark.browser
@pytest.mark.parametrize("path", ["/robots/robot01/", f"/robots/robot01/admin?token={ADMIN_TOKEN}",
                                  f"/class?token={ADMIN_TOKEN}"])
def test_the_pages_run_under_their_csp(server: ServerProcess, browser: Any, path: str) -> None:
    """Each page, with its CSP enforced (no bypass), loads, connects and shows its robot(s):
    no script, style or socket of it is refused."""
    context = browser.new_context(bypass_csp=False)
    try:
        page = context.new_page()
        problems: list[str] = []
        page.on("console", lambda msg: problems.append(msg.text)
                if msg.type == "error" and "workers.json" not in str(msg.location) else None)
        page.on("pageerror", lambda error: problems.append(str(error)))
        page.goto(f"{server.http_url}{path}")
        if path.startswith("/class"):
            page.wait_for_selector(".robot-card [data-field=pose]:not(:text-is('–'))",
                                   timeout=15000)
        else:
            page.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
        page.wait_for_timeout(1000)
        assert [p for p in problems if "Content Security Policy" in p] == []
        assert problems == []
    finally:
        context.close()
