"""What a rosbridge client may do, in one place: the topic, service and action allow-list.

The bridge asks ``check`` before every operation that names a topic, service or action; the
one other access rule, admin rights for changing parameters, is ``services.require_admin``.

A client without the drive right (``Session.may_drive``: a class robot's client that presented
neither the robot's token nor the instructor's) may only watch: subscribe, list, call the
services that change nothing. What changes the robot is the bridge's owner's to say
(``DriveRules``: the topics the robot subscribes, its services that change it, the namespaces
of its own services, the only ones a watcher may call, and the in-process actions that only
read, to which a watcher may send goals); offering services or actions, and sending other
goals, always need the right.

Every client (student or admin) may:

* subscribe to any topic: the robot's, other clients', and with ``--ros`` the ROS graph's;
* publish ``/cmd_vel`` and topics of its own (relayed to other clients, and with ``--ros`` to
  the graph), but not the simulator's outputs (``/odom``, ``/scan``, ``/tf``...; refused by the
  bridge) nor ROS infrastructure topics (``/rosout``, ``/parameter_events``);
* call any service (changing parameters then needs the admin token), and offer services of its
  own, but not in the namespaces the bridge's owner reserves for its own nodes (the robot's:
  ``/virtual_robot/``, ``/rosapi/``, ``/websim/``, ``ros_nodes.robot_interface``);
* send goals to any action, and offer actions of its own, outside those namespaces too.

Names are resolved and checked once, before this (``rosbridge.core.schema.resolve_name``), and one
client may hold at most ``ClientLimits.max_subscriptions`` subscriptions, ``max_advertised``
advertised topics, ``max_services`` services and ``max_actions`` actions, so that one
connection cannot grow the server's tables without bound.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from rosbridge.core.limits import ClientLimits

RESERVED_TOPICS = frozenset({"/rosout", "/parameter_events"})
"""ROS infrastructure topics clients may not publish."""

DRIVE_OPS = frozenset({"advertise_service", "advertise_action", "send_action_goal"})
"""Operations that always need the drive right: offering services or actions on the robot,
and sending goals (an action's server drives it)."""


@dataclass(frozen=True)
class DriveRules:
    """What needs the drive right on a bridge, as its owner (the robot) says.

    Attributes:
        topics: topics the robot subscribes (``/cmd_vel``): publishing them needs the right.
        services: services that change the robot (``/reset_simulation``).
        watch_services: the namespaces (or names) of the services a client without the right
            may call (the robot's own: ``/rosapi/``...), but for ``services``; any other
            service (one a client offers, the ROS graph's) needs the right. Empty: every
            service but ``services``.
        watch_actions: the in-process actions that change nothing (the TF republisher's),
            to which a client without the right may send goals; any other goal needs it.
        hint: how to get the right, appended to a refusal.
    """

    topics: frozenset[str] = frozenset()
    services: frozenset[str] = frozenset()
    watch_services: tuple[str, ...] = ()
    watch_actions: frozenset[str] = frozenset()
    hint: str = ""

    def refusal(self, what: str) -> str:
        """The reason sent back to a client without the right."""
        return (f"{what} changes the robot and needs its token; this connection may only "
                f"watch (subscribe, list, call read-only services){self.hint}")

class AccessError(Exception):
    """An operation the allow-list refuses; the message is the reason sent back."""


class Holder(Protocol):
    """What ``check`` needs to know of a client: what it holds already, and its limits."""

    @property
    def subscriptions(self) -> Mapping[str, Any]:
        """Topics it subscribes to."""

    @property
    def advertised(self) -> Mapping[str, Any]:
        """Topics it advertises."""

    @property
    def services(self) -> Mapping[str, Any]:
        """Services it offers."""

    @property
    def actions(self) -> Mapping[str, Any]:
        """Actions it offers."""

    @property
    def limits(self) -> ClientLimits:
        """The bounds it lives within."""

    @property
    def may_drive(self) -> bool:
        """Whether it may change the robot (``DriveRules``), not only watch it."""


def check(client: Holder, op: str, name: str, reserved: tuple[str, ...] = (),
          drive: DriveRules | None = None) -> None:
    """Raise ``AccessError`` unless ``client`` may do ``op`` on the topic, service or action.

    ``name`` is already resolved (``schema.resolve_name``). Operations that only give
    something up (``unsubscribe``, ``unadvertise``...) are always allowed. Topics the
    simulator publishes are refused by the bridge, which knows who owns them. ``reserved``:
    the namespaces (``"/virtual_robot/"``) in which clients may not offer services or
    actions: the bridge's owner's own nodes. ``drive``: what needs the drive right (None:
    nothing, every client drives).
    """
    if drive is not None and not client.may_drive:
        _check_drive(op, name, drive)
    limits = client.limits
    if op == "subscribe":
        _within(client.subscriptions, name, limits.max_subscriptions, "subscriptions")
    elif op in ("advertise", "publish"):
        if name in RESERVED_TOPICS:
            raise AccessError(f"{name} is a ROS infrastructure topic; clients cannot "
                              "publish it")
        if op == "advertise":
            _within(client.advertised, name, limits.max_advertised, "advertised topics")
    elif op == "advertise_service":
        if reserved and name.startswith(reserved):
            raise AccessError(f"{name}: services under {', '.join(reserved)} "
                              "belong to the simulator")
        _within(client.services, name, limits.max_services, "services")
    elif op == "advertise_action":
        if reserved and name.startswith(reserved):
            raise AccessError(f"{name}: actions under {', '.join(reserved)} "
                              "belong to the simulator")
        _within(client.actions, name, limits.max_actions, "actions")


def _check_drive(op: str, name: str, drive: DriveRules) -> None:
    """Raise ``AccessError`` if ``op`` on ``name`` changes the robot."""
    if op in DRIVE_OPS and not (op == "send_action_goal" and name in drive.watch_actions):
        raise AccessError(drive.refusal(f"{op} {name}"))
    if op in ("advertise", "publish") and name in drive.topics:
        raise AccessError(drive.refusal(f"publishing {name}"))
    if op == "call_service" and (name in drive.services or (
            drive.watch_services and not name.startswith(drive.watch_services))):
        raise AccessError(drive.refusal(f"calling {name}"))


def _within(held: Mapping[str, Any], name: str, limit: int, what: str) -> None:
    if name not in held and len(held) >= limit:
        raise AccessError(f"{name}: a client may hold at most {limit} {what}")
