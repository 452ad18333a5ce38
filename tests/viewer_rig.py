"""What the viewer tests share: a server whose every frame differs, and its TF tree by hand.

``websim serve`` on the 6 m arena with the robot spawned off the origin and turned
(``SPAWN``), ``localization: perfect`` (so ``map -> odom`` is on ``/tf``), and the LiDAR 10 cm
ahead, 5 cm left and turned 90 degrees (``MOUNT``): every transform a viewer is handed shows
whether map -> odom -> base_link -> laser were composed, and in which order.
``expected_pose`` works a frame's pose in the fixed frame out from an ``/odom`` and a
``/ground_truth`` message (map -> odom is what a perfect localizer publishes: the true pose
composed with the odometry's inverse).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from physics.frames import compose, inverse
from physics.snapshots import Pose2D

from conftest import ARENA_HALF_M
from server_process import ServerProcess, start_server

ROOT = Path(__file__).resolve().parent.parent

MOUNT = {"mount_x_m": 0.1, "mount_y_m": 0.05, "mount_yaw_rad": math.pi / 2}
"""The laser in base_link: 10 cm ahead, 5 cm left, turned 90 degrees."""

SPAWN = Pose2D(1.0, -0.5, 0.4)
"""Where the robot starts in map (m, m, rad): odom's origin, so map -> odom is not identity."""

WORLD = f"""\
name: viewer arena
start: [{SPAWN.x}, {SPAWN.y}, {SPAWN.theta}]
localization: perfect
polylines:
  - points: [[-{ARENA_HALF_M}, -{ARENA_HALF_M}], [{ARENA_HALF_M}, -{ARENA_HALF_M}],
             [{ARENA_HALF_M}, {ARENA_HALF_M}], [-{ARENA_HALF_M}, {ARENA_HALF_M}]]
    closed: true
"""
"""worlds/empty.yaml's arena, the robot spawned at ``SPAWN``, map -> odom published."""


def viewer_files(folder: Path) -> tuple[Path, Path]:
    """(world, parameters): ``WORLD`` and the shipped parameters with the laser at ``MOUNT``."""
    text = (ROOT / "config" / "pi4b_params.yaml").read_text()
    for key, value in MOUNT.items():
        text, count = re.subn(rf"^(\s*{key}:\s*)\S+", rf"\g<1>{value!r}", text, flags=re.M)
        assert count == 1, key
    params, world = folder / "mounted_params.yaml", folder / "viewer_arena.yaml"
    params.write_text(text)
    world.write_text(WORLD)
    return world, params


@pytest.fixture(scope="module")
def viewer_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    """``websim serve`` on ``WORLD`` with the laser at ``MOUNT``."""
    world, params = viewer_files(tmp_path_factory.mktemp("viewer"))
    running = start_server(["--world", str(world), "--params", str(params)])
    yield running
    running.stop()


def pose_of(msg: dict[str, Any]) -> Pose2D:
    """An ``Odometry`` message's pose (m, rad)."""
    p, q = msg["pose"]["pose"]["position"], msg["pose"]["pose"]["orientation"]
    return Pose2D(p["x"], p["y"], 2.0 * math.atan2(q["z"], q["w"]))


def expected_pose(fixed: str, frame: str, odom: dict[str, Any],
                  ground_truth: dict[str, Any]) -> Pose2D:
    """``frame`` 's pose in ``fixed`` (``odom`` or ``map``), the robot being where the two
    messages (``/odom``, ``/ground_truth``, of one instant) put it."""
    in_odom = pose_of(odom)
    map_odom = compose(pose_of(ground_truth), inverse(in_odom))  # what /tf carries
    mount = Pose2D(MOUNT["mount_x_m"], MOUNT["mount_y_m"], MOUNT["mount_yaw_rad"])
    in_odom_frame = {"odom": Pose2D(0.0, 0.0, 0.0), "base_link": in_odom,
                     "laser": compose(in_odom, mount), "map": inverse(map_odom)}[frame]
    return in_odom_frame if fixed == "odom" else compose(map_odom, in_odom_frame)


def planar(translation: dict[str, float],
           rotation: dict[str, float]) -> tuple[float, float, float, float, float, float]:
    """(x, y, yaw, z, rotation x, rotation y) of a transform: planar if the last three are 0."""
    return (translation["x"], translation["y"], 2.0 * math.atan2(rotation["z"], rotation["w"]),
            translation["z"], rotation["x"], rotation["y"])


def same_pose(got: tuple[float, ...], want: Pose2D, tolerance: float = 1e-6) -> bool:
    """Whether a ``planar`` transform is ``want`` (the yaw modulo a turn), and planar."""
    x, y, yaw, *off_plane = got
    return (abs(x - want.x) <= tolerance and abs(y - want.y) <= tolerance
            and abs(math.remainder(yaw - want.theta, 2 * math.pi)) <= tolerance
            and all(abs(value) <= tolerance for value in off_plane))
