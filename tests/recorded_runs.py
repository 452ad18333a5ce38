"""Real recordings for the validation tests: ``websim serve --record`` driven by roslibpy.

``record_program`` starts a real server on sim time (``--speed``), with the parameter file
given, and publishes a program of ``/cmd_vel`` steps on the sim time it reads from ``/clock``
(so each step lasts its sim-time duration however loaded the machine is); at the end it stops
the server (SIGTERM closes the bag) and returns the bag's folder.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path

import roslibpy

from server_process import start_server, wait_for

Step = tuple[float, float, float]
"""(duration s of sim time, linear.x m/s, angular.z rad/s)."""

EXCITING_PROGRAM: tuple[Step, ...] = (
    (1.0, 0.0, 0.0), (2.0, 0.3, 0.0), (1.0, 0.0, 0.0), (1.5, 0.0, 1.2), (1.0, 0.0, 0.0),
    (2.0, 0.2, 0.6), (1.0, 0.0, -1.5), (1.5, -0.25, 0.0), (1.0, 0.0, 0.0), (2.0, 0.35, -0.8),
    (1.0, 0.1, 0.0), (1.5, 0.0, 2.0), (1.0, 0.0, 0.0), (2.0, 0.25, 0.9), (1.0, 0.0, 0.0),
    (1.5, -0.2, -1.0), (1.5, 0.3, 0.3), (1.0, 0.0, 0.0),
)
"""Steps of both speeds, up and down, turning both ways: what a fit needs to see (24 s)."""


def twist(linear: float, angular: float) -> dict[str, dict[str, float]]:
    return {"linear": {"x": linear, "y": 0.0, "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": angular}}


def record_program(bags: Path, program: Sequence[Step], params: Path | None = None,
                   speed: float = 4.0, world: str = "empty") -> Path:
    """Drive ``program`` on a recording server; the bag's folder once it is closed."""
    extra = ["--record", str(bags), "--speed", str(speed), "--world", world]
    if params is not None:
        extra += ["--params", str(params)]
    server = start_server(extra)
    try:
        client = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
        client.run(timeout=10)
        cmd_vel = roslibpy.Topic(client, "/cmd_vel", "geometry_msgs/msg/Twist")
        cmd_vel.advertise()
        clock = roslibpy.Topic(client, "/clock", "rosgraph_msgs/msg/Clock")
        boundaries = []
        elapsed = 0.0
        for duration_s, _, _ in program:
            boundaries.append(elapsed)
            elapsed += duration_s
        state = {"start": None, "next": 0}
        done = threading.Event()

        def on_clock(msg: dict) -> None:
            now = msg["clock"]["sec"] + msg["clock"]["nanosec"] * 1e-9
            if state["start"] is None:
                state["start"] = now
            since = now - state["start"]
            while state["next"] < len(program) and since >= boundaries[state["next"]]:
                _, linear, angular = program[state["next"]]
                cmd_vel.publish(roslibpy.Message(twist(linear, angular)))
                state["next"] += 1
            if since >= elapsed + 1.0:
                done.set()

        clock.subscribe(on_clock)
        wait_for(done.is_set, timeout_s=60.0 + elapsed / speed * 4,
                 what="the program to be driven")
        clock.unsubscribe()
        cmd_vel.unadvertise()
        client.close()
    finally:
        server.stop()
    (bag,) = [path for path in bags.iterdir() if path.is_dir()]
    return bag
