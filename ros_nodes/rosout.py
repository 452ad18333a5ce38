"""The simulator's ``/rosout`` and ``/parameter_events``, as rclpy publishes them for a node.

Every ROS 2 node publishes its log lines on ``/rosout`` (``rcl_interfaces/msg/Log``) and its
parameter changes on ``/parameter_events`` (``rcl_interfaces/msg/ParameterEvent``); without a
ROS graph, the simulator publishes them itself for its node, ``/virtual_robot``, so a student's
``rqt_console``-like page or parameter watcher works as on the real robot. With ``--ros``, the
rclpy node publishes its own on the graph as well.

What is logged is what a student should see: the start (world and mode), resets, parameter
changes, refused commands and fault recoveries. Log lines are rate-bounded per place that
logs (``LOG_RATE_PER_S``): a page sending a NaN Twist at 20 Hz costs one line per message only
up to the burst, and does not silence the reset logged next; the lines dropped meanwhile are
counted in the next one from the same place.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from typing import Any

from ros_nodes.parameters import parameter_value_msg, shorten_value
from ros_nodes.robot_interface import (
    NODE_BASENAME,
    NODE_NAME,
    NODE_TOPICS,
    PARAMETER_EVENTS,
    ROSOUT,
)
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Bridge
from rosbridge.core.limits import TokenBucket
from rosbridge.msgs.values import Message, stamp

DEBUG, INFO, WARN, ERROR, FATAL = 10, 20, 30, 40, 50
"""``rcl_interfaces/msg/Log`` severity levels."""

LOGGER_NAME = NODE_BASENAME
"""The Log ``name`` field: rclpy names a node's logger after the node, without the slash."""

LOG_RATE_PER_S = 5.0
"""Log lines per second sustained, per place that logs: a client cannot flood /rosout."""

LOG_BURST = 20.0
"""Log lines that may go out at once (a parameter form submitting every field)."""


class RobotLog:
    """The ``/rosout`` and ``/parameter_events`` of one robot's node.

    Publishes the parameter declarations at once (rclpy announces a node's declared
    parameters as ``new_parameters``) and a ParameterEvent for every change the robot's
    parameters report (``RobotParameters.listeners``), whoever made it.

    Args:
        bridge: the robot's bridge.
        robot: the robot whose node this is (its clock stamps the messages and bounds the
            log rate).
    """

    def __init__(self, bridge: Bridge, robot: VirtualRobot) -> None:
        self._bridge = bridge
        self._robot = robot
        self._budgets: dict[tuple[str, int], TokenBucket] = {}
        self._dropped: dict[tuple[str, int], int] = {}
        for spec in NODE_TOPICS:
            bridge.topics.own(spec.name, spec.type)
        robot.parameters.listeners.append(self._changed)
        self._publish_event(new=robot.parameters.names())

    def info(self, text: str) -> None:
        """Log ``text`` at INFO."""
        self._log(INFO, text)

    def warning(self, text: str) -> None:
        """Log ``text`` at WARN."""
        self._log(WARN, text)

    def error(self, text: str) -> None:
        """Log ``text`` at ERROR."""
        self._log(ERROR, text)

    def _log(self, level: int, text: str) -> None:
        caller = sys._getframe(2)  # the frame that called info/warning/error, as rclpy fills
        site = (caller.f_code.co_filename, caller.f_lineno)  # bounded: lines of this code
        budget = self._budgets.get(site)
        if budget is None:
            budget = self._budgets[site] = TokenBucket(LOG_RATE_PER_S, LOG_BURST,
                                                       self._robot.clock.monotonic_s)
        if not budget.take(1.0):
            self._dropped[site] = self._dropped.get(site, 0) + 1
            return
        dropped = self._dropped.pop(site, 0)
        if dropped:
            text = f"{text} ({dropped} earlier lines dropped: more than " \
                   f"{LOG_RATE_PER_S:g} lines/s)"
        msg: Message = {"stamp": stamp(self._robot.clock.stamp_s()), "level": level,
                        "name": LOGGER_NAME, "msg": text,
                        "file": os.path.basename(caller.f_code.co_filename),
                        "function": caller.f_code.co_name, "line": caller.f_lineno}
        self._bridge.publish(ROSOUT.name, msg)

    def _changed(self, names: list[str]) -> None:
        """A parameter change went through: announce it and log it."""
        self._publish_event(changed=names)
        params = self._robot.parameters
        self.info("parameters set: " + ", ".join(
            f"{name}={shorten_value(params.get(name))}" for name in names))

    def _publish_event(self, new: Sequence[str] = (), changed: Sequence[str] = ()) -> None:
        params = self._robot.parameters

        def entries(names: Sequence[str]) -> list[dict[str, Any]]:
            return [{"name": name, "value": parameter_value_msg(params.get(name))}
                    for name in names]

        self._bridge.publish(PARAMETER_EVENTS.name, {
            "stamp": stamp(self._robot.clock.stamp_s()), "node": NODE_NAME,
            "new_parameters": entries(new), "changed_parameters": entries(changed),
            "deleted_parameters": []})
