"""Scenario and suite files: what a graded run is, read from YAML into frozen dataclasses.

A scenario (every coordinate in the ``map`` frame, m and rad; docs/grading.md has the whole
format)::

    name: heading_pid                 # optional; default: the file's name
    description: a 90° step           # optional
    world: empty                      # a shipped world's name, or a path from this file
    start: [0.0, 0.0, 0.0]            # optional; default: the world's start
    mode: kinematic                   # kinematic | dynamic
    payload: {scale: 1.0}             # or {mass_kg: 2.4, inertia_kg_m2: 0.0132}
    duration_s: 10.0                  # the run's length, its timeout (sim time)
    seed: 0
    controller_rate_hz: 10            # how often the controller is asked for a command
    parameters:                       # told to the controller as WEBSIM_<NAME>
      setpoint_rad: 1.5708
    changes:                          # at set times: payload, mode, parameters
      - {at_s: 5.0, payload: {scale: 2.0}, parameters: {setpoint_rad: 0.0}}
    end: {point: [5.5, 4.0], radius_m: 1.0}   # optional: the run ends there
    lidar: {angle_min_rad: -pi}       # optional: the scan's angles (over the world's)
    metrics:
      - {kind: heading_step, threshold: 3.0, weight: 1.0}

A suite lists scenarios, each from a file (a path from the suite, or a shipped scenario's
name) or written inline, with a weight::

    name: wall_following
    scenarios:
      - {file: heading_pid.yaml, weight: 1}
      - {weight: 2, scenario: {name: right_wall, world: corridor, ...}}

Every error names the file, the line and the entry, with a suggestion for an unknown key,
e.g. ``examples/scenarios/heading_pid.yaml:7: metrics[0]: unknown key 'treshold'; did you
mean 'threshold'?``.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from grading.geometry import nearest_obstacles, obstacle_origins, world_shapes
from grading.metrics import METRICS
from grading.metrics.heading_step import setpoint_schedule
from grading.metrics.wall_following import MIT_END_RADIUS_M
from physics.params import LidarParams, RobotParams
from physics.pid import CONTROL_PERIOD_S
from physics.robot import MODES
from physics.shipped import by_name, shipped
from physics.simulation import TICK_PERIOD_S
from physics.snapshots import Pose2D
from physics.validation import (
    ConfigError,
    as_finite_float,
    as_mapping,
    as_non_negative_float,
    as_number_list,
    as_positive_float,
    check_keys,
    did_you_mean,
    fail,
    line_of,
    load_yaml_file,
    located,
    shown,
    type_name,
)
from physics.world import WORLDS_DIR, World, lidar_overrides, load_world

SCENARIOS_DIR = shipped("physics", "examples/scenarios")
"""The shipped scenarios and suites; ``load_suite("heading_pid")`` looks here."""

SCENARIO_KEYS = ("name", "description", "world", "start", "mode", "payload", "duration_s",
                 "seed", "controller_rate_hz", "parameters", "changes", "end", "lidar",
                 "metrics")
REQUIRED_KEYS = ("world", "duration_s", "metrics")
SUITE_KEYS = ("name", "description", "defaults", "scenarios")
"""``defaults`` is not read: it holds what scenarios written inline share, with a YAML anchor
(``defaults: &defaults``) that each merges (``<<: *defaults``)."""
SUITE_ENTRY_KEYS = ("file", "scenario", "weight", "visibility")
VISIBILITIES = ("visible", "hidden", "after_due_date", "after_published")
"""A suite entry's ``visibility``: when a student sees its result on Gradescope (its test's
``visibility``; ``websim grade`` prints every result to the instructor)."""
CHANGE_KEYS = ("at_s", "payload", "mode", "parameters")
PAYLOAD_KEYS = ("scale", "mass_kg", "inertia_kg_m2")
END_KEYS = ("point", "radius_m")
METRIC_KEYS = ("kind", "name", "weight")
"""The keys of a metric's entry besides its parameters."""

MAX_DURATION_S = 3600.0
"""Longest run (s of sim time): an hour is far beyond any assignment."""

MAX_PARAMETERS = 32
MAX_CHANGES = 100
MAX_METRICS = 16
MAX_SUITE_SCENARIOS = 64
MAX_TEXT_CHARS = 2000
"""Bounds on what a file may list: a scenario is a page, a suite a course's worth."""

DEFAULT_CONTROLLER_RATE_HZ = 1.0 / CONTROL_PERIOD_S
"""The course's controllers run at 10 Hz."""

ENV_PREFIX = "WEBSIM_"
"""A parameter ``name`` reaches the controller as the environment variable WEBSIM_NAME."""

CHANGES_SUFFIX = "_changes"
"""A parameter that changes during the run is also told as WEBSIM_NAME_CHANGES, e.g.
``5.0:0.0`` (at 5 s it becomes 0.0), changes separated by commas."""

PARAMETER_NAME = re.compile(r"[a-z][a-z0-9_]{0,47}\Z")
"""A parameter's name: lower case, digits and underscores (its variable is upper case)."""

PARAMETER_WORD = re.compile(r"[A-Za-z0-9_.+-]{1,64}\Z")
"""A text parameter's value: one word (``left``), safe in any shell and in a changes list."""

ParameterValue = float | int | str
"""A parameter is a number or a word."""

_SCENARIO_FACTS_NEEDED = {
    "setpoints": "the parameter 'setpoint_rad'",
    "end_x_m": "the scenario's 'end'",
    "end_y_m": "the scenario's 'end'",
    "end_radius_m": "the scenario's 'end'",
}
"""What a scenario must have for a metric that reads one of its facts."""


@dataclass(frozen=True)
class Payload:
    """The robot's mass and inertia in force (a payload changes both).

    Attributes:
        mass_kg: mass (kg).
        inertia_kg_m2: yaw moment of inertia (kg m^2).
    """

    mass_kg: float
    inertia_kg_m2: float


@dataclass(frozen=True)
class TimedChange:
    """What changes at a set time of the run.

    Attributes:
        at_s: when, from the start (s, sim time).
        payload: the new mass and inertia, or None.
        mode: the new motion model, or None.
        parameters: parameters that take new values, as (name, value) pairs.
        origin: where the file says so (``file:LINE``).
    """

    at_s: float
    payload: Payload | None
    mode: str | None
    parameters: tuple[tuple[str, ParameterValue], ...]
    origin: str


@dataclass(frozen=True)
class EndPoint:
    """Where the run ends: the first sample within ``radius_m`` of (x, y).

    Attributes:
        x_m: x in the map frame (m).
        y_m: y in the map frame (m).
        radius_m: how close (m).
    """

    x_m: float
    y_m: float
    radius_m: float


@dataclass(frozen=True)
class MetricSpec:
    """One metric of a scenario.

    Attributes:
        name: its name in the report (its kind unless the file names it).
        kind: which metric (a key of ``grading.metrics.METRICS``).
        weight: its weight in the scenario's score (>= 0).
        params: its parameters (the kind's dataclass).
        origin: where the file declares it (``file:LINE``).
    """

    name: str
    kind: str
    weight: float
    params: Any
    origin: str


@dataclass(frozen=True)
class Scenario:
    """One graded run.

    Attributes:
        name: its name (in a suite, unique).
        description: what it tests, for the report.
        source: the file it was read from (a suite's, for one written inline).
        world: the world, its ``start`` the scenario's start pose and its ``lidar`` the
            world's LiDAR settings with the scenario's over them (``Scenario.lidar``).
        mode: the motion model at the start (``kinematic`` or ``dynamic``).
        robot: the robot's parameters at the start (the payload applied).
        duration_s: the run's length and timeout (s of sim time).
        seed: the simulation's seed.
        controller_rate_hz: how often the controller is asked for a command (Hz); its
            period is a whole number of simulation ticks.
        parameters: what the controller is told, as (name, value) pairs.
        changes: what changes during the run, in time order.
        end: where the run ends early, or None (it lasts ``duration_s``).
        metrics: how it is scored.
    """

    name: str
    description: str
    source: str
    world: World
    mode: str
    robot: RobotParams
    duration_s: float
    seed: int
    controller_rate_hz: float
    parameters: tuple[tuple[str, ParameterValue], ...]
    changes: tuple[TimedChange, ...]
    end: EndPoint | None
    metrics: tuple[MetricSpec, ...]

    @property
    def start(self) -> Pose2D:
        """The start pose in the map frame (m, rad)."""
        return self.world.start

    @property
    def lidar(self) -> LidarParams:
        """The LiDAR of the run: the shipped one with the world's and the scenario's values."""
        return self.world.lidar_over(LidarParams())

    @property
    def controller_period_ticks(self) -> int:
        """Simulation ticks between two calls of the controller."""
        return round(1.0 / (self.controller_rate_hz * TICK_PERIOD_S))

    def parameters_at(self, t_s: float) -> dict[str, ParameterValue]:
        """The parameters in force at ``t_s`` (s): the initial ones, then each change's."""
        values = dict(self.parameters)
        for change in self.changes:
            if change.at_s <= t_s:
                values.update(change.parameters)
        return values


@dataclass(frozen=True)
class SuiteEntry:
    """A scenario of a suite, its weight in the suite's total and who sees its result."""

    scenario: Scenario
    weight: float
    visibility: str = "visible"


@dataclass(frozen=True)
class Suite:
    """Scenarios graded together (a single scenario file is a suite of one).

    Attributes:
        name: its name.
        description: what it grades.
        source: its file.
        entries: its scenarios with their weights, in the file's order.
    """

    name: str
    description: str
    source: str
    entries: tuple[SuiteEntry, ...]


def resolve_scenario_path(name_or_path: str | Path) -> Path:
    """The file for a path, or for the name of a shipped scenario (``"heading_pid"``)."""
    return by_name(name_or_path, SCENARIOS_DIR)


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario file (or a shipped scenario by name).

    Raises:
        ConfigError: the file, its world or an entry is invalid; the message names the file,
            the line and the entry.
    """
    resolved = resolve_scenario_path(path)
    source = str(path) if resolved == Path(path) else str(resolved)
    document = load_yaml_file(resolved, "scenario")
    return scenario_from_document(document, source=source, folder=resolved.parent,
                                  default_name=resolved.stem)


def load_suite(path: str | Path) -> Suite:
    """Read a suite file, or a scenario file as a suite of one (or a shipped one by name).

    Raises:
        ConfigError: as ``load_scenario``, for the suite and every scenario it lists.
    """
    resolved = resolve_scenario_path(path)
    source = str(path) if resolved == Path(path) else str(resolved)
    document = load_yaml_file(resolved, "scenario or suite")
    if not (isinstance(document, Mapping) and "scenarios" in document):
        scenario = scenario_from_document(document, source=source, folder=resolved.parent,
                                          default_name=resolved.stem)
        return Suite(scenario.name, scenario.description, source,
                     (SuiteEntry(scenario, 1.0),))
    top = as_mapping(source, document)
    check_keys(source, top, SUITE_KEYS, key_where=_keys_at(source, top, ""))
    entries_list = top["scenarios"]
    where = located(source, top, "scenarios", "scenarios")
    if not isinstance(entries_list, list) or not entries_list:
        raise fail(where, f"expected a list of scenarios, got {shown(entries_list)}")
    if len(entries_list) > MAX_SUITE_SCENARIOS:
        raise fail(where, f"{len(entries_list)} scenarios; at most {MAX_SUITE_SCENARIOS}")
    entries: list[SuiteEntry] = []
    names: dict[str, str] = {}
    for index, item in enumerate(entries_list):
        entry_name = f"scenarios[{index}]"
        here = located(source, entries_list, index, entry_name)
        entry = as_mapping(here, item)
        check_keys(here, entry, SUITE_ENTRY_KEYS,
                   key_where=_keys_at(source, entry, entry_name))
        weight = as_non_negative_float(located(source, entry, "weight", f"{entry_name}.weight"),
                                       entry.get("weight", 1.0))
        if ("file" in entry) == ("scenario" in entry):
            raise fail(here, "give either 'file' (a scenario file) or 'scenario' (one "
                             "written here)")
        if "file" in entry:
            scenario = _scenario_from_suite_file(source, resolved.parent, entry, entry_name)
        else:
            scenario = scenario_from_document(
                entry["scenario"], source=source, folder=resolved.parent, default_name=None,
                where_prefix=f"{entry_name}.scenario.")
        if scenario.name in names:
            raise fail(here, f"a second scenario named '{scenario.name}' (the first is "
                             f"{names[scenario.name]}); give each a name of its own")
        names[scenario.name] = entry_name
        visibility = entry.get("visibility", "visible")
        if visibility not in VISIBILITIES:
            raise fail(located(source, entry, "visibility", f"{entry_name}.visibility"),
                       f"expected one of {', '.join(VISIBILITIES)}, got {visibility!r:.40}")
        entries.append(SuiteEntry(scenario, weight, visibility))
    if sum(entry.weight for entry in entries) <= 0.0:
        raise fail(where, "every weight is 0: give at least one scenario a weight > 0")
    name = _text(source, top, "name", resolved.stem)
    return Suite(name, _text(source, top, "description", ""), source, tuple(entries))


def _scenario_from_suite_file(source: str, folder: Path, entry: Mapping[str, Any],
                              entry_name: str) -> Scenario:
    where = located(source, entry, "file", f"{entry_name}.file")
    reference = entry["file"]
    if not isinstance(reference, str) or not reference:
        raise fail(where, f"expected a file name, got {shown(reference)}")
    path = Path(reference)
    if not path.is_absolute() and (path.suffix or len(path.parts) > 1):
        path = folder / path
    try:
        return load_scenario(path)
    except ConfigError as error:
        raise ConfigError(f"{where}: {error}") from None


def scenario_from_document(document: Any, *, source: str, folder: Path,
                           default_name: str | None, where_prefix: str = "") -> Scenario:
    """Check a parsed scenario (from ``load_yaml_file``) and build a ``Scenario``.

    Args:
        document: the scenario's mapping.
        source: the file it came from, for errors.
        folder: where a world's relative path starts.
        default_name: its name if it gives none (None: it must give one).
        where_prefix: its entry in the file (``"scenarios[2].scenario."``), for errors.
    """
    def at(container: Any, key: Any, entry: str) -> str:
        return located(source, container, key, where_prefix + entry)

    top = as_mapping(located(source, document, None, where_prefix.rstrip(".") or "scenario"),
                     document)
    check_keys(source, top, SCENARIO_KEYS,
               key_where=_keys_at(source, top, where_prefix.rstrip(".")))
    for required in REQUIRED_KEYS:
        if required not in top:
            raise fail(at(top, None, required), f"missing; a scenario needs "
                                                f"{', '.join(REQUIRED_KEYS)}")
    if default_name is None and "name" not in top:
        raise fail(at(top, None, "name"), "missing; a scenario written in a suite needs a name")
    name = _text(source, top, "name", default_name or "", where_prefix)
    if not name:
        raise fail(at(top, "name", "name"), "must not be empty")
    world = _world(at(top, "world", "world"), top["world"], folder)
    duration_s = as_positive_float(at(top, "duration_s", "duration_s"), top["duration_s"])
    if duration_s > MAX_DURATION_S:
        raise fail(at(top, "duration_s", "duration_s"),
                   f"must be at most {MAX_DURATION_S:g} s, got {duration_s:g}")
    mode = _mode(at(top, "mode", "mode"), top.get("mode", MODES[0]))
    base = RobotParams()
    payload = _payload(source, top, "payload", where_prefix, base) if "payload" in top else None
    robot = base if payload is None else dataclasses.replace(
        base, mass_kg=payload.mass_kg, inertia_kg_m2=payload.inertia_kg_m2)
    start = _start(at(top, "start", "start"), top.get("start", list(world.start)), world,
                   robot.footprint_radius_m)
    seed = top.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2 ** 63:
        raise fail(at(top, "seed", "seed"), f"expected a whole number from 0 to 2**63 - 1, "
                                            f"got {shown(seed)}")
    rate = _controller_rate(at(top, "controller_rate_hz", "controller_rate_hz"),
                            top.get("controller_rate_hz", DEFAULT_CONTROLLER_RATE_HZ))
    parameters = _parameters(source, top, where_prefix)
    changes = _changes(source, top, where_prefix, duration_s, dict(parameters), base)
    end = _end(source, top, where_prefix) if "end" in top else None
    if end is not None and math.hypot(start.x - end.x_m, start.y - end.y_m) <= end.radius_m:
        raise fail(located(source, top, "end", where_prefix + "end"),
                   f"the start {list(start)} is already within {end.radius_m:g} m of the end "
                   f"point ({end.x_m:g}, {end.y_m:g}): the run would end at once")
    lidar = dict(world.lidar)
    lidar.update(lidar_overrides(at(top, "lidar", "lidar"), top.get("lidar")))
    facts = _facts(robot, duration_s, parameters, changes, end)
    metrics = _metrics(source, top, where_prefix, dict(parameters), facts)
    return Scenario(
        name=name, description=_text(source, top, "description", "", where_prefix),
        source=source, world=dataclasses.replace(world, start=start,
                                                 lidar=tuple(lidar.items())),
        mode=mode, robot=robot,
        duration_s=duration_s, seed=seed, controller_rate_hz=rate,
        parameters=tuple(parameters), changes=changes, end=end, metrics=metrics)


def controller_environment(scenario: Scenario) -> dict[str, str]:
    """The environment variables that tell the controller the scenario's parameters.

    ``WEBSIM_<NAME>`` for each parameter (numbers as Python writes them, so they read back
    exactly: ``1.5707963267948966``), and ``WEBSIM_<NAME>_CHANGES`` (``at_s:value`` pairs
    separated by commas) for a parameter that changes during the run.
    """
    environment = {ENV_PREFIX + name.upper(): _formatted(value)
                   for name, value in scenario.parameters}
    timeline: dict[str, list[str]] = {}
    for change in scenario.changes:
        for name, value in change.parameters:
            timeline.setdefault(name, []).append(f"{change.at_s!r}:{_formatted(value)}")
    for name, entries in timeline.items():
        environment[ENV_PREFIX + (name + CHANGES_SUFFIX).upper()] = ",".join(entries)
    return environment


def _keys_at(source: str, container: Any, entry: str) -> Callable[[Any], str]:
    """Where each key of ``container`` (the entry ``entry`` of the file) is: for check_keys."""
    def where(key: Any) -> str:
        return located(source, container, key, f"{entry}.{key}" if entry else str(key))
    return where


def _origin(source: str, container: Any, key: Any) -> str:
    """``file:LINE`` of an entry (``file`` when its line is unknown)."""
    line = line_of(container, key)
    return source if line is None else f"{source}:{line}"


def _formatted(value: ParameterValue) -> str:
    return repr(value) if isinstance(value, float) else str(value)


def _text(source: str, top: Mapping[str, Any], key: str, default: str,
          where_prefix: str = "") -> str:
    value = top.get(key, default)
    if not isinstance(value, str) or len(value) > MAX_TEXT_CHARS:
        raise fail(located(source, top, key, where_prefix + key),
                   f"expected text of at most {MAX_TEXT_CHARS} characters, got {shown(value)}")
    return value


def _world(where: str, reference: Any, folder: Path) -> World:
    if not isinstance(reference, str) or not reference:
        raise fail(where, f"expected a shipped world's name or a file, got {shown(reference)}")
    path = Path(reference)
    if not path.suffix and len(path.parts) == 1:
        resolved = WORLDS_DIR / f"{reference}.yaml"
        if not resolved.is_file():
            known = ", ".join(sorted(p.stem for p in WORLDS_DIR.glob("*.yaml")))
            raise fail(where, f"no shipped world '{reference}'"
                              f"{did_you_mean(reference, known.split(', '))} "
                              f"(shipped worlds: {known}; or give a file)")
    else:
        resolved = path if path.is_absolute() else folder / path
    try:
        return load_world(resolved)
    except ConfigError as error:
        raise ConfigError(f"{where}: {error}") from None


def _mode(where: str, mode: Any) -> str:
    if mode not in MODES:
        raise fail(where, f"must be one of {', '.join(MODES)}, got {shown(mode)}"
                          f"{did_you_mean(mode, MODES)}")
    return str(mode)


def _payload(source: str, container: Any, key: str, where_prefix: str,
             base: RobotParams) -> Payload:
    """A payload: ``{scale: k}`` (k times the robot's mass and inertia) or absolute values."""
    where = located(source, container, key, where_prefix + key)
    entry = as_mapping(where, container[key])
    check_keys(where, entry, PAYLOAD_KEYS, key_where=_keys_at(source, entry, where_prefix + key))
    if not entry:
        raise fail(where, "give 'scale' or 'mass_kg' and/or 'inertia_kg_m2'")
    if "scale" in entry:
        if len(entry) > 1:
            raise fail(where, "give either 'scale' or 'mass_kg' / 'inertia_kg_m2', not both")
        scale = as_positive_float(located(source, entry, "scale", f"{where_prefix}{key}.scale"),
                                  entry["scale"])
        values = {"mass_kg": base.mass_kg * scale, "inertia_kg_m2": base.inertia_kg_m2 * scale}
    else:
        values = {name: entry.get(name, getattr(base, name))
                  for name in ("mass_kg", "inertia_kg_m2")}
    for name, value in values.items():
        try:
            dataclasses.replace(base, **{name: value})
        except ConfigError as error:
            raise ConfigError(f"{located(source, entry, name, f'{where_prefix}{key}')}: "
                              f"{error}") from None
    return Payload(float(values["mass_kg"]), float(values["inertia_kg_m2"]))


def _start(where: str, value: Any, world: World, radius_m: float) -> Pose2D:
    start = Pose2D(*as_number_list(where, value, 3))
    distance, index = nearest_obstacles(world_shapes(world), np.array([start[:2]]))
    if distance[0] < radius_m:
        wall = obstacle_origins(world)[int(index[0])]
        raise fail(where, f"{list(start)} puts the robot footprint (radius {radius_m:g} m) "
                          f"{distance[0]:.3f} m from {wall} of {world.source}; it needs "
                          f"{radius_m:g} m of clearance")
    return start


def _controller_rate(where: str, value: Any) -> float:
    rate = as_positive_float(where, value)
    ticks = 1.0 / (rate * TICK_PERIOD_S)
    if round(ticks) < 1 or abs(ticks - round(ticks)) > 1e-9:
        rates = ", ".join(f"{1.0 / (n * TICK_PERIOD_S):g}" for n in (1, 2, 4, 5, 10, 20))
        raise fail(where, f"{rate:g} Hz is not a whole number of {TICK_PERIOD_S:g} s "
                          f"simulation ticks per call; e.g. {rates} Hz")
    return rate


def _parameter_value(where: str, value: Any) -> ParameterValue:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise fail(where, f"expected a number or a word, got {shown(value)}")
    if isinstance(value, str):
        if not PARAMETER_WORD.match(value):
            raise fail(where, f"a text value is one word of letters, digits and _ . + - "
                              f"(at most 64), got {shown(value)}")
        return value
    if isinstance(value, float):
        return as_finite_float(where, value)
    as_finite_float(where, value)  # an integer beyond float range is refused
    return value


def _parameters(source: str, top: Mapping[str, Any],
                where_prefix: str) -> list[tuple[str, ParameterValue]]:
    if "parameters" not in top or top["parameters"] is None:
        return []
    where = located(source, top, "parameters", where_prefix + "parameters")
    mapping = as_mapping(where, top["parameters"])
    if len(mapping) > MAX_PARAMETERS:
        raise fail(where, f"{len(mapping)} parameters; at most {MAX_PARAMETERS}")
    parameters = []
    for name, value in mapping.items():
        here = located(source, mapping, name, f"{where_prefix}parameters.{name}")
        if not isinstance(name, str) or not PARAMETER_NAME.match(name):
            raise fail(here, f"a parameter's name is lower case letters, digits and _, "
                             f"starting with a letter (at most 48), got {shown(name)}")
        if name.endswith(CHANGES_SUFFIX):
            raise fail(here, f"a name may not end in '{CHANGES_SUFFIX}': WEBSIM_NAME"
                             f"{CHANGES_SUFFIX.upper()} tells a parameter's changes")
        parameters.append((name, _parameter_value(here, value)))
    return parameters


def _changes(source: str, top: Mapping[str, Any], where_prefix: str, duration_s: float,
             parameters: dict[str, ParameterValue],
             base: RobotParams) -> tuple[TimedChange, ...]:
    if "changes" not in top or top["changes"] is None:
        return ()
    where = located(source, top, "changes", where_prefix + "changes")
    items = top["changes"]
    if not isinstance(items, list):
        raise fail(where, f"expected a list, got {type_name(items)} {shown(items)}")
    if len(items) > MAX_CHANGES:
        raise fail(where, f"{len(items)} changes; at most {MAX_CHANGES}")
    changes: list[TimedChange] = []
    for index, item in enumerate(items):
        name = f"{where_prefix}changes[{index}]"
        here = located(source, items, index, name)
        entry = as_mapping(here, item)
        check_keys(here, entry, CHANGE_KEYS,
                   key_where=_keys_at(source, entry, name))
        if "at_s" not in entry:
            raise fail(here, "missing 'at_s': when the change happens (s)")
        at_where = located(source, entry, "at_s", f"{name}.at_s")
        at_s = as_non_negative_float(at_where, entry["at_s"])
        if at_s >= duration_s:
            raise fail(at_where, f"{at_s:g} s is not within the run's {duration_s:g} s")
        if changes and at_s < changes[-1].at_s:
            raise fail(at_where, f"{at_s:g} s comes before the change above it "
                                 f"({changes[-1].at_s:g} s): list changes in time order")
        payload = _payload(source, entry, "payload", f"{name}.", base) \
            if "payload" in entry else None
        mode = _mode(located(source, entry, "mode", f"{name}.mode"), entry["mode"]) \
            if "mode" in entry else None
        changed = _changed_parameters(source, entry, name, parameters)
        if payload is None and mode is None and not changed:
            raise fail(here, "changes nothing: give a payload, a mode or parameters")
        changes.append(TimedChange(at_s, payload, mode, changed, _origin(source, items, index)))
    return tuple(changes)


def _changed_parameters(source: str, entry: Mapping[str, Any], name: str,
                        parameters: dict[str, ParameterValue]
                        ) -> tuple[tuple[str, ParameterValue], ...]:
    if "parameters" not in entry:
        return ()
    where = located(source, entry, "parameters", f"{name}.parameters")
    mapping = as_mapping(where, entry["parameters"])
    changed = []
    for key, value in mapping.items():
        here = located(source, mapping, key, f"{name}.parameters.{key}")
        if key not in parameters:
            raise fail(here, f"unknown parameter '{key}'{did_you_mean(key, parameters)} (a "
                             f"change sets only what the scenario's 'parameters' declare)")
        new = _parameter_value(here, value)
        if isinstance(new, str) != isinstance(parameters[key], str):
            kind = "a word" if isinstance(parameters[key], str) else "a number"
            raise fail(here, f"'{key}' is {kind} (see 'parameters'), got {shown(value)}")
        changed.append((str(key), new))
    return tuple(changed)


def _end(source: str, top: Mapping[str, Any], where_prefix: str) -> EndPoint:
    where = located(source, top, "end", where_prefix + "end")
    entry = as_mapping(where, top["end"])
    check_keys(where, entry, END_KEYS,
               key_where=_keys_at(source, entry, where_prefix + "end"))
    if "point" not in entry:
        raise fail(where, "missing 'point': [x, y] in the map frame (m)")
    x, y = as_number_list(located(source, entry, "point", f"{where_prefix}end.point"),
                          entry["point"], 2)
    radius = as_positive_float(located(source, entry, "radius_m", f"{where_prefix}end.radius_m"),
                               entry.get("radius_m", MIT_END_RADIUS_M))
    return EndPoint(x, y, radius)


def _facts(robot: RobotParams, duration_s: float,
           parameters: list[tuple[str, ParameterValue]], changes: tuple[TimedChange, ...],
           end: EndPoint | None) -> dict[str, Any]:
    """The scenario's facts a metric may read (``param(from_scenario=...)``)."""
    facts: dict[str, Any] = {"footprint_radius_m": robot.footprint_radius_m,
                             "max_linear_mps": robot.max_linear_mps,
                             "max_angular_rps": robot.max_angular_rps,
                             "duration_s": duration_s}
    values = dict(parameters)
    if "setpoint_rad" in values and not isinstance(values["setpoint_rad"], str):
        facts["setpoints"] = setpoint_schedule(
            float(values["setpoint_rad"]),
            [(change.at_s, float(value)) for change in changes
             for key, value in change.parameters if key == "setpoint_rad"])
    if end is not None:
        facts.update(end_x_m=end.x_m, end_y_m=end.y_m, end_radius_m=end.radius_m)
    return facts


def _metrics(source: str, top: Mapping[str, Any], where_prefix: str,
             parameters: dict[str, ParameterValue],
             facts: dict[str, Any]) -> tuple[MetricSpec, ...]:
    where = located(source, top, "metrics", where_prefix + "metrics")
    items = top["metrics"]
    if not isinstance(items, list) or not items:
        raise fail(where, f"expected a list of one or more metrics, got {shown(items)}")
    if len(items) > MAX_METRICS:
        raise fail(where, f"{len(items)} metrics; at most {MAX_METRICS}")
    specs: list[MetricSpec] = []
    for index, item in enumerate(items):
        name = f"{where_prefix}metrics[{index}]"
        here = located(source, items, index, name)
        metric = _metric(source, here, name, as_mapping(here, item), parameters, facts,
                         top.get("parameters"), where_prefix)
        specs.append(dataclasses.replace(metric, origin=_origin(source, items, index)))
    names = [spec.name for spec in specs]
    for spec in specs:
        if names.count(spec.name) > 1:
            raise fail(spec.origin, f"two metrics named '{spec.name}': give each a 'name'")
    if not any(spec.weight > 0.0 for spec in specs):
        raise fail(where, "every metric has weight 0: give at least one a weight > 0")
    return tuple(specs)


def _metric(source: str, here: str, name: str, entry: Mapping[str, Any],
            parameters: dict[str, ParameterValue], facts: dict[str, Any],
            parameters_node: Any, where_prefix: str) -> MetricSpec:
    if "kind" not in entry:
        raise fail(here, f"missing 'kind': one of {', '.join(METRICS)}")
    kind_name = entry["kind"]
    if kind_name not in METRICS:
        raise fail(located(source, entry, "kind", f"{name}.kind"),
                   f"unknown metric '{kind_name}'{did_you_mean(kind_name, METRICS)} "
                   f"(metrics: {', '.join(METRICS)})")
    kind = METRICS[kind_name]
    fields = dataclasses.fields(kind.params_type)
    settable = [field.name for field in fields if field.metadata["check"] is not None]
    check_keys(here, entry, (*METRIC_KEYS, *settable),
               key_where=_keys_at(source, entry, name))
    values: dict[str, Any] = {}
    for field in fields:
        meta = field.metadata
        key_where = located(source, entry, field.name, f"{name}.{field.name}")
        if meta["from_scenario"] is not None:
            if meta["from_scenario"] in facts:
                values[field.name] = facts[meta["from_scenario"]]
            elif field.default is dataclasses.MISSING:
                needed = _SCENARIO_FACTS_NEEDED.get(meta["from_scenario"],
                                                    f"'{meta['from_scenario']}'")
                raise fail(here, f"{kind_name} needs {needed}")
        elif field.name in entry:
            values[field.name] = meta["check"](key_where, entry[field.name])
        elif meta["from_parameter"] and field.name in parameters:
            values[field.name] = meta["check"](located(
                source, parameters_node, field.name,
                f"{where_prefix}parameters.{field.name} (read by {name})"),
                parameters[field.name])
        elif field.default is dataclasses.MISSING:
            also = " or in the scenario's parameters" if meta["from_parameter"] else ""
            raise fail(here, f"{kind_name} needs '{field.name}': give it in this "
                             f"metric{also}")
    try:
        params = kind.params_type(**values)
    except (ConfigError, ValueError) as error:
        raise fail(here, str(error)) from None
    metric_name = entry.get("name", kind_name)
    if not isinstance(metric_name, str) or not PARAMETER_NAME.match(metric_name):
        raise fail(located(source, entry, "name", f"{name}.name"),
                   f"a metric's name is lower case letters, digits and _, got {shown(metric_name)}")
    weight = as_non_negative_float(located(source, entry, "weight", f"{name}.weight"),
                                   entry.get("weight", kind.default_weight))
    if math.isinf(weight):
        raise fail(located(source, entry, "weight", f"{name}.weight"), "must be finite")
    return MetricSpec(metric_name, kind_name, weight, params, here)
