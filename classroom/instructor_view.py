"""The instructor's root connection to a class: every robot under ``/NAME/``.

As in a ROS 2 multi-robot graph, robot alice's topics and services appear as ``/alice/odom``,
``/alice/reset_simulation``, ``/alice/virtual_robot/set_parameters``. The view is a hub for
one connection (``connection.Hub``): it reads each frame once, and an operation naming
``/alice/...`` is handed, parsed and with the name un-prefixed, to an admin session of its
own on alice's bridge (``Bridge.handle_operation``). That session shares the connection's
outbox and has the namespace ``/alice`` (``Session.namespace``): the bridge prefixes the names
of what it sends in the messages, before they are encoded. So the robots' bridges need to
know nothing of the view, and whatever the instructor holds on a robot is released when the
connection goes.

At the root itself: ``/websim/robots`` (no args) lists the robots' names, and
``/websim/class_status`` (no args) every robot's status at once (``RobotHost.status``), which
the dashboard asks for twice a second: one answer of a fixed size per robot, however many
clients the robots have, so a class of 100 costs one small call, not 100. CBOR is not offered
on this view, nor fragmented replies: every frame to it is JSON text.
"""

from __future__ import annotations

from typing import Any

from classroom.registry import Classroom
from rosbridge.core.bridge import Bridge
from rosbridge.core.encoding import parse_json
from rosbridge.core.errors import BridgeError
from rosbridge.core.outbox import Frame
from rosbridge.core.schema import NAME_FIELDS, ProtocolError, read_operation, resolve_name
from rosbridge.core.session import Flush, Ready, Session, take_flush

ROBOTS_SERVICE = "/websim/robots"
"""At the root: ``{names: [...]}``, the class's robots."""

CLASS_STATUS_SERVICE = "/websim/class_status"
"""At the root: ``{robots: [{name, **status}]}``, every robot's ``RobotHost.status`` in the
class's order (``websim/srv/ClassStatus``)."""


class InstructorView:
    """One instructor connection's view of every robot of a class.

    Args:
        classroom: the class.
    """

    def __init__(self, classroom: Classroom) -> None:
        self._classroom = classroom
        self._root: Session | None = None
        self._inner: dict[str, tuple[Bridge, Session]] = {}
        self._ready: Ready = {}

    def connect(self, session: Session) -> None:
        """The instructor's connection (it has the admin token)."""
        self._root = session
        session.ready = self._ready

    def disconnect(self, session: Session) -> Flush:
        """Release everything the instructor held on every robot; who must be written."""
        flush = Flush()
        for bridge, inner in self._inner.values():
            flush += bridge.disconnect(inner)
        self._inner.clear()
        self._root = None
        self._ready.pop(session, None)
        return take_flush(self._ready) + flush

    def handle(self, session: Session, frame: Frame) -> Flush:
        """Route one frame to the robot its name names; never raises. Who must be written."""
        flush = self._handle(session, frame)
        return take_flush(self._ready) + flush

    def _handle(self, session: Session, frame: Frame) -> Flush:
        message: Any = None
        session.frame_bytes = len(frame)
        try:
            op, message = read_operation(frame, parse_json)
            if op == "fragment":  # put together here, then routed as one frame
                text = session.fragments.add(message)
                return Flush() if text is None else self._handle(session, text)
            message.pop("fragment_size", None)  # JSON text, not fragmented, on this view
            field = NAME_FIELDS.get(op)
            if field is None:  # set_level, auth: for every robot this view touches
                if op == "set_level":
                    session.status_level = message["level"]
                flush = Flush()
                for bridge, inner in self._inner.values():
                    inner.frame_bytes = session.frame_bytes
                    flush += bridge.handle_operation(inner, op, dict(message))
                return flush
            name = message[field]
            if op == "call_service" and name in (ROBOTS_SERVICE, CLASS_STATUS_SERVICE):
                self._answer(session, message, self._robots() if name == ROBOTS_SERVICE
                             else self._statuses())
                return Flush()
            robot, _, rest = name.lstrip("/").partition("/")  # robot names: a-z 0-9 _ -
            bridge, inner = self._robot(session, robot)
            if not rest:
                raise BridgeError(f"'{name[:80]}': name a robot's topic or service, "
                                  f"/{robot}/NAME")
            message[field] = resolve_name(f"/{rest}")
            message.pop("compression", None)  # JSON text: no CBOR on this view
            inner.frame_bytes = session.frame_bytes
            return bridge.handle_operation(inner, op, message)
        except (ProtocolError, BridgeError) as error:
            session.refuse(str(error), message)
            return Flush()

    def _robot(self, session: Session, robot: str) -> tuple[Bridge, Session]:
        held = self._inner.get(robot)
        if held is not None:
            return held
        host = self._classroom.get(robot) if robot in self._classroom.students else None
        if host is None:
            raise BridgeError(f"no robot named '{robot[:40]}' in this class "
                              "(/websim/robots lists them)")
        inner = Session(session.peer, True, session.outbox, limits=session.limits,
                        namespace=f"/{robot}")
        inner.server_admin = True  # the instructor's, on every robot
        inner.status_level = session.status_level
        host.bridge.connect(inner)
        self._inner[robot] = (host.bridge, inner)
        return host.bridge, inner

    def _robots(self) -> dict[str, Any]:
        return {"names": [name for name, _ in self._classroom]}

    def _statuses(self) -> dict[str, Any]:
        return {"robots": [{"name": name, **host.status()} for name, host in self._classroom]}

    @staticmethod
    def _answer(session: Session, message: dict[str, Any], values: dict[str, Any]) -> None:
        """The root's own service ``message`` asked for, answered with ``values``."""
        response: dict[str, Any] = {"op": "service_response", "service": message["service"],
                                    "values": values, "result": True}
        if "id" in message:
            response["id"] = message["id"]
        session.reply(response)
