"""``websim serve`` as a process, with real clients: roslibpy and raw WebSocket connections."""

from __future__ import annotations

import asyncio
import itertools
import json
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator

import pytest
import roslibpy
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from websim.lan import lan_addresses, qr_lines

from server_process import ADMIN_TOKEN, ServerProcess, free_port, start_server, wait_for

TWIST_03 = {"linear": {"x": 0.3, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
STOP = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


@pytest.fixture(scope="module")
def ros(server: ServerProcess):
    """One roslibpy client for the module: its Twisted reactor cannot be restarted."""
    client = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
    client.run(timeout=10)
    yield client
    client.close()


def stamp_s(msg: dict) -> float:
    return msg["header"]["stamp"]["sec"] + msg["header"]["stamp"]["nanosec"] * 1e-9


def reset(ros: roslibpy.Ros) -> None:
    roslibpy.Service(ros, "/reset_simulation", "std_srvs/srv/Empty").call(
        roslibpy.ServiceRequest({}), timeout=5)


def test_roslibpy_drives_the_robot_and_reads_odom(ros: roslibpy.Ros) -> None:
    reset(ros)
    odoms: list[dict] = []
    listener = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry", queue_length=100)
    listener.subscribe(odoms.append)
    wait_for(lambda: odoms, what="first /odom")
    cmd_vel = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
    cmd_vel.publish(roslibpy.Message(TWIST_03))
    moving = wait_for(lambda: [m for m in odoms
                               if m["pose"]["pose"]["position"]["x"] > 0], what="motion")
    first = moving[0]
    wait_for(lambda: stamp_s(odoms[-1]) - stamp_s(first) >= 1.0, what="1 s of driving")
    cmd_vel.publish(roslibpy.Message(STOP))
    after_1s = next(m for m in odoms if stamp_s(m) - stamp_s(first) >= 1.0 - 1e-3)
    ticks = round((stamp_s(after_1s) - stamp_s(first)) / 0.05)
    # The first moving odom already shows one tick of motion: x = 0.3 * 0.05 * (ticks + 1).
    assert after_1s["pose"]["pose"]["position"]["x"] == pytest.approx(
        0.3 * 0.05 * (ticks + 1), abs=0.015)
    assert after_1s["twist"]["twist"]["linear"]["x"] == pytest.approx(0.3)
    assert after_1s["header"]["frame_id"] == "odom"
    assert after_1s["child_frame_id"] == "base_link"
    listener.unsubscribe()


def test_scan_has_360_ranges_at_10_hz(ros: roslibpy.Ros) -> None:
    scans: list[dict] = []
    listener = roslibpy.Topic(ros, "/scan", "sensor_msgs/msg/LaserScan", queue_length=10)
    listener.subscribe(scans.append)
    wait_for(lambda: len(scans) >= 6, what="6 scans")
    listener.unsubscribe()
    assert all(len(scan["ranges"]) == 360 for scan in scans)
    assert scans[0]["header"]["frame_id"] == "laser"
    periods = [stamp_s(b) - stamp_s(a) for a, b in itertools.pairwise(scans)]
    assert all(p == pytest.approx(0.1, abs=0.03) for p in periods)


def test_get_topics_lists_the_robot_interface(ros: roslibpy.Ros) -> None:
    topics = ros.get_topics()
    for name in ("/cmd_vel", "/odom", "/scan", "/tf", "/tf_static", "/ground_truth", "/world"):
        assert name in topics
    assert ros.get_topic_type("/tf") == "tf2_msgs/msg/TFMessage"


def test_roslibpy_param_and_parameter_services_need_the_token(server: ServerProcess,
                                                              ros: roslibpy.Ros) -> None:
    request = roslibpy.ServiceRequest({"parameters": [
        {"name": "inertia_kg_m2", "value": {"type": 3, "double_value": 0.0099}}]})
    service = roslibpy.Service(ros, "/virtual_robot/set_parameters",
                               "rcl_interfaces/srv/SetParameters")
    with pytest.raises(Exception, match="admin"):
        service.call(request, timeout=5)
    admin = roslibpy.Ros(host=server.admin_ws_url)
    admin.run(timeout=10)
    try:
        result = roslibpy.Service(admin, "/virtual_robot/set_parameters",
                                  "rcl_interfaces/srv/SetParameters").call(request, timeout=5)
        assert result["results"] == [{"successful": True, "reason": ""}]
    finally:
        admin.close()
    assert roslibpy.Param(ros, "/virtual_robot:inertia_kg_m2").get(timeout=5) == 0.0099


async def raw_session(server: ServerProcess, frames: list[str | bytes]) -> list[dict]:
    """Send frames on one raw connection, then subscribe to /odom and return what comes."""
    async with connect(server.ws_url) as websocket:
        await websocket.send(json.dumps({"op": "set_level", "level": "error"}))
        for frame in frames:
            await websocket.send(frame)
        await websocket.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
        received = []
        async with asyncio.timeout(5):
            while not any(m.get("topic") == "/odom" for m in received):
                received.append(json.loads(await websocket.recv()))
        return received


def test_malformed_input_leaves_the_connection_usable(server: ServerProcess) -> None:
    ticks_before = server.health()["ticks"]
    bad = ["{nope", "[]", json.dumps({"op": "warp"}), json.dumps({"op": "subscribe"}),
           json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": "a"}}}),
           '{"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": NaN}}}',
           b"\xff\xfe", "[" * 200_000 + "]" * 200_000,
           json.dumps({"op": "publish", "topic": "/cmd_vel",
                       "msg": {"linear": {"x": [0.5] * 100_000}}})]
    received = asyncio.run(raw_session(server, bad))
    statuses = [m for m in received if m["op"] == "status"]
    assert len(statuses) == len(bad)
    assert any(m.get("topic") == "/odom" for m in received)
    wait_for(lambda: server.health()["ticks"] > ticks_before + 5, what="ticks to go on")


def test_oversized_frame_closes_with_a_reason(server: ServerProcess) -> None:
    async def send_huge() -> tuple[int | None, str | None]:
        async with connect(server.ws_url, max_size=None) as websocket:
            await websocket.send("x" * (2 << 20))
            with pytest.raises(Exception):  # noqa: B017 (ConnectionClosed subclasses)
                async with asyncio.timeout(5):
                    await websocket.recv()
            return websocket.close_code, websocket.close_reason

    code, reason = asyncio.run(send_huge())
    assert code == 1009
    assert reason is not None and "exceeds limit of 1048576 bytes" in reason
    assert server.health()["status"] == "ok"


async def closed_after(url: str, frames: list[str]) -> tuple[int | None, str | None]:
    """Send ``frames`` as fast as possible and return how the server closed the connection."""
    async with connect(url, max_size=None) as websocket:
        try:
            for frame in frames:
                await websocket.send(frame)
            async with asyncio.timeout(5):
                while True:
                    await websocket.recv()
        except ConnectionClosed:
            pass
        return websocket.close_code, websocket.close_reason


def test_flooding_client_is_closed_for_policy_violation(server: ServerProcess) -> None:
    flood = [json.dumps({"op": "set_level", "level": "none"})] * 2000
    code, reason = asyncio.run(closed_after(server.ws_url, flood))
    assert (code, reason) == (1008, "rate limit: more than 200 messages/s")
    assert server.health()["status"] == "ok"
    wait_for(lambda: server.health()["clients"] <= 1, what="the flooder to be forgotten")


@pytest.fixture(scope="module")
def strict() -> Iterator[ServerProcess]:
    """A server with small limits and one extra allowed origin."""
    running = start_server(["--max-rate", "20", "--max-frame-bytes", "4096",
                            "--allow-origin", "https://robot.example"])
    yield running
    running.stop()


def test_limits_are_options(strict: ServerProcess) -> None:
    code, reason = asyncio.run(closed_after(strict.ws_url, ["x" * 5000]))
    assert code == 1009 and reason is not None and "limit of 4096 bytes" in reason
    steady = [json.dumps({"op": "set_level", "level": "none"})] * 15

    async def burst_then_call() -> dict:
        async with connect(strict.ws_url) as websocket:
            for frame in steady:
                await websocket.send(frame)
            await websocket.send(json.dumps({"op": "call_service", "id": "n",
                                             "service": "/rosapi/nodes"}))
            async with asyncio.timeout(5):
                return dict(json.loads(await websocket.recv()))

    assert asyncio.run(burst_then_call())["result"] is True, "a burst within the rate passes"
    code, reason = asyncio.run(closed_after(strict.ws_url, steady * 3))
    assert (code, reason) == (1008, "rate limit: more than 20 messages/s")


def handshake(url: str, origin: str | None) -> int:
    """Open a WebSocket with this Origin header; the HTTP status (101 when accepted)."""
    async def attempt() -> int:
        try:
            async with connect(url, origin=origin) as websocket:  # type: ignore[arg-type]
                await websocket.send(json.dumps({"op": "set_level", "level": "none"}))
                return 101
        except InvalidStatus as refused:
            return refused.response.status_code
    return asyncio.run(attempt())


def test_pages_from_other_origins_are_refused_at_the_handshake(strict: ServerProcess) -> None:
    own = f"http://127.0.0.1:{strict.http_port}"
    assert handshake(strict.ws_url, None) == 101, "roslibpy and Node send no Origin"
    assert handshake(strict.ws_url, own) == 101
    assert handshake(strict.ws_url, f"http://localhost:{strict.http_port}") == 101
    assert handshake(strict.ws_url, "https://robot.example") == 101, "--allow-origin"
    assert handshake(strict.ws_url, "https://evil.example") == 403
    assert handshake(strict.ws_url, f"http://127.0.0.1:{strict.ws_port + 1}") == 101, \
        "pages from this machine, any port"
    assert handshake(strict.ws_url, "http://10.11.12.13:8080") == 403
    strict.stop()
    assert "origin https://evil.example is not allowed" in "".join(strict.output)


def test_healthz_on_both_ports(server: ServerProcess) -> None:
    page = server.health()
    with urllib.request.urlopen(f"http://127.0.0.1:{server.ws_port}/healthz",
                                timeout=2) as response:
        socket_health = json.load(response)
    assert page["status"] == socket_health["status"] == "ok"
    assert page["mode"] == "kinematic" and page["world"] == "empty arena"


def test_tick_loop_does_not_drift(server: ServerProcess) -> None:
    wait_for(lambda: server.health()["uptime_s"] > 3, what="3 s of running")
    for _ in range(5):
        health = server.health()
        assert abs(health["ticks"] - health["ticks_due"]) <= 1, health
        time.sleep(0.37)


def test_port_in_use_is_a_one_line_error() -> None:
    first = start_server()
    try:
        result = subprocess.run(
            [sys.executable, "-m", "websim.cli", "serve", "--ws-port", str(first.ws_port),
             "--http-port", str(free_port())], capture_output=True, text=True, timeout=30)
    finally:
        first.stop()
    assert result.returncode == 1
    assert result.stderr.strip().splitlines() == [
        f"websim: error: WebSocket port 127.0.0.1:{first.ws_port} is already in use "
        "(is another websim running?)"]


def test_sigterm_stops_cleanly_and_banner_shows_urls() -> None:
    running = start_server()
    assert running.stop() == 0
    output = "".join(running.output)
    assert f"ws://localhost:{running.ws_port}/" in output
    assert f"http://localhost:{running.http_port}/admin?token={ADMIN_TOKEN}" in output
    assert "websim: stopped" in output and "Traceback" not in output


def test_on_every_interface_every_url_names_the_address_students_reach_and_a_qr_code(
) -> None:
    """One host everywhere: the machine's address on the network, not 'localhost' for some
    lines and the host name (which students' machines often cannot resolve) for others."""
    running = start_server(["--host", "0.0.0.0"])
    assert running.stop() == 0
    output = "".join(running.output)
    addresses = lan_addresses()
    assert all(not address.startswith("127.") for address in addresses)
    if not addresses:  # a machine with loopback only
        assert "no network address found besides loopback" in output
        return
    page = f"http://{addresses[0]}:{running.http_port}/"
    assert f"  page:      {page}\n" in output
    assert f"  websocket: ws://{addresses[0]}:{running.ws_port}/\n" in output
    assert f"  admin:     {page}admin?token=" in output
    urls = [word for word in output.split() if "://" in word]
    assert urls and all(f"://{addresses[0]}:" in url for url in urls), urls
    assert socket.gethostname() not in urls[0]
    code = qr_lines(page)
    assert "\n".join(f"  {line}" for line in code) in output
    assert len(code) >= 12 and len({len(line) for line in code}) == 1  # a square of modules
    assert set("".join(code)) <= set("█▀▄ ")


def test_random_admin_token_is_printed_once() -> None:
    ws_port, http_port = free_port(), free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "websim.cli", "serve", "--ws-port", str(ws_port),
         "--http-port", str(http_port)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)
    running = ServerProcess(ws_port, http_port, process)
    wait_for(lambda: running.health()["status"] == "ok" if _listening(running) else False,
             timeout_s=20, what="server")
    running.stop()
    output = "".join(running.output)
    tokens = [line.split("token=")[1] for line in output.splitlines() if "token=" in line]
    assert len(tokens) == 1 and len(tokens[0]) >= 20


def _listening(running: ServerProcess) -> bool:
    try:
        running.health()
        return True
    except OSError:
        return False


def test_missing_page_libraries_are_named_in_the_banner(tmp_path) -> None:
    running = start_server(["--web-dir", str(tmp_path)])
    assert running.stop() == 0
    assert "run: npm ci --prefix web-interface" in "".join(running.output)
    installed = start_server()
    installed.stop()
    assert "npm ci" not in "".join(installed.output)


def test_client_that_stops_reading_stalls_only_itself(server: ServerProcess) -> None:
    """A real socket with a tiny receive buffer that never reads, next to a healthy client."""
    async def scenario() -> tuple[int, dict]:
        sock = socket.create_connection(("127.0.0.1", server.ws_port))
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.setblocking(False)
        stalled = await connect(server.ws_url, sock=sock, max_queue=1)
        healthy = await connect(server.ws_url)
        for topic, length in (("/scan", 5), ("/odom", 5), ("/ground_truth", 5)):
            await stalled.send(json.dumps({"op": "subscribe", "topic": topic,
                                           "queue_length": length}))
        await healthy.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
        # The stalled client's socket and websockets' buffers fill; then its outbox does.
        await asyncio.to_thread(wait_for, lambda: server.health()["queued_frames"] >= 10,
                                15.0, "the stalled client's outbox to fill")
        first = server.health()
        received = 0
        async with asyncio.timeout(10):
            while received < 40:  # 2 s of /odom at 20 Hz
                if json.loads(await healthy.recv()).get("topic") == "/odom":
                    received += 1
        last = server.health()
        for websocket in (stalled, healthy):  # a closing handshake waits for unread frames
            websocket.transport.abort()
        return last["ticks"] - first["ticks"], last

    before = server.health()["clients"]
    ticks, health = asyncio.run(scenario())
    assert ticks <= 40 + 3, "the healthy client got every /odom while the other stalled"
    assert abs(health["ticks"] - health["ticks_due"]) <= 1, "the tick loop kept its schedule"
    assert health["queued_frames"] <= 15, "per subscription, only the newest 5 wait"
    wait_for(lambda: server.health()["clients"] == before, what="both clients to be forgotten")


def test_connect_disconnect_churn_leaves_no_session(server: ServerProcess) -> None:
    async def churn(cycles: int) -> None:
        for cycle in range(cycles):
            websocket = await connect(server.ws_url)
            await websocket.send(json.dumps({"op": "subscribe", "topic": "/scan"}))
            await websocket.send(json.dumps({"op": "advertise", "topic": f"/c{cycle}",
                                             "type": "std_msgs/String"}))
            await websocket.recv()
            if cycle % 2:
                websocket.transport.abort()  # vanish without a close frame
            else:
                await websocket.close()

    before = server.health()["clients"]
    asyncio.run(churn(40))
    wait_for(lambda: server.health()["clients"] == before, what="every churned session gone")
    assert server.health()["queued_frames"] == 0 or before > 0
