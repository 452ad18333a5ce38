"""Typed relay between clients, as rosbridge's message conversion does it (no ROS graph).

A message a client publishes reaches the other clients as a message of its type: missing
fields filled with their defaults, fields the type lacks refused with a status naming them,
integers out of their type's range refused, ROS 1's ``{secs, nsecs}`` stamps accepted and
relayed as ``{sec, nanosec}``, and a type websim defines nowhere (``wangle_msgs/Jam``) refused
at advertise with rosbridge's reason. example_interfaces, which the rosbags typestore lacks,
is shipped (``ros_nodes/interfaces``). Numeric arrays reach a CBOR roslibjs subscriber as
typed arrays and ``uint8[]`` as bytes, as they do from rclpy with ``--ros``.

Real clients against a real ``websim serve``: the websockets library (which shows the exact
JSON and the status messages), roslibpy, and roslibjs under Node.
"""

from __future__ import annotations

import base64
import contextlib
import itertools
import json
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import roslibpy
from websockets.sync.client import ClientConnection, connect

from rosbridge.msgs.checks import INTEGER_RANGES
from rosbridge.msgs.definitions import COURSE_PACKAGES, packages

from server_process import ServerProcess, wait_for

NODE = shutil.which("node")
OTHER_PACKAGES = len(packages()) - len(COURSE_PACKAGES)
"""How many more packages than the course's the refusal counts (its wording)."""
NODE_PROGRAMS = Path(__file__).parent / "node"
ANSWER_TIMEOUT_S = 10.0
"""How long a round trip to the server may take on a loaded machine."""

ZERO_TWIST = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0},
              "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


class RawClient:
    """A rosbridge client on the websockets library: JSON frames in and out, statuses on."""

    _ids = itertools.count()

    def __init__(self, connection: ClientConnection) -> None:
        self.connection = connection
        self.pending: list[dict[str, Any]] = []
        """Frames received while waiting for another, not yet looked at."""
        self.send(op="set_level", level="error")

    def send(self, **message: Any) -> None:
        self.connection.send(json.dumps(message))

    def _receive(self) -> dict[str, Any]:
        return dict(json.loads(self.connection.recv(timeout=ANSWER_TIMEOUT_S)))

    def sync(self) -> list[dict[str, Any]]:
        """The status frames that arrive until the server answers a call sent now.

        The server handles one client's ops in order, so everything sent before is done.
        Other frames are kept for ``next_publish``.
        """
        call_id = f"sync-{next(self._ids)}"
        self.send(op="call_service", service="/rosapi/topics", id=call_id)
        statuses: list[dict[str, Any]] = []
        while True:
            frame = self._receive()
            if frame.get("op") == "service_response" and frame.get("id") == call_id:
                return statuses
            (statuses if frame.get("op") == "status" else self.pending).append(frame)

    def statuses(self) -> list[str]:
        """The status texts that arrived until now."""
        return [frame["msg"] for frame in self.sync()]

    def next_publish(self, topic: str) -> dict[str, Any]:
        """The next message on ``topic``."""
        for index, frame in enumerate(self.pending):
            if frame.get("op") == "publish" and frame.get("topic") == topic:
                del self.pending[index]
                return dict(frame["msg"])
        while True:
            frame = self._receive()
            if frame.get("op") == "publish" and frame.get("topic") == topic:
                return dict(frame["msg"])
            self.pending.append(frame)


@pytest.fixture
def raw(server: ServerProcess) -> Iterator[Any]:
    """Opens websockets clients (``raw()``), all closed at the end of the test."""
    with contextlib.ExitStack() as stack:
        yield lambda: RawClient(stack.enter_context(connect(server.ws_url, max_size=None)))


def roslibpy_listener(ros: roslibpy.Ros, topic: str, type_name: str) -> list[dict[str, Any]]:
    """Subscribe with roslibpy; the list its messages go to, once the server has it."""
    messages: list[dict[str, Any]] = []
    roslibpy.Topic(ros, topic, type_name, queue_length=10).subscribe(messages.append)
    ros.get_topics()  # a round trip: the subscribe before it is in force
    return messages


class NodeSubscriber:
    """``first_messages.js``: roslibjs under Node, subscribed to some topics."""

    def __init__(self, url: str, compression: str, *topics: str) -> None:
        assert NODE is not None
        self.process = subprocess.Popen(
            [NODE, str(NODE_PROGRAMS / "first_messages.js"), url, compression, *topics],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert self.process.stderr is not None
        for line in self.process.stderr:  # roslib may warn first
            if line.strip() == "subscribed":
                return
        self.result()  # it ended before subscribing: fail with its reason

    def result(self, timeout_s: float = 30.0) -> dict[str, Any]:
        """The first message of each topic, as the program prints them."""
        out, err = self.process.communicate(timeout=timeout_s)
        assert self.process.returncode == 0, err
        return dict(json.loads(out))


needs_node = pytest.mark.skipif(NODE is None, reason="node not installed")


def test_a_partial_twist_reaches_every_subscriber_filled_with_zeros(
        server: ServerProcess, raw: Any, ros: roslibpy.Ros) -> None:
    topic = "/partial_twist"
    watcher = raw()
    watcher.send(op="subscribe", topic=topic, type="geometry_msgs/msg/Twist")
    watcher.sync()
    in_roslibpy = roslibpy_listener(ros, topic, "geometry_msgs/msg/Twist")
    in_roslibjs = NodeSubscriber(server.ws_url, "none", f"{topic}:geometry_msgs/msg/Twist") \
        if NODE else None
    talker = raw()
    talker.send(op="advertise", topic=topic, type="geometry_msgs/Twist")
    talker.send(op="publish", topic=topic, msg={"linear": {"x": 0.5}})
    assert talker.statuses() == []

    expected = {"linear": {"x": 0.5, "y": 0.0, "z": 0.0}, "angular": ZERO_TWIST["angular"]}
    assert watcher.next_publish(topic) == expected
    wait_for(lambda: in_roslibpy, ANSWER_TIMEOUT_S, "the Twist in roslibpy")
    assert in_roslibpy == [expected]
    if in_roslibjs is not None:
        assert in_roslibjs.result()[topic] == expected


def test_a_field_the_type_lacks_is_refused_with_a_status_naming_it(raw: Any) -> None:
    topic = "/extra_fields"
    watcher, talker = raw(), raw()
    watcher.send(op="subscribe", topic=topic)
    watcher.sync()
    talker.send(op="advertise", topic=topic, type="geometry_msgs/msg/Twist")
    talker.send(op="publish", topic=topic, msg={"linear": {"x": 1.0}, "bogus": 1})
    talker.send(op="publish", topic=topic, msg={"linear": {"x": 1.0, "w": 2.0}})
    talker.send(op="publish", topic=topic, msg={"angular": {"z": "fast"}})
    talker.send(op="publish", topic=topic, msg={"angular": {"z": 0.25}})
    statuses = talker.statuses()
    assert statuses == [
        f"publish to {topic}: geometry_msgs/msg/Twist has no field 'bogus' "
        "(fields: linear, angular)",
        f"publish to {topic}: linear: geometry_msgs/msg/Vector3 has no field 'w' "
        "(fields: x, y, z)",
        f"publish to {topic}: angular.z: expected a number (float64), got str",
    ]
    # None of the refused messages was relayed: the first to arrive is the last one.
    assert watcher.next_publish(topic) == {"linear": ZERO_TWIST["linear"],
                                           "angular": {"x": 0.0, "y": 0.0, "z": 0.25}}


def test_a_type_defined_nowhere_is_refused_with_rosbridges_reason(raw: Any) -> None:
    topic = "/jam"
    watcher, talker = raw(), raw()
    watcher.send(op="subscribe", topic=topic)
    watcher.send(op="subscribe", topic="/jam_typed", type="wangle_msgs/Jam")
    assert watcher.statuses() == [
        "subscribe /jam_typed: Unable to import wangle_msgs.msg from package wangle_msgs. "
        "Caused by: No module named 'wangle_msgs' (websim knows std_msgs, geometry_msgs, "
        f"sensor_msgs, nav_msgs, example_interfaces and {OTHER_PACKAGES} more packages; with "
        "--ros, every installed one)"]
    talker.send(op="advertise", topic=topic, type="wangle_msgs/Jam", id="jam-1")
    talker.send(op="advertise", topic=topic, type="std_msgs/msg/Jam")
    talker.send(op="publish", topic=topic, msg={"strawberry": True})
    frames = talker.sync()
    assert frames[0]["id"] == "jam-1"
    reasons = [frame["msg"] for frame in frames]
    assert reasons[0].startswith(
        "advertise /jam: Unable to import wangle_msgs.msg from package wangle_msgs. Caused by: "
        "No module named 'wangle_msgs'")
    assert reasons[1].startswith(
        "advertise /jam: Unable to import msg class Jam from package std_msgs. Caused by "
        "module 'std_msgs.msg' has no attribute 'Jam'")
    assert len(reasons) == 3 and topic in reasons[2]  # the publish: no type to check it by
    # Nothing was relayed: the first message the watcher gets is one of a real type.
    talker.send(op="advertise", topic=topic, type="std_msgs/String")
    talker.send(op="publish", topic=topic, msg={"data": "after"})
    assert watcher.next_publish(topic) == {"data": "after"}


def test_example_interfaces_messages_are_typed_and_relayed(ros: roslibpy.Ros, raw: Any) -> None:
    heard = roslibpy_listener(ros, "/counter", "example_interfaces/msg/Int32")
    words = roslibpy_listener(ros, "/words", "example_interfaces/WString")
    talker = raw()
    talker.send(op="advertise", topic="/counter", type="example_interfaces/msg/Int32")
    talker.send(op="advertise", topic="/words", type="example_interfaces/msg/WString")
    talker.send(op="publish", topic="/counter", msg={})
    talker.send(op="publish", topic="/counter", msg={"data": 2**31})
    talker.send(op="publish", topic="/counter", msg={"data": -7})
    talker.send(op="publish", topic="/words", msg={"data": "Grüße"})
    assert talker.statuses() == [
        "publish to /counter: data: 2147483648 is out of int32 range "
        "(-2147483648 to 2147483647)"]
    wait_for(lambda: len(heard) >= 2 and words, ANSWER_TIMEOUT_S, "the example_interfaces "
             "messages in roslibpy")
    assert heard == [{"data": 0}, {"data": -7}]
    assert words == [{"data": "Grüße"}]


INTEGER_TYPES = {"int8": "Int8", "uint8": "UInt8", "int16": "Int16", "uint16": "UInt16",
                 "int32": "Int32", "uint32": "UInt32", "int64": "Int64", "uint64": "UInt64"}
"""Each ROS integer type and the std_msgs message that holds one."""


def test_every_integer_out_of_its_types_range_is_refused(raw: Any) -> None:
    watcher, talker = raw(), raw()
    for base_type in INTEGER_TYPES:
        watcher.send(op="subscribe", topic=f"/range_{base_type}")
    watcher.sync()
    expected_statuses: list[str] = []
    expected_relayed: list[tuple[str, list[int]]] = []
    for base_type, message in INTEGER_TYPES.items():
        bounds = INTEGER_RANGES[base_type]
        assert bounds is not None
        low, high = bounds
        topic = f"/range_{base_type}"
        talker.send(op="advertise", topic=topic, type=f"std_msgs/{message}")
        for value in (low - 1, low, high, high + 1):
            talker.send(op="publish", topic=topic, msg={"data": value})
        expected_statuses += [
            f"publish to {topic}: data: {value} is out of {base_type} range ({low} to {high})"
            for value in (low - 1, high + 1)]
        expected_relayed.append((topic, [low, high]))
    talker.send(op="advertise", topic="/small", type="example_interfaces/Int8")
    talker.send(op="publish", topic="/small", msg={"data": 300})
    talker.send(op="advertise", topic="/one_float", type="std_msgs/Float32")
    talker.send(op="publish", topic="/one_float", msg={"data": 1e39})
    assert talker.statuses() == [
        *expected_statuses,
        "publish to /small: data: 300 is out of int8 range (-128 to 127)",
        "publish to /one_float: data: 1e+39 is out of float32 range (±3.402823e+38)"]
    for topic, values in expected_relayed:
        assert [watcher.next_publish(topic)["data"] for _ in values] == values


def test_a_ros1_stamp_is_accepted_and_relayed_as_sec_and_nanosec(
        ros: roslibpy.Ros, raw: Any) -> None:
    watcher = raw()
    watcher.send(op="subscribe", topic="/stamped")
    watcher.send(op="subscribe", topic="/waited")
    watcher.sync()
    header = roslibpy.Topic(ros, "/stamped", "std_msgs/msg/Header")
    header.advertise()
    # roslibpy's own Header is ROS 1's: seq (dropped) and a {secs, nsecs} stamp.
    header.publish(roslibpy.Message(roslibpy.Header(seq=7, stamp={"secs": 12, "nsecs": 345},
                                                    frame_id="map")))
    assert watcher.next_publish("/stamped") == {"stamp": {"sec": 12, "nanosec": 345},
                                                "frame_id": "map"}
    duration = roslibpy.Topic(ros, "/waited", "builtin_interfaces/msg/Duration")
    duration.advertise()
    duration.publish(roslibpy.Message({"secs": 3, "nsecs": 4}))
    assert watcher.next_publish("/waited") == {"sec": 3, "nanosec": 4}


@needs_node
def test_numeric_arrays_reach_a_cbor_roslibjs_subscriber_as_typed_arrays(
        server: ServerProcess, raw: Any) -> None:
    topics = {"/ints": "std_msgs/msg/Int32MultiArray",
              "/doubles": "example_interfaces/msg/Float64MultiArray",
              "/image": "sensor_msgs/msg/Image", "/odom": "nav_msgs/msg/Odometry"}
    subscriber = NodeSubscriber(server.ws_url, "cbor",
                                *(f"{name}:{type_name}" for name, type_name in topics.items()))
    watcher, talker = raw(), raw()
    watcher.send(op="subscribe", topic="/image")
    watcher.sync()
    for name, type_name in topics.items():
        if name != "/odom":  # the robot's
            talker.send(op="advertise", topic=name, type=type_name)
    talker.send(op="publish", topic="/ints", msg={"data": [1, -2, 2**31 - 1]})
    talker.send(op="publish", topic="/doubles", msg={"data": [0.5, -1.25]})
    talker.send(op="publish", topic="/image", msg={"height": 1, "width": 3, "step": 3,
                                                   "encoding": "mono8", "data": [0, 1, 255]})
    assert talker.statuses() == []
    first = subscriber.result()

    layout = {"dim": [], "data_offset": 0}
    assert first["/ints"] == {"layout": layout,
                              "data": {"typed": "Int32Array", "values": [1, -2, 2**31 - 1]}}
    assert first["/doubles"] == {"layout": layout,
                                 "data": {"typed": "Float64Array", "values": [0.5, -1.25]}}
    assert first["/image"]["data"] == {"typed": "Uint8Array", "values": [0, 1, 255]}
    covariance = first["/odom"]["pose"]["covariance"]  # built by websim, typed alike
    assert covariance["typed"] == "Float64Array" and len(covariance["values"]) == 36
    # JSON subscribers get a uint8[] as base64 text, as rosbridge sends it.
    assert watcher.next_publish("/image")["data"] == base64.b64encode(bytes([0, 1, 255])).decode()
