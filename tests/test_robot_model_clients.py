"""The robot model, TwistStamped and the command watchdog with real clients and a real server.

roslibpy drives the robot with ``geometry_msgs/TwistStamped`` (what Jazzy-era nav2 publishes)
beside a Twist client; roslibjs 1.4.1 under Node reads ``/robot_description`` with its own URDF
parser (what ros3djs draws from); the watchdog is set through the admin's parameter service
and stops the robot. One ``websim serve`` for the module.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import roslibpy

from physics import TICK_PERIOD_S, LidarParams, RobotParams
from ros_nodes.parameters import PARAMETER_DOUBLE
from ros_nodes.urdf import CHASSIS_HEIGHT_M, LASER_HEIGHT_M

from server_process import ServerProcess, wait_for

NODE = shutil.which("node")
NODE_PROGRAMS = Path(__file__).parent / "node"

SPEED_MPS = 0.3


@pytest.fixture
def admin(server: ServerProcess) -> Iterator[roslibpy.Ros]:
    client = roslibpy.Ros(host=server.admin_ws_url)
    client.run(timeout=10)
    yield client
    client.close()


def reset(ros: roslibpy.Ros) -> None:
    roslibpy.Service(ros, "/reset_simulation", "std_srvs/srv/Empty").call(
        roslibpy.ServiceRequest({}), timeout=5)


def set_timeout(admin: roslibpy.Ros, timeout_s: float) -> None:
    result = roslibpy.Service(admin, "/virtual_robot/set_parameters",
                              "rcl_interfaces/srv/SetParameters").call(
        roslibpy.ServiceRequest({"parameters": [
            {"name": "cmd_vel_timeout_s",
             "value": {"type": PARAMETER_DOUBLE, "double_value": timeout_s}}]}), timeout=5)
    assert result["results"] == [{"successful": True, "reason": ""}]


def odometry(ros: roslibpy.Ros) -> tuple[roslibpy.Topic, list[dict[str, Any]]]:
    """A subscription to /odom and the list its messages go to."""
    received: list[dict[str, Any]] = []
    topic = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry")
    topic.subscribe(received.append)
    return topic, received


def stamp_s(msg: dict[str, Any]) -> float:
    stamp = msg["header"]["stamp"]
    return stamp["sec"] + stamp["nanosec"] * 1e-9


def stamped(linear_mps: float, angular_rps: float = 0.0) -> roslibpy.Message:
    return roslibpy.Message({"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
                             "twist": {"linear": {"x": linear_mps, "y": 0.0, "z": 0.0},
                                       "angular": {"x": 0.0, "y": 0.0, "z": angular_rps}}})


def twist(linear_mps: float, angular_rps: float = 0.0) -> roslibpy.Message:
    return roslibpy.Message({"linear": {"x": linear_mps, "y": 0.0, "z": 0.0},
                             "angular": {"x": 0.0, "y": 0.0, "z": angular_rps}})


def test_twist_stamped_drives_the_robot_beside_a_twist_client(server: ServerProcess,
                                                               ros: roslibpy.Ros) -> None:
    reset(ros)
    _, odom = odometry(ros)
    nav2 = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/TwistStamped")
    heard_stamped: list[dict[str, Any]] = []
    roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/TwistStamped").subscribe(
        heard_stamped.append)
    nav2.advertise()
    nav2.publish(stamped(SPEED_MPS))
    wait_for(lambda: odom and odom[-1]["twist"]["twist"]["linear"]["x"] == SPEED_MPS,
             10.0, "the robot moving on a TwistStamped")
    wait_for(lambda: heard_stamped, 5.0, "the TwistStamped echoed to its subscriber")
    assert heard_stamped[0]["twist"]["linear"]["x"] == SPEED_MPS

    with_twist = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
    with_twist.run(timeout=10)
    try:
        heard_twists: list[dict[str, Any]] = []
        teleop = roslibpy.Topic(with_twist, "/cmd_vel", "geometry_msgs/Twist")
        teleop.subscribe(heard_twists.append)
        teleop.advertise()
        teleop.publish(twist(0.0, 1.0))  # the latest command of either type drives
        wait_for(lambda: odom[-1]["twist"]["twist"]["angular"]["z"] == 1.0
                 and odom[-1]["twist"]["twist"]["linear"]["x"] == 0.0, 10.0, "the turn")
        nav2.publish(stamped(0.1))
        wait_for(lambda: odom[-1]["twist"]["twist"]["linear"]["x"] == 0.1
                 and odom[-1]["twist"]["twist"]["angular"]["z"] == 0.0, 10.0, "nav2 again")
        teleop.publish(twist(0.0))
        wait_for(lambda: odom[-1]["twist"]["twist"]["linear"]["x"] == 0.0, 10.0, "the stop")
        # Each subscriber gets the type it subscribed with: the Twist client its own Twists.
        assert [m["angular"]["z"] for m in heard_twists] == [1.0, 0.0]
        assert [m["twist"]["linear"]["x"] for m in heard_stamped] == [SPEED_MPS, 0.1]
    finally:
        with_twist.close()
        nav2.unadvertise()


def test_the_watchdog_stops_the_robot_and_off_it_keeps_going(ros: roslibpy.Ros,
                                                              admin: roslibpy.Ros) -> None:
    timeout_s = 0.5
    set_timeout(admin, timeout_s)
    try:
        reset(ros)
        _, odom = odometry(ros)
        driver = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/TwistStamped")
        driver.publish(stamped(SPEED_MPS))  # once, then silence
        wait_for(lambda: odom and odom[-1]["twist"]["twist"]["linear"]["x"] == SPEED_MPS,
                 10.0, "motion")
        wait_for(lambda: odom[-1]["twist"]["twist"]["linear"]["x"] == 0.0, 10.0, "the stop")
        # It moved for about the timeout, whole ticks of 15 mm: ten on time. The exact bound
        # (within the timeout and one tick) is test_cmd_vel_types' on a manual clock; here a
        # loaded host may run a late tick or two inside the timeout.
        travelled_m = odom[-1]["pose"]["pose"]["position"]["x"]
        ticks = round(travelled_m / (SPEED_MPS * TICK_PERIOD_S))
        assert travelled_m == pytest.approx(ticks * SPEED_MPS * TICK_PERIOD_S, abs=1e-9)
        assert 1 <= ticks <= timeout_s / TICK_PERIOD_S + 2
        stop = odom[-1]
        wait_for(lambda: stamp_s(odom[-1]) - stamp_s(stop) >= 2 * timeout_s, 10.0, "a second")
        assert odom[-1]["pose"]["pose"]["position"]["x"] == travelled_m  # and it stays

        set_timeout(admin, 0.0)
        reset(ros)
        odom.clear()
        driver.publish(stamped(SPEED_MPS))
        wait_for(lambda: odom and odom[-1]["twist"]["twist"]["linear"]["x"] == SPEED_MPS,
                 10.0, "motion")
        first = stamp_s(odom[-1])
        wait_for(lambda: stamp_s(odom[-1]) - first >= 3 * timeout_s, 10.0, "three timeouts")
        assert odom[-1]["twist"]["twist"]["linear"]["x"] == SPEED_MPS  # keeps its command
    finally:
        set_timeout(admin, 0.0)
        roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/Twist").publish(twist(0.0))


def test_joint_states_follow_the_wheels_over_the_bridge(ros: roslibpy.Ros) -> None:
    reset(ros)
    states: list[dict[str, Any]] = []
    roslibpy.Topic(ros, "/joint_states", "sensor_msgs/msg/JointState").subscribe(states.append)
    _, odom = odometry(ros)
    roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/Twist").publish(twist(SPEED_MPS))
    wait_for(lambda: len(odom) > 20 and odom[-1]["twist"]["twist"]["linear"]["x"] > 0, 10.0,
             "motion")
    roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/Twist").publish(twist(0.0))
    wait_for(lambda: odom[-1]["twist"]["twist"]["linear"]["x"] == 0.0, 10.0, "the stop")
    stop = odom[-1]
    # The stop's /joint_states: published at the same tick as its /odom, with its stamp.
    last = wait_for(lambda: next((m for m in states if stamp_s(m) == stamp_s(stop)), None),
                    5.0, "the joint states of the stop's tick")
    x = stop["pose"]["pose"]["position"]["x"]
    radius = RobotParams().wheel_radius_m
    assert last["name"] == ["left_wheel_joint", "right_wheel_joint"]
    assert last["position"] == pytest.approx([x / radius] * 2, abs=1e-9)
    assert x > 0.1


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_roslibjs_reads_the_robot_description_with_its_urdf_parser(server: ServerProcess) -> None:
    assert NODE is not None
    result = subprocess.run([NODE, str(NODE_PROGRAMS / "urdf.js"), server.ws_url],
                            capture_output=True, text=True, timeout=30, check=False)
    assert result.returncode == 0, result.stderr
    model = json.loads(result.stdout)
    robot, lidar = RobotParams(), LidarParams()
    assert model["name"] == "virtual_robot"
    assert set(model["links"]) == {"base_link", "left_wheel", "right_wheel", "laser"}
    (chassis,) = model["links"]["base_link"]
    assert chassis["geometry"] == {"type": "cylinder", "radius": robot.footprint_radius_m,
                                   "length": CHASSIS_HEIGHT_M}
    assert chassis["rgba"] is not None  # the named material resolved to its colour
    left = model["joints"]["left_wheel_joint"]
    assert (left["type"], left["parent"], left["child"]) == ("continuous", "base_link",
                                                             "left_wheel")
    assert left["origin"]["xyz"] == [0.0, robot.wheelbase_m / 2, robot.wheel_radius_m]
    (wheel,) = model["links"]["left_wheel"]
    assert wheel["geometry"]["radius"] == robot.wheel_radius_m
    # roslibjs turns the rpy into a quaternion: -90 degrees about x (the cylinder on the axle).
    assert wheel["origin"]["quaternion"] == pytest.approx(
        [-math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)])
    laser = model["joints"]["laser_joint"]
    assert laser["type"] == "fixed"
    assert laser["origin"]["xyz"] == [lidar.mount_x_m, lidar.mount_y_m, 0.0]
    (puck,) = model["links"]["laser"]
    assert puck["origin"]["xyz"][2] == pytest.approx(
        robot.wheel_radius_m + CHASSIS_HEIGHT_M + LASER_HEIGHT_M / 2)
