"""Parameter files: the project's numbers, one source, validated on load."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
import yaml

from physics import ConfigError, LidarParams, NoiseParams, RobotParams, load_params
from physics.params import SHIPPED_PARAMS_FILE


def test_defaults_are_the_projects_numbers() -> None:
    p = RobotParams()
    assert (p.mass_kg, p.wheel_radius_m, p.wheelbase_m, p.inertia_kg_m2) == \
        (1.2, 0.033, 0.160, 0.0066)
    assert (p.max_linear_mps, p.max_angular_rps, p.max_wheel_force_n, p.footprint_radius_m) == \
        (0.5, 2.5, 1.5, 0.11)
    assert NoiseParams() == NoiseParams(0.0, 0.0, 0.0)


def test_inertia_default_is_that_of_the_stated_box() -> None:
    p = RobotParams()
    assert p.mass_kg * (0.20**2 + 0.16**2) / 12 == pytest.approx(p.inertia_kg_m2, rel=0.01)


def test_every_field_comes_from_the_shipped_file() -> None:
    document = yaml.safe_load(SHIPPED_PARAMS_FILE.read_text())
    for section, cls in (("robot", RobotParams), ("lidar", LidarParams),
                         ("noise", NoiseParams)):
        names = [f.name for f in dataclasses.fields(cls)]
        assert sorted(document[section]) == sorted(names)
        assert {n: getattr(cls(), n) for n in names} == document[section]


def test_derived_quantities_are_properties() -> None:
    p = RobotParams()
    assert p.half_wheelbase_m == pytest.approx(0.08)
    assert p.max_wheel_rim_speed_mps == pytest.approx(0.5 + 2.5 * 0.08)
    assert p.max_wheel_speed_rad_s == pytest.approx(0.7 / 0.033)
    assert p.max_linear_accel_mps2 == pytest.approx(2 * 1.5 / 1.2)
    assert p.max_angular_accel_rps2 == pytest.approx(1.5 * 0.16 / 0.0066)
    faster = dataclasses.replace(p, max_linear_mps=1.0)
    assert faster.max_wheel_rim_speed_mps == pytest.approx(1.2)


def test_load_shipped_file_gives_defaults() -> None:
    platform = load_params(SHIPPED_PARAMS_FILE)
    assert platform.robot == RobotParams()
    assert platform.lidar == LidarParams()


def test_partial_file_overrides_only_what_it_names(tmp_path: Path) -> None:
    path = tmp_path / "heavy.yaml"
    path.write_text("robot:\n  mass_kg: 2.4\nlidar:\n  no_return: inf\n")
    platform = load_params(path)
    assert platform.robot == dataclasses.replace(RobotParams(), mass_kg=2.4)
    assert platform.lidar.no_return_range_m == math.inf


@pytest.mark.parametrize(("text", "expected"), [
    ("robot:\n  mass_kg: -1\n", "robot.mass_kg: must be between 0.01 and 1000, got -1"),
    ("robot:\n  mass_kg: .inf\n", "robot.mass_kg: expected a finite number"),
    ("robot:\n  mass: 2\n", "unknown key 'mass'; did you mean 'mass_kg'"),
    ("robots: {}\n", "unknown key 'robots'; did you mean 'robot'"),
    ("lidar:\n  num_rays: 0\n", "lidar.num_rays: must be a whole number"),
    ("lidar:\n  range_min_m: 4\n", "lidar.range_min_m: must be < range_max_m"),
    ("lidar:\n  no_return: nan\n", "lidar.no_return: must be one of range_max, inf"),
    ("noise:\n  scan_sigma_m: -0.1\n", "noise.scan_sigma_m: must be between 0 and 1"),
    ("robot: [1, 2]\n", "robot: expected a mapping"),
    ("robot: {mass_kg: 1\n", "not valid YAML"),
])
def test_bad_parameter_file_names_file_and_field(tmp_path: Path, text: str,
                                                 expected: str) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=expected) as caught:
        load_params(path)
    assert str(caught.value).startswith(str(path))


def test_missing_parameter_file() -> None:
    with pytest.raises(ConfigError, match="cannot read parameter file"):
        load_params("/nonexistent/params.yaml")


def test_params_are_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        RobotParams().mass_kg = 3.0  # type: ignore[misc]
