"""Issue 20, section 6: everything one client relays to others is budgeted and typed.

Service requests and responses, goals, feedback and results are charged to their sender's
relay budget (``ClientLimits.relay_bytes_per_s``) as publications are, and refused at the
sender while the receiver's send queue is half full (``relay.RECEIVER_ROOM_SHARE``): a
flood never closes its receiver for send-queue overflow. Goals are checked against their
action's goal type, as service requests are against theirs.
"""

from __future__ import annotations

import pytest
from bridge_rig import Rig

from rosbridge.core.capabilities.services import MAX_PENDING_CALLS_PER_CLIENT
from rosbridge.core.limits import ClientLimits
from rosbridge.core.relay import RECEIVER_ROOM_SHARE

LIMITS = ClientLimits()
BIG = "x" * 900_000
FIBONACCI = "example_interfaces/action/Fibonacci"


@pytest.fixture
def rig() -> Rig:
    return Rig()


def failures(frames: list[dict]) -> list[str]:
    return [str(f.get("values", f.get("msg"))) for f in frames
            if f.get("result") is False or f.get("op") == "status"]


def test_a_flood_of_large_service_calls_is_refused_at_its_senders_not_at_the_provider(
        rig: Rig) -> None:
    provider = rig.client()
    rig.send(provider, {"op": "advertise_service", "service": "/big", "type": "my_pkg/Big"})
    callers = [rig.client() for _ in range(4)]
    refused = []
    for round_number in range(3):
        for number, caller in enumerate(callers):
            rig.send(caller, {"op": "call_service", "service": "/big", "id": f"{number}",
                              "args": {"data": BIG}})
            refused += failures(rig.drain(caller))
        room = LIMITS.max_queued_bytes * RECEIVER_ROOM_SHARE
        assert provider.outbox.queued_bytes <= room
        assert provider.outbox.overflowed is None
        assert round_number or len(refused) >= 1
        rig.drain(provider)  # it reads: now the callers' own budgets refuse them
    assert any("its receiver has" in reason for reason in refused)
    assert any("bytes/s relayed to other clients" in reason for reason in refused)
    assert provider.outbox.overflowed is None


def test_a_providers_flood_of_responses_is_charged_and_the_caller_still_hears(
        rig: Rig) -> None:
    provider, caller = rig.client(), rig.client()
    rig.send(provider, {"op": "set_level", "level": "error"})
    rig.send(provider, {"op": "advertise_service", "service": "/big", "type": "my_pkg/Big"})
    answers = []
    for number in range(3):
        rig.send(caller, {"op": "call_service", "service": "/big", "id": f"c{number}",
                          "args": {}})
        request = [f for f in rig.drain(provider) if f.get("op") == "call_service"][-1]
        rig.send(provider, {"op": "service_response", "service": "/big", "id": request["id"],
                            "values": {"data": BIG}, "result": True})
        answers += [f for f in rig.drain(caller) if f.get("op") == "service_response"]
    assert len(answers) == 3  # every call answered, one way or the other
    assert answers[0]["result"] is True
    assert any(a["result"] is False and "bytes/s relayed" in a["values"] for a in answers)
    assert caller.outbox.overflowed is None


def serve_fibonacci(rig: Rig):
    server = rig.client()
    rig.send(server, {"op": "advertise_action", "action": "/fib", "type": FIBONACCI})
    return server


def test_goals_are_checked_against_their_type_and_filled_as_rosbridge_fills_them(
        rig: Rig) -> None:
    server, sender = serve_fibonacci(rig), rig.client()
    rig.send(sender, {"op": "send_action_goal", "action": "/fib", "action_type": FIBONACCI,
                      "id": "bad", "args": {"order": "six"}})
    rig.send(sender, {"op": "send_action_goal", "action": "/fib", "action_type": FIBONACCI,
                      "id": "extra", "args": {"order": 3, "colour": "red"}})
    refused = rig.drain(sender)
    assert [f["id"] for f in refused if f["op"] == "action_result"] == ["bad", "extra"]
    assert all(f["result"] is False and "does not fit" in f["values"]
               for f in refused if f["op"] == "action_result")
    assert [f for f in rig.drain(server) if f.get("op") == "send_action_goal"] == []
    rig.send(sender, {"op": "send_action_goal", "action": "/fib", "action_type": FIBONACCI,
                      "id": "empty"})
    goals = [f for f in rig.drain(server) if f.get("op") == "send_action_goal"]
    assert [goal["args"] for goal in goals] == [{"order": 0}]


def test_a_flood_of_large_goals_is_refused_at_its_sender(rig: Rig) -> None:
    server = rig.client()
    rig.send(server, {"op": "advertise_action", "action": "/big", "type": "my_pkg/Big"})
    sender = rig.client()
    results = []
    for number in range(4):
        rig.send(sender, {"op": "send_action_goal", "action": "/big",
                          "action_type": "my_pkg/Big", "id": number, "args": {"data": BIG}})
        results += [f for f in rig.drain(sender) if f.get("op") == "action_result"]
    assert results and all(f["result"] is False for f in results)
    assert any("bytes/s relayed to other clients" in f["values"] for f in results)
    assert server.outbox.overflowed is None


def test_calls_waiting_for_a_provider_are_bounded_per_caller_and_forgotten_with_it(
        rig: Rig) -> None:
    provider, caller = rig.client(), rig.client()
    rig.send(provider, {"op": "advertise_service", "service": "/slow", "type": "my_pkg/Slow"})
    for number in range(MAX_PENDING_CALLS_PER_CLIENT + 6):
        rig.send(caller, {"op": "call_service", "service": "/slow", "id": number, "args": {}})
    refused = failures(rig.drain(caller))
    assert len(refused) == 6 and all("calls waiting for an answer" in r for r in refused)
    rig.bridge.disconnect(caller)
    services = rig.bridge.services
    assert not services._pending and not services._by_caller and not services._by_service
