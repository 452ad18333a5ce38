"""Immutable results of the simulation: poses, odometry, scans and whole-state snapshots.

Units are SI (m, s, rad); frames follow REP 105 (``map`` is the world, ``odom`` starts at the
spawn pose, ``base_link`` is the robot centre with x forward and y left).
"""

from __future__ import annotations

from typing import NamedTuple


class Pose2D(NamedTuple):
    """A planar pose.

    Attributes:
        x: position along the frame's x axis (m).
        y: position along the frame's y axis (m).
        theta: heading, counter-clockwise from the x axis (rad); not wrapped.
    """

    x: float
    y: float
    theta: float


class Command(NamedTuple):
    """A velocity command after clamping to the robot's limits.

    Attributes:
        linear_mps: forward speed, as ``twist.linear.x`` (m/s).
        angular_rps: yaw rate, counter-clockwise positive, as ``twist.angular.z`` (rad/s).
    """

    linear_mps: float
    angular_rps: float


class Odometry(NamedTuple):
    """Pose and body-frame velocity, like ``nav_msgs/Odometry``.

    ``Simulation.odometry()`` is in the ``odom`` frame (zero at spawn, integrated from the wheel
    speeds); ``Simulation.ground_truth()`` is in the ``map`` frame.

    Attributes:
        x: position x (m).
        y: position y (m).
        theta: heading (rad); not wrapped, so full turns accumulate.
        v: forward speed in base_link (m/s).
        omega: yaw rate (rad/s).
    """

    x: float
    y: float
    theta: float
    v: float
    omega: float


class LaserScan(NamedTuple):
    """One LiDAR scan with the fields of ``sensor_msgs/LaserScan`` (frame ``laser``).

    Beam ``i`` points at ``angle_min + i * angle_increment`` in the laser frame, and
    ``angle_max == angle_min + (len(ranges) - 1) * angle_increment``.

    Attributes:
        ranges: distance along each beam (m); see ``physics.lidar`` for no-return and
            too-close values.
        angle_min: angle of the first beam (rad).
        angle_max: angle of the last beam (rad).
        angle_increment: angle between beams (rad).
        range_min: shortest measurable range (m).
        range_max: longest measurable range (m).
        scan_time: time for a full scan (s).
        time_increment: time between two beams (s).
    """

    ranges: tuple[float, ...]
    angle_min: float
    angle_max: float
    angle_increment: float
    range_min: float
    range_max: float
    scan_time: float
    time_increment: float


class WheelState(NamedTuple):
    """The two drive wheels, as their encoders count them (``sensor_msgs/JointState``).

    Attributes:
        left_rad: left wheel angle since spawn or reset, about its axle (+y of base_link:
            positive rolls forward); not wrapped (rad).
        right_rad: right wheel angle, likewise (rad).
        left_rad_s: left wheel angular speed over the last encoder sample (rad/s).
        right_rad_s: right wheel angular speed, likewise (rad/s).
    """

    left_rad: float
    right_rad: float
    left_rad_s: float
    right_rad_s: float


class RobotState(NamedTuple):
    """Everything that changes in one tick, for transports that publish it.

    Attributes:
        time_s: simulated time since spawn or reset (s).
        tick: ticks since spawn or reset.
        mode: ``"kinematic"`` or ``"dynamic"``.
        command: the clamped command in force.
        ground_truth: pose and velocity in the ``map`` frame.
        odometry: pose and velocity in the ``odom`` frame.
        collided: True if the robot touched a wall during the last tick.
    """

    time_s: float
    tick: int
    mode: str
    command: Command
    ground_truth: Odometry
    odometry: Odometry
    collided: bool
