"""Sim time and faster than real time: ``SimClock``, ``--speed``, ``/clock``, lossless ``max``.

Real servers (``websim serve --speed ...``) with real clients (roslibpy, raw sockets), the
command line in-process, and the robot rig for what one tick stamps. The ROS graph's side
(``use_sim_time`` at ``--speed 10``) is in ``test_sim_time_ros.py``.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import math
import threading
import time
from typing import Any

import pytest
import roslibpy
from robot_rig import robot_rig

from heartbeat.schedule import CLIENT_WAIT_S
from physics.params import SHIPPED_PARAMS_FILE
from ros_nodes.sim_clock import MAX_SPEED, MIN_SPEED, SPEED_MAX, SimClock
from rosbridge.core.clock import ManualClock
from rosbridge.core.limits import ClientLimits
from websim.cli import main, make_simulation

from server_process import roslibpy_client, start_server, wait_for
from ws_clients import NonReader

TICK_NS = 50_000_000
RUN_TICKS = 1200
"""60 s of sim time."""

COMMAND = {"linear": {"x": 0.3, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.5}}


def stamp_ns(stamp: dict[str, int]) -> int:
    return int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"])


def consecutive(stamps_ns: list[int]) -> bool:
    """Whether the stamps are one tick apart each, none missing."""
    return all(b - a == TICK_NS for a, b in itertools.pairwise(stamps_ns))


# ---- the clock ---------------------------------------------------------------------------


def test_sim_time_starts_at_the_wall_time_of_the_start_and_moves_one_tick_per_tick() -> None:
    wall = ManualClock(5.0, epoch_s=1_700_000_000.0)
    clock = SimClock(0.05, speed=10.0, wall=wall)
    assert clock.stamp_s() == 1_700_000_005.0  # the wall clock's stamp when it started
    wall.advance(3.0)
    assert clock.stamp_s() == 1_700_000_005.0  # wall time passing moves no stamp
    assert clock.monotonic_s() == 8.0  # intervals are wall time
    rig = robot_rig(clock=clock)  # type: ignore[arg-type]
    assert clock.following, "the robot's world's ticks: the one tick counter"
    for _ in range(3):
        rig.tick_now()
    assert clock.ticks == rig.robot.sim.world_sim.tick == 3
    assert clock.stamp_s() == pytest.approx(1_700_000_005.15, abs=1e-6)


def test_stamps_of_sim_time_are_exact_to_the_nanosecond_after_days() -> None:
    clock = SimClock(0.05, epoch_s=1_767_225_600.123456,
                     ticks=lambda: 20 * 86_400 * 3 + 1)  # three days of ticks, and one
    rig = robot_rig(clock=clock)  # type: ignore[arg-type]
    admin = rig.client(admin=True)
    now = rig.call(admin, "/rosapi/get_time")["values"]["time"]
    expected_ns = 1_767_225_600_123_456_000 + (20 * 86_400 * 3 + 1) * TICK_NS
    assert stamp_ns(now) == expected_ns


@pytest.mark.parametrize("speed", [0.0, -1.0, MIN_SPEED / 2, MAX_SPEED * 2, float("nan")])
def test_a_sim_clock_refuses_a_speed_out_of_its_range(speed: float) -> None:
    with pytest.raises(ValueError, match=r"speed must be 0\.1 to 100 times real time, or max"):
        SimClock(0.05, speed=speed)


def test_every_message_of_a_tick_is_stamped_with_the_time_clock_says() -> None:
    clock = SimClock(0.05, speed=SPEED_MAX, epoch_s=1_700_000_000.0)
    rig = robot_rig(clock=clock)  # type: ignore[arg-type]
    client = rig.client()
    for topic in ("/clock", "/odom", "/tf", "/scan", "/ground_truth"):
        rig.send(client, {"op": "subscribe", "topic": topic})
    published: list[dict[str, Any]] = []
    for _ in range(4):
        rig.tick_now()  # the world steps: its tick is the clock's
        published += [frame for frame in rig.drain(client) if frame.get("op") == "publish"]
    clocks = [stamp_ns(f["msg"]["clock"]) for f in published if f["topic"] == "/clock"]
    assert clocks == [1_700_000_000_000_000_000 + n * TICK_NS for n in (1, 2, 3, 4)]
    for frame in published:
        msg = frame["msg"]
        stamp = msg["clock"] if frame["topic"] == "/clock" else (
            msg["transforms"][0]["header"]["stamp"] if frame["topic"] == "/tf"
            else msg["header"]["stamp"])
        assert stamp_ns(stamp) in clocks
    assert [f["topic"] for f in published][:4] == ["/clock", "/odom", "/tf", "/ground_truth"]


def test_the_cmd_vel_watchdog_counts_sim_time_whatever_the_wall_clock_does() -> None:
    wall = ManualClock()
    clock = SimClock(0.05, speed=SPEED_MAX, wall=wall)
    rig = robot_rig(clock=clock)  # type: ignore[arg-type]
    rig.robot.parameters.set_many({"cmd_vel_timeout_s": 0.5})
    admin = rig.client(admin=True)
    rig.send(admin, {"op": "publish", "topic": "/cmd_vel",
                     "msg": {**COMMAND, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}})
    xs = []
    for _ in range(30):
        wall.advance(5.0)  # wall time races ahead: the watchdog does not read it
        rig.tick_now()
        xs.append(rig.robot.sim.ground_truth().x)
    steps = [b - a for a, b in itertools.pairwise([0.0, *xs])]
    # 0.5 s of sim time at 0.3 m/s: ten ticks of 15 mm, then it stands (as at real time).
    assert steps[:10] == pytest.approx([0.015] * 10, abs=1e-12)
    assert steps[10:] == [0.0] * 20


# ---- the command line --------------------------------------------------------------------


@pytest.mark.parametrize("command", ["serve", "demo"])
@pytest.mark.parametrize(("value", "hint"), [
    ("0", ""), ("-1", ""), ("nan", ""), ("inf", "(as fast as the host allows is 'max')"),
    ("fast", ""), ("1e9", "(as fast as the host allows is 'max')"), ("0.05", ""),
])
def test_a_bad_speed_is_a_clear_command_line_error(command: str, value: str, hint: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main([command, f"--speed={value}"])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert (f"argument --speed: expected a number of times real time from 0.1 to 100, or "
            f"'max', got '{value}'") in err
    assert hint in err


def test_demo_at_a_speed_runs_at_that_pace_and_at_max_as_fast_as_it_can(
        capsys: pytest.CaptureFixture[str]) -> None:
    started = time.monotonic()
    assert main(["demo", "--seconds", "2", "--speed", "10", "--angular", "0"]) == 0
    paced_s = time.monotonic() - started
    paced = capsys.readouterr().out
    assert paced_s >= 0.19  # 2 s of sim time at 10x: a pace not to exceed
    assert main(["demo", "--seconds", "2", "--speed", "max", "--angular", "0"]) == 0
    assert capsys.readouterr().out == paced  # the same run, only faster


# ---- faster than real time over the bridge ------------------------------------------------


def headless_poses(world: str, mode: str, ticks: int) -> list[tuple[float, float, float]]:
    """The odometry poses (x, y, yaw) of a physics-only run of ``COMMAND``, tick by tick."""
    sim = make_simulation(argparse.Namespace(world=world, mode=mode, seed=0,
                                             params=str(SHIPPED_PARAMS_FILE)))
    sim.command(COMMAND["linear"]["x"], COMMAND["angular"]["z"])
    poses = []
    for _ in range(ticks):
        sim.step()
        odom = sim.odometry()
        poses.append((odom.x, odom.y, odom.theta))
    return poses


def pose_of(msg: dict[str, Any]) -> tuple[float, float, float]:
    """An /odom's pose: x, y (m) and yaw (rad) in ``odom``."""
    pose = msg["pose"]["pose"]
    q = pose["orientation"]
    return (pose["position"]["x"], pose["position"]["y"],
            2.0 * math.atan2(q["z"], q["w"]))


def test_at_max_speed_a_client_gets_every_odom_and_the_run_is_the_headless_one() -> None:
    server = start_server(["--speed", "max", "--world", "maze", "--mode", "dynamic"])
    try:
        with roslibpy_client(server) as ros:
            odom: list[dict[str, Any]] = []
            clock: list[dict[str, Any]] = []
            scans: list[dict[str, Any]] = []
            done = threading.Event()

            def on_odom(msg: dict[str, Any]) -> None:
                odom.append(msg)
                if len(odom) >= RUN_TICKS + 200:
                    done.set()

            roslibpy.Topic(ros, "/clock", "rosgraph_msgs/msg/Clock").subscribe(clock.append)
            roslibpy.Topic(ros, "/scan", "sensor_msgs/msg/LaserScan").subscribe(scans.append)
            wait_for(lambda: clock and scans, 10.0, "/clock and /scan at max speed")
            roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(on_odom)
            wait_for(lambda: len(odom) >= 20, 10.0, "/odom at max speed")
            cmd_vel = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
            cmd_vel.publish(roslibpy.Message(COMMAND))
            assert done.wait(60.0), f"{len(odom)} /odom in 60 s of wall time"
        health = server.health()
    finally:
        server.stop()
    odom_ns = [stamp_ns(msg["header"]["stamp"]) for msg in odom]
    clock_ns = [stamp_ns(msg["clock"]) for msg in clock]
    assert consecutive(odom_ns), "an /odom was dropped"
    assert consecutive(clock_ns), "a /clock was dropped"
    assert set(odom_ns) <= set(clock_ns)
    scan_ns = [stamp_ns(msg["header"]["stamp"]) for msg in scans]
    assert all(b - a == 2 * TICK_NS for a, b in itertools.pairwise(scan_ns)), "a /scan dropped"
    assert health["speed"] == "max" and health["scans_shed"] == 0
    assert health["clients_released"] == 0
    assert health["sim_time_s"] > 5 * health["uptime_s"]  # far faster than real time

    # The robot stood at spawn until the tick the command arrived at (whichever that was):
    # from its first tick on, the run must be the headless run's, tick for tick.
    at_rest = odom[0]["twist"]["twist"]
    assert pose_of(odom[0]) == (0.0, 0.0, 0.0)
    moving = next(index for index, msg in enumerate(odom) if msg["twist"]["twist"] != at_rest)
    assert all(pose_of(msg) == (0.0, 0.0, 0.0) for msg in odom[:moving])
    run = odom[moving:moving + RUN_TICKS]
    assert len(run) == RUN_TICKS  # 60 s of sim time, every tick
    expected = headless_poses("maze", "dynamic", RUN_TICKS)
    for got, want in zip(map(pose_of, run), expected, strict=True):
        assert got[:2] == pytest.approx(want[:2], abs=1e-9)
        assert math.remainder(got[2] - want[2], math.tau) == pytest.approx(0.0, abs=1e-9)
    last_x, last_y, _ = pose_of(run[-1])
    assert (last_x, last_y) != pytest.approx((0.0, 0.0), abs=0.05)  # it went somewhere


@pytest.mark.slow
def test_at_max_speed_a_stalled_client_is_released_and_the_others_lose_nothing() -> None:
    server = start_server(["--speed", "max"])
    try:
        async def scenario() -> tuple[list[int], dict[str, Any], dict[str, Any], bool]:
            from websockets.asyncio.client import connect

            stamps: list[int] = []
            async with connect(server.ws_url, max_size=None) as healthy:
                await healthy.send(json.dumps({"op": "subscribe", "topic": "/odom"}))

                async def listen() -> None:
                    async for frame in healthy:
                        message = json.loads(frame)
                        if message.get("topic") == "/odom":
                            stamps.append(stamp_ns(message["msg"]["header"]["stamp"]))

                listening = asyncio.create_task(listen())
                await asyncio.to_thread(wait_for, lambda: len(stamps) > 100, 10.0, "/odom")
                stalled = NonReader(server.ws_port)
                for topic in ("/odom", "/scan", "/tf", "/ground_truth", "/clock"):
                    stalled.send({"op": "subscribe", "topic": topic})
                released = await asyncio.to_thread(
                    wait_for, lambda: (health := server.health())["clients_released"] and
                    health, 20.0, "the stalled client to be released")
                await asyncio.to_thread(wait_for,
                                        lambda: server.health()["ticks"] >
                                        released["ticks"] + 2000,
                                        10.0, "the robot to go on without the stalled client")
                later = server.health()
                # the watchdog closes it once its socket has taken nothing for its stall timeout
                limits = ClientLimits()
                await asyncio.to_thread(
                    wait_for, lambda: server.health()["clients"] == 1,
                    limits.stall_timeout_s + limits.close_timeout_s + 10.0,
                    "the stalled client to be closed")
                closed = stalled.is_closed_by_server()
                stalled.close()
                listening.cancel()
            return stamps, released, later, closed

        stamps, released, later, closed = asyncio.run(scenario())
    finally:
        server.stop()
    assert released["clients_released"] == 1
    assert later["ticks"] > released["ticks"] + 2000
    assert consecutive(stamps), "the healthy client lost an /odom while the other stalled"
    assert len(stamps) > 2000
    assert closed
    assert "not reading: the socket accepted nothing for" in "".join(server.output)
    assert f"did not take one tick's frames within {CLIENT_WAIT_S:g} s" in \
        "".join(server.output)


# ---- a class -------------------------------------------------------------------------------


def test_each_robot_of_a_class_runs_on_its_own_clock_at_the_class_speed() -> None:
    """A world each, a pace each (``test_pace.py``), all from the one start: sim time
    counts each world's ticks from the same epoch."""
    server = start_server(["--class", "2", "--speed", "20"])
    try:
        clocks: dict[str, list[int]] = {"robot01": [], "robot02": []}
        clients = []
        try:
            for name, received in clocks.items():
                ros = roslibpy.Ros(host=f"{server.ws_url}robots/{name}")
                ros.run(timeout=10)
                clients.append(ros)
                roslibpy.Topic(ros, "/clock", "rosgraph_msgs/msg/Clock").subscribe(
                    lambda msg, into=received: into.append(stamp_ns(msg["clock"])))
            wait_for(lambda: all(len(received) > 200 for received in clocks.values()), 30.0,
                     "/clock of both robots")
        finally:
            for ros in clients:
                ros.close()
        health = server.health()
    finally:
        server.stop()
    for received in clocks.values():
        assert consecutive(received[:200])
    epochs = {(received[0] - TICK_NS) % TICK_NS for received in clocks.values()}
    assert len(epochs) == 1, "one epoch: the server's start"
    robots = health["robots"]
    assert {robot["speed"] for robot in robots.values()} == {20.0}
    assert all(robot["clients_released"] == 0 for robot in robots.values())
