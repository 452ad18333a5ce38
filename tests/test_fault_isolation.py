"""Faults at a robot's boundary: caught, logged once, reported, and the loop goes on.

No client input known to us can still make the robot raise (the hostile-client tests try),
so these tests provoke each kind of fault directly inside a real server running in this
process (real tick loop, real sockets, real websockets clients): the physics raising in a
step, a state gone non-finite, a message no encoder can write, one client's outbox failing,
and a handler raising. Each time ``/healthz`` must say ``degraded`` with the cause, the robot
must end in a finite state, and a healthy client must keep its 20 Hz /odom.
"""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import Awaitable, Callable
from typing import Any

import pytest
import websockets

from physics import Pose2D, Simulation, load_world
from ros_nodes.robot_interface import ODOM
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.transport.front import start_websocket
from websim.robot_server import SimServer

from server_process import free_port
from ws_clients import OdomListener

MIN_HEALTHY_HZ = 18.0

Fault = Callable[[SimServer], None]


async def run_with_fault(fault: Fault,
                         during: Callable[[str, SimServer], Awaitable[None]] | None = None,
                         mode: str = "kinematic") -> tuple[dict[str, Any], float, SimServer]:
    """Serve a robot, start a listener, provoke ``fault``; (health, listener Hz, server)."""
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0, mode=mode))
    server = SimServer(robot, "token")
    port = free_port()
    listening = await start_websocket(server, "127.0.0.1", port)
    ticking = asyncio.create_task(server.run_ticks())
    url = f"ws://127.0.0.1:{port}/"
    try:
        async with OdomListener(url) as listener:
            await asyncio.sleep(0.5)
            start = listener.mark()
            fault(server)
            if during is not None:
                await during(url, server)
            await asyncio.sleep(1.5)
            rate_hz, _ = listener.rate_since(start)
        return server.health(), rate_hz, server
    finally:
        ticking.cancel()
        listening.close()
        await listening.wait_closed()


def raise_once(obj: Any, name: str, error: Exception) -> None:
    """Make ``obj.name`` raise ``error`` on its next call only (a fault, injected)."""
    original = getattr(obj, name)

    def failing(*args: Any, **kwargs: Any) -> Any:
        setattr(obj, name, original)
        raise error

    setattr(obj, name, failing)


def assert_recovered(health: dict[str, Any], rate_hz: float, server: SimServer,
                     kind: str) -> None:
    assert health["status"] == "degraded"
    assert kind in health["faults"], health["faults"]
    assert health["last_fault"].startswith(kind)
    assert all(math.isfinite(v) for v in server.robot.sim.ground_truth())
    assert rate_hz >= MIN_HEALTHY_HZ, f"the healthy client saw {rate_hz:.1f} Hz"


def test_a_physics_exception_in_a_step_is_caught_and_the_robot_reset() -> None:
    def fault(server: SimServer) -> None:
        raise_once(server.robot.sim.world_sim, "step", RuntimeError("pymunk blew up"))

    health, rate_hz, server = asyncio.run(run_with_fault(fault))
    assert_recovered(health, rate_hz, server, "stepping the robot: RuntimeError")
    assert health["robot_resets"] == 1


@pytest.mark.parametrize("mode", ["kinematic", "dynamic"])
def test_a_state_gone_non_finite_is_reset_to_spawn(mode: str) -> None:
    def fault(server: SimServer) -> None:
        server.robot.sim.model.teleport(Pose2D(math.nan, math.inf, 0.0))

    health, rate_hz, server = asyncio.run(run_with_fault(fault, mode=mode))
    assert_recovered(health, rate_hz, server, "stepping the robot: FloatingPointError")
    assert health["robot_resets"] == 1
    assert server.robot.sim.ground_truth()[:2] == pytest.approx((0.0, 0.0), abs=1e-6)


def test_a_message_no_encoder_can_write_is_a_fault_not_a_crash() -> None:
    def fault(server: SimServer) -> None:
        robot = server.robot
        messages = robot.messages

        def with_a_bad_message(sensors: Any, shed: bool = False) -> list[Any]:
            robot.messages = messages  # type: ignore[method-assign]
            return [*messages(sensors, shed), (ODOM, {"header": object()})]

        robot.messages = with_a_bad_message  # type: ignore[method-assign]

    health, rate_hz, server = asyncio.run(run_with_fault(fault))
    assert_recovered(health, rate_hz, server, "encoding /odom: TypeError")


def test_one_clients_failing_outbox_does_not_stop_the_others() -> None:
    async def victim_fails(url: str, server: SimServer) -> None:
        before = set(server.bridge.sessions)
        async with websockets.connect(url) as victim_ws:
            await victim_ws.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
            await victim_ws.recv()
            victim, = set(server.bridge.sessions) - before

            def failing(*args: Any) -> None:
                raise MemoryError("this client's outbox failed")

            victim.outbox.put_topic = failing  # type: ignore[method-assign]
            await asyncio.sleep(1.0)

    health, rate_hz, server = asyncio.run(run_with_fault(lambda server: None, victim_fails))
    assert_recovered(health, rate_hz, server, "delivering /odom: MemoryError")
    assert health["faults"]["delivering /odom: MemoryError"] >= 15  # every tick, logged once


def test_a_handler_raising_is_reported_and_the_connection_stays_open() -> None:
    replies: list[dict[str, Any]] = []

    def fault(server: SimServer) -> None:
        raise_once(server.bridge.topics, "_known_type", KeyError("bug"))

    async def subscriber(url: str, server: SimServer) -> None:
        async with websockets.connect(url) as ws:
            await ws.send(json.dumps({"op": "set_level", "level": "error"}))
            await ws.send(json.dumps({"op": "subscribe", "topic": "/odom",
                                      "type": "nav_msgs/Odometry"}))
            replies.append(json.loads(await asyncio.wait_for(ws.recv(), 3)))
            await ws.send(json.dumps({"op": "subscribe", "topic": "/odom",
                                      "type": "nav_msgs/Odometry"}))
            replies.append(json.loads(await asyncio.wait_for(ws.recv(), 3)))

    health, rate_hz, server = asyncio.run(run_with_fault(fault, subscriber))
    assert_recovered(health, rate_hz, server, "handling subscribe: KeyError")
    assert replies[0] == {"op": "status", "level": "error",
                          "msg": "internal error handling subscribe: KeyError"}
    assert replies[1]["op"] == "publish" and replies[1]["topic"] == "/odom"
