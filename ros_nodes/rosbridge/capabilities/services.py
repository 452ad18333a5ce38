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
from typing import TYPE_CHECKING, Any

from physics import ConfigError
from ros_nodes.messages import normalize_service_type
from ros_nodes.rosbridge.errors import BridgeError, ServiceError, shorten
from ros_nodes.rosbridge.session import Session

if TYPE_CHECKING:
    from ros_nodes.rosbridge.bridge import Bridge

log = logging.getLogger("websim.bridge")

SERVICE_TIMEOUT_S = 5.0
"""How long a call to a client-provided service may wait for its answer."""

ServiceHandler = Callable[[Mapping[str, Any], Session], Mapping[str, Any]]
"""An in-process service: (args, caller) -> response values; raises ``ServiceError``."""


@dataclass
class _PendingCall:
    caller: Session
    caller_id: Any
    service: str
    provider: Session
    deadline_s: float


class Services:
    """The service capability of one bridge.

    Args:
        bridge: the bridge it belongs to (sessions, clock).
        timeout_s: how long a call to a client-provided service may take.
    """

    OPS = ("call_service", "service_response", "advertise_service", "unadvertise_service")

    def __init__(self, bridge: Bridge, timeout_s: float = SERVICE_TIMEOUT_S) -> None:
        self._bridge = bridge
        self._timeout_s = timeout_s
        self._local: dict[str, tuple[str, ServiceHandler]] = {}
        self._providers: dict[str, tuple[Session, str]] = {}
        self._pending: dict[str, _PendingCall] = {}
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
                del self._pending[call_id]

    def expire(self) -> None:
        """Fail calls to client-provided services that waited longer than the timeout."""
        now = self._bridge.clock()
        for call_id, call in list(self._pending.items()):
            if now >= call.deadline_s:
                del self._pending[call_id]
                self.fail(call.caller, call.caller_id, call.service,
                          f"{call.service} did not answer within {self._timeout_s:g} s")

    # ---- calls ----------------------------------------------------------------------------

    def _call(self, session: Session, message: dict[str, Any]) -> None:
        service, call_id = message["service"], message.get("id")
        args = message.get("args", {})
        if service in self._providers:
            self._forward(session, call_id, service, args)
            return
        if service not in self._local:
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
        except (ServiceError, BridgeError, ConfigError) as error:
            reason = shorten(str(error))
            log.warning("client %s: %s failed: %s", session.peer, service, reason)
            self.fail(session, call_id, service, reason)
            return
        response: dict[str, Any] = {"op": "service_response", "service": service,
                                    "values": dict(values), "result": True}
        if call_id is not None:
            response["id"] = call_id
        session.reply(response)

    def _forward(self, caller: Session, caller_id: Any, service: str, args: Any) -> None:
        provider, _ = self._providers[service]
        count = self._call_counts[service] = self._call_counts.get(service, 0) + 1
        forward_id = f"service_request:{service}:{count}"
        self._pending[forward_id] = _PendingCall(caller, caller_id, service, provider,
                                                 self._bridge.clock() + self._timeout_s)
        provider.reply({"op": "call_service", "id": forward_id, "service": service,
                        "args": args})

    def _response(self, session: Session, message: dict[str, Any]) -> None:
        call = self._pending.get(str(message.get("id")))
        if call is None or call.provider is not session:
            raise BridgeError(f"service_response for {message['service']}: no call "
                              f"with id {str(message.get('id'))[:80]!r} is waiting for it")
        del self._pending[str(message["id"])]
        response: dict[str, Any] = {"op": "service_response", "service": call.service,
                                    "values": message.get("values", {}),
                                    "result": message["result"]}
        if call.caller_id is not None:
            response["id"] = call.caller_id
        if call.caller in self._bridge.sessions:
            call.caller.reply(response)

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

    def _unadvertise(self, session: Session, message: dict[str, Any]) -> None:
        service = message["service"]
        if service in session.services:
            self._withdraw(session, service, f"{service} was unadvertised by its provider")

    def _withdraw(self, session: Session, service: str, reason: str) -> None:
        session.services.pop(service, None)
        self._providers.pop(service, None)
        self._call_counts.pop(service, None)
        for call_id, call in list(self._pending.items()):
            if call.provider is session and call.service == service:
                del self._pending[call_id]
                self.fail(call.caller, call.caller_id, call.service, reason)
