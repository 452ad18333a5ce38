"""The robot model on a real ROS 2 graph: /robot_description (transient local, as
robot_state_publisher offers it) and /joint_states from ``websim-robot`` and ``websim serve
--ros``, a payload change publishing the URDF again, and TwistStamped beside Twist with --ros.

Real processes and a real rclpy node in this test process, each test on its own ROS domain.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)

import roslibpy  # noqa: E402
from geometry_msgs.msg import Twist  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from physics import LidarParams, RobotParams  # noqa: E402
from ros_nodes.parameters import PARAMETER_DOUBLE  # noqa: E402
from ros_nodes.urdf import robot_urdf  # noqa: E402

from ros_fixtures import LATCHED, RELIABLE, Graph, RobotProcess  # noqa: E402
from server_process import ServerProcess  # noqa: E402


def mass_in(urdf: str) -> float:
    mass = ET.fromstring(urdf).find("link/inertial/mass")
    assert mass is not None
    return float(mass.attrib["value"])


def test_websim_robot_offers_the_urdf_to_late_subscribers_and_again_after_a_payload_change(
        graph: Graph, start_robot: Callable[..., RobotProcess]) -> None:
    start_robot("use_sim_time:=true")
    # Subscribed after the node started: transient local, as robot_state_publisher's.
    descriptions = graph.collect(String, "/robot_description", LATCHED)
    graph.spin_until(lambda: descriptions, 10.0, "/robot_description")
    assert descriptions[0][1].data == robot_urdf(RobotParams(), LidarParams())
    assert [r.successful for r in graph.set_parameters(mass_kg=2.4)] == [True]
    graph.spin_until(lambda: len(descriptions) == 2, 10.0, "the new /robot_description")
    assert mass_in(descriptions[1][1].data) == 2.4
    late = graph.collect(String, "/robot_description", LATCHED)
    graph.spin_until(lambda: late, 10.0, "the new description for a late subscriber")
    assert [msg.data for _, msg in late] == [descriptions[1][1].data]


def test_websim_robot_joint_states_follow_the_wheels(
        graph: Graph, start_robot: Callable[..., RobotProcess]) -> None:
    start_robot("use_sim_time:=true")  # stamps in ticks: /odom and /joint_states pair exactly
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    states = graph.collect(JointState, "/joint_states", RELIABLE)
    cmd_vel = graph.node.create_publisher(Twist, "/cmd_vel", 10)
    graph.spin_until(lambda: cmd_vel.get_subscription_count() > 0, 10.0, "/cmd_vel subscriber")
    command = Twist()
    command.linear.x = 0.3
    cmd_vel.publish(command)
    graph.spin_until(lambda: any(m.pose.pose.position.x > 0.2 for _, m in odom), 10.0,
                     "0.2 m travelled")
    by_stamp = {(m.header.stamp.sec, m.header.stamp.nanosec): m for _, m in states}
    radius = RobotParams().wheel_radius_m
    paired = [(m, by_stamp[key]) for _, m in odom
              if (key := (m.header.stamp.sec, m.header.stamp.nanosec)) in by_stamp]
    assert len(paired) > 10
    for pose, joints in paired:
        assert list(joints.name) == ["left_wheel_joint", "right_wheel_joint"]
        assert list(joints.position) == pytest.approx(
            [pose.pose.pose.position.x / radius] * 2, abs=1e-9)


def test_serve_ros_puts_the_model_on_the_graph_and_twist_stamped_drives_beside_it(
        graph: Graph, ros_server: ServerProcess, ros_client: Any) -> None:
    descriptions = graph.collect(String, "/robot_description", LATCHED)
    states = graph.collect(JointState, "/joint_states", RELIABLE)
    graph.spin_until(lambda: descriptions and states, 20.0, "the model on the graph")
    assert mass_in(descriptions[0][1].data) == RobotParams().mass_kg

    admin = roslibpy.Ros(host=ros_server.admin_ws_url)
    admin.run(timeout=10)
    try:
        result = roslibpy.Service(admin, "/virtual_robot/set_parameters",
                                  "rcl_interfaces/srv/SetParameters").call(
            roslibpy.ServiceRequest({"parameters": [
                {"name": "mass_kg", "value": {"type": PARAMETER_DOUBLE, "double_value": 3.0}}]}),
            timeout=5)
        assert result["results"] == [{"successful": True, "reason": ""}]
    finally:
        admin.close()
    graph.spin_until(lambda: len(descriptions) == 2, 10.0, "the URDF again on the graph")
    assert mass_in(descriptions[1][1].data) == 3.0

    odom = graph.collect(Odometry, "/odom", RELIABLE)
    teleop = roslibpy.Topic(ros_client, "/cmd_vel", "geometry_msgs/Twist")
    teleop.advertise()  # first: the graph gets /cmd_vel as Twist
    other = roslibpy.Ros(host="127.0.0.1", port=ros_server.ws_port)  # one type per client
    other.run(timeout=10)
    try:
        nav2 = roslibpy.Topic(other, "/cmd_vel", "geometry_msgs/TwistStamped")
        nav2.publish(roslibpy.Message({"header": {"frame_id": "base_link"},
                                       "twist": {"linear": {"x": 0.2}, "angular": {"z": 0.0}}}))
        graph.spin_until(lambda: odom and odom[-1][1].twist.twist.linear.x == 0.2, 10.0,
                         "the robot driven by a TwistStamped")
        teleop.publish(roslibpy.Message({"linear": {"x": 0.0}, "angular": {"z": 0.5}}))
        graph.spin_until(lambda: odom[-1][1].twist.twist.angular.z == 0.5
                         and odom[-1][1].twist.twist.linear.x == 0.0, 10.0, "the Twist's turn")
    finally:
        other.close()
