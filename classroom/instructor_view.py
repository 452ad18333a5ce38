"""The instructor's root connection to a class: every robot under ``/NAME/``.

As in a ROS 2 multi-robot graph, robot alice's topics and services appear as ``/alice/odom``,
``/alice/reset_simulation``, ``/alice/virtual_robot/set_parameters``. The view is a hub for
one connection (``server.Hub``): an operation naming ``/alice/...`` is handed, with the name
un-prefixed, to an admin session of its own on alice's bridge, whose outbox forwards every
frame back with the names prefixed. So the robots' bridges need to know nothing of it, and
whatever the instructor holds on a robot is released when the connection goes.

At the root itself: ``/websim/robots`` (no args) lists the robots' names. CBOR is not
offered on this view (frames are rewritten as text).
"""

from __future__ import annotations

import json
from typing import Any

from classroom.registry import Classroom
from rosbridge.core.bridge import Bridge
from rosbridge.core.encoding import parse_json, to_json
from rosbridge.core.errors import BridgeError
from rosbridge.core.outbox import Frame, Frames, Outbox
from rosbridge.core.schema import NAME_FIELDS, ProtocolError, read_operation, resolve_name
from rosbridge.core.session import Session

ROBOTS_SERVICE = "/websim/robots"
"""At the root: ``{names: [...]}``, the class's robots."""


class PrefixingOutbox(Outbox):
    """An outbox that forwards every frame to another, topic and service names prefixed.

    Args:
        target: the instructor connection's own outbox.
        prefix: ``/NAME``.
    """

    def __init__(self, target: Outbox, prefix: str) -> None:
        super().__init__()
        self._target = target
        self._prefix = prefix

    def put_topic(self, topic: str, frame: Frames, queue_length: int) -> None:
        """Forward a topic frame as ``/NAME/topic`` (JSON frames only on this view)."""
        if not isinstance(frame, str):  # CBOR, or fragments: not offered on this view
            return
        marker = f'"topic":{json.dumps(topic)}'
        renamed = frame.replace(marker, f'"topic":{json.dumps(self._prefix + topic)}', 1)
        self._target.put_topic(self._prefix + topic, renamed, queue_length)

    def put_reply(self, frame: Frames) -> None:
        """Forward a reply with its service or topic name prefixed."""
        if not isinstance(frame, str):
            return
        message = json.loads(frame)
        for key in ("service", "topic"):
            if isinstance(message.get(key), str):
                message[key] = self._prefix + message[key]
        self._target.put_reply(to_json(message))

    def discard_topic(self, topic: str) -> None:
        """Forget the forwarded frames of a topic."""
        self._target.discard_topic(self._prefix + topic)

    def send_now(self) -> None:
        """Have the instructor's connection write what waits now."""
        self._target.send_now()


class InstructorView:
    """One instructor connection's view of every robot of a class.

    Args:
        classroom: the class.
    """

    def __init__(self, classroom: Classroom) -> None:
        self._classroom = classroom
        self._root: Session | None = None
        self._inner: dict[str, tuple[Bridge, Session]] = {}

    def connect(self, session: Session) -> None:
        """The instructor's connection (it has the admin token)."""
        self._root = session

    def disconnect(self, session: Session) -> None:
        """Release everything the instructor held on every robot."""
        for bridge, inner in self._inner.values():
            bridge.disconnect(inner)
        self._inner.clear()
        self._root = None

    def handle(self, session: Session, frame: Frame) -> None:
        """Route one frame to the robot its name names; never raises."""
        message: Any = None
        try:
            op, message = read_operation(frame, parse_json)
            if op == "fragment":  # put together here, then routed as one frame
                text = session.fragments.add(message)
                if text is not None:
                    self.handle(session, text)
                return
            message.pop("fragment_size", None)  # rewritten as text: not fragmented either
            field = NAME_FIELDS.get(op)
            if field is None:  # set_level, auth: for every robot this view touches
                if op == "set_level":
                    session.status_level = message["level"]
                for bridge, inner in self._inner.values():
                    bridge.handle(inner, to_json(message))
                return
            name = message[field]
            if op == "call_service" and name == ROBOTS_SERVICE:
                self._robots(session, message)
                return
            robot, _, rest = name.lstrip("/").partition("/")  # robot names: a-z 0-9 _ -
            bridge, inner = self._robot(session, robot)
            if not rest:
                raise BridgeError(f"'{name[:80]}': name a robot's topic or service, "
                                  f"/{robot}/NAME")
            message[field] = resolve_name(f"/{rest}")
            message.pop("compression", None)  # rewritten as text: no CBOR on this view
            bridge.handle(inner, to_json(message))
        except (ProtocolError, BridgeError) as error:
            session.refuse(str(error), message)

    def _robot(self, session: Session, robot: str) -> tuple[Bridge, Session]:
        held = self._inner.get(robot)
        if held is not None:
            return held
        host = self._classroom.get(robot) if robot in self._classroom.students else None
        if host is None:
            raise BridgeError(f"no robot named '{robot[:40]}' in this class "
                              "(/websim/robots lists them)")
        inner = Session(session.peer, True, PrefixingOutbox(session.outbox, f"/{robot}"),
                        limits=session.limits)
        inner.status_level = session.status_level
        host.bridge.connect(inner)
        self._inner[robot] = (host.bridge, inner)
        return host.bridge, inner

    def _robots(self, session: Session, message: dict[str, Any]) -> None:
        response: dict[str, Any] = {"op": "service_response", "service": ROBOTS_SERVICE,
                                    "values": {"names": [name for name, _ in self._classroom]},
                                    "result": True}
        if "id" in message:
            response["id"] = message["id"]
        session.reply(response)
