"""One connected client, as every capability of the bridge sees it.

A ``Session`` holds everything of one client and nothing of any other: its rights, its
subscriptions and advertisements, the services it offers, its outbox and its budgets. The
bridge's tables point at sessions; dropping a session (``Bridge.disconnect``) releases all of
it.

Frames reach a client only through its session (``reply``, ``queue_topic``), which notes the
client as ready in its hub's ``Ready`` set; the hub's entry points hand what is ready back to
the transport as a ``Flush``: the core never writes, nor calls the transport.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, TypeAlias

from rosbridge.core.clock import Clock
from rosbridge.core.encoding import to_json
from rosbridge.core.errors import shorten
from rosbridge.core.fragments import Reassembly, fragment
from rosbridge.core.limits import ClientLimits, TokenBucket
from rosbridge.core.outbox import Entry, Outbox
from rosbridge.core.schema import MAX_NAME_CHARS, STATUS_LEVELS, GoalStatus, echoable_id

log = logging.getLogger("websim.bridge")


NAMESPACED_FIELDS = ("service", "topic")
"""The fields of a message sent to a client that a ``namespace`` prefixes."""

COMPRESSION_PRECEDENCE = ("cbor-raw", "cbor", "png")
"""Which compression a topic is sent with when its subscribe ids ask for several (rosbridge's
``Subscription.update_params``): the first any id asked for."""


@dataclass
class Subscription:
    """One client's subscription to one topic, merged over its subscribe ids.

    Attributes:
        throttle_ms: per id, the least time between two messages (ms).
        queue_length: per id, how many of the newest messages may wait.
        compressions: per id, the compression it asked for (``schema.COMPRESSIONS``).
        compression: the one in force: ``cbor-raw`` if any id asked for it, else ``cbor``,
            else ``png``, else ``none`` (rosbridge's choice).
        last_sent_s: when the last message was queued (monotonic s).
        throttle_in_force_ms: the least throttle over the ids (ms): what delivery obeys.
        queue_in_force: the longest queue over the ids.
        type_name: the type its first subscribe named (``pkg/msg/Type``), None if none did:
            on a topic that carries several types it gets the messages of this one (none
            named: the topic's first type).
    """

    throttle_ms: dict[Any, float] = field(default_factory=dict)
    queue_length: dict[Any, int] = field(default_factory=dict)
    compressions: dict[Any, str] = field(default_factory=dict)
    compression: str = "none"
    last_sent_s: float = -math.inf
    throttle_in_force_ms: float = 0.0
    queue_in_force: int = 0
    type_name: str | None = None

    def add(self, sub_id: Any, throttle_ms: float, queue_length: int,
            compression: str = "none") -> None:
        """Add (or replace) subscribe id ``sub_id``."""
        self.throttle_ms[sub_id] = throttle_ms
        self.queue_length[sub_id] = queue_length
        self.compressions[sub_id] = compression
        self._merge()

    def remove(self, sub_id: Any) -> bool:
        """Drop subscribe id ``sub_id``; whether any id is left."""
        self.throttle_ms.pop(sub_id, None)
        self.queue_length.pop(sub_id, None)
        self.compressions.pop(sub_id, None)
        if not self.throttle_ms:
            return False
        self._merge()
        return True

    def effective(self) -> tuple[float, int]:
        """(throttle_ms, queue_length) in force: the least throttle, the longest queue."""
        return self.throttle_in_force_ms, self.queue_in_force

    def _merge(self) -> None:
        """Computed when ids change, not for every message delivered."""
        self.throttle_in_force_ms = min(self.throttle_ms.values())
        self.queue_in_force = max(self.queue_length.values())
        asked = set(self.compressions.values())
        self.compression = next((name for name in COMPRESSION_PRECEDENCE if name in asked),
                                "none")


Ready: TypeAlias = "dict[Session, None]"
"""An ordered set of clients whose outboxes got frames (or overflowed) since it was taken."""


@dataclass(frozen=True)
class Flush:
    """Who must be written after a call into the core, in this order; the transport writes.

    Attributes:
        now: the clients closing a loop (``capabilities.topics.CLOSING_LOOP_S``): write them
            at once.
        later: every other client whose outbox got frames: write them once the current
            callback (a tick, a frame) is done, one write each for all it queued.
    """

    now: tuple[Session, ...] = ()
    later: tuple[Session, ...] = ()

    def __bool__(self) -> bool:
        return bool(self.now or self.later)

    def __add__(self, other: Flush) -> Flush:
        """Both, ``now`` before ``now`` and ``later`` before ``later`` (hubs' flushes joined)."""
        return Flush(self.now + other.now, self.later + other.later)


NOTHING = Flush()
"""The flush of a call that queued nothing (most of a tick's: one made once)."""


def take_flush(ready: Ready, closing: Ready | None = None) -> Flush:
    """Empty ``ready`` (and ``closing``, the clients closing a loop among them) into a Flush."""
    if not ready and not closing:
        return NOTHING
    if closing:
        flush = Flush(tuple(closing), tuple(s for s in ready if s not in closing))
        closing.clear()
    else:
        flush = Flush((), tuple(ready))
    ready.clear()
    return flush


class Session:
    """One connected client: its rights, subscriptions, advertisements, outbox and budgets.

    Args:
        peer: the client's address, for logs.
        is_admin: whether it presented the admin token.
        outbox: where its outgoing frames wait (default: one bounded by ``limits``).
        limits: the bounds this client lives within.
        clock: the clock of its budgets and fragment timeouts (default: wall time).
        namespace: a prefix (``/NAME``) for the topic and service names of everything it is
            sent, for a client that sees several robots under their names (the instructor's
            view of a class); empty: none. Names are prefixed in the messages, before they are
            encoded.
        may_drive: whether it may change the robot (``access.DriveRules``): a class robot's
            client with neither its token nor the instructor's may only watch.
        instructor: whether its admin rights are the instructor's (the server's admin token:
            every bridge of the server), not only a robot's own token's (its owner's): the
            dashboard counts them apart, and an arena's simulation services grant it every
            robot (``ros_nodes.simulator_control``). Set by the transport.

    Attributes:
        advertised: topic -> {advertise id: type}; a topic stays advertised while any id does.
        services: service name -> type, for the services this client offers.
        actions: action name -> type, for the actions this client offers.
        relay_budget: bytes/s of messages it may have relayed to other clients.
        fragment_size: the longest JSON frame it is sent; longer ones go as ``fragment``
            ops. Set by the ``fragment_size`` of any op it sends (rosbridge's
            ``Protocol.incoming``: one setting per client, the last one given; ``null``: off).
        fragments: its fragmented messages being put back together.
        ready: where it notes that its outbox got frames: the ``Ready`` set of the hub it is
            connected to (the hub's ``connect`` sets it; a set of its own before).
    """

    def __init__(self, peer: str, is_admin: bool, outbox: Outbox | None = None, *,
                 limits: ClientLimits | None = None,
                 clock: Clock | None = None, namespace: str = "",
                 may_drive: bool = True, instructor: bool = False) -> None:
        self.peer = peer
        self.instructor = instructor
        """Whether it presented the instructor's token (not only its robot's)."""
        self.namespace = namespace
        self.is_admin = is_admin
        self.may_drive = may_drive
        """Whether it may change the robot, not only watch (``access.DriveRules``)."""
        self.url_path = "/"
        """The path of the WebSocket URL it connected to (``/robots/alice``): a hint names the
        URL that works on this server (set by the transport)."""
        self.limits = limits or ClientLimits()
        self.outbox = outbox if outbox is not None else \
            Outbox(self.limits.max_queued_bytes, self.limits.max_replies)
        self.subscriptions: dict[str, Subscription] = {}
        self.advertised: dict[str, dict[Any, str]] = {}
        self.services: dict[str, str] = {}
        self.actions: dict[str, str] = {}
        self.status_level: str | None = None
        self.frame_bytes = 0
        """Size of the frame being handled (what a publish costs the relay budget)."""
        self.fragment_size: int | None = None
        self.ready: Ready = {}
        clock_args = () if clock is None else (clock.monotonic_s,)
        self.fragments = Reassembly(self.limits, *clock_args)
        self.relay_budget = TokenBucket(  # a burst holds one message of the largest size
            self.limits.relay_bytes_per_s,
            max(self.limits.relay_bytes_per_s, self.limits.max_frame_bytes), *clock_args)

    def reply(self, message: Mapping[str, Any]) -> None:
        """Queue a reply (JSON text), in ``fragment`` ops if longer than ``fragment_size``.

        Its ``service`` or ``topic`` name is prefixed with the ``namespace``, if any.
        """
        if self.namespace:
            message = {key: self.namespace + value
                       if key in NAMESPACED_FIELDS and isinstance(value, str) else value
                       for key, value in message.items()}
        text = to_json(message)
        if self.fragment_size is not None and len(text) > self.fragment_size:
            self.outbox.put_reply(fragment(text, self.fragment_size, message.get("id")))
        else:
            self.outbox.put_reply(text)
        self.ready[self] = None

    def queue_topic(self, topic: str, frames: Entry, queue_length: int) -> None:
        """Queue a message of ``topic`` (``Outbox.put_topic``: its newest ``queue_length``).

        ``frames`` carry the name the client knows the topic by (``namespace`` + ``topic``).
        """
        self.outbox.put_topic(self.namespace + topic, frames, queue_length)
        self.ready[self] = None

    def discard_topic(self, topic: str) -> None:
        """Forget the frames of ``topic`` waiting (it unsubscribed)."""
        self.outbox.discard_topic(self.namespace + topic)

    def report(self, reason: str, message: Any = None) -> None:
        """Log an error and, if this client asked with set_level, send it as a status.

        A reason longer than ``MAX_REASON_CHARS`` is cut: it may quote the client's input.
        """
        reason = shorten(reason)
        log.warning("client %s: %s", self.peer, reason)
        level = self.status_level
        if level is not None and STATUS_LEVELS.index(level) <= STATUS_LEVELS.index("error"):
            status: dict[str, Any] = {"op": "status", "level": "error", "msg": reason}
            call_id = echoable_id(message)
            if call_id is not None:
                status["id"] = call_id
            self.reply(status)

    def fail_call(self, call_id: Any, service: str, reason: str) -> None:
        """Answer a call with ``result: false`` and the reason in ``values``."""
        response: dict[str, Any] = {"op": "service_response", "service": service,
                                    "values": reason, "result": False}
        if call_id is not None:
            response["id"] = call_id
        self.reply(response)

    def fail_goal(self, goal_id: Any, action: str, reason: str,
                  status: GoalStatus = GoalStatus.UNKNOWN) -> None:
        """Answer a goal with ``result: false``, ``status`` and the reason in ``values``.

        As rosbridge answers a goal it could not send: ``status`` UNKNOWN when no server
        took it, ABORTED when its server went away.
        """
        result: dict[str, Any] = {"op": "action_result", "action": action, "values": reason,
                                  "status": int(status), "result": False}
        if goal_id is not None:
            result["id"] = goal_id
        self.reply(result)

    def refuse(self, reason: str, message: Any) -> None:
        """Refuse an operation: report it, and answer a ``call_service`` or goal as failed.

        The answer makes the caller's callback run (roslib waits for it otherwise).
        """
        if isinstance(message, dict) and message.get("op") == "call_service" \
                and isinstance(message.get("service"), str):
            self.fail_call(echoable_id(message), message["service"][:MAX_NAME_CHARS],
                           shorten(reason))
        if isinstance(message, dict) and message.get("op") == "send_action_goal" \
                and isinstance(message.get("action"), str):
            self.fail_goal(echoable_id(message), message["action"][:MAX_NAME_CHARS],
                           shorten(reason))
        self.report(reason, message)

    def __repr__(self) -> str:
        return f"Session({self.peer}{', admin' if self.is_admin else ''})"
