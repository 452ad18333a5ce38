"""roslibjs 1.4.1 under Node against a real ``websim serve``: the course's browser code path.

Each test runs one program from ``tests/node/`` as ``node <program>.js WS_URL [ARGS...]``. The
program uses roslibjs as the course text's snippets do (``ROSLIB.Ros``, ``ROSLIB.Topic``,
``ROSLIB.Service``, ``ros.getTopics``), prints one JSON result and exits non-zero on an error
or a timeout; the assertions are here. roslib comes from ``web-interface/node_modules``, which
``scripts/test.sh`` installs from ``web-interface/package-lock.json``.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from physics import TICK_PERIOD_S, Pose2D, RobotParams, Simulation, load_world
from ros_nodes.parameters import PARAMETER_DOUBLE
from ros_nodes.robot_messages import MARKER_LINE_LIST

from conftest import ARENA_HALF_M
from server_process import ServerProcess, wait_for

NODE = shutil.which("node")
pytestmark = pytest.mark.skipif(NODE is None, reason="node not installed")

NODE_PROGRAMS = Path(__file__).parent / "node"
NODE_TIMEOUT_S = 30.0

SPEED_MPS = 0.3
TICK_M = SPEED_MPS * TICK_PERIOD_S
"""Travel in one 50 ms tick at 0.3 m/s: 0.015 m."""

STAMP_JITTER_S = 0.025
"""Stamps are the wall-clock times of ticks scheduled every 50 ms; a tick may start late (a
loaded 2-core machine: 22 ms seen). Half a tick, so a stamp still names one tick; the travel
by tick count below is exact."""


def run_node(program: str, *args: str) -> Any:
    """Run ``tests/node/<program>`` and return the JSON it printed."""
    assert NODE is not None
    result = subprocess.run([NODE, str(NODE_PROGRAMS / program), *args], capture_output=True,
                            text=True, timeout=NODE_TIMEOUT_S, check=False)
    assert result.returncode == 0, (
        f"node {program} exited with {result.returncode} (scripts/test.sh installs roslib "
        f"in web-interface/node_modules):\n{result.stderr}")
    return json.loads(result.stdout)


def nanoseconds(stamp: dict[str, int]) -> int:
    """A ``builtin_interfaces/Time`` as integer nanoseconds."""
    return int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"])


def stamp_ns(msg: dict[str, Any]) -> int:
    return nanoseconds(msg["header"]["stamp"])


def seconds_between(first: dict[str, Any], last: dict[str, Any]) -> float:
    return (stamp_ns(last) - stamp_ns(first)) / 1e9


def position(odom: dict[str, Any]) -> tuple[float, float]:
    point = odom["pose"]["pose"]["position"]
    return point["x"], point["y"]


def yaw(odom: dict[str, Any]) -> float:
    """Heading (rad) from a planar quaternion: θ = 2·atan2(z, w)."""
    q = odom["pose"]["pose"]["orientation"]
    return 2.0 * math.atan2(q["z"], q["w"])


def speed(odom: dict[str, Any]) -> float:
    return float(odom["twist"]["twist"]["linear"]["x"])


def test_one_cmd_vel_drives_the_robot_until_a_zero_twist(server: ServerProcess) -> None:
    out = run_node("drive.js", server.ws_url, str(SPEED_MPS))
    rest = out["before"][-1]
    assert speed(rest) == 0.0
    x0, y0 = position(rest)

    def travelled(odom: dict[str, Any]) -> float:
        x, y = position(odom)
        return math.hypot(x - x0, y - y0)

    moving = [odom for odom in out["driving"] if position(odom) != (x0, y0)]
    assert moving, "the robot did not move"
    first = moving[0]
    at_one_s = None
    for odom in moving:
        elapsed_s = seconds_between(first, odom)
        ticks = round(elapsed_s / TICK_PERIOD_S)
        assert abs(elapsed_s - ticks * TICK_PERIOD_S) < STAMP_JITTER_S
        # x += v·dt each tick, the first moving message's tick included: travel is
        # v·(elapsed + dt), i.e. 0.3·elapsed to within one tick, and exact by tick count.
        assert travelled(odom) == pytest.approx(TICK_M * (ticks + 1), abs=1e-9)
        assert speed(odom) == SPEED_MPS  # the robot keeps the last command
        if ticks == 19:
            at_one_s = odom
    assert at_one_s is not None, "no /odom 19 ticks after the first move"
    assert travelled(at_one_s) == pytest.approx(0.30, abs=1e-9)

    stopped = out["after"][-5:]
    assert [speed(odom) for odom in stopped] == [0.0] * 5
    last_moving = [odom for odom in out["driving"] + out["after"] if speed(odom) > 0][-1]
    assert {position(odom) for odom in stopped} == {position(last_moving)}


def test_scan_equals_the_physics_scan_at_the_true_pose(server: ServerProcess) -> None:
    out = run_node("scan.js", server.ws_url)
    scan, truth = out["scan"], out["ground_truth"]
    assert stamp_ns(scan) == stamp_ns(truth)
    assert scan["header"]["frame_id"] == "laser"
    assert len(scan["ranges"]) == 360
    assert None not in scan["ranges"], "JSON null: a non-finite range"
    increment = 2.0 * math.pi / 360
    assert scan["angle_increment"] == pytest.approx(increment, rel=1e-15)
    assert scan["angle_max"] == pytest.approx(scan["angle_min"] + 359 * increment, rel=1e-15)
    assert (scan["range_min"], scan["range_max"]) == (0.12, 3.5)

    x, y = position(truth)
    expected = Simulation(load_world("empty")).lidar.scan(Pose2D(x, y, yaw(truth)))
    assert scan["angle_min"] == expected.angle_min
    assert scan["angle_max"] == expected.angle_max
    np.testing.assert_allclose(scan["ranges"], expected.ranges, rtol=0, atol=1e-6)


def test_late_subscribers_get_the_latched_tf_static_and_world(server: ServerProcess) -> None:
    wait_for(lambda: server.health()["ticks"] >= 20, what="the server to run for 1 s")
    out = run_node("latched.js", server.ws_url)
    assert out["waited_ms"] < 2000
    (laser,) = out["tf_static"]["transforms"]
    assert (laser["header"]["frame_id"], laser["child_frame_id"]) == ("base_link", "laser")
    assert laser["transform"]["translation"] == {"x": 0.0, "y": 0.0, "z": 0.0}
    assert laser["transform"]["rotation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}

    (walls,) = out["world"]["markers"]
    assert walls["header"]["frame_id"] == "map"
    assert walls["type"] == MARKER_LINE_LIST
    points = [(p["x"], p["y"]) for p in walls["points"]]
    assert len(points) == 8
    h = ARENA_HALF_M
    square = {frozenset(side) for side in (((-h, -h), (h, -h)), ((h, -h), (h, h)),
                                           ((h, h), (-h, h)), ((-h, h), (-h, -h)))}
    assert {frozenset(points[i:i + 2]) for i in range(0, 8, 2)} == square


def test_cbor_scan_decodes_to_a_float32array_equal_to_the_json_scan(
        server: ServerProcess) -> None:
    out = run_node("cbor.js", server.ws_url)
    assert out["cbor_ranges_is_float32array"], out["cbor_ranges_type"]
    assert len(out["cbor_ranges"]) == len(out["json_ranges"]) == 360
    # JSON carries the doubles; CBOR the same values rounded to float32 (relative error at
    # most 2**-24), and a Float32Array widens back to double exactly.
    json_ranges = np.array(out["json_ranges"], dtype=np.float64)
    np.testing.assert_allclose(out["cbor_ranges"], json_ranges, rtol=2.0**-24, atol=0)
    assert np.array_equal(np.array(out["cbor_ranges"]), json_ranges.astype(np.float32))


def test_get_topics_lists_the_robot_topics_with_ros2_types(server: ServerProcess) -> None:
    out = run_node("topics.js", server.ws_url)
    listed = dict(zip(out["topics"], out["types"], strict=True))
    assert listed.items() >= {
        "/cmd_vel": "geometry_msgs/msg/Twist",
        "/odom": "nav_msgs/msg/Odometry",
        "/scan": "sensor_msgs/msg/LaserScan",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/tf_static": "tf2_msgs/msg/TFMessage",
        "/ground_truth": "nav_msgs/msg/Odometry",
        "/world": "visualization_msgs/msg/MarkerArray",
    }.items()


def test_reset_simulation_returns_odometry_to_zero(server: ServerProcess) -> None:
    out = run_node("reset.js", server.ws_url)
    assert math.hypot(*position(out["driven"])) > 0.1
    assert out["reset"] == {"ok": True, "values": {}}
    for odom in out["after"][-5:]:
        assert position(odom) == pytest.approx((0.0, 0.0), abs=1e-12)
        assert yaw(odom) == pytest.approx(0.0, abs=1e-12)
        assert speed(odom) == 0.0  # the reset also zeroed the command


def test_set_parameters_needs_the_admin_token(server: ServerProcess) -> None:
    refused = run_node("params.js", server.ws_url, "2.4")
    assert refused["set"]["ok"] is False
    assert "admin" in refused["set"]["reason"]
    (before,) = refused["get"]["values"]["values"]
    assert (before["type"], before["double_value"]) == (PARAMETER_DOUBLE, RobotParams().mass_kg)

    accepted = run_node("params.js", server.admin_ws_url, "2.4")
    assert accepted["set"] == {"ok": True,
                               "values": {"results": [{"successful": True, "reason": ""}]}}
    (after,) = accepted["get"]["values"]["values"]
    assert (after["type"], after["double_value"]) == (PARAMETER_DOUBLE, 2.4)

    restored = run_node("params.js", server.admin_ws_url, str(before["double_value"]))
    assert restored["get"]["values"]["values"][0]["double_value"] == before["double_value"]


def test_throttle_rate_200_ms_gives_5_odom_per_second(server: ServerProcess) -> None:
    out = run_node("throttle.js", server.ws_url, "200")

    def per_second_over_2_s(stamps: list[dict[str, int]]) -> float:
        times_ns = sorted(nanoseconds(stamp) for stamp in stamps)
        assert times_ns[-1] - times_ns[0] >= 2_000_000_000, "recorded less than 2 s"
        return sum(1 for t in times_ns if t - times_ns[0] < 2_000_000_000) / 2.0

    assert 4.0 <= per_second_over_2_s(out["throttled"]) <= 6.0
    assert 18.0 <= per_second_over_2_s(out["unthrottled"]) <= 22.0
