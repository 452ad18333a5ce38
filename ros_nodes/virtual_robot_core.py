"""The virtual robot without a transport: /cmd_vel in, ROS-shaped messages out, per tick.

The embedded rosbridge server and the rclpy node both wrap this class, so what the robot
publishes, at which tick and with which stamp, is decided in one place.
"""

from __future__ import annotations

from collections.abc import Callable, Container
from typing import Any

from physics import Simulation
from ros_nodes.parameters import RobotParameters
from ros_nodes.robot_interface import GROUND_TRUTH, ODOM, SCAN, TF, TF_STATIC, WORLD, TopicSpec
from ros_nodes.robot_messages import (
    BASE_FRAME,
    LASER_FRAME,
    MAP_FRAME,
    ODOM_FRAME,
    ODOM_POSE_VARIANCE,
    ODOM_TWIST_VARIANCE,
    laser_scan_msg,
    odometry_msg,
    tf_msg,
    transform_stamped_msg,
    twist_from_msg,
    world_markers_msg,
)
from rosbridge.core.clock import Clock, WallClock
from rosbridge.msgs.values import Message

Publication = tuple[TopicSpec, Message]

TIMEOUT_TOLERANCE_S = 1e-9
"""Rounding slack of the command watchdog: a 0.5 s timeout expires after exactly 10 ticks."""


class VirtualRobot:
    """One simulated robot and the messages it publishes.

    Args:
        sim: the simulation to drive.
        clock: the one clock of the robot: its ``stamp_s`` stamps the messages (s since the
            epoch in wall time, as a real robot stamps them), its ``monotonic_s`` times the
            robot's host (idle time, throttles, the last command's age). Default: wall time.

    Attributes:
        clock: the clock the stamps come from, and its host's intervals.
        listeners: called with every tick's publications, after ``step`` computed them (the
            rclpy node of ``websim serve --ros`` publishes them on the ROS graph with one).
    """

    def __init__(self, sim: Simulation, clock: Clock | None = None) -> None:
        self.sim = sim
        self.parameters = RobotParameters(sim)
        self.listeners: list[Callable[[list[Publication]], None]] = []
        self.clock: Clock = WallClock() if clock is None else clock
        self._ticks_since_command = 0
        self.collisions = 0
        """Times the robot ran into a wall (ticks where a contact began) since it started."""
        self._colliding = False

    def on_cmd_vel(self, msg: Any, stamped: bool = False) -> None:
        """Apply a ``geometry_msgs/Twist`` (or ``TwistStamped``) dict as the new command.

        Raises:
            ConfigError: malformed or non-finite; the command in force is kept.
        """
        linear, angular = twist_from_msg(msg, stamped=stamped)
        self.sim.command(linear, angular)
        self._ticks_since_command = 0

    def step(self, scan: bool = True,
             wanted: Container[str] | None = None) -> list[Publication]:
        """Advance one tick and return the messages due at it (/scan on every second tick).

        ``advance`` then ``publications``. With ``cmd_vel_timeout_s`` > 0, a command older
        than that is replaced by a stop first.

        Args:
            scan: whether to cast the LiDAR on ticks /scan is due (False: nobody listens, so
                the rays are not cast and no /scan is returned).
            wanted: the topics whose messages to build (None: all; a listener gets all).
        """
        self.advance()
        return self.publications(scan, wanted)

    def advance(self) -> None:
        """Advance the simulation one tick (stopping a command past its timeout first)."""
        timeout_s = self.parameters.cmd_vel_timeout_s
        expired = timeout_s > 0.0 and \
            self._ticks_since_command * self.sim.dt_s >= timeout_s - TIMEOUT_TOLERANCE_S
        if expired and self.sim.last_command != (0.0, 0.0):
            self.sim.command(0.0, 0.0)
        self._ticks_since_command += 1
        self.sim.step()
        collided = self.sim.state().collided
        if collided and not self._colliding:
            self.collisions += 1
        self._colliding = collided

    def scan_due(self, scan: bool = True, wanted: Container[str] | None = None) -> bool:
        """Whether ``publications(scan, wanted)`` will carry a /scan at this tick."""
        if self.listeners:
            wanted = None
        return scan and self.sim.tick % SCAN.every_ticks == 0 and \
            (wanted is None or SCAN.name in wanted)

    def publications(self, scan: bool = True,
                     wanted: Container[str] | None = None) -> list[Publication]:
        """The messages due at the tick just advanced to (arguments as ``step``'s)."""
        now = self.clock.stamp_s()
        state = self.sim.state()
        noise = self.sim.noise
        pose_variance = (ODOM_POSE_VARIANCE,) * 3
        twist_variance = (max(noise.odom_linear_sigma_mps**2, ODOM_TWIST_VARIANCE),
                          max(noise.odom_angular_sigma_rps**2, ODOM_TWIST_VARIANCE))
        odom = state.odometry
        scan_due = self.scan_due(scan, wanted)
        if self.listeners:
            wanted = None
        out: list[Publication] = []
        if wanted is None or ODOM.name in wanted:
            out.append((ODOM, odometry_msg(odom, now, ODOM_FRAME, pose_variance,
                                           twist_variance)))
        if wanted is None or TF.name in wanted:
            out.append((TF, tf_msg([transform_stamped_msg(now, ODOM_FRAME, BASE_FRAME, odom.x,
                                                          odom.y, odom.theta)])))
        if wanted is None or GROUND_TRUTH.name in wanted:
            out.append((GROUND_TRUTH, odometry_msg(state.ground_truth, now, MAP_FRAME)))
        if scan_due:
            out.append((SCAN, laser_scan_msg(self.sim.scan(), now)))
        for listener in self.listeners:
            listener(out)
        return out

    def latched(self) -> list[Publication]:
        """The transient-local messages: /tf_static (base_link -> laser) and /world."""
        now = self.clock.stamp_s()
        lidar = self.sim.lidar.params
        laser = transform_stamped_msg(now, BASE_FRAME, LASER_FRAME, lidar.mount_x_m,
                                      lidar.mount_y_m, lidar.mount_yaw_rad)
        return [(TF_STATIC, tf_msg([laser])), (WORLD, world_markers_msg(self.sim.world, now))]

    def reset(self) -> None:
        """Back to spawn with odometry zeroed (``/reset_simulation``)."""
        self.sim.reset()
