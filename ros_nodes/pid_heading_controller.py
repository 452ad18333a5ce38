"""The ``pid_heading_controller`` rclpy node: the course's heading PID on a real ROS 2 graph.

A thin adapter around ``physics.pid.HeadingPid`` (Module 2.4, Eq. 9): a 10 Hz timer
(``CONTROL_PERIOD_S``) feeds the latest measured heading to the PID and publishes its output as
``/cmd_vel`` (``geometry_msgs/msg/Twist``, ``angular.z`` only, rad/s). The heading is the yaw
of a ``nav_msgs/msg/Odometry`` (θ = 2·atan2(q.z, q.w), planar quaternion): ``/odom`` (wheel
odometry, what the real robot's controller sees) or ``/ground_truth`` (the true heading, as an
IMU would give it). Until the first heading arrives nothing is published; on shutdown one zero
Twist stops the robot.

Run it with ``websim-pid --ros-args -p kp:=4.0 -p setpoint_rad:=1.5708`` or
``python -m ros_nodes.pid_heading_controller``.

Parameters (``ros2 param describe /pid_heading_controller NAME`` shows each): ``kp``, ``ki``,
``kd`` (≥ 0), ``setpoint_rad`` (rad, in the heading topic's frame) and ``output_limit_rps``
(> 0, rad/s) change at runtime and take effect at the next step, keeping the integral;
``heading_topic`` is read at start. Integers are accepted for the doubles
(``ros2 param set /pid_heading_controller kp 4``). Bad values are refused with the reason;
nothing changes. ``use_sim_time:=true`` paces the timer by ``/clock``.
"""

from __future__ import annotations

import math
import signal
import sys
import threading
from typing import Any

try:
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
    from rclpy.duration import Duration
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from rclpy.signals import SignalHandlerOptions
except ImportError as error:  # pragma: no cover - depends on the installation
    raise ImportError(f"{error}: the pid_heading_controller node needs rclpy and the ROS "
                      "message packages (pip install '.[ros]')") from error

from physics import ConfigError
from physics.pid import CONTROL_PERIOD_S, HeadingPid, PidGains
from physics.validation import as_finite_float
from ros_nodes.node_parameters import add_parameter_callbacks

NODE_NAME = "pid_heading_controller"
"""The node's name, as in the course."""

DEFAULT_GAINS = PidGains()
"""Defaults of kp, ki, kd and output_limit_rps: the library's (output limit 2.5 rad/s, the
robot's max_angular_rps)."""

HEADING_TOPICS = ("/odom", "/ground_truth")
"""The robot's two Odometry topics; another topic of that type may be named too."""

STOP_ACK_TIMEOUT_S = 1.0
"""How long shutdown waits for subscribers to acknowledge the final zero Twist."""

_GAIN_PARAMETERS = {
    "kp": "proportional gain (rad/s per rad of heading error), >= 0",
    "ki": "integral gain (rad/s per rad s), >= 0",
    "kd": "derivative gain on the measured heading (rad/s per rad/s), >= 0",
    "output_limit_rps": "largest |angular.z| published (rad/s), > 0",
}
_DOUBLE_PARAMETERS = {*_GAIN_PARAMETERS, "setpoint_rad"}
_GAIN_FIELDS = {"kp": "kp", "ki": "ki", "kd": "kd", "output_limit_rps": "output_limit"}


def yaw_of(msg: Any) -> float:
    """Heading (rad) of a ``nav_msgs/msg/Odometry`` with a planar quaternion."""
    q = msg.pose.pose.orientation
    return 2.0 * math.atan2(q.z, q.w)


class PidHeadingControllerNode(Node):
    """The heading PID as a ROS 2 node; see the module docstring.

    Args:
        **node_kwargs: passed to ``rclpy.node.Node`` (e.g. ``context``).

    Raises:
        rclpy.exceptions.InvalidParameterValueException: a parameter override is invalid.
    """

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__(NODE_NAME, **node_kwargs)
        add_parameter_callbacks(self, _DOUBLE_PARAMETERS, self._validate_parameters,
                                self._apply_parameters)

        defaults = {"kp": DEFAULT_GAINS.kp, "ki": DEFAULT_GAINS.ki, "kd": DEFAULT_GAINS.kd,
                    "output_limit_rps": DEFAULT_GAINS.output_limit}
        # Dynamic typing lets an integer override through (``-p kp:=4``: rclpy runs no
        # pre-set callback on overrides); the validation refuses anything but a number.
        for name, description in _GAIN_PARAMETERS.items():
            self.declare_parameter(name, float(defaults[name]), ParameterDescriptor(
                description=description, dynamic_typing=True))
        self.declare_parameter("setpoint_rad", 0.0, ParameterDescriptor(
            description="heading to hold (rad), in the heading topic's frame",
            dynamic_typing=True))
        self._heading_topic = str(self.declare_parameter(
            "heading_topic", HEADING_TOPICS[0], ParameterDescriptor(
                description="nav_msgs/msg/Odometry topic the heading is read from: /odom "
                            "(wheel odometry) or /ground_truth (the true heading, like an IMU)",
                read_only=True)).value)

        self.pid = HeadingPid(self._gains({}), float(self.get_parameter("setpoint_rad").value))
        self.heading_rad: float | None = None
        """The latest measured heading (rad), None until the first message."""

        # Best effort takes the latest heading from a reliable or a best-effort publisher.
        self.create_subscription(Odometry, self._heading_topic, self._on_heading,
                                 qos_profile_sensor_data)
        self._cmd_vel = self.create_publisher(
            Twist, "/cmd_vel", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.create_timer(CONTROL_PERIOD_S, self._step)

    # ---- parameters -----------------------------------------------------------------------

    def _gains(self, changes: dict[str, Any]) -> PidGains:
        """The gains with ``changes`` (parameter name -> value) applied; raises ConfigError."""
        values = {field: changes[name] if name in changes else self.get_parameter(name).value
                  for name, field in _GAIN_FIELDS.items()}
        return PidGains(**values)

    def _validate_parameters(self, parameters: list[Parameter[Any]]) -> SetParametersResult:
        """Refuse non-finite values and negative gains with the reason."""
        changes = {p.name: p.value for p in parameters if p.name in _GAIN_FIELDS}
        try:
            if changes and all(self.has_parameter(name) for name in _GAIN_FIELDS):
                self._gains(changes)
            else:  # an override checked while the parameters are being declared
                for name, value in changes.items():
                    PidGains(**{_GAIN_FIELDS[name]: value})
            for p in parameters:
                if p.name == "setpoint_rad":
                    as_finite_float("setpoint_rad", p.value)
        except ConfigError as error:
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter[Any]]) -> None:
        """Give validated changes to the PID; they count from its next step."""
        pid: HeadingPid | None = getattr(self, "pid", None)
        if pid is None:  # still declaring: the constructor builds the PID afterwards
            return
        # From the list, not get_parameter: Humble calls this before it stores the values.
        values = {p.name: p.value for p in parameters}
        changes = {name: value for name, value in values.items() if name in _GAIN_FIELDS}
        if changes:
            pid.gains = self._gains(changes)
        if "setpoint_rad" in values:
            pid.setpoint_rad = float(values["setpoint_rad"])

    def _on_heading(self, msg: Any) -> None:
        self.heading_rad = yaw_of(msg)

    def _step(self) -> None:
        """One control period: latest heading in, yaw rate command out."""
        if self.heading_rad is None:
            return
        command = Twist()
        command.angular.z = self.pid.update(self.heading_rad, CONTROL_PERIOD_S)
        self._cmd_vel.publish(command)

    def stop_robot(self) -> None:
        """Publish a zero Twist and wait (bounded) until subscribers have it."""
        self._cmd_vel.publish(Twist())
        self._cmd_vel.wait_for_all_acked(Duration(seconds=STOP_ACK_TIMEOUT_S))


SHUTDOWN_POLL_S = 0.1
"""The longest a stop request waits for the executor to return (one control period)."""


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl+C or SIGTERM, then stop the robot; ``args`` default to ``sys.argv``.

    rclpy's own signal handlers would shut the context down before the final zero Twist could
    be sent, and an exception raised inside rclpy's C code can leave a message half taken, so
    SIGINT and SIGTERM only set a flag that the spin loop checks.

    Returns:
        0 after a clean shutdown, 2 when a parameter is invalid (the reason is printed).
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    previous = {signum: signal.signal(signum, lambda signum, frame: stop.set())
                for signum in (signal.SIGINT, signal.SIGTERM)}
    node = None
    try:
        node = PidHeadingControllerNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=SHUTDOWN_POLL_S)
    except (InvalidParameterValueException, InvalidParameterTypeException,
            ConfigError) as error:
        print(f"websim-pid: error: {error}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if node is not None:
            if rclpy.ok():
                node.stop_robot()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
