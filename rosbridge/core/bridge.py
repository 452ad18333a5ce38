"""The rosbridge v2 protocol for one robot, without I/O: frames in, frames queued in outboxes.

``Bridge.handle`` takes one WebSocket message from one client, validates it against
``schema.OP_FIELDS`` (types and ranges), resolves the one name it carries
(``schema.NAME_FIELDS``), asks the allow-list (``rosbridge.core.access``) once, and dispatches it
to the capability that implements the op, as rosbridge_library splits them:

* ``capabilities.topics``: advertise, publish, subscribe, throttles, queues, latching;
* ``capabilities.services``: calls, client-provided services, timeouts;
* ``capabilities.actions``: ROS 2 action goals, client-provided actions, cancels.

They share one ``BridgeContext`` (the clients, the clock, faults, refusals and the
``GraphPort`` to a ROS 2 graph, ``websim serve --ros``), and reach each other only through
what the bridge hands them.

The robot is attached like a client of the hub (``robot_endpoint.attach``): it subscribes
/cmd_vel and publishes its topics through ``topics``. A bridge holds no module-level state:
many can run in one process, one per robot.

Errors never close the connection or change anything else: a failed ``call_service`` gets a
``service_response`` with ``result: false`` and the reason in ``values``; any other error is
logged and, for a client that asked with ``set_level``, sent as a ``status`` message. An
unexpected exception in a handler is a fault (``faults``): logged once, counted, and the
bridge goes on.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rosbridge.core import access
from rosbridge.core.capabilities.actions import Actions
from rosbridge.core.capabilities.services import SERVICE_TIMEOUT_S, Services
from rosbridge.core.capabilities.topics import Topics
from rosbridge.core.clock import Clock, WallClock
from rosbridge.core.context import BridgeContext
from rosbridge.core.encoding import parse_json
from rosbridge.core.errors import BridgeError, ServiceError
from rosbridge.core.faults import Faults
from rosbridge.core.graph_port import Graph, GraphPort
from rosbridge.core.outbox import Frame
from rosbridge.core.schema import NAME_FIELDS, ProtocolError, read_operation, resolve_name
from rosbridge.core.session import Session
from rosbridge.msgs.checks import MessageError

__all__ = ["Bridge", "BridgeError", "Graph", "ServiceError", "Session"]

Handler = Callable[[Session, dict[str, Any]], None]


class Bridge:
    """The rosbridge hub for one simulated robot and its clients.

    Args:
        clock: the clock of throttles, service timeouts and ``cbor-raw`` stamps (default:
            wall time).
        refusals: the errors of the bridge's owner that refuse an operation with a reason
            for the client (a robot's invalid command or parameter), besides the bridge's
            own ``BridgeError`` and ``MessageError``.
        service_timeout_s: how long a call to a client-provided service may take.
        faults: where unexpected exceptions are recorded (default: a new record).

    Attributes:
        sessions: the connected clients.
        topics: the topic capability (in-process endpoints publish and subscribe here).
        services: the service capability (in-process services are added here).
        actions: the action capability (``attach`` the ROS graph's actions with ``--ros``).
        graph: the port to a ROS 2 graph (``attach`` one with ``--ros``).
        faults: unexpected exceptions caught in handlers.
        clock: the bridge's clock.
        refusals: what an in-process handler raises to refuse with a reason (not a fault).
    """

    def __init__(self, clock: Clock | None = None,
                 service_timeout_s: float = SERVICE_TIMEOUT_S,
                 faults: Faults | None = None,
                 refusals: tuple[type[Exception], ...] = ()) -> None:
        self.clock: Clock = WallClock() if clock is None else clock
        self.refusals: tuple[type[Exception], ...] = (BridgeError, MessageError, *refusals)
        self.faults = faults or Faults()
        self.graph = GraphPort(lambda: self.topics.relayed_topics())
        self._context = BridgeContext(self.clock, self.faults, self.refusals, self.graph)
        self.sessions: set[Session] = self._context.sessions
        self.topics = Topics(self._context)
        self.services = Services(self._context, service_timeout_s)
        self.actions = Actions(self._context)
        self._handlers: dict[str, Handler] = {
            **self.topics.handlers(), **self.services.handlers(), **self.actions.handlers(),
            "set_level": self._set_level, "auth": lambda session, message: None,
            "fragment": self._fragment,
        }

    # ---- what in-process endpoints use ------------------------------------------------------

    def publish(self, topic: str, msg: Any, latch: bool = False) -> None:
        """Send an in-process message (the robot's, the graph's) to ``topic``'s subscribers."""
        self.topics.publish(topic, msg, latch)

    def publish_many(self, messages: list[tuple[str, Any]],
                     tick_s: float | None = None) -> None:
        """Send one tick's in-process messages; each client gets its share in one write.

        ``tick_s``: when the tick was due (``clock.monotonic_s``), for throttles.
        """
        self.topics.publish_many(messages, tick_s)

    def topic_types(self) -> dict[str, str]:
        """Every known topic and its type: the robot's, the clients' and the ROS graph's."""
        return {**self.graph.topic_types(), **self.topics.types()}

    # ---- connections ----------------------------------------------------------------------

    def connect(self, session: Session) -> None:
        """Register a new client."""
        self.sessions.add(session)

    def disconnect(self, session: Session) -> None:
        """Forget a client: its subscriptions, advertisements, services, actions and calls."""
        self.sessions.discard(session)
        self.topics.disconnect(session)
        self.services.disconnect(session)
        self.actions.disconnect(session)

    # ---- input ----------------------------------------------------------------------------

    def handle(self, session: Session, frame: Frame, *, reassembled: bool = False) -> None:
        """Act on one incoming WebSocket message from ``session``; never raises.

        ``reassembled``: ``frame`` is the text of a fragmented message, put back together.
        """
        message: Any = None
        session.frame_bytes = len(frame)
        if session.fragments:
            for reason in session.fragments.expire():
                session.report(reason)
        try:
            op, message = read_operation(frame, parse_json)
            if reassembled and op == "fragment":
                raise ProtocolError("a fragmented message cannot itself be a fragment")
            if "fragment_size" in message:  # any op sets it (rosbridge)
                session.fragment_size = message["fragment_size"]
            name_field = NAME_FIELDS.get(op)
            if name_field is not None:
                name = message[name_field] = resolve_name(message[name_field])
                try:
                    access.check(session, op, name)
                except access.AccessError as denied:
                    raise BridgeError(str(denied)) from None
            self._handlers[op](session, message)
        except ProtocolError as error:
            session.refuse(str(error), message if message is not None else error.message)
        except self.refusals as error:
            session.refuse(str(error), message)
        except Exception as error:  # a bug must not stop the bridge: record it, go on
            self.faults.record(f"handling {_op_of(message)}", error)
            session.refuse(f"internal error handling {_op_of(message)}: "
                           f"{type(error).__name__}", message)

    def report(self, session: Session, reason: str, message: Any = None) -> None:
        """Log an error and, for a client that asked with set_level, send it as a status."""
        session.report(reason, message)

    def _set_level(self, session: Session, message: dict[str, Any]) -> None:
        session.status_level = message["level"]

    def _fragment(self, session: Session, message: dict[str, Any]) -> None:
        """One ``fragment``: the message it completes is handled as any frame is."""
        text = session.fragments.add(message)
        if text is not None:
            self.handle(session, text, reassembled=True)


def _op_of(message: Any) -> str:
    op = message.get("op") if isinstance(message, dict) else None
    return op[:40] if isinstance(op, str) else "a message"
