"""The robot's sensors: what it publishes per tick, at which ticks, and what a late tick sheds."""

from __future__ import annotations

import pytest
from robot_rig import robot_rig

from physics import NoiseParams, Pose2D, Simulation, load_world
from physics.lidar import ScanRequest, scan_many
from ros_nodes.robot_host import SHED_SCANS_AFTER_S
from ros_nodes.robot_interface import CLOCK, GROUND_TRUTH, JOINT_STATES, ODOM, SCAN, TF, TopicSpec
from ros_nodes.sensors import ROBOT_SENSORS, Sensor
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.msgs.values import Message

BATTERY = TopicSpec("/battery", "std_msgs/msg/Float32", "out", 4, "reliable", "volts")


def battery(sim: Simulation, stamp_s: float) -> Message:
    return {"data": 12.0 - sim.time_s}


def test_the_robot_publishes_its_sensors_in_order_each_at_its_rate() -> None:
    assert [sensor.topic for sensor in ROBOT_SENSORS] == [CLOCK, ODOM, TF, GROUND_TRUTH,
                                                           JOINT_STATES, SCAN]
    assert [sensor.topic.name for sensor in ROBOT_SENSORS if sensor.sheddable] == ["/scan"]
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0))
    topics = [[spec.name for spec, _ in robot.step()] for _ in range(4)]
    assert topics == [["/clock", "/odom", "/tf", "/ground_truth", "/joint_states"],
                      ["/clock", "/odom", "/tf", "/ground_truth", "/joint_states", "/scan"]] * 2


def test_a_new_sensor_is_one_more_sensor() -> None:
    sensors = (*ROBOT_SENSORS, Sensor(BATTERY, battery))
    robot = VirtualRobot(Simulation(load_world("empty"), seed=0), sensors=sensors)
    published = [[(spec.name, msg) for spec, msg in robot.step(wanted={"/battery"})]
                 for _ in range(8)]
    assert published == [[]] * 3 + [[("/battery", {"data": pytest.approx(11.8)})]] + \
        [[]] * 3 + [[("/battery", {"data": pytest.approx(11.6)})]]


def test_a_late_tick_sheds_every_sheddable_sensor_and_counts_it() -> None:
    rig = robot_rig()
    rig.robot.sensors = (*ROBOT_SENSORS, Sensor(BATTERY, battery, sheddable=True))
    heard: list[str] = []
    rig.robot.tap.add(lambda direction, topic, *_: heard.append(topic))
    rig.tick(3)
    rig.tick(lateness_s=2 * SHED_SCANS_AFTER_S)  # tick 4: /scan and /battery are due
    assert heard.count("/odom") == 4
    assert "/battery" not in heard and heard.count("/scan") == 1
    assert (rig.host.stats.scans_shed, rig.host.stats.scans_cast) == (2, 1)
    assert rig.host.health()["scans_shed"] == 2


def test_scans_cast_together_equal_scans_cast_alone() -> None:
    noise = NoiseParams(scan_sigma_m=0.01)
    sims = [Simulation(load_world(world), noise=noise, seed=seed)
            for world, seed in (("maze", 0), ("empty", 1), ("maze", 2))]
    for index, sim in enumerate(sims):
        sim.command(0.2, 0.1 * index)
        sim.step(3 + index)
    together = scan_many([sim.scan_request() for sim in sims])
    for sim, scan in zip(sims, together, strict=True):
        assert scan.ranges == pytest.approx(sim.scan().ranges, abs=1e-12)
    assert scan_many([]) == []
    pose = Pose2D(0.5, -0.2, 0.3)
    assert scan_many([ScanRequest(sims[0].lidar, pose)]) == [sims[0].lidar.scan(pose)]
