"""The bridge's port to a ROS 2 graph (``websim serve --ros``): topics reach beyond the clients.

A subscription to a topic the simulator does not publish also subscribes on the graph, and
what clients publish (``/cmd_vel`` included) is also published there. The graph's messages
come back through ``Bridge.publish``. ``Graph`` is the only way out; this module imports no
ROS (the rclpy side is ``rosbridge.graph.relay.GraphRelay``). Without a graph attached every
method does nothing.

The capabilities reach the graph only through this port (``BridgeContext.graph``), and the
port knows no capability: what it must know of them (the topics clients subscribe to) it is
given as a callable.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any, Protocol

from rosbridge.core.errors import BridgeError
from rosbridge.core.session import Session
from rosbridge.msgs.values import normalize_type


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

    def service_types(self) -> Mapping[str, str]:
        """The services on the graph and their types (``pkg/srv/Type``)."""

    def nodes(self) -> Mapping[str, tuple[list[str], list[str], list[str]]]:
        """Each node on the graph (full name): (topics it publishes, subscribes, services)."""

    def call_service(self, service: str, type_name: str | None, args: Mapping[str, Any],
                     answer: Callable[[bool, Any], None]) -> None:
        """Call a graph service; ``answer(ok, values_or_reason)`` later, on this thread.

        ``type_name`` None: the graph does not show it yet; wait for it a moment.
        """

    def offer_service(self, service: str, type_name: str,
                      forward: Callable[[Mapping[str, Any], Callable[[bool, Any], None]],
                                        None]) -> None:
        """Offer a client's service on the graph; requests go to ``forward(args, answer)``."""

    def withdraw_service(self, service: str) -> None:
        """Stop offering a client's service on the graph."""


class GraphPort:
    """One bridge's port to a ROS 2 graph; errors go back to the client that caused them.

    Args:
        relayed_topics: the topics to relay from a graph once one is attached: those clients
            subscribe to that the simulator does not publish.
    """

    def __init__(self, relayed_topics: Callable[[], Iterable[str]] = tuple) -> None:
        self._relayed_topics = relayed_topics
        self._graph: Graph | None = None
        self._subscribed: set[str] = set()
        self._advertised: dict[str, str] = {}
        """Each topic published on the graph, and its type there (the first advertised)."""
        self._refused: set[tuple[str, str]] = set()
        """(topic, type) the graph refused, said once: relayed between clients only."""

    def attach(self, graph: Graph | None) -> None:
        """Relay to and from ``graph`` from now on (None: stop relaying)."""
        self._graph = graph
        self._subscribed.clear()
        self._advertised.clear()
        self._refused.clear()
        if graph is not None:
            for topic in list(self._relayed_topics()):
                self.subscribe(None, topic, None)

    @property
    def attached(self) -> bool:
        """Whether a graph is attached (``--ros``)."""
        return self._graph is not None

    def topic_types(self) -> Mapping[str, str]:
        """The graph's topics and types (none without a graph)."""
        return {} if self._graph is None else self._graph.topic_types()

    def subscribe(self, session: Session | None, topic: str, type_name: str | None) -> None:
        """Also relay ``topic`` from the graph (one the simulator does not publish).

        ``session``: the client that subscribed, told if the graph refuses (None: nobody).
        """
        if self._graph is None or topic in self._subscribed:
            return
        try:
            self._graph.subscribe(topic, normalize_type(type_name) if type_name else None)
        except BridgeError as error:
            if session is not None:
                session.report(f"{error}; {topic} is relayed between clients only")
            return
        self._subscribed.add(topic)

    def unsubscribe(self, topic: str) -> None:
        """The last client subscription to ``topic`` ended."""
        if self._graph is not None and topic in self._subscribed:
            self._subscribed.discard(topic)
            self._graph.unsubscribe(topic)

    def advertise(self, session: Session, topic: str, type_name: str) -> None:
        """Publish ``topic`` on the graph too; a failure leaves client-to-client relay working.

        A topic is published on the graph as one type, the first advertised; a client's
        other type on it (a topic that carries several: the robot's /cmd_vel) stays with
        the clients and the robot, and that client is told once.
        """
        if self._graph is None or (topic, type_name) in self._refused:
            return
        graph_type = self._advertised.get(topic)
        if graph_type is not None:
            if graph_type != type_name:
                self._refused.add((topic, type_name))
                session.report(f"{topic} is published on the ROS graph as {graph_type}; "
                               f"{type_name} is relayed between clients only")
            return
        try:
            self._graph.advertise(topic, type_name)
        except BridgeError as error:
            self._refused.add((topic, type_name))  # said once, not at every publish
            session.report(f"{error}; {topic} is relayed between clients only")
            return
        self._advertised[topic] = type_name

    def unadvertise(self, topic: str) -> None:
        """The last client advertisement of ``topic`` ended."""
        if self._graph is None:
            return
        self._refused = {refused for refused in self._refused if refused[0] != topic}
        if self._advertised.pop(topic, None) is not None:
            self._graph.unadvertise(topic)

    def publish(self, session: Session, topic: str, type_name: str, msg: Any) -> None:
        """A client published ``msg`` on ``topic``: publish it on the graph too."""
        if self._graph is None:
            return
        self.advertise(session, topic, type_name)
        if self._advertised.get(topic) == type_name:
            self._graph.publish(topic, msg)

    # ---- services -------------------------------------------------------------------------

    def service_types(self) -> Mapping[str, str]:
        """The graph's services and types (none without a graph)."""
        return {} if self._graph is None else self._graph.service_types()

    def nodes(self) -> Mapping[str, tuple[list[str], list[str], list[str]]]:
        """The graph's nodes: (published topics, subscribed topics, services) each."""
        return {} if self._graph is None else self._graph.nodes()

    def call_service(self, service: str, args: Mapping[str, Any],
                     answer: Callable[[bool, Any], None]) -> bool:
        """Call ``service`` on the graph; False: there is no graph.

        A service the graph does not show yet is waited for a moment (a node just started);
        ``answer`` then says it does not exist, as rosbridge does.

        Raises:
            BridgeError: the request does not fit the service's type, or it is not installed.
        """
        if self._graph is None:
            return False
        self._graph.call_service(service, self._graph.service_types().get(service), args,
                                 answer)
        return True

    def offer_service(self, session: Session, service: str, type_name: str,
                      forward: Callable[[Mapping[str, Any], Callable[[bool, Any], None]],
                                        None]) -> None:
        """Offer a client's service on the graph too; a failure leaves it to clients only."""
        if self._graph is None:
            return
        try:
            self._graph.offer_service(service, type_name, forward)
        except BridgeError as error:
            session.report(f"{error}; {service} is offered to clients only")

    def withdraw_service(self, service: str) -> None:
        """A client's service is gone: withdraw it from the graph."""
        if self._graph is not None:
            self._graph.withdraw_service(service)
