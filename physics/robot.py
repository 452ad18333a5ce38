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
walls and with other robots are pymunk's: the world steps its space once per substep for all
its robots (``physics.world_sim``), each robot pushing with its wheels first (``push``).

Many robots share one world's space. A kinematic robot's body is a pymunk kinematic body
(position-controlled: a dynamic robot stops at it as at a wall); it sweeps its footprint
against the walls and against the other robots' footprints where they stand now
(``step_kinematic``'s ``others``), so a robot driving into another stops at contact.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import pymunk

from physics.kinematics import body_speeds, clamp, integrate_pose, wheel_rim_speeds
from physics.params import RobotParams
from physics.snapshots import Command, Pose2D
from physics.space import WALLS_ONLY, WorldSpace, robot_filter

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


class Disc(NamedTuple):
    """Another robot's footprint where it stands: centre (m, map frame) and radius (m)."""

    x: float
    y: float
    radius_m: float


class MobileRobotPhysics:
    """The robot model of the course text, on a pymunk body in a world's space.

    Args:
        params: physical parameters.
        world_space: the world; the robot's body is added to its space.
        start: initial pose in the map frame.
        mode: ``"kinematic"`` or ``"dynamic"``.
        group: the robot's number in its world (> 0): its footprint's pymunk group, so the
            queries made for it (``physics.space.seen_by``) never see it.
    """

    def __init__(self, params: RobotParams, world_space: WorldSpace, start: Pose2D,
                 mode: str = "kinematic", group: int = 1) -> None:
        self._params = params
        self._space = world_space.space
        self._mode = _checked_mode(mode)
        self.group = group
        self._body = pymunk.Body(params.mass_kg, params.inertia_kg_m2)
        self._body.velocity_func = self._update_velocity
        self._heading_before_step = self._body.rotation_vector
        self._shape = self._make_footprint(params)
        self._space.add(self._body, self._shape)
        self._pose = start
        self._v = 0.0
        self._omega = 0.0
        self._collided = False
        self._samples: list[EncoderSample] = []
        self._held = False
        self._set_body_type()
        self.teleport(start)

    def remove(self) -> None:
        """Take the robot's body and footprint out of its world's space (it was deleted)."""
        self._space.remove(self._body, self._shape)

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
        self._set_body_type()
        self._sync_body()

    @property
    def held(self) -> bool:
        """Whether it is held where it stands (``hold``)."""
        return self._held

    def hold(self, held: bool) -> None:
        """Hold the robot where it stands, at rest, or let it go (``held`` False).

        A paused robot in a world that runs on. A held robot is not stepped; to the others it
        is an obstacle that does not yield (its body is placed by hand, as a kinematic
        robot's).
        """
        if held == self._held:
            return
        self._held = held
        if held:
            self._v = self._omega = 0.0
        self._set_body_type()
        self._sync_body()

    @property
    def footprint(self) -> Disc:
        """Its footprint where it stands now."""
        return Disc(self._pose.x, self._pose.y, self._params.footprint_radius_m)

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
        self._params = params
        if self._body.body_type == pymunk.Body.DYNAMIC:
            self._body.mass = params.mass_kg
            self._body.moment = params.inertia_kg_m2

    def teleport(self, pose: Pose2D) -> None:
        """Place the robot at ``pose`` (map frame), at rest."""
        self._pose = Pose2D(float(pose.x), float(pose.y), float(pose.theta))
        self._v = 0.0
        self._omega = 0.0
        self._collided = False
        self._sync_body()
        self._space.reindex_shapes_for_body(self._body)

    def step(self, command: Command, dt_s: float) -> Sequence[EncoderSample]:
        """Advance alone by ``dt_s`` under ``command`` (already clamped): encoder samples.

        The robot of a world of one; a world of several steps them together
        (``physics.world_sim.WorldSim.step``).
        """
        if self._mode == "kinematic":
            return self.step_kinematic(command, dt_s)
        substeps, sub_dt = dynamic_substeps(dt_s)
        self.begin_dynamic()
        for _ in range(substeps):
            self.push(command, sub_dt)
            self._space.step(sub_dt)
            self.note_contacts()
        return self.end_dynamic()

    def _make_footprint(self, params: RobotParams) -> pymunk.Circle:
        shape = pymunk.Circle(self._body, params.footprint_radius_m)
        shape.filter = robot_filter(self.group)
        shape.friction = 0.0
        shape.elasticity = 0.0
        return shape

    def _set_body_type(self) -> None:
        """Dynamic: a body of its mass that pymunk moves; kinematic: one placed by hand.

        A kinematic robot's body does not yield to a dynamic robot pushing it (as the robot
        it models holds its commanded speed), and pymunk never moves it.
        """
        body = self._body
        if self._mode == "dynamic" and not self._held:
            if body.body_type != pymunk.Body.DYNAMIC:
                body.body_type = pymunk.Body.DYNAMIC
            body.mass = self._params.mass_kg
            body.moment = self._params.inertia_kg_m2
        elif body.body_type != pymunk.Body.KINEMATIC:
            body.body_type = pymunk.Body.KINEMATIC

    def _sync_body(self) -> None:
        """Copy pose and velocity into the pymunk body (kinematic mode moves it by hand)."""
        body = self._body
        body.position = (self._pose.x, self._pose.y)
        body.angle = self._pose.theta
        if body.body_type == pymunk.Body.DYNAMIC:
            body.velocity = (self._v * math.cos(self._pose.theta),
                             self._v * math.sin(self._pose.theta))
            body.angular_velocity = self._omega
        else:  # placed by hand each tick, never moved by pymunk
            body.velocity = (0.0, 0.0)
            body.angular_velocity = 0.0

    def place_body(self) -> None:
        """Bring a kinematic robot's pymunk body to where it stands.

        Before pymunk steps or is queried: the others' contacts and the reference scan see it
        there.
        """
        if self._body.body_type == pymunk.Body.KINEMATIC:
            self._sync_body()
            self._space.reindex_shapes_for_body(self._body)

    def step_kinematic(self, command: Command, dt_s: float,
                       others: Sequence[Disc] = ()) -> list[EncoderSample]:
        """One tick of Eq. 1-3, stopping at contact with a wall or another robot.

        Args:
            command: the clamped command.
            dt_s: the tick (s).
            others: the other robots' footprints where they stand now.
        """
        v, omega = command
        target = integrate_pose(self._pose, v, omega, dt_s)
        fraction = min(self._free_fraction(self._pose, target),
                       self._free_among(self._pose, target, others))
        self._collided = fraction < 1.0
        if self._collided:
            v *= fraction
            target = integrate_pose(self._pose, v, omega, dt_s)
        self._pose, self._v, self._omega = target, v, omega
        # Nothing asks pymunk where a kinematic robot is (walls are queried, not the robot)
        # unless a dynamic robot shares its world (``place_body``), or the model switches.
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

    def _free_among(self, start: Pose2D, end: Pose2D, others: Sequence[Disc]) -> float:
        """Share of the move start -> end the footprint can make before another robot's.

        The footprint's centre meets disc j where it comes within r + r_j of j's centre: a
        ray against a circle of that radius, solved exactly. A move that leads away from a
        robot it touches (or overlaps, after a spawn) is free.
        """
        dx, dy = end.x - start.x, end.y - start.y
        length_2 = dx * dx + dy * dy
        if length_2 == 0.0 or not others:
            return 1.0
        length = math.sqrt(length_2)
        radius = self._params.footprint_radius_m
        fraction = 1.0
        for other in others:
            fx, fy = start.x - other.x, start.y - other.y
            along = fx * dx + fy * dy
            if along >= 0.0:
                continue  # moving away from it (or past it sideways)
            reach = radius + other.radius_m
            gap_2 = fx * fx + fy * fy - reach * reach
            if gap_2 <= 0.0:
                return 0.0  # touching or overlapping, and moving closer
            discriminant = along * along - length_2 * gap_2
            if discriminant < 0.0:
                continue  # passes it by
            t = (-along - math.sqrt(discriminant)) / length_2
            if t <= 1.0:
                fraction = min(fraction, max(0.0, (t * length - CONTACT_SKIN_M) / length))
        return fraction

    def begin_dynamic(self) -> None:
        """A dynamic tick begins: no encoder samples and no contact yet."""
        self._samples = []
        self._collided = False

    def push(self, command: Command, sub_dt: float) -> None:
        """Apply one substep's wheel forces for ``command``, and note what the encoders read.

        The world then steps its space (once for all its robots) and calls ``note_contacts``.
        """
        params = self._params
        half_b = params.half_wheelbase_m
        want_left, want_right = wheel_rim_speeds(command.linear_mps, command.angular_rps, half_b)
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
        self._samples.append(EncoderSample(*body_speeds(rim_left, rim_right, half_b), sub_dt))
        self._heading_before_step = body.rotation_vector

    def note_contacts(self) -> None:
        """After a substep of the space: whether the footprint touches a wall or a robot."""
        if not self._collided:
            self._collided = self._touching()

    def end_dynamic(self) -> list[EncoderSample]:
        """A dynamic tick ends: read the pose and speeds off the body; the encoder samples."""
        self._pose = Pose2D(self._body.position.x, self._body.position.y, self._body.angle)
        self._v, self._omega = self._body_frame_speeds()
        return self._samples

    def _body_frame_speeds(self) -> tuple[float, float]:
        body = self._body
        heading = body.rotation_vector
        return body.velocity.dot(heading), body.angular_velocity

    def _touching(self) -> bool:
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


def dynamic_substeps(dt_s: float) -> tuple[int, float]:
    """How many pymunk steps a dynamic tick of ``dt_s`` takes, and each one's length (s)."""
    substeps = max(1, math.ceil(dt_s / MAX_SUBSTEP_S - 1e-9))
    return substeps, dt_s / substeps


def _checked_mode(mode: str) -> str:
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    return mode
