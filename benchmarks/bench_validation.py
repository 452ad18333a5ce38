"""websim compare --real and websim fit on a 10-minute recording at 20 Hz: the time each takes.

The recording is made here, as a real robot's would be: a simulated robot with a driver of
its own (lag 0.12 s, scales 0.93 and 1.06, ramps 1.2 m/s^2 and 5 rad/s^2) drives a random
program of steps (a new command every 0.5 to 3 s, sent at 10 Hz as a teleop node sends it);
/cmd_vel and /odom (20 Hz) are written to a rosbag2 MCAP by rosbags. Then the two commands
run on it as a student runs them (``websim.cli.main``), each timed, with the fit's result.

    python benchmarks/bench_validation.py [--minutes 10]
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import math
import tempfile
import time
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from physics import RobotParams, Simulation
from physics.params import load_params
from physics.recorded_run import open_world
from physics.snapshots import Pose2D
from websim.cli import main

TRUE_DRIVER = {"cmd_lag_s": 0.12, "linear_scale": 0.93, "angular_scale": 1.06,
               "linear_accel_limit_mps2": 1.2, "angular_accel_limit_rps2": 5.0}


def write_recording(path: Path, minutes: float, seed: int = 0) -> int:
    """A rosbag2 MCAP of ``minutes`` of driving; returns the number of messages."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    rng = np.random.default_rng(seed)
    params = dataclasses.replace(RobotParams(), **TRUE_DRIVER)
    sim = Simulation(open_world(Pose2D(0.0, 0.0, 0.0)), params, seed=seed)
    ticks = int(minutes * 60 / sim.dt_s)
    start_ns = 1_700_000_000 * 10**9
    written = 0
    next_change = 0
    command = (0.0, 0.0)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        cmd_vel = writer.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=store)
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        vector = types["geometry_msgs/msg/Vector3"]
        for tick in range(ticks):
            if tick >= next_change:
                command = (float(rng.choice([0.0, rng.uniform(-0.3, 0.4)])),
                           float(rng.choice([0.0, rng.uniform(-2.0, 2.0)])))
                next_change = tick + int(rng.integers(10, 60))
            if tick % 2 == 0:  # 10 Hz, 0 to 40 ms into the tick (Wi-Fi)
                sent_ns = start_ns + tick * 50_000_000 + int(rng.integers(0, 40_000_000))
                twist = types["geometry_msgs/msg/Twist"](vector(command[0], 0.0, 0.0),
                                                         vector(0.0, 0.0, command[1]))
                writer.write(cmd_vel, sent_ns,
                             store.serialize_cdr(twist, "geometry_msgs/msg/Twist"))
                sim.command(*command)
                written += 1
            sim.step()
            writer.write(odom, start_ns + (tick + 1) * 50_000_000,
                         store.serialize_cdr(odometry(types, sim, start_ns + (tick + 1) *
                                                      50_000_000), "nav_msgs/msg/Odometry"))
            written += 1
    return written


def odometry(types: dict, sim: Simulation, stamp_ns: int) -> object:
    odom = sim.odometry()
    header = types["std_msgs/msg/Header"](
        types["builtin_interfaces/msg/Time"](stamp_ns // 10**9, stamp_ns % 10**9), "odom")
    pose = types["geometry_msgs/msg/Pose"](
        types["geometry_msgs/msg/Point"](odom.x, odom.y, 0.0),
        types["geometry_msgs/msg/Quaternion"](0.0, 0.0, math.sin(odom.theta / 2),
                                              math.cos(odom.theta / 2)))
    vector = types["geometry_msgs/msg/Vector3"]
    twist = types["geometry_msgs/msg/Twist"](vector(odom.v, 0.0, 0.0),
                                             vector(0.0, 0.0, odom.omega))
    return types["nav_msgs/msg/Odometry"](
        header, "base_link",
        types["geometry_msgs/msg/PoseWithCovariance"](pose, np.zeros(36)),
        types["geometry_msgs/msg/TwistWithCovariance"](twist, np.zeros(36)))


def timed(argv: list[str]) -> tuple[float, str]:
    printed = io.StringIO()
    started = time.perf_counter()
    with contextlib.redirect_stdout(printed):
        code = main(argv)
    elapsed = time.perf_counter() - started
    if code != 0:
        raise SystemExit(f"websim {' '.join(argv)} exited with {code}")
    return elapsed, printed.getvalue()


def run(minutes: float) -> None:
    with tempfile.TemporaryDirectory(prefix="bench-validation-") as folder:
        bag = Path(folder) / "robot"
        started = time.perf_counter()
        messages = write_recording(bag, minutes)
        print(f"recording: {minutes:g} min, {messages} messages (/cmd_vel 10 Hz, /odom 20 Hz), "
              f"{sum(p.stat().st_size for p in bag.iterdir()) / 1e6:.1f} MB, written in "
              f"{time.perf_counter() - started:.1f} s")
        compare_s, printed = timed(["compare", "--real", str(bag), "--out",
                                    str(Path(folder) / "compare")])
        ape = [line for line in printed.splitlines() if line.startswith("APE translation RMSE")]
        print(f"websim compare --real: {compare_s:.2f} s ({ape[0].split(None, 4)[-1].strip()} "
              "m APE RMSE, kinematic and dynamic)")
        fitted = Path(folder) / "fitted.yaml"
        fit_s, printed = timed(["fit", str(bag), "--out", str(fitted)])
        robot = load_params(fitted).robot
        found = ", ".join(f"{name} {getattr(robot, name):.4g} (true {value:g})"
                          for name, value in TRUE_DRIVER.items())
        print(f"websim fit: {fit_s:.2f} s; {found}")
        for line in printed.splitlines():
            if "RMSE" in line:
                print("   " + line.strip())


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    run(parser.parse_args().minutes)
