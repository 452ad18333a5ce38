"""The robot's tap: what it accepts and what it publishes, both directions, in sim time."""

from __future__ import annotations

import json
from typing import Any

import pytest
from robot_rig import robot_rig

from physics import ConfigError, Simulation, load_world
from ros_nodes.robot_host import RobotHost
from ros_nodes.tap import IN, OUT
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.session import Session
from rosbridge.msgs.values import Message

TWIST = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.5}}

Crossing = tuple[str, str, str, Message, float]


def recording(robot: VirtualRobot) -> list[Crossing]:
    """Every crossing of ``robot``'s tap from now on."""
    heard: list[Crossing] = []
    robot.tap.add(lambda *crossing: heard.append(crossing))
    return heard


def test_the_tap_sees_commands_in_and_messages_out_with_their_sim_time() -> None:
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0))
    heard = recording(robot)
    robot.step()
    robot.on_cmd_vel(TWIST)
    published = robot.step()
    assert [(direction, topic, type_name) for direction, topic, type_name, *_ in heard] == [
        (OUT, "/clock", "rosgraph_msgs/msg/Clock"),
        (OUT, "/odom", "nav_msgs/msg/Odometry"),
        (OUT, "/tf", "tf2_msgs/msg/TFMessage"),
        (OUT, "/ground_truth", "nav_msgs/msg/Odometry"),
        (OUT, "/joint_states", "sensor_msgs/msg/JointState"),
        (IN, "/cmd_vel", "geometry_msgs/msg/Twist"),
        (OUT, "/clock", "rosgraph_msgs/msg/Clock"),
        (OUT, "/odom", "nav_msgs/msg/Odometry"),
        (OUT, "/tf", "tf2_msgs/msg/TFMessage"),
        (OUT, "/ground_truth", "nav_msgs/msg/Odometry"),
        (OUT, "/joint_states", "sensor_msgs/msg/JointState"),
        (OUT, "/scan", "sensor_msgs/msg/LaserScan"),
    ]
    assert [time_s for *_, time_s in heard] == pytest.approx([0.05] * 6 + [0.1] * 6)
    assert heard[5][3] is TWIST
    assert [msg for direction, _, _, msg, _ in heard[6:]] == [msg for _, msg in published]


def test_a_stamped_command_is_tapped_with_its_type_and_a_refused_one_not_at_all() -> None:
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0))
    heard = recording(robot)
    robot.on_cmd_vel({"header": {}, "twist": TWIST}, stamped=True)
    with pytest.raises(ConfigError):
        robot.on_cmd_vel({"linear": {"x": float("nan")}})
    assert [(direction, topic, type_name, time_s) for direction, topic, type_name, _, time_s
            in heard] == [(IN, "/cmd_vel", "geometry_msgs/msg/TwistStamped", 0.0)]


def test_the_tap_sees_what_a_client_sends_through_the_bridge_and_all_the_robot_builds() -> None:
    rig = robot_rig()
    host: RobotHost = rig.host
    heard = recording(host.robot)
    client = Session("driver", False)
    host.bridge.connect(client)
    host.bridge.handle(client, json.dumps({"op": "publish", "topic": "/cmd_vel",
                                           "msg": TWIST}))
    rig.tick_now()
    rig.tick_now()  # nobody subscribes, yet the tap gets every message, /scan included
    topics: list[Any] = [(direction, topic) for direction, topic, *_ in heard]
    per_tick = [(OUT, "/clock"), (OUT, "/odom"), (OUT, "/tf"), (OUT, "/ground_truth"),
                (OUT, "/joint_states")]
    assert topics == [(IN, "/cmd_vel"), *per_tick, *per_tick, (OUT, "/scan")]
    assert host.stats.scans_cast == 1


def test_a_removed_callback_hears_nothing_more() -> None:
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0))
    heard: list[str] = []

    def callback(direction: str, topic: str, *_: Any) -> None:
        heard.append(topic)

    robot.tap.add(callback)
    robot.step()
    robot.tap.remove(callback)
    robot.tap.remove(callback)  # twice: nothing
    robot.step()
    assert heard == ["/clock", "/odom", "/tf", "/ground_truth", "/joint_states"]
    assert callback not in robot.tap and not robot.tap.attached
