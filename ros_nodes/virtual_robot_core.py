"""The virtual robot without a transport: /cmd_vel in, ROS-shaped messages out, per tick.

The embedded rosbridge server and the rclpy node both wrap this class, so what the robot
publishes (its sensors, ``ros_nodes.sensors``), at which tick and with which stamp (its one
clock) is decided in one place; its tap (``ros_nodes.tap``) sees what crosses it both ways.
"""

from __future__ import annotations

from collections.abc import Container
from typing import Any

from physics import Simulation
from physics.occupancy import OccupancyGrid
from ros_nodes.parameters import RobotParameters
from ros_nodes.robot_interface import (
    CMD_VEL,
    CMD_VEL_STAMPED_TYPE,
    MAP,
    TF_STATIC,
    WORLD,
    TopicSpec,
)
from ros_nodes.robot_messages import (
    BASE_FRAME,
    LASER_FRAME,
    occupancy_grid_msg,
    tf_msg,
    transform_stamped_msg,
    twist_from_msg,
    world_map,
    world_markers_msg,
)
from ros_nodes.sensors import Sensor, robot_sensors
from ros_nodes.tap import IN, OUT, Tap
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
        sensors: what it publishes per tick, in that order (default: ``robot_sensors`` of its
            ``localization``).
        localization: ``none`` or ``perfect`` (``physics.world.LOCALIZATIONS``: whether
            websim publishes map -> odom); default: the world's.

    Raises:
        ConfigError: an unknown localization.

    Attributes:
        clock: the clock the stamps come from, and its host's intervals.
        sensors: what it publishes per tick (``ros_nodes.sensors``).
        localization: who publishes map -> odom: ``none`` (a localizer) or ``perfect`` (this
            robot, from the ground truth).
        map: the world's occupancy grid, /map (``physics.occupancy``), made once per world.
        tap: sees every /cmd_vel the robot accepts and every message it publishes per tick
            (``ros_nodes.tap``); while a callback listens, every message is built (the rclpy
            node of ``websim serve --ros`` publishes them on the ROS graph through it).
    """

    def __init__(self, sim: Simulation, clock: Clock | None = None,
                 sensors: tuple[Sensor, ...] | None = None,
                 localization: str | None = None) -> None:
        self.sim = sim
        self.localization = sim.world.localization if localization is None else localization
        self.sensors = robot_sensors(self.localization) if sensors is None else sensors
        self.map: OccupancyGrid = world_map(sim.world)
        self.parameters = RobotParameters(sim)
        self.tap = Tap()
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
        if self.tap.attached:
            self.tap.emit(IN, CMD_VEL.name, CMD_VEL_STAMPED_TYPE if stamped else CMD_VEL.type,
                          msg, self.sim.time_s)

    def step(self, wanted: Container[str] | None = None) -> list[Publication]:
        """Advance one tick and return the messages due at it (``advance``, ``publications``).

        With ``cmd_vel_timeout_s`` > 0, a command older than that is replaced by a stop first.

        Args:
            wanted: the topics whose messages to build (None: all; a tap gets all).
        """
        self.advance()
        return self.publications(wanted)

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

    def due(self, wanted: Container[str] | None = None) -> list[Sensor]:
        """The sensors due at the tick just advanced to whose topics are ``wanted``.

        Args:
            wanted: the topics some client subscribes to (None: all; a tap gets all).
        """
        if self.tap.attached:
            wanted = None
        tick = self.sim.tick
        return [sensor for sensor in self.sensors
                if sensor.due(tick) and (wanted is None or sensor.topic.name in wanted)]

    def publications(self, wanted: Container[str] | None = None,
                     shed: bool = False) -> list[Publication]:
        """The messages due at the tick just advanced to.

        Args:
            wanted: the topics whose messages to build (None: all; a tap gets all).
            shed: leave out the sheddable sensors (a late tick: /scan goes first).
        """
        now_s = self.clock.stamp_s()
        out: list[Publication] = [(sensor.topic, sensor.build(self.sim, now_s))
                                  for sensor in self.due(wanted)
                                  if not (shed and sensor.sheddable)]
        if self.tap.attached:
            time_s = self.sim.time_s
            for spec, msg in out:
                self.tap.emit(OUT, spec.name, spec.type, msg, time_s)
        return out

    def latched(self) -> list[Publication]:
        """The transient-local messages: /tf_static (base_link -> laser), /world and /map.

        The world never changes while the robot runs (a reset keeps it), so these are sent
        once, at start, and to every later subscriber.
        """
        now_s = self.clock.stamp_s()
        lidar = self.sim.lidar.params
        laser = transform_stamped_msg(now_s, BASE_FRAME, LASER_FRAME, lidar.mount_x_m,
                                      lidar.mount_y_m, lidar.mount_yaw_rad)
        return [(TF_STATIC, tf_msg([laser])),
                (WORLD, world_markers_msg(self.sim.world, now_s)),
                (MAP, occupancy_grid_msg(self.map, now_s))]

    def reset(self) -> None:
        """Back to spawn with odometry zeroed (``/reset_simulation``)."""
        self.sim.reset()
