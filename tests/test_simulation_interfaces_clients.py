"""simulation_interfaces and turtlesim's names with real clients against ``websim serve``.

roslibpy (Python) and roslibjs 1.4.1 (Node, ``tests/node/simulation.js``) call the services
as course code does; in a class, a student's call on another student's robot is refused and
on their own robot it is answered. The in-process tests (``test_simulation_interfaces.py``)
cover every result code; these check the wire, the typing and the rights end to end.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import roslibpy

from server_process import ServerProcess, start_server, wait_for

NODE = shutil.which("node")
NODE_PROGRAM = Path(__file__).parent / "node" / "simulation.js"
OK, FEATURE_UNSUPPORTED, OPERATION_FAILED = 1, 0, 4
PAUSED, PLAYING = 2, 1
SRV = "simulation_interfaces/srv/"


@pytest.fixture(scope="module")
def server() -> Iterator[ServerProcess]:
    running = start_server()
    yield running
    running.stop()


def call(ros: roslibpy.Ros, name: str, type_name: str, args: dict[str, Any],
         timeout_s: float = 10.0) -> dict[str, Any]:
    return dict(roslibpy.Service(ros, name, type_name).call(roslibpy.ServiceRequest(args),
                                                            timeout=timeout_s))


def connected(url: str) -> roslibpy.Ros:
    ros = roslibpy.Ros(host=url)
    ros.run(timeout=10)
    return ros


def test_roslibpy_teleports_pauses_and_steps(server: ServerProcess) -> None:
    ros, admin = connected(server.ws_url), connected(server.admin_ws_url)
    try:
        features = call(ros, "/get_simulator_features", SRV + "GetSimulatorFeatures", {})
        assert 11 in features["features"]["features"] and 0 not in features["features"][
            "features"]
        answer = call(ros, "/set_entity_state", SRV + "SetEntityState", {
            "entity": "robot", "state": {"pose": {"position": {"x": 1.0, "y": 0.5}}}})
        assert answer["result"]["result"] == OK
        state = call(ros, "/get_entity_state", SRV + "GetEntityState", {"entity": "robot"})
        assert state["state"]["pose"]["position"]["x"] == pytest.approx(1.0)
        # Pausing needs the admin token; the anonymous client gets the reason.
        refused = call(ros, "/set_simulation_state", SRV + "SetSimulationState",
                       {"state": {"state": PAUSED}})
        assert refused["result"]["result"] == OPERATION_FAILED
        assert "admin" in refused["result"]["error_message"]
        assert call(admin, "/set_simulation_state", SRV + "SetSimulationState",
                    {"state": {"state": PAUSED}})["result"]["result"] == OK
        odoms: list[dict[str, Any]] = []
        topic = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry", queue_length=50)
        topic.subscribe(odoms.append)
        # A held robot publishes nothing; ten steps publish ten /odom, then nothing.
        stepped = call(admin, "/step_simulation", SRV + "StepSimulation", {"steps": 10})
        assert stepped["result"]["result"] == OK
        wait_for(lambda: len(odoms) >= 10, what="the ten steps' /odom")
        assert len(odoms) == 10  # the answer came after the tenth step's messages
        assert call(admin, "/set_simulation_state", SRV + "SetSimulationState",
                    {"state": {"state": PLAYING}})["result"]["result"] == OK
        topic.unsubscribe()
        spawn = call(ros, "/spawn_entity", SRV + "SpawnEntity",
                     {"name": "second", "uri": "websim://robot"})
        assert spawn["result"]["result"] == FEATURE_UNSUPPORTED
        with pytest.raises(roslibpy.core.ServiceException, match="arena"):
            call(ros, "/kill", "turtlesim/srv/Kill", {"name": "robot"})
        assert call(ros, "/reset", "std_srvs/srv/Empty", {}) == {}
        assert roslibpy.Service(ros, "/spawn_entity", "x").ros.get_service_type(
            "/spawn_entity") == SRV + "SpawnEntity"
    finally:
        ros.close()
        admin.close()


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_roslibjs_calls_them(server: ServerProcess) -> None:
    assert NODE is not None
    result = subprocess.run([NODE, str(NODE_PROGRAM), server.ws_url], capture_output=True,
                            text=True, timeout=30, check=False)
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["features"]["ok"] and 33 in out["features"]["values"]["features"]["features"]
    assert out["set"] == {"ok": True, "values": {"result": {"result": OK, "error_message": ""}}}
    position = out["state"]["values"]["state"]["pose"]["position"]
    assert (position["x"], position["y"]) == pytest.approx((1.25, -0.5))
    assert out["teleport"] == {"ok": True, "values": {}}
    orientation = out["stateAfterTeleport"]["values"]["state"]["pose"]["orientation"]
    assert 2 * math.atan2(orientation["z"], orientation["w"]) == pytest.approx(1.5, abs=1e-6)
    assert out["spawn"]["values"]["result"]["result"] == FEATURE_UNSUPPORTED
    assert out["turtleSpawn"]["ok"] is False and "arena" in out["turtleSpawn"]["reason"]


@pytest.fixture(scope="module")
def classroom(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[ServerProcess,
                                                                          dict[str, str]]]:
    folder = tmp_path_factory.mktemp("class")
    (folder / "roster.txt").write_text("alice\nbob\n")
    running = start_server(["--class", str(folder / "roster.txt"),
                            "--links", str(folder / "links.csv")])
    tokens = {row["name"]: row["token"] for row in csv.DictReader(
        (folder / "links.csv").open()) if row["name"] in ("alice", "bob")}
    yield running, tokens
    running.stop()


def test_a_students_call_on_another_students_robot_is_refused(
        classroom: tuple[ServerProcess, dict[str, str]]) -> None:
    server, tokens = classroom
    base = f"ws://127.0.0.1:{server.ws_port}/robots"
    alice_at_bob = connected(f"{base}/bob?token={tokens['alice']}")
    alice = connected(f"{base}/alice?token={tokens['alice']}")
    try:
        move = {"entity": "bob", "state": {"pose": {"position": {"x": 1.0}}}}
        refused = call(alice_at_bob, "/set_entity_state", SRV + "SetEntityState", move)
        assert refused["result"]["result"] == OPERATION_FAILED
        assert "token" in refused["result"]["error_message"]
        with pytest.raises(roslibpy.core.ServiceException, match="token"):
            call(alice_at_bob, "/bob/teleport_absolute", "turtlesim/srv/TeleportAbsolute",
                 {"x": 1.0, "y": 0.0, "theta": 0.0})
        paused = call(alice_at_bob, "/set_simulation_state", SRV + "SetSimulationState",
                      {"state": {"state": PAUSED}})
        assert paused["result"]["result"] == OPERATION_FAILED
        state = call(alice_at_bob, "/get_entity_state", SRV + "GetEntityState",
                     {"entity": "bob"})  # watching is anyone's
        assert state["state"]["pose"]["position"]["x"] == 0.0
        mine = call(alice, "/set_entity_state", SRV + "SetEntityState",
                    {"entity": "alice", "state": {"pose": {"position": {"x": 1.0}}}})
        assert mine["result"]["result"] == OK
        assert call(alice, "/alice/teleport_absolute", "turtlesim/srv/TeleportAbsolute",
                    {"x": -1.0, "y": 0.0, "theta": 0.0}) == {}
        assert call(alice, "/websim/reset_simulation", SRV + "ResetSimulation",
                    {"scope": 2})["result"]["result"] == OK
    finally:
        alice_at_bob.close()
        alice.close()
