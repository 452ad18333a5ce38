"""A TF buffer: the newest transform of every frame from ``/tf`` and ``/tf_static``, composed.

What tf2's ``Buffer.lookup_transform(target, source, Time(0))`` answers, without ROS: each
``tf2_msgs/TFMessage`` gives, per child frame, its parent and its pose in that parent; the
buffer keeps the newest per child (tf2's latest-time lookup; websim's viewers never ask for
the past) and composes them along the tree to give any frame's pose in any other that shares
a root with it. Frame names are taken without a leading ``/``, as tf2 takes them.

Units: translations in m, rotations as unit quaternions ``(x, y, z, w)``. This module knows
no robot, and no message beyond ``TFMessage``'s shape.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

Vector = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]
"""``(x, y, z, w)``, normalised."""

MAX_FRAMES = 1000
"""Frames one buffer keeps (a large robot's tree has a few hundred); a message naming a new
frame beyond this is ignored for that frame, so a publisher cannot grow the buffer without
bound."""

MAX_FRAME_CHARS = 256
"""The longest frame name kept (longer ones are ignored, as any malformed transform is)."""


class TransformLookupError(LookupError):
    """A transform that cannot be composed: a frame is unknown, or the two are not joined."""


@dataclass(frozen=True)
class Transform:
    """A rigid transform: a frame's pose in another (``translation`` m, ``rotation``).

    ``compose`` chains them as tf2 does: ``parent_child.compose(child_grandchild)`` is the
    grandchild's pose in the parent.
    """

    translation: Vector = (0.0, 0.0, 0.0)
    rotation: Quaternion = (0.0, 0.0, 0.0, 1.0)

    def compose(self, other: Transform) -> Transform:
        """``self * other``: ``other`` (a pose in this transform's child) in its parent."""
        moved = rotate(self.rotation, other.translation)
        return Transform((self.translation[0] + moved[0], self.translation[1] + moved[1],
                          self.translation[2] + moved[2]),
                         multiply(self.rotation, other.rotation))

    def inverse(self) -> Transform:
        """The parent's pose in the child."""
        x, y, z, w = self.rotation
        conjugate = (-x, -y, -z, w)
        back = rotate(conjugate, self.translation)
        return Transform((-back[0], -back[1], -back[2]), conjugate)

    def distance_m(self, other: Transform) -> float:
        """How far apart the two translations are (m)."""
        return math.dist(self.translation, other.translation)

    def angle_rad(self, other: Transform) -> float:
        """The angle of the rotation from one orientation to the other (rad, 0 to pi)."""
        dot = abs(sum(a * b for a, b in zip(self.rotation, other.rotation, strict=True)))
        return 2.0 * math.acos(min(1.0, dot))


def multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """The Hamilton product ``a b``: rotation ``b`` then ``a``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def rotate(q: Quaternion, v: Vector) -> Vector:
    """``v`` rotated by the unit quaternion ``q``."""
    x, y, z, _ = multiply(multiply(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)


def clean_frame(frame_id: str) -> str:
    """A frame name as tf2 keys it: without a leading ``/``."""
    return frame_id[1:] if frame_id.startswith("/") else frame_id


def transform_of(transform: Mapping[str, Any]) -> Transform | None:
    """A ``geometry_msgs/Transform`` dict as a ``Transform``; None if not finite or no rotation.

    The rotation is normalised (tf2 does the same with what it is given).
    """
    try:
        t, r = transform["translation"], transform["rotation"]
        translation = (float(t["x"]), float(t["y"]), float(t["z"]))
        rotation = (float(r["x"]), float(r["y"]), float(r["z"]), float(r["w"]))
    except (KeyError, TypeError, ValueError):
        return None
    norm = math.sqrt(sum(c * c for c in rotation))
    if not all(math.isfinite(c) for c in (*translation, norm)) or norm < 1e-9:
        return None
    return Transform(translation, (rotation[0] / norm, rotation[1] / norm,
                                   rotation[2] / norm, rotation[3] / norm))


@dataclass(frozen=True)
class _Edge:
    parent: str
    transform: Transform


class TfBuffer:
    """The newest transform of each frame, from ``TFMessage`` s, and lookups over them.

    Args:
        max_frames: the most child frames kept (``MAX_FRAMES``).

    Attributes:
        ignored: transforms not kept since the buffer was made or cleared: malformed
            (a non-finite value, no rotation, a frame named empty, too long or its own
            parent) or naming a frame beyond ``max_frames``.
    """

    def __init__(self, max_frames: int = MAX_FRAMES) -> None:
        self._max_frames = max_frames
        self._edges: dict[str, _Edge] = {}
        self.ignored = 0

    def clear(self) -> None:
        """Forget every transform (nobody listened to the TF topics for a while)."""
        self._edges.clear()
        self.ignored = 0

    def add(self, message: Mapping[str, Any]) -> None:
        """Keep the transforms of a ``tf2_msgs/TFMessage`` dict (``/tf`` or ``/tf_static``)."""
        transforms = message.get("transforms")
        if not isinstance(transforms, list):
            return
        for stamped in transforms:
            self._add_one(stamped)

    def _add_one(self, stamped: Any) -> None:
        try:
            parent = clean_frame(stamped["header"]["frame_id"])
            child = clean_frame(stamped["child_frame_id"])
            transform = transform_of(stamped["transform"])
        except (KeyError, TypeError, AttributeError):
            transform = None
            parent = child = ""
        if transform is None or not parent or not child or parent == child or \
                max(len(parent), len(child)) > MAX_FRAME_CHARS or \
                (child not in self._edges and len(self._edges) >= self._max_frames):
            self.ignored += 1
            return
        self._edges[child] = _Edge(parent, transform)

    def frames(self) -> set[str]:
        """Every frame named so far, as a child or as a parent."""
        return set(self._edges) | {edge.parent for edge in self._edges.values()}

    def lookup(self, target: str, source: str) -> Transform:
        """``source`` 's pose in ``target`` (tf2's ``lookup_transform(target, source)``).

        Raises:
            TransformLookupError: a frame is unknown, or the two are in trees with no common frame;
                the reason names them.
        """
        target, source = clean_frame(target), clean_frame(source)
        known = self.frames()
        for frame in (target, source):
            if frame not in known:
                raise TransformLookupError(f"frame '{frame}' does not exist")
        to_source = self._chain(source)
        to_target = self._chain(target)
        common = next((frame for frame in to_source if frame in to_target), None)
        if common is None:
            raise TransformLookupError(f"'{target}' and '{source}' are not in the same tree")
        return self._from(common, target).inverse().compose(self._from(common, source))

    def _chain(self, frame: str) -> dict[str, None]:
        """``frame`` and its ancestors, nearest first (a cycle ends the walk)."""
        chain: dict[str, None] = {frame: None}
        while (edge := self._edges.get(frame)) is not None and edge.parent not in chain:
            frame = edge.parent
            chain[frame] = None
        return chain

    def _from(self, ancestor: str, frame: str) -> Transform:
        """``frame`` 's pose in its ``ancestor``."""
        steps: list[Transform] = []
        while frame != ancestor:
            edge = self._edges[frame]
            steps.append(edge.transform)
            frame = edge.parent
        pose = Transform()
        for step in reversed(steps):
            pose = pose.compose(step)
        return pose


def transform_stamped(target: str, source: str, transform: Transform,
                      stamp: Mapping[str, int]) -> dict[str, Any]:
    """A ``geometry_msgs/TransformStamped`` dict: ``source`` 's pose in ``target``."""
    (x, y, z), (qx, qy, qz, qw) = transform.translation, transform.rotation
    return {"header": {"stamp": dict(stamp), "frame_id": target},
            "child_frame_id": source,
            "transform": {"translation": {"x": x, "y": y, "z": z},
                          "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}}}
