"""Hostile and buggy clients against a real ``websim serve``: nothing they send stops the robot.

Each test attacks a real server process over real sockets while a healthy client listens to
/odom, and asserts both sides: the attacker gets a clear error or close reason, and the
healthy client keeps the robot's 20 Hz (measured from the header stamps the robot wrote,
with a margin for a loaded 2-core machine).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import Iterator
from typing import Any

import pytest
import websockets

from rosbridge.core.limits import ClientLimits

from server_process import ServerProcess, start_server, wait_for
from ws_clients import NonReader, OdomListener

LIMITS = ClientLimits()
MIN_HEALTHY_HZ = 18.0
"""The robot publishes /odom at 20 Hz; a healthy client must see at least this."""

MAX_GAP_S = 0.3
"""Largest gap between two /odom stamps a healthy client may see during an attack."""

TWIST = {"linear": {"x": 0.1, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


@pytest.fixture(scope="module")
def server() -> Iterator[ServerProcess]:
    running = start_server()
    yield running
    running.stop()


async def errors_for(url: str, messages: list[Any], expect: int,
                     timeout_s: float = 5.0) -> list[dict[str, Any]]:
    """Send ``messages`` (after ``set_level``) and collect ``expect`` error statuses."""
    async with websockets.connect(url, max_size=None) as ws:
        await ws.send(json.dumps({"op": "set_level", "level": "error"}))
        for message in messages:
            await ws.send(message if isinstance(message, str) else json.dumps(message))
        statuses: list[dict[str, Any]] = []
        deadline = time.monotonic() + timeout_s
        while len(statuses) < expect:
            frame = await asyncio.wait_for(ws.recv(), max(0.1, deadline - time.monotonic()))
            reply = json.loads(frame)
            if reply.get("op") in ("status", "service_response"):
                statuses.append(reply)
        return statuses


def assert_healthy(listener: OdomListener, start: int) -> None:
    rate_hz, gap_s = listener.rate_since(start)
    assert rate_hz >= MIN_HEALTHY_HZ, f"healthy client saw /odom at {rate_hz:.1f} Hz"
    assert gap_s <= MAX_GAP_S, f"healthy client saw a {gap_s:.3f} s gap in /odom"


def still_ticking(server: ServerProcess, seconds: float = 1.0) -> None:
    before = server.health()
    time.sleep(seconds)
    after = server.health()
    assert after["ticks"] - before["ticks"] >= 0.8 * seconds / 0.05
    assert after["status"] == "ok", after


HUGE = 10**400


@pytest.mark.parametrize("fields, reason", [
    ({"queue_length": HUGE}, "field 'queue_length' must be between 0 and 100, got a 401-digit"),
    ({"queue_length": 2**63}, "field 'queue_length' must be between 0 and 100"),
    ({"queue_length": -1}, "field 'queue_length' must be between 0 and 100, got -1"),
    ({"throttle_rate": HUGE}, "field 'throttle_rate' must be between 0 and 3.6e+06"),
    ({"throttle_rate": 1e308}, "field 'throttle_rate' must be between 0 and 3.6e+06"),
    ({"throttle_rate": -5}, "field 'throttle_rate' must be between 0 and 3.6e+06"),
    ({"fragment_size": HUGE}, "field 'fragment_size' must be between 1 and"),
    ({"id": HUGE}, "field 'id' must be within ±2^53"),
    ({"id": "x" * 1000}, "field 'id' is longer than 256 characters"),
    ({"compression": "zip"}, "field 'compression' must be one of none, cbor, png, cbor-raw"),
])
def test_out_of_range_subscribe_fields_are_refused_and_the_robot_keeps_its_rate(
        server: ServerProcess, fields: dict[str, Any], reason: str) -> None:
    async def attack() -> None:
        async with OdomListener(server.ws_url) as listener:
            await asyncio.sleep(0.3)
            start = listener.mark()
            for topic in ("/odom", "/cmd_vel"):  # /cmd_vel: every publisher's subscribers
                statuses = await errors_for(server.ws_url, [
                    {"op": "subscribe", "topic": topic, **fields}], expect=1)
                assert reason in statuses[0]["msg"]
            await drive_and_check(server)
            await asyncio.sleep(1.0)
            assert_healthy(listener, start)

    asyncio.run(attack())
    still_ticking(server)


async def drive_and_check(server: ServerProcess) -> None:
    """A page publishing /cmd_vel (and subscribed to it) is not disconnected."""
    async with websockets.connect(server.ws_url) as page:
        await page.send(json.dumps({"op": "subscribe", "topic": "/cmd_vel"}))
        for _ in range(3):
            await page.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST}))
        frame = json.loads(await asyncio.wait_for(page.recv(), 3))
        assert frame["topic"] == "/cmd_vel"
        assert frame["msg"] == TWIST


def test_integers_beyond_float_range_in_a_twist_are_refused(server: ServerProcess) -> None:
    huge_twist = '{"op":"publish","topic":"/cmd_vel","msg":{"linear":{"x":1' + "0" * 400 + \
        '},"angular":{"z":0}}}'
    statuses = asyncio.run(errors_for(server.ws_url, [huge_twist], expect=1))
    assert "linear.x: 401-digit integer is out of float64 range" in statuses[0]["msg"]
    still_ticking(server)


@pytest.mark.parametrize("name, value, reason", [
    ("max_linear_mps", 1e308, "max_linear_mps: must be between 0.01 and 10, got 1e+308"),
    ("max_angular_rps", 21.0, "max_angular_rps: must be between 0.01 and 20, got 21.0"),
    ("mass_kg", 0.001, "mass_kg: must be between 0.01 and 1000, got 0.001"),
    ("mass_kg", HUGE, "mass_kg: expected a finite number, got an integer of 401 digits"),
    ("world", "maze", "world: read-only (it is set when the robot starts)"),
])
def test_absurd_parameters_are_refused_even_for_the_admin(
        server: ServerProcess, name: str, value: Any, reason: str) -> None:
    kind = {"world": (4, "string_value")}.get(name, (2, "integer_value") if isinstance(
        value, int) else (3, "double_value"))
    request = {"op": "call_service", "service": "/virtual_robot/set_parameters", "id": "p",
               "args": {"parameters": [{"name": name, "value": {"type": kind[0],
                                                                kind[1]: value}}]}}
    replies = asyncio.run(errors_for(server.admin_ws_url, [request], expect=1))
    result = replies[0]["values"]["results"][0]
    assert result["successful"] is False
    assert reason in result["reason"]
    still_ticking(server)


def test_an_admin_driving_flat_out_at_the_largest_limits_stays_finite(
        server: ServerProcess) -> None:
    async def drive() -> dict[str, Any]:
        async with websockets.connect(server.admin_ws_url) as admin:
            values = [{"name": "max_linear_mps", "value": {"type": 3, "double_value": 10.0}},
                      {"name": "max_angular_rps", "value": {"type": 3, "double_value": 20.0}}]
            await admin.send(json.dumps({"op": "call_service", "id": "s", "args": {
                "parameters": values}, "service": "/virtual_robot/set_parameters"}))
            await admin.recv()
            await admin.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {
                "linear": {"x": 1e300}, "angular": {"z": -1e300}}}))
            await asyncio.sleep(1.0)
            await admin.send(json.dumps({"op": "subscribe", "topic": "/ground_truth"}))
            truth = json.loads(await admin.recv())["msg"]
            await admin.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {}}))
            for name, default in (("max_linear_mps", 0.5), ("max_angular_rps", 2.5)):
                await admin.send(json.dumps({"op": "call_service", "id": "r", "args": {
                    "parameters": [{"name": name, "value": {"type": 3,
                                                            "double_value": default}}]},
                    "service": "/virtual_robot/set_parameters"}))
            return dict(truth)

    truth = asyncio.run(drive())
    assert truth["twist"]["twist"]["linear"]["x"] in (10.0, 0.0)  # at the limit, or at a wall
    assert abs(truth["pose"]["pose"]["position"]["x"]) < 3.0
    still_ticking(server)


def test_subscribe_ids_per_topic_are_capped(server: ServerProcess) -> None:
    limit = LIMITS.max_ids_per_topic
    messages = [{"op": "subscribe", "topic": "/tf", "id": f"s{i}", "throttle_rate": 1000}
                for i in range(limit + 3)]
    statuses = asyncio.run(errors_for(server.ws_url, messages, expect=3))
    assert all(f"at most {limit} subscribe ids on one topic" in s["msg"] for s in statuses)


def test_a_large_latched_message_is_refused(server: ServerProcess) -> None:
    big = {"op": "publish", "topic": "/notes", "latch": True,
           "msg": {"data": "x" * (LIMITS.max_latched_bytes + 1)}}
    statuses = asyncio.run(errors_for(server.ws_url, [
        {"op": "advertise", "topic": "/notes", "type": "std_msgs/String"}, big], expect=1))
    assert f"a latched message may be at most {LIMITS.max_latched_bytes} bytes" in \
        statuses[0]["msg"]


def test_extra_fields_are_refused_not_relayed(server: ServerProcess) -> None:
    async def attack() -> list[Any]:
        async with websockets.connect(server.ws_url) as watcher:
            await watcher.send(json.dumps({"op": "subscribe", "topic": "/cmd_vel"}))
            bloated = {**TWIST, "junk": "x" * 500_000}
            statuses = await errors_for(server.ws_url, [
                {"op": "publish", "topic": "/cmd_vel", "msg": bloated},
                {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 0.1}}}],
                expect=1, timeout_s=2)
            assert "geometry_msgs/msg/Twist has no field 'junk'" in statuses[0]["msg"]
            relayed = json.loads(await asyncio.wait_for(watcher.recv(), 3))
            return [statuses, relayed]

    _, relayed = asyncio.run(attack())
    assert relayed["msg"] == TWIST, "a partial Twist is relayed filled in, in canonical form"


COSTLY_FRAMES = {
    "empty arrays": ("[" + ",".join(["[]"] * 340_000) + "]", "too many elements (about 680000"),
    "empty objects": ('{"op":"publish","topic":"/x","msg":{"a":[' + ",".join(["{}"] * 300_000)
                      + "]}}", "too many elements"),
    "numbers": ("[" + ",".join(["0"] * 500_000) + "]", "too many elements (about 500000"),
    "deep": ("[" * 65 + "]" * 65, "too deeply nested (more than 64 levels)"),
    "deep many": ("[" + ",".join(["[" * 60 + "]" * 60] * 8000) + "]", "too many elements"),
    "within limits": ("[" + ",".join(["[" * 60 + "]" * 60] * 200) + "]", None),
}


@pytest.mark.parametrize("kind", COSTLY_FRAMES)
def test_costly_frames_are_refused_before_parsing(server: ServerProcess, kind: str) -> None:
    frame, reason = COSTLY_FRAMES[kind]

    async def attack() -> None:
        async with OdomListener(server.ws_url) as listener:
            await asyncio.sleep(0.3)
            start = listener.mark()
            if reason is None:  # within the limits: answered (not an op), never slow
                statuses = await errors_for(server.ws_url, [frame] * 3, expect=3)
                assert all("expected a JSON object, got list" in s["msg"] for s in statuses)
            else:
                statuses = await errors_for(server.ws_url, [frame] * 3, expect=3)
                assert all(reason in s["msg"] for s in statuses)
            await asyncio.sleep(1.0)
            assert_healthy(listener, start)

    asyncio.run(attack())


def test_a_second_provider_cannot_take_over_a_service(server: ServerProcess) -> None:
    async def attack() -> list[Any]:
        async with websockets.connect(server.ws_url) as owner:
            await owner.send(json.dumps({"op": "advertise_service", "service": "/grade",
                                         "type": "std_srvs/Empty"}))
            await asyncio.sleep(0.2)
            statuses = await errors_for(server.ws_url, [
                {"op": "advertise_service", "service": "grade", "type": "std_srvs/Empty"},
                {"op": "advertise_service", "service": "/virtual_robot/x", "topic": "/mine",
                 "type": "std_srvs/Empty"},
                {"op": "advertise_service", "service": "~private", "type": "std_srvs/Empty"}],
                expect=3)
            async with websockets.connect(server.ws_url) as caller:
                await caller.send(json.dumps({"op": "call_service", "service": "/grade",
                                              "id": "c"}))
                request = json.loads(await asyncio.wait_for(owner.recv(), 3))
            return [statuses, request]

    statuses, request = asyncio.run(attack())
    assert "/grade is already provided by another client" in statuses[0]["msg"]
    assert "services under /virtual_robot/, /rosapi/, /websim/ belong to the simulator" in \
        statuses[1]["msg"]
    assert "private names (~) are not offered to clients" in statuses[2]["msg"]
    assert request["op"] == "call_service" and request["service"] == "/grade"


@pytest.mark.slow
def test_a_client_that_never_reads_is_closed_and_released() -> None:
    """A real socket that stops reading: closed within stall timeout + close timeout."""
    server = start_server()
    try:
        async def attack() -> tuple[float, bool]:
            async with OdomListener(server.ws_url) as listener:
                await asyncio.sleep(0.3)
                start = listener.mark()
                reader = NonReader(server.ws_port)
                for topic in ("/odom", "/scan", "/tf", "/ground_truth", "/world"):
                    reader.send({"op": "subscribe", "topic": topic, "queue_length": 100})
                began = time.monotonic()
                await asyncio.to_thread(
                    wait_for, lambda: server.health()["clients"] == 1,
                    LIMITS.stall_timeout_s + LIMITS.close_timeout_s + 10.0,
                    "the non-reading client to be dropped", 0.2)
                dropped_after_s = time.monotonic() - began
                assert_healthy(listener, start)
                closed = reader.is_closed_by_server()
                reader.close()
                return dropped_after_s, closed

        dropped_after_s, closed = asyncio.run(attack())
        assert closed
        # It first fills its kernel buffers (seconds), then stalls for stall_timeout_s.
        assert dropped_after_s <= LIMITS.stall_timeout_s + LIMITS.close_timeout_s + 8.0
        health = server.health()
        assert health["queued_bytes"] < 100_000 and health["status"] == "ok"
    finally:
        server.stop()
    assert "not reading: the socket accepted nothing for" in "".join(server.output)


def test_an_unread_backlog_stays_within_the_byte_budget_newest_frames_kept() -> None:
    """A client that does not read holds at most its byte budget: its oldest topic frames
    make room for the newest (it is closed as not reading by the stall watchdog:
    test_a_client_that_never_reads_is_closed_and_released), never for what others sent."""
    budget = 200_000
    server = start_server(["--max-queued-bytes", str(budget)])
    try:
        reader = NonReader(server.ws_port)
        for topic in ("/scan", "/odom", "/world", "/tf", "/ground_truth"):
            reader.send({"op": "subscribe", "topic": topic, "queue_length": 100})
        wait_for(lambda: server.health()["queued_bytes"] > budget // 2, 15.0,
                 "the unread backlog to build up", 0.2)
        for _ in range(10):
            health = server.health()
            assert health["clients"] == 1
            assert health["queued_bytes"] <= budget + 20_000, health["queued_bytes"]
            time.sleep(0.2)
        reader.close()
    finally:
        server.stop()
    assert "send queue overflow" not in "".join(server.output)


def test_connections_beyond_max_clients_are_refused_with_503() -> None:
    server = start_server(["--max-clients", "2"])
    try:
        async def crowd() -> str:
            async with websockets.connect(server.ws_url), websockets.connect(server.ws_url):
                with pytest.raises(websockets.InvalidStatus) as refused:
                    async with websockets.connect(server.ws_url):
                        pass
                return str(refused.value.response.body, "utf-8")

        body = asyncio.run(crowd())
        assert "this robot serves at most 2 clients at once" in body
        wait_for(lambda: server.health()["clients"] == 0, 5.0, "the two clients to leave")
        asyncio.run(drive_and_check(server))  # room again
    finally:
        server.stop()


def test_publications_relayed_beyond_the_relay_budget_are_dropped(server: ServerProcess) -> None:
    chunk = {"op": "publish", "topic": "/essay", "msg": {"data": "x" * (200 << 10)}}

    async def flood() -> tuple[int, list[dict[str, Any]]]:
        async with websockets.connect(server.ws_url, max_size=None) as reader:
            await reader.send(json.dumps({"op": "subscribe", "topic": "/essay"}))
            await asyncio.sleep(0.2)
            statuses = await errors_for(server.ws_url, [
                {"op": "advertise", "topic": "/essay", "type": "std_msgs/String"},
                *[chunk] * 8], expect=2)
            received = 0
            with contextlib.suppress(TimeoutError):
                while True:
                    await asyncio.wait_for(reader.recv(), 1.0)
                    received += 1
            return received, statuses

    received, statuses = asyncio.run(flood())
    assert all(f"more than {LIMITS.relay_bytes_per_s} bytes/s published; message dropped"
               in s["msg"] for s in statuses)
    burst = max(LIMITS.relay_bytes_per_s, LIMITS.max_frame_bytes) // len(json.dumps(chunk))
    assert 1 <= received <= burst + 1, "the burst passes, the rest is dropped"


def test_a_reading_subscriber_is_never_closed_for_what_32_publishers_burst(
        server: ServerProcess) -> None:
    """Turn 3 of issue 20's attacks, as issue 27 found it still landing: 32 publishers (each
    from an address of its own, so no address budget spaces them out) burst 1 MB each on a
    topic; a subscriber reading at full speed was closed as "not reading" (send queue
    overflow), one round in two at least. Several rounds, both queue lengths: it stays, and
    gets messages of every round."""
    payload = "x" * 1_000_000

    async def attack(queue_length: int) -> tuple[int, str | None]:
        subscriber = await websockets.connect(server.ws_url, max_size=None)
        await subscriber.send(json.dumps({"op": "subscribe", "topic": "/flood",
                                          "type": "std_msgs/String",
                                          "queue_length": queue_length}))
        publishers = [await websockets.connect(server.ws_url, max_size=None,
                                               local_addr=(f"127.0.3.{number + 1}", 0))
                      for number in range(32)]
        got, closed = 0, None

        async def read() -> None:
            nonlocal got, closed
            try:
                async for frame in subscriber:
                    got += '"topic": "/flood"' in frame[:100] or '"topic":"/flood"' in frame[:100]
            except websockets.ConnectionClosed as error:
                closed = error.rcvd.reason if error.rcvd else "closed"

        reader = asyncio.create_task(read())
        try:
            for publisher in publishers:
                await publisher.send(json.dumps({"op": "advertise", "topic": "/flood",
                                                 "type": "std_msgs/String"}))
            await asyncio.sleep(0.2)
            await asyncio.gather(*(publisher.send(json.dumps({
                "op": "publish", "topic": "/flood", "msg": {"data": payload}}))
                for publisher in publishers))
            deadline = time.monotonic() + 15.0
            while got < 4 and closed is None and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
            await asyncio.sleep(0.5)  # what the outbox still sends, or a late close
        finally:
            for publisher in publishers:
                await publisher.close()
            await subscriber.close()
            await reader
        return got, closed

    for queue_length in (0, 10, 0, 10):
        got, closed = asyncio.run(attack(queue_length))
        assert closed is None or closed == "", f"queue_length {queue_length}: closed: {closed}"
        assert got >= 4, f"queue_length {queue_length}: {got} messages of 32"
