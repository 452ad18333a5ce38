"""Services between the bridge and the ROS 2 graph (``websim serve --ros``), as rosbridge.

Two directions, one object per relay node:

* a client's ``call_service`` to a service on the graph (``call``): an rclpy client per
  service, its answer handed to the event loop; a service whose server is not matched yet
  is retried until ``DISCOVERY_S``, then the call fails with the reason;
* a client-provided service (``advertise_service``) offered on the graph (``offer``): an
  rclpy service whose (coroutine) callback hands the request to the event loop and awaits
  the provider's answer, as rosbridge's ``AdvertisedServiceHandler`` does.

Threads: ``call`` and ``offer`` run on the event loop; rclpy callbacks on the executor
thread, which never blocks (its futures are completed from the loop). A ROS 2 service has no
way to report a failure to its caller: when the provider fails or leaves, the graph caller
gets the type's default response and the failure is logged.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections import OrderedDict
from collections.abc import Callable, Mapping
from typing import Any

import rclpy.task
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import Executor
from rclpy.node import Node

from rosbridge.core.errors import BridgeError
from rosbridge.msgs.rclpy_conversion import (
    MessageConversionError,
    message_class,
    to_dict,
    to_message,
)
from rosbridge.msgs.values import normalize_service_type

log = logging.getLogger("websim.ros")

DISCOVERY_S = 2.0
"""How long a call waits for the graph's server to be matched (a client is created at the
first call of a service; discovery takes tens of milliseconds)."""

RETRY_S = 0.02
DISCOVERY_RETRY_S = 0.1
"""How often a service not on the graph yet is looked up again (one graph query each)."""
RETIRE_GRACE_S = 0.5
"""How long a withdrawn server outlives its last answer (the executor sends it after the
handler returns)."""
CALL_TIMEOUT_S = 5.0
"""How long a call to a graph service may take (as a call to a client-provided one)."""
MAX_CLIENTS = 64
"""rclpy clients kept (one per service called); the least recently used is destroyed."""

Answer = Callable[[bool, Any], None]
"""``answer(ok, values_or_reason)``: how a call's outcome comes back, on the event loop."""

Forward = Callable[[Mapping[str, Any], Answer], None]
"""``forward(args, answer)``: hands a graph caller's request to the providing client."""


class GraphServices:
    """rclpy clients and servers of one relay node, used from the event loop.

    Args:
        node: the relay node (``rosbridge_websocket``).
        executor: the executor spinning ``node`` (its futures wake it).
        loop: the event loop the bridge runs on.
        post: runs a function on ``loop`` from the executor's thread (default:
            ``loop.call_soon_threadsafe``; the server's writes what it queued at once).
    """

    def __init__(self, node: Node, executor: Executor,
                 loop: asyncio.AbstractEventLoop,
                 post: Callable[[Callable[[], None]], None] | None = None) -> None:
        self._node = node
        self._executor = executor
        self._loop = loop
        self._post_to_loop = post
        self._clients: OrderedDict[tuple[str, str], Any] = OrderedDict()
        self._offered: dict[str, _Offer] = {}

    def service_types(self) -> dict[str, str]:
        """Services on the graph, each with its first type (``pkg/srv/Type``)."""
        return {name: normalize_service_type(types[0])
                for name, types in self._node.get_service_names_and_types() if types}

    # ---- calls to the graph ---------------------------------------------------------------

    def call(self, service: str, type_name: str | None, args: Mapping[str, Any],
             answer: Answer) -> None:
        """Call ``service`` on the graph; ``answer`` gets the outcome on the loop.

        ``type_name`` None: the service is not on the graph (yet); its type is looked up
        again until ``DISCOVERY_S`` (a node just started), then the call fails as rosbridge
        fails it ("Service ... does not exist").

        Raises:
            BridgeError: the type is not installed or the request does not fit it.
        """
        if type_name is None:
            self._when_discovered(service, args, answer, self._loop.time() + DISCOVERY_S)
            return
        try:
            cls = message_class(type_name)
            request = to_message(cls.Request, args)
        except MessageConversionError as error:
            raise BridgeError(f"{service}: {error}") from None
        client = self._client(service, type_name, cls)
        deadline_s = self._loop.time() + DISCOVERY_S

        def attempt() -> None:
            if not client.service_is_ready():
                if self._loop.time() < deadline_s:
                    self._loop.call_later(RETRY_S, attempt)
                else:
                    answer(False, f"Service {service} is not available on the ROS graph "
                                  f"(no server matched within {DISCOVERY_S:g} s)")
                return
            future = client.call_async(request)
            timer = self._loop.call_later(CALL_TIMEOUT_S, give_up, future)
            future.add_done_callback(lambda done: self._post(lambda: finish(done, timer)))

        def finish(done: Any, timer: asyncio.TimerHandle) -> None:
            timer.cancel()
            if not done.cancelled():
                _answered(done, answer)

        def give_up(future: Any) -> None:
            client.remove_pending_request(future)  # rclpy forgets it: nothing is held
            future.cancel()
            answer(False, f"{service} did not answer within {CALL_TIMEOUT_S:g} s")

        attempt()

    def _when_discovered(self, service: str, args: Mapping[str, Any], answer: Answer,
                         deadline_s: float) -> None:
        type_name = self.service_types().get(service)
        if type_name is not None:
            try:
                self.call(service, type_name, args, answer)
            except BridgeError as error:
                answer(False, str(error))
        elif self._loop.time() < deadline_s:
            self._loop.call_later(DISCOVERY_RETRY_S, self._when_discovered, service, args,
                                  answer, deadline_s)
        else:
            answer(False, f"Service {service} does not exist")

    def _client(self, service: str, type_name: str, cls: Any) -> Any:
        key = (service, type_name)
        client = self._clients.get(key)
        if client is None:
            client = self._node.create_client(cls, service)
            self._clients[key] = client
            if len(self._clients) > MAX_CLIENTS:
                _, oldest = self._clients.popitem(last=False)
                self._node.destroy_client(oldest)
        self._clients.move_to_end(key)
        return client

    # ---- client-provided services on the graph --------------------------------------------

    def offer(self, service: str, type_name: str, forward: Forward) -> None:
        """Offer a client's service on the graph; its requests go to ``forward``.

        Raises:
            BridgeError: the type is not installed.
        """
        try:
            cls = message_class(type_name)
        except MessageConversionError as error:
            raise BridgeError(f"{service}: {error}") from None
        executor, post = self._executor, self._post
        offer = _Offer()

        async def handle(request: Any, response: Any) -> Any:
            outcome: rclpy.task.Future[tuple[bool, Any]] = rclpy.task.Future(executor=executor)
            outcome.add_done_callback(lambda _: None)  # completing it wakes the executor
            args = to_dict(request)
            offer.begin()
            try:
                post(lambda: forward(args, lambda ok, values: outcome.set_result((ok, values))))
                answered = await outcome
            finally:
                if offer.end():  # withdrawn meanwhile: destroyed once this answer is out
                    post(lambda: self._destroy_later(offer))
            ok, values = answered if answered is not None else (False, "no answer")
            if not ok:
                log.warning("%s: a ROS caller gets the default response: %s", service, values)
                return response
            try:
                return to_message(cls.Response, values if isinstance(values, Mapping) else {})
            except MessageConversionError as error:
                log.warning("%s: the provider's response does not fit %s: %s", service,
                            type_name, error)
                return response

        self.withdraw(service)
        # Reentrant, as rosbridge's: a second request is taken while the first waits for its
        # provider (a mutually exclusive group would queue it behind the first's answer).
        offer.server = self._node.create_service(
            cls, service, handle, callback_group=ReentrantCallbackGroup())
        self._offered[service] = offer

    def withdraw(self, service: str) -> None:
        """Stop offering a client's service on the graph.

        A server still answering (its provider just left: the callers get the default
        response) is destroyed once the last answer is out; destroyed now, the callers would
        wait for ever.
        """
        offer = self._offered.pop(service, None)
        if offer is not None and offer.retire():
            self._destroy(offer)

    def _destroy_later(self, offer: _Offer) -> None:
        self._loop.call_later(RETIRE_GRACE_S, self._destroy, offer)

    def _destroy(self, offer: _Offer) -> None:
        if offer.server is not None:
            self._node.destroy_service(offer.server)
            offer.server = None

    def offered(self) -> frozenset[str]:
        """The client-provided services offered on the graph."""
        return frozenset(self._offered)

    def _post(self, fn: Callable[[], None]) -> None:
        if self._post_to_loop is not None:
            self._post_to_loop(fn)
            return
        try:
            self._loop.call_soon_threadsafe(fn)
        except RuntimeError:  # the loop closed while shutting down
            log.debug("event loop closed; dropped a service answer")


class _Offer:
    """One client-provided service on the graph: its rclpy server and requests in flight.

    Counted from both threads (the executor's handlers, the loop's withdraw), under a lock.
    """

    def __init__(self) -> None:
        self.server: Any = None
        self._lock = threading.Lock()
        self._in_flight = 0
        self._retired = False

    def begin(self) -> None:
        with self._lock:
            self._in_flight += 1

    def end(self) -> bool:
        """One request answered; whether the server is to be destroyed now."""
        with self._lock:
            self._in_flight -= 1
            return self._retired and self._in_flight == 0

    def retire(self) -> bool:
        """Withdrawn; whether it can be destroyed at once (nothing in flight)."""
        with self._lock:
            self._retired = True
            return self._in_flight == 0


def _answered(future: Any, answer: Answer) -> None:
    """Hand a graph service's outcome to ``answer`` (on the loop)."""
    error = future.exception()
    if error is not None:
        answer(False, f"the ROS service failed: {error}")
        return
    answer(True, to_dict(future.result()))
