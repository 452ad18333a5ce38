"""The virtual robot without a transport: /cmd_vel in, ROS-shaped messages out, per tick.

The embedded rosbridge server and the rclpy node both wrap this class, so what the robot
publishes (its sensors, ``ros_nodes.sensors``), at which tick and with which stamp (its one
clock) is decided in one place; its tap (``ros_nodes.tap``) sees what crosses it both ways.
"""

from __future__ import annotations

from collections.abc import Callable, Container, Sequence
from typing import Any

from physics import Simulation
from physics.occupancy import OccupancyGrid
from ros_nodes.parameters import RobotParameters
from ros_nodes.robot_interface import (
    CMD_VEL,
    CMD_VEL_STAMPED_TYPE,
    MAP,
    ROBOT_DESCRIPTION,
    TF_STATIC,
    WORLD,
    TopicSpec,
)
from ros_nodes.robot_messages import (
    BASE_FRAME,
    LASER_FRAME,
    occupancy_grid_msg,
    robot_description_msg,
    tf_msg,
    transform_stamped_msg,
    twist_from_msg,
    world_map,
    world_markers_msg,
)
from ros_nodes.sensors import Sensor, robot_sensors
from ros_nodes.sim_clock import SimClock
from ros_nodes.tap import IN, OUT, Tap
from ros_nodes.urdf import robot_urdf
from rosbridge.core.clock import Clock, WallClock
from rosbridge.msgs.values import Message

Publication = tuple[TopicSpec, Message]

LatchedListener = Callable[[Publication], None]
"""Called with a latched message that changed while the robot runs (its new value)."""

TIMEOUT_TOLERANCE_S = 1e-9
"""Rounding slack of the command watchdog: a command 0.5 s old on ticks 50 ms apart has
expired, whatever the last bits of 10 x 0.05 say."""


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
        latched_listeners: called with each latched message that changes while the robot
            runs: ``/robot_description`` when a parameter that shapes the URDF (mass,
            inertia, the speed and traction limits) is set. The bridge endpoint and the
            rclpy node publish it again (transient local: late subscribers get the new one).
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
        if isinstance(self.clock, SimClock) and not self.clock.following:
            world = sim.world_sim
            self.clock.follow(lambda: world.tick)  # the one tick counter: its world's
        self._command_s: float | None = None
        """When the last command arrived (``watchdog_s``); None: none yet."""
        self.collisions = 0
        """Times the robot ran into a wall or another robot (ticks where a contact began)
        since it started."""
        self._colliding = False
        self.latched_listeners: list[LatchedListener] = []
        self._urdf = self.urdf()
        self.parameters.listeners.append(self._on_parameters_changed)

    def urdf(self) -> str:
        """The robot's URDF for the parameters in force (``ros_nodes.urdf``)."""
        return robot_urdf(self.sim.params, self.sim.lidar.params)

    def _on_parameters_changed(self, names: list[str]) -> None:
        """Publish the URDF again when a change reshaped it (a payload, a limit)."""
        urdf = self.urdf()
        if urdf == self._urdf:
            return
        self._urdf = urdf
        publication = (ROBOT_DESCRIPTION, robot_description_msg(urdf))
        for listener in self.latched_listeners:
            listener(publication)

    def on_cmd_vel(self, msg: Any, stamped: bool = False) -> None:
        """Apply a ``geometry_msgs/Twist`` (or ``TwistStamped``) dict as the new command.

        Raises:
            ConfigError: malformed or non-finite; the command in force is kept.
        """
        linear, angular = twist_from_msg(msg, stamped=stamped)
        self.sim.command(linear, angular)
        self._command_s = self.watchdog_s()
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

    def watchdog_s(self) -> float:
        """The time the ``/cmd_vel`` watchdog reads (s).

        On sim time (a ``SimClock``: ``--speed``, a ``use_sim_time`` node) the robot's own:
        its simulation's time, which the tick about to step starts at, so a 0.5 s timeout
        is ten ticks of motion at any speed. Otherwise the clock's monotonic time (wall
        time, as a motor driver's timeout runs).
        """
        if isinstance(self.clock, SimClock):
            return self.sim.time_s
        return self.clock.monotonic_s()

    def advance(self) -> None:
        """Advance the simulation one tick (stopping a command past its timeout first).

        ``before_step``, its world's ``step``, ``after_step``: what the tick driver does for
        every robot of a world around the world's one step.
        """
        self.before_step()
        self.sim.step()
        self.after_step()

    def before_step(self) -> None:
        """Before its world steps: a command past its timeout is replaced by a stop.

        The watchdog (``cmd_vel_timeout_s`` > 0) measures the last command's age on the
        robot's clock (``watchdog_s``: wall time, or simulated time where the clock
        runs on it), so the robot stops at the first tick at least the timeout after the
        last command: within the timeout and one tick.
        """
        timeout_s = self.parameters.cmd_vel_timeout_s
        if timeout_s > 0.0 and self._command_s is not None and \
                self.watchdog_s() - self._command_s >= timeout_s - TIMEOUT_TOLERANCE_S:
            self._command_s = None  # stopped: nothing left to expire
            self.sim.command(0.0, 0.0)

    def after_step(self) -> None:
        """After its world stepped: count a contact that began (``collisions``)."""
        collided = self.sim.state().collided
        if collided and not self._colliding:
            self.collisions += 1
        self._colliding = collided

    def due(self, wanted: Container[str] | None = None,
            scans: bool | None = None) -> list[Sensor]:
        """The sensors due at the tick just advanced to whose topics are ``wanted``.

        Args:
            wanted: the topics some client subscribes to (None: all; a tap gets all).
            scans: only the sensors that read the LiDAR's scan (True), only the others
                (False), or all (None).
        """
        if self.tap.attached:
            wanted = None
        tick = self.sim.tick
        return [sensor for sensor in self.sensors
                if sensor.due(tick) and (wanted is None or sensor.topic.name in wanted)
                and (scans is None or sensor.reads_scan == scans)]

    def publications(self, wanted: Container[str] | None = None,
                     shed: bool = False, scans: bool | None = None) -> list[Publication]:
        """The messages due at the tick just advanced to.

        Args:
            wanted: the topics whose messages to build (None: all; a tap gets all).
            shed: leave out the sheddable sensors (a late tick: /scan goes first).
            scans: only the messages that read the LiDAR's scan (True), only the others
                (False: the tick's /odom and /tf, out before its scan pass), or all (None).
        """
        return self.messages(self.due(wanted, scans), shed)

    def messages(self, sensors: Sequence[Sensor], shed: bool = False) -> list[Publication]:
        """The messages of ``sensors`` (``due``'s) at the tick just advanced to.

        The tap sees them.

        Args:
            sensors: the sensors due whose messages to build.
            shed: leave out the sheddable sensors (a late tick: /scan goes first).
        """
        now_s = self.clock.stamp_s()
        out: list[Publication] = [(sensor.topic, sensor.build(self.sim, now_s))
                                  for sensor in sensors if not (shed and sensor.sheddable)]
        if self.tap.attached:
            time_s = self.sim.time_s
            for spec, msg in out:
                self.tap.emit(OUT, spec.name, spec.type, msg, time_s)
        return out

    def latched(self) -> list[Publication]:
        """The transient-local messages: /tf_static, /world, /map and /robot_description.

        /tf_static holds base_link -> laser. The world never changes while the robot runs (a
        reset keeps it), so the first three are sent once, at start, and to every later
        subscriber; /robot_description is the URDF in force (``latched_listeners`` hear when a
        parameter change makes a new one).
        """
        now_s = self.clock.stamp_s()
        lidar = self.sim.lidar.params
        laser = transform_stamped_msg(now_s, BASE_FRAME, LASER_FRAME, lidar.mount_x_m,
                                      lidar.mount_y_m, lidar.mount_yaw_rad)
        return [(TF_STATIC, tf_msg([laser])),
                (WORLD, world_markers_msg(self.sim.world, now_s)),
                (MAP, occupancy_grid_msg(self.map, now_s)),
                (ROBOT_DESCRIPTION, robot_description_msg(self._urdf))]

    def reset(self) -> None:
        """Back to spawn with odometry zeroed (``/reset_simulation``)."""
        self.sim.reset()
        self._command_s = None  # the reset stopped it: nothing left to expire
