"""The rosbridge v2 protocol without I/O: frames in, frames queued in client outboxes.

``Bridge.handle`` takes one WebSocket message from one client and acts on it: it validates the
operation against ``schema.OP_FIELDS``, dispatches through an ``op -> handler`` table, relays
topics between clients as rosbridge does, answers services, and queues every outgoing frame in
the right client's ``Outbox``. The server (``server.py``) only moves frames between sockets
and outboxes and calls ``publish`` once per tick. Nothing here awaits or touches a socket.

What a client may publish, subscribe, call and offer is ``ros_nodes.access.check``, asked once
per operation here. Errors never close the connection or change anything else: a failed
``call_service`` gets a ``service_response`` with ``result: false`` and the reason in
``values``; any other error is logged and, for a client that asked with ``set_level``, sent as
a ``status`` message (reasons cut to ``MAX_REASON_CHARS``).

With a ``Graph`` attached (``websim serve --ros``), topics reach beyond the clients: a
subscription to a topic the robot does not publish also subscribes on the ROS graph, and what
clients publish (``/cmd_vel`` included) is also published there. The graph's own messages come
back through ``publish``. The Graph is the only way out; this module imports no ROS.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from physics import ConfigError
from ros_nodes import access
from ros_nodes.messages import normalize_service_type, normalize_type
from ros_nodes.rosbridge.encoding import parse_json, to_cbor, to_json
from ros_nodes.rosbridge.outbox import Frame, Outbox
from ros_nodes.rosbridge.schema import COMPRESSIONS, STATUS_LEVELS, ProtocolError, check_fields
from ros_nodes.topics import CMD_VEL, PUBLISHED_TOPICS, ROBOT_TOPICS

log = logging.getLogger("websim.bridge")

SERVICE_TIMEOUT_S = 5.0
"""How long a call to a client-provided service may wait for its answer."""

THROTTLE_JITTER_S = 0.005
"""Tick jitter a throttle tolerates: ``throttle_rate`` is the least time between two messages
(rosbridge's definition), less this, so a 200 ms throttle on the 20 Hz /odom gives 5 Hz even
when a tick starts a few milliseconds early relative to the last one sent."""


MAX_REASON_CHARS = 300
"""Longest error reason logged or sent back; reasons quote input, which may be a megabyte."""


def shorten(reason: str) -> str:
    """``reason``, cut to ``MAX_REASON_CHARS`` with its full length noted."""
    if len(reason) <= MAX_REASON_CHARS:
        return reason
    return f"{reason[:MAX_REASON_CHARS]}... ({len(reason)} characters)"


class BridgeError(Exception):
    """An operation that cannot be carried out; the message is the reason sent back."""


class ServiceError(BridgeError):
    """A service call failed; the reason goes back in ``service_response.values``."""


@dataclass
class Subscription:
    """One client's subscription to one topic, merged over its subscribe ids.

    Attributes:
        throttle_ms: per id, the least time between two messages (ms).
        queue_length: per id, how many of the newest messages may wait.
        compression: ``"none"`` or ``"cbor"``.
        last_sent_s: when the last message was queued (monotonic s).
    """

    throttle_ms: dict[Any, float] = field(default_factory=dict)
    queue_length: dict[Any, int] = field(default_factory=dict)
    compression: str = "none"
    last_sent_s: float = -math.inf

    def effective(self) -> tuple[float, int]:
        """(throttle_ms, queue_length) in force: the least throttle, the longest queue."""
        return min(self.throttle_ms.values()), max(self.queue_length.values())


class Session:
    """One connected client: its rights, subscriptions, advertisements and outbox.

    Args:
        peer: the client's address, for logs.
        is_admin: whether it presented the admin token.
        outbox: where its outgoing frames wait.
    """

    def __init__(self, peer: str, is_admin: bool, outbox: Outbox) -> None:
        self.peer = peer
        self.is_admin = is_admin
        self.outbox = outbox
        self.subscriptions: dict[str, Subscription] = {}
        self.advertised: dict[str, str] = {}
        self.services: dict[str, str] = {}
        self.status_level: str | None = None

    def reply(self, message: Mapping[str, Any]) -> None:
        """Queue a reply (JSON text)."""
        self.outbox.put_reply(to_json(message))


class _Encoded:
    """One publish envelope, encoded at most once per format whatever the subscriber count."""

    def __init__(self, topic: str, msg: Any) -> None:
        self.envelope = {"op": "publish", "topic": topic, "msg": msg}
        self._json: str | None = None
        self._cbor: bytes | None = None

    def frame(self, compression: str) -> Frame:
        if compression == "cbor":
            if self._cbor is None:
                self._cbor = to_cbor(self.envelope)
            return self._cbor
        if self._json is None:
            self._json = to_json(self.envelope)
        return self._json


ServiceHandler = Callable[[Mapping[str, Any], Session], Mapping[str, Any]]


class Graph(Protocol):
    """The ROS 2 graph beyond the bridge, as the bridge uses it; called on the bridge's thread.

    Its messages enter through ``Bridge.publish`` (called on the bridge's thread too). Each
    method raises ``BridgeError`` with the reason when it cannot do what is asked.
    """

    def topic_types(self) -> Mapping[str, str]:
        """The topics on the graph and their types (``pkg/msg/Type``)."""

    def subscribe(self, topic: str, type_name: str | None) -> None:
        """Relay ``topic`` from the graph; ``type_name`` None: whatever type it turns out to be."""

    def unsubscribe(self, topic: str) -> None:
        """Stop relaying ``topic`` from the graph."""

    def advertise(self, topic: str, type_name: str) -> None:
        """Be ready to publish ``topic`` on the graph."""

    def unadvertise(self, topic: str) -> None:
        """Stop publishing ``topic`` on the graph."""

    def publish(self, topic: str, msg: Any) -> None:
        """Publish a message (a dict) on an advertised ``topic``."""


@dataclass
class _PendingCall:
    caller: Session
    caller_id: Any
    service: str
    provider: Session
    deadline_s: float


class Bridge:
    """The rosbridge hub for one simulated robot and its clients.

    Args:
        on_cmd_vel: applies a ``/cmd_vel`` Twist dict to the robot; raises ``ConfigError``.
        clock: monotonic clock (s), for throttling and service timeouts.
        service_timeout_s: how long a call to a client-provided service may take.
    """

    def __init__(self, on_cmd_vel: Callable[[Any], None],
                 clock: Callable[[], float] = time.monotonic,
                 service_timeout_s: float = SERVICE_TIMEOUT_S) -> None:
        self._on_cmd_vel = on_cmd_vel
        self._clock = clock
        self._service_timeout_s = service_timeout_s
        self.sessions: set[Session] = set()
        self._topic_types: dict[str, str] = {spec.name: spec.type for spec in ROBOT_TOPICS}
        self._owned = {spec.name for spec in PUBLISHED_TOPICS}
        self._subscribers: dict[str, set[Session]] = {}
        self._latched: dict[str, _Encoded] = {}
        self._services: dict[str, tuple[str, ServiceHandler]] = {}
        self._providers: dict[str, tuple[Session, str]] = {}
        self._pending: dict[str, _PendingCall] = {}
        self._call_counter = 0
        self._graph: Graph | None = None
        self._graph_subscribed: set[str] = set()
        self._graph_advertised: set[str] = set()
        self._graph_refused: set[str] = set()
        self._handlers: dict[str, Callable[[Session, dict[str, Any]], None]] = {
            "advertise": self._advertise, "unadvertise": self._unadvertise,
            "publish": self._publish, "subscribe": self._subscribe,
            "unsubscribe": self._unsubscribe, "call_service": self._call_service,
            "service_response": self._service_response,
            "advertise_service": self._advertise_service,
            "unadvertise_service": self._unadvertise_service,
            "set_level": self._set_level, "auth": lambda session, message: None,
        }

    # ---- registry -------------------------------------------------------------------------

    def add_service(self, name: str, type_name: str, handler: ServiceHandler) -> None:
        """Offer a service implemented by the server itself."""
        self._services[name] = (normalize_service_type(type_name), handler)

    def attach_graph(self, graph: Graph | None) -> None:
        """Relay topics to and from a ROS graph from now on (None: stop relaying)."""
        self._graph = graph
        self._graph_subscribed.clear()
        self._graph_advertised.clear()
        self._graph_refused.clear()
        if graph is None:
            return
        for topic in self._subscribers:
            self._graph_subscribe(None, topic, None)

    def topics(self) -> dict[str, str]:
        """Every known topic and its type: the robot's, the clients' and the ROS graph's."""
        if self._graph is None:
            return dict(self._topic_types)
        return {**self._graph.topic_types(), **self._topic_types}

    def services(self) -> dict[str, str]:
        """Every service and its type: the server's and the clients' advertised ones."""
        listed = {name: type_name for name, (type_name, _) in self._services.items()}
        listed.update({name: type_name for name, (_, type_name) in self._providers.items()})
        return listed

    # ---- connections ----------------------------------------------------------------------

    def connect(self, session: Session) -> None:
        """Register a new client."""
        self.sessions.add(session)

    def disconnect(self, session: Session) -> None:
        """Forget a client: its subscriptions, advertisements, services and pending calls."""
        self.sessions.discard(session)
        for topic in list(session.subscriptions):
            self._drop_subscription(session, topic)
        for topic in list(session.advertised):
            self._drop_advertisement(session, topic)
        for service in list(session.services):
            self._providers.pop(service, None)
        for call_id, call in list(self._pending.items()):
            if call.caller is session:
                del self._pending[call_id]
            elif call.provider is session:
                del self._pending[call_id]
                self._answer_failure(call.caller, call.caller_id, call.service,
                                     f"service provider for {call.service} disconnected")

    # ---- input ----------------------------------------------------------------------------

    def handle(self, session: Session, frame: Frame) -> None:
        """Act on one incoming WebSocket message from ``session``."""
        message: Any = None
        try:
            if isinstance(frame, bytes):
                raise ProtocolError("binary frames are not accepted; send JSON text")
            try:
                message = parse_json(frame)
            except ValueError as error:
                raise ProtocolError(f"invalid JSON: {error}") from None
            if not isinstance(message, dict):
                raise ProtocolError(f"expected a JSON object, got {type(message).__name__}")
            op = check_fields(message)
            name = message.get("topic", message.get("service"))
            if isinstance(name, str):
                try:
                    access.check(session, op, name)
                except access.AccessError as denied:
                    if op != "call_service":
                        raise BridgeError(str(denied)) from None
                    log.warning("client %s: %s", session.peer, denied)
                    self._answer_failure(session, message.get("id"), name, str(denied))
                    return
            self._handlers[op](session, message)
        except (ProtocolError, BridgeError, ConfigError) as error:
            self.report(session, str(error), message)

    def report(self, session: Session, reason: str, message: Any = None) -> None:
        """Log an error and, for a client that asked with set_level, send it as a status.

        A reason longer than ``MAX_REASON_CHARS`` is cut: it may quote the client's input.
        """
        reason = shorten(reason)
        log.warning("client %s: %s", session.peer, reason)
        level = session.status_level
        if level is not None and STATUS_LEVELS.index(level) <= STATUS_LEVELS.index("error"):
            status: dict[str, Any] = {"op": "status", "level": "error", "msg": reason}
            if isinstance(message, dict) and "id" in message:
                status["id"] = message["id"]
            session.reply(status)

    # ---- topics ---------------------------------------------------------------------------

    def _known_type(self, topic: str, type_name: str) -> str:
        """Check ``type_name`` against what ``topic`` is known to carry; return it normalised."""
        try:
            normalized = normalize_type(type_name)
        except ValueError as error:
            raise BridgeError(f"{topic}: {error}") from None
        known = self._topic_types.get(topic)
        if known is not None and known != normalized:
            raise BridgeError(f"{topic} carries {known}, not {normalized}")
        return normalized

    def _advertise(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        type_name = self._known_type(topic, message["type"])
        self._topic_types[topic] = type_name
        session.advertised[topic] = type_name
        self._graph_advertise(session, topic, type_name)

    def _graph_advertise(self, session: Session, topic: str, type_name: str) -> None:
        """Publish ``topic`` on the graph too; a failure leaves client-to-client relay working."""
        if self._graph is None or topic in self._graph_advertised | self._graph_refused:
            return
        try:
            self._graph.advertise(topic, type_name)
        except BridgeError as error:
            self._graph_refused.add(topic)  # said once, not at every publish
            self.report(session, f"{error}; {topic} is relayed between clients only")
            return
        self._graph_advertised.add(topic)

    def _unadvertise(self, session: Session, message: dict[str, Any]) -> None:
        self._drop_advertisement(session, message["topic"])

    def _drop_advertisement(self, session: Session, topic: str) -> None:
        if session.advertised.pop(topic, None) is None:
            return
        still_used = topic in {spec.name for spec in ROBOT_TOPICS} or any(
            topic in other.advertised for other in self.sessions)
        if not still_used:
            self._topic_types.pop(topic, None)
            self._latched.pop(topic, None)
        if self._graph is not None and not any(
                topic in other.advertised for other in self.sessions):
            self._graph_refused.discard(topic)
            if topic in self._graph_advertised:
                self._graph_advertised.discard(topic)
                self._graph.unadvertise(topic)

    def _publish(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        if topic not in session.advertised and topic not in self._topic_types:
            raise BridgeError(f"publish to {topic}: advertise it first (type unknown)")
        msg = message["msg"]
        if topic == CMD_VEL.name:
            self._on_cmd_vel(msg)
        encoded = _Encoded(topic, msg)
        if message.get("latch"):
            self._latched[topic] = encoded
        self._deliver(topic, encoded)
        if self._graph is not None:
            if topic not in self._graph_advertised:
                type_name = session.advertised.get(topic) or self._topic_types.get(topic)
                if type_name is not None:
                    self._graph_advertise(session, topic, type_name)
            if topic in self._graph_advertised:
                self._graph.publish(topic, msg)

    def publish(self, topic: str, msg: Any, latch: bool = False) -> None:
        """Send a message the simulator publishes to every subscriber of ``topic``."""
        encoded = _Encoded(topic, msg)
        if latch:
            self._latched[topic] = encoded
        self._deliver(topic, encoded)

    def _deliver(self, topic: str, encoded: _Encoded) -> None:
        now = self._clock()
        for session in self._subscribers.get(topic, ()):
            subscription = session.subscriptions[topic]
            throttle_ms, queue_length = subscription.effective()
            gap_s = now - subscription.last_sent_s
            if throttle_ms > 0 and gap_s < throttle_ms / 1000.0 - THROTTLE_JITTER_S:
                continue
            subscription.last_sent_s = now
            session.outbox.put_topic(topic, encoded.frame(subscription.compression),
                                     queue_length)

    def _subscribe(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        if message.get("type"):
            self._known_type(topic, message["type"])
        compression = message.get("compression", "none")
        if compression not in COMPRESSIONS:
            raise BridgeError(f"subscribe {topic}: unknown compression '{compression}' "
                              f"(use one of {', '.join(COMPRESSIONS)})")
        throttle_ms = float(message.get("throttle_rate", 0))
        queue_length = int(message.get("queue_length", 0))
        if not math.isfinite(throttle_ms) or throttle_ms < 0 or queue_length < 0:
            raise BridgeError(f"subscribe {topic}: throttle_rate and queue_length must be >= 0")
        subscription = session.subscriptions.setdefault(topic, Subscription())
        sub_id = message.get("id")
        subscription.throttle_ms[sub_id] = throttle_ms
        subscription.queue_length[sub_id] = queue_length
        if compression == "cbor":
            subscription.compression = "cbor"
        self._subscribers.setdefault(topic, set()).add(session)
        self._graph_subscribe(session, topic, message.get("type") or None)
        latched = self._latched.get(topic)
        if latched is not None:
            _, length = subscription.effective()
            session.outbox.put_topic(topic, latched.frame(subscription.compression), length)

    def _unsubscribe(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        subscription = session.subscriptions.get(topic)
        if subscription is None:
            return
        if "id" in message and message["id"] in subscription.throttle_ms:
            del subscription.throttle_ms[message["id"]]
            del subscription.queue_length[message["id"]]
            if subscription.throttle_ms:
                return
        self._drop_subscription(session, topic)

    def _drop_subscription(self, session: Session, topic: str) -> None:
        session.subscriptions.pop(topic, None)
        session.outbox.discard_topic(topic)
        subscribers = self._subscribers.get(topic)
        if subscribers is not None:
            subscribers.discard(session)
            if not subscribers:
                del self._subscribers[topic]
                if self._graph is not None and topic in self._graph_subscribed:
                    self._graph_subscribed.discard(topic)
                    self._graph.unsubscribe(topic)

    def _graph_subscribe(self, session: Session | None, topic: str,
                         type_name: str | None) -> None:
        """Also relay ``topic`` from the graph, unless the robot publishes it here."""
        if self._graph is None or topic in self._owned or topic in self._graph_subscribed:
            return
        known = type_name or self._topic_types.get(topic)
        try:
            self._graph.subscribe(topic, normalize_type(known) if known else None)
        except BridgeError as error:
            if session is not None:
                self.report(session, f"{error}; {topic} is relayed between clients only")
            return
        self._graph_subscribed.add(topic)

    # ---- services -------------------------------------------------------------------------

    def _call_service(self, session: Session, message: dict[str, Any]) -> None:
        service, call_id = message["service"], message.get("id")
        args = message.get("args", {})
        if service in self._providers:
            self._forward_call(session, call_id, service, args)
            return
        if service not in self._services:
            self._answer_failure(session, call_id, service, f"Service {service} does not exist")
            return
        _, handler = self._services[service]
        if isinstance(args, list):
            if args:
                self._answer_failure(session, call_id, service,
                                     f"{service}: args must be an object of named fields")
                return
            args = {}
        try:
            values = handler(args, session)
        except (ServiceError, BridgeError, ConfigError) as error:
            reason = shorten(str(error))
            log.warning("client %s: %s failed: %s", session.peer, service, reason)
            self._answer_failure(session, call_id, service, reason)
            return
        response: dict[str, Any] = {"op": "service_response", "service": service,
                                    "values": dict(values), "result": True}
        if call_id is not None:
            response["id"] = call_id
        session.reply(response)

    def _answer_failure(self, session: Session, call_id: Any, service: str, reason: str) -> None:
        response: dict[str, Any] = {"op": "service_response", "service": service,
                                    "values": reason, "result": False}
        if call_id is not None:
            response["id"] = call_id
        session.reply(response)

    def _forward_call(self, caller: Session, caller_id: Any, service: str, args: Any) -> None:
        provider, _ = self._providers[service]
        self._call_counter += 1
        forward_id = f"service_request:{service}:{self._call_counter}"
        self._pending[forward_id] = _PendingCall(caller, caller_id, service, provider,
                                                 self._clock() + self._service_timeout_s)
        provider.reply({"op": "call_service", "id": forward_id, "service": service,
                        "args": args})

    def _service_response(self, session: Session, message: dict[str, Any]) -> None:
        call = self._pending.get(str(message.get("id")))
        if call is None or call.provider is not session:
            raise BridgeError(f"service_response for {message['service']}: no call "
                              f"with id {message.get('id')!r} is waiting for it")
        del self._pending[str(message["id"])]
        response: dict[str, Any] = {"op": "service_response", "service": call.service,
                                    "values": message.get("values", {}),
                                    "result": message["result"]}
        if call.caller_id is not None:
            response["id"] = call.caller_id
        if call.caller in self.sessions:
            call.caller.reply(response)

    def expire_calls(self) -> None:
        """Fail calls to client-provided services that waited longer than the timeout."""
        now = self._clock()
        for call_id, call in list(self._pending.items()):
            if now >= call.deadline_s:
                del self._pending[call_id]
                self._answer_failure(call.caller, call.caller_id, call.service,
                                     f"{call.service} did not answer within "
                                     f"{self._service_timeout_s:g} s")

    def _advertise_service(self, session: Session, message: dict[str, Any]) -> None:
        service = message["service"]
        if service in self._services:
            raise BridgeError(f"{service} is provided by the simulator")
        try:
            type_name = normalize_service_type(message["type"])
        except ValueError as error:
            raise BridgeError(f"{service}: {error}") from None
        previous = self._providers.get(service)
        if previous is not None:
            previous[0].services.pop(service, None)
        self._providers[service] = (session, type_name)
        session.services[service] = type_name

    def _unadvertise_service(self, session: Session, message: dict[str, Any]) -> None:
        service = message["service"]
        if session.services.pop(service, None) is not None:
            self._providers.pop(service, None)

    def _set_level(self, session: Session, message: dict[str, Any]) -> None:
        level = message["level"]
        if level not in STATUS_LEVELS:
            raise BridgeError(f"set_level: unknown level '{level}' "
                              f"(use one of {', '.join(STATUS_LEVELS)})")
        session.status_level = level

