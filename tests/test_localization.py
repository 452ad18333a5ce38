"""map -> odom from the ground truth (``localization: perfect``), and odometry that drifts.

REP 105's chain map -> odom -> base_link must be the true pose however far the odometry has
drifted: checked on the frames' algebra, on the simulation, and on the /tf and /ground_truth
a client receives from the robot's bridge.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from robot_rig import RobotRig, robot_rig

from physics import ConfigError, NoiseParams, Pose2D, Simulation, load_world
from physics.frames import compose, inverse, map_to_odom
from physics.params import SHIPPED_PARAMS_FILE
from physics.world import world_from_dict
from ros_nodes.sensors import ROBOT_SENSORS, robot_sensors
from ros_nodes.virtual_robot_core import VirtualRobot
from websim.cli import make_simulation

NOISY_WORLD = """\
name: noisy
start: [1.0, -0.5, 0.7]
localization: perfect
noise:
  odom_linear_sigma_mps: 0.05
  odom_angular_sigma_rps: 0.2
polylines:
  - points: [[-4, -4], [4, -4], [4, 4], [-4, 4]]
    closed: true
"""
"""Spawning off the origin and turned, so map and odom differ from the first tick."""


@pytest.fixture
def noisy_world(tmp_path: Path) -> Path:
    path = tmp_path / "noisy.yaml"
    path.write_text(NOISY_WORLD)
    return path


def planar(transform: dict[str, Any]) -> Pose2D:
    """A ``geometry_msgs/Transform`` (or a ``Pose``) dict as (x, y, yaw)."""
    translation = transform.get("translation", transform.get("position"))
    rotation = transform.get("rotation", transform.get("orientation"))
    return Pose2D(translation["x"], translation["y"],
                  2.0 * math.atan2(rotation["z"], rotation["w"]))


def same_pose(a: Pose2D, b: Pose2D, tolerance: float = 1e-9) -> bool:
    turn = math.remainder(a.theta - b.theta, 2.0 * math.pi)
    return abs(a.x - b.x) <= tolerance and abs(a.y - b.y) <= tolerance and \
        abs(turn) <= tolerance


# ---- the algebra -------------------------------------------------------------------------


def test_compose_and_inverse_are_rigid_transforms() -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        a, b, c = (Pose2D(*rng.uniform(-5, 5, 2), rng.uniform(-20, 20)) for _ in range(3))
        assert same_pose(compose(a, inverse(a)), Pose2D(0.0, 0.0, 0.0))
        assert same_pose(compose(compose(a, b), c), compose(a, compose(b, c)))
        assert same_pose(compose(map_to_odom(a, b), b), a)
    # By hand: odom turned 90 deg and 1 m along map's x; a robot 2 m ahead in odom is at (1, 2).
    assert same_pose(compose(Pose2D(1.0, 0.0, math.pi / 2), Pose2D(2.0, 0.0, 0.0)),
                     Pose2D(1.0, 2.0, math.pi / 2))


# ---- the world's settings ----------------------------------------------------------------


def test_the_world_sets_localization_and_noise(noisy_world: Path) -> None:
    world = load_world(noisy_world)
    assert world.localization == "perfect"
    assert world.noise == (("odom_linear_sigma_mps", 0.05), ("odom_angular_sigma_rps", 0.2))
    base = NoiseParams(odom_linear_sigma_mps=0.01, scan_sigma_m=0.02)
    assert world.noise_over(base) == NoiseParams(odom_linear_sigma_mps=0.05,
                                                 odom_angular_sigma_rps=0.2, scan_sigma_m=0.02)
    assert load_world("maze").localization == "none" and load_world("maze").noise == ()
    # websim serve, demo and compare build the simulation with the world's noise on top.
    args = argparse.Namespace(world=str(noisy_world), params=str(SHIPPED_PARAMS_FILE),
                              mode="kinematic", seed=0)
    assert make_simulation(args).noise == world.noise_over(NoiseParams())


@pytest.mark.parametrize(("entry", "message"), [
    ({"localization": "amcl"}, "localization: must be one of none, perfect, got 'amcl'"),
    ({"noise": {"odom_linear_sigma": 0.1}},
     "noise: unknown key 'odom_linear_sigma'; did you mean 'odom_linear_sigma_mps'?"),
    ({"noise": {"odom_angular_sigma_rps": -1}},
     "noise.odom_angular_sigma_rps: must be between 0 and 5, got -1"),
    ({"noise": [0.1]}, "noise: expected a mapping"),
])
def test_bad_settings_are_refused_with_the_key(entry: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigError) as raised:
        world_from_dict({"walls": [[1, -1, 1, 1]], **entry}, source="w.yaml")
    assert str(raised.value).startswith("w.yaml: ")
    assert message in str(raised.value)


# ---- the simulation ----------------------------------------------------------------------


def drive(sim: Simulation, seconds: float) -> None:
    """Figure-of-eight-ish driving that stays clear of the walls of a 8 x 8 m arena."""
    for second in range(int(seconds)):
        sim.command(0.3, 0.6 if (second // 5) % 2 == 0 else -0.6)
        sim.step(round(1.0 / sim.dt_s))


def test_map_to_odom_keeps_the_chain_on_the_ground_truth_as_odometry_drifts(
        noisy_world: Path) -> None:
    world = load_world(noisy_world)
    sim = Simulation(world, noise=world.noise_over(NoiseParams()), seed=1)
    assert same_pose(sim.map_to_odom(), world.start)  # at spawn odom is the spawn pose
    drift = []
    for _ in range(6):
        drive(sim, 5.0)
        odom, truth = sim.odometry(), sim.ground_truth()
        expected = Pose2D(truth.x, truth.y, truth.theta)
        assert same_pose(compose(sim.map_to_odom(), Pose2D(odom.x, odom.y, odom.theta)),
                         expected)
        dead_reckoned = compose(world.start, Pose2D(odom.x, odom.y, odom.theta))
        drift.append(math.hypot(dead_reckoned.x - truth.x, dead_reckoned.y - truth.y))
    assert max(drift) > 0.05, drift  # the noise made odometry wander from the truth
    # Without noise, odometry is the truth relative to spawn, and map -> odom stays the spawn.
    clean = Simulation(world, seed=1)
    drive(clean, 10.0)
    assert same_pose(clean.map_to_odom(), world.start)


# ---- over the bridge ---------------------------------------------------------------------


def received(rig: RobotRig, ticks: int, topics: tuple[str, ...]) -> list[dict[str, Any]]:
    client = rig.client()
    for topic in topics:
        rig.send(client, {"op": "subscribe", "topic": topic})
    frames = []
    for _ in range(ticks):
        rig.tick()
        frames += rig.drain(client)
    return frames


def test_perfect_localization_publishes_map_to_odom_that_composes_to_the_ground_truth(
        noisy_world: Path) -> None:
    world = load_world(noisy_world)
    rig = robot_rig(str(noisy_world), noise=world.noise_over(NoiseParams()), seed=2)
    assert rig.robot.localization == "perfect"
    rig.robot.on_cmd_vel({"linear": {"x": 0.3}, "angular": {"z": 0.5}})
    frames = received(rig, 400, ("/tf", "/ground_truth", "/odom"))
    tf = [f["msg"] for f in frames if f["topic"] == "/tf"]
    truth = [f["msg"] for f in frames if f["topic"] == "/ground_truth"]
    odom = [f["msg"] for f in frames if f["topic"] == "/odom"]
    assert len(tf) == len(truth) == len(odom) == 400
    for message, true_pose, odometry in zip(tf, truth, odom, strict=True):
        (to_odom, to_base, *wheels) = message["transforms"]
        assert [t["child_frame_id"] for t in wheels] == ["left_wheel", "right_wheel"]
        assert (to_odom["header"]["frame_id"], to_odom["child_frame_id"]) == ("map", "odom")
        assert (to_base["header"]["frame_id"], to_base["child_frame_id"]) == ("odom",
                                                                              "base_link")
        assert to_odom["header"]["stamp"] == true_pose["header"]["stamp"]
        chained = compose(planar(to_odom["transform"]), planar(to_base["transform"]))
        assert same_pose(chained, planar(true_pose["pose"]["pose"]))
        assert same_pose(planar(to_base["transform"]), planar(odometry["pose"]["pose"]))
    # And the odometry did drift: dead reckoning from spawn is off the truth.
    last_odom, last_truth = planar(odom[-1]["pose"]["pose"]), planar(truth[-1]["pose"]["pose"])
    dead_reckoned = compose(world.start, last_odom)
    assert math.hypot(dead_reckoned.x - last_truth.x, dead_reckoned.y - last_truth.y) > 0.02


def test_without_localization_tf_carries_odom_to_base_link_only() -> None:
    rig = robot_rig("maze")
    assert rig.robot.localization == "none" and rig.robot.sensors == ROBOT_SENSORS
    frames = received(rig, 3, ("/tf",))
    assert [[(t["header"]["frame_id"], t["child_frame_id"]) for t in f["msg"]["transforms"]]
            for f in frames] == [[("odom", "base_link"), ("base_link", "left_wheel"),
                                  ("base_link", "right_wheel")]] * 3


def test_a_flag_overrides_the_world_either_way(noisy_world: Path) -> None:
    perfect = VirtualRobot(Simulation(load_world("maze")), localization="perfect")
    assert perfect.sensors == robot_sensors("perfect") != ROBOT_SENSORS
    topics = [[len(msg["transforms"]) for spec, msg in perfect.step() if spec.name == "/tf"]]
    assert topics == [[4]]  # map -> odom -> base_link, and the two wheels
    off = VirtualRobot(Simulation(load_world(noisy_world)), localization="none")
    assert [len(msg["transforms"]) for spec, msg in off.step() if spec.name == "/tf"] == [3]
    with pytest.raises(ConfigError, match="localization: must be one of none, perfect"):
        VirtualRobot(Simulation(load_world("maze")), localization="amcl")
