"""The bridge's topics, driven in-process: subscribe, publish, latching, encodings, relay.

A real Simulation, VirtualRobot and Bridge (``bridge_rig.Rig``): frames in, what the bridge
queued per client out.
"""

from __future__ import annotations

import json
import math

import cbor2
import numpy as np
import pytest
from bridge_rig import Rig, topics_of

from physics import LidarParams
from rosbridge.core.bridge import Session
from rosbridge.core.outbox import Outbox


@pytest.fixture
def rig() -> Rig:
    return Rig()


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


def test_disconnect_forgets_everything_of_the_client(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom"})
    rig.send(client, {"op": "advertise", "topic": "/mine", "type": "std_msgs/String"})
    rig.bridge.disconnect(client)
    assert client not in rig.bridge.sessions
    assert list(rig.bridge.topics.subscribed_topics()) == []
    assert "/mine" not in rig.bridge.topic_types()


def test_a_namespaced_client_gets_its_names_prefixed_in_messages_encoded_once(rig: Rig) -> None:
    """The instructor's view of a class: robot alice's /odom is /alice/odom."""
    views = [Session(f"instructor-{i}", True, Outbox(), namespace="/alice") for i in range(2)]
    for view in views:
        rig.bridge.connect(view)
        rig.send(view, {"op": "subscribe", "topic": "/odom"})
    rig.tick()
    frames = [view.outbox.pop() for view in views]
    assert frames[0] is frames[1], "encoded once for both"
    assert json.loads(str(frames[0]))["topic"] == "/alice/odom"
    reply = rig.call(views[0], "/nope")
    assert reply["service"] == "/alice/nope" and reply["result"] is False
