"""rosbridge 2.x's service semantics between clients, against a real ``websim serve``.

A client-provided service (roslibpy's ``Service.advertise``) answers calls relayed to it with
``service_response``; rosbridge makes the provider's values the ROS response and ignores the
provider's ``result``, numbers the relayed requests ``service_request:<service>:<n>`` per
advertised service, and fails calls in progress at once when the provider unadvertises.
"""

from __future__ import annotations

import json
import time
from typing import Any

import roslibpy
import websockets.sync.client as ws_client

from server_process import ServerProcess, wait_for

SERVICE_TIMEOUT_S = 5.0
"""websim's timeout for a client-provided service (capabilities.services)."""


def call(ros: roslibpy.Ros, name: str, type_name: str, args: dict[str, Any]) -> dict[str, Any]:
    """Call with roslibpy; {"ok": values} or {"error": reason}."""
    answer: dict[str, Any] = {}
    roslibpy.Service(ros, name, type_name).call(
        roslibpy.ServiceRequest(args), lambda values: answer.update(ok=dict(values)),
        lambda reason: answer.update(error=reason))
    wait_for(lambda: answer, SERVICE_TIMEOUT_S * 2, f"the answer of {name}")
    return answer


def test_a_providers_result_false_is_ignored_as_rosbridge_2_does(
        server: ServerProcess, ros: roslibpy.Ros) -> None:
    def refuse_but_answer(request: dict[str, Any], response: dict[str, Any]) -> bool:
        response["success"] = True
        response["message"] = f"got {request['data']}"
        return False  # roslibpy sends this as "result"

    provider = roslibpy.Service(ros, "/provided_setbool", "std_srvs/srv/SetBool")
    provider.advertise(refuse_but_answer)
    caller = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
    caller.run()
    try:
        answer = call(caller, "/provided_setbool", "std_srvs/srv/SetBool", {"data": True})
    finally:
        caller.close()
        provider.unadvertise()
    assert answer == {"ok": {"success": True, "message": "got True"}}


def test_relayed_requests_are_numbered_per_advertised_service(server: ServerProcess) -> None:
    with ws_client.connect(server.ws_url) as provider, \
            ws_client.connect(server.ws_url) as caller:
        for name in ("/first_service", "/second_service"):
            provider.send(json.dumps({"op": "advertise_service", "service": name,
                                      "type": "std_srvs/srv/Trigger"}))
        time.sleep(0.1)
        ids = []
        for name in ("/first_service", "/second_service", "/first_service"):
            caller.send(json.dumps({"op": "call_service", "service": name, "id": name}))
            request = json.loads(provider.recv(timeout=5))
            assert request["op"] == "call_service" and request["service"] == name
            ids.append(request["id"])
            provider.send(json.dumps({"op": "service_response", "service": name,
                                      "id": request["id"], "result": True,
                                      "values": {"success": True, "message": ""}}))
            answer = json.loads(caller.recv(timeout=5))
            assert answer["id"] == name and answer["result"] is True
    assert ids == ["service_request:/first_service:1", "service_request:/second_service:1",
                   "service_request:/first_service:2"]


def test_unadvertising_mid_call_fails_the_caller_at_once(
        server: ServerProcess, ros: roslibpy.Ros) -> None:
    with ws_client.connect(server.ws_url) as provider:
        provider.send(json.dumps({"op": "advertise_service", "service": "/slow_service",
                                  "type": "std_srvs/srv/Trigger"}))
        time.sleep(0.1)
        answer: dict[str, Any] = {}
        roslibpy.Service(ros, "/slow_service", "std_srvs/srv/Trigger").call(
            roslibpy.ServiceRequest({}), lambda values: answer.update(ok=values),
            lambda reason: answer.update(error=reason))
        assert json.loads(provider.recv(timeout=5))["op"] == "call_service"
        started = time.monotonic()
        provider.send(json.dumps({"op": "unadvertise_service", "service": "/slow_service"}))
        wait_for(lambda: answer, SERVICE_TIMEOUT_S * 2, "the caller's failure")
        waited_s = time.monotonic() - started
    assert "unadvertised" in str(answer.get("error")), answer
    assert waited_s < SERVICE_TIMEOUT_S, "failed by the unadvertise, not by the timeout"


def test_a_request_that_does_not_fit_the_service_type_fails_before_the_provider_sees_it(
        server: ServerProcess) -> None:
    """rosbridge fills the ROS request from the args: a float for SetBool's bool fails."""
    with ws_client.connect(server.ws_url) as provider, \
            ws_client.connect(server.ws_url) as caller:
        provider.send(json.dumps({"op": "advertise_service", "service": "/typed_setbool",
                                  "type": "std_srvs/SetBool"}))
        time.sleep(0.1)
        caller.send(json.dumps({"op": "call_service", "service": "/typed_setbool",
                                "id": "bad", "args": {"data": 42.0}}))
        answer = json.loads(caller.recv(timeout=5))
        assert answer["result"] is False and "data: expected true or false" in answer["values"]
        caller.send(json.dumps({"op": "call_service", "service": "/typed_setbool",
                                "id": "empty", "args": {}}))
        request = json.loads(provider.recv(timeout=5))
    assert request["args"] == {"data": False}, "the first call never reached the provider"
