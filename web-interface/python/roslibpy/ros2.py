"""roslibpy.ros2 in the browser: ROS 2's std_msgs/Header (no ``seq``)."""

from __future__ import annotations

from typing import Any

from roslibpy.core import Header as _Ros1Header
from roslibpy.core import Time

__all__ = ["Header"]


class Header(_Ros1Header):
    """A ROS 2 std_msgs/Header: ``stamp`` and ``frame_id``."""

    def __init__(self, stamp: dict[str, Any] | None = None, frame_id: str | None = None) -> None:
        super().__init__(stamp=stamp, frame_id=frame_id)
        self.data["stamp"] = Time(stamp["secs"], stamp["nsecs"]) if stamp else None
        del self.data["seq"]
