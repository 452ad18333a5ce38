"""What the viewer tests share: a server whose laser is mounted off-centre, and its TF tree.

``websim serve`` with the shipped parameters but the LiDAR 10 cm ahead, 5 cm left and turned
90 degrees (``MOUNT``), so that every transform a viewer is handed shows whether the
odometry and the mount were composed, and in which order. ``expected_pose`` works a frame's
pose in ``odom`` out by hand from an ``/odom`` message.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from server_process import ServerProcess, start_server

ROOT = Path(__file__).resolve().parent.parent

MOUNT = {"mount_x_m": 0.1, "mount_y_m": 0.05, "mount_yaw_rad": math.pi / 2}
"""The laser in base_link: 10 cm ahead, 5 cm left, turned 90 degrees."""


def mounted_params(folder: Path) -> Path:
    """The shipped parameters file with the laser at ``MOUNT``, written in ``folder``."""
    text = (ROOT / "config" / "pi4b_params.yaml").read_text()
    for key, value in MOUNT.items():
        text, count = re.subn(rf"^(\s*{key}:\s*)\S+", rf"\g<1>{value!r}", text, flags=re.M)
        assert count == 1, key
    path = folder / "mounted_params.yaml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def mounted_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    """``websim serve`` on the empty world with the laser at ``MOUNT``."""
    params = mounted_params(tmp_path_factory.mktemp("params"))
    running = start_server(["--params", str(params)])
    yield running
    running.stop()


def planar_pose(odom: dict[str, Any]) -> tuple[float, float, float]:
    """(x, y, yaw) of an ``/odom`` message's pose (m, rad)."""
    p, q = odom["pose"]["pose"]["position"], odom["pose"]["pose"]["orientation"]
    return p["x"], p["y"], 2.0 * math.atan2(q["z"], q["w"])


def expected_pose(odom: dict[str, Any], frame: str) -> tuple[float, float, float]:
    """``frame`` 's pose in ``odom`` (x, y, yaw) when the robot is at ``odom`` 's pose."""
    x, y, yaw = planar_pose(odom)
    if frame == "odom":
        return 0.0, 0.0, 0.0
    if frame == "base_link":
        return x, y, yaw
    assert frame == "laser", frame
    c, s = math.cos(yaw), math.sin(yaw)
    return (x + c * MOUNT["mount_x_m"] - s * MOUNT["mount_y_m"],
            y + s * MOUNT["mount_x_m"] + c * MOUNT["mount_y_m"], yaw + MOUNT["mount_yaw_rad"])


def pose_of(translation: dict[str, float],
            rotation: dict[str, float]) -> tuple[float, float, float, float, float, float]:
    """(x, y, yaw, z, roll-pitch part x, y) of a planar transform: the last three must be 0."""
    return (translation["x"], translation["y"], 2.0 * math.atan2(rotation["z"], rotation["w"]),
            translation["z"], rotation["x"], rotation["y"])


def same_pose(got: tuple[float, ...], want: tuple[float, float, float],
              tolerance: float = 1e-6) -> bool:
    """Whether a planar ``pose_of`` is ``want`` (x, y, yaw; the yaw modulo a turn)."""
    x, y, yaw, *off_plane = got
    return (abs(x - want[0]) <= tolerance and abs(y - want[1]) <= tolerance
            and abs(math.remainder(yaw - want[2], 2 * math.pi)) <= tolerance
            and all(abs(value) <= tolerance for value in off_plane))
