"""Issue 20 (sections 1, 2, 6, 8) against a real ``websim serve``: attacker on 127.0.0.2.

Each test attacks from 127.0.0.2 over real sockets while healthy clients on 127.0.0.1 go on,
and asserts both sides: healthy clients keep their rate (or are not closed), the attacker
gets a clear refusal (or is only itself made late).
"""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

import pytest
import websockets

from rosbridge.core.limits import ClientLimits

from server_process import ServerProcess, start_server
from ws_clients import OdomListener

ATTACKER = ("127.0.0.2", 0)
MIN_HEALTHY_HZ = 19.0
MAX_GAP_S = 0.3


@pytest.fixture(scope="module")
def server() -> Any:
    running = start_server()
    yield running
    running.stop()


def rss_mb(server: ServerProcess) -> float:
    with open(f"/proc/{server.process.pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


async def attacker(url: str) -> Any:
    return await websockets.connect(url, max_size=None, local_addr=ATTACKER)


async def read_all(connection: Any, frames: list[Any]) -> None:
    try:
        async for frame in connection:
            frames.append(frame)
    except websockets.ConnectionClosed:
        pass


async def costly_attack(attacked_url: str, healthy_url: str
                        ) -> tuple[float, float, list[Any], int]:
    """32 sockets from 127.0.0.2 on ``attacked_url`` asking png and fragment sizes from 1 to
    1148 on four topics, while a healthy client counts /odom on ``healthy_url``."""
    frames: list[Any] = []
    refused = 0
    async with OdomListener(healthy_url) as healthy:
        await asyncio.sleep(1.0)
        sockets = []
        for number in range(32):
            try:
                connection = await attacker(attacked_url)
            except (websockets.InvalidStatus, OSError):
                refused += 1  # a per-address budget may refuse some: fine
                continue
            size = 1 + 37 * number
            for topic in ("/scan", "/odom", "/tf", "/ground_truth"):
                await connection.send(json.dumps({
                    "op": "subscribe", "topic": topic, "fragment_size": size,
                    "compression": "png" if number % 2 else "none"}))
            sockets.append(connection)
        readers = [asyncio.create_task(read_all(ws, frames)) for ws in sockets]
        await asyncio.sleep(1.0)
        start = healthy.mark()
        await asyncio.sleep(4.0)
        rate_hz, gap_s = healthy.rate_since(start)
        for connection in sockets:
            await connection.close()
        await asyncio.gather(*readers)
    return rate_hz, gap_s, frames, refused


@pytest.mark.slow
def test_costly_encodings_on_one_class_robot_never_make_anothers_odom_late(
        tmp_path: Any) -> None:
    server = start_server(["--class", "2"])
    try:
        base = f"ws://127.0.0.1:{server.ws_port}/robots/"
        rate_hz, gap_s, frames, refused = asyncio.run(
            costly_attack(base + "robot01", base + "robot02"))
        print(f"class: robot02's /odom {rate_hz:.2f} Hz, largest gap {gap_s:.3f} s, while "
              f"robot01 is attacked ({len(frames)} frames, {refused} sockets refused)")
        assert rate_hz >= MIN_HEALTHY_HZ, f"healthy client saw /odom at {rate_hz:.1f} Hz"
        assert gap_s <= MAX_GAP_S, f"healthy client saw a {gap_s:.3f} s gap"
        assert frames or refused
    finally:
        server.stop()


@pytest.mark.slow
def test_costly_encodings_asked_by_many_sockets_never_make_a_healthy_client_late(
        server: ServerProcess) -> None:
    rate_hz, gap_s, frames, refused = asyncio.run(costly_attack(server.ws_url, server.ws_url))
    print(f"healthy /odom {rate_hz:.2f} Hz, largest gap {gap_s:.3f} s; attacker got "
          f"{len(frames)} frames, {refused} sockets refused")
    assert rate_hz >= MIN_HEALTHY_HZ, f"healthy client saw /odom at {rate_hz:.1f} Hz"
    assert gap_s <= MAX_GAP_S, f"healthy client saw a {gap_s:.3f} s gap"
    fragments = [json.loads(f) for f in frames if isinstance(f, str) and '"fragment"' in f[:20]]
    assert fragments, "the attacker's fragments never came (it is served, later)"
    assert min(len(f["data"]) for f in fragments if f["num"] < f["total"] - 1) >= 256
    assert server.health()["status"] == "ok"


@pytest.mark.slow
def test_latched_messages_of_short_connections_go_with_them_and_are_bounded(
        server: ServerProcess) -> None:
    size = 60_000
    message = {"data": "x" * size}

    async def one_shot(number: int) -> None:
        async with await attacker(server.ws_url) as connection:
            topic = f"/latched{number}"
            await connection.send(json.dumps({"op": "advertise", "topic": topic,
                                              "type": "std_msgs/String"}))
            await connection.send(json.dumps({"op": "publish", "topic": topic,
                                              "msg": message, "latch": True}))
            await asyncio.sleep(0.05)

    async def holder() -> list[str]:
        async with await attacker(server.ws_url) as connection:
            await connection.send(json.dumps({"op": "set_level", "level": "error"}))
            for number in range(24):
                await connection.send(json.dumps({"op": "advertise", "topic": f"/held{number}",
                                                  "type": "std_msgs/String"}))
                await connection.send(json.dumps({"op": "publish", "topic": f"/held{number}",
                                                  "msg": message, "latch": True}))
                await asyncio.sleep(0.3)  # within the relay budget
            reasons = []
            deadline = time.monotonic() + 3
            while time.monotonic() < deadline:
                try:
                    reply = json.loads(await asyncio.wait_for(connection.recv(), 0.5))
                except TimeoutError:
                    break
                if reply.get("op") == "status":
                    reasons.append(reply["msg"])
            return reasons

    async def late_subscriber_gets(topic: str) -> bool:
        async with websockets.connect(server.ws_url) as connection:
            await connection.send(json.dumps({"op": "subscribe", "topic": topic,
                                              "type": "std_msgs/String"}))
            try:
                await asyncio.wait_for(connection.recv(), 1.0)
                return True
            except TimeoutError:
                return False

    async def scenario() -> tuple[float, list[str], bool]:
        for start in range(0, 150, 10):
            await asyncio.gather(*(one_shot(n) for n in range(start, start + 10)))
        after_short = rss_mb(server)
        reasons = await holder()
        return after_short, reasons, await late_subscriber_gets("/latched7")

    before = rss_mb(server)
    after_short, reasons, kept = asyncio.run(scenario())
    print(f"server RSS {before:.0f} MB before, {after_short:.0f} MB after 150 short latched "
          f"connections, {rss_mb(server):.0f} MB after the holder")
    assert not kept, "a latched message outlived its publisher"
    assert after_short - before < 40
    assert any("this robot's latched messages hold" in r for r in reasons), reasons
    assert len([r for r in reasons if "latched messages hold" in r]) >= \
        24 - ClientLimits().robot_latched_bytes // size
    assert server.health()["status"] == "ok"


@pytest.mark.slow
def test_a_flood_of_large_service_calls_never_closes_the_provider(
        server: ServerProcess) -> None:
    big = {"data": "x" * 900_000}

    async def scenario() -> tuple[list[str], bool, dict[str, Any]]:
        provider = await websockets.connect(server.ws_url, max_size=None, max_queue=2)
        await provider.send(json.dumps({"op": "advertise_service", "service": "/provided",
                                        "type": "my_pkg/Big"}))
        await asyncio.sleep(0.3)
        reasons: list[str] = []

        async def flood(number: int) -> None:
            async with await attacker(server.ws_url) as connection:
                for call in range(3):
                    await connection.send(json.dumps({"op": "call_service",
                                                      "service": "/provided",
                                                      "id": f"{number}-{call}", "args": big}))
                    await asyncio.sleep(0.4)  # within the message rate
                deadline = time.monotonic() + 2
                while time.monotonic() < deadline:
                    try:
                        reply = json.loads(await asyncio.wait_for(connection.recv(), 0.5))
                    except TimeoutError:
                        break
                    if reply.get("result") is False:
                        reasons.append(str(reply["values"]))

        await asyncio.gather(*(flood(n) for n in range(6)))  # the provider reads nothing
        requests = 0
        answered: dict[str, Any] = {}
        async with websockets.connect(server.ws_url) as caller:
            await caller.send(json.dumps({"op": "call_service", "service": "/provided",
                                          "id": "healthy", "args": {"data": "hi"}}))
            deadline = time.monotonic() + 15
            while time.monotonic() < deadline and not answered:
                request = json.loads(await asyncio.wait_for(provider.recv(), 10))
                requests += 1
                if request.get("args") == {"data": "hi"}:
                    await provider.send(json.dumps({"op": "service_response",
                                                    "service": "/provided",
                                                    "id": request["id"],
                                                    "values": {"ok": True}, "result": True}))
                    answered = json.loads(await asyncio.wait_for(caller.recv(), 5))
        open_after = provider.state is websockets.protocol.State.OPEN
        await provider.close()
        return reasons, open_after, answered

    reasons, open_after, answered = asyncio.run(scenario())
    print(f"attacker refusals: {len(reasons)}; first: {reasons[:1]}")
    assert open_after, "the provider was closed by others' flood"
    assert answered.get("result") is True and answered.get("values") == {"ok": True}
    assert reasons and all("receiver has" in r or "bytes/s relayed" in r
                           or "rate" in r for r in reasons), reasons


@pytest.mark.slow
def test_a_latched_lone_surrogate_is_refused_and_cbor_subscribers_are_served(
        server: ServerProcess) -> None:
    async def scenario() -> tuple[list[str], list[Any]]:
        async with websockets.connect(server.ws_url) as cbor:
            await cbor.send(json.dumps({"op": "subscribe", "topic": "/text",
                                        "type": "std_msgs/String", "compression": "cbor"}))
            async with await attacker(server.ws_url) as connection:
                await connection.send(json.dumps({"op": "set_level", "level": "error"}))
                await connection.send('{"op": "publish", "topic": "/text", "latch": true, '
                                      '"msg": {"data": "\\ud800"}}')
                await connection.send(json.dumps({"op": "publish", "topic": "/text",
                                                  "msg": {"data": "fine"}}))
                status = json.loads(await asyncio.wait_for(connection.recv(), 3))
            got = await asyncio.wait_for(cbor.recv(), 3)
            return [status["msg"]], [got]

    reasons, got = asyncio.run(scenario())
    assert "lone UTF-16 surrogate" in reasons[0]
    assert isinstance(got[0], bytes) and b"fine" in got[0]
    assert server.health()["status"] == "ok"
