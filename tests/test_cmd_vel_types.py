"""/cmd_vel as Twist and as TwistStamped, per client, and the command watchdog's timing.

In-process, through the robot's bridge as ``websim serve`` builds it (``robot_rig``), on a
manual clock: the robot takes both types, each client's messages of the type it advertised;
subscribers get the type they named; the watchdog stops the robot within its timeout and one
tick of the last command, measured on the robot's clock.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pytest
from bridge_rig import topics_of
from robot_rig import RobotRig, robot_rig
from rosbags.typesys import Stores, get_typestore

from ros_nodes.parameters import PARAMETER_DOUBLE
from ros_nodes.tap import IN
from rosbridge.core.graph_port import GraphPort
from rosbridge.core.session import Session

TWIST = "geometry_msgs/msg/Twist"
STAMPED = "geometry_msgs/msg/TwistStamped"


def twist(linear_mps: float, angular_rps: float = 0.0) -> dict[str, Any]:
    return {"linear": {"x": linear_mps, "y": 0.0, "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": angular_rps}}


def stamped(linear_mps: float, angular_rps: float = 0.0) -> dict[str, Any]:
    return {"header": {"stamp": {"sec": 7, "nanosec": 0}, "frame_id": "base_link"},
            "twist": twist(linear_mps, angular_rps)}


def statuses(rig: RobotRig, session: Session) -> list[str]:
    return [frame["msg"] for frame in rig.drain(session) if frame["op"] == "status"]


def advertise(rig: RobotRig, session: Session, type_name: str) -> None:
    rig.send(session, {"op": "set_level", "level": "error"})
    rig.send(session, {"op": "advertise", "topic": "/cmd_vel", "type": type_name})


def test_a_twist_stamped_client_drives_and_the_latest_command_of_either_type_wins() -> None:
    rig = robot_rig()
    heard: list[tuple[str, str, str]] = []
    rig.robot.tap.add(lambda direction, topic, type_name, *_: heard.append(
        (direction, topic, type_name)))
    nav2, teleop = rig.client("nav2"), rig.client("teleop")
    advertise(rig, nav2, STAMPED)
    advertise(rig, teleop, "geometry_msgs/Twist")
    rig.send(nav2, {"op": "publish", "topic": "/cmd_vel", "msg": stamped(0.3, 0.2)})
    assert rig.robot.sim.last_command == (0.3, 0.2)
    rig.send(teleop, {"op": "publish", "topic": "/cmd_vel", "msg": twist(0.0, -1.0)})
    assert rig.robot.sim.last_command == (0.0, -1.0)
    rig.send(nav2, {"op": "publish", "topic": "/cmd_vel", "msg": stamped(0.1)})
    assert rig.robot.sim.last_command == (0.1, 0.0)
    assert statuses(rig, nav2) == statuses(rig, teleop) == []
    assert [item for item in heard if item[0] == IN] == [
        (IN, "/cmd_vel", STAMPED), (IN, "/cmd_vel", TWIST), (IN, "/cmd_vel", STAMPED)]
    assert rig.host.endpoint.last_driver == "nav2"


def test_subscribers_get_the_type_they_named_and_a_typeless_one_gets_twist() -> None:
    rig = robot_rig()
    typeless, as_twist, as_stamped = rig.client("a"), rig.client("b"), rig.client("c")
    rig.send(typeless, {"op": "subscribe", "topic": "/cmd_vel"})
    rig.send(as_twist, {"op": "subscribe", "topic": "/cmd_vel", "type": TWIST})
    rig.send(as_stamped, {"op": "subscribe", "topic": "/cmd_vel", "type": STAMPED})
    nav2, teleop = rig.client("nav2"), rig.client("teleop")
    advertise(rig, nav2, STAMPED)
    rig.send(nav2, {"op": "publish", "topic": "/cmd_vel", "msg": stamped(0.3)})
    rig.send(teleop, {"op": "publish", "topic": "/cmd_vel", "msg": twist(0.2)})  # no advertise
    twists = [twist(0.2)]
    assert [frame["msg"] for frame in rig.drain(typeless)] == twists
    assert [frame["msg"] for frame in rig.drain(as_twist)] == twists
    (frame,) = rig.drain(as_stamped)
    assert frame["msg"]["twist"] == twist(0.3)
    assert frame["msg"]["header"]["frame_id"] == "base_link"


def test_a_stamped_command_in_cbor_raw_is_the_cdr_of_a_twist_stamped() -> None:
    rig = robot_rig()
    raw = rig.client("raw")
    rig.send(raw, {"op": "subscribe", "topic": "/cmd_vel", "type": STAMPED,
                   "compression": "cbor-raw"})
    nav2 = rig.client("nav2")
    advertise(rig, nav2, STAMPED)
    rig.send(nav2, {"op": "publish", "topic": "/cmd_vel", "msg": stamped(0.25, 0.5)})
    (frame,) = rig.drain(raw)
    store = get_typestore(Stores.ROS2_HUMBLE)
    msg = store.deserialize_cdr(bytes(frame["msg"]["bytes"]), STAMPED)
    assert (msg.twist.linear.x, msg.twist.angular.z) == (0.25, 0.5)
    assert (msg.header.stamp.sec, msg.header.frame_id) == (7, "base_link")


@pytest.mark.parametrize(("first", "second", "reason"), [
    (STAMPED, TWIST, "this client advertised it as geometry_msgs/msg/TwistStamped"),
    (TWIST, "geometry_msgs/msg/Vector3",
     "/cmd_vel carries geometry_msgs/msg/Twist or geometry_msgs/msg/TwistStamped, "
     "not geometry_msgs/msg/Vector3"),
])
def test_one_client_one_type_and_no_third_type(first: str, second: str, reason: str) -> None:
    rig = robot_rig()
    client = rig.client()
    advertise(rig, client, first)
    rig.send(client, {"op": "advertise", "topic": "/cmd_vel", "type": second})
    (status,) = statuses(rig, client)
    assert reason in status
    rig.send(client, {"op": "subscribe", "topic": "/cmd_vel", "type": first})
    rig.send(client, {"op": "subscribe", "topic": "/cmd_vel", "id": "2",
                      "type": STAMPED if first == TWIST else TWIST})
    assert "this client subscribed to it as" in statuses(rig, client)[0]


def test_a_malformed_stamped_command_is_refused_with_the_field() -> None:
    rig = robot_rig()
    nav2 = rig.client()
    advertise(rig, nav2, STAMPED)
    rig.send(nav2, {"op": "publish", "topic": "/cmd_vel",
                    "msg": {"twist": {"linear": {"x": "fast"}}}})
    (status,) = statuses(rig, nav2)
    assert "twist.linear.x" in status
    assert rig.robot.sim.last_command == (0.0, 0.0)


class RecordingGraph:
    """A ROS graph that records what the port publishes and advertises on it."""

    def __init__(self) -> None:
        self.calls: list[tuple[Any, ...]] = []

    def topic_types(self) -> Mapping[str, str]:
        return {}

    def advertise(self, topic: str, type_name: str) -> None:
        self.calls.append(("advertise", topic, type_name))

    def publish(self, topic: str, msg: Any) -> None:
        self.calls.append(("publish", topic, msg))

    def __getattr__(self, name: str) -> Any:
        return lambda *args, **kwargs: None


def test_with_a_graph_the_first_type_goes_out_and_the_other_stays_with_the_robot() -> None:
    rig = robot_rig()
    graph = RecordingGraph()
    port: GraphPort = rig.bridge.graph
    port.attach(graph)  # type: ignore[arg-type]
    teleop, nav2 = rig.client("teleop"), rig.client("nav2")
    advertise(rig, teleop, TWIST)
    advertise(rig, nav2, STAMPED)
    rig.send(nav2, {"op": "publish", "topic": "/cmd_vel", "msg": stamped(0.3)})
    rig.send(nav2, {"op": "publish", "topic": "/cmd_vel", "msg": stamped(0.3)})
    assert rig.robot.sim.last_command == (0.3, 0.0)  # the robot took it
    rig.send(teleop, {"op": "publish", "topic": "/cmd_vel", "msg": twist(0.1)})
    assert graph.calls == [("advertise", "/cmd_vel", TWIST),
                           ("publish", "/cmd_vel", twist(0.1))]
    assert statuses(rig, nav2) == [  # said once
        "/cmd_vel is published on the ROS graph as geometry_msgs/msg/Twist; "
        "geometry_msgs/msg/TwistStamped is relayed between clients only"]


def set_timeout(rig: RobotRig, timeout_s: float) -> None:
    admin = rig.client("admin", admin=True)
    reply = rig.call(admin, "/virtual_robot/set_parameters", {"parameters": [
        {"name": "cmd_vel_timeout_s", "value": {"type": PARAMETER_DOUBLE,
                                                "double_value": timeout_s}}]})
    assert reply["values"]["results"][0]["successful"], reply


def stamp_s(frame: dict[str, Any]) -> float:
    stamp = frame["msg"]["header"]["stamp"]
    return float(stamp["sec"] + stamp["nanosec"] * 1e-9)


@pytest.mark.parametrize("timeout_s", [0.5, 0.12, 0.03])
@pytest.mark.parametrize("offset_s", [0.0, 0.01, 0.049])
def test_the_watchdog_stops_within_the_timeout_and_one_tick(timeout_s: float,
                                                           offset_s: float) -> None:
    rig = robot_rig()
    set_timeout(rig, timeout_s)
    watcher, nav2 = rig.client("watcher"), rig.client("nav2")
    rig.send(watcher, {"op": "subscribe", "topic": "/odom"})
    advertise(rig, nav2, STAMPED)
    rig.tick(3)
    rig.tick_now()  # a tick, then the command offset_s after it, between two ticks
    dt_s = rig.robot.sim.dt_s
    rig.clock.advance(offset_s)
    sent_s = rig.clock.stamp_s()
    rig.send(nav2, {"op": "publish", "topic": "/cmd_vel", "msg": stamped(0.3)})
    rig.clock.advance(dt_s - offset_s)
    rig.drain(watcher)
    rig.tick(30)
    odom = rig.drain(watcher)
    assert topics_of(odom) == ["/odom"] * 30
    # A tick's /odom is stamped with the robot's clock when the tick runs. The robot moves
    # at the ticks less than the timeout after the command, and stands still from the first
    # tick at least the timeout after it, which is within the timeout and one tick.
    speeds = [frame["msg"]["twist"]["twist"]["linear"]["x"] for frame in odom]
    ages_s = [stamp_s(frame) - sent_s for frame in odom]
    assert speeds == [0.3 if age_s < timeout_s - 1e-6 else 0.0 for age_s in ages_s]
    first_stop = speeds.index(0.0)
    assert timeout_s - 1e-6 <= ages_s[first_stop] <= timeout_s + dt_s + 1e-6
    assert rig.robot.sim.ground_truth().x == pytest.approx(0.3 * dt_s * first_stop)


def test_every_command_restarts_the_watchdog_and_off_the_robot_keeps_going() -> None:
    rig = robot_rig()
    set_timeout(rig, 0.2)
    teleop = rig.client("teleop")
    for _ in range(20):  # a 10 Hz teleop turning in place: never 0.2 s without a command
        rig.send(teleop, {"op": "publish", "topic": "/cmd_vel", "msg": twist(0.0, 1.0)})
        rig.tick(2)
    assert rig.robot.sim.last_command == (0.0, 1.0)
    assert rig.robot.sim.ground_truth().theta == pytest.approx(1.0 * 40 * 0.05)

    set_timeout(rig, 0.0)
    rig.tick(200)  # ten seconds without a command: the course's robot keeps it
    assert rig.robot.sim.last_command == (0.0, 1.0)
    assert rig.robot.sim.ground_truth().theta == pytest.approx(1.0 * 240 * 0.05)
