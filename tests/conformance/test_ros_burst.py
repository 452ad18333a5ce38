"""A burst a ROS node publishes at full speed reaches a queue_length 0 client whole (``--ros``).

rosbridge's promise for queue_length 0 with no throttle is every message; websim keeps it
from the graph too: the relay's subscription to a reliable publisher is deep enough that DDS
does not drop what the relay has not taken yet (``rosbridge.graph.relay.RELIABLE_RELAY_DEPTH``).
``benchmarks/ros_burst.py`` prints the same for 1000 messages.
"""

from __future__ import annotations

from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)

import roslibpy  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from ros_fixtures import Graph  # noqa: E402
from server_process import wait_for  # noqa: E402

BURST = 500


def test_a_burst_from_a_ros_node_reaches_a_queue_length_0_subscriber_complete_in_order(
        graph: Graph, ros_client: roslibpy.Ros) -> None:
    publisher = graph.node.create_publisher(
        String, "/ros_burst", QoSProfile(depth=BURST, reliability=ReliabilityPolicy.RELIABLE))
    received: list[Any] = []
    roslibpy.Topic(ros_client, "/ros_burst", "std_msgs/msg/String").subscribe(
        lambda message: received.append(message["data"]))
    graph.spin_until(lambda: publisher.get_subscription_count() > 0, 15.0,
                     "the relay's subscription on the graph")

    def probe_arrived() -> bool:  # until matched both ways, a message may be lost
        publisher.publish(String(data="probe"))
        return bool(received)

    graph.spin_until(probe_arrived, 15.0, "a first message through the relay")
    for index in range(BURST):
        publisher.publish(String(data=str(index)))
    wait_for(lambda: sum(data != "probe" for data in received) >= BURST, 20.0,
             f"{BURST} messages")
    burst = [data for data in received if data != "probe"]
    assert burst == [str(index) for index in range(BURST)]
