"""The fan-out: frames serialized once, written per client in one write, drivers first.

Real pymunk robot and bridge, real websockets framing; the last test drives a real server
over real sockets with a client that closes a loop among many that only watch.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import json
import time
import weakref
from collections.abc import AsyncIterator

import pytest
from robot_rig import robot_rig
from websockets.asyncio.client import connect
from websockets.frames import Frame as WebSocketFrame
from websockets.frames import Opcode
from websockets.streams import StreamReader

from physics import Simulation, load_world
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Session
from rosbridge.core.clock import ManualClock
from rosbridge.core.outbox import Outbox
from rosbridge.transport.front import start_websocket
from rosbridge.transport.wire import WireFrames, serialize
from rosbridge.transport.writers import Writers
from websim.robot_server import SimServer

TWIST = {"linear": {"x": 0.1, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


def parse_frame(data: bytes) -> WebSocketFrame:
    """Parse ``data`` as one frame, the way a websockets client reads it."""
    reader = StreamReader()
    reader.feed_data(data)
    reader.feed_eof()
    parser = WebSocketFrame.parse(reader.read_exact, mask=False)
    try:
        next(parser)
    except StopIteration as done:
        return done.value
    raise AssertionError("the frame was incomplete")


@pytest.mark.parametrize("size", [0, 125, 126, 65535, 65536, 300_000])
def test_serialized_text_frames_parse_back_at_every_length_encoding(size: int) -> None:
    text = "é" * (size // 2) + "x" * (size % 2)  # multi-byte UTF-8: bytes, not characters
    frame = parse_frame(serialize(text))
    assert frame.opcode is Opcode.TEXT and frame.fin
    assert frame.data.decode() == text


def test_binary_frames_stay_binary() -> None:
    frame = parse_frame(serialize(b"\x00\xff" * 100))
    assert frame.opcode is Opcode.BINARY and frame.data == b"\x00\xff" * 100


def test_the_memo_frames_a_message_once_and_stays_within_its_budget() -> None:
    memo = WireFrames(max_bytes=10_000)
    message = "x" * 1000
    first = memo.of(message)
    assert memo.of(message) is first  # the same bytes object: not framed again
    for index in range(30):  # 30 KB of other messages through a 10 KB memo
        memo.of(f"{index:04d}" + "y" * 996)
        assert memo.held_bytes <= 10_000
    assert memo.of(message) == first  # dropped and framed again, identically


def test_take_gives_the_pop_order_and_respects_its_budget() -> None:
    def filled() -> Outbox:
        outbox = Outbox()
        outbox.put_topic("/a", "a1", 5)
        outbox.put_reply("r1")
        outbox.put_topic("/b", "b1", 5)
        outbox.put_topic("/a", "a2", 5)
        outbox.put_reply("r2")
        return outbox

    popped = filled()
    order = []
    while (frame := popped.pop()) is not None:
        order.append(frame)
    assert order == ["r1", "r2", "a1", "b1", "a2"]
    everything = filled()
    assert everything.take(1000) == order
    assert everything.queued_bytes == 0 and len(everything) == 0 and everything.pop() is None
    part = filled()
    assert part.take(5) == ["r1", "r2", "a1"]  # at most about the budget, in order
    assert part.take(1000) == ["b1", "a2"]


def test_a_client_that_drives_gets_its_odom_before_it_is_queued_for_watchers() -> None:
    rig = robot_rig()
    robot, bridge = rig.robot, rig.bridge
    seen_by_driver: list[int] = []
    watchers = [Session(f"watcher-{i}", False, Outbox()) for i in range(20)]

    def driver_sends() -> None:  # what the driver's connection writes, and when
        if len(driver.outbox) and not seen_by_driver:
            seen_by_driver.append(sum(len(watcher.outbox) for watcher in watchers))

    driver = Session("driver", False, Outbox())
    for session in [*watchers[:10], driver, *watchers[10:]]:
        bridge.connect(session)
        bridge.handle(session, json.dumps({"op": "subscribe", "topic": "/odom"}))
    bridge.handle(driver, json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST}))
    for flush in bridge.publish_many([(spec.name, msg) for spec, msg in robot.step()]):
        if driver in flush.now:  # what the transport writes at once
            driver_sends()
    assert seen_by_driver == [0]  # written while no watcher had it queued yet
    assert all(len(watcher.outbox) == 1 for watcher in watchers)
    assert len(driver.outbox) == 1  # (the test's send callback does not take it)


def test_a_watcher_is_not_served_first() -> None:
    rig = robot_rig()
    robot, bridge = rig.robot, rig.bridge
    sent: list[str] = []
    sessions = [Session(f"c{i}", False, Outbox()) for i in range(3)]
    for session in sessions:
        bridge.connect(session)
        bridge.handle(session, json.dumps({"op": "subscribe", "topic": "/odom"}))
    for flush in bridge.publish_many([(spec.name, msg) for spec, msg in robot.step()]):
        sent.extend(session.peer for session in flush.now)  # written at once
    assert sent == []  # nobody drives: every frame waits for the tick's one write


def test_the_transport_writes_a_driver_at_once_and_each_watcher_once_after_the_tick() -> None:
    async def scenario() -> list[str]:
        rig = robot_rig()
        robot, bridge, writers = rig.robot, rig.bridge, Writers()
        written: list[str] = []
        sessions = [Session(name, False, Outbox()) for name in ("w0", "driver", "w1")]
        for session in sessions:
            bridge.connect(session)
            writers.add(session.outbox, lambda session=session: (
                written.append(session.peer), session.outbox.take(1 << 20)))
            writers.write(bridge.handle(session, json.dumps({"op": "subscribe",
                                                             "topic": "/odom"})))
        writers.write(bridge.handle(sessions[1], json.dumps(
            {"op": "publish", "topic": "/cmd_vel", "msg": TWIST})))
        await asyncio.sleep(0)
        written.clear()
        for _ in range(2):  # two ticks in one callback: still one write per watcher
            for flush in bridge.publish_many([(spec.name, msg) for spec, msg in robot.step()]):
                writers.write(flush)
        assert written == ["driver", "driver"]  # at once, each tick
        await asyncio.sleep(0)  # the callback is done
        assert sorted(written[2:]) == ["w0", "w1"]
        for spec, msg in robot.step():  # Flushes not written: the next tick's sweep does it
            bridge.publish(spec.name, msg)
        writers.sweep()
        return written[4:]

    assert sorted(asyncio.run(scenario())) == ["driver", "w0", "w1"]


@contextlib.asynccontextmanager
async def embedded_server() -> AsyncIterator[tuple[SimServer, str]]:
    """A real server in this event loop, ticking, on a free port: (server, its URL)."""
    server = SimServer(VirtualRobot(Simulation(load_world("empty"), seed=0)), "t")
    listening = await start_websocket(server, "127.0.0.1", 0)
    port = listening.sockets[0].getsockname()[1]
    ticks = asyncio.create_task(server.run_ticks())
    try:
        yield server, f"ws://127.0.0.1:{port}/"
    finally:
        ticks.cancel()
        listening.close()
        await listening.wait_closed()


def test_many_watchers_and_one_driver_over_real_sockets() -> None:
    """Every watcher gets every /odom in order, in whole frames; the driver's commands show."""
    async def scenario() -> None:
        async with embedded_server() as (_, url):
            watchers = [await connect(url, compression=None) for _ in range(30)]
            driver = await connect(url, compression=None)
            for connection in [*watchers, driver]:
                await connection.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
            await driver.send(json.dumps({"op": "advertise", "topic": "/cmd_vel",
                                          "type": "geometry_msgs/msg/Twist"}))
            speeds = []
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline and len(speeds) < 10:
                await driver.send(json.dumps({"op": "publish", "topic": "/cmd_vel",
                                              "msg": TWIST}))
                message = json.loads(await asyncio.wait_for(driver.recv(), 5.0))
                speeds.append(message["msg"]["twist"]["twist"]["linear"]["x"])
            assert speeds[-1] == pytest.approx(0.1)
            for watcher in watchers:
                stamps = []
                for _ in range(5):
                    message = json.loads(await asyncio.wait_for(watcher.recv(), 5.0))
                    stamp = message["msg"]["header"]["stamp"]
                    stamps.append(stamp["sec"] + 1e-9 * stamp["nanosec"])
                assert stamps == sorted(stamps) and len(set(stamps)) == 5
            for connection in [*watchers, driver]:
                await connection.close()

    asyncio.run(scenario())


def test_a_driver_gets_all_of_its_tick_in_one_write() -> None:
    rig = robot_rig()
    robot, bridge = rig.robot, rig.bridge
    writes: list[int] = []
    driver = Session("driver", False, Outbox())
    bridge.connect(driver)
    for topic in ("/odom", "/tf", "/scan"):
        bridge.handle(driver, json.dumps({"op": "subscribe", "topic": topic}))
    bridge.handle(driver, json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST}))
    writes.clear()
    published = []
    for _ in range(2):  # /scan comes every second tick
        messages = [(spec.name, msg) for spec, msg in robot.step()]
        published.append(sum(name in ("/odom", "/tf", "/scan") for name, _ in messages))
        for flush in bridge.publish_many(messages):
            if driver in flush.now:  # what the transport writes at once
                writes.append(len(driver.outbox))
        driver.outbox.take(1 << 20)  # what the connection's write takes
    assert sorted(published) == [2, 3]
    assert writes == published  # each tick's /odom, /tf (and /scan): one write


def test_only_the_messages_someone_subscribes_to_are_built() -> None:
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0))
    assert [spec.name for spec, _ in robot.step(wanted={"/odom"})] == ["/odom"]
    assert [spec.name for spec, _ in robot.step(wanted={"/odom", "/scan"})] == \
        ["/odom", "/scan"]  # the scan tick
    heard: list[list[str]] = [[]]
    robot.tap.add(lambda direction, topic, *_: heard[-1].append(topic))
    robot.step(wanted={"/odom"})  # a tap (the ROS node) gets everything
    assert heard == [["/clock", "/odom", "/tf", "/ground_truth", "/joint_states"]]


def test_a_throttle_counts_from_when_ticks_were_due_so_late_ticks_lose_nothing() -> None:
    rig = robot_rig(clock=ManualClock(100.0))
    host, clock = rig.host, rig.clock
    watcher = Session("dashboard", True, Outbox())
    host.bridge.connect(watcher)
    host.bridge.handle(watcher, json.dumps({"op": "subscribe", "topic": "/odom",
                                            "throttle_rate": 200, "queue_length": 100}))
    lateness = [0.0, 0.018, 0.0, 0.002, 0.019, 0.0, 0.011, 0.0] * 5  # up to 19 ms late
    delivered = []
    for tick, late_s in enumerate(lateness):
        clock.advance(100.0 + 0.05 * tick + late_s - clock.monotonic_s())
        queued = len(watcher.outbox)
        rig.tick_now(late_s)
        if len(watcher.outbox) > queued:
            delivered.append(tick)
    assert delivered == list(range(0, len(lateness), 4))  # every fourth tick, on the grid


def test_a_closed_connection_is_freed_at_once_not_at_the_next_full_collection() -> None:
    """A client's buffers (up to a megabyte a frame) must not wait for the cyclic GC."""
    async def scenario() -> None:
        async with embedded_server() as (server, url):
            async with connect(url, compression=None) as client:
                await client.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
                await asyncio.wait_for(client.recv(), 5.0)
                session, = server.bridge.sessions
                gone = weakref.ref(session)
                del session
            deadline = time.monotonic() + 5.0
            while server.bridge.sessions and time.monotonic() < deadline:
                await asyncio.sleep(0.02)
            for _ in range(5):  # let the connection's tasks finish
                await asyncio.sleep(0.05)
            assert gone() is None, [type(r).__name__ for r in gc.get_referrers(gone())]

    gc.disable()
    try:
        asyncio.run(scenario())
    finally:
        gc.enable()
