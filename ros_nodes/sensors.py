"""The robot's sensors: each topic it publishes per tick, and how its message is built.

A ``Sensor`` is one periodic topic of the robot (its ``TopicSpec``: name, type, and rate as
``every_ticks``), how its message is built from the simulation at a stamp, whether a late
tick may shed it, and whether it reads the LiDAR's scan: the tick's one scan pass casts the
scans of every robot that will read one, together (``heartbeat.driver``), before any message
is built. The robot publishes ``ROBOT_SENSORS``; adding a sensor is one more ``Sensor`` in
that tuple (and its ``TopicSpec`` in ``robot_interface``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from physics import ConfigError, Simulation
from physics.world import LOCALIZATIONS
from ros_nodes.robot_interface import CLOCK, GROUND_TRUTH, JOINT_STATES, ODOM, SCAN, TF, TopicSpec
from ros_nodes.robot_messages import (
    BASE_FRAME,
    MAP_FRAME,
    ODOM_FRAME,
    ODOM_POSE_VARIANCE,
    ODOM_TWIST_VARIANCE,
    axis_quaternion,
    clock_msg,
    joint_state_msg,
    laser_scan_msg,
    odometry_msg,
    tf_msg,
    transform_msg,
    transform_stamped_msg,
)
from ros_nodes.urdf import WHEEL_AXIS, WHEEL_JOINTS, WHEEL_LINKS, wheel_origin_m
from rosbridge.msgs.values import Message

BuildMessage = Callable[[Simulation, float], Message]
"""Builds a sensor's message from the simulation at a stamp (s)."""


@dataclass(frozen=True)
class Sensor:
    """One topic the robot publishes every ``topic.every_ticks`` ticks.

    Attributes:
        topic: its topic (name, type, QoS; ``every_ticks`` is its rate, in 50 ms ticks).
        build: its message from the simulation just advanced, at a stamp (s; the robot's
            ``clock.stamp_s``).
        sheddable: a tick that starts late may leave it out (the LiDAR: the biggest
            message, whose loss a reader survives); the others keep their rate.
        reads_scan: ``build`` reads the robot's LiDAR scan (``Simulation.scan``), which the
            tick's one scan pass casts for every robot due, together.
    """

    topic: TopicSpec
    build: BuildMessage
    sheddable: bool = False
    reads_scan: bool = False

    def due(self, tick: int) -> bool:
        """Whether it publishes at ``tick`` (ticks since spawn or reset)."""
        return tick % self.topic.every_ticks == 0


def sim_clock(sim: Simulation, stamp_s: float) -> Message:
    """``/clock``: the tick's time, the stamp of every message of the tick."""
    return clock_msg(stamp_s)


def odometry(sim: Simulation, stamp_s: float) -> Message:
    """``/odom``: wheel odometry in ``odom``, its covariances from the noise model."""
    noise = sim.noise
    pose_variance = (ODOM_POSE_VARIANCE,) * 3
    twist_variance = (max(noise.odom_linear_sigma_mps**2, ODOM_TWIST_VARIANCE),
                      max(noise.odom_angular_sigma_rps**2, ODOM_TWIST_VARIANCE))
    return odometry_msg(sim.odometry(), stamp_s, ODOM_FRAME, pose_variance, twist_variance)


def odometry_transform(sim: Simulation, stamp_s: float) -> Message:
    """``/tf``: odom -> base_link (the odometry's pose), then the wheels in base_link."""
    odom = sim.odometry()
    return tf_msg([transform_stamped_msg(stamp_s, ODOM_FRAME, BASE_FRAME, odom.x, odom.y,
                                         odom.theta),
                   *wheel_transforms(sim, stamp_s)])


def wheel_transforms(sim: Simulation, stamp_s: float) -> list[Message]:
    """base_link -> left_wheel and right_wheel, each at its joint, turned by its angle.

    What robot_state_publisher would make of ``/joint_states`` and the URDF
    (``ros_nodes.urdf``), so viewers draw the turning wheels with no ROS install.
    """
    wheels = sim.wheels()
    robot = sim.params
    return [transform_msg(stamp_s, BASE_FRAME, link, wheel_origin_m(robot, joint),
                          axis_quaternion(WHEEL_AXIS, angle_rad))
            for joint, link, angle_rad in zip(WHEEL_JOINTS, WHEEL_LINKS,
                                              (wheels.left_rad, wheels.right_rad),
                                              strict=True)]


def joint_states(sim: Simulation, stamp_s: float) -> Message:
    """``/joint_states``: the wheel joints' angles and speeds, as the encoders count them."""
    wheels = sim.wheels()
    return joint_state_msg(stamp_s, WHEEL_JOINTS, (wheels.left_rad, wheels.right_rad),
                           (wheels.left_rad_s, wheels.right_rad_s))


def localized_transforms(sim: Simulation, stamp_s: float) -> Message:
    """``/tf`` with perfect localization: map -> odom from the ground truth, odom -> base_link.

    map -> odom is ``Simulation.map_to_odom``, so the chain map -> odom -> base_link is the
    true pose (REP 105) however far the odometry has drifted.
    """
    correction, odom = sim.map_to_odom(), sim.odometry()
    return tf_msg([
        transform_stamped_msg(stamp_s, MAP_FRAME, ODOM_FRAME, *correction),
        transform_stamped_msg(stamp_s, ODOM_FRAME, BASE_FRAME, odom.x, odom.y, odom.theta),
        *wheel_transforms(sim, stamp_s)])


def ground_truth(sim: Simulation, stamp_s: float) -> Message:
    """``/ground_truth``: the true pose and speeds in ``map`` (simulation only)."""
    return odometry_msg(sim.ground_truth(), stamp_s, MAP_FRAME)


def laser_scan(sim: Simulation, stamp_s: float) -> Message:
    """``/scan``: the LiDAR's scan in ``laser`` (cast in the tick's scan pass, else now)."""
    return laser_scan_msg(sim.scan(), stamp_s)


TIME = Sensor(CLOCK, sim_clock)
ODOMETRY = Sensor(ODOM, odometry)
ODOMETRY_TF = Sensor(TF, odometry_transform)
GROUND_TRUTH_POSE = Sensor(GROUND_TRUTH, ground_truth)
LIDAR = Sensor(SCAN, laser_scan, sheddable=True, reads_scan=True)
WHEEL_JOINT_STATES = Sensor(JOINT_STATES, joint_states)

LOCALIZED_TF = Sensor(TF, localized_transforms)

ROBOT_SENSORS = (TIME, ODOMETRY, ODOMETRY_TF, GROUND_TRUTH_POSE, WHEEL_JOINT_STATES, LIDAR)
"""What the robot publishes per tick, in the order it publishes it (the time first, as a
simulator publishes ``/clock`` before the messages stamped with it; no localization: AMCL or
SLAM publishes map -> odom, as on the real robot)."""


def robot_sensors(localization: str) -> tuple[Sensor, ...]:
    """What the robot publishes with ``localization`` (``physics.world.LOCALIZATIONS``).

    ``perfect``: /tf also carries map -> odom.

    Raises:
        ConfigError: not one of ``LOCALIZATIONS``.
    """
    if localization not in LOCALIZATIONS:
        raise ConfigError(f"localization: must be one of {', '.join(LOCALIZATIONS)}, "
                          f"got {localization!r}")
    if localization == "perfect":
        return tuple(LOCALIZED_TF if sensor is ODOMETRY_TF else sensor
                     for sensor in ROBOT_SENSORS)
    return ROBOT_SENSORS
