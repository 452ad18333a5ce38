"""The differential-drive robot: kinematic (course Eq. 1-3) or dynamic (pymunk) motion.

Kinematic mode (the default) applies the commanded velocities instantly and moves the pose by
exactly one step of Eq. 1-3 per tick. A tick whose motion would push the footprint into a wall
stops at contact instead (``collided`` is then True); turning in place is always allowed.

Dynamic mode is a pymunk body of ``mass_kg`` and ``inertia_kg_m2`` pushed by two wheels at
+-wheelbase/2 on the body's y axis. In every substep each wheel's speed controller asks for the
force that would bring its rim speed to the commanded one within that substep (an ideal, stiff
motor loop); the ground transmits at most ``max_wheel_force_n``. Below the limit the wheel
grips and its encoder reads the ground speed; at the limit it slips and spins at the commanded
speed, so odometry runs ahead of the true motion (hard starts, pushing against a wall). Wheels
do not slip sideways: the body's lateral velocity is removed every substep. Contacts with
walls are pymunk's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import pymunk

from physics.kinematics import body_speeds, clamp, integrate_pose, wheel_rim_speeds
from physics.params import RobotParams
from physics.snapshots import Command, Pose2D
from physics.space import ROBOT_CATEGORY, WALLS_ONLY, WorldSpace

MODES = ("kinematic", "dynamic")

MAX_SUBSTEP_S = 0.01
"""Longest pymunk step in dynamic mode: at the 0.5 m/s limit the body moves 5 mm per substep,
under 1/20 of the footprint, so contacts are caught before any visible overlap."""

CONTACT_SKIN_M = 1e-6
"""Kinematic mode stops this far short of a wall, so the next tick starts clear of it and a
command away from the wall moves the robot again."""


class EncoderSample(NamedTuple):
    """Body speeds from the wheel encoders over one interval, which odometry integrates.

    Attributes:
        v: forward speed from the two wheel rim speeds (m/s).
        omega: yaw rate from the two wheel rim speeds (rad/s).
        dt_s: length of the interval (s).
    """

    v: float
    omega: float
    dt_s: float


class MobileRobotPhysics:
    """The robot model of the course text, on a pymunk body in a world's space.

    Args:
        params: physical parameters.
        world_space: the world; the robot's body is added to its space.
        start: initial pose in the map frame.
        mode: ``"kinematic"`` or ``"dynamic"``.
    """

    def __init__(self, params: RobotParams, world_space: WorldSpace, start: Pose2D,
                 mode: str = "kinematic") -> None:
        self._params = params
        self._space = world_space.space
        self._mode = _checked_mode(mode)
        self._body = pymunk.Body(params.mass_kg, params.inertia_kg_m2)
        self._body.velocity_func = self._update_velocity
        self._heading_before_step = self._body.rotation_vector
        self._shape = self._make_footprint(params)
        self._space.add(self._body, self._shape)
        self._pose = start
        self._v = 0.0
        self._omega = 0.0
        self._collided = False
        self.teleport(start)

    @property
    def params(self) -> RobotParams:
        """The parameters in force."""
        return self._params

    @property
    def mode(self) -> str:
        """``"kinematic"`` or ``"dynamic"``; switching keeps pose and velocity."""
        return self._mode

    @mode.setter
    def mode(self, mode: str) -> None:
        self._mode = _checked_mode(mode)
        self._sync_body()

    @property
    def pose(self) -> Pose2D:
        """Pose in the map frame."""
        return self._pose

    @property
    def v(self) -> float:
        """True forward speed in base_link (m/s)."""
        return self._v

    @property
    def omega(self) -> float:
        """True yaw rate (rad/s)."""
        return self._omega

    @property
    def collided(self) -> bool:
        """True if the footprint touched a wall during the last step."""
        return self._collided

    def set_params(self, params: RobotParams) -> None:
        """Apply new parameters now, e.g. a payload change; pose and velocity are kept."""
        if params.footprint_radius_m != self._params.footprint_radius_m:
            self._space.remove(self._shape)
            self._shape = self._make_footprint(params)
            self._space.add(self._shape)
        self._body.mass = params.mass_kg
        self._body.moment = params.inertia_kg_m2
        self._params = params

    def teleport(self, pose: Pose2D) -> None:
        """Place the robot at ``pose`` (map frame), at rest."""
        self._pose = Pose2D(float(pose.x), float(pose.y), float(pose.theta))
        self._v = 0.0
        self._omega = 0.0
        self._collided = False
        self._sync_body()
        self._space.reindex_shapes_for_body(self._body)

    def step(self, command: Command, dt_s: float) -> Sequence[EncoderSample]:
        """Advance by ``dt_s`` under ``command`` (already clamped); returns encoder samples."""
        if self._mode == "kinematic":
            return self._step_kinematic(command, dt_s)
        return self._step_dynamic(command, dt_s)

    def _make_footprint(self, params: RobotParams) -> pymunk.Circle:
        shape = pymunk.Circle(self._body, params.footprint_radius_m)
        shape.filter = pymunk.ShapeFilter(categories=ROBOT_CATEGORY)
        shape.friction = 0.0
        shape.elasticity = 0.0
        return shape

    def _sync_body(self) -> None:
        """Copy pose and velocity into the pymunk body (kinematic mode moves it by hand)."""
        body = self._body
        body.position = (self._pose.x, self._pose.y)
        body.angle = self._pose.theta
        body.velocity = (self._v * math.cos(self._pose.theta),
                         self._v * math.sin(self._pose.theta))
        body.angular_velocity = self._omega

    def _step_kinematic(self, command: Command, dt_s: float) -> list[EncoderSample]:
        v, omega = command
        target = integrate_pose(self._pose, v, omega, dt_s)
        fraction = self._free_fraction(self._pose, target)
        self._collided = fraction < 1.0
        if self._collided:
            v *= fraction
            target = integrate_pose(self._pose, v, omega, dt_s)
        self._pose, self._v, self._omega = target, v, omega
        # Nothing asks pymunk where a kinematic robot is (walls are queried, not the robot):
        # its body is brought up to date when the dynamic model takes over (``mode``).
        return [EncoderSample(v, omega, dt_s)]

    def _free_fraction(self, start: Pose2D, end: Pose2D) -> float:
        """Share of the straight move start -> end the footprint can make before a wall.

        Candidates come from pymunk's index (bb_query over the swept box); each is then swept
        with the shape's own query, because ``Space.segment_query`` with a radius can miss
        shapes whose bounding box the centre line does not cross.
        """
        dx, dy = end.x - start.x, end.y - start.y
        length = math.hypot(dx, dy)
        if length == 0.0:
            return 1.0
        radius = self._params.footprint_radius_m
        swept = pymunk.BB(min(start.x, end.x) - radius, min(start.y, end.y) - radius,
                          max(start.x, end.x) + radius, max(start.y, end.y) + radius)
        fraction = 1.0
        for shape in self._space.bb_query(swept, WALLS_ONLY):
            hit = shape.segment_query((start.x, start.y), (end.x, end.y), radius)
            if hit is None or hit.shape is None or hit.normal.x * dx + hit.normal.y * dy >= 0.0:
                continue  # no contact, or the move leads away from this wall
            fraction = min(fraction, max(0.0, (hit.alpha * length - CONTACT_SKIN_M) / length))
        return fraction

    def _step_dynamic(self, command: Command, dt_s: float) -> list[EncoderSample]:
        substeps = max(1, math.ceil(dt_s / MAX_SUBSTEP_S - 1e-9))
        sub_dt = dt_s / substeps
        params = self._params
        half_b = params.half_wheelbase_m
        want_left, want_right = wheel_rim_speeds(command.linear_mps, command.angular_rps, half_b)
        samples = []
        collided = False
        for _ in range(substeps):
            body = self._body
            v, omega = self._body_frame_speeds()
            force_total = params.mass_kg * (command.linear_mps - v) / sub_dt
            torque = params.inertia_kg_m2 * (command.angular_rps - omega) / sub_dt
            ask_left = 0.5 * force_total - torque / (2.0 * half_b)
            ask_right = 0.5 * force_total + torque / (2.0 * half_b)
            force_left = clamp(ask_left, params.max_wheel_force_n)
            force_right = clamp(ask_right, params.max_wheel_force_n)
            body.apply_force_at_local_point((force_left, 0.0), (0.0, half_b))
            body.apply_force_at_local_point((force_right, 0.0), (0.0, -half_b))
            # pymunk moves the body with the velocity it has now, then applies the forces; the
            # encoders see that motion, or the commanded speed where a wheel slips.
            ground_left, ground_right = wheel_rim_speeds(v, omega, half_b)
            rim_left = want_left if force_left != ask_left else ground_left
            rim_right = want_right if force_right != ask_right else ground_right
            samples.append(EncoderSample(*body_speeds(rim_left, rim_right, half_b), sub_dt))
            self._heading_before_step = body.rotation_vector
            self._space.step(sub_dt)
            collided = collided or self._touching_wall()
        self._pose = Pose2D(self._body.position.x, self._body.position.y, self._body.angle)
        self._v, self._omega = self._body_frame_speeds()
        self._collided = collided
        return samples

    def _body_frame_speeds(self) -> tuple[float, float]:
        body = self._body
        heading = body.rotation_vector
        return body.velocity.dot(heading), body.angular_velocity

    def _touching_wall(self) -> bool:
        touching = False

        def note(arbiter: pymunk.Arbiter) -> None:
            nonlocal touching
            touching = True

        self._body.each_arbiter(note)
        return touching

    def _update_velocity(self, body: pymunk.Body, gravity: tuple[float, float],
                         damping: float, dt: float) -> None:
        """Integrate the wheel forces, then apply the wheels' no-sideways-slip constraint.

        pymunk has already turned the body for this step. The forces were applied along the
        heading from before the turn, so the forward speed is measured along that heading and
        the velocity turned with the body, as rolling wheels turn it (the constraint force is
        perpendicular to the motion and does no work). Any sideways part is dropped.
        """
        pymunk.Body.update_velocity(body, (0.0, 0.0), 1.0, dt)
        forward = clamp(body.velocity.dot(self._heading_before_step), self._params.max_linear_mps)
        body.velocity = body.rotation_vector * forward
        body.angular_velocity = clamp(body.angular_velocity, self._params.max_angular_rps)


def _checked_mode(mode: str) -> str:
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    return mode
