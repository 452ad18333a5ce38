"""One tap per robot: every message that crosses the robot's boundary, in both directions.

Callbacks added to a robot's ``Tap`` are called with what the robot accepts on its topics
(``"in"``: a /cmd_vel it applied, from a browser or from the ROS graph) and what it
publishes each tick (``"out"``: /odom, /tf, /ground_truth, /scan), with the simulated time
of the crossing. The rclpy node of ``websim serve --ros`` publishes the robot's messages on
the graph through it; a recorder or a grader attaches the same way.
"""

from __future__ import annotations

from collections.abc import Callable

from rosbridge.msgs.values import Message

IN = "in"
"""A message the robot accepted on one of its topics."""

OUT = "out"
"""A message the robot published."""

TapCallback = Callable[[str, str, str, Message, float], None]
"""``(direction, topic, type, message, sim_time_s)``: direction ``IN`` or ``OUT``, the
topic's name and ``pkg/msg/Type``, the message as a dict (do not change it), and the
simulated time (s since spawn or the last reset) at which it crossed."""


class Tap:
    """The callbacks that see one robot's messages, called in the order they were added.

    A callback runs within the robot's tick (or its command's delivery): it must be quick,
    must not change the message, and should not raise (an exception is the robot's fault).
    """

    def __init__(self) -> None:
        self._callbacks: list[TapCallback] = []

    def add(self, callback: TapCallback) -> None:
        """Call ``callback`` with every message from now on."""
        self._callbacks.append(callback)

    def remove(self, callback: TapCallback) -> None:
        """Stop calling ``callback`` (nothing if it was not added)."""
        if callback in self._callbacks:
            self._callbacks.remove(callback)

    def __contains__(self, callback: object) -> bool:
        return callback in self._callbacks

    @property
    def attached(self) -> bool:
        """Whether any callback listens (then the robot builds every message it publishes)."""
        return bool(self._callbacks)

    def emit(self, direction: str, topic: str, type_name: str, message: Message,
             sim_time_s: float) -> None:
        """Call every callback with one message (arguments as ``TapCallback``'s)."""
        for callback in self._callbacks:
            callback(direction, topic, type_name, message, sim_time_s)
