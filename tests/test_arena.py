"""An arena: ``websim serve --class ROSTER --arena``, every student's robot in one world.

A real server, real roslibpy clients, each with its robot's token at ``/robots/NAME``: the
robots the world file places start there, the others where there is room; each student reads
the others in its LiDAR at the distance worked by hand and on ``/world_robots``; a robot that
drives into another stops at contact; a reset puts it back at its spawn; one student cannot
drive another's robot; the instructor's root view sees every robot.
"""

from __future__ import annotations

import json
import math
import threading
import urllib.request
from collections.abc import Iterator
from typing import Any

import pytest
import roslibpy

from physics import RobotParams
from physics.robot import CONTACT_SKIN_M

from server_process import ADMIN_TOKEN, ServerProcess, start_arena, wait_for

RADIUS_M = RobotParams().footprint_radius_m
ROBOTS = """\
robots:
  - {name: alice, start: [-1.0, 0.0, 0.0]}
  - {name: bob, start: [1.0, 0.0, 3.141592653589793], params: {footprint_radius_m: 0.15}}
"""
BOB_RADIUS_M = 0.15
TWIST = {"linear": {"x": 0.5, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


@pytest.fixture(scope="module")
def arena(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[ServerProcess,
                                                                      dict[str, str]]]:
    server, links = start_arena(tmp_path_factory.mktemp("arena"), ROBOTS,
                                ["alice", "bob", "carol"], ["--student-spawn", "1"])
    tokens = {row["name"]: row["token"] for row in links}
    yield server, tokens
    server.stop()


class Student:
    """A roslibpy client of one robot, with its token."""

    def __init__(self, server: ServerProcess, name: str, token: str | None) -> None:
        query = f"?token={token}" if token else ""
        self.ros = roslibpy.Ros(host=f"ws://127.0.0.1:{server.ws_port}/robots/{name}{query}")
        self.ros.run(timeout=10)
        self.latest: dict[str, Any] = {}
        self._lock = threading.Lock()

    def listen(self, topic: str, type_name: str) -> None:
        def keep(msg: dict[str, Any]) -> None:
            with self._lock:
                self.latest[topic] = msg

        roslibpy.Topic(self.ros, topic, type_name).subscribe(keep)

    def get(self, topic: str) -> Any:
        with self._lock:
            return self.latest.get(topic)

    def call(self, service: str, type_name: str, args: dict[str, Any] | None = None) -> Any:
        return roslibpy.Service(self.ros, service, type_name).call(
            roslibpy.ServiceRequest(args or {}), timeout=10)

    def close(self) -> None:
        self.ros.close()


def truth_xy(msg: dict[str, Any]) -> tuple[float, float]:
    position = msg["pose"]["pose"]["position"]
    return position["x"], position["y"]


def test_every_student_reaches_their_robot_and_the_robots_see_each_other(
        arena: tuple[ServerProcess, dict[str, str]]) -> None:
    server, tokens = arena
    alice, bob = Student(server, "alice", tokens["alice"]), Student(server, "bob", tokens["bob"])
    try:
        for student in (alice, bob):
            student.listen("/scan", "sensor_msgs/msg/LaserScan")
            student.listen("/ground_truth", "nav_msgs/msg/Odometry")
            student.listen("/world_robots", "visualization_msgs/msg/MarkerArray")
        wait_for(lambda: all(s.get(t) for s in (alice, bob)
                             for t in ("/scan", "/ground_truth", "/world_robots")),
                 20.0, "both robots' topics")
        assert truth_xy(alice.get("/ground_truth")) == pytest.approx((-1.0, 0.0), abs=1e-9)
        assert truth_xy(bob.get("/ground_truth")) == pytest.approx((1.0, 0.0), abs=1e-9)
        # Worked by hand: centres 2 m apart on the x axis, each laser at its centre, facing the
        # other: alice reads bob's 0.15 m footprint at 1.85 m, bob reads alice's at 1.89 m.
        assert alice.get("/scan")["ranges"][0] == pytest.approx(2.0 - BOB_RADIUS_M, abs=1e-9)
        assert bob.get("/scan")["ranges"][0] == pytest.approx(2.0 - RADIUS_M, abs=1e-9)
        markers = {m["text"]: m for m in alice.get("/world_robots")["markers"]}
        assert set(markers) == {"alice", "bob", "carol"}
        assert markers["bob"]["scale"]["x"] == pytest.approx(2 * BOB_RADIUS_M)
        carol = markers["carol"]["pose"]["position"]
        # carol is placed by nobody: at the world's start, which is free
        assert (carol["x"], carol["y"]) == pytest.approx((0.0, -2.0), abs=1e-9)
        assert markers["alice"]["header"]["frame_id"] == "map"
    finally:
        alice.close()
        bob.close()


def test_a_robot_driving_into_another_stops_at_contact_and_a_reset_brings_it_back(
        arena: tuple[ServerProcess, dict[str, str]]) -> None:
    server, tokens = arena
    alice = Student(server, "alice", tokens["alice"])
    intruder = Student(server, "alice", tokens["bob"])  # bob's token on alice's robot
    try:
        alice.listen("/ground_truth", "nav_msgs/msg/Odometry")
        wait_for(lambda: alice.get("/ground_truth"), 20.0, "alice's ground truth")
        refused = roslibpy.Topic(intruder.ros, "/cmd_vel", "geometry_msgs/msg/Twist")
        refused.publish(roslibpy.Message(TWIST))
        cmd_vel = roslibpy.Topic(alice.ros, "/cmd_vel", "geometry_msgs/msg/Twist")
        contact_x = 1.0 - BOB_RADIUS_M - RADIUS_M - CONTACT_SKIN_M

        def stopped_at_bob() -> bool:
            cmd_vel.publish(roslibpy.Message(TWIST))  # within the command watchdog
            x, _ = truth_xy(alice.get("/ground_truth"))
            return abs(x - contact_x) < 1e-6

        wait_for(stopped_at_bob, 20.0, "alice to stop at bob", interval_s=0.1)
        status = alice.call("/websim/status", "websim/srv/RobotStatus")
        assert status["collisions"] >= 1
        alice.call("/reset_simulation", "std_srvs/srv/Empty")
        wait_for(lambda: truth_xy(alice.get("/ground_truth")) == pytest.approx(
            (-1.0, 0.0), abs=1e-9), 10.0, "alice back at her spawn")
    finally:
        alice.close()
        intruder.close()


def test_the_instructor_sees_every_robot_of_the_arena(
        arena: tuple[ServerProcess, dict[str, str]]) -> None:
    server, _ = arena
    ros = roslibpy.Ros(host=f"ws://127.0.0.1:{server.ws_port}/?token={ADMIN_TOKEN}")
    ros.run(timeout=10)
    seen: dict[str, Any] = {}
    try:
        for name in ("alice", "bob", "carol"):
            roslibpy.Topic(ros, f"/{name}/ground_truth", "nav_msgs/msg/Odometry").subscribe(
                lambda msg, name=name: seen.setdefault(name, msg))
        wait_for(lambda: len(seen) == 3, 20.0, "every robot's ground truth")
    finally:
        ros.close()
    health = server.health()
    robots = health["robots"]
    assert set(robots) == {"alice", "bob", "carol"}
    assert all(robot["world"] == "arena" for robot in robots.values())
    positions = [truth_xy(msg) for msg in seen.values()]
    for i, a in enumerate(positions):
        for b in positions[i + 1:]:
            assert math.dist(a, b) >= 2 * RADIUS_M, "no two footprints overlap"


SRV = "simulation_interfaces/srv/"
OK, OPERATION_FAILED = 1, 4


def spawn_args(name: str, x: float, y: float) -> dict[str, Any]:
    return {"name": name, "uri": "websim://robot",
            "initial_pose": {"header": {"frame_id": "map"},
                             "pose": {"position": {"x": x, "y": y, "z": 0.0},
                                      "orientation": {"x": 0.0, "y": 0.0, "z": 0.0,
                                                      "w": 1.0}}}}


def test_the_arena_spawns_and_deletes_robots_within_each_callers_rights(
        arena: tuple[ServerProcess, dict[str, str]]) -> None:
    server, tokens = arena
    teacher = Student(server, "alice", ADMIN_TOKEN)
    carol = Student(server, "carol", tokens["carol"])
    try:
        features = teacher.call("/get_simulator_features", SRV + "GetSimulatorFeatures")
        assert features["features"]["spawn_formats"] == ["websim"]  # the uri scheme
        spawned = teacher.call("/spawn_entity", SRV + "SpawnEntity",
                               spawn_args("dave", 2.0, 2.0))
        assert spawned["result"]["result"] == OK, spawned
        entities = teacher.call("/get_entities", SRV + "GetEntities", {"filters": {}})
        assert set(entities["entities"]) == {"alice", "bob", "carol", "dave"}
        state = teacher.call("/get_entity_state", SRV + "GetEntityState", {"entity": "dave"})
        assert state["state"]["pose"]["position"]["x"] == pytest.approx(2.0)
        # dave is a robot of the class: its own page and bridge, its name on /world_robots
        dave = Student(server, "dave", None)
        dave.listen("/world_robots", "visualization_msgs/msg/MarkerArray")
        wait_for(lambda: dave.get("/world_robots"), 20.0, "dave's /world_robots")
        assert "dave" in {m["text"] for m in dave.get("/world_robots")["markers"]}
        dave.close()
        # a student: one robot of their own (--student-spawn 1), where there is room
        blocked = carol.call("/spawn_entity", SRV + "SpawnEntity", spawn_args("erin", 2.05, 2))
        assert blocked["result"]["result"] != OK, "dave stands there"
        mine = carol.call("/spawn_entity", SRV + "SpawnEntity", spawn_args("erin", -2.0, 2.0))
        assert mine["result"]["result"] == OK, mine
        second = carol.call("/spawn_entity", SRV + "SpawnEntity", spawn_args("finn", -2, -1))
        assert second["result"]["result"] == OPERATION_FAILED
        assert "--student-spawn" in second["result"]["error_message"]
        theirs = carol.call("/delete_entity", SRV + "DeleteEntity", {"entity": "dave"})
        assert theirs["result"]["result"] == OPERATION_FAILED, "dave is the instructor's"
        paused = carol.call("/set_simulation_state", SRV + "SetSimulationState",
                            {"state": {"state": 2}})
        assert paused["result"]["result"] == OPERATION_FAILED, "the arena is everyone's"
        assert carol.call("/delete_entity", SRV + "DeleteEntity",
                          {"entity": "erin"})["result"]["result"] == OK
        assert teacher.call("/delete_entity", SRV + "DeleteEntity",
                            {"entity": "dave"})["result"]["result"] == OK
        entities = teacher.call("/get_entities", SRV + "GetEntities", {"filters": {}})
        assert set(entities["entities"]) == {"alice", "bob", "carol"}
    finally:
        teacher.close()
        carol.close()


def test_a_spawned_robot_is_no_student_in_the_instructors_submissions(
        arena: tuple[ServerProcess, dict[str, str]]) -> None:
    """The Code panel's overview lists the class's students, not the robots spawned into it."""
    server, _ = arena
    teacher = Student(server, "alice", ADMIN_TOKEN)
    try:
        spawned = teacher.call("/spawn_entity", SRV + "SpawnEntity",
                               spawn_args("gina", 2.0, -1.0))
        assert spawned["result"]["result"] == OK, spawned
        request = urllib.request.Request(f"{server.http_url}/class/submissions.json",
                                         headers={"Authorization": f"Bearer {ADMIN_TOKEN}"})
        with urllib.request.urlopen(request, timeout=30) as response:
            overview = json.load(response)
        assert [student["name"] for student in overview["students"]] == \
            ["alice", "bob", "carol"]
        assert teacher.call("/delete_entity", SRV + "DeleteEntity",
                            {"entity": "gina"})["result"]["result"] == OK
    finally:
        teacher.close()
