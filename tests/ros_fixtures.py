"""A ROS 2 graph for tests: its own domain, an rclpy node spun on the test thread, node processes.

A pytest plugin (``pytest_plugins = ("ros_fixtures",)`` in the test modules that use it):
fixtures ``domain`` (a ROS_DOMAIN_ID of this test's own, discovery kept on this machine),
``graph``, ``test_world``, ``start_robot``, ``ros_server`` (``websim serve --ros`` on the test
world) and ``ros_client`` (roslibpy connected to it); helpers to start any node process and wait
until it publishes. Each wait polls with a bound.
"""

from __future__ import annotations

import itertools
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")

from rcl_interfaces.srv import GetParameters, SetParameters  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter, parameter_value_to_python  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402

from server_process import (  # noqa: E402
    ServerProcess,
    roslibpy_client,
    start_server,
    stop_process,
    wait_for,
)

WALL_X_M = 2.0
"""The test world's one wall: x = 2 m, so beam 0 (straight ahead at spawn) reads 2 m."""

TEST_WORLD = f"""\
name: ros-test
walls:
  - [{WALL_X_M}, -2.0, {WALL_X_M}, 2.0]
"""

RELIABLE = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
DT_S = 0.05
STARTUP_TIMEOUT_S = 30.0


DOMAIN_IDS = ((os.getpid() % 100 + n) % 100 + 1 for n in itertools.count())
"""ROS_DOMAIN_IDs 1..100, distinct within the session (test_pid_node imports this module),
offset by the process id."""


@pytest.fixture
def domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """This test's domain, set in the environment that this process and its children use."""
    domain_id = next(DOMAIN_IDS)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain_id))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOCALHOST_ONLY", "1")
    return domain_id


class Graph:
    """This test's own rclpy node, spun on the test thread while waiting."""

    def __init__(self, domain_id: int) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node("websim_test", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, condition: Callable[[], Any], timeout_s: float = 10.0,
                   what: str = "condition") -> Any:
        """Spin until ``condition`` returns something truthy; fail after ``timeout_s``."""
        return wait_for(condition, timeout_s, what,
                        pause=lambda: self.executor.spin_once(timeout_sec=0.02))

    def collect(self, msg_type: Any, topic: str, qos: QoSProfile) -> list[tuple[float, Any]]:
        """Subscribe; the list fills with (receive time, message) while spinning."""
        received: list[tuple[float, Any]] = []
        self.node.create_subscription(msg_type, topic,
                                      lambda msg: received.append((time.monotonic(), msg)), qos)
        return received

    def call(self, srv_type: Any, name: str, request: Any, timeout_s: float = 10.0) -> Any:
        client = self.node.create_client(srv_type, name)
        self.spin_until(client.service_is_ready, timeout_s, f"service {name}")
        future = client.call_async(request)
        self.spin_until(future.done, timeout_s, f"answer from {name}")
        self.node.destroy_client(client)
        return future.result()

    def set_parameters(self, **values: Any) -> list[Any]:
        request = SetParameters.Request(parameters=[
            Parameter(name, value=value).to_parameter_msg() for name, value in values.items()])
        return list(self.call(SetParameters, "/virtual_robot/set_parameters", request).results)

    def get_parameter(self, name: str) -> Any:
        response = self.call(GetParameters, "/virtual_robot/get_parameters",
                             GetParameters.Request(names=[name]))
        return parameter_value_to_python(response.values[0])

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


@pytest.fixture
def graph(domain: int) -> Iterator[Graph]:
    running = Graph(domain)
    yield running
    running.close()


@dataclass
class RobotProcess:
    """A running ``websim-robot``."""

    process: subprocess.Popen[str]
    output: list[str] = field(default_factory=list)

    def stop(self, timeout_s: float = 10.0) -> int:
        """Ctrl+C, as a terminal or ros2 launch sends it; returns the exit code."""
        return stop_process(self.process, self.output, signal.SIGINT, timeout_s)


def node_command(script: str, module: str, *parameters: str) -> list[str]:
    """``script --ros-args -p ...`` (``python -m module`` if the script is not on PATH)."""
    found = shutil.which(script)
    base = [found] if found else [sys.executable, "-m", module]
    args = [arg for parameter in parameters for arg in ("-p", parameter)]
    return [*base, "--ros-args", *args] if args else base


def robot_command(*parameters: str) -> list[str]:
    """``websim-robot --ros-args -p ...``."""
    return node_command("websim-robot", "ros_nodes.virtual_robot", *parameters)


@contextmanager
def node_processes(graph: Graph, name: str,
                   topic: str) -> Iterator[Callable[[list[str]], RobotProcess]]:
    """Start node processes, each awaited until it publishes ``topic``; stopped with Ctrl+C,
    which must end each with exit code 0."""
    started: list[RobotProcess] = []

    def start(command: list[str]) -> RobotProcess:
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                   text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
        node = RobotProcess(process)
        started.append(node)

        def publishing() -> bool:
            if process.poll() is not None:
                out, _ = process.communicate()
                raise AssertionError(f"{name} exited with {process.returncode}:\n{out}")
            return graph.node.count_publishers(topic) > 0

        graph.spin_until(publishing, STARTUP_TIMEOUT_S, f"{name} to publish {topic}")
        return node

    yield start
    for node in started:
        code = node.stop()
        assert code == 0, f"{name} exited with {code}:\n{''.join(node.output)}"


@pytest.fixture
def test_world(tmp_path: Path) -> Path:
    path = tmp_path / "ros_test.yaml"
    path.write_text(TEST_WORLD)
    return path


@pytest.fixture
def start_robot(graph: Graph, test_world: Path) -> Iterator[Callable[..., RobotProcess]]:
    """Start ``websim-robot`` on the test world and wait until it publishes /odom."""
    with node_processes(graph, "websim-robot", "/odom") as start:
        yield lambda *parameters: start(robot_command(f"world:={test_world}", *parameters))


def stamp_s(msg: Any) -> float:
    return float(msg.header.stamp.sec) + msg.header.stamp.nanosec * 1e-9


@pytest.fixture
def ros_server(domain: int, test_world: Path) -> Iterator[ServerProcess]:
    """``websim serve --ros`` on the test world, in this test's domain; it must stop cleanly."""
    running = start_server(["--ros", "--world", str(test_world)])
    yield running
    assert running.stop() == 0, "".join(running.output)


@pytest.fixture
def ros_client(ros_server: ServerProcess) -> Iterator[Any]:
    """roslibpy connected to ``ros_server`` (a browser's or a student's script's view)."""
    with roslibpy_client(ros_server) as client:
        yield client
