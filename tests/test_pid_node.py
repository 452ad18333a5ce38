"""The pid_heading_controller node (``websim-pid``) closing the loop around ``websim-robot``.

Both are real processes on this test's own ROS_DOMAIN_ID, discovery kept on this machine (the
fixtures of ``test_ros_node``). Times are measured from the robot's message stamps, never from
when this process received them; every wait polls with a bound.
"""

from __future__ import annotations

import math
import signal
import subprocess
from collections.abc import Callable, Iterator
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)
"""Fixtures domain, graph, test_world, start_robot."""

from geometry_msgs.msg import Twist  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from physics.pid import wrap_angle  # noqa: E402
from ros_nodes.pid_heading_controller import NODE_NAME, yaw_of  # noqa: E402

from ros_fixtures import (  # noqa: E402
    RELIABLE,
    STARTUP_TIMEOUT_S,
    Graph,
    RobotProcess,
    node_command,
    node_processes,
    stamp_s,
)
from server_process import stop_process  # noqa: E402

SETPOINT_RAD = math.pi / 2
TOLERANCE_RAD = math.radians(2.0)

KINEMATIC_KP = 4.0
SETTLING_BOUND_S = 2.0
"""Kinematic robot, Kp = 4: saturated at 2.5 rad/s for the first ~0.4 s, then the error decays
as exp(-4 t); within 2° after ~1.2 s (the 10 Hz controller, the 20 Hz robot and the transport
add up to one robot tick of delay). Measured here: 0.9-1.0 s."""

SETTLED_FOR_S = 1.0
"""A heading counts as settled once it has stayed within the tolerance this long (stamps)."""

DYNAMIC_KP = 8.0
"""Large enough that the doubled inertia shows in the overshoot (physics.compare, true heading
fed back: 1.7 % at 1x, 5.1 % at 2x; websim-pid around websim-robot measured the same)."""

PAYLOAD_PARAMETERS = ("mass_kg", "inertia_kg_m2")
"""Doubling both gives a heavier robot of the same shape (1.2 kg, 0.0066 kg m² -> 2.4, 0.0132
with config/pi4b_params.yaml)."""


def pid_command(*parameters: str) -> list[str]:
    """``websim-pid --ros-args -p ...``."""
    return node_command("websim-pid", "ros_nodes.pid_heading_controller", *parameters)


@pytest.fixture
def start_pid(graph: Graph) -> Iterator[Callable[..., RobotProcess]]:
    """Start ``websim-pid`` and wait until it publishes /cmd_vel; stopped with Ctrl+C."""
    with node_processes(graph, "websim-pid", "/cmd_vel") as start:
        yield lambda *parameters: start(pid_command(*parameters))


def set_pid_parameters(graph: Graph, **values: Any) -> list[Any]:
    request = SetParameters.Request(parameters=[
        Parameter(name, value=value).to_parameter_msg() for name, value in values.items()])
    return list(graph.call(SetParameters, f"/{NODE_NAME}/set_parameters", request).results)


def settled_since(samples: list[tuple[float, float]], target_rad: float) -> float | None:
    """The stamp from which every (stamp, yaw) sample is within the tolerance of the target,
    if the samples after it cover ``SETTLED_FOR_S``; else None."""
    since = None
    for stamp, yaw in samples:
        if abs(wrap_angle(yaw - target_rad)) > TOLERANCE_RAD:
            since = None
        elif since is None:
            since = stamp
    if since is None or samples[-1][0] - since < SETTLED_FOR_S:
        return None
    return since


def yaws(received: list[tuple[float, Any]], after_s: float = -math.inf
         ) -> list[tuple[float, float]]:
    """(stamp, yaw) of the Odometry messages stamped after ``after_s``, in stamp order."""
    return sorted((stamp_s(msg), yaw_of(msg)) for _, msg in received if stamp_s(msg) > after_s)


def test_kinematic_robot_settles_on_the_setpoint_and_stops_with_the_node(
        graph: Graph, start_robot: Callable[..., RobotProcess],
        start_pid: Callable[..., RobotProcess]) -> None:
    start_robot()
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    commands = graph.collect(Twist, "/cmd_vel", RELIABLE)
    graph.spin_until(lambda: odom, 10.0, "/odom")
    controller = start_pid(f"kp:={KINEMATIC_KP}", f"setpoint_rad:={SETPOINT_RAD}")

    graph.spin_until(lambda: settled_since(yaws(odom), SETPOINT_RAD), 20.0,
                     f"/odom to settle within 2° of 90° for {SETTLED_FOR_S} s")
    samples = yaws(odom)
    start_s = max(stamp for stamp, yaw in samples if abs(yaw) < 1e-9)  # last still at 0
    settled_s = settled_since(samples, SETPOINT_RAD)
    assert settled_s is not None
    settling_s = settled_s - start_s
    print(f"kinematic, Kp {KINEMATIC_KP}: within 2° of 90° after {settling_s:.2f} s")
    assert 0.0 < settling_s < SETTLING_BOUND_S
    # This node may see the controller's /cmd_vel seconds after the robot does (discovery).
    graph.spin_until(lambda: commands, 15.0, "/cmd_vel from websim-pid")
    # Only angular.z is commanded, so the robot turned in place.
    assert all(msg.linear.x == 0.0 and msg.angular.x == msg.angular.y == 0.0
               for _, msg in commands)
    position = odom[-1][1].pose.pose.position
    assert math.hypot(position.x, position.y) < 1e-9

    # Ctrl+C: the node's last word is a zero Twist, and the robot stops turning.
    assert stop_process(controller.process, controller.output, signal.SIGINT) == 0
    graph.spin_until(lambda: commands and commands[-1][1] == Twist(), 5.0, "a zero /cmd_vel")
    stopped_after = stamp_s(odom[-1][1])
    graph.spin_until(lambda: odom and stamp_s(odom[-1][1]) > stopped_after + 0.2, 5.0, "/odom")
    assert odom[-1][1].twist.twist.angular.z == 0.0


def test_parameters_are_validated_and_apply_at_once(
        graph: Graph, start_robot: Callable[..., RobotProcess],
        start_pid: Callable[..., RobotProcess]) -> None:
    start_robot()
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    start_pid("kp:=4")  # an integer override is taken as 4.0; setpoint 0: holds still
    refused = set_pid_parameters(graph, kp=-1.0)
    assert not refused[0].successful and "kp: must be >= 0" in refused[0].reason
    refused = set_pid_parameters(graph, setpoint_rad=math.inf)
    assert not refused[0].successful and "finite" in refused[0].reason
    refused = set_pid_parameters(graph, output_limit_rps=0.0)
    assert not refused[0].successful and "output_limit" in refused[0].reason

    assert set_pid_parameters(graph, setpoint_rad=-1)[0].successful  # integer: -1.0 rad
    graph.spin_until(lambda: settled_since(yaws(odom), -1.0), 20.0, "the new setpoint")


@pytest.mark.parametrize(("override", "reason"), [
    ("kp:=-1.0", "kp: must be >= 0"),
    ("setpoint_rad:=.nan", "setpoint_rad: expected a finite number"),
    ("output_limit_rps:=0", "output_limit: must be > 0"),
])
def test_invalid_start_parameters_exit_with_the_reason(domain: int, override: str,
                                                       reason: str) -> None:
    result = subprocess.run(pid_command(override), capture_output=True, text=True,
                            timeout=STARTUP_TIMEOUT_S, check=False)
    assert result.returncode == 2
    assert "websim-pid: error:" in result.stderr and reason in result.stderr


def overshoot_pct(graph: Graph, truth: list[tuple[float, Any]], payload: dict[str, float]
                  ) -> float:
    """Set the payload, return to 0 rad, step to 90°: the true heading's overshoot (% of step)."""
    assert all(result.successful for result in graph.set_parameters(**payload))
    assert set_pid_parameters(graph, setpoint_rad=0.0)[0].successful
    graph.spin_until(lambda: settled_since(yaws(truth), 0.0), 20.0, "the heading back at 0")
    step_s = yaws(truth)[-1][0]
    assert set_pid_parameters(graph, setpoint_rad=SETPOINT_RAD)[0].successful
    graph.spin_until(lambda: settled_since(yaws(truth, step_s), SETPOINT_RAD), 20.0,
                     "the heading to settle at 90°")
    peak = max(yaw for _, yaw in yaws(truth, step_s))
    return max(0.0, (peak - SETPOINT_RAD) / SETPOINT_RAD * 100.0)


def test_heavier_payload_overshoots_more_on_ground_truth(
        graph: Graph, start_robot: Callable[..., RobotProcess],
        start_pid: Callable[..., RobotProcess]) -> None:
    start_robot("mode:=dynamic")
    truth = graph.collect(Odometry, "/ground_truth", RELIABLE)
    graph.spin_until(lambda: truth, 10.0, "/ground_truth")
    start_pid(f"kp:={DYNAMIC_KP}", "heading_topic:=/ground_truth")

    payload = {name: float(graph.get_parameter(name)) for name in PAYLOAD_PARAMETERS}
    default = overshoot_pct(graph, truth, payload)
    doubled = overshoot_pct(graph, truth, {name: 2.0 * value for name, value in payload.items()})
    print(f"dynamic, Kp {DYNAMIC_KP}, true heading fed back: overshoot {default:.1f} % at 1x, "
          f"{doubled:.1f} % at 2x payload")
    assert doubled > default + 1.0
