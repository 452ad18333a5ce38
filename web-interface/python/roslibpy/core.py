"""roslibpy's API in the browser (``roslibpy.core``), over websim_browser's loop.

In the browser a program's ``import roslibpy`` finds this module (the page installs it in
Pyodide's file system), so a file written for ``pip install roslibpy`` runs unchanged:
``Ros`` (``run``, ``run_forever``, ``terminate``, ``close``, ``is_connected``, ``on_ready``,
``on``/``off``/``emit``, the rosapi queries), ``Topic`` (``subscribe``, ``unsubscribe``,
``publish``, ``advertise``, ``unadvertise``), ``Service`` (``call`` with a callback and an
errback, or blocking; ``advertise``), ``Param``, ``Message``, ``ServiceRequest``,
``ServiceResponse``, ``Header``, ``Time``, ``RosTimeoutError``. The rosbridge operations
are those roslibpy sends, field for field, and callbacks get what roslibpy gives them.

Where the browser differs: every ``Ros`` connects to the robot of the page the program runs
in (whatever address the program names: on a laptop, the address it names), with that
page's token; callbacks run while the program waits (``websim_browser``), not on a thread of
their own; ``ActionClient`` and ``roslibpy.tf`` are not here.
"""

from __future__ import annotations

import json
import time
from collections import UserDict
from collections.abc import Callable
from enum import Enum
from typing import Any

import websim_browser

__version__ = "2.1.0-websim-browser"

CONNECTION_TIMEOUT = 10
"""Seconds ``Ros.run`` and ``close`` wait by default (roslibpy's)."""

RECONNECT_FIRST_S = 1.0
RECONNECT_MAX_S = 30.0
"""A connection lost without ``close()`` is opened again after 1 s, doubling up to 30 s (as
roslibpy's reconnecting factory does), and topics and services re-register."""

REOPENED = "websim:reopened"
"""The event a ``Ros`` emits when its connection opened again (not roslibpy's)."""

_rosapi_timeout_s = [3.0]

__all__ = ["ActionClient", "Feedback", "Goal", "GoalStatus", "Header", "Message", "Param",
           "Result", "Ros", "RosTimeoutError", "Service", "ServiceException", "ServiceRequest",
           "ServiceResponse", "Time", "Topic", "set_default_transport", "set_rosapi_timeout"]


def set_rosapi_timeout(timeout: float) -> None:
    """Seconds the rosapi queries (``Ros.get_topics``...) wait for their answer."""
    _rosapi_timeout_s[0] = timeout


class RosTimeoutError(TimeoutError):
    """A blocking call got no answer in time."""


class ServiceException(Exception):  # noqa: N818 (roslibpy's name)
    """A service call failed: the bridge answered ``result: false`` (the reason inside)."""


class _Values(UserDict):  # type: ignore[type-arg]
    """A message-like dict (roslibpy's message types are ``UserDict``s too)."""

    def __init__(self, values: Any = None) -> None:
        super().__init__()
        if values is not None:
            self.update(values)


class Message(_Values):
    """A ROS message: a dict of its fields."""


class ServiceRequest(_Values):
    """A service call's request."""


class ServiceResponse(_Values):
    """A service call's response."""


class Goal(_Values):
    """An action goal."""


class Result(_Values):
    """An action result."""


class Feedback(_Values):
    """An action's feedback."""


class ActionClient:
    """The action client of roslibpy: not in the browser (the course's programs use none)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise NotImplementedError("roslibpy.ActionClient is not available in the browser: run "
                                  "this program on a laptop with pip install roslibpy")


def set_default_transport(name: str) -> None:
    """Choose roslibpy's transport: there is one here, the page's (nothing to choose)."""


class GoalStatus(Enum):
    """ROS 2 goal statuses (action_msgs/msg/GoalStatus)."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6


class Time(_Values):
    """A ROS 1 time: whole seconds and nanoseconds (``secs``, ``nsecs``)."""

    def __init__(self, secs: int | float, nsecs: int | float) -> None:
        super().__init__({"secs": _whole(secs), "nsecs": _whole(nsecs)})

    @property
    def secs(self) -> int:
        """Seconds since the epoch."""
        return int(self.data["secs"])

    @property
    def nsecs(self) -> int:
        """Nanoseconds past ``secs``."""
        return int(self.data["nsecs"])

    def is_zero(self) -> bool:
        """Whether both are 0."""
        return self.secs == 0 and self.nsecs == 0

    def to_nsec(self) -> int:
        """Nanoseconds since the epoch."""
        return self.secs * 1_000_000_000 + self.nsecs

    def to_sec(self) -> float:
        """Seconds since the epoch, as a float."""
        return self.secs + self.nsecs / 1e9

    @staticmethod
    def from_sec(seconds: float) -> Time:
        """From float seconds."""
        whole = int(seconds)
        return Time(whole, int((seconds - whole) * 1e9))

    @staticmethod
    def now() -> Time:
        """The wall clock's time (not ROS time)."""
        return Time.from_sec(time.time())


def _whole(value: int | float) -> int:
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, int):
        return value
    raise ValueError("argument must be an integer")


class Header(_Values):
    """A ROS 1 std_msgs/Header (``seq``, ``stamp``, ``frame_id``)."""

    def __init__(self, seq: int | None = None, stamp: dict[str, Any] | None = None,
                 frame_id: str | None = None) -> None:
        super().__init__({"seq": seq,
                          "stamp": Time(stamp["secs"], stamp["nsecs"]) if stamp else None,
                          "frame_id": frame_id})


def _encode(value: Any) -> Any:
    """A message's value as JSON takes it (``UserDict`` values become dicts)."""
    if isinstance(value, UserDict):
        return {key: _encode(item) for key, item in value.data.items()}
    if isinstance(value, dict):
        return {key: _encode(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_encode(item) for item in value]
    return value


class Ros:
    """A connection to rosbridge: in the browser, to this page's robot.

    Args:
        host: the bridge's host, or its whole URL (``ws://HOST:9090/robots/NAME?token=T``)
            with ``port`` None.
        port: its port.
        is_secure: wss instead of ws.
        headers: ignored (a browser cannot set a WebSocket's headers).
        transport: ignored (one transport here).
    """

    def __init__(self, host: str, port: int | None = None, is_secure: bool = False,
                 headers: Any = None, transport: Any = None) -> None:
        scheme = "wss" if is_secure else "ws"
        self.url = host if port is None else f"{scheme}://{host}:{port}"
        self._loop = websim_browser.current()
        self._id_counter = 0
        self._listeners: dict[str, list[Callable[..., Any]]] = {}
        self._on_ready: list[Callable[[], Any]] = []
        self._calls: dict[str, tuple[Callable[[Any], Any] | None,
                                     Callable[[Any], Any] | None]] = {}
        self._socket: int | None = None
        self._open = False
        self._closing = False
        self._terminated = False
        self._was_open = False
        self._retry_s = RECONNECT_FIRST_S
        self.is_connecting = False
        self.connect()

    @property
    def id_counter(self) -> int:
        """A new id for a message (1, 2, ...)."""
        self._id_counter += 1
        return self._id_counter

    @property
    def is_connected(self) -> bool:
        """Whether the connection is open."""
        return self._open

    def connect(self) -> None:
        """Open the connection (once: it reopens itself when lost)."""
        if self._open or self.is_connecting:
            return
        self.is_connecting = True
        self._closing = False
        self._socket = self._loop.open(self.url, _Socket(self))

    def close(self, timeout: float = CONNECTION_TIMEOUT) -> None:
        """Close the connection (no reopening)."""
        self._closing = True
        if self._socket is not None:
            if self._open:
                self.emit("closing")
            socket, self._socket = self._socket, None
            self._loop.close(socket)
        was_open, self._open = self._open, False
        self.is_connecting = False
        if was_open:
            self.emit("close", self)

    def run(self, timeout: float = CONNECTION_TIMEOUT) -> None:
        """Wait until the connection is open (RosTimeoutError after ``timeout`` s)."""
        if not self._loop.run_until(self._loop.clock() + timeout, lambda: self._open):
            raise RosTimeoutError("Failed to connect to ROS")

    def run_forever(self) -> None:
        """Deliver messages to the callbacks until ``terminate()``."""
        self._loop.run_until(None, lambda: self._terminated)

    def run_event_loop(self) -> None:
        """``run_forever`` (its old name)."""
        self.run_forever()

    def terminate(self) -> None:
        """Close the connection and end ``run_forever``."""
        self.close()
        self._terminated = True

    def call_in_thread(self, callback: Callable[[], Any]) -> None:
        """Run ``callback`` soon (here: when the program next waits; there are no threads)."""
        self._loop.call_later(0.0, callback)

    def call_later(self, delay: float, callback: Callable[[], Any]) -> None:
        """Run ``callback`` after ``delay`` s (when the program waits)."""
        self._loop.call_later(delay, callback)

    def on(self, event_name: str, callback: Callable[..., Any]) -> None:
        """Call ``callback`` on each ``event_name`` (a topic's name: its messages)."""
        self._listeners.setdefault(event_name, []).append(callback)

    def off(self, event_name: str, callback: Callable[..., Any] | None = None) -> None:
        """Stop calling ``callback`` (None: every callback) on ``event_name``."""
        if callback is None:
            self._listeners.pop(event_name, None)
            return
        callbacks = self._listeners.get(event_name, [])
        if callback in callbacks:
            callbacks.remove(callback)

    def emit(self, event_name: str, *args: Any) -> None:
        """Call ``event_name``'s callbacks with ``args``."""
        for callback in list(self._listeners.get(event_name, [])):
            callback(*args)

    def on_ready(self, callback: Callable[[], Any], run_in_thread: bool = True) -> None:
        """Run ``callback`` once connected (now, if connected)."""
        if self._open:
            self._loop.call_later(0.0, callback)
        else:
            self._on_ready.append(callback)

    def send_on_ready(self, message: Any) -> None:
        """Send a rosbridge message once connected (now, if connected)."""
        text = json.dumps(_encode(message))
        if self._open and self._socket is not None:
            self._loop.send(self._socket, text)
        else:
            self._on_ready.append(lambda: self._send_text(text))

    def _send_text(self, text: str) -> None:
        if self._socket is not None:
            self._loop.send(self._socket, text)

    def call_async_service(self, message: Any, callback: Callable[[Any], Any] | None,
                           errback: Callable[[Any], Any] | None) -> None:
        """Send a ``call_service`` and route its answer to ``callback`` or ``errback``."""
        self._calls[message["id"]] = (callback, errback)
        self.send_on_ready(message)

    def call_sync_service(self, message: Any, timeout: float | None) -> dict[str, Any]:
        """Send a ``call_service`` and wait for its answer.

        Returns:
            ``{"result": ServiceResponse}``, or ``{"exception": values}`` when it failed.
        """
        answer: dict[str, Any] = {}
        self.call_async_service(message, lambda response: answer.update(result=response),
                                lambda values: answer.update(exception=values))
        deadline = None if timeout is None else self._loop.clock() + timeout
        if not self._loop.run_until(deadline, lambda: bool(answer)):
            self._calls.pop(message["id"], None)
            raise RosTimeoutError(f"no answer from {message['service']} within {timeout} s")
        return answer

    def set_status_level(self, level: str, identifier: str) -> None:
        """Ask the bridge for status messages of ``level`` and above."""
        self.send_on_ready(Message({"op": "set_level", "level": level, "id": identifier}))

    def _rosapi(self, name: str, kind: str, args: dict[str, Any], key: str,
                callback: Callable[[Any], Any] | None,
                errback: Callable[[Any], Any] | None) -> Any:
        service = Service(self, f"/rosapi/{name}", f"rosapi/{kind}")
        if callback is not None:
            service.call(ServiceRequest(args), lambda response: callback(response[key]),
                         errback)
            return None
        return service.call(ServiceRequest(args), timeout=_rosapi_timeout_s[0])[key]

    def get_topics(self, callback: Callable[[Any], Any] | None = None,
                   errback: Callable[[Any], Any] | None = None) -> Any:
        """The topics (blocking without ``callback``)."""
        return self._rosapi("topics", "Topics", {}, "topics", callback, errback)

    def get_topic_type(self, topic: str, callback: Callable[[Any], Any] | None = None,
                       errback: Callable[[Any], Any] | None = None) -> Any:
        """A topic's type."""
        return self._rosapi("topic_type", "TopicType", {"topic": topic}, "type", callback,
                            errback)

    def get_topics_for_type(self, topic_type: str,
                            callback: Callable[[Any], Any] | None = None,
                            errback: Callable[[Any], Any] | None = None) -> Any:
        """The topics of a type."""
        return self._rosapi("topics_for_type", "TopicsForType", {"type": topic_type},
                            "topics", callback, errback)

    def get_services(self, callback: Callable[[Any], Any] | None = None,
                     errback: Callable[[Any], Any] | None = None) -> Any:
        """The services."""
        return self._rosapi("services", "Services", {}, "services", callback, errback)

    def get_service_type(self, service_name: str,
                         callback: Callable[[Any], Any] | None = None,
                         errback: Callable[[Any], Any] | None = None) -> Any:
        """A service's type."""
        return self._rosapi("service_type", "ServiceType", {"service": service_name},
                            "type", callback, errback)

    def get_nodes(self, callback: Callable[[Any], Any] | None = None,
                  errback: Callable[[Any], Any] | None = None) -> Any:
        """The nodes."""
        return self._rosapi("nodes", "Nodes", {}, "nodes", callback, errback)

    def get_params(self, callback: Callable[[Any], Any] | None = None,
                   errback: Callable[[Any], Any] | None = None) -> Any:
        """The parameters' names."""
        return self._rosapi("get_param_names", "GetParamNames", {}, "names", callback,
                            errback)

    # what the socket tells (websim_browser.Handler, through _Socket)

    def _opened(self) -> None:
        self._open = True
        self.is_connecting = False
        self._retry_s = RECONNECT_FIRST_S
        if self._was_open:  # a reopened connection: topics and services register again
            self.emit(REOPENED, self)
        self._was_open = True
        waiting, self._on_ready = self._on_ready, []
        for callback in waiting:
            callback()
        self.emit("ready", self)

    def _message(self, text: str) -> None:
        message = json.loads(text)
        op = message.get("op")
        if op == "publish":
            self.emit(message["topic"], message["msg"])
        elif op == "service_response":
            callback, errback = self._calls.pop(message.get("id"), (None, None))
            if message.get("result") is False:
                if errback is not None:
                    errback(message.get("values"))
            elif callback is not None:
                callback(ServiceResponse(message.get("values")))
        elif op == "call_service":
            self.emit(message["service"], message)
        elif op == "status":
            self._loop.note_status(str(message.get("msg", "")))

    def _closed(self, reason: str) -> None:
        was_open, self._open = self._open, False
        self.is_connecting = False
        self._socket = None
        if was_open:
            self.emit("close", self)
        if self._closing or self._terminated:
            return
        delay, self._retry_s = self._retry_s, min(RECONNECT_MAX_S, self._retry_s * 2)
        self._loop.call_later(delay, self._reconnect)

    def _reconnect(self) -> None:
        if not (self._closing or self._terminated or self._open or self.is_connecting):
            self.connect()


class _Socket:
    """A ``Ros``'s socket handler (websim_browser.Handler)."""

    def __init__(self, ros: Ros) -> None:
        self.ros = ros

    def on_open(self) -> None:
        self.ros._opened()

    def on_message(self, text: str) -> None:
        self.ros._message(text)

    def on_close(self, reason: str) -> None:
        self.ros._closed(reason)


class Topic:
    """A topic to publish and subscribe to (roslibpy's arguments)."""

    SUPPORTED_COMPRESSION_TYPES = ("png", "none")

    def __init__(self, ros: Ros, name: str, message_type: str,
                 compression: str | None = None, latch: bool = False,
                 throttle_rate: int = 0, queue_size: int = 100, queue_length: int = 0,
                 reconnect_on_close: bool = True) -> None:
        self.ros = ros
        self.name = name
        self.message_type = message_type
        self.compression = compression or "none"
        if self.compression not in self.SUPPORTED_COMPRESSION_TYPES:
            raise ValueError("Unsupported compression type. Must be one of: "
                             + str(self.SUPPORTED_COMPRESSION_TYPES))
        self.latch = latch
        self.throttle_rate = throttle_rate
        self.queue_size = queue_size
        self.queue_length = queue_length
        self.reconnect_on_close = reconnect_on_close
        self._subscribe_id: str | None = None
        self._advertise_id: str | None = None
        self._register: list[dict[str, Any]] = []

    @property
    def is_advertised(self) -> bool:
        """Whether this topic is advertised (a publisher)."""
        return self._advertise_id is not None

    @property
    def is_subscribed(self) -> bool:
        """Whether this topic is subscribed."""
        return self._subscribe_id is not None

    def subscribe(self, callback: Callable[[dict[str, Any]], Any]) -> None:
        """Call ``callback(message)`` (a dict) with each message on the topic."""
        if self._subscribe_id:
            return
        self._subscribe_id = f"subscribe:{self.name}:{self.ros.id_counter}"
        self.ros.on(self.name, callback)
        self._connect({"op": "subscribe", "id": self._subscribe_id, "type": self.message_type,
                       "topic": self.name, "compression": self.compression,
                       "throttle_rate": self.throttle_rate,
                       "queue_length": self.queue_length})

    def unsubscribe(self) -> None:
        """Stop the subscription (every callback of this topic's name on this ``Ros``)."""
        if not self._subscribe_id:
            return
        self.ros.off(self.name)
        self._forget("subscribe")
        self.ros.send_on_ready(Message({"op": "unsubscribe", "id": self._subscribe_id,
                                        "topic": self.name}))
        self._subscribe_id = None

    def publish(self, message: Any) -> None:
        """Publish ``message`` (advertising the topic first if it is not)."""
        if not self.is_advertised:
            self.advertise()
        self.ros.send_on_ready(Message({"op": "publish",
                                        "id": f"publish:{self.name}:{self.ros.id_counter}",
                                        "topic": self.name, "msg": dict(message),
                                        "latch": self.latch}))

    def advertise(self) -> None:
        """Register as the topic's publisher."""
        if self.is_advertised:
            return
        self._advertise_id = f"advertise:{self.name}:{self.ros.id_counter}"
        self._connect({"op": "advertise", "id": self._advertise_id, "type": self.message_type,
                       "topic": self.name, "latch": self.latch,
                       "queue_size": self.queue_size})
        if not self.reconnect_on_close:
            self.ros.on("close", self._reset_advertise_id)

    def unadvertise(self) -> None:
        """No longer publish on the topic."""
        if not self.is_advertised:
            return
        self._forget("advertise")
        self.ros.send_on_ready(Message({"op": "unadvertise", "id": self._advertise_id,
                                        "topic": self.name}))
        self._advertise_id = None

    def _reset_advertise_id(self, _ros: Any) -> None:
        self._advertise_id = None

    def _connect(self, message: dict[str, Any]) -> None:
        self.ros.send_on_ready(Message(message))
        if self.reconnect_on_close:
            if not self._register:
                self.ros.on(REOPENED, self._reregister)
            self._register.append(message)

    def _forget(self, op: str) -> None:
        self._register = [message for message in self._register if message["op"] != op]
        if not self._register:
            self.ros.off(REOPENED, self._reregister)

    def _reregister(self, _ros: Any) -> None:
        """A reopened connection: subscribe and advertise again."""
        for message in self._register:
            self.ros.send_on_ready(Message(message))


class Service:
    """A service to call, or to offer (roslibpy's arguments)."""

    def __init__(self, ros: Ros, name: str, service_type: str,
                 reconnect_on_close: bool = True) -> None:
        self.ros = ros
        self.name = name
        self.service_type = service_type
        self.reconnect_on_close = reconnect_on_close
        self._service_callback: Callable[[Any, Any], Any] | None = None
        self._is_advertised = False

    @property
    def is_advertised(self) -> bool:
        """Whether this side offers the service."""
        return self._is_advertised

    def call(self, request: Any, callback: Callable[[Any], Any] | None = None,
             errback: Callable[[Any], Any] | None = None,
             timeout: float | None = None) -> Any:
        """Call the service: with ``callback``, answer there; else wait for the answer.

        Raises:
            ServiceException: (blocking) the call failed; its reason inside.
            RosTimeoutError: (blocking) no answer within ``timeout`` s.
        """
        if self.is_advertised:
            return None
        message = Message({"op": "call_service",
                           "id": f"call_service:{self.name}:{self.ros.id_counter}",
                           "service": self.name, "args": dict(request)})
        if callback:
            self.ros.call_async_service(message, callback, errback)
            return None
        answer = self.ros.call_sync_service(message, timeout)
        if "exception" in answer:
            raise ServiceException(answer["exception"])
        return answer["result"]

    def advertise(self, callback: Callable[[Any, Any], Any]) -> None:
        """Offer the service.

        ``callback(request, response)`` fills ``response`` and returns True on success.
        """
        if self.is_advertised:
            return
        if not callable(callback):
            raise ValueError("Callback is not a valid callable")
        self._service_callback = callback
        self.ros.on(self.name, self._answer)
        self.ros.send_on_ready(Message({"op": "advertise_service", "type": self.service_type,
                                        "service": self.name}))
        self._is_advertised = True

    def unadvertise(self) -> None:
        """No longer offer the service."""
        if not self.is_advertised:
            return
        self.ros.send_on_ready(Message({"op": "unadvertise_service", "service": self.name}))
        self.ros.off(self.name, self._answer)
        self._is_advertised = False

    def _answer(self, request: dict[str, Any]) -> None:
        response = ServiceResponse()
        assert self._service_callback is not None
        success = self._service_callback(request["args"], response)
        answer = Message({"op": "service_response", "service": self.name,
                          "values": dict(response), "result": success})
        if "id" in request:
            answer["id"] = request["id"]
        self.ros.send_on_ready(answer)


class Param:
    """A ROS parameter, through rosapi."""

    def __init__(self, ros: Ros, name: str) -> None:
        self.ros = ros
        self.name = name

    def get(self, callback: Callable[[Any], Any] | None = None,
            errback: Callable[[Any], Any] | None = None, timeout: float | None = None) -> Any:
        """The parameter's value (blocking without ``callback``)."""
        client = Service(self.ros, "/rosapi/get_param", "rosapi/GetParam")
        request = ServiceRequest({"name": self.name})
        if callback is None:
            return json.loads(client.call(request, timeout=timeout)["value"])
        client.call(request, lambda result: callback(json.loads(result["value"])), errback)
        return None

    def set(self, value: Any, callback: Callable[[Any], Any] | None = None,
            errback: Callable[[Any], Any] | None = None, timeout: float | None = None) -> Any:
        """Set the parameter's value."""
        client = Service(self.ros, "/rosapi/set_param", "rosapi/SetParam")
        request = ServiceRequest({"name": self.name, "value": json.dumps(value)})
        return client.call(request, callback, errback, timeout=timeout)

    def delete(self, callback: Callable[[Any], Any] | None = None,
               errback: Callable[[Any], Any] | None = None,
               timeout: float | None = None) -> Any:
        """Delete the parameter."""
        client = Service(self.ros, "/rosapi/delete_param", "rosapi/DeleteParam")
        return client.call(ServiceRequest({"name": self.name}), callback, errback,
                           timeout=timeout)
