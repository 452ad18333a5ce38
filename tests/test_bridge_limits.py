"""The bridge against bad and hostile input, driven in-process: errors, bounds and limits.

Bad frames are refused with a reason (for a client that asked) and change nothing; every
table and queue a client can grow is bounded; the rate limit and the origin policy.
"""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from bridge_rig import Clock, Rig, topics_of

from rosbridge.core.bridge import Session
from rosbridge.core.encoding import MAX_NESTING
from rosbridge.core.limits import ClientLimits, OriginPolicy, RateLimit
from rosbridge.core.outbox import Outbox
from rosbridge.core.schema import OP_FIELDS, Field


@pytest.fixture
def rig() -> Rig:
    return Rig()


def _nested(depth: int) -> Any:
    value: Any = 0.1
    for _ in range(depth):
        value = {"x": value}
    return value


BAD_FRAMES = [
    "{not json", "[1, 2, 3]", '"text"', "{}", json.dumps({"op": "fly"}),
    json.dumps({"op": "subscribe"}), json.dumps({"op": "subscribe", "topic": 5}),
    json.dumps({"op": "subscribe", "topic": "/odom", "throttle_rate": "fast"}),
    json.dumps({"op": "subscribe", "topic": "/odom", "queue_length": True}),
    json.dumps({"op": "subscribe", "topic": "/odom", "throttle_rate": -5}),
    json.dumps({"op": "subscribe", "topic": "/odom", "compression": "zip"}),
    json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": "go"}),
    json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": "fast"}}}),
    json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": 3}}),
    '{"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": NaN}}}',
    '{"op": "publish", "topic": "/cmd_vel", "msg": {"angular": {"z": Infinity}}}',
    json.dumps({"op": "publish", "topic": "/nobody", "msg": {}}),
    json.dumps({"op": "advertise", "topic": "/x", "type": "notatype"}),
    json.dumps({"op": "service_response", "service": "/x", "id": "nope", "result": True}),
    json.dumps({"op": "set_level", "level": "loud"}),
    b"\x00\x01binary",
    "[" * 100_000 + "]" * 100_000,  # json.loads alone raises RecursionError
    json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": _nested(65)}}),
    json.dumps({"op": "subscribe", "topic": "/odom; rm -rf"}),
    json.dumps({"op": "advertise", "topic": "/rosout", "type": "rcl_interfaces/msg/Log"}),
    json.dumps({"op": "advertise_service", "service": "/rosapi/topics",
                "type": "rosapi_msgs/srv/Topics"}),
]


@pytest.mark.parametrize("frame", BAD_FRAMES)
def test_bad_input_is_reported_only_when_asked_and_changes_nothing(rig: Rig,
                                                                   frame: str | bytes) -> None:
    quiet, asking = rig.client(), rig.client()
    rig.send(asking, {"op": "set_level", "level": "error"})
    rig.robot.sim.command(0.2, 0.1)
    for client in (quiet, asking):
        rig.send(client, frame)
    assert rig.drain(quiet) == [], "no status unless asked: roslibpy raises on unknown ops"
    statuses = rig.drain(asking)
    assert len(statuses) == 1 and statuses[0]["op"] == "status"
    assert statuses[0]["level"] == "error" and statuses[0]["msg"]
    assert rig.robot.sim.last_command == (0.2, 0.1)
    rig.send(quiet, {"op": "subscribe", "topic": "/odom"})
    rig.tick()
    assert topics_of(rig.drain(quiet)) == ["/odom"], "the client is still served"
    assert all(math.isfinite(v) for v in rig.robot.sim.ground_truth())


def _valid(spec: Field) -> Any:
    """A value of the right type for a required field (not necessarily a sensible one)."""
    if spec.choices:
        return spec.choices[0]
    kind = spec.types[0]
    if kind is str:
        return "/websim_test"
    if kind is int:
        return 0 if spec.minimum is None else int(spec.minimum)
    return kind()


def test_every_op_in_the_schema_is_answered_not_a_fault(rig: Rig) -> None:
    """An op the schema admits but no capability handles would be a fault, not an answer."""
    client = rig.client(admin=True)
    rig.send(client, {"op": "set_level", "level": "error"})
    for op, fields in OP_FIELDS.items():
        rig.send(client, {"op": op, **{name: _valid(spec) for name, spec in fields.items()
                                       if spec.required}})
    assert rig.bridge.faults.total == 0, rig.bridge.faults.last_reason
    assert not [frame for frame in rig.drain(client) if "internal error" in json.dumps(frame)]


def test_reply_overflow_marks_the_outbox(rig: Rig) -> None:
    session = Session("slow", False, Outbox(max_replies=5))
    rig.bridge.connect(session)
    for index in range(8):
        rig.send(session, {"op": "call_service", "service": "/rosapi/nodes", "id": str(index)})
    assert session.outbox.overflowed
    assert len(session.outbox) == 5


def test_deep_nesting_is_a_protocol_error_naming_the_limit(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "set_level", "level": "error"})
    rig.send(client, "[" * 100_000 + "]" * 100_000)
    rig.send(client, json.dumps({"op": "publish", "topic": "/cmd_vel",
                                 "msg": {"linear": _nested(MAX_NESTING - 2)}}))
    messages = [status["msg"] for status in rig.drain(client)]
    assert messages[0] == f"invalid JSON: too deeply nested (more than {MAX_NESTING} levels)"
    assert "too deeply" not in messages[1], "within the limit, the frame is parsed"


def test_huge_array_is_relayed_within_the_bounded_queue(rig: Rig) -> None:
    sender, reader = rig.client(), rig.client()
    rig.send(sender, {"op": "advertise", "topic": "/big", "type": "std_msgs/Float32MultiArray"})
    rig.send(reader, {"op": "subscribe", "topic": "/big"})
    reader.outbox.behind = True  # its socket takes nothing: the connection says so
    for _ in range(20):
        rig.send(sender, {"op": "publish", "topic": "/big", "msg": {"data": [1.5] * 20_000}})
    assert len(reader.outbox) == 1, "a reader that does not read keeps only the newest"
    assert len(rig.drain(reader)[0]["msg"]["data"]) == 20_000
    rig.tick(3)
    assert all(math.isfinite(v) for v in rig.robot.sim.ground_truth())


def test_one_client_cannot_grow_the_tables_without_bound(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "set_level", "level": "error"})
    for index in range(ClientLimits().max_subscriptions + 5):
        rig.send(client, {"op": "subscribe", "topic": f"/t{index}"})
    rig.send(client, {"op": "subscribe", "topic": "/t0", "id": "again"})
    assert len(client.subscriptions) == ClientLimits().max_subscriptions
    statuses = rig.drain(client)
    assert len(statuses) == 5
    assert all(f"at most {ClientLimits().max_subscriptions} subscriptions" in s["msg"]
               for s in statuses)


def test_rate_limit_is_a_token_bucket_counting_big_frames_more() -> None:
    clock = Clock()
    limit = RateLimit(200, clock=clock)
    assert all(limit.allow() for _ in range(200)), "a burst of one second's worth passes"
    assert not limit.allow()
    clock.now_s += 0.25
    assert sum(limit.allow() for _ in range(80)) == 50, "refills at 200/s"
    clock.now_s += 10.0
    assert limit.allow(1 << 20) and limit.allow(1 << 20) and limit.allow(1 << 20)
    assert not limit.allow(1 << 20), "1 MiB counts as 64 messages"
    assert limit.reason() == "rate limit: more than 200 messages/s"
    with pytest.raises(ValueError):
        RateLimit(0)


def test_origin_policy_admits_its_own_pages_local_pages_and_clients_without_origin() -> None:
    local = OriginPolicy.default("127.0.0.1", 8080)
    assert local.allows(None)
    assert local.allows("http://localhost:8080") and local.allows("http://127.0.0.1:8080/")
    assert local.allows("http://localhost:8000"), "a student's page from python -m http.server"
    assert local.allows("http://[::1]:3000")
    assert not local.allows("http://localhost.evil.example:8080")
    assert not local.allows("null"), "sandboxed frames and file:// pages send null"
    assert not local.allows("https://evil.example", "127.0.0.1:9090")
    classroom = OriginPolicy.default("0.0.0.0", 8080, ["https://robot.example"])
    assert classroom.allows("http://192.168.1.5:8080", "192.168.1.5:9090"), "any address"
    assert not classroom.allows("http://192.168.1.5:8080", "10.0.0.1:9090")
    assert not classroom.allows("http://evil.example:8080", "192.168.1.5:9090")
    assert classroom.allows("HTTPS://Robot.example")
    assert OriginPolicy.default("127.0.0.1", 8080, ["*"]).allows("http://anything:1")
    worker = OriginPolicy.default("127.0.0.1", 8080, proxied=True)  # nginx's page port
    assert worker.allows("http://class.example:8080", "class.example:9090"), "through nginx"
    assert worker.allows("http://192.168.1.5:8080", "192.168.1.5:9090")
    assert not worker.allows("http://evil.example:8080", "class.example:9090")
    assert not worker.allows("http://class.example:8081", "class.example:9090")
