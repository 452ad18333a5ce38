"""The virtual_robot rclpy node and ``websim serve --ros`` on a real ROS 2 graph.

Real processes (``websim-robot``, ``websim serve --ros``) and a real rclpy node in this test
process. Each test runs on its own ROS_DOMAIN_ID with discovery kept on this machine, so tests
never see each other or the network. Every wait polls with a bound.
"""

from __future__ import annotations

import importlib.util
import itertools
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)
"""Fixtures domain, graph, test_world, start_robot."""

import roslibpy  # noqa: E402
from geometry_msgs.msg import Twist  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rcl_interfaces.msg import ParameterType  # noqa: E402
from rclpy.qos import (  # noqa: E402
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import Empty  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from physics import RobotParams, Simulation, load_world  # noqa: E402
from ros_nodes.parameters import PARAMETER_DOUBLE  # noqa: E402
from ros_nodes.robot_interface import PUBLISHED_TOPICS, WORLD_ROBOTS  # noqa: E402
from ros_nodes.robot_messages import Float32Sequence, world_robots_msg  # noqa: E402
from ros_nodes.virtual_robot import TF_MISSING_WARNING  # noqa: E402
from ros_nodes.virtual_robot_core import VirtualRobot  # noqa: E402
from rosbridge.msgs.rclpy_conversion import (  # noqa: E402
    MessageConversionError,
    message_class,
    to_dict,
    to_message,
)

from ros_fixtures import (  # noqa: E402
    DT_S,
    LATCHED,
    RELIABLE,
    STARTUP_TIMEOUT_S,
    WALL_X_M,
    Graph,
    RobotProcess,
    robot_command,
    stamp_s,
)
from server_process import ServerProcess, start_server, wait_for  # noqa: E402

HAS_TF2_MSGS = importlib.util.find_spec("tf2_msgs") is not None

def twist(linear: float = 0.0, angular: float = 0.0) -> Twist:
    msg = Twist()
    msg.linear.x = float(linear)
    msg.angular.z = float(angular)
    return msg


def rate_hz(received: list[tuple[float, Any]]) -> float:
    """The publisher's rate, from its header stamps (the receiver's timing under load, and a
    lost best-effort message, do not count): one over the median stamp interval."""
    stamps = sorted(stamp_s(msg) for _, msg in received)
    return 1.0 / statistics.median(b - a for a, b in itertools.pairwise(stamps))


# ---- dicts <-> rclpy messages ------------------------------------------------------------


def test_every_robot_message_converts_and_comes_back_unchanged() -> None:
    robot = VirtualRobot(Simulation(load_world("maze"), seed=0))
    robot.on_cmd_vel({"linear": {"x": 0.2}, "angular": {"z": 0.4}})
    publications = robot.latched() + robot.step() + robot.step()
    world = robot.sim.world_sim  # and the world's own message, built once for its robots
    publications.append((WORLD_ROBOTS, world_robots_msg(
        world.names, world.poses().tolist(), world.footprints()[:, 2].tolist(), 1.5)))
    assert {spec.name for spec, _ in publications} == {topic.name for topic in PUBLISHED_TOPICS}
    for spec, msg in publications:
        if spec.type.startswith("tf2_msgs/") and not HAS_TF2_MSGS:
            continue
        ros_msg = to_message(message_class(spec.type), msg)
        back = to_dict(ros_msg)
        if spec.name == "/scan":  # float32 on the wire
            assert isinstance(back["ranges"], Float32Sequence)
            assert back["ranges"] == pytest.approx(msg["ranges"], rel=1e-7)
            back["ranges"] = msg["ranges"]
        assert back == msg, spec.name


def test_uint8_arrays_are_base64_and_errors_name_the_field() -> None:
    from sensor_msgs.msg import CompressedImage

    image = to_message(CompressedImage, {"format": "png", "data": "AAEC/w=="})
    assert list(image.data) == [0, 1, 2, 255]
    assert to_dict(image)["data"] == "AAEC/w=="
    with pytest.raises(MessageConversionError, match=r"linear\.x: expected a number"):
        to_message(Twist, {"linear": {"x": "fast"}})
    with pytest.raises(MessageConversionError, match=r"lineer: .* has no such field"):
        to_message(Twist, {"lineer": {}})
    with pytest.raises(MessageConversionError, match="pip install ros-no-such-msgs"):
        message_class("no_such_msgs/msg/Thing")


# ---- websim-robot ------------------------------------------------------------------------


def test_topics_types_rates_frames_and_qos(graph: Graph,
                                           start_robot: Callable[..., RobotProcess]) -> None:
    robot = start_robot()
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    scans = graph.collect(LaserScan, "/scan", qos_profile_sensor_data)
    truth = graph.collect(Odometry, "/ground_truth", RELIABLE)
    world = graph.collect(MarkerArray, "/world", LATCHED)
    graph.spin_until(lambda: len(odom) >= 61 and len(scans) >= 31, 15.0, "3 s of /odom, /scan")

    assert rate_hz(odom) == pytest.approx(20.0, rel=0.1)
    assert rate_hz(scans) == pytest.approx(10.0, rel=0.1)
    types = dict(graph.node.get_topic_names_and_types())
    assert types["/odom"] == ["nav_msgs/msg/Odometry"]
    assert types["/scan"] == ["sensor_msgs/msg/LaserScan"]
    assert types["/ground_truth"] == ["nav_msgs/msg/Odometry"]
    assert types["/world"] == ["visualization_msgs/msg/MarkerArray"]
    assert [info.topic_type for info in
            graph.node.get_subscriptions_info_by_topic("/cmd_vel")] == ["geometry_msgs/msg/Twist"]
    scan_qos = graph.node.get_publishers_info_by_topic("/scan")[0].qos_profile
    assert scan_qos.reliability == ReliabilityPolicy.BEST_EFFORT
    world_qos = graph.node.get_publishers_info_by_topic("/world")[0].qos_profile
    assert world_qos.durability == DurabilityPolicy.TRANSIENT_LOCAL

    last_odom, scan = odom[-1][1], scans[-1][1]
    assert (last_odom.header.frame_id, last_odom.child_frame_id) == ("odom", "base_link")
    assert truth[-1][1].header.frame_id == "map"
    assert scan.header.frame_id == "laser"
    assert len(scan.ranges) == 360
    assert scan.angle_min + 359 * scan.angle_increment == pytest.approx(scan.angle_max)
    assert scan.ranges[0] == pytest.approx(WALL_X_M, abs=1e-6)  # float32
    # A late subscriber still gets the latched world: its one wall as a LINE_LIST.
    graph.spin_until(lambda: world, 5.0, "latched /world")
    wall = world[0][1].markers[0]
    assert wall.header.frame_id == "map"
    assert [(p.x, p.y) for p in wall.points] == [(WALL_X_M, -2.0), (WALL_X_M, 2.0)]

    if HAS_TF2_MSGS:
        from tf2_msgs.msg import TFMessage

        tf_static = graph.collect(TFMessage, "/tf_static", LATCHED)
        tf = graph.collect(TFMessage, "/tf", RELIABLE)
        graph.spin_until(lambda: tf_static and tf, 5.0, "/tf and /tf_static")
        static = tf_static[0][1].transforms[0]
        assert (static.header.frame_id, static.child_frame_id) == ("base_link", "laser")
        moving = tf[-1][1].transforms[0]
        assert (moving.header.frame_id, moving.child_frame_id) == ("odom", "base_link")
    assert robot.stop() == 0
    warnings = "".join(robot.output).count(TF_MISSING_WARNING)
    assert warnings == (0 if HAS_TF2_MSGS else 1)


def test_cmd_vel_drives_at_the_commanded_speed(graph: Graph,
                                               start_robot: Callable[..., RobotProcess]) -> None:
    start_robot()
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    cmd_vel = graph.node.create_publisher(Twist, "/cmd_vel", 10)
    graph.spin_until(lambda: cmd_vel.get_subscription_count() > 0, 10.0, "/cmd_vel subscriber")
    cmd_vel.publish(twist(0.3))
    graph.spin_until(lambda: odom and odom[-1][1].pose.pose.position.x > 0.3, 10.0, "driving")
    cmd_vel.publish(twist())
    moving = [msg for _, msg in odom if msg.twist.twist.linear.x > 0]
    # Kinematic mode: every tick moves exactly v * dt along x.
    steps = [b.pose.pose.position.x - a.pose.pose.position.x
             for a, b in itertools.pairwise(moving)]
    assert steps and all(step == pytest.approx(0.3 * DT_S, abs=1e-9) for step in steps)
    assert moving[-1].twist.twist.linear.x == pytest.approx(0.3)


def test_cmd_vel_timeout_stops_after_the_timeout(graph: Graph,
                                                  start_robot: Callable[..., RobotProcess]) -> None:
    start_robot("cmd_vel_timeout_s:=0.5", "use_sim_time:=true")  # the command's age in ticks
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    cmd_vel = graph.node.create_publisher(Twist, "/cmd_vel", 10)
    graph.spin_until(lambda: cmd_vel.get_subscription_count() > 0, 10.0, "/cmd_vel subscriber")
    cmd_vel.publish(twist(0.3))
    graph.spin_until(lambda: any(m.twist.twist.linear.x > 0 for _, m in odom), 10.0, "motion")
    graph.spin_until(lambda: odom[-1][1].twist.twist.linear.x == 0.0, 10.0, "the watchdog stop")
    # 0.5 s of 0.3 m/s: ten ticks of 15 mm.
    assert odom[-1][1].pose.pose.position.x == pytest.approx(0.15, abs=1e-9)
    assert graph.get_parameter("cmd_vel_timeout_s") == 0.5


def _acceleration_mps2(graph: Graph, truth: list[tuple[float, Any]], cmd_vel: Any) -> float:
    """Command 0.5 m/s from rest; the true acceleration while it ramps (sim-time stamps)."""
    graph.call(Empty, "/reset_simulation", Empty.Request())
    start = len(truth)
    cmd_vel.publish(twist(0.5))
    graph.spin_until(lambda: any(m.twist.twist.linear.x >= 0.45 for _, m in truth[start:]),
                     10.0, "speed 0.45 m/s")
    cmd_vel.publish(twist())
    ramp = sorted((stamp_s(m), m.twist.twist.linear.x) for _, m in truth[start:]
                  if 0.0 < m.twist.twist.linear.x < 0.45)
    assert len(ramp) >= 2, ramp
    (t0, v0), (t1, v1) = ramp[0], ramp[-1]
    return (v1 - v0) / (t1 - t0)


def test_mass_parameter_changes_dynamic_motion(graph: Graph,
                                               start_robot: Callable[..., RobotProcess]) -> None:
    start_robot("mode:=dynamic", "use_sim_time:=true")  # exact stamps, whatever the load
    truth = graph.collect(Odometry, "/ground_truth", RELIABLE)
    cmd_vel = graph.node.create_publisher(Twist, "/cmd_vel", 10)
    graph.spin_until(lambda: cmd_vel.get_subscription_count() > 0, 10.0, "/cmd_vel subscriber")
    params = RobotParams()
    light = _acceleration_mps2(graph, truth, cmd_vel)
    assert light == pytest.approx(params.max_linear_accel_mps2, rel=0.1)  # 2.5 m/s^2

    # An integer, as `ros2 param set /virtual_robot mass_kg 12` sends it, is taken as a double.
    assert [r.successful for r in graph.set_parameters(mass_kg=12)] == [True]
    assert graph.get_parameter("mass_kg") == 12.0
    heavy = _acceleration_mps2(graph, truth, cmd_vel)
    assert heavy == pytest.approx(2.0 * params.max_wheel_force_n / 12.0, rel=0.1)  # 0.25


def test_invalid_parameters_are_refused_with_the_reason(
        graph: Graph, start_robot: Callable[..., RobotProcess]) -> None:
    start_robot()
    negative, = graph.set_parameters(mass_kg=-1.0)
    assert not negative.successful
    assert "mass_kg out of range Min: 0.01, Max: 1000.0" in negative.reason  # rclpy, from the spec
    flying, = graph.set_parameters(mode="flying")
    assert not flying.successful and "must be one of kinematic, dynamic" in flying.reason
    timeout, = graph.set_parameters(cmd_vel_timeout_s=-0.1)
    assert not timeout.successful and "cmd_vel_timeout_s" in timeout.reason
    world, = graph.set_parameters(world="maze")
    assert not world.successful and "read-only" in world.reason
    assert graph.get_parameter("mass_kg") == RobotParams().mass_kg
    assert graph.get_parameter("mode") == "kinematic"


@pytest.mark.parametrize(("override", "reason"), [
    ("world:=no_such_world", "no_such_world"),
    ("mass_kg:=-2.0", "Parameter mass_kg out of range Min: 0.01, Max: 1000.0"),
    ("scan_sigma_m:=-1.0", "scan_sigma_m"),
])
def test_invalid_start_parameters_exit_with_the_reason(domain: int, override: str,
                                                        reason: str) -> None:
    result = subprocess.run(robot_command(override), capture_output=True, text=True,
                            timeout=STARTUP_TIMEOUT_S)
    assert result.returncode == 2, result.stdout + result.stderr
    assert reason in result.stderr


def test_reset_simulation_returns_to_spawn(graph: Graph,
                                           start_robot: Callable[..., RobotProcess]) -> None:
    start_robot()
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    cmd_vel = graph.node.create_publisher(Twist, "/cmd_vel", 10)
    graph.spin_until(lambda: cmd_vel.get_subscription_count() > 0, 10.0, "/cmd_vel subscriber")
    cmd_vel.publish(twist(0.4, 1.0))
    graph.spin_until(lambda: odom and odom[-1][1].pose.pose.position.x > 0.1, 10.0, "driving")
    graph.call(Empty, "/reset_simulation", Empty.Request())
    start = len(odom)
    graph.spin_until(lambda: len(odom) > start + 2, 5.0, "odometry after the reset")
    after = odom[-1][1]
    pose = after.pose.pose
    assert (pose.position.x, pose.position.y, pose.orientation.z) == (0.0, 0.0, 0.0)
    assert after.twist.twist.linear.x == 0.0  # the reset also zeroes the command


@pytest.mark.parametrize("sim_time", [True, False])
def test_the_node_publishes_clock_and_stamps_with_it(
        graph: Graph, start_robot: Callable[..., RobotProcess], sim_time: bool) -> None:
    started_s = time.time()
    start_robot(f"use_sim_time:={str(sim_time).lower()}")
    clock = graph.collect(Clock, "/clock", QoSProfile(depth=50))
    odom = graph.collect(Odometry, "/odom", RELIABLE)
    graph.spin_until(lambda: len(clock) >= 10 and len(odom) >= 10, 10.0, "/clock and /odom")
    clock_ns = [m.clock.sec * 10**9 + m.clock.nanosec for _, m in clock]
    stamps_ns = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in odom]
    # Every /odom is stamped with a time /clock said, which starts at the wall time of the
    # start (never 0, as a real robot's stamps: a node without use_sim_time sees no jump).
    inside = [ns for ns in stamps_ns if clock_ns[0] <= ns <= clock_ns[-1]]
    assert len(inside) >= 5 and set(inside) <= set(clock_ns)
    assert started_s - 5.0 < clock_ns[0] / 1e9 < time.time() + 1.0
    if sim_time:  # sim time: exactly one tick per tick, whatever the load
        assert all(b - a == DT_S * 1e9 for a, b in itertools.pairwise(clock_ns))


# ---- websim serve --ros ------------------------------------------------------------------


def test_serve_ros_browser_and_rclpy_drive_the_same_robot(
        graph: Graph, ros_server: ServerProcess, ros_client: roslibpy.Ros) -> None:
    graph.spin_until(lambda: graph.node.count_publishers("/odom") > 0, STARTUP_TIMEOUT_S,
                     "the in-process virtual_robot node")
    ros_odom = graph.collect(Odometry, "/odom", RELIABLE)
    seen_cmd_vel = graph.collect(Twist, "/cmd_vel", RELIABLE)
    browser_odom: list[dict[str, Any]] = []
    roslibpy.Topic(ros_client, "/odom", "nav_msgs/msg/Odometry").subscribe(browser_odom.append)

    # A student's rclpy node drives; the browser sees the motion.
    cmd_vel = graph.node.create_publisher(Twist, "/cmd_vel", 10)
    graph.spin_until(lambda: cmd_vel.get_subscription_count() > 0, 10.0, "/cmd_vel subscriber")
    cmd_vel.publish(twist(0.3))
    wait_for(lambda: browser_odom and browser_odom[-1]["twist"]["twist"]["linear"]["x"] == 0.3,
             10.0, "the browser to see the rclpy command")

    # The browser drives; the rclpy node sees the motion and the command itself.
    browser_cmd = roslibpy.Topic(ros_client, "/cmd_vel", "geometry_msgs/msg/Twist")
    browser_cmd.advertise()
    browser_cmd.publish(roslibpy.Message({"linear": {"x": 0.0, "y": 0.0, "z": 0.0},
                                          "angular": {"x": 0.0, "y": 0.0, "z": 0.5}}))
    graph.spin_until(lambda: ros_odom and ros_odom[-1][1].twist.twist.angular.z == 0.5, 10.0,
                     "rclpy to see the browser's command")
    assert ros_odom[-1][1].twist.twist.linear.x == 0.0
    graph.spin_until(lambda: any(m.angular.z == 0.5 for _, m in seen_cmd_vel), 5.0,
                     "the browser's /cmd_vel on the ROS graph")

    # One parameter table: the admin page's change shows in the node's ROS parameters.
    admin = roslibpy.Ros(host=ros_server.admin_ws_url)
    admin.run(timeout=10)
    try:
        reply = roslibpy.Service(admin, "/virtual_robot/set_parameters",
                                 "rcl_interfaces/srv/SetParameters").call(
            roslibpy.ServiceRequest({"parameters": [{"name": "mass_kg", "value": {
                "type": PARAMETER_DOUBLE, "double_value": 3.5}}]}), timeout=5)
    finally:
        admin.close()
    assert reply["results"][0]["successful"] is True
    graph.spin_until(lambda: graph.get_parameter("mass_kg") == 3.5, 5.0,
                     "the admin page's mass_kg in the ROS parameters")
    # And the other way: ros2 param set, seen by the browser's parameter service.
    assert [r.successful for r in graph.set_parameters(mass_kg=4.0)] == [True]
    got = roslibpy.Service(ros_client, "/virtual_robot/get_parameters",
                           "rcl_interfaces/srv/GetParameters").call(
        roslibpy.ServiceRequest({"names": ["mass_kg"]}), timeout=5)
    assert got["values"][0]["type"] == ParameterType.PARAMETER_DOUBLE
    assert got["values"][0]["double_value"] == 4.0


def test_serve_ros_relays_graph_topics_both_ways(
        graph: Graph, ros_server: ServerProcess, ros_client: roslibpy.Ros) -> None:
    # A topic only the ROS graph has: the browser subscribes before anyone publishes it.
    heard: list[dict[str, Any]] = []
    roslibpy.Topic(ros_client, "/chatter", "std_msgs/msg/String",
                   queue_length=10).subscribe(heard.append)
    chatter = graph.node.create_publisher(String, "/chatter", 10)
    graph.spin_until(lambda: chatter.get_subscription_count() > 0, 10.0, "the relay to subscribe")
    for index in range(3):
        chatter.publish(String(data=f"hello {index}"))
    wait_for(lambda: len(heard) >= 3, 10.0, "/chatter in the browser")
    assert [m["data"] for m in heard[:3]] == ["hello 0", "hello 1", "hello 2"]

    # A browser topic reaches rclpy once per message: the relay's own messages do not come
    # back to the browser through the graph.
    received = graph.collect(String, "/from_browser", RELIABLE)
    in_browser: list[dict[str, Any]] = []
    talker = roslibpy.Topic(ros_client, "/from_browser", "std_msgs/msg/String", queue_length=10)
    talker.subscribe(in_browser.append)
    talker.advertise()
    graph.spin_until(lambda: graph.node.count_publishers("/from_browser") > 0, 10.0,
                     "the relay to publish /from_browser")
    for text in ("a", "b"):
        talker.publish(roslibpy.Message({"data": text}))
    graph.spin_until(lambda: len(received) >= 2, 10.0, "the browser's messages in rclpy")
    assert [m.data for _, m in received] == ["a", "b"]
    # A message from rclpy comes through the graph after any echo of "a" and "b" would have.
    rclpy_talker = graph.node.create_publisher(String, "/from_browser", 10)
    graph.spin_until(lambda: rclpy_talker.get_subscription_count() >= 2, 10.0,
                     "the relay and this test to subscribe")  # the test's own counts too
    rclpy_talker.publish(String(data="c"))
    wait_for(lambda: any(m["data"] == "c" for m in in_browser), 10.0, "rclpy's message")
    assert [m["data"] for m in in_browser] == ["a", "b", "c"]
    assert "/chatter" in ros_client.get_topics()


# ---- websim serve --class --ros --------------------------------------------------------------

STUDENT = Path(__file__).resolve().parent / "ros_students" / "drive.py"


def test_class_ros_namespaced_students_drive_their_own_robots(graph: Graph,
                                                              domain: int) -> None:
    server = start_server(["--class", "2", "--ros"])
    try:
        for name in ("robot01", "robot02"):
            graph.spin_until(lambda n=name: graph.node.count_publishers(f"/{n}/odom") > 0,
                             STARTUP_TIMEOUT_S, f"the /{name}/virtual_robot node")
        odoms = {name: graph.collect(Odometry, f"/{name}/odom", RELIABLE)
                 for name in ("robot01", "robot02")}
        students = [subprocess.Popen([sys.executable, str(STUDENT), str(speed), "1.5",
                                      "--ros-args", "-r", f"__ns:=/{name}"],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True)
                    for name, speed in (("robot01", 0.2), ("robot02", 0.4))]
        graph.spin_until(lambda: all(student.poll() is not None for student in students),
                         STARTUP_TIMEOUT_S + 10, "the students' nodes to finish")
        for student in students:
            out, _ = student.communicate()
            assert student.returncode == 0, out
        graph.spin_until(lambda: all(odoms.values()), 5.0, "both robots' odometry")
        first = {name: odoms[name][-1][1] for name in odoms}
        assert first["robot01"].header.frame_id == "robot01/odom"
        assert first["robot01"].child_frame_id == "robot01/base_link"
        top = {name: max(m.twist.twist.linear.x for _, m in odoms[name]) for name in odoms}
        assert top["robot01"] == pytest.approx(0.2) and top["robot02"] == pytest.approx(0.4)
        x = {name: first[name].pose.pose.position.x for name in first}
        assert x["robot02"] > 1.5 * x["robot01"] > 0.2, "each drove its own robot"
        scans = graph.collect(LaserScan, "/robot01/scan", qos_profile_sensor_data)
        graph.spin_until(lambda: scans, 5.0, "robot01's /scan on the graph")
        assert scans[-1][1].header.frame_id == "robot01/laser"
        # One class, one clock: one /clock at the root, by the class, not one per robot.
        clock = graph.collect(Clock, "/clock", QoSProfile(depth=50))
        graph.spin_until(lambda: len(clock) >= 5, 5.0, "the class's /clock")
        assert [info.node_name for info in graph.node.get_publishers_info_by_topic(
            "/clock")] == ["websim_clock"]
        assert graph.node.count_publishers("/robot01/clock") == 0
        clock_s = clock[-1][1].clock.sec + clock[-1][1].clock.nanosec * 1e-9
        assert abs(clock_s - time.time()) < 5.0  # the wall clock, as the robots' stamps
    finally:
        assert server.stop() == 0, "".join(server.output)


def test_class_ros_keeps_discovery_on_this_machine_unless_told(
        graph: Graph, domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """With neither ROS_AUTOMATIC_DISCOVERY_RANGE nor ROS_LOCALHOST_ONLY in its environment, a
    class with --ros limits discovery to this machine (the banner says so) and a node here
    still reaches its robots; an exported range is kept."""
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE")  # the server's environment only:
    monkeypatch.delenv("ROS_LOCALHOST_ONLY")  # this test's node started with LOCALHOST
    server = start_server(["--class", "1", "--ros"])
    try:
        graph.spin_until(lambda: graph.node.count_publishers("/robot01/odom") > 0,
                         STARTUP_TIMEOUT_S, "the class's robot on this machine's graph")
    finally:
        assert server.stop() == 0, "".join(server.output)
    assert "discovery range LOCALHOST" in "".join(server.output)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")
    server = start_server(["--class", "1", "--ros"])
    assert server.stop() == 0, "".join(server.output)
    assert "discovery range SUBNET" in "".join(server.output)
