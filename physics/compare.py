"""Kinematic vs dynamic: run one command sequence through both modes and measure the difference.

For assignments and notebooks::

    from physics import load_world
    from physics.compare import compare, load_commands
    result = compare(load_world("empty"), load_commands("examples/commands/step.yaml"))
    result.summary["difference"]["final_position_m"]

A command file is a YAML list (or a CSV with these columns) of segments::

    - {duration_s: 2.0, linear_mps: 0.3, angular_rps: 0.0}
    - {duration_s: 3.0, linear_mps: 0.3, angular_rps: 0.5, mass_kg: 2.4, inertia_kg_m2: 0.0132}

``mass_kg`` and ``inertia_kg_m2`` are optional payload changes made at the segment's start (the
admin page's perturbation). Both modes run headless with the same seed; with a heading PID the
segments' ``angular_rps`` is replaced by the controller's output at 10 Hz, fed the odometry or
the true heading, and each mode's summary adds the step responses of both headings
(``heading``: odometry, ``true_heading``: ground truth relative to spawn), each with its
``final_error_deg``.
"""

from __future__ import annotations

import csv
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from physics.params import LidarParams, NoiseParams, RobotParams
from physics.pid import CONTROL_PERIOD_S, HeadingPid, PidGains, wrap_angle
from physics.shipped import by_name, shipped
from physics.simulation import Simulation
from physics.validation import (
    ConfigError,
    as_finite_float,
    as_mapping,
    as_positive_float,
    check_keys,
    parse_yaml,
    read_text_file,
    shown,
)
from physics.world import World

COMMANDS_DIR = shipped("physics", "examples/commands")
"""The shipped command files (``step``, ``circle``, ``square``, ``payload_bonus``), found by
name as worlds are."""

MODES_COMPARED = ("kinematic", "dynamic")

HEADING_FEEDBACK = ("odometry", "ground_truth")
"""What a heading controller can be fed: /odom (the course's node) or the true heading (an IMU)."""

SEGMENT_KEYS = ("duration_s", "linear_mps", "angular_rps", "mass_kg", "inertia_kg_m2")

TRAJECTORY_COLUMNS = ("t_s", "mode", "cmd_v", "cmd_omega", "x", "y", "theta", "v", "omega",
                      "odom_x", "odom_y", "odom_theta")
"""The columns of ``trajectory.csv``: ground truth unprefixed, odometry prefixed."""

RISE_FRACTION = 0.9
"""Rise time is the time to 90 % of a step."""


@dataclass(frozen=True)
class Segment:
    """A stretch of constant command.

    Attributes:
        duration_s: how long it lasts (s).
        linear_mps: linear.x (m/s).
        angular_rps: angular.z (rad/s).
        mass_kg: payload change at the start, or None.
        inertia_kg_m2: payload change at the start, or None.
    """

    duration_s: float
    linear_mps: float
    angular_rps: float
    mass_kg: float | None = None
    inertia_kg_m2: float | None = None


class TrajectoryRow(NamedTuple):
    """One tick of one mode; ground truth unprefixed, odometry prefixed (m, rad, m/s, rad/s)."""

    t_s: float
    mode: str
    cmd_v: float
    cmd_omega: float
    x: float
    y: float
    theta: float
    v: float
    omega: float
    odom_x: float
    odom_y: float
    odom_theta: float


@dataclass(frozen=True)
class HeadingController:
    """Replace the segments' angular_rps by a heading PID at 10 Hz.

    Attributes:
        gains: the PID's gains; its output limit is clamped to the robot's max_angular_rps.
        setpoint_rad: the heading to hold, in the odom frame (rad).
        feedback: the heading it measures: ``"odometry"`` (wheel encoders, like ``/odom``) or
            ``"ground_truth"`` (the true heading relative to spawn, like an IMU).
    """

    gains: PidGains
    setpoint_rad: float
    feedback: str = "odometry"

    def __post_init__(self) -> None:
        if self.feedback not in HEADING_FEEDBACK:
            raise ConfigError(f"feedback: must be one of {', '.join(HEADING_FEEDBACK)}, "
                              f"got {shown(self.feedback)}")


@dataclass(frozen=True)
class Comparison:
    """What ``compare`` measured: the files' contents, as data.

    Attributes:
        rows: every tick of every mode, the rows of ``trajectory.csv``.
        summary: the content of ``summary.json``.
    """

    rows: tuple[TrajectoryRow, ...]
    summary: dict[str, Any]

    def mode_rows(self, mode: str) -> list[TrajectoryRow]:
        """The rows of one mode, in time order."""
        return [row for row in self.rows if row.mode == mode]


def resolve_commands_path(path: str | Path) -> Path:
    """``path`` itself, or for a bare name (``"step"``) the shipped command file of that name."""
    return by_name(path, COMMANDS_DIR)


def load_commands(path: str | Path) -> tuple[Segment, ...]:
    """Read a command file (``.yaml``/``.yml`` or ``.csv``), or a shipped one by name (``step``).

    Raises:
        ConfigError: unreadable file or a bad segment; the message names the segment and field.
    """
    source = str(path)
    resolved = resolve_commands_path(path)
    try:
        text = read_text_file(resolved, "command", source=source)
    except ConfigError as error:
        if resolved.exists():
            raise
        known = ", ".join(sorted(shipped.stem for shipped in COMMANDS_DIR.glob("*.yaml")))
        raise ConfigError(f"{error} (shipped command files: {known})") from None
    if resolved.suffix.lower() == ".csv":
        items: Any = [{key: value for key, value in row.items() if value not in ("", None)}
                      for row in csv.DictReader(text.splitlines())]
        items = [{key: _csv_number(source, index, key, value) for key, value in row.items()}
                 for index, row in enumerate(items)]
    else:
        items = parse_yaml(text, source)
    return segments_from_list(items, source=source)


def _csv_number(source: str, index: int, key: str, value: str) -> Any:
    try:
        return float(value)
    except ValueError:
        return value  # left for the field check, which names segment and field


def segments_from_list(items: Any, *, source: str = "<commands>") -> tuple[Segment, ...]:
    """Validate a list of segment mappings."""
    if not isinstance(items, list) or not items:
        raise ConfigError(f"{source}: expected a non-empty list of segments, got {shown(items)}")
    segments = []
    for index, item in enumerate(items):
        where = f"{source}: segment {index + 1}"
        mapping = as_mapping(where, item)
        check_keys(where, mapping, SEGMENT_KEYS)
        if "duration_s" not in mapping:
            raise ConfigError(f"{where}: missing duration_s")
        payload = {key: as_positive_float(f"{where}.{key}", mapping[key])
                   for key in ("mass_kg", "inertia_kg_m2") if key in mapping}
        segments.append(Segment(
            duration_s=as_positive_float(f"{where}.duration_s", mapping["duration_s"]),
            linear_mps=as_finite_float(f"{where}.linear_mps", mapping.get("linear_mps", 0.0)),
            angular_rps=as_finite_float(f"{where}.angular_rps",
                                        mapping.get("angular_rps", 0.0)),
            **payload))
    return tuple(segments)


def run_mode(world: World, segments: Sequence[Segment], mode: str,
             params: RobotParams | None = None, *, seed: int = 0,
             lidar: LidarParams | None = None, noise: NoiseParams | None = None,
             controller: HeadingController | None = None,
             on_tick: Callable[[], None] | None = None) -> list[TrajectoryRow]:
    """Drive ``segments`` through one mode; one row per tick, the first at t = 0."""
    sim = Simulation(world, params, mode=mode, seed=seed, lidar=lidar, noise=noise)
    pid = None
    feedback = HEADING_FEEDBACK[0]
    if controller is not None:
        feedback = controller.feedback
        limit = min(controller.gains.output_limit, sim.params.max_angular_rps)
        gains = PidGains(controller.gains.kp, controller.gains.ki, controller.gains.kd, limit)
        pid = HeadingPid(gains, controller.setpoint_rad)
    ticks_per_control = max(1, round(CONTROL_PERIOD_S / sim.dt_s))
    rows = [_row(sim, mode)]
    for segment in segments:
        if segment.mass_kg is not None or segment.inertia_kg_m2 is not None:
            sim.set_payload(segment.mass_kg, segment.inertia_kg_m2)
        angular = segment.angular_rps
        sim.command(segment.linear_mps, angular)
        for _ in range(max(1, round(segment.duration_s / sim.dt_s))):
            if pid is not None and sim.tick % ticks_per_control == 0:
                heading = (sim.odometry().theta if feedback == "odometry"
                           else wrap_angle(sim.ground_truth().theta - world.start.theta))
                angular = pid.update(heading, ticks_per_control * sim.dt_s)
                sim.command(segment.linear_mps, angular)
            sim.step()
            rows.append(_row(sim, mode))
            if on_tick is not None:
                on_tick()
    return rows


def _row(sim: Simulation, mode: str) -> TrajectoryRow:
    truth, odom, command = sim.ground_truth(), sim.odometry(), sim.last_command
    return TrajectoryRow(round(sim.time_s, 9), mode, command.linear_mps, command.angular_rps,
                         truth.x, truth.y, truth.theta, truth.v, truth.omega,
                         odom.x, odom.y, odom.theta)


def compare(world: World, segments: Sequence[Segment], params: RobotParams | None = None, *,
            seed: int = 0, lidar: LidarParams | None = None, noise: NoiseParams | None = None,
            controller: HeadingController | None = None,
            on_tick: Callable[[], None] | None = None) -> Comparison:
    """Run ``segments`` in both modes with the same seed and summarise the difference."""
    runs = {mode: run_mode(world, segments, mode, params, seed=seed, lidar=lidar, noise=noise,
                           controller=controller, on_tick=on_tick)
            for mode in MODES_COMPARED}
    summary: dict[str, Any] = {mode: _mode_summary(rows, segments, controller,
                                                   world.start.theta)
                               for mode, rows in runs.items()}
    kinematic, dynamic = runs["kinematic"], runs["dynamic"]
    deviations = [math.hypot(a.x - b.x, a.y - b.y) for a, b in
                  zip(kinematic, dynamic, strict=True)]
    summary["difference"] = {
        "final_position_m": deviations[-1],
        "final_heading_rad": wrap_angle(dynamic[-1].theta - kinematic[-1].theta),
        "max_path_deviation_m": max(deviations),
        "max_path_deviation_at_s": kinematic[deviations.index(max(deviations))].t_s,
    }
    summary["ticks_per_mode"] = len(kinematic)
    summary["seed"] = seed
    return Comparison(rows=tuple(kinematic + dynamic), summary=summary)


def _mode_summary(rows: list[TrajectoryRow], segments: Sequence[Segment],
                  controller: HeadingController | None, spawn_theta: float) -> dict[str, Any]:
    final = rows[-1]
    distance = sum(math.hypot(b.x - a.x, b.y - a.y) for a, b in itertools.pairwise(rows))
    steps = []
    start_index = 0
    for number, segment in enumerate(segments, start=1):
        ticks = max(1, round(segment.duration_s / (rows[1].t_s - rows[0].t_s)))
        window = rows[start_index:start_index + ticks + 1]
        steps.append({
            "segment": number,
            "v": step_response([r.t_s for r in window], [r.v for r in window],
                               window[-1].cmd_v),
            "omega": step_response([r.t_s for r in window], [r.omega for r in window],
                                   window[-1].cmd_omega),
        })
        start_index += ticks
    summary: dict[str, Any] = {
        "final_pose": {"x": final.x, "y": final.y, "theta": final.theta},
        "final_odometry": {"x": final.odom_x, "y": final.odom_y, "theta": final.odom_theta},
        "distance_travelled_m": distance,
        "steps": steps,
    }
    if controller is not None:
        times = [r.t_s for r in rows]
        odometry = [r.odom_theta for r in rows]
        truth = [wrap_angle(r.theta - spawn_theta) for r in rows]
        for key, headings in (("heading", odometry), ("true_heading", truth)):
            summary[key] = {
                **step_response(times, headings, controller.setpoint_rad),
                "final_error_deg": math.degrees(wrap_angle(headings[-1]
                                                           - controller.setpoint_rad)),
            }
    return summary


def step_response(times_s: Sequence[float], values: Sequence[float],
                  target: float) -> Mapping[str, float | None]:
    """Rise time to 90 % and overshoot of a step from ``values[0]`` towards ``target``.

    Rise time is interpolated between samples and counted from ``times_s[0]`` (None if never
    reached, or no step); overshoot is the largest excursion past ``target`` as a percentage of
    the step (0 if none); settling is the time after which the value stays within 2 % of the
    step of ``target``.
    """
    start = values[0]
    step = target - start
    if abs(step) < 1e-12:
        return {"rise_time_s": None, "overshoot_pct": 0.0, "settling_time_s": None}
    progress = [(value - start) / step for value in values]
    rise = None
    for index in range(1, len(progress)):
        if progress[index] >= RISE_FRACTION:
            before, after = progress[index - 1], progress[index]
            share = (RISE_FRACTION - before) / (after - before) if after != before else 0.0
            rise = times_s[index - 1] + share * (times_s[index] - times_s[index - 1]) \
                - times_s[0]
            break
    overshoot = max(0.0, (max(progress) - 1.0) * 100.0)
    settling = None
    for index in range(len(progress) - 1, -1, -1):
        if abs(progress[index] - 1.0) > 0.02:
            if index + 1 < len(progress):
                settling = times_s[index + 1] - times_s[0]
            break
    else:
        settling = 0.0
    return {"rise_time_s": rise, "overshoot_pct": overshoot, "settling_time_s": settling}
