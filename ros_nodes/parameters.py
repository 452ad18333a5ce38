"""The virtual robot's runtime parameters, in the shapes of ROS 2's ``rcl_interfaces``.

The admin page, ``ros2 param`` and rosapi all read and write the same table, so a change made
one way is seen the others. Values are validated by the simulation itself: a bad value is
refused with a reason and changes nothing.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from physics import MODES, ConfigError, NoiseParams, RobotParams, Simulation
from physics.params import field_range, field_unit
from physics.validation import as_finite_float, as_float_in_range, shown
from physics.world import LOCALIZATIONS
from rosbridge.msgs.values import Base64Bytes, Message

# rcl_interfaces/msg/ParameterType
PARAMETER_NOT_SET = 0
PARAMETER_BOOL = 1
PARAMETER_INTEGER = 2
PARAMETER_DOUBLE = 3
PARAMETER_STRING = 4
PARAMETER_BYTE_ARRAY = 5
PARAMETER_BOOL_ARRAY = 6
PARAMETER_INTEGER_ARRAY = 7
PARAMETER_DOUBLE_ARRAY = 8
PARAMETER_STRING_ARRAY = 9

_VALUE_FIELDS = {
    PARAMETER_BOOL: "bool_value", PARAMETER_INTEGER: "integer_value",
    PARAMETER_DOUBLE: "double_value", PARAMETER_STRING: "string_value",
    PARAMETER_BYTE_ARRAY: "byte_array_value", PARAMETER_BOOL_ARRAY: "bool_array_value",
    PARAMETER_INTEGER_ARRAY: "integer_array_value",
    PARAMETER_DOUBLE_ARRAY: "double_array_value",
    PARAMETER_STRING_ARRAY: "string_array_value",
}


ADMIN = "admin"
"""``ParameterSpec.set_by``: changes at runtime, by admin clients (the token), ``ros2 param``."""

AT_START = "start"
"""``ParameterSpec.set_by``: read when the robot starts (a file, ``-p name:=value``); read-only
afterwards."""


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter of the virtual robot: the one definition every transport derives from.

    The embedded bridge's parameter services and rosapi, the rclpy node's ``declare_parameter``
    and its validation, the admin page (through ``robot.json``) and the README's table all read
    these fields.

    Attributes:
        name: the ROS parameter name.
        type_code: its ``rcl_interfaces/msg/ParameterType``.
        description: what it does.
        unit: SI unit, ``""`` when it has none.
        default: the value a new robot starts with (robot and noise values come from
            ``config/pi4b_params.yaml``).
        minimum: smallest accepted value (numbers); None for strings and booleans.
        maximum: largest accepted value (numbers); None for strings and booleans.
        choices: the accepted values of a string parameter; empty: any string.
        set_by: ``ADMIN`` (runtime: admin clients, ``ros2 param set``) or ``AT_START``.
        embedded: whether the embedded bridge serves it (False: the rclpy node only).
    """

    name: str
    type_code: int
    description: str
    unit: str
    default: Any
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[str, ...] = ()
    set_by: str = ADMIN
    embedded: bool = True

    @property
    def runtime(self) -> bool:
        """Whether the parameter changes while the robot runs."""
        return self.set_by == ADMIN

    def validate(self, value: Any) -> Any:
        """``value`` as this parameter holds it (integers become doubles for DOUBLE ones).

        Raises:
            ConfigError: wrong type, outside the range or not one of the choices.
        """
        if self.type_code == PARAMETER_DOUBLE:
            number = _double(self.name, value)
            assert self.minimum is not None and self.maximum is not None
            return as_float_in_range(self.name, number, self.minimum, self.maximum)
        if self.type_code == PARAMETER_INTEGER:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"{self.name}: expected an integer, got "
                                  f"{type(value).__name__} {shorten_value(value)}")
            assert self.minimum is not None and self.maximum is not None
            if not self.minimum <= value <= self.maximum:
                raise ConfigError(f"{self.name}: must be between {self.minimum:g} and "
                                  f"{self.maximum:g}, got {shorten_value(value)}")
            return value
        if self.type_code == PARAMETER_BOOL:
            if not isinstance(value, bool):
                raise ConfigError(f"{self.name}: expected true or false, got "
                                  f"{shorten_value(value)}")
            return value
        if not isinstance(value, str):
            raise ConfigError(f"{self.name}: expected a string, got {type(value).__name__} "
                              f"{shorten_value(value)}")
        if self.choices and value not in self.choices:
            raise ConfigError(f"{self.name}: must be one of {', '.join(self.choices)}, "
                              f"got {shorten_value(value)}")
        return value

    def range_text(self) -> str:
        """The accepted values, for docs and errors: ``0.01 to 1000``, ``kinematic, dynamic``."""
        if self.choices:
            return ", ".join(self.choices)
        if self.type_code == PARAMETER_INTEGER:
            return f"{self.minimum:.0f} to {self.maximum:.0f}"
        if self.minimum is not None and self.maximum is not None:
            return f"{self.minimum:g} to {self.maximum:g}"
        return "true, false" if self.type_code == PARAMETER_BOOL else "any"


def shorten_value(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters: values may be megabytes of input."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 200:
        return f"an integer of {len(str(abs(value)))} digits"
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def _robot(name: str, description: str) -> ParameterSpec:
    """A runtime parameter that is a field of ``RobotParams``: range, unit and default there."""
    low, high = field_range(RobotParams, name)
    return ParameterSpec(name, PARAMETER_DOUBLE, description, field_unit(RobotParams, name),
                         getattr(RobotParams(), name), low, high)


def _noise(name: str, description: str) -> ParameterSpec:
    """A start-time noise sigma, a field of ``NoiseParams``."""
    low, high = field_range(NoiseParams, name)
    return ParameterSpec(name, PARAMETER_DOUBLE, description, field_unit(NoiseParams, name),
                         getattr(NoiseParams(), name), low, high, set_by=AT_START)


CMD_VEL_TIMEOUT_OFF_S = 0.0
"""The course's behaviour: the robot keeps the last command however old it is."""

WORLD_LOCALIZATION = "world"
"""``localization``'s default: as the world file says (``none`` unless it says otherwise)."""

MAX_SEED = 2**32 - 1
"""Largest noise seed (numpy accepts any, ROS integers are 64-bit; 32 bits is plenty)."""

SCAN_RELIABILITIES = ("best_effort", "reliable")
"""``scan_reliability``: /scan's publisher as the topic table says (sensor data), or reliable
(``websim grade --ros`` offers it so: a reliable publisher serves both kinds of subscriber)."""

PARAMETERS = (
    ParameterSpec("mode", PARAMETER_STRING, "motion model", "", MODES[0], choices=MODES),
    _robot("mass_kg", "chassis mass; acts in dynamic mode"),
    _robot("inertia_kg_m2", "yaw moment of inertia; acts in dynamic mode"),
    _robot("max_linear_mps", "linear velocity limit; commands are clamped to it"),
    _robot("max_angular_rps", "angular velocity limit; commands are clamped to it"),
    _robot("max_wheel_force_n", "traction force limit per wheel; dynamic mode (very large "
                                "values approach the kinematic model)"),
    ParameterSpec("cmd_vel_timeout_s", PARAMETER_DOUBLE,
                  "stop when no /cmd_vel arrived for this long; 0 keeps the last command "
                  "(the course's behaviour)", "s", CMD_VEL_TIMEOUT_OFF_S, 0.0, 3600.0),
    ParameterSpec("world", PARAMETER_STRING,
                  "world file, or a shipped world's name (empty, maze, corridor)", "", "empty",
                  set_by=AT_START),
    ParameterSpec("seed", PARAMETER_INTEGER, "seed of the noise generator", "", 0, 0, MAX_SEED,
                  set_by=AT_START),
    _noise("odom_linear_sigma_mps", "odometry noise on the linear speed, per tick"),
    _noise("odom_angular_sigma_rps", "odometry noise on the yaw rate, per tick"),
    _noise("scan_sigma_m", "noise on every LiDAR hit"),
    ParameterSpec("params_file", PARAMETER_STRING, "robot, LiDAR and noise parameter file "
                  "(YAML)", "", "config/pi4b_params.yaml", set_by=AT_START, embedded=False),
    ParameterSpec("localization", PARAMETER_STRING,
                  "who publishes map -> odom: none (a localizer: AMCL, slam_toolbox), perfect "
                  "(this node, from the ground truth) or world (as the world file says)", "",
                  WORLD_LOCALIZATION, choices=(WORLD_LOCALIZATION, *LOCALIZATIONS),
                  set_by=AT_START, embedded=False),
    ParameterSpec("cmd_vel_stamped", PARAMETER_BOOL,
                  "subscribe /cmd_vel as geometry_msgs/TwistStamped (as Jazzy's navigation "
                  "stack publishes) instead of Twist", "", False, set_by=AT_START,
                  embedded=False),
    ParameterSpec("scan_reliability", PARAMETER_STRING,
                  "what /scan's publisher offers: best_effort (sensor data, as lidar drivers "
                  "publish) or reliable, which best-effort and reliable subscribers both "
                  "receive (a RELIABLE subscriber gets nothing from a best-effort publisher)",
                  "", SCAN_RELIABILITIES[0], choices=SCAN_RELIABILITIES, set_by=AT_START,
                  embedded=False),
)
"""Every parameter of the virtual robot, in the order services list them."""

RUNTIME_PARAMETERS = tuple(spec for spec in PARAMETERS if spec.runtime)
"""The parameters that change while the robot runs."""

EMBEDDED_PARAMETERS = tuple(spec for spec in PARAMETERS if spec.embedded)
"""The parameters the embedded bridge serves (runtime ones settable, start ones read-only)."""

_BY_NAME = {spec.name: spec for spec in PARAMETERS}


def parameter_spec(name: str) -> ParameterSpec:
    """The spec of ``name``; KeyError if there is none."""
    return _BY_NAME[name]


def markdown_table() -> str:
    """The README's parameter table, made from ``PARAMETERS``."""
    rows = ["| name | type | default | range | unit | set | meaning |",
            "|---|---|---|---|---|---|---|"]
    for spec in PARAMETERS:
        kind = {PARAMETER_DOUBLE: "double", PARAMETER_INTEGER: "integer",
                PARAMETER_STRING: "string", PARAMETER_BOOL: "bool"}[spec.type_code]
        when = "runtime (admin)" if spec.runtime else "at start"
        if not spec.embedded:
            when += ", node only"
        default = f"`{spec.default}`" if not isinstance(spec.default, float) \
            else f"`{spec.default:g}`"
        rows.append(f"| `{spec.name}` | {kind} | {default} | {spec.range_text()} | "
                    f"{spec.unit or '-'} | {when} | {spec.description} |")
    return "\n".join(rows)


def parameter_value_msg(value: Any) -> Message:
    """``rcl_interfaces/msg/ParameterValue`` holding a Python value (None -> NOT_SET)."""
    msg: Message = {"type": PARAMETER_NOT_SET, "bool_value": False, "integer_value": 0,
                    "double_value": 0.0, "string_value": "", "byte_array_value": Base64Bytes(""),
                    "bool_array_value": [], "integer_array_value": [],
                    "double_array_value": [], "string_array_value": []}
    if isinstance(value, bool):
        msg.update(type=PARAMETER_BOOL, bool_value=value)
    elif isinstance(value, int):
        msg.update(type=PARAMETER_INTEGER, integer_value=value)
    elif isinstance(value, float):
        msg.update(type=PARAMETER_DOUBLE, double_value=value)
    elif isinstance(value, str):
        msg.update(type=PARAMETER_STRING, string_value=value)
    elif value is not None:
        raise TypeError(f"no ParameterValue for {type(value).__name__}")
    return msg


def value_from_parameter_value(msg: Any) -> Any:
    """The Python value a ``ParameterValue`` dict holds, by its ``type`` code.

    Raises:
        ConfigError: not a ParameterValue, or an unknown type code.
    """
    if not isinstance(msg, Mapping):
        raise ConfigError(f"value: expected a ParameterValue object, got {shown(msg)}")
    type_code = msg.get("type")
    if type_code == PARAMETER_NOT_SET:
        return None
    if isinstance(type_code, bool) or type_code not in _VALUE_FIELDS:
        raise ConfigError(f"value.type: unknown ParameterType {shown(type_code)}")
    field = _VALUE_FIELDS[type_code]
    if field not in msg:
        raise ConfigError(f"value.{field}: missing for type {type_code}")
    return msg[field]


class RobotParameters:
    """Get, set and list the parameters of one simulation (``EMBEDDED_PARAMETERS``).

    Args:
        sim: the simulation whose parameters these are.

    Attributes:
        listeners: called, in order, with the names set after every successful change (the
            rclpy node mirrors changes made through the embedded bridge with one).
        cmd_vel_timeout_s: the command watchdog (s); 0 is off. Read by ``VirtualRobot``.
    """

    def __init__(self, sim: Simulation) -> None:
        self._sim = sim
        self.listeners: list[Callable[[list[str]], None]] = []
        self.cmd_vel_timeout_s = CMD_VEL_TIMEOUT_OFF_S

    @staticmethod
    def names() -> list[str]:
        """Every parameter name served, in order."""
        return [spec.name for spec in EMBEDDED_PARAMETERS]

    @staticmethod
    def spec(name: str) -> ParameterSpec:
        """The spec of ``name``; KeyError if there is none."""
        spec = _BY_NAME[name]
        if not spec.embedded:
            raise KeyError(name)
        return spec

    def get(self, name: str) -> Any:
        """The current value of ``name``; KeyError if unknown."""
        spec = self.spec(name)
        if spec.name == "mode":
            return self._sim.mode
        if spec.name == "cmd_vel_timeout_s":
            return self.cmd_vel_timeout_s
        if spec.name == "world":
            return self._sim.world.source
        if spec.name == "seed":
            return self._sim.seed if self._sim.seed is not None else 0
        if hasattr(self._sim.noise, name):
            return float(getattr(self._sim.noise, name))
        return float(getattr(self._sim.params, spec.name))

    def set(self, name: str, value: Any) -> None:
        """Set ``name`` to ``value`` now.

        Raises:
            ConfigError: unknown name, read-only, wrong type or invalid value; nothing
                changes.
        """
        self.set_many({name: value})

    def check(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Validate a change without making it; returns the values as they would be set.

        Raises:
            ConfigError: the first bad name or value, with the reason.
        """
        checked: dict[str, Any] = {}
        for name, value in values.items():
            spec = _BY_NAME.get(name) if isinstance(name, str) else None
            if spec is None or not spec.embedded:
                known = ", ".join(self.names())
                raise ConfigError(f"{str(name)[:60]}: no such parameter (known: {known})")
            if not spec.runtime:
                raise ConfigError(f"{name}: read-only (it is set when the robot starts)")
            checked[name] = spec.validate(value)
        robot_changes = {name: value for name, value in checked.items()
                         if hasattr(self._sim.params, name)}
        dataclasses.replace(self._sim.params, **robot_changes)  # the dataclass validates
        return checked

    def set_many(self, values: Mapping[str, Any]) -> None:
        """Set several parameters at once: all change, or (on any error) none do.

        Raises:
            ConfigError: the first bad name or value, with the reason.
        """
        checked = self.check(values)
        robot_changes = {name: value for name, value in checked.items()
                         if hasattr(self._sim.params, name)}
        previous = self._sim.params
        self._sim.update_params(**robot_changes)
        if "mode" in checked:
            try:
                self._sim.mode = checked["mode"]
            except ValueError:
                self._sim.update_params(**{n: getattr(previous, n) for n in robot_changes})
                raise
        if "cmd_vel_timeout_s" in checked:
            self.cmd_vel_timeout_s = checked["cmd_vel_timeout_s"]
        for listener in self.listeners:
            listener(list(values))


def _double(name: str, value: Any) -> float:
    """A DOUBLE parameter's value; integers are accepted (``ros2 param set mass_kg 2``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{name}: expected a number, got {type(value).__name__} "
                          f"{shorten_value(value)}")
    return as_finite_float(name, value)
