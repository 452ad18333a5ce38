"""What a rosbridge client may do, in one place: the topic and service allow-list.

The bridge asks ``check`` before every operation that names a topic or service; the one other
access rule, admin rights for changing parameters, is ``services.require_admin``.

Every client (student or admin) may:

* subscribe to any topic: the robot's, other clients', and with ``--ros`` the ROS graph's;
* publish ``/cmd_vel`` and topics of its own (relayed to other clients, and with ``--ros`` to
  the graph), but not the simulator's outputs (``/odom``, ``/scan``, ``/tf``...; refused by the
  bridge) nor ROS infrastructure topics (``/rosout``, ``/parameter_events``);
* call any service (changing parameters then needs the admin token), and offer services of its
  own, but not in the simulator's namespaces (``/virtual_robot/``, ``/rosapi/``).

Names must be ROS names (letters, digits and ``_`` in ``/``-separated tokens, at most 256
characters), and one client may hold at most ``MAX_SUBSCRIPTIONS`` subscriptions,
``MAX_ADVERTISED`` advertised topics and ``MAX_SERVICES`` services, so that one connection
cannot grow the server's tables without bound.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any, Protocol

from ros_nodes.topics import PUBLISHED_TOPICS

NAME = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")
"""A ROS 2 topic or service name (the leading ``/`` optional, as rosbridge accepts)."""

MAX_NAME_LENGTH = 256

MAX_SUBSCRIPTIONS = 64
"""Topics one client may subscribe to at once; the robot has seven."""

MAX_ADVERTISED = 32
"""Topics one client may advertise at once."""

MAX_SERVICES = 16
"""Services one client may offer at once."""

RESERVED_TOPICS = frozenset({"/rosout", "/parameter_events"})
"""ROS infrastructure topics clients may not publish."""

RESERVED_SERVICE_PREFIXES = ("/virtual_robot/", "/rosapi/")
"""Service namespaces of the simulator's own nodes; clients may not offer services in them."""

SIMULATOR_TOPICS = frozenset(spec.name for spec in PUBLISHED_TOPICS)
"""The robot's topics only the simulator publishes."""


class AccessError(Exception):
    """An operation the allow-list refuses; the message is the reason sent back."""


class Holder(Protocol):
    """What ``check`` needs to know of a client: what it holds already."""

    @property
    def subscriptions(self) -> Mapping[str, Any]:
        """Topics it subscribes to."""

    @property
    def advertised(self) -> Mapping[str, Any]:
        """Topics it advertises."""

    @property
    def services(self) -> Mapping[str, Any]:
        """Services it offers."""


def check(client: Holder, op: str, name: str) -> None:
    """Raise ``AccessError`` unless ``client`` may do ``op`` on topic or service ``name``.

    Operations that only give something up (``unsubscribe``, ``unadvertise``...) and those
    without a name are always allowed.
    """
    if op not in ("subscribe", "advertise", "publish", "call_service", "advertise_service"):
        return
    if len(name) > MAX_NAME_LENGTH or not NAME.fullmatch(name):
        raise AccessError(f"{op}: '{name[:80]}' is not a ROS name (letters, digits and _ "
                           f"in /-separated tokens, at most {MAX_NAME_LENGTH} characters)")
    if op == "subscribe":
        _within(client.subscriptions, name, MAX_SUBSCRIPTIONS, "subscriptions")
    elif op in ("advertise", "publish"):
        if name in SIMULATOR_TOPICS:
            raise AccessError(f"{name} is published by the simulator; clients cannot "
                               "publish it")
        if name in RESERVED_TOPICS:
            raise AccessError(f"{name} is a ROS infrastructure topic; clients cannot "
                               "publish it")
        if op == "advertise":
            _within(client.advertised, name, MAX_ADVERTISED, "advertised topics")
    elif op == "advertise_service":
        if name.startswith(RESERVED_SERVICE_PREFIXES):
            raise AccessError(f"{name}: services under {', '.join(RESERVED_SERVICE_PREFIXES)} "
                               "belong to the simulator")
        _within(client.services, name, MAX_SERVICES, "services")


def _within(held: Mapping[str, Any], name: str, limit: int, what: str) -> None:
    if name not in held and len(held) >= limit:
        raise AccessError(f"{name}: a client may hold at most {limit} {what}")
