"""``websim serve --ros``: the virtual_robot node in-process and the bridge relayed to ROS 2.

Threads: the asyncio event loop of ``websim serve`` owns the simulation and the ``Bridge``, as
without ROS; its tick loop stays the one clock, and each tick's messages go to the browser and,
through ``VirtualRobotNode.publish`` (rclpy publishers are thread-safe), onto the ROS graph.
rclpy has no asyncio executor, so a ``SingleThreadedExecutor`` spins in one background thread;
everything its callbacks do to the robot or the bridge is handed to the loop
(``loop.call_soon_threadsafe``), and whatever needs an answer (a parameter change, a reset)
waits for it there. Polling rclpy from the loop instead would add up to a poll period of
latency to every ROS message and burn CPU while idle.

Two nodes share one rclpy ``Context`` (no global state; rclpy's signal handlers stay off, the
server handles SIGINT and SIGTERM): ``virtual_robot`` and ``rosbridge_websocket``, the relay
behind ``GraphRelay``, as a real rosbridge deployment names it.

Latched topics: the relay has one rclpy subscription per topic, however many browsers
subscribe, so only the first browser would get a transient-local topic's history. Its
messages are therefore latched in the bridge (``Bridge.publish(..., latch=True)``), which
sends the newest to each later subscriber, as rosbridge gives each new client the history;
a later rclpy subscription's replay of what was already relayed is not relayed again. A
subscription's QoS follows the topic's publishers (``publisher_qos``): one made before they
were discovered (a browser subscribing to /map before the map server starts) is made again
on the next ``poll`` once they are, so the history reaches it then.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from rclpy.duration import Duration
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from rosbridge.core.errors import BridgeError
from rosbridge.graph.services import Answer, Forward, GraphServices
from rosbridge.msgs.rclpy_conversion import (
    MessageConversionError,
    PublisherFilter,
    message_class,
    to_dict,
    to_message,
)
from rosbridge.msgs.values import Message, normalize_type

log = logging.getLogger("websim.ros")

CALL_TIMEOUT_S = 2.0
"""How long an rclpy callback waits for the event loop to answer (a parameter change)."""

RELAY_DEPTH = 10
"""History depth of relay publishers, and of subscriptions to best-effort publishers
(rosbridge's default queue size): sensor streams, where the newest matters."""

RELIABLE_RELAY_DEPTH = 1000
"""History depth of a subscription to reliable publishers: what DDS may hold for the relay
while the executor thread catches up. rosbridge keeps 10, so a burst a ROS node publishes at
full speed (tens of thousands per second, faster than Python takes them) loses all but the
last ten before any client could get them; with 1000, a burst of 1000 reaches a queue_length
0 subscriber whole (benchmarks/ros_burst.py)."""

RELAY_PUBLISHER_QOS = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                                 lifespan=Duration(seconds=1))
"""The relay's publishers, as rosbridge's: a node that subscribes (transient local) within a
second of a client's message still gets it, as one that matched just after the publisher was
made (the first publish creates it)."""

T = TypeVar("T")


class LoopAccess:
    """Runs functions on the event loop that owns the robot, from any thread.

    Args:
        loop: the running loop; build this object on its thread.
        timeout_s: how long ``call`` waits.
        after: run on the loop after each function handed over (the server writes what the
            function queued for clients, at once rather than with the next tick).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop,
                 timeout_s: float = CALL_TIMEOUT_S,
                 after: Callable[[], None] | None = None) -> None:
        self._loop = loop
        self._loop_thread = threading.get_ident()
        self._timeout_s = timeout_s
        self._after = after

    def _then_after(self, fn: Callable[[], T]) -> Callable[[], T]:
        after = self._after
        if after is None:
            return fn

        def run() -> T:
            try:
                return fn()
            finally:
                after()
        return run

    def call(self, fn: Callable[[], T]) -> T:
        """Run ``fn`` on the loop and return its result.

        Raises:
            TimeoutError: the loop did not run it within the timeout (it is stopping).
        """
        fn = self._then_after(fn)
        if threading.get_ident() == self._loop_thread:
            return fn()
        future: concurrent.futures.Future[T] = concurrent.futures.Future()

        def run() -> None:
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(fn())
                except Exception as error:  # handed to the waiting thread, which re-raises
                    future.set_exception(error)

        self._loop.call_soon_threadsafe(run)
        try:
            return future.result(self._timeout_s)
        except concurrent.futures.TimeoutError:
            future.cancel()
            raise TimeoutError("the event loop did not answer") from None

    def post(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` on the loop soon; dropped if the loop has closed."""
        try:
            self._loop.call_soon_threadsafe(self._then_after(fn))
        except RuntimeError:
            log.debug("event loop closed; dropped a call")


def publisher_qos(endpoints: list[Any]) -> QoSProfile:
    """A subscription QoS that connects to every publisher in ``endpoints`` (rosbridge's rule).

    Best effort if any publisher is best effort (a reliable reader cannot match it), transient
    local if every publisher is (so late subscribers get latched messages).
    """
    reliable = all(e.qos_profile.reliability == ReliabilityPolicy.RELIABLE for e in endpoints)
    latched = bool(endpoints) and all(
        e.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for e in endpoints)
    return QoSProfile(depth=RELIABLE_RELAY_DEPTH if reliable else RELAY_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)


Deliver = Callable[[str, str, Message, bool], None]
"""``deliver(topic, type_name, msg_dict, latched)``: a message from the graph, with the type
it was received as (``pkg/msg/Type``: what its ``cbor-raw`` form is serialized as);
``latched``: its topic is transient local (every publisher's durability), so the bridge keeps
it for later subscribers."""


def publisher_key(info: Mapping[str, Any]) -> tuple[bytes, int]:
    """(publisher GID, position in its stream) of a received message's ``MessageInfo``.

    The position is the publication sequence number, or the source timestamp (ns) where the
    middleware has no sequence numbers; 0: neither is known.
    """
    gid = info.get("publisher_gid")
    number = info.get("publication_sequence_number") or info.get("source_timestamp") or 0
    return (bytes(gid["data"]) if gid else b""), int(number)


class GraphRelay:
    """The ``Graph`` the bridge relays through: rclpy publishers and subscriptions of one node.

    Its methods run on the bridge's thread (the event loop); subscription callbacks run on the
    executor thread, convert each message to a dict there and hand it to ``deliver``.

    Args:
        node: the relay node (``rosbridge_websocket``).
        deliver: gets every message from the graph (``Deliver``); it must be safe to call from
            the executor thread.
    """

    def __init__(self, node: Node, deliver: Deliver) -> None:
        self._node = node
        self._deliver = deliver
        self._subscriptions: dict[str, Any] = {}
        self._waiting: set[str] = set()
        self._publishers: dict[str, tuple[Any, Any]] = {}
        self.services: GraphServices | None = None
        """Service calls and client-provided services (set once the executor exists)."""
        self._qos: dict[str, tuple[str, QoSProfile]] = {}
        """Each subscription's type and QoS, to make it again when the publishers change."""
        self._relayed: dict[str, dict[bytes, int]] = {}
        """Per topic, per publisher GID: the position of the newest message relayed
        (``publisher_key``), kept across subscriptions so a replay of a transient-local
        history is not relayed twice; only the topic's current publishers are kept."""

    def topic_types(self) -> Mapping[str, str]:
        """Topics on the graph, each with its first type."""
        return {name: normalize_type(types[0])
                for name, types in self._node.get_topic_names_and_types() if types}

    def subscribe(self, topic: str, type_name: str | None) -> None:
        """Relay ``topic`` from the graph; without a type, as soon as one publishes it.

        Raises:
            BridgeError: the graph carries another type, or the type's package is missing.
        """
        graph_type = self.topic_types().get(topic)
        if type_name is not None and graph_type is not None and graph_type != type_name:
            raise BridgeError(f"{topic} carries {graph_type} on the ROS graph, not {type_name}")
        resolved = type_name or graph_type
        if resolved is None:
            self._waiting.add(topic)
            return
        self._create_subscription(topic, resolved)

    def _create_subscription(self, topic: str, type_name: str) -> None:
        try:
            cls = message_class(type_name)
        except MessageConversionError as error:
            raise BridgeError(str(error)) from None
        publishers = self._node.get_publishers_info_by_topic(topic)
        qos = publisher_qos(publishers)
        latched = qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
        relayed = self._relayed_from(topic, publishers)
        own = PublisherFilter(self._node, topic, self._node.get_name())
        deliver = self._deliver

        def relay(msg: Any, info: Any) -> None:
            if own.is_from(info):
                return
            gid, position = publisher_key(info)
            if position and position <= relayed.get(gid, 0):
                return  # relayed (and latched) already: a replay for a new subscription
            relayed[gid] = position
            deliver(topic, type_name, to_dict(msg), latched)

        old = self._subscriptions.pop(topic, None)
        if old is not None:
            self._node.destroy_subscription(old)
        self._subscriptions[topic] = self._node.create_subscription(cls, topic, relay, qos)
        self._qos[topic] = (type_name, qos)
        self._waiting.discard(topic)

    def _relayed_from(self, topic: str, publishers: list[Any]) -> dict[bytes, int]:
        """What was relayed of ``topic`` from its current ``publishers`` (``_relayed``)."""
        live = {bytes(endpoint.endpoint_gid) for endpoint in publishers}
        kept = {gid: position for gid, position in self._relayed.get(topic, {}).items()
                if gid in live}
        self._relayed[topic] = kept
        return kept

    def poll(self) -> None:
        """Start the subscriptions that wait for their topic; redo those whose QoS is stale.

        A subscription's QoS is stale when the topic's publishers now call for another
        (``publisher_qos``): made before they were discovered, or before they changed.
        """
        for topic, (type_name, qos) in list(self._qos.items()):
            publishers = self._node.get_publishers_info_by_topic(topic)
            wanted = publisher_qos(publishers)
            if publishers and (wanted.durability, wanted.reliability) != \
                    (qos.durability, qos.reliability):
                self._create_subscription(topic, type_name)
        if not self._waiting:
            return
        types = self.topic_types()
        for topic in sorted(self._waiting & types.keys()):
            try:
                self._create_subscription(topic, types[topic])
            except BridgeError as error:
                log.warning("cannot relay %s from the ROS graph: %s", topic, error)
                self._waiting.discard(topic)

    def unsubscribe(self, topic: str) -> None:
        """Stop relaying ``topic`` from the graph."""
        self._waiting.discard(topic)
        self._qos.pop(topic, None)
        subscription = self._subscriptions.pop(topic, None)
        if subscription is not None:
            self._node.destroy_subscription(subscription)

    def advertise(self, topic: str, type_name: str) -> None:
        """Create the graph publisher of ``topic``.

        Raises:
            BridgeError: the graph carries another type, or the type's package is missing.
        """
        graph_type = self.topic_types().get(topic)
        if graph_type is not None and graph_type != type_name:
            raise BridgeError(f"{topic} carries {graph_type} on the ROS graph, not {type_name}")
        try:
            cls = message_class(type_name)
        except MessageConversionError as error:
            raise BridgeError(str(error)) from None
        publisher = self._node.create_publisher(cls, topic, RELAY_PUBLISHER_QOS)
        self._publishers[topic] = (publisher, cls)

    def unadvertise(self, topic: str) -> None:
        """Destroy the graph publisher of ``topic``."""
        entry = self._publishers.pop(topic, None)
        if entry is not None:
            self._node.destroy_publisher(entry[0])

    def publish(self, topic: str, msg: Any) -> None:
        """Publish a client's message on the graph.

        Raises:
            BridgeError: the message does not fit the type (the field is named).
        """
        publisher, cls = self._publishers[topic]
        try:
            publisher.publish(to_message(cls, msg))
        except MessageConversionError as error:
            raise BridgeError(f"publish {topic}: {error}") from None


    # ---- services (ros_services.GraphServices does the work) ------------------------------

    def service_types(self) -> Mapping[str, str]:
        """Services on the graph and their types (none before ``services`` is set)."""
        return {} if self.services is None else self.services.service_types()

    def nodes(self) -> dict[str, tuple[list[str], list[str], list[str]]]:
        """Each node on the graph: (topics it publishes, topics it subscribes, services)."""
        node = self._node
        found: dict[str, tuple[list[str], list[str], list[str]]] = {}
        for name, namespace in node.get_node_names_and_namespaces():
            full = f"{namespace.rstrip('/')}/{name}"
            try:
                found[full] = (
                    sorted(t for t, _ in node.get_publisher_names_and_types_by_node(
                        name, namespace)),
                    sorted(t for t, _ in node.get_subscriber_names_and_types_by_node(
                        name, namespace)),
                    sorted(s for s, _ in node.get_service_names_and_types_by_node(
                        name, namespace)))
            except (_rclpy.NodeNameNonExistentError, RuntimeError):
                continue  # it left between the two questions
        return found

    def call_service(self, service: str, type_name: str | None, args: Mapping[str, Any],
                     answer: Answer) -> None:
        """Call a graph service; ``answer(ok, values_or_reason)`` on the loop."""
        if self.services is None:
            answer(False, "the ROS graph is not ready")
            return
        self.services.call(service, type_name, args, answer)

    def offer_service(self, service: str, type_name: str, forward: Forward) -> None:
        """Offer a client-provided service on the graph."""
        if self.services is not None:
            self.services.offer(service, type_name, forward)

    def withdraw_service(self, service: str) -> None:
        """Stop offering a client-provided service on the graph."""
        if self.services is not None:
            self.services.withdraw(service)
