"""Services: call_service, service_response, advertise_service, unadvertise_service.

Calls go to a service implemented in-process (``add``: the robot's parameters, reset,
rosapi) or are relayed to the client that offers it, with a timeout. A service belongs to
whoever offered it first: a second ``advertise_service`` of the same name is refused, and a
provider that leaves (or unadvertises) fails its pending calls at once.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from rosbridge.core import relay
from rosbridge.core.context import BridgeContext
from rosbridge.core.errors import BridgeError, shorten
from rosbridge.core.session import Session
from rosbridge.msgs import definitions
from rosbridge.msgs.values import normalize_service_type

log = logging.getLogger("websim.bridge")

SERVICE_TIMEOUT_S = 5.0
"""How long a call to a client-provided service may wait for its answer."""

MAX_PENDING_CALLS_PER_CLIENT = 64
"""Calls to client-provided services one client may have waiting at once; past it a call
fails at once (browsers wait for each answer; 64 is a burst of a whole page's calls)."""

MAX_PENDING_CALLS_PER_SERVICE = 256
"""Calls one client-provided service may have waiting at once, from all callers (the
graph's too): what its provider is asked to hold; past it a call fails at once."""

Outcome = tuple[bool, Any]
"""A graph service's outcome: (ok, response values or the reason)."""


@dataclass(frozen=True)
class ViaGraph:
    """An in-process service's answer that services on the ROS graph give (``--ros``).

    rosapi asks graph nodes' own parameter services, as rosapi does on ROS 2.

    Attributes:
        calls: the graph services to call, each with its request (in parallel).
        response: makes the response values from their outcomes, in ``calls`` order.
    """

    calls: tuple[tuple[str, Mapping[str, Any]], ...]
    response: Callable[[list[Outcome]], Mapping[str, Any]]


Answer = Callable[[bool, Any], None]
"""``answer(ok, values_or_reason)``: how a call's outcome reaches its caller."""


@dataclass(frozen=True)
class Later:
    """An in-process service's answer that comes later (a simulation stepped N ticks).

    Attributes:
        start: called at once with the call's ``Answer``, which its owner calls once, later
            (nothing reaches a caller that has left). The owner bounds what it holds.
    """

    start: Callable[[Answer], None]


ServiceHandler = Callable[[Mapping[str, Any], Session],
                          "Mapping[str, Any] | ViaGraph | Later"]
"""An in-process service: (args, caller) -> response values (or ``ViaGraph``, ``Later``);
raises ``ServiceError``."""


@dataclass
class _PendingCall:
    """A call relayed to a providing client, waiting for its ``service_response``.

    ``caller`` is None for a call from the ROS graph (``--ros``); ``answer`` delivers it.
    """

    caller: Session | None
    service: str
    provider: Session
    deadline_s: float
    answer: Answer


def request_args(service_type: str, args: Any) -> Any:
    """A caller's request in canonical form, where the service type is known.

    rosbridge fills the ROS request from the args before any provider sees them: a field the
    type lacks or a value of the wrong type fails the call, missing fields take defaults.

    Raises:
        MessageError: the args do not fit the request type.
    """
    request_type = f"{service_type}_Request"
    if not definitions.known(request_type):
        return args
    if args in ([], None):  # roslibpy and roslibjs send [] for an empty request
        args = {}
    return definitions.canonical(request_type, args)


def response_values(service_type: str | None, values: Any) -> Any:
    """A provider's response values in canonical form, where the service type is known.

    rosbridge fills the ROS response from them (defaults for what is missing, refusing what
    the type lacks); websim does the same with the type's definition (``definitions``),
    and passes an unknown type's values as they are.

    Raises:
        MessageError: the values do not fit the response type.
    """
    response_type = f"{service_type}_Response" if service_type else None
    if response_type is None or not definitions.known(response_type):
        return values
    if values in ([], None):  # roslibpy and roslibjs send [] for an empty response
        values = {}
    return definitions.canonical(response_type, values)


class Services:
    """The service capability of one bridge.

    Args:
        context: what it shares with the bridge's other capabilities (sessions, clock,
            refusals, the graph port).
        timeout_s: how long a call to a client-provided service may take.
    """

    OPS = ("call_service", "service_response", "advertise_service", "unadvertise_service")

    def __init__(self, context: BridgeContext, timeout_s: float = SERVICE_TIMEOUT_S) -> None:
        self._context = context
        self._timeout_s = timeout_s
        self._local: dict[str, tuple[str, ServiceHandler]] = {}
        self._providers: dict[str, tuple[Session, str]] = {}
        self._pending: dict[str, _PendingCall] = {}
        """Calls relayed to a providing client and not yet answered (bounded per caller and
        per service; each goes with its answer, its timeout, its provider or its caller)."""
        self._by_caller: dict[Session, int] = {}
        self._by_service: dict[str, int] = {}
        self._call_counts: dict[str, int] = {}

    def handlers(self) -> dict[str, Callable[[Session, dict[str, Any]], None]]:
        """This capability's ops."""
        return {"call_service": self._call, "service_response": self._response,
                "advertise_service": self._advertise, "unadvertise_service": self._unadvertise}

    def add(self, name: str, type_name: str, handler: ServiceHandler) -> None:
        """Offer a service implemented in-process."""
        self._local[name] = (normalize_service_type(type_name), handler)

    def types(self) -> dict[str, str]:
        """Every service and its type: the in-process ones and those clients offer."""
        listed = {name: type_name for name, (type_name, _) in self._local.items()}
        listed.update({name: type_name for name, (_, type_name) in self._providers.items()})
        return listed

    def fail(self, session: Session, call_id: Any, service: str, reason: str) -> None:
        """Answer a call with ``result: false`` and the reason in ``values``."""
        session.fail_call(call_id, service, reason)

    def disconnect(self, session: Session) -> None:
        """Withdraw ``session``'s services and calls; fail the calls it was answering."""
        for service in list(session.services):
            self._withdraw(session, service, f"service provider for {service} disconnected")
        for call_id, call in list(self._pending.items()):
            if call.caller is session:
                self._take(call_id)

    def expire(self) -> None:
        """Fail calls to client-provided services that waited longer than the timeout."""
        now = self._context.clock.monotonic_s()
        for call_id, call in list(self._pending.items()):
            if now >= call.deadline_s:
                self._take(call_id)
                call.answer(False, f"{call.service} did not answer within "
                                   f"{self._timeout_s:g} s")

    def _answer_for(self, session: Session, call_id: Any, service: str) -> Answer:
        """How the outcome of ``session``'s call reaches it (not at all once it has left)."""
        def answer(ok: bool, values: Any) -> None:
            if session not in self._context.sessions:
                return
            if not ok:
                self.fail(session, call_id, service, shorten(str(values)))
                return
            response: dict[str, Any] = {"op": "service_response", "service": service,
                                        "values": values, "result": True}
            if call_id is not None:
                response["id"] = call_id
            session.reply(response)
        return answer

    # ---- calls ----------------------------------------------------------------------------

    def _call(self, session: Session, message: dict[str, Any]) -> None:
        service, call_id = message["service"], message.get("id")
        args = message.get("args", {})
        if service in self._providers:
            try:
                args = request_args(self._providers[service][1], args)
                relay.charge(session, f"call_service {service}", self._providers[service][0])
            except self._context.refusals as error:
                self.fail(session, call_id, service, f"{service}: {shorten(str(error))}")
                return
            self._forward(session, service, args, self._answer_for(session, call_id, service))
            return
        if service not in self._local:
            if self._context.graph.attached:
                try:
                    relay.charge(session, f"call_service {service}")
                except self._context.refusals as error:
                    self.fail(session, call_id, service, shorten(str(error)))
                    return
            if not self._context.graph.call_service(
                    service, args if isinstance(args, dict) else {},
                    self._answer_for(session, call_id, service)):
                self.fail(session, call_id, service, f"Service {service} does not exist")
            return
        _, handler = self._local[service]
        if isinstance(args, list):
            if args:
                self.fail(session, call_id, service,
                          f"{service}: args must be an object of named fields")
                return
            args = {}
        try:
            values = handler(args, session)
        except self._context.refusals as error:
            reason = shorten(str(error))
            log.warning("client %s: %s failed: %s", session.peer, service, reason)
            self.fail(session, call_id, service, reason)
            return
        answer = self._answer_for(session, call_id, service)
        if isinstance(values, ViaGraph):
            self._via_graph(values, lambda response: answer(True, response))
            return
        if isinstance(values, Later):
            values.start(answer)
            return
        answer(True, dict(values))

    def _via_graph(self, via: ViaGraph, done: Callable[[Mapping[str, Any]], None]) -> None:
        """Call ``via``'s graph services; ``done`` gets the response once all answered."""
        outcomes: list[Outcome | None] = [None] * len(via.calls)
        waiting = [len(via.calls)]

        def answered(index: int, ok: bool, got: Any) -> None:
            outcomes[index] = (ok, got)
            waiting[0] -= 1
            if waiting[0] == 0:
                done(via.response([outcome for outcome in outcomes if outcome is not None]))

        if not via.calls:
            done(via.response([]))
        for index, (service, args) in enumerate(via.calls):
            def answer(ok: bool, got: Any, index: int = index) -> None:
                answered(index, ok, got)

            if not self._context.graph.call_service(service, dict(args), answer):
                answer(False, f"Service {service} does not exist")

    def _forward(self, caller: Session | None, service: str, args: Any,
                 answer: Answer) -> None:
        """Relay a call to the client providing ``service``, numbered as rosbridge does."""
        provider, _ = self._providers[service]
        count = self._call_counts[service] = self._call_counts.get(service, 0) + 1
        forward_id = f"service_request:{service}:{count}"
        deadline_s = self._context.clock.monotonic_s() + self._timeout_s
        if caller is not None and \
                self._by_caller.get(caller, 0) >= MAX_PENDING_CALLS_PER_CLIENT:
            answer(False, f"{service}: a client may have at most "
                          f"{MAX_PENDING_CALLS_PER_CLIENT} calls waiting for an answer")
            return
        if self._by_service.get(service, 0) >= MAX_PENDING_CALLS_PER_SERVICE:
            answer(False, f"{service}: {MAX_PENDING_CALLS_PER_SERVICE} calls are waiting for "
                          "its provider already")
            return
        self._pending[forward_id] = _PendingCall(caller, service, provider, deadline_s, answer)
        if caller is not None:
            self._by_caller[caller] = self._by_caller.get(caller, 0) + 1
        self._by_service[service] = self._by_service.get(service, 0) + 1
        provider.reply({"op": "call_service", "id": forward_id, "service": service,
                        "args": args})

    def _from_graph(self, service: str) -> Callable[[Any, Answer], None]:
        """What a call from the ROS graph to a client-provided ``service`` goes through."""
        def forward(args: Any, answer: Answer) -> None:
            if service not in self._providers:
                answer(False, f"{service} is no longer provided")
                return
            self._forward(None, service, dict(args), answer)
        return forward

    def _response(self, session: Session, message: dict[str, Any]) -> None:
        call = self._pending.get(str(message.get("id")))
        if call is None or call.provider is not session:
            raise BridgeError(f"service_response for {message['service']}: no call "
                              f"with id {str(message.get('id'))[:80]!r} is waiting for it")
        self._take(str(message["id"]))
        try:
            relay.charge(session, f"service_response for {call.service}", call.caller)
        except self._context.refusals as error:  # the caller still hears of its call
            call.answer(False, f"{call.service}: the provider's response was refused: "
                               f"{shorten(str(error))}")
            raise
        try:
            values = response_values(self._providers_type(session, call.service),
                                     message.get("values", {}))
        except self._context.refusals as error:  # the provider's answer does not fit the type
            call.answer(False, f"{call.service}: the provider's response does not fit its "
                               f"type: {shorten(str(error))}")
            raise BridgeError(f"service_response for {call.service}: {error}") from None
        # rosbridge 2.x makes the provider's values the ROS response and ignores its
        # "result": the call succeeded once there is an answer of the right type.
        call.answer(True, values)

    def _take(self, call_id: str) -> _PendingCall | None:
        """Forget a pending call (its counts too); it, or None if it was not pending."""
        call = self._pending.pop(call_id, None)
        if call is None:
            return None
        if call.caller is not None:
            _decrement(self._by_caller, call.caller)
        _decrement(self._by_service, call.service)
        return call

    @staticmethod
    def _providers_type(provider: Session, service: str) -> str | None:
        return provider.services.get(service)

    # ---- providing ------------------------------------------------------------------------

    def _advertise(self, session: Session, message: dict[str, Any]) -> None:
        service = message["service"]
        if service in self._local:
            raise BridgeError(f"{service} is provided by the simulator")
        provider = self._providers.get(service)
        if provider is not None and provider[0] is not session:
            raise BridgeError(f"{service} is already provided by another client; it stays "
                              "theirs until they unadvertise it or disconnect")
        try:
            type_name = normalize_service_type(message["type"])
        except ValueError as error:
            raise BridgeError(f"{service}: {error}") from None
        self._providers[service] = (session, type_name)
        session.services[service] = type_name
        self._context.graph.offer_service(session, service, type_name, self._from_graph(service))

    def _unadvertise(self, session: Session, message: dict[str, Any]) -> None:
        service = message["service"]
        if service in session.services:
            self._withdraw(session, service, f"{service} was unadvertised by its provider")

    def _withdraw(self, session: Session, service: str, reason: str) -> None:
        session.services.pop(service, None)
        self._providers.pop(service, None)
        self._call_counts.pop(service, None)
        self._context.graph.withdraw_service(service)
        for call_id, call in list(self._pending.items()):
            if call.provider is session and call.service == service:
                self._take(call_id)
                call.answer(False, reason)


def _decrement(counts: dict[Any, int], key: Any) -> None:
    left = counts.pop(key, 1) - 1
    if left:
        counts[key] = left
