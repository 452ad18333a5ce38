"""What ``websim serve --ros`` adds to the ROS-free layers, tested without ROS.

The bridge's ``Graph`` hook (driven with a recording graph), the command watchdog
(``cmd_vel_timeout_s``) and validation without side effects (``RobotParameters.check``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import cbor2
import pytest
from robot_rig import robot_rig
from rosbags.typesys import Stores, get_typestore

from physics import ConfigError, RobotParams, Simulation, load_world
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import BridgeError, Session
from rosbridge.core.clock import ManualClock
from rosbridge.core.outbox import Outbox

TWIST = {"linear": {"x": 0.3, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


class RecordingGraph:
    """A ROS graph that records what the bridge asks of it."""

    def __init__(self, types: Mapping[str, str] | None = None,
                 missing: tuple[str, ...] = ()) -> None:
        self.types = dict(types or {})
        self.missing = missing
        self.calls: list[tuple[Any, ...]] = []

    def topic_types(self) -> Mapping[str, str]:
        return self.types

    def subscribe(self, topic: str, type_name: str | None) -> None:
        self._check(type_name)
        self.calls.append(("subscribe", topic, type_name))

    def unsubscribe(self, topic: str) -> None:
        self.calls.append(("unsubscribe", topic))

    def advertise(self, topic: str, type_name: str) -> None:
        self._check(type_name)
        self.calls.append(("advertise", topic, type_name))

    def unadvertise(self, topic: str) -> None:
        self.calls.append(("unadvertise", topic))

    def publish(self, topic: str, msg: Any) -> None:
        self.calls.append(("publish", topic, msg))

    def _check(self, type_name: str | None) -> None:
        if type_name is not None and type_name.split("/")[0] in self.missing:
            raise BridgeError(f"package {type_name.split('/')[0]} is not installed")


class Rig:
    def __init__(self, graph: RecordingGraph | None = None) -> None:
        rig = robot_rig()
        self.robot, self.bridge = rig.robot, rig.bridge
        self.graph = graph or RecordingGraph()
        self.bridge.graph.attach(self.graph)

    def client(self) -> Session:
        session = Session("test-peer", False, Outbox())
        self.bridge.connect(session)
        session.status_level = "error"
        return session

    def send(self, session: Session, message: dict[str, Any]) -> None:
        self.bridge.handle(session, json.dumps(message))

    @staticmethod
    def drain(session: Session) -> list[Any]:
        frames = []
        while (frame := session.outbox.pop()) is not None:
            assert isinstance(frame, str)
            frames.append(json.loads(frame))
        return frames


def test_subscribing_a_graph_topic_subscribes_once_and_relays_its_messages() -> None:
    rig = Rig(RecordingGraph({"/chatter": "std_msgs/msg/String"}))
    first, second = rig.client(), rig.client()
    rig.send(first, {"op": "subscribe", "topic": "/chatter", "type": "std_msgs/String"})
    rig.send(second, {"op": "subscribe", "topic": "/chatter"})
    assert rig.graph.calls == [("subscribe", "/chatter", "std_msgs/msg/String")]
    rig.bridge.publish("/chatter", {"data": "hi"})  # what the relay does for each message
    for client in (first, second):
        assert rig.drain(client) == [{"op": "publish", "topic": "/chatter",
                                      "msg": {"data": "hi"}}]
    rig.send(first, {"op": "unsubscribe", "topic": "/chatter"})
    assert rig.graph.calls[-1][0] == "subscribe"
    rig.bridge.disconnect(second)
    assert rig.graph.calls[-1] == ("unsubscribe", "/chatter")
    assert "/chatter" in rig.bridge.topic_types()


def test_robot_topics_never_come_from_the_graph() -> None:
    rig = Rig()
    client = rig.client()
    for topic in ("/odom", "/scan", "/tf", "/tf_static", "/world", "/ground_truth"):
        rig.send(client, {"op": "subscribe", "topic": topic})
    assert rig.graph.calls == []


def test_client_publications_go_to_the_graph_cmd_vel_included() -> None:
    rig = Rig()
    client = rig.client()
    rig.send(client, {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"})
    rig.send(client, {"op": "publish", "topic": "/cmd_vel", "msg": TWIST})
    assert rig.robot.sim.last_command == (0.3, 0.0)  # applied here, not via the graph
    assert rig.graph.calls == [("advertise", "/cmd_vel", "geometry_msgs/msg/Twist"),
                               ("publish", "/cmd_vel", TWIST)]
    rig.bridge.disconnect(client)
    assert rig.graph.calls[-1] == ("unadvertise", "/cmd_vel")


def test_a_missing_message_package_leaves_client_relay_working() -> None:
    rig = Rig(RecordingGraph(missing=("example_interfaces",)))  # websim knows its types
    talker, listener = rig.client(), rig.client()
    rig.send(listener, {"op": "subscribe", "topic": "/custom",
                        "type": "example_interfaces/Int32"})
    rig.send(talker, {"op": "advertise", "topic": "/custom", "type": "example_interfaces/Int32"})
    rig.send(talker, {"op": "publish", "topic": "/custom", "msg": {"data": 1}})
    statuses = [frame["msg"] for frame in rig.drain(talker) if frame["op"] == "status"]
    assert statuses == ["package example_interfaces is not installed; /custom is relayed "
                        "between clients only"]
    assert [frame["msg"] for frame in rig.drain(listener) if frame["op"] == "publish"] == [
        {"data": 1}]
    assert not any(call[0] == "publish" for call in rig.graph.calls)


def cdr_payloads(session: Session) -> list[Any]:
    """What ``session`` was sent: each cbor-raw frame's CDR decoded (rosbags), else the frame."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    out: list[Any] = []
    while (frame := session.outbox.pop()) is not None:
        if isinstance(frame, bytes):
            envelope = cbor2.loads(frame)
            out.append(store.deserialize_cdr(envelope["msg"]["bytes"], "std_msgs/msg/String"))
        else:
            out.append(json.loads(frame))
    return out


def test_a_cbor_raw_subscribe_without_a_type_gets_a_graph_topics_cdr() -> None:
    # Lichtblick's RosbridgePlayer: the type only rosapi knows (the graph's), none given.
    rig = Rig(RecordingGraph({"/chatter": "std_msgs/msg/String"}))
    player = rig.client()
    rig.send(player, {"op": "subscribe", "topic": "/chatter", "compression": "cbor-raw"})
    assert rig.graph.calls == [("subscribe", "/chatter", None)]
    # what the relay does: the message with the type its rclpy subscription took, latched
    rig.bridge.publish("/chatter", {"data": "hello"}, latch=True,
                       type_name="std_msgs/msg/String")
    [message] = cdr_payloads(player)
    assert message.data == "hello"


def test_a_late_subscriber_gets_the_latched_graph_message_as_cdr_with_or_without_type() -> None:
    rig = Rig(RecordingGraph({"/chatter": "std_msgs/msg/String"}))
    first = rig.client()
    rig.send(first, {"op": "subscribe", "topic": "/chatter", "compression": "cbor-raw"})
    rig.bridge.publish("/chatter", {"data": "latched"}, latch=True,
                       type_name="std_msgs/msg/String")
    assert [m.data for m in cdr_payloads(first)] == ["latched"]
    for subscribe in ({"type": "std_msgs/msg/String"}, {}):  # no new message in between
        late = rig.client()
        rig.send(late, {"op": "subscribe", "topic": "/chatter", "compression": "cbor-raw",
                        **subscribe})
        assert [m.data for m in cdr_payloads(late)] == ["latched"]


def test_an_in_process_message_takes_the_type_a_subscription_named_for_its_topic() -> None:
    rig = Rig()
    untyped, typed = rig.client(), rig.client()
    rig.send(untyped, {"op": "subscribe", "topic": "/mystery", "compression": "cbor-raw"})
    rig.bridge.publish("/mystery", {"data": "x"})  # nobody knows its type
    [status] = cdr_payloads(untyped)
    assert status["op"] == "status" and "its type is not known" in status["msg"]
    rig.send(typed, {"op": "subscribe", "topic": "/mystery", "type": "std_msgs/msg/String"})
    rig.bridge.publish("/mystery", {"data": "y"}, latch=True)
    assert [m.data for m in cdr_payloads(untyped)] == ["y"]


def test_cbor_raw_of_a_graph_type_websim_cannot_serialize_is_refused_at_subscribe() -> None:
    rig = Rig(RecordingGraph({"/custom": "my_pkg/msg/Custom"}))
    player = rig.client()
    rig.send(player, {"op": "subscribe", "topic": "/custom", "compression": "cbor-raw"})
    [status] = rig.drain(player)
    assert "my_pkg/msg/Custom is not a type websim can serialize" in status["msg"]


def test_the_watchdog_stops_after_cmd_vel_timeout() -> None:
    clock = ManualClock()
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0), clock)
    robot.parameters.set("cmd_vel_timeout_s", 0.5)
    robot.on_cmd_vel(TWIST)
    for _ in range(40):
        robot.step()
        clock.advance(robot.sim.dt_s)
    # 0.5 s of 0.3 m/s: exactly ten 50 ms ticks of 15 mm, then standing still.
    assert robot.sim.odometry().x == pytest.approx(0.15, abs=1e-12)
    assert robot.sim.last_command == (0.0, 0.0)


def test_without_timeout_the_robot_keeps_the_last_command() -> None:
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0))
    assert robot.parameters.get("cmd_vel_timeout_s") == 0.0
    robot.on_cmd_vel(TWIST)
    for _ in range(40):
        robot.step()
    assert robot.sim.odometry().x == pytest.approx(0.3 * 40 * 0.05, abs=1e-12)


def test_check_validates_without_changing_anything() -> None:
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0))
    params = robot.parameters
    assert params.check({"mass_kg": 2, "mode": "dynamic", "cmd_vel_timeout_s": 1}) == {
        "mass_kg": 2.0, "mode": "dynamic", "cmd_vel_timeout_s": 1.0}
    assert (robot.sim.params.mass_kg, robot.sim.mode) == (RobotParams().mass_kg, "kinematic")
    for values, reason in (({"mass_kg": -1.0}, "mass_kg: must be between 0.01 and 1000"),
                           ({"cmd_vel_timeout_s": -0.5}, "cmd_vel_timeout_s"),
                           ({"mode": "flying"}, "must be one of kinematic, dynamic"),
                           ({"mass": 1.0}, "mass: no such parameter")):
        with pytest.raises(ConfigError, match=reason):
            params.check(values)


def test_parameter_listeners_hear_every_change() -> None:
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0))
    heard: list[list[str]] = []
    robot.parameters.listeners.append(heard.append)
    robot.parameters.set_many({"mass_kg": 2.0, "mode": "dynamic"})
    with pytest.raises(ConfigError):
        robot.parameters.set("mass_kg", 0.0)
    assert heard == [["mass_kg", "mode"]]
