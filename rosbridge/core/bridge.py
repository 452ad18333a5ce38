"""The rosbridge v2 protocol for one robot, without I/O: frames in, frames queued in outboxes.

Pull-style, as a Sans-I/O protocol: every entry point (``handle``, ``handle_operation``,
``publish``, ``publish_many``, ``disconnect``) returns who must be written (a ``Flush``: the
clients closing a loop first), and the transport writes it; the bridge never writes to a
socket nor calls the transport.

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

An in-process endpoint (a robot's) is attached like a client of the hub: it subscribes
/cmd_vel and publishes its topics through ``topics``. A bridge holds no module-level state:
many can run in one process, one per robot.

Errors never close the connection or change anything else: a failed ``call_service`` gets a
``service_response`` with ``result: false`` and the reason in ``values``; any other error is
logged and, for a client that asked with ``set_level``, sent as a ``status`` message. An
unexpected exception in a handler is a fault (``faults``): logged once, counted, and the
bridge goes on.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
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
from rosbridge.core.limits import ClientLimits, LatchedBytes
from rosbridge.core.outbox import Frame
from rosbridge.core.schema import NAME_FIELDS, ProtocolError, read_operation, resolve_name
from rosbridge.core.session import Flush, Session, take_flush
from rosbridge.msgs.checks import MessageError

__all__ = ["Bridge", "BridgeError", "Flush", "Graph", "ServiceError", "Session"]

Handler = Callable[[Session, dict[str, Any]], None]


class Bridge:
    """The rosbridge hub for one simulated robot and its clients.

    Args:
        clock: the clock of throttles, service timeouts and ``cbor-raw`` stamps (default:
            wall time).
        refusals: the errors of the bridge's owner that refuse an operation with a reason
            for the client (a robot's invalid command or parameter), besides the bridge's
            own ``BridgeError`` and ``MessageError``.
        reserved_namespaces: the namespaces of the owner's own nodes (``"/virtual_robot/"``),
            in which clients may not offer services or actions.
        drive_rules: what changes the owner's robot, which a client without the drive right
            (``Session.may_drive``) may not do; None: every client may.
        service_timeout_s: how long a call to a client-provided service may take.
        faults: where unexpected exceptions are recorded (default: a new record).
        latched: the pool clients' latched messages are counted in (its robot's, within
            its server's: ``LatchedBytes.for_robot``; default: one of the default size).

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
                 refusals: tuple[type[Exception], ...] = (),
                 reserved_namespaces: tuple[str, ...] = (),
                 drive_rules: access.DriveRules | None = None,
                 latched: LatchedBytes | None = None) -> None:
        self.reserved_namespaces = reserved_namespaces
        """Where clients may not offer services or actions: the owner's own nodes'."""
        self.drive_rules = drive_rules
        """What a client needs the drive right for (None: nothing)."""
        self.clock: Clock = WallClock() if clock is None else clock
        self.refusals: tuple[type[Exception], ...] = (BridgeError, MessageError, *refusals)
        self.faults = faults or Faults()
        self.graph = GraphPort(lambda: self.topics.relayed_topics())
        self.latched = latched or LatchedBytes.for_server(ClientLimits()).for_robot()
        """What clients' latched messages on this bridge hold (bytes)."""
        self._context = BridgeContext(self.clock, self.faults, self.refusals, self.graph,
                                      self.latched)
        self.sessions: set[Session] = self._context.sessions
        self.topics = Topics(self._context)
        self.services = Services(self._context, service_timeout_s)
        self.actions = Actions(self._context)
        self._leaving: list[Callable[[Session], None]] = []
        self._handlers: dict[str, Handler] = {
            **self.topics.handlers(), **self.services.handlers(), **self.actions.handlers(),
            "set_level": self._set_level, "auth": lambda session, message: None,
            "fragment": self._fragment,
        }

    # ---- what in-process endpoints use ------------------------------------------------------

    def publish(self, topic: str, msg: Any, latch: bool = False,
                type_name: str | None = None) -> Flush:
        """Queue an in-process message (the robot's, the graph's) for ``topic``'s subscribers.

        ``type_name``: its type as its publisher knows it (the ROS graph's messages carry
        theirs); None: the type ``topic`` is known to carry (the robot's own topics).

        Returns:
            who must be written now (``Flush``).
        """
        self.topics.publish(topic, msg, latch, type_name)
        return self.take_flush()

    def publish_many(self, messages: list[tuple[str, Any]],
                     tick_s: float | None = None) -> Iterator[Flush]:
        """Queue one tick's in-process messages; each client gets its share in one write.

        A generator, to be run to its end, writing each ``Flush`` it yields before asking for
        the next: first the clients closing a loop (their frames queued, the watchers' not
        yet), then everyone else. ``tick_s``: when the tick was due (``clock.monotonic_s``),
        for throttles.
        """
        for _ in self.topics.publish_many(messages, tick_s):
            yield self.take_flush()
        yield self.take_flush()

    def on_disconnect(self, forget: Callable[[Session], None]) -> None:
        """Have ``forget(session)`` called when a client leaves, after the capabilities forgot it.

        For an in-process endpoint that holds something per client (the TF republisher's
        republications), so that it is freed when its client leaves.
        """
        self._leaving.append(forget)

    def take_flush(self) -> Flush:
        """Who must be written for what was queued since the last call returned its ``Flush``.

        Every entry point returns it; this is for what the bridge did on another's behalf in
        between (a ROS graph's answer, ``services.expire``).
        """
        return take_flush(self._context.ready, self._context.closing)

    def topic_types(self) -> dict[str, str]:
        """Every known topic and its type: the robot's, the clients' and the ROS graph's."""
        return {**self.graph.topic_types(), **self.topics.types()}

    # ---- connections ----------------------------------------------------------------------

    def connect(self, session: Session) -> None:
        """Register a new client: from now on its frames are noted in this bridge's flushes."""
        self.sessions.add(session)
        session.ready = self._context.ready

    def disconnect(self, session: Session) -> Flush:
        """Forget a client: its subscriptions, advertisements, services, actions and calls.

        Returns:
            who must be written: the other clients told of what it held (failed calls).
        """
        self.sessions.discard(session)
        self.topics.disconnect(session)
        self.services.disconnect(session)
        self.actions.disconnect(session)
        for forget in self._leaving:
            try:
                forget(session)
            except Exception as error:  # an endpoint's bug must not keep the client's state
                self.faults.record("forgetting a client", error)
        self._context.ready.pop(session, None)
        self._context.closing.pop(session, None)
        return self.take_flush()

    # ---- input ----------------------------------------------------------------------------

    def handle(self, session: Session, frame: Frame) -> Flush:
        """Act on one incoming WebSocket message from ``session``; never raises.

        Returns:
            who must be written (``Flush``): the clients closing a loop first.
        """
        self._handle(session, frame, reassembled=False)
        return self.take_flush()

    def handle_operation(self, session: Session, op: str, message: dict[str, Any]) -> Flush:
        """Act on one operation already read (``schema.read_operation``); never raises.

        For a hub that reads frames itself (the instructor's view of a class): ``message``
        is taken as the operation's validated fields, and ``session.frame_bytes`` as the size
        it arrived in.

        Returns:
            who must be written (``Flush``): the clients closing a loop first.
        """
        self._operate(session, op, message, reassembled=False)
        return self.take_flush()

    def _handle(self, session: Session, frame: Frame, *, reassembled: bool) -> None:
        """Read one frame and act on it; ``reassembled``: the text of a fragmented message."""
        session.frame_bytes = len(frame)
        if session.fragments:
            for reason in session.fragments.expire():
                session.report(reason)
        try:
            op, message = read_operation(frame, parse_json)
        except ProtocolError as error:
            session.refuse(str(error), error.message)
            return
        except Exception as error:  # a bug must not stop the bridge: record it, go on
            self.faults.record(f"handling {_op_of(None)}", error)
            session.refuse(f"internal error handling {_op_of(None)}: {type(error).__name__}",
                           None)
            return
        self._operate(session, op, message, reassembled=reassembled)

    def _operate(self, session: Session, op: str, message: dict[str, Any], *,
                 reassembled: bool) -> None:
        """Resolve, authorise and dispatch one operation; errors go back to ``session``."""
        try:
            if reassembled and op == "fragment":
                raise ProtocolError("a fragmented message cannot itself be a fragment")
            if "fragment_size" in message:  # any op sets it (rosbridge)
                session.fragment_size = message["fragment_size"]
            name_field = NAME_FIELDS.get(op)
            if name_field is not None:
                name = message[name_field] = resolve_name(message[name_field])
                try:
                    access.check(session, op, name, self.reserved_namespaces,
                                 self.drive_rules)
                except access.AccessError as denied:
                    raise BridgeError(str(denied)) from None
            self._handlers[op](session, message)
        except ProtocolError as error:
            session.refuse(str(error), message)
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
            self._handle(session, text, reassembled=True)


def _op_of(message: Any) -> str:
    op = message.get("op") if isinstance(message, dict) else None
    return op[:40] if isinstance(op, str) else "a message"
