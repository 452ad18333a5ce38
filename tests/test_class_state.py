"""A class's state survives a restart (issue 20, section 9).

The class keeps its secret, enrolments and each robot's parameters, pause and pose in one
SQLite file (``--state``); a restart of the same command brings every robot back and every
token the same; a file of another class, of a newer schema, locked or corrupt is refused
with the reason; ``--fresh`` starts over. The slow test kills a real server with SIGKILL while
20 robots are driven.
"""

from __future__ import annotations

import asyncio
import csv
import json
import math
import signal
import sqlite3
import time
from pathlib import Path
from typing import Any

import pytest
import websockets

from classroom.registry import Classroom, Student
from classroom.state import (
    SAVE_INTERVAL_S,
    SCHEMA_VERSION,
    ClassState,
    class_identity,
    default_state_path,
)
from physics import ConfigError, Simulation, load_world
from ros_nodes.virtual_robot_core import VirtualRobot
from websim import cli

from server_process import ADMIN_TOKEN, start_server, stop_process, wait_for

IDENTITY = "roster:/class/roster.txt"


def make_robot(student: Student) -> VirtualRobot:
    return VirtualRobot(Simulation(load_world("empty")))


def test_a_classroom_comes_back_as_it_was_with_the_same_tokens(tmp_path: Path) -> None:
    path = tmp_path / "state.sqlite"
    roster = [Student("alice"), Student("bob")]
    state = ClassState(path, IDENTITY)
    before = Classroom(roster, make_robot, open_class=True, idle_pause_s=None, state=state)
    assert before.get("dave") is not None and before.claim("dave")
    assert before.get("erin") is not None  # enrolled, not yet handed to anyone
    alice = dict(before)["alice"]
    alice.robot.parameters.set_many({"mode": "dynamic", "mass_kg": 2.5})
    alice.robot.sim.command(0.3, 0.4)
    alice.robot.sim.step(40)
    alice.held = True
    pose, odometry = alice.robot.sim.ground_truth(), alice.robot.sim.odometry()
    tokens = {name: before.token(name) for name in ("alice", "bob", "dave", "erin")}
    before.save()
    state.close()

    state = ClassState(path, IDENTITY)
    assert state.restored
    after = Classroom(roster, make_robot, open_class=True, idle_pause_s=None, state=state)
    assert {name: after.token(name) for name in tokens} == tokens
    assert set(dict(after)) == {"alice", "bob", "dave", "erin"}
    assert after.unclaimed == {"erin"} and not after.claim("dave")
    restored = dict(after)["alice"]
    assert restored.robot.sim.mode == "dynamic" and restored.robot.sim.params.mass_kg == 2.5
    assert restored.held
    again = restored.robot.sim.ground_truth()
    assert (again.x, again.y, again.theta) == pytest.approx((pose.x, pose.y, pose.theta))
    odom = restored.robot.sim.odometry()
    assert (odom.x, odom.y, odom.theta) == pytest.approx((odometry.x, odometry.y,
                                                          odometry.theta))
    state.close()


def test_a_worker_comes_back_with_the_robots_it_had_made(tmp_path: Path) -> None:
    """A worker (lazy: it makes a robot when nginx first routes it there) restarted with
    robots in its state file: it crashed ('dictionary changed size during iteration')."""
    path = tmp_path / "state.sqlite"
    roster = [Student("alice"), Student("bob"), Student("carol")]
    state = ClassState(path, IDENTITY)
    before = Classroom(roster, make_robot, idle_pause_s=None, lazy=True, state=state)
    for name in ("alice", "bob"):
        host = before.get(name)
        assert host is not None
        host.robot.sim.command(0.2, 0.0)
        host.robot.sim.step(20)
    before.save()
    state.close()

    state = ClassState(path, IDENTITY)
    after = Classroom(roster, make_robot, idle_pause_s=None, lazy=True, state=state)
    assert set(dict(after)) == {"alice", "bob"}, "carol was never made: she is not now"
    assert dict(after)["bob"].robot.sim.ground_truth().x == pytest.approx(0.2, abs=0.02)
    state.close()


def test_another_class_a_newer_schema_a_locked_or_corrupt_file_are_refused(
        tmp_path: Path) -> None:
    path = tmp_path / "state.sqlite"
    ClassState(path, IDENTITY).close()
    with pytest.raises(ConfigError, match="this file holds another class"):
        ClassState(path, "robots:20")

    held = ClassState(path, IDENTITY)
    with pytest.raises(ConfigError, match="another websim serve is using this class's state"):
        ClassState(path, IDENTITY)
    held.close()

    db = sqlite3.connect(path)
    with db:
        db.execute("UPDATE meta SET value = ? WHERE key = 'schema'", (str(SCHEMA_VERSION + 1),))
    db.close()
    with pytest.raises(ConfigError, match="written by a newer websim"):
        ClassState(path, IDENTITY)

    corrupt = tmp_path / "corrupt.sqlite"
    corrupt.write_bytes(b"this is no database" * 100)
    with pytest.raises(ConfigError, match="corrupt"):
        ClassState(corrupt, IDENTITY)
    assert corrupt.read_bytes() == b"this is no database" * 100, "nothing silently lost"

    fresh = ClassState(path, IDENTITY, fresh=True)  # deliberately starts over
    assert not fresh.restored
    fresh.close()


def test_serve_names_the_problem_with_a_state_file(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    state = tmp_path / "state.sqlite"
    ClassState(state, class_identity("7")).close()
    assert cli.main(["serve", "--class", "3", "--state", str(state),
                     "--admin-token", ADMIN_TOKEN]) == 2
    assert "this file holds another class (robots:7, not robots:3)" in capsys.readouterr().err


def test_workers_of_two_rosters_of_one_name_keep_two_files(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The README's scale-out recipe run in a second folder (its roster.txt, the same worker
    ports) is another class: before, its worker found the first class's file in
    ``$XDG_DATA_HOME/websim`` (roster-worker-9091.sqlite) and refused to start."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    rosters = []
    for folder in ("spring", "autumn"):
        (tmp_path / folder).mkdir()
        rosters.append(tmp_path / folder / "roster.txt")
    paths = [default_state_path(str(roster), 9091) for roster in rosters]
    assert paths[0] != paths[1]
    assert all(path.parent == tmp_path / "data" / "websim" for path in paths)
    assert all(path.name.startswith("roster-") and path.name.endswith("-worker-9091.sqlite")
               for path in paths)
    assert default_state_path(str(rosters[0]), 9092) != paths[0], "one file per worker"
    assert default_state_path(str(rosters[0]), 9091) == paths[0], "a restart finds it"
    secrets = []
    for roster, path in zip(rosters, paths, strict=True):  # each class opens its own
        state = ClassState(path, class_identity(str(roster)))
        secrets.append(state.secret)
        state.close()
    again = ClassState(paths[0], class_identity(str(rosters[0])))
    assert again.secret == secrets[0] != secrets[1], "the first class's own secret, kept"
    again.close()


# ---- a real server killed with SIGKILL while 20 robots are driven ------------------------------

ROBOTS = 20


async def drive_all(ws_port: int, tokens: dict[str, str], seconds: float) -> None:
    """Each robot driven by its owner at its own speed, at 10 Hz, for ``seconds``."""
    async def drive(index: int, name: str) -> None:
        url = f"ws://127.0.0.1:{ws_port}/robots/{name}?token={tokens[name]}"
        twist = {"linear": {"x": 0.05 + 0.01 * index}, "angular": {"z": 0.2}}
        async with websockets.connect(url) as ws:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                await ws.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": twist}))
                await asyncio.sleep(0.1)

    # every driver ends before the first failure is raised: none is left behind to be
    # destroyed with its loop (a server killed mid-drive fails them all)
    ended = await asyncio.gather(*(drive(index, name) for index, name in enumerate(tokens)),
                                 return_exceptions=True)
    failures = [result for result in ended if isinstance(result, BaseException)]
    if failures:
        raise failures[0]


async def poses(ws_port: int, names: list[str]) -> dict[str, tuple[float, float, float]]:
    """Each robot's true pose (x, y, yaw), watched without a token."""
    async def one(name: str) -> tuple[float, float, float]:
        async with websockets.connect(f"ws://127.0.0.1:{ws_port}/robots/{name}") as ws:
            await ws.send(json.dumps({"op": "subscribe", "topic": "/ground_truth"}))
            while True:
                message: dict[str, Any] = json.loads(await asyncio.wait_for(ws.recv(), 5))
                if message.get("topic") == "/ground_truth":
                    pose = message["msg"]["pose"]["pose"]
                    q = pose["orientation"]
                    return (pose["position"]["x"], pose["position"]["y"],
                            2.0 * math.atan2(q["z"], q["w"]))

    found = await asyncio.gather(*(one(name) for name in names))
    return dict(zip(names, found, strict=True))


@pytest.mark.slow
def test_a_class_killed_with_sigkill_comes_back_within_the_save_interval(
        tmp_path: Path) -> None:
    state, links = tmp_path / "class.sqlite", tmp_path / "links.csv"
    command = ["--class", str(ROBOTS), "--state", str(state), "--links", str(links),
               "--idle-pause", "3600"]
    server = start_server(command)
    try:  # from here on the server goes whatever fails
        tokens = {row["name"]: row["token"] for row in csv.DictReader(links.open())}
        assert len(tokens) == ROBOTS
        asyncio.run(drive_all(server.ws_port, tokens, 4.0))
        time.sleep(SAVE_INTERVAL_S + 0.5)  # stopped robots: a save has seen them still
        before = asyncio.run(poses(server.ws_port, list(tokens)))
        # and drive again, killing the server mid-drive
        driving = asyncio.new_event_loop()
        task = driving.create_task(drive_all(server.ws_port, tokens, 30.0))
        driving.run_until_complete(asyncio.sleep(1.0 + SAVE_INTERVAL_S))
        stop_process(server.process, server.output, signal.SIGKILL)
        with pytest.raises((OSError, websockets.ConnectionClosed)):
            driving.run_until_complete(task)
        driving.close()
    finally:
        if server.process.poll() is None:
            stop_process(server.process, server.output, signal.SIGKILL)
    assert server.process.returncode == -signal.SIGKILL

    links.unlink()
    again = start_server(command, ws_port=server.ws_port, http_port=server.http_port)
    try:
        assert {row["name"]: row["token"] for row in csv.DictReader(links.open())} == tokens
        after = asyncio.run(poses(again.ws_port, list(tokens)))
        top_speed = 0.05 + 0.01 * (ROBOTS - 1)
        for name in tokens:
            moved = math.dist(before[name][:2], after[name][:2])
            assert moved > 0.0, f"{name}: the drive before the kill was saved"
            # driven at most 1 s + the save interval + a tick before the kill, at most this far
            assert moved <= top_speed * (1.0 + 2 * SAVE_INTERVAL_S) + 0.05, name
        wait_for(lambda: again.health()["robot_count"] == ROBOTS, 5.0, "every robot back")
    finally:
        again.stop()
    assert f"state:     {state}: restored, saved " in "".join(again.output)
    assert f"{ROBOTS} robots as they were, the same tokens" in "".join(again.output)


# ---- a class's state belongs to one class ----------------------------------------------------


def test_two_classes_of_n_robots_from_two_folders_or_ports_keep_two_files(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two sections run as --class 40 by one account shared one file: the class secret (last
    week's links drove this week's robots) and every enrolment ever made."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monday, tuesday = tmp_path / "monday", tmp_path / "tuesday"
    monday.mkdir()
    tuesday.mkdir()
    one = default_state_path("40", ws_port=9090, folder=monday)
    assert one == default_state_path("40", ws_port=9090, folder=monday), "a restart finds it"
    assert one != default_state_path("40", ws_port=9090, folder=tuesday)
    assert one != default_state_path("40", ws_port=9190, folder=monday)
    assert one != default_state_path("41", ws_port=9090, folder=monday)
    assert one.parent == tmp_path / "data" / "websim" and one.name.startswith("class-40-")


def test_a_default_file_saved_another_day_starts_anew_unless_named(tmp_path: Path) -> None:
    path = tmp_path / "state.sqlite"
    state = ClassState(path, "robots:4", now_s=1_000_000.0)
    secret = state.secret
    state.save_robots({}, now_s=1_000_000.0)
    state.close()
    hours = 3600.0
    state = ClassState(path, "robots:4", stale_after_s=12 * hours, now_s=1_000_000 + 11 * hours)
    assert state.secret == secret and state.stale_s is None, "the same day: a restart"
    state.save_robots({}, now_s=1_000_000 + 11 * hours)
    state.close()
    state = ClassState(path, "robots:4", stale_after_s=12 * hours, now_s=1_000_000 + 40 * hours)
    assert state.secret != secret and state.stale_s == pytest.approx(29 * hours)
    state.close()
    named = ClassState(path, "robots:4", now_s=1_000_000 + 400 * hours)
    assert named.stale_s is None, "a file the instructor names is kept however old"
    named.close()


def test_an_open_class_forgets_enrolments_nobody_used_for_the_enrolment_time(
        tmp_path: Path) -> None:
    """Every open-class enrolment ever made came back at each start (198 robots seen)."""
    path = tmp_path / "state.sqlite"
    hours = 3600.0
    state = ClassState(path, IDENTITY)
    classroom = Classroom([Student("alice")], make_robot, open_class=True, idle_pause_s=None,
                          state=state)
    for name in ("dave", "erin", "fay"):
        assert classroom.get(name) is not None
    classroom.save()
    state.enrol("dave", claimed=True, now_s=time.time() - 13 * hours)  # last week's
    state.enrol("erin", claimed=True, now_s=time.time() - 11 * hours)
    state.close()

    state = ClassState(path, IDENTITY)
    again = Classroom([Student("alice")], make_robot, open_class=True, idle_pause_s=None,
                      state=state, enrolment_hours=12.0)
    assert again.forgotten == ["dave"]
    assert set(dict(again)) == {"alice", "erin", "fay"}
    assert "dave" not in state.enrolments() and "dave" not in state.robots()
    assert again.get("dave") is not None and "dave" in again.unclaimed, "the name enrols anew"
    state.close()


def test_a_schema_1_file_is_brought_up_and_keeps_its_enrolments(tmp_path: Path) -> None:
    path = tmp_path / "old.sqlite"
    db = sqlite3.connect(path)
    with db:
        db.executescript("CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);"
                         "CREATE TABLE enrolments (name TEXT PRIMARY KEY, "
                         "claimed INTEGER NOT NULL DEFAULT 0);"
                         "CREATE TABLE robots (name TEXT PRIMARY KEY, state TEXT NOT NULL);")
        db.executemany("INSERT INTO meta VALUES (?, ?)", [("schema", "1"), ("class", IDENTITY),
                                                          ("secret", "s" * 43)])
        db.execute("INSERT INTO enrolments VALUES ('dave', 1)")
    db.close()
    state = ClassState(path, IDENTITY)
    assert state.secret == "s" * 43 and state.enrolments() == {"dave": True}
    assert state.forget_enrolments(3600.0) == [], "kept one enrolment time from now"
    state.close()
    db = sqlite3.connect(path)
    assert db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone() == (
        str(SCHEMA_VERSION),)
    db.close()


def serve_without_a_token(args: list[str]) -> tuple[str, str]:
    """Start and stop ``websim serve ARGS`` (no --admin-token); its dashboard token, banner."""
    server = start_server(args, admin_token=None)
    server.stop()
    output = "".join(server.output)
    dashboard = next(line for line in output.splitlines() if "dashboard:" in line)
    return dashboard.split("token=")[1].strip(), output


def test_the_instructors_token_is_kept_with_the_class_state(tmp_path: Path) -> None:
    """It changed at every restart unless given, breaking an open dashboard."""
    state = tmp_path / "class.sqlite"
    first, output = serve_without_a_token(["--class", "2", "--state", str(state)])
    assert f"state:     {state}: new" in output
    second, output = serve_without_a_token(["--class", "2", "--state", str(state)])
    assert second == first
    assert "the instructor's token" in next(line for line in output.splitlines()
                                        if line.startswith("  state:"))
    third, _ = serve_without_a_token(["--class", "2", "--state", str(state), "--fresh"])
    assert third != first, "--fresh: a new token too"
    given, _ = serve_without_a_token(["--class", "2", "--state", str(state), "--admin-token",
                                      ADMIN_TOKEN])
    assert given == ADMIN_TOKEN
    kept, _ = serve_without_a_token(["--class", "2", "--state", str(state)])
    assert kept == ADMIN_TOKEN, "a token given once is the class's from then on"
