"""The robot model: /robot_description's URDF against the parameters, /joint_states, the wheels'
transforms, and the URDF published again when a parameter that shapes it changes."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import pytest
from robot_rig import RobotRig

from physics import LidarParams, RobotParams, Simulation, load_world
from ros_nodes.parameters import PARAMETER_DOUBLE, PARAMETER_STRING
from ros_nodes.sensors import joint_states, odometry_transform
from ros_nodes.urdf import LASER_HEIGHT_M, robot_urdf
from ros_nodes.virtual_robot_core import VirtualRobot
from ros_nodes.world_host import WorldHost
from rosbridge.core.clock import ManualClock

ROBOT = RobotParams(wheel_radius_m=0.05, wheelbase_m=0.23, footprint_radius_m=0.17,
                    mass_kg=2.5, inertia_kg_m2=0.02)
LIDAR = LidarParams(mount_x_m=0.04, mount_y_m=-0.01, mount_yaw_rad=0.3)


def rig_of(robot: RobotParams = ROBOT, lidar: LidarParams = LIDAR,
           mode: str = "kinematic") -> RobotRig:
    """What ``websim serve`` builds for a robot of these parameters, on a manual clock."""
    clock = ManualClock()
    sim = Simulation(load_world("empty"), robot, lidar=lidar, mode=mode, seed=0)
    world, host = WorldHost.of(VirtualRobot(sim, clock))
    return RobotRig(host, clock, world)


def numbers(element: ET.Element, attribute: str) -> list[float]:
    return [float(value) for value in element.attrib[attribute].split()]


def joints(root: ET.Element) -> dict[str, ET.Element]:
    return {joint.attrib["name"]: joint for joint in root.iter("joint")}


def cylinder(link: ET.Element, kind: str) -> tuple[float, float]:
    """(radius, length) of the cylinder of ``link``'s ``visual`` or ``collision``."""
    shape = link.find(f"{kind}/geometry/cylinder")
    assert shape is not None
    return float(shape.attrib["radius"]), float(shape.attrib["length"])


def test_the_urdf_is_the_robot_of_its_parameters() -> None:
    root = ET.fromstring(robot_urdf(ROBOT, LIDAR))
    links = {link.attrib["name"]: link for link in root.iter("link")}
    assert set(links) == {"base_link", "left_wheel", "right_wheel", "laser"}
    assert cylinder(links["base_link"], "collision")[0] == ROBOT.footprint_radius_m
    inertial = links["base_link"].find("inertial")
    assert inertial is not None
    assert float(inertial.find("mass").attrib["value"]) == ROBOT.mass_kg  # type: ignore[union-attr]
    assert float(inertial.find("inertia").attrib["izz"]) == ROBOT.inertia_kg_m2  # type: ignore[union-attr]

    by_name = joints(root)
    assert set(by_name) == {"left_wheel_joint", "right_wheel_joint", "laser_joint"}
    for name, side in (("left_wheel_joint", 1.0), ("right_wheel_joint", -1.0)):
        joint = by_name[name]
        assert joint.attrib["type"] == "continuous"
        assert joint.find("parent").attrib["link"] == "base_link"  # type: ignore[union-attr]
        child = joint.find("child").attrib["link"]  # type: ignore[union-attr]
        origin = joint.find("origin")
        assert origin is not None
        # On the axle: +-wheelbase/2 to the side, the wheel radius up from the ground.
        assert numbers(origin, "xyz") == [0.0, side * ROBOT.wheelbase_m / 2, ROBOT.wheel_radius_m]
        assert numbers(joint.find("axis"), "xyz") == [0.0, 1.0, 0.0]  # type: ignore[arg-type]
        limit = joint.find("limit")
        assert limit is not None
        assert float(limit.attrib["velocity"]) == pytest.approx(
            (ROBOT.max_linear_mps + ROBOT.max_angular_rps * ROBOT.wheelbase_m / 2)
            / ROBOT.wheel_radius_m)
        assert float(limit.attrib["effort"]) == pytest.approx(
            ROBOT.max_wheel_force_n * ROBOT.wheel_radius_m)
        assert cylinder(links[child], "visual")[0] == ROBOT.wheel_radius_m
        # The wheel cylinder is drawn along the axle (its z turned onto y).
        rpy = numbers(links[child].find("visual/origin"), "rpy")  # type: ignore[arg-type]
        assert rpy == pytest.approx([-math.pi / 2, 0.0, 0.0])

    laser = by_name["laser_joint"]
    assert laser.attrib["type"] == "fixed"
    origin = laser.find("origin")
    assert origin is not None
    assert numbers(origin, "xyz") == [LIDAR.mount_x_m, LIDAR.mount_y_m, 0.0]
    assert numbers(origin, "rpy") == [0.0, 0.0, LIDAR.mount_yaw_rad]
    assert cylinder(links["laser"], "visual")[1] == LASER_HEIGHT_M


def test_the_urdf_is_one_tree_rooted_at_base_link() -> None:
    root = ET.fromstring(robot_urdf(RobotParams(), LidarParams()))
    links = {link.attrib["name"] for link in root.iter("link")}
    children = [joint.find("child").attrib["link"]  # type: ignore[union-attr]
                for joint in root.iter("joint")]
    parents = {joint.find("parent").attrib["link"]  # type: ignore[union-attr]
               for joint in root.iter("joint")}
    assert sorted(children) == sorted(links - {"base_link"})  # each link has one parent...
    assert parents <= links and "base_link" not in children  # ...and base_link is the root
    assert "base_footprint" not in links  # the real robot's frames: odom, base_link, laser
    materials = {material.attrib["name"] for material in root.findall("material")}
    used = {material.attrib["name"] for material in root.iter("material")
            if "rgba" not in material.attrib and material.find("color") is None}
    assert used <= materials


def test_the_laser_joint_is_the_transform_on_tf_static() -> None:
    rig = rig_of()
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/tf_static"})
    (transform,) = rig.drain(client)[0]["msg"]["transforms"]
    origin = joints(ET.fromstring(rig.robot.urdf()))["laser_joint"].find("origin")
    assert origin is not None
    translation = transform["transform"]["translation"]
    assert [translation["x"], translation["y"], translation["z"]] == numbers(origin, "xyz")
    rotation = transform["transform"]["rotation"]
    yaw = 2 * math.atan2(rotation["z"], rotation["w"])
    assert [0.0, 0.0, yaw] == pytest.approx(numbers(origin, "rpy"), abs=1e-15)


def test_robot_description_is_latched_with_the_urdf() -> None:
    rig = rig_of()
    rig.tick(5)
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/robot_description",
                      "type": "std_msgs/msg/String"})
    frames = rig.drain(client)
    assert [frame["topic"] for frame in frames] == ["/robot_description"]
    assert frames[0]["msg"] == {"data": robot_urdf(ROBOT, LIDAR)}


def set_parameter(rig: RobotRig, name: str, value: Any) -> None:
    admin = rig.client("admin", admin=True)
    type_code, field = ((PARAMETER_STRING, "string_value") if isinstance(value, str)
                        else (PARAMETER_DOUBLE, "double_value"))
    reply = rig.call(admin, "/virtual_robot/set_parameters", {"parameters": [
        {"name": name, "value": {"type": type_code, field: value}}]})
    assert reply["values"]["results"][0]["successful"], reply


def mass_in(urdf: str) -> float:
    mass = ET.fromstring(urdf).find("link/inertial/mass")
    assert mass is not None
    return float(mass.attrib["value"])


def test_a_payload_change_publishes_the_urdf_again_and_late_subscribers_get_the_new_one() -> None:
    rig = rig_of()
    watcher = rig.client()
    rig.send(watcher, {"op": "subscribe", "topic": "/robot_description"})
    assert [mass_in(frame["msg"]["data"]) for frame in rig.drain(watcher)] == [ROBOT.mass_kg]

    set_parameter(rig, "mode", "dynamic")  # does not shape the URDF: nothing sent
    rig.tick()
    assert rig.drain(watcher) == []
    set_parameter(rig, "mass_kg", 5.0)
    rig.tick()
    assert [mass_in(frame["msg"]["data"]) for frame in rig.drain(watcher)] == [5.0]
    set_parameter(rig, "max_linear_mps", 0.3)  # the wheels' speed limit
    rig.tick()
    (frame,) = rig.drain(watcher)
    limit = joints(ET.fromstring(frame["msg"]["data"]))["left_wheel_joint"].find("limit")
    assert limit is not None and float(limit.attrib["velocity"]) == pytest.approx(
        (0.3 + ROBOT.max_angular_rps * ROBOT.wheelbase_m / 2) / ROBOT.wheel_radius_m)

    late = rig.client("late")
    rig.send(late, {"op": "subscribe", "topic": "/robot_description"})
    assert [frame["msg"]["data"] for frame in rig.drain(late)] == [rig.robot.urdf()]
    assert mass_in(rig.robot.urdf()) == 5.0


def test_wheel_joints_turn_by_the_distance_over_the_wheel_radius() -> None:
    rig = rig_of()
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/joint_states"})
    rig.send(client, {"op": "publish", "topic": "/cmd_vel",
                      "msg": {"linear": {"x": 0.3}, "angular": {"z": 0.0}}})
    rig.tick(40)
    states = [frame["msg"] for frame in rig.drain(client) if frame["topic"] == "/joint_states"]
    assert len(states) == 40  # at the odometry rate, 20 Hz
    last = states[-1]
    assert last["name"] == ["left_wheel_joint", "right_wheel_joint"]
    distance_m = rig.robot.sim.ground_truth().x
    assert distance_m == pytest.approx(0.3 * 40 * 0.05)
    assert last["position"] == pytest.approx([distance_m / ROBOT.wheel_radius_m] * 2, abs=1e-12)
    assert last["velocity"] == pytest.approx([0.3 / ROBOT.wheel_radius_m] * 2, abs=1e-12)
    assert last["header"]["frame_id"] == "" and last["effort"] == []


def test_turning_in_place_turns_the_wheels_opposite_ways() -> None:
    sim = Simulation(load_world("empty"), ROBOT, seed=0)
    sim.command(0.0, 1.0)
    sim.step(20)
    wheel_angle_rad = 1.0 * 20 * 0.05 * (ROBOT.wheelbase_m / 2) / ROBOT.wheel_radius_m
    msg = joint_states(sim, 0.0)
    assert msg["position"] == pytest.approx([-wheel_angle_rad, wheel_angle_rad], abs=1e-12)
    sim.reset()
    assert joint_states(sim, 0.0)["position"] == [0.0, 0.0]


def test_slipping_wheels_turn_as_the_encoders_count_which_odometry_integrates() -> None:
    # Dynamic mode from rest at full speed: the wheels slip, so they turn further than the
    # ground distance; odometry integrates the same encoders, so it agrees with them.
    sim = Simulation(load_world("empty"), ROBOT, mode="dynamic", seed=0)
    sim.command(ROBOT.max_linear_mps, 0.0)
    sim.step(6)
    wheels = sim.wheels()
    assert wheels.left_rad == pytest.approx(wheels.right_rad, abs=1e-12)
    rolled_m = wheels.left_rad * ROBOT.wheel_radius_m
    assert rolled_m == pytest.approx(sim.odometry().x, abs=1e-12)
    assert rolled_m > sim.ground_truth().x + 1e-3


def test_tf_carries_each_wheel_at_its_joint_turned_by_its_angle() -> None:
    sim = Simulation(load_world("empty"), ROBOT, seed=0)
    sim.command(0.2, 0.5)
    sim.step(7)
    transforms = odometry_transform(sim, 12.5)["transforms"]
    assert [(t["header"]["frame_id"], t["child_frame_id"]) for t in transforms] == [
        ("odom", "base_link"), ("base_link", "left_wheel"), ("base_link", "right_wheel")]
    origins = {name: numbers(joint.find("origin"), "xyz")  # type: ignore[arg-type]
               for name, joint in joints(ET.fromstring(robot_urdf(ROBOT, LIDAR))).items()}
    angles = joint_states(sim, 12.5)["position"]
    for transform, joint, angle in zip(transforms[1:], ("left_wheel_joint", "right_wheel_joint"),
                                       angles, strict=True):
        translation = transform["transform"]["translation"]
        assert [translation["x"], translation["y"], translation["z"]] == origins[joint]
        q = transform["transform"]["rotation"]
        assert (q["x"], q["z"]) == (0.0, 0.0)  # about the axle, y
        assert 2 * math.atan2(q["y"], q["w"]) == pytest.approx(math.remainder(angle, 2 * math.pi))
        assert transform["header"]["stamp"] == {"sec": 12, "nanosec": 500_000_000}
