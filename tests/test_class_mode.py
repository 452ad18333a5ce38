"""Class mode: a robot per student on one ``websim serve --class``, each isolated, by name.

Against a real server process with real WebSocket and HTTP clients: what one robot's clients
publish, latch or reset never reaches another robot; unknown names are refused with a reason;
each robot's token is admin there only; the instructor's everywhere; pages and their
``config.json`` are per robot; idle robots pause and resume with their state.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import json
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import websockets
from robot_rig import robot_rig

from classroom.registry import (
    Classroom,
    Student,
    derived_token,
    numbered_roster,
    read_roster,
)
from physics import ConfigError, Simulation, load_world
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.session import Session
from websim.sites import instructor_links_path

from server_process import ADMIN_TOKEN, ServerProcess, start_server, wait_for

TWIST = {"linear": {"x": 0.3}, "angular": {"z": 0.0}}
CAROL_TOKEN = "Carols-Own-Token-2026"
TOKENS: dict[str, str] = {}
"""The class's robot tokens, from its links file (the ``server`` fixture's)."""


@pytest.fixture(scope="module")
def roster(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("class") / "roster.txt"
    path.write_text("# a class\nalice\nbob, maze\ncarol,,Carols-Own-Token-2026\n")
    return path


@pytest.fixture(scope="module")
def links(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("links") / "links.csv"


@pytest.fixture(scope="module")
def server(roster: Path, links: Path) -> Iterator[ServerProcess]:
    running = start_server(["--class", str(roster), "--links", str(links)])
    TOKENS.update({row["name"]: row["token"] for row in csv.DictReader(links.open())})
    yield running
    running.stop()


def robot_url(server: ServerProcess, name: str, token: str | None = None) -> str:
    return f"ws://127.0.0.1:{server.ws_port}/robots/{name}" + (f"?token={token}"
                                                                if token else "")


def owner_url(server: ServerProcess, name: str) -> str:
    """Robot ``name``'s URL with its token: its owner's (who may drive it)."""
    return robot_url(server, name, TOKENS[name])


async def first(ws: Any, topic: str) -> dict[str, Any]:
    while True:
        message = json.loads(await asyncio.wait_for(ws.recv(), 5))
        if message.get("topic") == topic:
            return dict(message["msg"])


async def ground_truth_x(url: str) -> float:
    async with websockets.connect(url) as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": "/ground_truth"}))
        return float((await first(ws, "/ground_truth"))["pose"]["pose"]["position"]["x"])


async def call(url: str, service: str, args: dict[str, Any]) -> dict[str, Any]:
    async with websockets.connect(url) as ws:
        await ws.send(json.dumps({"op": "call_service", "service": service, "id": "c",
                                  "args": args}))
        while True:
            reply = json.loads(await asyncio.wait_for(ws.recv(), 5))
            if reply.get("op") == "service_response":
                return dict(reply)


def set_mass(url: str, mass_kg: float) -> dict[str, Any]:
    return asyncio.run(call(url, "/virtual_robot/set_parameters", {"parameters": [
        {"name": "mass_kg", "value": {"type": 3, "double_value": mass_kg}}]}))


# ---- rosters -----------------------------------------------------------------------------

def test_roster_lines_give_names_worlds_and_tokens(roster: Path) -> None:
    assert read_roster(roster) == [Student("alice"), Student("bob", "maze"),
                                   Student("carol", None, CAROL_TOKEN)]
    assert [s.name for s in numbered_roster(3)] == ["robot01", "robot02", "robot03"]
    assert numbered_roster(120)[-1].name == "robot120"


@pytest.mark.parametrize("text, reason", [
    ("alice\nAlice\n", "roster.txt:2: 'Alice' is not a robot name"),
    ("alice\nalice\n", "roster.txt:2: 'alice' is on the roster twice"),
    ("a,b,c,d\n", "roster.txt:1: expected name[,world[,token]], got 4 fields"),
    ("x" * 33 + "\n", "is not a robot name (1 to 32 of a-z, 0-9, _ and -)"),
    ("# nobody\n\n", "roster.txt: the roster names no student"),
    ("alice\nbob,maz\n", "roster.txt:2: the world of 'bob': maz: cannot read world file"),
])
def test_bad_rosters_name_the_file_and_line(tmp_path: Path, text: str, reason: str) -> None:
    path = tmp_path / "roster.txt"
    path.write_text(text)
    with pytest.raises(ConfigError) as error:
        read_roster(path)
    assert reason in str(error.value)


def test_a_bad_world_on_the_roster_stops_the_server_with_the_reason(tmp_path: Path) -> None:
    path = tmp_path / "roster.txt"
    path.write_text("alice\nbob,no_such_world\n")
    result = subprocess.run([sys.executable, "-m", "websim.cli", "serve", "--class", str(path)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert f"{path}:2: the world of 'bob': no_such_world" in result.stderr


# ---- isolation ---------------------------------------------------------------------------

def test_driving_one_robot_leaves_the_others_where_they_are(server: ServerProcess) -> None:
    async def drive() -> tuple[float, float]:
        async with websockets.connect(owner_url(server, "alice")) as alice:
            await alice.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST}))
            await asyncio.sleep(1.0)
            await alice.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {}}))
        return (await ground_truth_x(robot_url(server, "alice")),
                await ground_truth_x(robot_url(server, "carol")))

    alice_x, carol_x = asyncio.run(drive())
    assert alice_x > 0.2
    assert carol_x == 0.0


def test_topics_latches_and_resets_stay_on_their_robot(server: ServerProcess) -> None:
    async def scenario() -> tuple[list[Any], dict[str, Any], dict[str, Any]]:
        async with websockets.connect(owner_url(server, "alice")) as alice, \
                websockets.connect(owner_url(server, "carol")) as carol:
            for ws in (alice, carol):
                await ws.send(json.dumps({"op": "subscribe", "topic": "/chat"}))
            await alice.send(json.dumps({"op": "advertise", "topic": "/chat",
                                         "type": "std_msgs/String"}))
            await alice.send(json.dumps({"op": "publish", "topic": "/chat", "latch": True,
                                         "msg": {"data": "alice only"}}))
            said = await first(alice, "/chat")
            heard: list[Any] = []
            with contextlib.suppress(TimeoutError):
                heard.append(await asyncio.wait_for(first(carol, "/chat"), 0.5))
            async with websockets.connect(robot_url(server, "carol")) as late:
                await late.send(json.dumps({"op": "subscribe", "topic": "/chat"}))
                with contextlib.suppress(TimeoutError):
                    heard.append(await asyncio.wait_for(first(late, "/chat"), 0.5))
            worlds = {}
            for name, ws in (("alice", alice), ("bob", None)):
                if ws is None:
                    async with websockets.connect(robot_url(server, name)) as other:
                        await other.send(json.dumps({"op": "subscribe", "topic": "/world"}))
                        worlds[name] = await first(other, "/world")
                else:
                    await ws.send(json.dumps({"op": "subscribe", "topic": "/world"}))
                    worlds[name] = await first(ws, "/world")
            return heard, said, worlds

    heard, said, worlds = asyncio.run(scenario())
    assert said == {"data": "alice only"}
    assert heard == [], "carol's clients heard alice's topic"
    assert worlds["alice"] != worlds["bob"], "bob's robot runs the maze of his roster line"


def test_reset_resets_only_the_callers_robot(server: ServerProcess) -> None:
    async def scenario() -> tuple[float, float]:
        for name in ("alice", "carol"):
            async with websockets.connect(owner_url(server, name)) as ws:
                await ws.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST}))
                await asyncio.sleep(0.5)
                await ws.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {}}))
        await call(owner_url(server, "carol"), "/reset_simulation", {})
        return (await ground_truth_x(robot_url(server, "alice")),
                await ground_truth_x(robot_url(server, "carol")))

    alice_x, carol_x = asyncio.run(scenario())
    assert alice_x > 0.1 and carol_x == 0.0


# ---- names and rights ----------------------------------------------------------------------

def test_unknown_names_and_the_root_are_refused_with_a_reason(server: ServerProcess) -> None:
    async def refused(url: str) -> tuple[int, str]:
        with pytest.raises(websockets.InvalidStatus) as error:
            async with websockets.connect(url):
                pass
        response = error.value.response
        return response.status_code, response.body.decode()

    status, body = asyncio.run(refused(robot_url(server, "mallory")))
    assert status == 404 and "no robot named 'mallory' in this class" in body
    status, body = asyncio.run(refused(server.ws_url))
    assert status == 404 and "connect to ws://HOST:PORT/robots/NAME" in body
    status, body = asyncio.run(refused(f"{server.ws_url}?token=Not-The-Instructors-1"))
    assert status == 403 and body.startswith("wrong instructor token")  # not a 404


def test_a_wrong_name_is_refused_with_what_is_wrong_and_never_a_classmates_name(
        server: ServerProcess) -> None:
    """A student who mistyped their robot's name got "404 Not Found" (roslibpy prints the
    status line); the names close to theirs are classmates': only the instructor's log
    names them."""
    async def refused(url: str) -> tuple[int, str, str]:
        with pytest.raises(websockets.InvalidStatus) as error:
            async with websockets.connect(url):
                pass
        response = error.value.response
        return response.status_code, response.reason_phrase, response.body.decode()

    for name, reason in (("carl", "no robot named 'carl' in this class"),
                         ("Alice", "'Alice' is not a robot name"),
                         ("", "this address names no robot: a robot is at /robots/NAME")):
        status, phrase, body = asyncio.run(refused(robot_url(server, name)))
        assert status == 404 and phrase.startswith(reason) and body.startswith(reason), phrase
        assert "your instructor's links give" in body
        page_status, page = get(f"{server.http_url}/robots/{name}/")
        assert page_status == 404 and reason in page, page
        for classmate in ("alice", "bob", "carol"):  # case matters: 'Alice' is what they typed
            assert classmate not in body and classmate not in page, (name, body, page)
        assert "Traceback" not in page
    status, page = get(f"{server.http_url}/robots")
    assert status == 404 and "this address names no robot" in page
    status, page = get(f"{server.http_url}/")  # was a robot page that could never connect
    assert status == 200 and "This server hosts a class" in page and "/robots/NAME/" in page


def test_each_robot_token_is_admin_on_its_robot_only(server: ServerProcess,
                                                    links: Path) -> None:
    rows = {row["name"]: row for row in csv.DictReader(links.open())}
    assert list(rows) == ["alice", "bob", "carol"]  # the handout: the robots only
    assert ADMIN_TOKEN not in links.read_text()
    private = dict(line.split("=", 1) for line in
                   instructor_links_path(links).read_text().splitlines()[1:])
    assert private["dashboard"].endswith(f":{server.http_port}/class?token={ADMIN_TOKEN}")
    assert private["token"] == ADMIN_TOKEN
    assert rows["carol"]["token"] == CAROL_TOKEN
    alice_token = rows["alice"]["token"]
    assert rows["alice"]["admin_page"].endswith(f"/robots/alice/admin?token={alice_token}")
    assert rows["alice"]["websocket"].endswith(f":{server.ws_port}/robots/alice")

    own = set_mass(robot_url(server, "alice", alice_token), 2.0)
    assert own["values"]["results"][0]["successful"] is True
    other = set_mass(robot_url(server, "bob", alice_token), 2.0)
    assert other["result"] is False and "needs admin rights" in other["values"]
    # the hint names the URL that works in a class (the root refuses students)
    assert "ws://HOST:PORT/robots/bob?token=TOKEN" in other["values"]
    for name in ("alice", "bob"):
        instructor = set_mass(robot_url(server, name, ADMIN_TOKEN), 1.2)
        assert instructor["values"]["results"][0]["successful"] is True


# ---- pages -------------------------------------------------------------------------------

def get(url: str) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(url, timeout=5) as response:
            return response.status, response.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, error.read().decode()


def test_each_robot_has_its_page_and_the_page_learns_its_bridge(server: ServerProcess) -> None:
    status, page = get(f"{server.http_url}/robots/bob/")
    assert status == 200 and "<html" in page.lower()
    status, config = get(f"{server.http_url}/robots/bob/config.json")
    assert status == 200
    assert json.loads(config)["ws"] == f"ws://127.0.0.1:{server.ws_port}/robots/bob"
    assert get(f"{server.http_url}/robots/bob/admin")[0] == 200
    assert get(f"{server.http_url}/robots/bob/js/main.js")[0] == 200
    robot = json.loads(get(f"{server.http_url}/robots/bob/robot.json")[1])
    assert robot["topics"]["cmd_vel"]["name"] == "/cmd_vel"
    status, body = get(f"{server.http_url}/robots/nobody/")
    assert status == 404 and "no robot named 'nobody'" in body
    status, body = get(f"{server.http_url}/robots/Bob/")  # wrongly cased: no name given away
    assert status == 404 and "'Bob' is not a robot name" in body and "bob" not in body
    with urllib.request.urlopen(f"{server.http_url}/robots/bob", timeout=5) as response:
        assert response.url.endswith("/robots/bob/")  # redirected: relative URLs need the /


def test_health_reports_every_robot(server: ServerProcess) -> None:
    health = server.health()
    assert health["status"] == "ok" and health["robot_count"] == 3
    assert set(health["robots"]) == {"alice", "bob", "carol"}
    assert health["robots"]["bob"]["world"] != health["robots"]["alice"]["world"]


# ---- an open class, idle robots --------------------------------------------------------------

def test_an_open_class_enrols_new_names_up_to_its_limit(tmp_path: Path) -> None:
    path = tmp_path / "roster.txt"
    path.write_text("alice\n")
    server = start_server(["--class", str(path), "--open-class", "--max-robots", "2"])
    try:
        async def scenario() -> str:
            async with websockets.connect(robot_url(server, "dave")) as dave:
                await dave.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
                await first(dave, "/odom")
            with pytest.raises(websockets.InvalidStatus) as full:
                async with websockets.connect(robot_url(server, "erin")):
                    pass
            return full.value.response.body.decode()

        assert "the class is full (2 robots)" in asyncio.run(scenario())
        assert set(server.health()["robots"]) == {"alice", "dave"}
    finally:
        server.stop()


def test_a_robot_nobody_uses_pauses_and_resumes_with_its_state(tmp_path: Path) -> None:
    links = tmp_path / "links.csv"
    server = start_server(["--class", "2", "--idle-pause", "0.5", "--links", str(links)])
    url = robot_url(server, "robot01")
    token = {row["name"]: row["token"] for row in csv.DictReader(links.open())}["robot01"]
    try:
        async def drive() -> None:
            async with websockets.connect(robot_url(server, "robot01", token)) as ws:
                await ws.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST}))
                await asyncio.sleep(0.3)

        asyncio.run(drive())  # robot01 keeps the command: it drives on until it pauses
        wait_for(lambda: server.health()["robots"]["robot01"]["paused"], 5.0, "robot01 paused")
        ticks = server.health()["robots"]["robot01"]["ticks"]
        time.sleep(0.5)
        assert server.health()["robots"]["robot01"]["ticks"] == ticks
        assert server.health()["paused_robots"] == 2
        x = asyncio.run(ground_truth_x(url))  # connecting resumes it, where it was
        assert 0.0 < x < 3.0
        assert server.health()["robots"]["robot01"]["ticks"] > ticks
    finally:
        server.stop()


# ---- in-process: one tick driver, a world each, scans only when wanted -----------------

def test_a_scan_is_cast_only_when_someone_subscribes_to_it() -> None:
    rig = robot_rig("maze")
    host = rig.host
    for _ in range(10):
        rig.tick_now()
    assert host.stats.scans_cast == 0
    session = Session("reader", False)
    host.bridge.connect(session)
    host.bridge.handle(session, json.dumps({"op": "subscribe", "topic": "/scan"}))
    for _ in range(10):
        rig.tick_now()
    assert host.stats.scans_cast == 5


def test_classroom_robots_are_independent_objects() -> None:
    made: list[VirtualRobot] = []

    def make(student: Student) -> VirtualRobot:
        made.append(VirtualRobot(Simulation(load_world(student.world or "empty"), seed=0)))
        return made[-1]

    classroom = Classroom(numbered_roster(2), make, idle_pause_s=None)
    (_, first_host), (_, second_host) = list(classroom)
    assert first_host.bridge is not second_host.bridge
    assert first_host.robot.sim is not second_host.robot.sim
    assert classroom.world("robot01") is not classroom.world("robot02"), "a world each"
    assert classroom.world("robot01").world is first_host.robot.sim.world_sim
    assert classroom.driver.worlds == [classroom.world("robot01"), classroom.world("robot02")]
    assert classroom.get("robot03") is None, "a closed class enrols nobody"
    assert classroom.is_robot_token("robot01", classroom.token("robot01"))
    assert not classroom.is_robot_token("robot02", classroom.token("robot01"))


# ---- the instructor's view ---------------------------------------------------------------

async def reply_to(ws: Any, request: dict[str, Any]) -> dict[str, Any]:
    await ws.send(json.dumps(request))
    while True:
        message = json.loads(await asyncio.wait_for(ws.recv(), 5))
        if message.get("op") in ("service_response", "status"):
            return dict(message)


def test_the_instructor_sees_every_robot_under_its_namespace(server: ServerProcess) -> None:
    root = f"ws://127.0.0.1:{server.ws_port}/?token={ADMIN_TOKEN}"

    async def scenario() -> dict[str, Any]:
        seen: dict[str, Any] = {}
        async with websockets.connect(root) as ws:
            robots = await reply_to(ws, {"op": "call_service", "service": "/websim/robots",
                                         "id": "r"})
            seen["names"] = robots["values"]["names"]
            await ws.send(json.dumps({"op": "subscribe", "topic": "/carol/odom",
                                      "throttle_rate": 200}))
            odom = json.loads(await asyncio.wait_for(ws.recv(), 5))
            seen["odom_topic"] = odom["topic"]
            seen["frame"] = odom["msg"]["header"]["frame_id"]
            await ws.send(json.dumps({"op": "unsubscribe", "topic": "/carol/odom"}))
            await ws.send(json.dumps({"op": "publish", "topic": "/carol/cmd_vel",
                                      "msg": TWIST}))
            await asyncio.sleep(0.5)
            status = await reply_to(ws, {"op": "call_service", "id": "s",
                                         "service": "/carol/websim/status"})
            seen["status"] = status
            seen["pause"] = await reply_to(ws, {"op": "call_service", "id": "p",
                                                "service": "/bob/websim/pause",
                                                "args": {"paused": True}})
            seen["reset"] = await reply_to(ws, {"op": "call_service", "id": "z",
                                                "service": "/carol/reset_simulation"})
            seen["unknown"] = await reply_to(ws, {"op": "call_service", "id": "u",
                                                  "service": "/mallory/reset_simulation"})
            seen["clients_while"] = server.health()["robots"]["carol"]["clients"]
            await reply_to(ws, {"op": "call_service", "service": "/bob/websim/pause", "id": "q",
                                "args": {"paused": False}})
        return seen

    seen = asyncio.run(scenario())
    assert seen["names"] == ["alice", "bob", "carol"]
    assert seen["odom_topic"] == "/carol/odom" and seen["frame"] == "odom"
    status = seen["status"]
    assert status["service"] == "/carol/websim/status" and status["result"] is True
    assert status["values"]["speed_mps"] > 0.0, "the instructor drove carol"
    assert status["values"]["last_driver"].startswith("127.0.0.1:")
    assert [c["admin"] for c in status["values"]["clients"]] == [True]
    assert seen["pause"]["values"] == {"paused": True}
    assert seen["reset"]["service"] == "/carol/reset_simulation" and seen["reset"]["result"]
    assert seen["unknown"]["result"] is False
    assert "no robot named 'mallory'" in seen["unknown"]["values"]
    assert seen["clients_while"] == 1
    wait_for(lambda: server.health()["robots"]["carol"]["clients"] == 0, 5.0,
             "the instructor's hold on carol to be released")
    assert asyncio.run(ground_truth_x(robot_url(server, "carol"))) == 0.0


def test_the_root_answers_every_robots_status_at_once(server: ServerProcess) -> None:
    """``/websim/class_status``: what the dashboard shows of each robot, in one call."""
    root = f"ws://127.0.0.1:{server.ws_port}/?token={ADMIN_TOKEN}"

    async def scenario() -> tuple[dict[str, Any], dict[str, Any]]:
        async with websockets.connect(owner_url(server, "carol")) as carol, \
                websockets.connect(robot_url(server, "carol")), \
                websockets.connect(root) as ws:
            await carol.send(json.dumps({"op": "publish", "topic": "/cmd_vel",
                                         "msg": {"linear": {"x": 0.0}, "angular": {"z": 0.0}}}))
            await asyncio.sleep(0.3)
            whole = await reply_to(ws, {"op": "call_service", "id": "c",
                                        "service": "/websim/class_status"})
            one = await reply_to(ws, {"op": "call_service", "id": "s",
                                      "service": "/carol/websim/status"})
        return whole, one

    whole, one = asyncio.run(scenario())
    assert whole["service"] == "/websim/class_status" and whole["result"] is True, whole
    robots = whole["values"]["robots"]
    assert [robot["name"] for robot in robots] == ["alice", "bob", "carol"]
    carol = robots[2]
    assert carol["last_driver"].startswith("127.0.0.1:")
    assert 0.0 <= carol["last_drive_age_s"] < 1.0, "carol's owner commanded zero 0.3 s ago"
    assert (carol["client_count"], carol["admin_count"]) == (2, 1)  # owner + watcher
    assert all((robot["last_driver"] is None) == (robot["last_drive_age_s"] is None)
               for robot in robots)
    # the per-robot status is the same, with each client's address besides
    per_robot = one["values"]
    assert {key for key in per_robot if key != "clients"} | {"name"} == set(carol)
    assert len(per_robot["clients"]) == 3  # the root's own session on carol too
    # one fixed set of fields per robot, however many clients it has: a bounded answer
    assert all(set(robot) == set(carol) for robot in robots)


def test_the_root_without_the_instructor_token_is_refused(server: ServerProcess) -> None:
    async def refused(url: str) -> str:
        with pytest.raises(websockets.InvalidStatus) as error:
            async with websockets.connect(url):
                pass
        return str(error.value.response.body, "utf-8")

    carol = asyncio.run(refused(f"ws://127.0.0.1:{server.ws_port}/?token={CAROL_TOKEN}"))
    assert "it needs the instructor's token" in carol


def test_students_cannot_ask_for_status_or_pause(server: ServerProcess) -> None:
    reply = asyncio.run(call(robot_url(server, "alice"), "/websim/status", {}))
    assert reply["result"] is False and "needs admin rights" in reply["values"]


def test_robot_tokens_derive_from_the_class_secret_not_the_instructor_token(
        server: ServerProcess, links: Path) -> None:
    rows = {row["name"]: row["token"] for row in csv.DictReader(links.open())}
    assert rows["alice"] != derived_token(ADMIN_TOKEN, "alice")  # no offline guessing
    assert len(rows["alice"]) == 24 and len(set(rows.values())) == 3
    assert rows["carol"] == CAROL_TOKEN  # the roster's own token wins


# ---- only a robot's owner drives it (issue 20, section 4) -------------------------------------

async def replies(url: str, operations: list[dict[str, Any]], wait_s: float = 0.6
                  ) -> list[dict[str, Any]]:
    """Send ``operations`` (asking for status errors), collect what comes back for a while."""
    got: list[dict[str, Any]] = []
    async with websockets.connect(url) as ws:
        await ws.send(json.dumps({"op": "set_level", "level": "error"}))
        for operation in operations:
            await ws.send(json.dumps(operation))
        deadline = time.monotonic() + wait_s
        with contextlib.suppress(TimeoutError, asyncio.TimeoutError):
            while (left := deadline - time.monotonic()) > 0:
                got.append(json.loads(await asyncio.wait_for(ws.recv(), left)))
    return got


def test_a_classmate_without_the_token_watches_but_cannot_drive_or_reset(
        server: ServerProcess) -> None:
    start_x = asyncio.run(ground_truth_x(robot_url(server, "bob")))  # watching works
    got = asyncio.run(replies(robot_url(server, "bob"), [
        {"op": "subscribe", "topic": "/odom"},
        {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"},
        {"op": "publish", "topic": "/cmd_vel", "msg": TWIST},
        {"op": "call_service", "service": "/reset_simulation", "id": "r"},
        {"op": "call_service", "service": "/rosapi/topics", "id": "t"},
        {"op": "advertise_service", "service": "/bobs_service", "type": "std_srvs/Empty"},
    ], wait_s=1.0))
    reasons = [m["msg"] for m in got if m.get("op") == "status"]
    assert any(r.startswith("publishing /cmd_vel changes the robot and needs its token")
               for r in reasons), reasons
    assert any("advertise_service /bobs_service changes the robot" in r for r in reasons)
    assert all("ws://HOST:9090/robots/NAME?token=TOKEN" in r for r in reasons)
    calls = {m["id"]: m for m in got if m.get("op") == "service_response"}
    assert calls["r"]["result"] is False and "needs its token" in calls["r"]["values"]
    assert calls["t"]["result"] is True and "/odom" in calls["t"]["values"]["topics"]
    assert any(m.get("topic") == "/odom" for m in got), "a watcher gets the robot's topics"
    assert asyncio.run(ground_truth_x(robot_url(server, "bob"))) == start_x == 0.0
    # a service bob's own code offers is his: a classmate cannot call it either

    async def offered_and_called() -> dict[str, Any]:
        async with websockets.connect(owner_url(server, "bob")) as owner:
            await owner.send(json.dumps({"op": "advertise_service", "service": "/bobs_service",
                                         "type": "std_srvs/Empty"}))
            await asyncio.sleep(0.3)
            got = await replies(robot_url(server, "bob"), [
                {"op": "call_service", "service": "/bobs_service", "id": "b"}], 0.5)
            return next(m for m in got if m.get("op") == "service_response")

    offered = asyncio.run(offered_and_called())
    assert offered["result"] is False and "calling /bobs_service changes the robot" \
        in offered["values"]
    # bob's own token (or the instructor's) drives bob; alice's token does not
    for token, moves in ((TOKENS["alice"], False), (TOKENS["bob"], True), (ADMIN_TOKEN, True)):
        got = asyncio.run(replies(robot_url(server, "bob", token), [
            {"op": "publish", "topic": "/cmd_vel", "msg": TWIST},
            {"op": "call_service", "service": "/reset_simulation", "id": "r"}], wait_s=0.3))
        reset = next(m for m in got if m.get("op") == "service_response")
        assert reset["result"] is moves, token


def test_open_drive_lets_anyone_drive_as_before(tmp_path: Path) -> None:
    server = start_server(["--class", "2", "--open-drive"])
    try:
        got = asyncio.run(replies(robot_url(server, "robot02"), [
            {"op": "publish", "topic": "/cmd_vel", "msg": TWIST},
            {"op": "call_service", "service": "/reset_simulation", "id": "r"},
            {"op": "call_service", "service": "/virtual_robot/set_parameters", "id": "p",
             "args": {"parameters": []}}], wait_s=0.3))
        calls = {m["id"]: m for m in got if m.get("op") == "service_response"}
        assert calls["r"]["result"] is True
        assert calls["p"]["result"] is False and "needs admin rights" in calls["p"]["values"]
    finally:
        server.stop()
    assert "anyone may drive any robot (--open-drive)" in "".join(server.output)


def test_an_open_class_hands_a_new_name_to_its_first_connection_only(tmp_path: Path) -> None:
    path = tmp_path / "roster.txt"
    path.write_text("alice\n")
    server = start_server(["--class", str(path), "--open-class"])
    try:
        token_call = {"op": "call_service", "service": "/websim/token", "id": "k"}
        first_got = asyncio.run(replies(robot_url(server, "dave"), [token_call], 0.3))
        handed = next(m for m in first_got if m.get("op") == "service_response")
        assert handed["result"] is True
        token = handed["values"]["token"]
        assert len(token) == 24
        later = asyncio.run(replies(robot_url(server, "dave"), [
            token_call, {"op": "publish", "topic": "/cmd_vel", "msg": TWIST}], 0.3))
        again = next(m for m in later if m.get("op") == "service_response")
        assert again["result"] is False, "nobody else takes dave's token"
        assert any("needs its token" in m.get("msg", "") for m in later)
        owner = asyncio.run(replies(robot_url(server, "dave", token), [
            {"op": "call_service", "service": "/reset_simulation", "id": "r"}], 0.3))
        assert next(m for m in owner if m.get("op") == "service_response")["result"] is True
        config = json.load(urllib.request.urlopen(
            f"{server.http_url}/robots/dave/config.json", timeout=5))
        assert config["robotToken"]["name"] == "/websim/token"
    finally:
        server.stop()


def test_an_invalid_or_mistyped_name_is_refused_for_what_it_is(tmp_path: Path) -> None:
    def make_robot(student: Student) -> VirtualRobot:
        return VirtualRobot(Simulation(load_world("empty")))

    from classroom.class_server import ClassServer

    roster = Classroom([Student("alice"), Student("carol")], make_robot, open_class=True,
                       idle_pause_s=None, lazy=True)
    front = ClassServer(roster, ADMIN_TOKEN)
    assert front.find("/robots/Bad.Name") == \
        "'Bad.Name' is not a robot name (1 to 32 of a-z, 0-9, _ and -); your instructor's " \
        "links give your robot's"
    assert front.find("/robots/Alice").startswith("'Alice' is not a robot name")
    assert front.log_hint("/robots/Alice") == " (names close to it: alice)"
    closed = ClassServer(Classroom([Student("carol")], make_robot, idle_pause_s=None,
                                   lazy=True), ADMIN_TOKEN)
    assert closed.find("/robots/carl") == "no robot named 'carl' in this class; your " \
                                          "instructor's links give your robot's name"
    assert closed.log_hint("/robots/carl") == " (names close to it: carol)"
    assert closed.log_hint("/robots/zzzzzz") == ""


def test_tokenless_watchers_cannot_take_a_robots_tf_republisher_from_its_owner(
        server: ServerProcess) -> None:
    """Eight sockets without a token ask bob's TF republisher for all 64 republications (as
    ros3djs pages would): they get the watchers' share; bob's own page still gets its own."""
    request = {"source_frames": ["base_link"], "target_frame": "odom", "angular_thres": 0.0,
               "trans_thres": 0.0, "rate": 10.0}

    async def attack() -> tuple[int, str, dict[str, Any]]:
        watchers = [await websockets.connect(robot_url(server, "bob")) for _ in range(8)]
        granted, refusal = 0, ""
        try:
            for ws in watchers:
                for number in range(8):
                    await ws.send(json.dumps({"op": "call_service", "id": f"w{number}",
                                              "service": "/republish_tfs", "args": request}))
                    while True:
                        reply = json.loads(await asyncio.wait_for(ws.recv(), 5))
                        if reply.get("op") == "service_response":
                            break
                    granted += bool(reply["result"])
                    refusal = refusal or ("" if reply["result"] else str(reply["values"]))
            owner = await call(owner_url(server, "bob"), "/republish_tfs", request)
        finally:
            for ws in watchers:
                await ws.close()
        return granted, refusal, owner

    granted, refusal, owner = asyncio.run(attack())
    assert granted == 48 and "are kept for its owner" in refusal
    assert owner["result"] and owner["values"]["topic_name"].startswith("/tf_repub_")
