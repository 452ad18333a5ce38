"""/map and map -> odom on a real ROS 2 graph: ``websim serve --ros`` and ``websim-robot``.

A late rclpy subscriber (created after the server publishes) gets the latched /map, reliable
and transient local as map_server offers it, equal to what a roslibpy client gets; with
``localization:=perfect`` the node's /tf chains map -> odom -> base_link onto /ground_truth
while its odometry drifts.
"""

from __future__ import annotations

import importlib.util
import math
from collections.abc import Callable
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)
"""Fixtures domain, graph, test_world, start_robot, ros_server, ros_client."""

import roslibpy  # noqa: E402
from nav_msgs.msg import OccupancyGrid, Odometry  # noqa: E402
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy  # noqa: E402

from physics import Pose2D  # noqa: E402
from physics.frames import compose  # noqa: E402

from ros_fixtures import LATCHED, RELIABLE, STARTUP_TIMEOUT_S, Graph, RobotProcess  # noqa: E402
from server_process import ServerProcess, wait_for  # noqa: E402

HAS_TF2_MSGS = importlib.util.find_spec("tf2_msgs") is not None


def planar(translation: Any, rotation: Any) -> Pose2D:
    return Pose2D(translation.x, translation.y, 2.0 * math.atan2(rotation.z, rotation.w))


def test_a_late_rclpy_subscriber_gets_the_map_the_bridge_sends(
        graph: Graph, ros_server: ServerProcess, ros_client: roslibpy.Ros) -> None:
    graph.spin_until(lambda: graph.node.count_publishers("/map") > 0, STARTUP_TIMEOUT_S,
                     "the in-process node's /map")
    info = graph.node.get_publishers_info_by_topic("/map")[0]
    assert info.topic_type == "nav_msgs/msg/OccupancyGrid"
    assert info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
    # Subscribed only now, long after the node published it once: transient local delivers.
    maps = graph.collect(OccupancyGrid, "/map", LATCHED)
    graph.spin_until(lambda: maps, 10.0, "the latched /map on the graph")
    bridged: list[dict[str, Any]] = []
    roslibpy.Topic(ros_client, "/map", "nav_msgs/msg/OccupancyGrid").subscribe(bridged.append)
    wait_for(lambda: bridged, 10.0, "the latched /map over the bridge")

    ros_map, web_map = maps[0][1], bridged[0]
    assert ros_map.header.frame_id == web_map["header"]["frame_id"] == "map"
    assert (ros_map.info.width, ros_map.info.height) == \
        (web_map["info"]["width"], web_map["info"]["height"])
    assert ros_map.info.resolution == pytest.approx(web_map["info"]["resolution"], rel=1e-7)
    origin = web_map["info"]["origin"]["position"]
    assert (ros_map.info.origin.position.x, ros_map.info.origin.position.y) == \
        (origin["x"], origin["y"])
    assert ros_map.info.origin.orientation.w == 1.0
    assert list(ros_map.data) == web_map["data"]
    assert {-1, 0, 100} == set(ros_map.data)
    # Only one message: the map is published once, not per tick.
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    graph.spin_until(lambda: len(odom) >= 20, 10.0, "1 s of /odom")
    assert len(maps) == 1


@pytest.mark.skipif(not HAS_TF2_MSGS, reason="tf2_msgs not built (bash scripts/build_tf2_msgs.sh)")
def test_perfect_localization_on_the_graph_chains_onto_the_ground_truth(
        graph: Graph, start_robot: Callable[..., RobotProcess]) -> None:
    from tf2_msgs.msg import TFMessage

    robot = start_robot("localization:=perfect", "odom_angular_sigma_rps:=0.3",
                        "odom_linear_sigma_mps:=0.05")
    assert graph.get_parameter("localization") == "perfect"
    maps = graph.collect(OccupancyGrid, "/map", LATCHED)
    tf = graph.collect(TFMessage, "/tf", RELIABLE)
    truth = graph.collect(Odometry, "/ground_truth", RELIABLE)
    graph.spin_until(lambda: maps and len(tf) >= 60 and len(truth) >= 60, 15.0,
                     "/map, 3 s of /tf and /ground_truth")
    assert maps[0][1].header.frame_id == "map"
    by_stamp = {(m.header.stamp.sec, m.header.stamp.nanosec): m for _, m in truth}
    matched, correction_m = 0, 0.0
    for _, message in tf:
        to_odom, to_base, *wheels = message.transforms
        assert [t.child_frame_id for t in wheels] == ["left_wheel", "right_wheel"]
        assert (to_odom.header.frame_id, to_odom.child_frame_id) == ("map", "odom")
        assert (to_base.header.frame_id, to_base.child_frame_id) == ("odom", "base_link")
        true = by_stamp.get((to_odom.header.stamp.sec, to_odom.header.stamp.nanosec))
        if true is None:
            continue
        chained = compose(planar(to_odom.transform.translation, to_odom.transform.rotation),
                          planar(to_base.transform.translation, to_base.transform.rotation))
        expected = planar(true.pose.pose.position, true.pose.pose.orientation)
        assert chained.x == pytest.approx(expected.x, abs=1e-9)
        assert chained.y == pytest.approx(expected.y, abs=1e-9)
        assert math.remainder(chained.theta - expected.theta, 2 * math.pi) == \
            pytest.approx(0.0, abs=1e-9)
        matched += 1
        correction_m = max(correction_m, math.hypot(to_odom.transform.translation.x,
                                                    to_odom.transform.translation.y))
    assert matched >= 50
    assert correction_m > 1e-3  # the odometry drifted (spawn is the origin): map -> odom moved
    assert robot.stop() == 0
