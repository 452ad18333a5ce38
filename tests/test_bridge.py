"""The rosbridge protocol layer, driven in-process: real Simulation, VirtualRobot and Bridge.

The Bridge does no I/O, so these tests feed it frames and read what it queued per client.
A hand-advanced monotonic clock stands in for time where throttling and timeouts are checked.
"""

from __future__ import annotations

import itertools
import json
import math
from typing import Any

import cbor2
import numpy as np
import pytest

from physics import LidarParams, Simulation, load_world
from ros_nodes.parameters import PARAMETER_DOUBLE, PARAMETER_STRING
from ros_nodes.robot_endpoint import RobotEndpoint
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Bridge, Session
from rosbridge.core.clock import ManualClock
from rosbridge.core.encoding import MAX_NESTING
from rosbridge.core.limits import ClientLimits, OriginPolicy, RateLimit
from rosbridge.core.outbox import Outbox
from rosbridge.core.schema import OP_FIELDS


class Clock:
    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s

    def monotonic_s(self) -> float:
        return self.now_s

    def stamp_s(self) -> float:
        return 1_700_000_000.0 + self.now_s


class Rig:
    """A robot, its bridge, and helpers to act as clients."""

    def __init__(self, lidar: LidarParams | None = None) -> None:
        self.clock = Clock()
        self.robot = VirtualRobot(Simulation(load_world("empty"), lidar=lidar, seed=0),
                                  clock=ManualClock(epoch_s=1_700_000_000.25))
        self.bridge = Bridge(clock=self.clock)
        self.endpoint = RobotEndpoint(self.bridge, self.robot)

    def client(self, admin: bool = False) -> Session:
        session = Session("test-peer", admin, Outbox())
        self.bridge.connect(session)
        return session

    def send(self, session: Session, message: Any) -> None:
        self.bridge.handle(session, message if isinstance(message, (str, bytes))
                           else json.dumps(message))

    def tick(self, n: int = 1) -> None:
        for _ in range(n):
            for spec, msg in self.robot.step():
                self.bridge.publish(spec.name, msg)

    @staticmethod
    def drain(session: Session) -> list[Any]:
        frames = []
        while (frame := session.outbox.pop()) is not None:
            frames.append(cbor2.loads(frame) if isinstance(frame, bytes) else json.loads(frame))
        return frames

    def call(self, session: Session, service: str, args: Any = None, call_id: str = "c1") -> Any:
        self.send(session, {"op": "call_service", "service": service, "id": call_id,
                            "args": {} if args is None else args})
        replies = [f for f in self.drain(session) if f.get("op") == "service_response"]
        assert len(replies) == 1, replies
        assert replies[0]["id"] == call_id
        return replies[0]


@pytest.fixture
def rig() -> Rig:
    return Rig()


def topics_of(frames: list[Any]) -> list[str]:
    return [f["topic"] for f in frames if f.get("op") == "publish"]


def test_subscriber_gets_odom_every_tick_and_scan_every_second(rig: Rig) -> None:
    client = rig.client()
    for topic, type_name in (("/odom", "nav_msgs/msg/Odometry"),
                             ("/scan", "sensor_msgs/LaserScan")):
        rig.send(client, {"op": "subscribe", "topic": topic, "type": type_name,
                          "id": f"subscribe:{topic}:1", "queue_length": 10})
    rig.tick(4)
    assert topics_of(rig.drain(client)) == ["/odom", "/odom", "/scan", "/odom", "/odom",
                                            "/scan"]


def test_message_is_encoded_once_for_every_subscriber(rig: Rig) -> None:
    clients = [rig.client() for _ in range(3)]
    for client in clients:
        rig.send(client, {"op": "subscribe", "topic": "/odom"})
    rig.tick()
    frames = [client.outbox.pop() for client in clients]
    assert frames[0] is frames[1] is frames[2]


def test_cmd_vel_drives_the_robot_and_is_relayed(rig: Rig) -> None:
    driver, watcher = rig.client(), rig.client()
    rig.send(watcher, {"op": "subscribe", "topic": "/cmd_vel"})
    rig.send(driver, {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist",
                      "latch": False, "queue_size": 100, "id": "advertise:/cmd_vel:1"})
    twist = {"linear": {"x": 0.3, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.5}}
    rig.send(driver, {"op": "publish", "topic": "/cmd_vel", "msg": twist, "id": "p1",
                      "latch": False})
    assert rig.robot.sim.last_command == (0.3, 0.5)
    assert rig.drain(watcher) == [{"op": "publish", "topic": "/cmd_vel", "msg": twist}]
    assert rig.drain(driver) == []


def test_odom_json_shape(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom"})
    rig.robot.sim.command(0.0, 1.0)
    rig.tick(10)
    msg = rig.drain(client)[-1]["msg"]
    assert msg["header"] == {"stamp": {"sec": 1_700_000_000, "nanosec": 250_000_000},
                             "frame_id": "odom"}
    assert msg["child_frame_id"] == "base_link"
    q = msg["pose"]["pose"]["orientation"]
    assert (q["x"], q["y"]) == (0.0, 0.0)
    assert 2 * math.atan2(q["z"], q["w"]) == pytest.approx(0.5)
    assert len(msg["pose"]["covariance"]) == 36 and len(msg["twist"]["covariance"]) == 36
    assert msg["pose"]["covariance"][0] > 0 and msg["twist"]["covariance"][35] > 0
    assert msg["twist"]["twist"]["angular"]["z"] == 1.0


def test_late_subscriber_gets_latched_tf_static_and_world(rig: Rig) -> None:
    rig.tick(20)
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/tf_static"})
    rig.send(client, {"op": "subscribe", "topic": "/world"})
    frames = rig.drain(client)
    assert topics_of(frames) == ["/tf_static", "/world"]
    transform = frames[0]["msg"]["transforms"][0]
    assert (transform["header"]["frame_id"], transform["child_frame_id"]) == ("base_link",
                                                                              "laser")
    marker = frames[1]["msg"]["markers"][0]
    assert marker["type"] == 5 and len(marker["points"]) == 8


def test_repeated_subscribe_with_same_id_is_idempotent(rig: Rig) -> None:
    client = rig.client()
    for _ in range(3):
        rig.send(client, {"op": "subscribe", "topic": "/odom", "id": "subscribe:/odom:1"})
    rig.tick()
    assert topics_of(rig.drain(client)) == ["/odom"]


def test_unsubscribe_with_and_without_id(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom", "id": "a"})
    rig.send(client, {"op": "subscribe", "topic": "/odom", "id": "b"})
    rig.send(client, {"op": "unsubscribe", "topic": "/odom", "id": "a"})
    rig.tick()
    assert topics_of(rig.drain(client)) == ["/odom"], "id b still subscribes"
    rig.send(client, {"op": "unsubscribe", "topic": "/odom"})
    rig.tick()
    assert rig.drain(client) == []


def test_throttle_rate_drops_messages_inside_the_window(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom", "throttle_rate": 200,
                      "queue_length": 100})
    received = 0
    for _ in range(40):
        rig.tick()
        rig.clock.now_s += 0.05
        received += len(rig.drain(client))
    assert received == 10, "20 Hz throttled to one per 200 ms"


def test_queue_length_keeps_the_newest_messages_for_a_slow_client(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom", "queue_length": 3})
    rig.robot.sim.command(0.1, 0.0)
    rig.tick(10)
    xs = [f["msg"]["pose"]["pose"]["position"]["x"] for f in rig.drain(client)]
    assert xs == pytest.approx([0.040, 0.045, 0.050])
    assert client.outbox.dropped == 7


def test_default_queue_length_0_sends_every_message_while_the_client_keeps_up(
        rig: Rig) -> None:
    """rosbridge with no throttle: queue_length 0 drops nothing (a burst arrives whole)."""
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom"})
    rig.tick(5)
    stamps = [f["msg"]["header"]["stamp"]["nanosec"] for f in rig.drain(client)]
    assert len(stamps) == 5 and stamps == sorted(stamps)
    assert client.outbox.dropped == 0


def test_default_queue_length_0_keeps_only_the_newest_while_the_client_is_behind(
        rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom"})
    rig.tick(3)
    client.outbox.behind = True  # what the connection sets when the socket backs up
    rig.tick(2)
    frames = rig.drain(client)
    assert len(frames) == 1 and client.outbox.dropped == 4
    client.outbox.behind = False
    rig.tick(4)
    assert len(rig.drain(client)) == 4


def test_cbor_subscription_gets_binary_frames_with_typed_float32_ranges(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/scan", "compression": "cbor"})
    rig.tick(2)
    frame = client.outbox.pop()
    assert isinstance(frame, bytes)
    decoded = cbor2.loads(frame)
    assert decoded["op"] == "publish" and decoded["topic"] == "/scan"
    ranges = decoded["msg"]["ranges"]
    assert isinstance(ranges, cbor2.CBORTag) and ranges.tag == 85
    values = np.frombuffer(ranges.value, dtype="<f4")
    assert values.shape == (360,)
    assert values == pytest.approx(np.array(rig.robot.sim.scan().ranges), abs=1e-6)


def test_non_finite_ranges_are_null_in_json_and_inf_in_cbor() -> None:
    rig = Rig(lidar=LidarParams(no_return="inf", range_max_m=2.0))
    text, binary = rig.client(), rig.client()
    rig.send(text, {"op": "subscribe", "topic": "/scan"})
    rig.send(binary, {"op": "subscribe", "topic": "/scan", "compression": "cbor"})
    rig.tick(2)
    raw = text.outbox.pop()
    assert isinstance(raw, str) and "Infinity" not in raw and "NaN" not in raw
    assert json.loads(raw)["msg"]["ranges"][45] is None
    packed = cbor2.loads(binary.outbox.pop())["msg"]["ranges"].value
    assert np.isinf(np.frombuffer(packed, dtype="<f4")[45])


def test_both_type_spellings_are_accepted_and_mismatches_refused(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "set_level", "level": "error"})
    rig.send(client, {"op": "subscribe", "topic": "/odom", "type": "nav_msgs/Odometry"})
    rig.send(client, {"op": "subscribe", "topic": "/scan", "type": "geometry_msgs/msg/Twist",
                      "id": "s1"})
    statuses = [f for f in rig.drain(client) if f["op"] == "status"]
    assert len(statuses) == 1 and statuses[0]["id"] == "s1"
    assert "/scan carries sensor_msgs/msg/LaserScan" in statuses[0]["msg"]


def test_publishing_a_simulator_topic_is_refused(rig: Rig) -> None:
    client, watcher = rig.client(), rig.client()
    rig.send(client, {"op": "set_level", "level": "error"})
    rig.send(watcher, {"op": "subscribe", "topic": "/odom"})
    rig.send(client, {"op": "advertise", "topic": "/odom", "type": "nav_msgs/msg/Odometry"})
    rig.send(client, {"op": "publish", "topic": "/odom", "msg": {}})
    statuses = rig.drain(client)
    assert [s["op"] for s in statuses] == ["status", "status"]
    assert all("published by the simulator" in s["msg"] for s in statuses)
    assert rig.drain(watcher) == []


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


def test_every_op_in_the_schema_has_a_handler(rig: Rig) -> None:
    assert set(OP_FIELDS) == set(rig.bridge._handlers)


def test_clients_relay_topics_to_each_other(rig: Rig) -> None:
    talker, listener = rig.client(), rig.client()
    rig.send(talker, {"op": "advertise", "topic": "/chatter", "type": "std_msgs/String"})
    rig.send(listener, {"op": "subscribe", "topic": "/chatter", "type": "std_msgs/msg/String"})
    rig.send(talker, {"op": "publish", "topic": "/chatter", "msg": {"data": "hi"}})
    assert rig.drain(listener) == [{"op": "publish", "topic": "/chatter",
                                    "msg": {"data": "hi"}}]
    assert rig.bridge.topic_types()["/chatter"] == "std_msgs/msg/String"
    rig.bridge.disconnect(talker)
    assert "/chatter" not in rig.bridge.topic_types()


def test_latched_client_topic_reaches_late_subscribers(rig: Rig) -> None:
    talker = rig.client()
    rig.send(talker, {"op": "advertise", "topic": "/goal", "type": "std_msgs/String",
                      "latch": True})
    rig.send(talker, {"op": "publish", "topic": "/goal", "msg": {"data": "x"}, "latch": True})
    late = rig.client()
    rig.send(late, {"op": "subscribe", "topic": "/goal"})
    assert topics_of(rig.drain(late)) == ["/goal"]


def test_unknown_service_fails_with_reason(rig: Rig) -> None:
    reply = rig.call(rig.client(), "/nope")
    assert reply["result"] is False and "does not exist" in reply["values"]


def test_reset_simulation(rig: Rig) -> None:
    rig.robot.sim.command(0.3, 0.2)
    rig.tick(20)
    reply = rig.call(rig.client(), "/reset_simulation", call_id="call_service:/reset:1")
    assert reply == {"op": "service_response", "service": "/reset_simulation", "values": {},
                     "result": True, "id": "call_service:/reset:1"}
    assert rig.robot.sim.ground_truth() == (0.0, 0.0, 0.0, 0.0, 0.0)


def set_mass(rig: Rig, session: Session, value: Any) -> Any:
    return rig.call(session, "/virtual_robot/set_parameters", {"parameters": [
        {"name": "mass_kg", "value": {"type": PARAMETER_DOUBLE, "double_value": value}}]})


def test_set_parameters_needs_the_admin_token(rig: Rig) -> None:
    reply = set_mass(rig, rig.client(admin=False), 2.4)
    assert reply["result"] is False
    assert "set_parameters needs admin rights" in reply["values"] and "token" in reply["values"]
    assert rig.robot.sim.params.mass_kg == 1.2


def test_set_and_get_parameters_with_admin(rig: Rig) -> None:
    admin, student = rig.client(admin=True), rig.client()
    reply = set_mass(rig, admin, 2.4)
    assert reply["result"] is True
    assert reply["values"] == {"results": [{"successful": True, "reason": ""}]}
    got = rig.call(student, "/virtual_robot/get_parameters", {"names": ["mass_kg", "mode",
                                                                       "nope"]})
    values = got["values"]["values"]
    assert values[0]["type"] == PARAMETER_DOUBLE and values[0]["double_value"] == 2.4
    assert values[1]["type"] == PARAMETER_STRING and values[1]["string_value"] == "kinematic"
    assert values[2]["type"] == 0
    bad = set_mass(rig, admin, -1.0)["values"]["results"][0]
    assert bad["successful"] is False
    assert "mass_kg: must be between 0.01 and 1000, got -1.0" in bad["reason"]
    assert rig.robot.sim.params.mass_kg == 2.4


def test_mode_parameter_switches_the_model(rig: Rig) -> None:
    reply = rig.call(rig.client(admin=True), "/virtual_robot/set_parameters", {"parameters": [
        {"name": "mode", "value": {"type": PARAMETER_STRING, "string_value": "dynamic"}}]})
    assert reply["values"]["results"][0]["successful"] is True
    assert rig.robot.sim.mode == "dynamic"


def test_list_and_describe_parameters(rig: Rig) -> None:
    client = rig.client()
    names = rig.call(client, "/virtual_robot/list_parameters", {"prefixes": [], "depth": 0})
    listed = names["values"]["result"]["names"]
    assert {"mode", "mass_kg", "inertia_kg_m2", "max_linear_mps", "max_angular_rps"} <= \
        set(listed)
    described = rig.call(client, "/virtual_robot/describe_parameters", {"names": ["mass_kg"]})
    assert described["values"]["descriptors"][0]["type"] == PARAMETER_DOUBLE


def test_rosapi_topics_types_and_params(rig: Rig) -> None:
    client, admin = rig.client(), rig.client(admin=True)
    topics = rig.call(client, "/rosapi/topics")["values"]
    table = dict(zip(topics["topics"], topics["types"], strict=True))
    assert table["/odom"] == "nav_msgs/msg/Odometry"
    assert table["/tf"] == "tf2_msgs/msg/TFMessage"
    assert rig.call(client, "/rosapi/topic_type", {"topic": "/scan"})["values"] == {
        "type": "sensor_msgs/msg/LaserScan"}
    assert "/virtual_robot/set_parameters" in \
        rig.call(client, "/rosapi/services")["values"]["services"]
    names = rig.call(client, "/rosapi/get_param_names")["values"]["names"]
    assert "/virtual_robot:mass_kg" in names
    assert rig.call(client, "/rosapi/get_param", {"name": "/virtual_robot:mass_kg",
                                                  "default_value": ""})["values"] == {
        "value": "1.2", "successful": True, "reason": ""}
    refused = rig.call(client, "/rosapi/set_param", {"name": "/virtual_robot:mass_kg",
                                                     "value": "3.0"})["values"]
    assert refused["successful"] is False and "admin" in refused["reason"]
    assert rig.call(admin, "/rosapi/set_param", {"name": "/virtual_robot:mass_kg",
                                                 "value": "3.0"})["values"]["successful"]
    assert rig.robot.sim.params.mass_kg == 3.0


def test_client_provided_service_round_trip(rig: Rig) -> None:
    provider, caller = rig.client(), rig.client()
    rig.send(provider, {"op": "advertise_service", "service": "/add",
                        "type": "example_interfaces/AddTwoInts"})
    rig.send(caller, {"op": "call_service", "service": "/add", "id": "mine",
                      "args": {"a": 1, "b": 2}})
    [request] = rig.drain(provider)
    assert request["op"] == "call_service" and request["args"] == {"a": 1, "b": 2}
    rig.send(provider, {"op": "service_response", "service": "/add", "id": request["id"],
                        "values": {"sum": 3}, "result": True})
    assert rig.drain(caller) == [{"op": "service_response", "service": "/add",
                                  "values": {"sum": 3}, "result": True, "id": "mine"}]
    assert rig.bridge.services.types()["/add"] == "example_interfaces/srv/AddTwoInts"


def test_hanging_client_service_times_out(rig: Rig) -> None:
    provider, caller = rig.client(), rig.client()
    rig.send(provider, {"op": "advertise_service", "service": "/slow", "type": "std_srvs/Empty"})
    rig.send(caller, {"op": "call_service", "service": "/slow", "id": "c"})
    rig.send(caller, {"op": "subscribe", "topic": "/odom"})
    rig.tick()
    assert topics_of(rig.drain(caller)) == ["/odom"], "other traffic is not blocked"
    rig.clock.now_s += 4.9
    rig.bridge.services.expire()
    assert rig.drain(caller) == []
    rig.clock.now_s += 0.2
    rig.bridge.services.expire()
    [reply] = rig.drain(caller)
    assert reply["result"] is False and "did not answer within 5 s" in reply["values"]


def test_provider_disconnect_fails_its_pending_calls(rig: Rig) -> None:
    provider, caller = rig.client(), rig.client()
    rig.send(provider, {"op": "advertise_service", "service": "/s", "type": "std_srvs/Empty"})
    rig.send(caller, {"op": "call_service", "service": "/s", "id": "c"})
    rig.bridge.disconnect(provider)
    [reply] = rig.drain(caller)
    assert reply["result"] is False and "disconnected" in reply["values"]
    assert "/s" not in rig.bridge.services.types()


def test_disconnect_forgets_everything_of_the_client(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom"})
    rig.send(client, {"op": "advertise", "topic": "/mine", "type": "std_msgs/String"})
    rig.bridge.disconnect(client)
    assert client not in rig.bridge.sessions
    assert list(rig.bridge.topics.subscribed_topics()) == []
    assert "/mine" not in rig.bridge.topic_types()


def test_reply_overflow_marks_the_outbox(rig: Rig) -> None:
    session = Session("slow", False, Outbox(max_replies=5))
    rig.bridge.connect(session)
    for index in range(8):
        rig.send(session, {"op": "call_service", "service": "/rosapi/nodes", "id": str(index)})
    assert session.outbox.overflowed
    assert len(session.outbox) == 5


def test_throttle_never_sends_closer_than_the_rate_less_jitter(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom", "throttle_rate": 200,
                      "queue_length": 100})
    sent_at = []
    lateness = [0.0, 0.004, 0.001, 0.0045, 0.002]  # ticks start late, never early
    for tick in range(60):
        rig.clock.now_s = 100.0 + 0.05 * tick + lateness[tick % len(lateness)]
        rig.tick()
        if rig.drain(client):
            sent_at.append(rig.clock.now_s)
    gaps = [b - a for a, b in itertools.pairwise(sent_at)]
    assert min(gaps) >= 0.195
    assert len(sent_at) == 15, "5 Hz over 3 s despite the jitter"


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


def test_students_publish_cmd_vel_and_their_own_topics_and_subscribe_to_any(rig: Rig) -> None:
    client, other = rig.client(), rig.client()
    rig.send(client, {"op": "set_level", "level": "error"})
    rig.send(other, {"op": "subscribe", "topic": "/chat"})
    rig.send(client, {"op": "advertise", "topic": "/chat", "type": "std_msgs/String"})
    rig.send(client, {"op": "publish", "topic": "/chat", "msg": {"data": "hi"}})
    rig.send(client, {"op": "publish", "topic": "/cmd_vel",
                      "msg": {"linear": {"x": 0.1}, "angular": {"z": 0.0}}})
    rig.send(client, {"op": "subscribe", "topic": "not_yet_published"})
    assert rig.drain(client) == []
    assert [m["msg"] for m in rig.drain(other)] == [{"data": "hi"}]
    assert rig.robot.sim.last_command == (0.1, 0.0)


def test_access_denial_of_a_service_call_is_a_failed_response(rig: Rig) -> None:
    client = rig.client()
    reply = rig.call(client, "/bad name!")
    assert reply["result"] is False and "not a ROS name" in reply["values"]


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
