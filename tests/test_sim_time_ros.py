"""Sim time on a real ROS 2 graph: ``websim serve --ros --speed 10`` and a ``use_sim_time`` node.

A real ``websim serve --ros`` process and real rclpy nodes in this test process, on this
test's own ROS_DOMAIN_ID (``ros_fixtures``). Wall-time margins hold on a loaded 2-core
machine: 10 s of sim time must take less than 4 s of wall time (10x would take 1 s).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)

from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402

from ros_fixtures import RELIABLE, STARTUP_TIMEOUT_S, Graph  # noqa: E402
from server_process import ServerProcess, start_server  # noqa: E402

TICK_NS = 50_000_000
SPEED = 10.0
SIM_SPAN_S = 10.0
WALL_LIMIT_S = 4.0


@pytest.fixture
def fast_server(domain: int, test_world: Path) -> Iterator[ServerProcess]:
    """``websim serve --ros --speed 10`` on the test world, in this test's domain."""
    running = start_server(["--ros", "--speed", f"{SPEED:g}", "--world", str(test_world)])
    yield running
    assert running.stop() == 0, "".join(running.output)


def time_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def test_a_use_sim_time_node_sees_ten_times_real_time_and_stamps_that_agree(
        graph: Graph, fast_server: ServerProcess) -> None:
    student = Node("sim_time_student", context=graph.context,
                   parameter_overrides=[Parameter("use_sim_time", value=True)])
    graph.executor.add_node(student)
    try:
        clocks: list[int] = []
        odom: list[tuple[int, int]] = []  # (the node's sim time when it got it, its stamp)
        now_ns = lambda: student.get_clock().now().nanoseconds  # noqa: E731
        student.create_subscription(Clock, "/clock", lambda m: clocks.append(time_ns(m.clock)),
                                    RELIABLE)
        student.create_subscription(
            Odometry, "/odom", lambda m: odom.append((now_ns(), time_ns(m.header.stamp))),
            RELIABLE)
        graph.spin_until(lambda: now_ns() > 0 and odom, STARTUP_TIMEOUT_S,
                         "the node's sim time from /clock")
        start_wall, start_sim = time.monotonic(), now_ns()
        graph.spin_until(lambda: now_ns() - start_sim >= SIM_SPAN_S * 1e9, 30.0,
                         f"{SIM_SPAN_S:g} s of sim time")
        wall_s, sim_s = time.monotonic() - start_wall, (now_ns() - start_sim) / 1e9
    finally:
        student.destroy_node()

    assert wall_s < WALL_LIMIT_S, f"{sim_s:.1f} s of sim time took {wall_s:.2f} s"
    assert sim_s <= SPEED * wall_s + 1.0, "faster than --speed"  # + a late first /clock
    # Sim time began at the wall time of the start: it never reads 0, nor 1970.
    assert abs(clocks[0] / 1e9 - time.time()) < 600.0
    assert all(b - a == TICK_NS for a, b in itertools.pairwise(clocks)), "a /clock was lost"
    # Each /odom is stamped with a time /clock said, the node's own sim time at its arrival.
    stamps = [stamp for _, stamp in odom]
    inside = [stamp for stamp in stamps if clocks[0] <= stamp <= clocks[-1]]
    assert len(inside) > 100 and set(inside) <= set(clocks)
    assert all(-TICK_NS <= now - stamp <= 100 * TICK_NS for now, stamp in odom[1:])
