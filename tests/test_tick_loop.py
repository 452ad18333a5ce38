"""The server's tick loop, run in-process on a real event loop with a real robot and bridge.

An overloaded host is made real here: a task that holds the event loop for longer than a
tick, as a flood of client work would. The loop must keep /odom at one per tick and give up
/scan first.
"""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

from heartbeat.schedule import Schedule
from physics import Simulation, load_world
from ros_nodes.robot_host import SHED_SCANS_AFTER_S
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Session
from rosbridge.core.outbox import Outbox
from rosbridge.core.schema import MAX_QUEUE_LENGTH
from websim.robot_server import SimServer

TICKS = 40


def subscribed_client(server: SimServer) -> Session:
    """A session on /odom and /scan that keeps every frame (40 /odom, 20 /scan: < 100)."""
    session = Session("test-peer", False, Outbox())
    server.bridge.connect(session)
    for topic in ("/odom", "/scan"):
        server.bridge.handle(session, json.dumps(
            {"op": "subscribe", "topic": topic, "queue_length": MAX_QUEUE_LENGTH}))
    return session


def published_topics(session: Session) -> list[str]:
    topics = []
    while (frame := session.outbox.pop()) is not None:
        message: Any = json.loads(frame)
        if message.get("op") == "publish":
            topics.append(message["topic"])
    return topics


async def run_until(server: SimServer, ticks: int, hog_s: float) -> None:
    """Tick until ``ticks`` have run while another task holds the loop ``hog_s`` at a time."""

    async def hog() -> None:
        while True:
            time.sleep(hog_s)  # blocking on purpose: this is the overload
            await asyncio.sleep(0)

    ticking = asyncio.create_task(server.run_ticks())
    hogging = asyncio.create_task(hog()) if hog_s > 0 else None
    while server.stats.ticks < ticks:
        await asyncio.sleep(0.005)
    for task in (ticking, hogging):
        if task is not None:
            task.cancel()
    await asyncio.gather(ticking, *(t for t in (hogging,) if t), return_exceptions=True)


def test_an_overloaded_loop_sheds_scans_and_keeps_odometry() -> None:
    server = SimServer(VirtualRobot(Simulation(load_world("empty"), seed=0)), "token")
    session = subscribed_client(server)
    asyncio.run(run_until(server, TICKS, hog_s=2.5 * SHED_SCANS_AFTER_S))
    topics = published_topics(session)
    assert topics.count("/odom") == server.stats.ticks
    assert server.stats.scans_shed > 0
    assert topics.count("/scan") + server.stats.scans_shed == server.stats.ticks // 2
    assert server.stats.scans_cast == topics.count("/scan")  # a shed scan is not even cast
    assert server.health()["scans_shed"] == server.stats.scans_shed


def test_a_gate_holds_the_ticks_without_making_them_late() -> None:
    """``Schedule.gates``: no tick runs while a gate holds; the time it held is not lateness."""
    schedule = Schedule(0.05)
    lateness: list[float] = []
    opened = asyncio.Event()
    held_s = 0.4

    async def gate() -> None:
        if len(lateness) == 2:  # hold the third tick until opened
            await opened.wait()

    schedule.gates.append(gate)

    async def main() -> int:
        task = asyncio.create_task(schedule.run(lateness.append))
        while len(lateness) < 2:
            await asyncio.sleep(0.005)
        await asyncio.sleep(held_s)
        ticks_while_held = len(lateness)
        opened.set()
        while len(lateness) < 6:
            await asyncio.sleep(0.005)
        task.cancel()
        return ticks_while_held

    assert asyncio.run(main()) == 2
    assert schedule.resyncs == 0
    # after the hold the ticks go on from when it opened: none is 0.4 s late
    assert max(lateness[2:]) < held_s / 2
