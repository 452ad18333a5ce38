"""The TF buffer (``rosbridge.tf.buffer``): transforms composed along the tree, checked by hand.

Each expected pose is worked out on paper from the planar geometry (a yaw of 90 degrees maps
(x, y) to (-y, x)); the 3D cases check a roll against the same rule about another axis.
"""

from __future__ import annotations

import math
from typing import Any

import pytest

from rosbridge.tf.buffer import TfBuffer, Transform, TransformLookupError


def yaw(theta: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2))


def stamped(parent: str, child: str, x: float = 0.0, y: float = 0.0, z: float = 0.0,
            rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> Any:
    qx, qy, qz, qw = rotation
    return {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": parent},
            "child_frame_id": child,
            "transform": {"translation": {"x": x, "y": y, "z": z},
                          "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}}}


def tf(*transforms: Any) -> Any:
    return {"transforms": list(transforms)}


def assert_pose(pose: Transform, translation: tuple[float, float, float],
                rotation: tuple[float, float, float, float]) -> None:
    assert pose.translation == pytest.approx(translation, abs=1e-12)
    sign = 1.0 if sum(a * b for a, b in zip(pose.rotation, rotation, strict=True)) >= 0 else -1.0
    assert [sign * c for c in pose.rotation] == pytest.approx(rotation, abs=1e-12)


@pytest.fixture
def tree() -> TfBuffer:
    """map -> odom (1, 0), yaw 90; odom -> base_link (2, 0); base_link -> laser (0.1, 0, 0.2)."""
    buffer = TfBuffer()
    buffer.add(tf(stamped("map", "odom", 1.0, 0.0, rotation=yaw(math.pi / 2)),
                  stamped("odom", "base_link", 2.0, 0.0)))
    buffer.add(tf(stamped("/base_link", "laser", 0.1, 0.0, 0.2)))  # tf2 drops the slash
    return buffer


def test_a_child_in_its_grandparent_is_the_two_transforms_composed(tree: TfBuffer) -> None:
    # base_link at (2, 0) in odom; odom turned 90 degrees at (1, 0): (1, 0) + (0, 2)
    assert_pose(tree.lookup("map", "base_link"), (1.0, 2.0, 0.0), yaw(math.pi / 2))
    assert_pose(tree.lookup("map", "laser"), (1.0, 2.1, 0.2), yaw(math.pi / 2))
    assert_pose(tree.lookup("odom", "laser"), (2.1, 0.0, 0.2), yaw(0.0))


def test_a_parent_in_its_child_is_the_inverse(tree: TfBuffer) -> None:
    # base_link is at (1, 2) facing +y: map's origin is 2 m behind it and 1 m to its left
    assert_pose(tree.lookup("base_link", "map"), (-2.0, 1.0, 0.0), yaw(-math.pi / 2))
    composed = tree.lookup("map", "laser").compose(tree.lookup("laser", "map"))
    assert_pose(composed, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def test_a_frame_in_itself_is_the_identity_once_it_is_known(tree: TfBuffer) -> None:
    assert_pose(tree.lookup("odom", "odom"), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    with pytest.raises(TransformLookupError, match="frame 'nowhere' does not exist"):
        tree.lookup("nowhere", "nowhere")


def test_a_roll_turns_y_into_z() -> None:
    buffer = TfBuffer()
    roll = (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4))  # 90 degrees about x
    buffer.add(tf(stamped("a", "b", rotation=roll), stamped("b", "c", 0.0, 1.0, 0.0)))
    assert_pose(buffer.lookup("a", "c"), (0.0, 0.0, 1.0), roll)


def test_the_newest_transform_of_a_frame_wins(tree: TfBuffer) -> None:
    tree.add(tf(stamped("odom", "base_link", 3.0, 0.0)))
    assert_pose(tree.lookup("odom", "base_link"), (3.0, 0.0, 0.0), yaw(0.0))


def test_unknown_and_unconnected_frames_are_refused_with_their_names(tree: TfBuffer) -> None:
    with pytest.raises(TransformLookupError, match="frame 'base_footprint' does not exist"):
        tree.lookup("odom", "base_footprint")
    tree.add(tf(stamped("world", "marker")))
    with pytest.raises(TransformLookupError, match="'map' and 'marker' are not in the same"):
        tree.lookup("map", "marker")


def test_a_cycle_ends_the_walk_instead_of_hanging() -> None:
    buffer = TfBuffer()
    buffer.add(tf(stamped("a", "b", 1.0), stamped("b", "a", 1.0), stamped("b", "c", 1.0)))
    assert_pose(buffer.lookup("b", "c"), (1.0, 0.0, 0.0), yaw(0.0))
    buffer.lookup("a", "c")  # some composition, and no endless loop


def test_malformed_transforms_are_ignored_and_counted() -> None:
    buffer = TfBuffer()
    buffer.add(tf(stamped("a", "b", math.nan), stamped("a", "c", rotation=(0, 0, 0, 0)),
                  stamped("", "d"), stamped("e", "e"), stamped("a", "x" * 300),
                  {"header": {}}, stamped("a", "ok", rotation=(0, 0, 0, 2.0))))
    buffer.add({"transforms": "not a list"})
    assert buffer.ignored == 6
    assert buffer.frames() == {"a", "ok"}
    assert_pose(buffer.lookup("a", "ok"), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))  # normalised


def test_frames_beyond_the_limit_are_ignored_but_known_ones_still_update() -> None:
    buffer = TfBuffer(max_frames=2)
    buffer.add(tf(stamped("root", "one"), stamped("root", "two"), stamped("root", "three")))
    assert buffer.frames() == {"root", "one", "two"} and buffer.ignored == 1
    buffer.add(tf(stamped("root", "two", 5.0)))
    assert buffer.lookup("root", "two").translation == (5.0, 0.0, 0.0)


def test_angle_and_distance_between_poses() -> None:
    a, b = Transform((0.0, 0.0, 0.0), yaw(0.1)), Transform((3.0, 4.0, 0.0), yaw(-0.2))
    assert a.distance_m(b) == pytest.approx(5.0)
    assert a.angle_rad(b) == pytest.approx(0.3)
    flipped = Transform((0.0, 0.0, 0.0), tuple(-c for c in yaw(-0.2)))  # type: ignore[arg-type]
    assert a.angle_rad(flipped) == pytest.approx(0.3)  # q and -q are one orientation
