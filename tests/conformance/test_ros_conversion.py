"""``websim serve --ros``: messages converted between browsers and a real ROS 2 graph.

* a transient-local (latched) topic of an rclpy publisher reaches every browser subscriber,
  the second and later ones too, each once, and one that subscribed before the publisher
  started;
* an integer out of its type's range from a browser is refused (rclpy's own field checks are
  off since Jazzy: 32767 in an int8 would reach the graph as -1), for a type websim defines
  and for one only an installed package defines;
* roslibpy's ROS 1 ``Header`` (a ``{secs, nsecs}`` stamp, a ``seq``) reaches an rclpy
  subscriber with its stamp;
* an rclpy ``Int32MultiArray``, ``Float64MultiArray`` and an ``Image``'s ``uint8[]`` reach a
  CBOR roslibjs subscriber as an ``Int32Array``, a ``Float64Array`` and a ``Uint8Array``.

Real processes: ``websim serve --ros``, roslibjs under Node, and an rclpy node in this test
process on a ROS_DOMAIN_ID of this test's own (``ros_fixtures``).
"""

from __future__ import annotations

import base64
from collections.abc import Iterator
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)
"""Fixtures domain, graph, test_world."""

import roslibpy  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402
from service_msgs.msg import ServiceEventInfo  # noqa: E402
from std_msgs.msg import (  # noqa: E402
    Float64MultiArray,
    Header,
    Int8,
    Int32MultiArray,
    String,
)
from test_typed_relay import NODE, NodeSubscriber, RawClient  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

from rosbridge.msgs import definitions  # noqa: E402

from ros_fixtures import LATCHED, RELIABLE, STARTUP_TIMEOUT_S, Graph  # noqa: E402
from server_process import ServerProcess, wait_for  # noqa: E402

ANSWER_TIMEOUT_S = 10.0


@pytest.fixture
def browsers(ros_server: ServerProcess) -> Iterator[Any]:
    """Opens roslibpy clients (``browsers()``), all closed at the end of the test."""
    opened: list[roslibpy.Ros] = []

    def open_client() -> roslibpy.Ros:
        client = roslibpy.Ros(host="127.0.0.1", port=ros_server.ws_port)
        client.run(timeout=10)
        opened.append(client)
        return client

    yield open_client
    for client in opened:
        client.close()


@pytest.fixture
def raw(ros_server: ServerProcess) -> Iterator[RawClient]:
    """A websockets client, which sees the status of a refused operation."""
    with connect(ros_server.ws_url, max_size=None) as connection:
        yield RawClient(connection)


def subscribed(client: roslibpy.Ros, topic: str, type_name: str) -> tuple[roslibpy.Topic,
                                                                          list[Any]]:
    """A roslibpy subscription in force and the list its messages go to."""
    messages: list[Any] = []
    listener = roslibpy.Topic(client, topic, type_name, queue_length=10)
    listener.subscribe(messages.append)
    client.get_topics()  # a round trip: the subscribe before it is in force
    return listener, messages


def test_a_latched_graph_topic_reaches_every_browser_subscriber_once(
        graph: Graph, browsers: Any) -> None:
    topic = "/latched_map"
    publisher = graph.node.create_publisher(String, topic, LATCHED)
    publisher.publish(String(data="map v1"))

    first_client, second_client, third_client = browsers(), browsers(), browsers()
    first, in_first = subscribed(first_client, topic, "std_msgs/msg/String")
    wait_for(lambda: in_first, STARTUP_TIMEOUT_S, "the latched message in the first browser")
    second, in_second = subscribed(second_client, topic, "std_msgs/msg/String")
    wait_for(lambda: in_second, ANSWER_TIMEOUT_S, "the latched message in the second browser")
    assert in_first == in_second == [{"data": "map v1"}]

    # Every browser leaves (the relay's subscription ends), then one comes back: it gets the
    # latched message once, not again from the new subscription's replay of the history.
    first.unsubscribe()
    second.unsubscribe()
    wait_for(lambda: publisher.get_subscription_count() == 0, ANSWER_TIMEOUT_S,
             "the relay to unsubscribe")
    _, in_third = subscribed(third_client, topic, "std_msgs/msg/String")
    wait_for(lambda: publisher.get_subscription_count() == 1, ANSWER_TIMEOUT_S,
             "the relay to subscribe again (and be sent the history)")
    publisher.publish(String(data="map v2"))
    wait_for(lambda: {"data": "map v2"} in in_third, ANSWER_TIMEOUT_S, "map v2")
    assert in_third == [{"data": "map v1"}, {"data": "map v2"}]


def test_a_latched_topic_that_starts_after_the_browser_subscribed_still_reaches_it(
        graph: Graph, browsers: Any) -> None:
    # The relay subscribes before any publisher exists (a page open before the map server
    # starts): its subscription is remade transient local once the publisher shows up.
    _, heard = subscribed(browsers(), "/late_map", "std_msgs/msg/String")
    publisher = graph.node.create_publisher(String, "/late_map", LATCHED)
    publisher.publish(String(data="published once, before anyone matched"))
    wait_for(lambda: heard, STARTUP_TIMEOUT_S, "the latched message in the browser")
    assert heard == [{"data": "published once, before anyone matched"}]


def resend_until_received(raw: RawClient, topic: str, msg: dict[str, Any],
                          received: list[Any], graph: Graph) -> None:
    """Publish ``msg`` until the graph has it (the relay's publisher matches after a while)."""
    count = len(received)

    def arrived() -> bool:
        if len(received) == count:
            raw.send(op="publish", topic=topic, msg=msg)
        return len(received) > count

    graph.spin_until(arrived, STARTUP_TIMEOUT_S, f"{msg} on the graph")


def test_an_int8_out_of_range_is_refused_not_sent_to_the_graph_as_minus_1(
        graph: Graph, raw: RawClient) -> None:
    received = graph.collect(Int8, "/small", RELIABLE)
    raw.send(op="advertise", topic="/small", type="std_msgs/msg/Int8")
    resend_until_received(raw, "/small", {"data": -5}, received, graph)  # matched now
    raw.send(op="publish", topic="/small", msg={"data": 32767})
    raw.send(op="publish", topic="/small", msg={"data": 6})
    assert raw.statuses() == ["publish to /small: data: 32767 is out of int8 range "
                              "(-128 to 127)"]
    graph.spin_until(lambda: received[-1][1].data == 6, ANSWER_TIMEOUT_S, "6 on the graph")
    assert {msg.data for _, msg in received} == {-5, 6}  # reliable and in order: no -1


def test_a_type_only_an_installed_package_defines_is_checked_through_rclpy(
        graph: Graph, raw: RawClient) -> None:
    type_name = "service_msgs/msg/ServiceEventInfo"  # a dependency of rclpy's since Jazzy
    assert not definitions.known(type_name)
    received = graph.collect(ServiceEventInfo, "/events", RELIABLE)
    raw.send(op="advertise", topic="/wangle", type="wangle_msgs/msg/Jam")
    raw.send(op="advertise", topic="/events", type=type_name)
    resend_until_received(raw, "/events", {"event_type": 1}, received, graph)
    raw.send(op="publish", topic="/events", msg={"event_type": 300})
    raw.send(op="publish", topic="/events", msg={"sequence_number": 2**63})
    raw.send(op="publish", topic="/events", msg={"event_type": 1, "colour": "red"})
    raw.send(op="publish", topic="/events", msg={
        "event_type": 2, "stamp": {"secs": 5, "nsecs": 6}, "client_gid": [7] * 16})
    assert raw.statuses() == [
        "advertise /wangle: Unable to import wangle_msgs.msg from package wangle_msgs. "
        "Caused by: No module named 'wangle_msgs' (pip install ros-wangle-msgs, or source a "
        "ROS 2 installation that has it)",
        "publish to /events: event_type: 300 is out of uint8 range (0 to 255)",
        "publish to /events: sequence_number: 9223372036854775808 is out of int64 range "
        "(-9223372036854775808 to 9223372036854775807)",
        "publish to /events: colour: service_msgs/msg/ServiceEventInfo has no such field "
        "(fields: event_type, stamp, client_gid, sequence_number)"]
    graph.spin_until(lambda: received[-1][1].event_type == 2, ANSWER_TIMEOUT_S,
                     "the last event on the graph")
    assert {msg.event_type for _, msg in received} == {1, 2}  # 300 did not go out as 44
    msg = received[-1][1]
    assert (msg.stamp.sec, msg.stamp.nanosec, msg.sequence_number) == (5, 6, 0)
    assert list(msg.client_gid) == [7] * 16


def test_a_roslibpy_header_with_secs_and_nsecs_reaches_rclpy_with_its_stamp(
        graph: Graph, browsers: Any) -> None:
    received = graph.collect(Header, "/stamped", RELIABLE)
    talker = roslibpy.Topic(browsers(), "/stamped", "std_msgs/msg/Header")
    talker.advertise()
    header = roslibpy.Header(seq=3, stamp={"secs": 1_700_000_000, "nsecs": 250_000_000},
                             frame_id="map")

    def published() -> bool:
        if not received:
            talker.publish(roslibpy.Message(header))
        return bool(received)

    graph.spin_until(published, ANSWER_TIMEOUT_S, "the Header on the graph")
    msg = received[0][1]
    assert (msg.stamp.sec, msg.stamp.nanosec, msg.frame_id) == (1_700_000_000, 250_000_000,
                                                                "map")


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_rclpy_numeric_arrays_reach_a_cbor_roslibjs_subscriber_as_typed_arrays(
        graph: Graph, ros_server: ServerProcess, browsers: Any) -> None:
    topics = {"/ints": "std_msgs/msg/Int32MultiArray",
              "/doubles": "std_msgs/msg/Float64MultiArray", "/camera": "sensor_msgs/msg/Image"}
    subscriber = NodeSubscriber(ros_server.ws_url, "cbor",
                                *(f"{name}:{type_name}" for name, type_name in topics.items()))
    _, in_json = subscribed(browsers(), "/camera", "sensor_msgs/msg/Image")
    ints = graph.node.create_publisher(Int32MultiArray, "/ints", RELIABLE)
    doubles = graph.node.create_publisher(Float64MultiArray, "/doubles", RELIABLE)
    camera = graph.node.create_publisher(Image, "/camera", RELIABLE)
    image = Image(height=1, width=4, encoding="mono8", step=4, data=bytes([0, 1, 128, 255]))

    def publish_each() -> None:  # volatile topics: again until the relay has matched them
        ints.publish(Int32MultiArray(data=[1, -2, 2**31 - 1]))
        doubles.publish(Float64MultiArray(data=[0.5, -1.25, 1e300]))
        camera.publish(image)
        graph.executor.spin_once(timeout_sec=0.1)

    wait_for(lambda: in_json, STARTUP_TIMEOUT_S, "the Image in roslibpy", pause=publish_each)
    first = subscriber.result()
    assert first["/ints"]["data"] == {"typed": "Int32Array", "values": [1, -2, 2**31 - 1]}
    assert first["/doubles"]["data"] == {"typed": "Float64Array",
                                         "values": [0.5, -1.25, 1e300]}
    assert first["/camera"]["data"] == {"typed": "Uint8Array", "values": [0, 1, 128, 255]}
    assert first["/camera"]["width"] == 4 and first["/camera"]["encoding"] == "mono8"
    # A JSON client gets the uint8[] as base64 text, as rosbridge sends it.
    assert in_json[0]["data"] == base64.b64encode(bytes([0, 1, 128, 255])).decode()
