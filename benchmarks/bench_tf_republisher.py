"""What the TF republisher costs a robot's tick, up to the bounds clients may make it hold.

One robot (its host and bridge as ``websim serve`` builds them, on a manual clock, no
sockets) driving an arc while clients hold service republications, every topic subscribed,
thresholds 0 (every frame at every step: the most work) and a 20 Hz rate. The frames asked
for are the robot's five (odom, base_link, laser, the wheels) and, past five, names its tree
lacks (each a failed lookup per step: a client may ask for 32 however small the tree). It
prints, per setup, the republisher's step alone and the whole tick (the robot's step, /tf,
the fan-out and the step) in ms, mean and p99 over ``--ticks`` ticks, and the messages sent
per tick, against the same tick with no republication.

The setups: none; a ros3djs page (1 client, 1 republication of 5 frames); ten pages; and
the per-bridge bound (8 clients x 8 republications x 32 frames: 2048 frames per step).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

from physics import Simulation, load_world
from ros_nodes.robot_host import RobotHost
from ros_nodes.virtual_robot_core import VirtualRobot
from ros_nodes.world_host import WorldHost
from rosbridge.core.clock import ManualClock
from rosbridge.core.outbox import Outbox
from rosbridge.core.session import Session
from rosbridge.tf.republisher import REPUBLISH_SERVICE, RepublisherLimits

FRAMES = ("base_link", "laser", "odom", "left_wheel", "right_wheel")


def connect(host: RobotHost, peer: str) -> Session:
    session = Session(peer, False, Outbox())
    host.bridge.connect(session)
    return session


def send(host: RobotHost, session: Session, message: dict[str, Any]) -> list[Any]:
    """``session`` sends ``message``; what it was sent back (JSON frames)."""
    host.bridge.handle(session, json.dumps(message))
    replies = []
    while (frame := session.outbox.pop()) is not None:
        replies.append(json.loads(frame))
    return replies


def setup(clients: int, republications: int,
          frames: int) -> tuple[WorldHost, RobotHost, ManualClock]:
    """A robot driving an arc, with the republications held and subscribed."""
    clock = ManualClock()
    world, host = WorldHost.of(VirtualRobot(Simulation(load_world("empty")), clock))
    send(host, connect(host, "driver"), {"op": "publish", "topic": "/cmd_vel", "msg": {
        "linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.3}}})
    names = [FRAMES[i % len(FRAMES)] + ("" if i < len(FRAMES) else f"_{i}")
             for i in range(frames)]
    for n in range(clients):
        page = connect(host, f"page{n}")
        for _ in range(republications):
            [reply] = send(host, page, {"op": "call_service", "service": REPUBLISH_SERVICE,
                                        "args": {"source_frames": names, "target_frame": "odom",
                                                 "angular_thres": 0.0, "trans_thres": 0.0,
                                                 "rate": 20.0,
                                                 "timeout": {"sec": 0, "nanosec": 0}}})
            assert reply["result"], reply
            send(host, page, {"op": "subscribe", "topic": reply["values"]["topic_name"]})
    return world, host, clock


def measure(world: WorldHost, host: RobotHost, clock: ManualClock,
            ticks: int) -> dict[str, float]:
    """Mean and p99 (ms) of the step alone and of the whole tick; messages sent per tick."""
    sessions = list(host.bridge.sessions)
    totals: list[float] = []
    step = host.tf_republisher.step
    timed: list[float] = []

    def timed_step(now_s: float | None = None) -> None:
        start = time.perf_counter()
        step(now_s)
        timed.append(time.perf_counter() - start)

    host.tf_republisher.step = timed_step  # type: ignore[method-assign]
    sent = 0
    for _ in range(ticks):
        start = time.perf_counter()
        world.tick(lambda flush: None)
        totals.append(time.perf_counter() - start)
        clock.advance(host.robot.sim.dt_s)
        for session in sessions:
            while session.outbox.pop() is not None:
                sent += 1
    steps = timed

    def p99(values: list[float]) -> float:
        return 1000 * sorted(values)[int(0.99 * (len(values) - 1))]

    return {"step_mean_ms": 1000 * statistics.fmean(steps), "step_p99_ms": p99(steps),
            "tick_mean_ms": 1000 * statistics.fmean(totals), "tick_p99_ms": p99(totals),
            "messages_per_tick": sent / ticks}


def main(argv: list[str] | None = None) -> int:
    """Print the table (or JSON with ``--json``)."""
    limits = RepublisherLimits()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ticks", type=int, default=400)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    setups = [(0, 0, 0), (1, 1, len(FRAMES)), (10, 1, len(FRAMES)),
              (limits.per_bridge // limits.per_client, limits.per_client, limits.frames)]
    rows: list[dict[str, Any]] = []
    for clients, republications, frames in setups:
        figures = measure(*setup(clients, republications, frames), args.ticks)
        rows.append({"clients": clients, "republications": republications,
                     "frames": frames, **figures})
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'clients':>7} {'reps/client':>11} {'frames':>6} {'step mean':>10} {'step p99':>9} "
          f"{'tick mean':>10} {'tick p99':>9} {'messages/tick':>13}")
    for row in rows:
        print(f"{row['clients']:>7} {row['republications']:>11} {row['frames']:>6} "
              f"{row['step_mean_ms']:>8.3f}ms {row['step_p99_ms']:>7.3f}ms "
              f"{row['tick_mean_ms']:>8.3f}ms {row['tick_p99_ms']:>7.3f}ms "
              f"{row['messages_per_tick']:>13.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
