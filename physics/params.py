"""Robot, LiDAR and noise parameters: frozen dataclasses loaded from YAML.

``config/pi4b_params.yaml`` is the single source of the platform's numbers: the dataclasses
below take their defaults from it, so ``RobotParams()`` is the Pi 4B robot and no constant is
written twice. All values are SI: metres, seconds, radians, kilograms, newtons.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from physics.shipped import CHECKOUT_DIR, shipped
from physics.validation import (
    ConfigError,
    as_float_in_range,
    as_mapping,
    check_keys,
    fail,
    load_yaml_file,
    shown,
)

PROJECT_DIR = CHECKOUT_DIR
"""The checkout (or editable install); installed from a wheel, site-packages (see
``physics.shipped``)."""

SHIPPED_PARAMS_FILE = shipped("physics", "config") / "pi4b_params.yaml"
"""The Pi 4B parameter file whose values are every dataclass default."""

NO_RETURN_POLICIES = ("range_max", "inf")
"""What a ray that hits nothing reports: ``range_max`` (course platform) or ``inf`` (REP 117)."""


@functools.cache
def _shipped_defaults() -> Mapping[str, Mapping[str, Any]]:
    """Read the shipped parameter file once; sections are read-only mappings."""
    document = load_yaml_file(SHIPPED_PARAMS_FILE, "parameter")
    return MappingProxyType({name: MappingProxyType(dict(section))
                             for name, section in document.items()})


def _shipped(section: str, name: str, minimum: float, maximum: float, unit: str) -> Any:
    """A dataclass field whose default is ``name`` in ``section`` of the shipped file.

    ``minimum`` and ``maximum`` bound every value the field may take (from a file, or set at
    runtime): the range in which the model is physically sensible and numerically safe.
    """
    return field(default_factory=lambda: _shipped_defaults()[section][name],
                 metadata={"range": (minimum, maximum), "unit": unit})


def field_range(cls: type[Any], name: str) -> tuple[float, float]:
    """The (minimum, maximum) a field of a parameter dataclass may take; KeyError if none."""
    for item in dataclasses.fields(cls):
        if item.name == name and "range" in item.metadata:
            low, high = item.metadata["range"]
            return float(low), float(high)
    raise KeyError(f"{cls.__name__}.{name} has no range")


def field_unit(cls: type[Any], name: str) -> str:
    """The unit of a field of a parameter dataclass (``""``: none or dimensionless)."""
    for item in dataclasses.fields(cls):
        if item.name == name:
            return str(item.metadata.get("unit", ""))
    raise KeyError(f"{cls.__name__} has no field {name}")


def _check_ranges(instance: Any, names: list[str] | None = None) -> None:
    """Validate (and store as float) each ranged field of a frozen dataclass instance."""
    for item in dataclasses.fields(instance):
        if "range" not in item.metadata or (names is not None and item.name not in names):
            continue
        low, high = item.metadata["range"]
        value = as_float_in_range(item.name, getattr(instance, item.name), low, high)
        object.__setattr__(instance, item.name, value)


@dataclass(frozen=True)
class RobotParams:
    """Physical parameters of the differential-drive robot.

    Attributes:
        mass_kg: chassis mass with battery, Pi 4B and lidar (kg).
        wheel_radius_m: drive wheel radius (m).
        wheelbase_m: distance between the two drive wheels (m).
        inertia_kg_m2: yaw moment of inertia about the centre (kg m^2).
        max_linear_mps: linear velocity limit; commands are clamped to it (m/s).
        max_angular_rps: angular velocity limit; commands are clamped to it (rad/s).
        max_wheel_force_n: traction force limit per wheel in dynamic mode (N).
        footprint_radius_m: radius of the circular collision footprint (m).
        cmd_lag_s: dead time of the motor driver: a command acts this long after it arrives
            (s); 0: at once (``physics.command_pipeline``, as every field below).
        linear_scale: forward speed the driver gives per commanded m/s (1: as commanded; a
            wrong wheel radius in the driver, a motor's gain).
        angular_scale: yaw rate the driver gives per commanded rad/s (1: as commanded; a
            wrong wheelbase in the driver, wheel slip in turns).
        linear_accel_limit_mps2: the driver's ramp on the forward speed (m/s^2); 0: none.
        angular_accel_limit_rps2: the driver's ramp on the yaw rate (rad/s^2); 0: none.
    """

    mass_kg: float = _shipped("robot", "mass_kg", 0.01, 1000.0, "kg")
    wheel_radius_m: float = _shipped("robot", "wheel_radius_m", 0.005, 1.0, "m")
    wheelbase_m: float = _shipped("robot", "wheelbase_m", 0.02, 5.0, "m")
    inertia_kg_m2: float = _shipped("robot", "inertia_kg_m2", 1e-5, 1000.0, "kg m^2")
    max_linear_mps: float = _shipped("robot", "max_linear_mps", 0.01, 10.0, "m/s")
    max_angular_rps: float = _shipped("robot", "max_angular_rps", 0.01, 20.0, "rad/s")
    max_wheel_force_n: float = _shipped("robot", "max_wheel_force_n", 0.001, 1e6, "N")
    footprint_radius_m: float = _shipped("robot", "footprint_radius_m", 0.01, 5.0, "m")
    cmd_lag_s: float = _shipped("robot", "cmd_lag_s", 0.0, 2.0, "s")
    linear_scale: float = _shipped("robot", "linear_scale", 0.05, 5.0, "")
    angular_scale: float = _shipped("robot", "angular_scale", 0.05, 5.0, "")
    linear_accel_limit_mps2: float = _shipped("robot", "linear_accel_limit_mps2", 0.0, 1000.0,
                                              "m/s^2")
    angular_accel_limit_rps2: float = _shipped("robot", "angular_accel_limit_rps2", 0.0,
                                               1000.0, "rad/s^2")

    def __post_init__(self) -> None:
        _check_ranges(self)

    @property
    def half_wheelbase_m(self) -> float:
        """Distance from the centre to each wheel (m)."""
        return 0.5 * self.wheelbase_m

    @property
    def max_wheel_rim_speed_mps(self) -> float:
        """Wheel rim speed needed at both velocity limits at once (m/s)."""
        return self.max_linear_mps + self.max_angular_rps * self.half_wheelbase_m

    @property
    def max_wheel_speed_rad_s(self) -> float:
        """Wheel angular speed needed at both velocity limits at once (rad/s)."""
        return self.max_wheel_rim_speed_mps / self.wheel_radius_m

    @property
    def max_linear_accel_mps2(self) -> float:
        """Largest forward acceleration the two wheels' traction allows (m/s^2)."""
        return 2.0 * self.max_wheel_force_n / self.mass_kg

    @property
    def max_angular_accel_rps2(self) -> float:
        """Largest yaw acceleration the two wheels' traction allows (rad/s^2)."""
        return self.max_wheel_force_n * self.wheelbase_m / self.inertia_kg_m2


@dataclass(frozen=True)
class LidarParams:
    """A 2D LiDAR shaped like ``sensor_msgs/LaserScan`` (defaults: RPLIDAR A1-like).

    Attributes:
        num_rays: beams per scan; the increment is 2*pi / num_rays, so a full turn is covered
            without counting any direction twice.
        angle_min_rad: angle of the first beam in the laser frame (rad).
        range_min_m: hits closer than this cannot be measured (m); see ``Lidar``.
        range_max_m: longest measurable range (m).
        scan_time_s: time for one full scan (s); also the publishing period.
        mount_x_m: laser position in base_link, forward (m).
        mount_y_m: laser position in base_link, left (m).
        mount_yaw_rad: laser yaw in base_link (rad).
        no_return: what a ray that hits nothing within range_max reports: ``"range_max"`` (the
            course platform's behaviour, the default) or ``"inf"`` (REP 117).
    """

    num_rays: int = _shipped("lidar", "num_rays", 1, 4096, "")
    angle_min_rad: float = _shipped("lidar", "angle_min_rad", -2 * math.pi, 2 * math.pi, "rad")
    range_min_m: float = _shipped("lidar", "range_min_m", 0.0, 100.0, "m")
    range_max_m: float = _shipped("lidar", "range_max_m", 0.01, 100.0, "m")
    scan_time_s: float = _shipped("lidar", "scan_time_s", 0.001, 10.0, "s")
    mount_x_m: float = _shipped("lidar", "mount_x_m", -5.0, 5.0, "m")
    mount_y_m: float = _shipped("lidar", "mount_y_m", -5.0, 5.0, "m")
    mount_yaw_rad: float = _shipped("lidar", "mount_yaw_rad", -2 * math.pi, 2 * math.pi, "rad")
    no_return: str = field(default_factory=lambda: _shipped_defaults()["lidar"]["no_return"])

    def __post_init__(self) -> None:
        low, high = field_range(LidarParams, "num_rays")
        if isinstance(self.num_rays, bool) or not isinstance(self.num_rays, int) \
                or not low <= self.num_rays <= high:
            raise fail("num_rays", f"must be a whole number from {low:g} to {high:g}, "
                                   f"got {shown(self.num_rays)}")
        _check_ranges(self, [item.name for item in dataclasses.fields(self)
                             if item.name != "num_rays"])
        if self.range_min_m >= self.range_max_m:
            raise fail("range_min_m", f"must be < range_max_m ({self.range_max_m!r}), "
                                      f"got {self.range_min_m!r}")
        if self.no_return not in NO_RETURN_POLICIES:
            raise fail("no_return", f"must be one of {', '.join(NO_RETURN_POLICIES)}, "
                                    f"got {shown(self.no_return)}")

    @property
    def angle_increment_rad(self) -> float:
        """Angle between neighbouring beams (rad): 2*pi / num_rays."""
        return 2.0 * math.pi / self.num_rays

    @property
    def angle_max_rad(self) -> float:
        """Angle of the last beam: angle_min + (num_rays - 1) * increment (rad)."""
        return self.angle_min_rad + (self.num_rays - 1) * self.angle_increment_rad

    @property
    def time_increment_s(self) -> float:
        """Time between measurements: scan_time / num_rays (s)."""
        return self.scan_time_s / self.num_rays

    @property
    def no_return_range_m(self) -> float:
        """The value reported for a ray that hits nothing (m)."""
        return self.range_max_m if self.no_return == "range_max" else math.inf


@dataclass(frozen=True)
class NoiseParams:
    """Gaussian noise standard deviations; zero means noiseless (the default).

    Attributes:
        odom_linear_sigma_mps: on the linear speed that odometry integrates, per tick (m/s).
        odom_angular_sigma_rps: on the yaw rate that odometry integrates, per tick (rad/s).
        scan_sigma_m: on every lidar hit (m); no-return and too-close readings stay exact.
    """

    odom_linear_sigma_mps: float = _shipped("noise", "odom_linear_sigma_mps", 0.0, 1.0, "m/s")
    odom_angular_sigma_rps: float = _shipped("noise", "odom_angular_sigma_rps", 0.0, 5.0, "rad/s")
    scan_sigma_m: float = _shipped("noise", "scan_sigma_m", 0.0, 1.0, "m")

    def __post_init__(self) -> None:
        _check_ranges(self)


@dataclass(frozen=True)
class PlatformParams:
    """Everything a parameter file holds: the robot, its LiDAR and the noise model."""

    robot: RobotParams = field(default_factory=RobotParams)
    lidar: LidarParams = field(default_factory=LidarParams)
    noise: NoiseParams = field(default_factory=NoiseParams)


_SECTIONS: Mapping[str, type[RobotParams] | type[LidarParams] | type[NoiseParams]] = \
    MappingProxyType({"robot": RobotParams, "lidar": LidarParams, "noise": NoiseParams})


def load_params(path: str | Path) -> PlatformParams:
    """Load a parameter file such as ``config/pi4b_params.yaml``.

    Sections and keys that are left out keep the shipped defaults.

    Raises:
        ConfigError: the file is unreadable, not YAML, or holds an unknown or invalid entry;
            the message names the file and the entry.
    """
    source = str(path)
    document = load_yaml_file(path, "parameter")
    document = {} if document is None else as_mapping(source, document)
    check_keys(source, document, _SECTIONS)
    sections: dict[str, Any] = {}
    for name, cls in _SECTIONS.items():
        where = f"{source}: {name}"
        values = as_mapping(where, document.get(name) or {})
        check_keys(where, values, [item.name for item in dataclasses.fields(cls)])
        try:
            sections[name] = cls(**values)
        except ConfigError as error:
            raise ConfigError(f"{where}.{error}") from None
    return PlatformParams(**sections)
