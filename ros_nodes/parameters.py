"""The virtual robot's runtime parameters, in the shapes of ROS 2's ``rcl_interfaces``.

The admin page, ``ros2 param`` and rosapi all read and write the same table, so a change made
one way is seen the others. Values are validated by the simulation itself: a bad value is
refused with a reason and changes nothing.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from physics import MODES, ConfigError, Simulation
from physics.validation import as_non_negative_float
from ros_nodes.messages import Message

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


@dataclass(frozen=True)
class ParameterSpec:
    """One runtime parameter.

    Attributes:
        name: the ROS parameter name.
        type_code: its ``rcl_interfaces/msg/ParameterType``.
        description: what it does, with units.
    """

    name: str
    type_code: int
    description: str


PARAMETERS = (
    ParameterSpec("mode", PARAMETER_STRING, "motion model: kinematic or dynamic"),
    ParameterSpec("mass_kg", PARAMETER_DOUBLE, "chassis mass (kg); acts in dynamic mode"),
    ParameterSpec("inertia_kg_m2", PARAMETER_DOUBLE,
                  "yaw moment of inertia (kg m^2); acts in dynamic mode"),
    ParameterSpec("max_linear_mps", PARAMETER_DOUBLE, "linear velocity limit (m/s)"),
    ParameterSpec("max_angular_rps", PARAMETER_DOUBLE, "angular velocity limit (rad/s)"),
    ParameterSpec("max_wheel_force_n", PARAMETER_DOUBLE,
                  "traction force limit per wheel (N); dynamic mode"),
    ParameterSpec("cmd_vel_timeout_s", PARAMETER_DOUBLE,
                  "stop when no /cmd_vel arrived for this long (s); 0 keeps the last command "
                  "(the course's behaviour)"),
)
"""The parameters ``get/set/list_parameters`` serve, in order."""

CMD_VEL_TIMEOUT_OFF_S = 0.0
"""The course's behaviour: the robot keeps the last command however old it is."""

_BY_NAME = {spec.name: spec for spec in PARAMETERS}


def parameter_value_msg(value: Any) -> Message:
    """``rcl_interfaces/msg/ParameterValue`` holding a Python value (None -> NOT_SET)."""
    msg: Message = {"type": PARAMETER_NOT_SET, "bool_value": False, "integer_value": 0,
                    "double_value": 0.0, "string_value": "", "byte_array_value": [],
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
        raise ConfigError(f"value: expected a ParameterValue object, got {msg!r}")
    type_code = msg.get("type")
    if type_code == PARAMETER_NOT_SET:
        return None
    if isinstance(type_code, bool) or type_code not in _VALUE_FIELDS:
        raise ConfigError(f"value.type: unknown ParameterType {type_code!r}")
    field = _VALUE_FIELDS[type_code]
    if field not in msg:
        raise ConfigError(f"value.{field}: missing for type {type_code}")
    return msg[field]


class RobotParameters:
    """Get, set and list the runtime parameters of one simulation.

    Args:
        sim: the simulation whose parameters these are.
        on_change: called with the names set after every successful change (also appended
            to ``listeners``).

    Attributes:
        listeners: called, in order, with the names set after every successful change (the
            rclpy node mirrors changes made through the embedded bridge with one).
        cmd_vel_timeout_s: the command watchdog (s); 0 is off. Read by ``VirtualRobot``.
    """

    def __init__(self, sim: Simulation,
                 on_change: Callable[[list[str]], None] | None = None) -> None:
        self._sim = sim
        self.listeners: list[Callable[[list[str]], None]] = []
        if on_change is not None:
            self.listeners.append(on_change)
        self.cmd_vel_timeout_s = CMD_VEL_TIMEOUT_OFF_S

    @staticmethod
    def names() -> list[str]:
        """Every parameter name, in order."""
        return [spec.name for spec in PARAMETERS]

    @staticmethod
    def spec(name: str) -> ParameterSpec:
        """The spec of ``name``; KeyError if there is none."""
        return _BY_NAME[name]

    def get(self, name: str) -> Any:
        """The current value of ``name`` (a str or float); KeyError if unknown."""
        spec = _BY_NAME[name]
        if spec.name == "mode":
            return self._sim.mode
        if spec.name == "cmd_vel_timeout_s":
            return self.cmd_vel_timeout_s
        return float(getattr(self._sim.params, spec.name))

    def set(self, name: str, value: Any) -> None:
        """Set ``name`` to ``value`` now.

        Raises:
            ConfigError: unknown name, wrong type or invalid value; nothing changes.
        """
        self.set_many({name: value})

    def check(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Validate a change without making it; returns the values as they would be set.

        Raises:
            ConfigError: the first bad name or value, with the reason.
        """
        checked: dict[str, Any] = {}
        robot_changes: dict[str, float] = {}
        for name, value in values.items():
            spec = _BY_NAME.get(name)
            if spec is None:
                raise ConfigError(f"{name}: no such parameter (known: {', '.join(self.names())})")
            if spec.type_code == PARAMETER_STRING:
                if value not in MODES:
                    raise ConfigError(f"{name}: must be one of {', '.join(MODES)}, got {value!r}")
                checked[name] = value
            elif name == "cmd_vel_timeout_s":
                checked[name] = as_non_negative_float(name, _double(name, value))
            else:
                robot_changes[name] = checked[name] = _double(name, value)
        dataclasses.replace(self._sim.params, **robot_changes)  # the dataclass validates
        return checked

    def set_many(self, values: Mapping[str, Any]) -> None:
        """Set several parameters at once: all change, or (on any error) none do.

        Raises:
            ConfigError: the first bad name or value, with the reason.
        """
        checked = self.check(values)
        robot_changes = {name: value for name, value in checked.items()
                         if name not in ("mode", "cmd_vel_timeout_s")}
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
        raise ConfigError(f"{name}: expected a number, got {type(value).__name__} {value!r}")
    if not math.isfinite(value):
        raise ConfigError(f"{name}: expected a finite number, got {value!r}")
    return float(value)
