"""``websim replay``: a recording served back as its robot's topics, to clients and the page.

A recording is made with a real ``Recorder`` from a driven robot on the test rig; a real
``websim replay`` process serves it; a roslibpy client and headless Chromium (the robot's
own page) receive it.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import roslibpy
from bag_readers import Read, close, read_with_rosbags
from page_helpers import needs_browser, open_page, wait_connected
from robot_rig import robot_rig
from websockets.sync.client import connect

from ros_nodes.recording import Recorder
from ros_nodes.robot_interface import RECORDED_TOPICS
from rosbridge.core.clock import ManualClock
from rosbridge.core.outbox import Outbox
from rosbridge.core.session import Session
from websim.replay import Recording, ReplayHost

from server_process import ServerProcess, free_port, stop_process, wait_for

ARTIFACTS = Path(__file__).resolve().parent.parent / "test-artifacts"

TYPES = {spec.name: spec.type for spec in RECORDED_TOPICS}


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """4 s of a robot driven in the maze: forward, then turning."""
    recorder = Recorder(tmp_path_factory.mktemp("bags"))
    rig = robot_rig("maze")
    recording = recorder.record("alice", rig.robot)
    recorder.start()
    driver = rig.client("driver")
    rig.send(driver, {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"})
    for index, (x, z) in enumerate(((0.2, 0.0), (0.1, 0.8))):
        rig.send(driver, {"op": "publish", "topic": "/cmd_vel", "msg": {
            "linear": {"x": x, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": z}}})
        rig.tick(40 + index)
    recorder.close()
    return recording.path


def start_replay(bag: Path, *args: str) -> ServerProcess:
    ws_port, http_port = free_port(), free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "websim.cli", "replay", str(bag), "--ws-port", str(ws_port),
         "--http-port", str(http_port), *args], stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    server = ServerProcess(ws_port, http_port, process)

    def healthy() -> bool:
        if process.poll() is not None:
            raise AssertionError(f"websim replay exited: {process.communicate()[0]}")
        try:
            return server.health()["status"] == "ok"
        except OSError:
            return False

    wait_for(healthy, timeout_s=20.0, what="websim replay to answer /healthz")
    return server


@pytest.fixture
def replay(bag: Path) -> Iterator[ServerProcess]:
    server = start_replay(bag, "--speed", "4")
    yield server
    assert stop_process(server.process, server.output, signal.SIGTERM) == 0, \
        "".join(server.output)


def test_a_client_receives_every_recorded_message_in_order(replay: ServerProcess,
                                                          bag: Path) -> None:
    recorded = read_with_rosbags(bag)
    client = roslibpy.Ros(host="127.0.0.1", port=replay.ws_port)
    client.run(timeout=10)
    received: dict[str, list[dict[str, Any]]] = {topic: [] for topic in TYPES}
    for topic in ("/odom", "/cmd_vel", "/world", "/tf_static"):
        roslibpy.Topic(client, topic, TYPES[topic]).subscribe(received[topic].append)
    health = wait_for(lambda: (report := replay.health())["finished"] and report,
                      timeout_s=20, what="the replay to reach its end")
    assert health["speed"] == 4 and health["replay"] == "alice"
    assert health["duration_s"] == pytest.approx(
        (recorded[-1].log_time_ns - recorded[0].log_time_ns) / 1e9, abs=1e-3)
    # "finished" is the replay's; its last frames may still be on their way to this client
    last_odom = [r.message for r in recorded if r.topic == "/odom"][-1]
    wait_for(lambda: received["/odom"] and received["/odom"][-1]["header"] == last_odom["header"],
             timeout_s=10, what="the last recorded /odom to reach the client")
    client.close()
    # the latched topics reach a client that subscribed after they were published
    for topic in ("/world", "/tf_static"):
        (read,) = [r for r in recorded if r.topic == topic]
        assert len(received[topic]) == 1
        close(received[topic][0], read.message, where=topic)
    # every /odom published after the client subscribed, in order, as recorded
    odoms = [r.message for r in recorded if r.topic == "/odom"]
    first = odoms.index(next(m for m in odoms if m["header"] == received["/odom"][0]["header"]))
    assert len(received["/odom"]) == len(odoms) - first
    for got, read in zip(received["/odom"], odoms[first:], strict=True):
        close(got, read, where="/odom")
    commands = [r.message for r in recorded if r.topic == "/cmd_vel"]
    assert received["/cmd_vel"] == commands[len(commands) - len(received["/cmd_vel"]):]


def test_a_recording_is_not_driven_and_its_page_gets_the_recorded_robot(
        replay: ServerProcess) -> None:
    with connect(replay.ws_url) as ws:
        ws.send(json.dumps({"op": "set_level", "level": "error"}))
        ws.send(json.dumps({"op": "advertise", "topic": "/cmd_vel",
                            "type": "geometry_msgs/Twist"}))
        ws.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {}}))
        status = next(reply for reply in map(json.loads, iter(ws.recv, None))
                      if reply.get("op") == "status")
    assert status["level"] == "error" and "/cmd_vel" in status["msg"]
    import urllib.request

    with urllib.request.urlopen(f"{replay.http_url}/robot.json", timeout=5) as response:
        description = json.load(response)
    assert description["topics"]["odom"]["name"] == "/odom"
    with urllib.request.urlopen(f"{replay.http_url}/config.json", timeout=5) as response:
        assert json.load(response)["ws"].endswith(f":{replay.ws_port}/")


def test_the_replay_paces_messages_by_their_log_time_times_the_speed(bag: Path) -> None:
    clock = ManualClock()
    host = ReplayHost(Recording(bag), speed=2.0, clock=clock)
    recorded = read_with_rosbags(bag)
    start_ns = recorded[0].log_time_ns
    for _ in range(10):  # nobody watches: the recording waits
        clock.advance(0.05)
        host.tick()
    assert host.played == 0 and host.position_s == 0.0
    host.bridge.connect(Session("watcher", False, Outbox()))
    played, due = [], []
    clock.advance(0.0125)  # between two recorded ticks: no message sits on a boundary
    for step in range(50):
        host.tick()
        played.append(host.played)
        offset_s = 2.0 * (0.0125 + 0.05 * step)  # 0.1 s of the recording per tick at 2x
        due.append(sum(1 for r in recorded if r.log_time_ns - start_ns <= offset_s * 1e9))
        clock.advance(0.05)
    assert played[:30] == due[:30]
    assert 0 < played[0] < played[15] < played[29] < len(recorded)
    assert host.finished and host.passes == 1
    assert host.position_s == pytest.approx(host.recording.duration_s)


@pytest.mark.parametrize(("args", "reason"), [
    (["{missing}"], "no such recording"),
    (["{not_a_bag}"], "cannot read this recording"),
    (["{bag}", "--speed", "0"], "--speed must be a number from 0.05 to 100"),
])
def test_a_recording_that_cannot_be_played_is_refused_with_the_reason(
        tmp_path: Path, bag: Path, args: list[str], reason: str) -> None:
    not_a_bag = tmp_path / "notes.mcap"
    not_a_bag.write_text("not an MCAP file")
    paths = {"missing": tmp_path / "nothing", "not_a_bag": not_a_bag, "bag": bag}
    result = subprocess.run([sys.executable, "-m", "websim.cli", "replay",
                             *(arg.format(**paths) for arg in args)], capture_output=True,
                            text=True, timeout=60, check=False)
    assert result.returncode == 2, result.stderr
    assert reason in result.stderr


@needs_browser
def test_the_page_shows_the_recorded_robot(bag: Path, browser: Any) -> None:
    last: Read = [r for r in read_with_rosbags(bag) if r.topic == "/odom"][-1]
    server = start_replay(bag, "--speed", "2")
    context = browser.new_context(viewport={"width": 1280, "height": 860})
    try:
        page, log = open_page(context, f"{server.http_url}/")
        wait_connected(page)
        wait_for(lambda: server.health()["finished"], timeout_s=20, what="the replay's end")
        x = last.message["pose"]["pose"]["position"]["x"]
        page.wait_for_function(
            f"Math.abs(Number(document.querySelector('[data-readout=x]').textContent) - {x})"
            " < 0.0015", timeout=10000)
        assert not log.page_errors
    finally:
        context.close()
        assert stop_process(server.process, server.output, signal.SIGTERM) == 0


def control(host: ReplayHost, session: Session, **args: Any) -> dict[str, Any]:
    """Call the player's service as a client would, through the bridge; its reply."""
    host.bridge.handle(session, json.dumps({"op": "call_service", "service": "/websim/replay",
                                            "id": "c", "args": args}))
    replies = []
    while (frame := session.outbox.pop()) is not None:
        replies.append(json.loads(frame))
    (reply,) = [r for r in replies if r.get("op") == "service_response"]
    return dict(reply)


def test_the_player_pauses_seeks_and_sets_the_speed_for_every_viewer(bag: Path) -> None:
    clock = ManualClock()
    host = ReplayHost(Recording(bag), clock=clock)
    viewer = Session("viewer", False, Outbox())
    host.bridge.connect(viewer)
    host.bridge.handle(viewer, json.dumps({"op": "subscribe", "topic": "/odom"}))
    for _ in range(10):  # half a second of the recording
        clock.advance(0.05)
        host.tick()
    paused = control(host, viewer, command="pause")["values"]
    assert paused["playing"] is False and paused["position_s"] == pytest.approx(0.5)
    before = host.played
    for _ in range(10):
        clock.advance(0.05)
        host.tick()
    assert host.played == before and host.position_s == pytest.approx(0.5), "paused"

    middle_s = host.recording.duration_s / 2
    seeked = control(host, viewer, command="seek", position_s=middle_s)["values"]
    assert seeked["position_s"] == pytest.approx(middle_s)
    assert control(host, viewer, command="speed", speed=4)["values"]["speed"] == 4
    while viewer.outbox.pop() is not None:
        pass
    played = control(host, viewer, command="play")["values"]
    assert played["playing"] is True
    clock.advance(0.05)
    host.tick()  # 0.2 s of the recording at 4x, from the middle on
    frames = []
    while (frame := viewer.outbox.pop()) is not None:
        frames.append(json.loads(frame))
    odoms = [f["msg"]["header"]["stamp"] for f in frames if f.get("topic") == "/odom"]
    start_s = host.recording.start_ns / 1e9
    times = [stamp["sec"] + stamp["nanosec"] / 1e9 - start_s for stamp in odoms]
    assert times and all(middle_s - 0.001 <= t <= middle_s + 0.25 for t in times), times

    wrong = [control(host, viewer, command="rewind"),
             control(host, viewer, command="seek", position_s=-1),
             control(host, viewer, command="seek", position_s="10"),
             control(host, viewer, command="speed", speed=1e9)]
    assert [reply["result"] for reply in wrong] == [False] * 4
    assert "command must be one of play, pause, seek, speed, status" in wrong[0]["values"]
    assert "position_s must be a number from 0 to" in wrong[1]["values"]
    assert "speed must be a number from 0.05 to 100, got 1000000000.0" in wrong[3]["values"]


def test_a_seek_first_still_gives_the_walls_and_the_lasers_mount(bag: Path) -> None:
    """Latched topics recorded at the start: a page that seeks before they were played."""
    clock = ManualClock()
    host = ReplayHost(Recording(bag), clock=clock)
    viewer = Session("viewer", False, Outbox())
    host.bridge.connect(viewer)
    for topic in ("/world", "/tf_static"):
        host.bridge.handle(viewer, json.dumps({"op": "subscribe", "topic": topic}))
    host.control({"command": "seek", "position_s": host.recording.duration_s / 2}, viewer)
    topics = []
    while (frame := viewer.outbox.pop()) is not None:
        topics.append(json.loads(frame).get("topic"))
    assert {"/world", "/tf_static"} <= set(topics)


@needs_browser
def test_the_replay_page_is_a_player_without_driving(bag: Path, browser: Any) -> None:
    """It looked like a live robot (drive pad, PID panel, 'Another client is driving this
    robot') and the banner printed an admin token that did nothing."""
    server = start_replay(bag, "--speed", "0.5")
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    try:
        page, log = open_page(context, f"{server.http_url}/")
        wait_connected(page)
        for hidden in ("#drive-pad", "#pid-form", "nav a[href=admin]", "#other-driver"):
            assert not page.is_visible(hidden), hidden
        assert page.is_visible("#player") and page.is_visible("#player-seek")
        page.wait_for_function("document.querySelector('#player-toggle').textContent "
                               "=== 'Pause'", timeout=10000)
        page.click("#player-toggle")
        wait_for(lambda: server.health()["playing"] is False, timeout_s=10,
                 what="the replay to pause")
        assert page.text_content("#player-toggle") in ("Play", "Pause")
        page.wait_for_function("document.querySelector('#player-toggle').textContent "
                               "=== 'Play'", timeout=5000)
        page.select_option("#player-speed", "2")
        wait_for(lambda: server.health()["speed"] == 2, timeout_s=10, what="speed 2")
        target_s = round(server.health()["duration_s"] * 0.75, 1)
        page.evaluate("(value) => { const seek = document.querySelector('#player-seek');"
                      " seek.value = String(value);"
                      " seek.dispatchEvent(new Event('input'));"
                      " seek.dispatchEvent(new Event('change')); }", target_s)
        wait_for(lambda: abs(server.health()["position_s"] - target_s) < 0.11, timeout_s=10,
                 what="the replay at the position sought")
        page.wait_for_function("document.querySelector('#player-time').textContent"
                               ".includes(' / ')", timeout=5000)
        page.screenshot(path=str(ARTIFACTS / "replay-player.png"))
        assert not log.page_errors
        assert not [error for error in log.console_errors if "replay" in error.lower()]
    finally:
        context.close()
        assert stop_process(server.process, server.output, signal.SIGTERM) == 0
    output = "".join(server.output)
    assert "token=" not in output, "no admin token that does nothing"
    assert "player:    the page plays, pauses, seeks and sets the speed" in output
