"""The browser's roslibpy (``web-interface/python/``) held to the real one, on CPython.

The Code panel runs a student's Python in Pyodide with websim's ``roslibpy`` and
``websim_browser`` (frames delivered while the program waits). Here the same two modules run on
CPython (``tests/code_shim_runner.py``: a transport of real WebSockets instead of the page's
ring), so the course's snippets and the reference solutions can be run both ways against a real
``websim serve`` and a real ``websim grade``, and must do the same. The loop's own rules (what a
wait delivers, a callback that blocks, one that raises) are tested on a transport the test
scripts; the browser itself is tested in test_page_code_python.py.
"""

from __future__ import annotations

import _thread
import importlib.util
import json
import os
import queue
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from server_process import ServerProcess

ROOT = Path(__file__).resolve().parent.parent
RUNNER = ROOT / "tests" / "code_shim_runner.py"
SHIM = ROOT / "web-interface" / "python"
SOLUTIONS = ROOT / "examples" / "solutions"


def _load_loop_module() -> Any:
    """web-interface/python/websim_browser.py, imported by path: that folder is never put on
    this process's sys.path, where its roslibpy would shadow the real one for other tests."""
    spec = importlib.util.spec_from_file_location("websim_browser", SHIM / "websim_browser.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


websim_browser = _load_loop_module()


def run(program: Path | str, *args: str, shim: bool, timeout_s: float = 60.0,
        cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run a program with the browser's roslibpy (``shim``) or the real one."""
    command = [sys.executable, str(RUNNER)] if shim else [sys.executable]
    return subprocess.run([*command, str(program), *args], capture_output=True, text=True,
                          timeout=timeout_s, check=False, cwd=cwd)


def test_the_course_snippets_run_the_same_under_both_roslibpys(server: ServerProcess) -> None:
    results = {shim: run(ROOT / "examples" / "course_snippets.py", server.ws_url, shim=shim)
               for shim in (False, True)}
    for shim, result in results.items():
        assert result.returncode == 0, (shim, result.stdout, result.stderr)
        lines = result.stdout.splitlines()
        assert lines[0].startswith("Connected to ROS 2 at ws://127.0.0.1")
        assert any(line.startswith("scan: 360 beams") for line in lines), lines
        assert "stop: published a zero Twist" in lines
        scans = int(next(line for line in lines if line.startswith("received")).split()[1])
        assert 15 <= scans <= 25, lines  # 2 s of driving at 10 Hz, and the wait for data


PROGRAM = '''
import json, sys, threading, queue, time
import roslibpy
import roslibpy.core

ros = roslibpy.Ros(host=sys.argv[1])
ros.run(timeout=5)
ready = threading.Event()
odoms = queue.Queue()
listener = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry")
listener.subscribe(lambda message: (odoms.put(message), ready.set()))
print("event", ready.wait(5))
first = odoms.get(timeout=5)
print("frame", first["header"]["frame_id"])
topics = ros.get_topics()
print("topics", "/odom" in topics, "/cmd_vel" in topics)
service = roslibpy.Service(ros, "/no_such_service", "std_srvs/srv/Empty")
try:
    service.call(roslibpy.ServiceRequest(), timeout=5)
    print("call", "answered")
except roslibpy.core.ServiceException:
    print("call", "refused")
answers = []
service.call(roslibpy.ServiceRequest(), answers.append, lambda reason: answers.append("err"))
time.sleep(1.0)
print("async", answers)
listener.unsubscribe()
ros.terminate()
print("connected after terminate", ros.is_connected)
'''


def test_waits_queues_services_and_rosapi_answer_as_under_roslibpy(
        server: ServerProcess, tmp_path: Path) -> None:
    program = tmp_path / "program.py"
    program.write_text(PROGRAM)
    outputs = {}
    for shim in (False, True):
        result = run(program, server.ws_url, shim=shim)
        assert result.returncode == 0, (shim, result.stdout, result.stderr)
        outputs[shim] = result.stdout.splitlines()
    assert outputs[True] == outputs[False]
    assert outputs[True] == ["event True", "frame odom", "topics True True", "call refused",
                             "async ['err']", "connected after terminate False"]


def test_run_says_it_cannot_connect_as_roslibpy_does(tmp_path: Path) -> None:
    from server_process import free_port
    program = tmp_path / "program.py"
    program.write_text("import sys, roslibpy\nros = roslibpy.Ros(host=sys.argv[1])\n"
                       "from roslibpy.core import RosTimeoutError\n"
                       "try:\n    ros.run(timeout=1)\nexcept RosTimeoutError as e:\n"
                       "    print('timeout', e, isinstance(e, TimeoutError))\n")
    url = f"ws://127.0.0.1:{free_port()}"
    outputs = [run(program, url, shim=shim).stdout for shim in (False, True)]
    assert outputs[0] == outputs[1] == "timeout Failed to connect to ROS True\n"


def shim_submission(folder: Path, solution: str) -> Path:
    """A submission folder holding a reference solution and the browser's roslibpy runner."""
    folder.mkdir(parents=True)
    shutil.copy(SOLUTIONS / solution, folder)
    shutil.copy(RUNNER, folder)
    shim = folder / "web-interface" / "python"
    shutil.copytree(SHIM, shim, dirs_exist_ok=True,
                    ignore=shutil.ignore_patterns("__pycache__"))
    runner = folder / RUNNER.name  # find the shim beside it, as it is copied here
    runner.write_text(runner.read_text().replace(
        'Path(__file__).resolve().parent.parent / "web-interface" / "python"',
        'Path(__file__).resolve().parent / "web-interface" / "python"'))
    return folder


def grade(suite: str | Path, folder: Path, out: Path, *command: str) -> dict[str, Any]:
    result = subprocess.run([sys.executable, "-m", "websim.cli", "grade", str(suite),
                             "--submission", str(folder), "--out", str(out), "--", *command],
                            capture_output=True, text=True, timeout=900, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    return dict(json.loads((out / "summary.json").read_text()))


def metrics(out: Path, summary: dict[str, Any]) -> list[Any]:
    return [json.loads((out / row["report"]).read_text())["metrics"]
            for row in summary["scenarios"]]


SHORT_WALL_SUITE = """
name: wall_following_short
scenarios:
  - scenario:
      name: corridor_left_middle
      world: corridor
      mode: kinematic
      duration_s: 60.0
      seed: 0
      controller_rate_hz: 10
      start: [-0.5, 0.0, 0.0]
      parameters: {side: left, desired_distance_m: 0.5, speed_mps: 0.3}
      end: {point: [5.5, 4.0], radius_m: 1.0}
      metrics:
        - kind: wall_following
          weight: 1.0
"""


@pytest.mark.slow
@pytest.mark.parametrize(("suite", "solution", "arguments"), [
    ("heading_pid", "heading_pid.py", ()),
    ("heading_pid_payload", "heading_pid.py", ("--slew", "0.25")),
    ("go_to_goal", "go_to_goal.py", ()),
    ("wall_following_short", "wall_follower.py", ()),
])
def test_the_reference_solutions_grade_the_same_under_both_roslibpys(
        tmp_path: Path, suite: str, solution: str, arguments: tuple[str, ...]) -> None:
    if suite == "wall_following_short":  # not the shipped suite's six 120 s runs: one of them
        suite_file = tmp_path / "wall_following_short.yaml"
        suite_file.write_text(SHORT_WALL_SUITE)
        suite = str(suite_file)
    folder = shim_submission(tmp_path / "submission", solution)
    real = grade(suite, folder, tmp_path / "real", "python3", solution, *arguments)
    shimmed = grade(suite, folder, tmp_path / "shim", "python3", RUNNER.name, solution,
                    *arguments)
    assert shimmed["total"] == real["total"] > 0.5, (shimmed, real)
    # deterministic mode, in lock step: the same commands, so the same metrics to the digit
    assert metrics(tmp_path / "shim", shimmed) == metrics(tmp_path / "real", real)


# --- the loop's rules, on a transport the test scripts ---------------------------------------

class ScriptedTransport:
    """websim_browser's Transport whose frames a test thread puts in (``arrive``)."""

    def __init__(self) -> None:
        self.frames: queue.SimpleQueue[tuple[int, str, str]] = queue.SimpleQueue()
        self.sent: list[tuple[int, str]] = []
        self.paused_s = 0.0

    def arrive(self, text: str, after_s: float = 0.0, socket: int = 1) -> None:
        if not after_s:
            self.frames.put((socket, "message", text))
            return

        def later() -> None:
            websim_browser.real_sleep(after_s)
            self.frames.put((socket, "message", text))

        _thread.start_new_thread(later, ())  # not threading: Thread.start() waits (the loop)

    def open(self, url: str) -> int:
        return 1

    def send(self, socket: int, text: str) -> None:
        self.sent.append((socket, text))

    def close(self, socket: int) -> None:
        pass

    def wait(self, timeout_s: float) -> list[tuple[int, str, str]]:
        frames = []
        try:
            frames.append(self.frames.get(timeout=timeout_s) if timeout_s > 0
                          else self.frames.get_nowait())
            while True:
                frames.append(self.frames.get_nowait())
        except queue.Empty:
            pass
        return frames

    def pause(self, timeout_s: float) -> None:
        self.paused_s += timeout_s
        websim_browser.real_sleep(timeout_s)


class Recorder:
    """A socket handler that records what it is given and runs a hook per message."""

    def __init__(self, hook: Any = None) -> None:
        self.messages: list[str] = []
        self.hook = hook

    def on_open(self) -> None:
        pass

    def on_message(self, text: str) -> None:
        self.messages.append(text)
        if self.hook is not None:
            self.hook(text)

    def on_close(self, reason: str) -> None:
        pass


@pytest.fixture
def loop() -> Any:
    transport = ScriptedTransport()
    reported: list[BaseException] = []
    installed = websim_browser.install(transport, report=reported.append)
    installed.reported = reported  # type: ignore[attr-defined]
    yield installed
    websim_browser.uninstall()


def test_a_sleep_delivers_the_frames_that_arrive_during_it_in_order(loop: Any) -> None:
    handler = Recorder()
    loop.open("ws://robot", handler)
    for index in range(5):
        loop.transport.arrive(f"m{index}", after_s=0.05 * (index + 1))
    started = time.monotonic()
    time.sleep(0.6)
    assert time.monotonic() - started >= 0.6
    assert handler.messages == [f"m{index}" for index in range(5)]


def test_event_and_queue_waits_end_when_a_callback_sets_them(loop: Any) -> None:
    event = threading.Event()
    items: queue.Queue[str] = queue.Queue()
    loop.open("ws://robot", Recorder(lambda text: (items.put(text), event.set())))
    loop.transport.arrive("hello", after_s=0.1)
    started = time.monotonic()
    assert event.wait(5.0) is True
    assert time.monotonic() - started < 2.0
    assert items.get(timeout=1.0) == "hello"
    assert threading.Event().wait(0.2) is False  # nobody sets it: the timeout


def test_a_callback_that_sleeps_blocks_the_others_as_roslibpys_reactor_thread(
        loop: Any) -> None:
    order: list[str] = []

    def hook(text: str) -> None:
        order.append(f"start {text}")
        time.sleep(0.2)  # inside a callback: no other callback runs meanwhile
        order.append(f"end {text}")

    loop.open("ws://robot", Recorder(hook))
    loop.transport.arrive("a")
    loop.transport.arrive("b")
    time.sleep(0.6)
    assert order == ["start a", "end a", "start b", "end b"]
    assert loop.transport.paused_s > 0.39  # two sleeps of 0.2 s, in pieces


def test_a_callback_that_raises_is_reported_and_the_program_goes_on(loop: Any) -> None:
    def hook(text: str) -> None:
        if text == "bad":
            raise ValueError("the callback's own error")

    handler = Recorder(hook)
    loop.open("ws://robot", handler)
    for text in ("ok1", "bad", "ok2"):
        loop.transport.arrive(text)
    time.sleep(0.2)
    assert handler.messages == ["ok1", "bad", "ok2"]
    assert [str(error) for error in loop.reported] == ["the callback's own error"]


def test_timers_run_while_the_program_waits(loop: Any) -> None:
    fired: list[float] = []
    started = time.monotonic()
    loop.call_later(0.2, lambda: fired.append(time.monotonic() - started))
    time.sleep(0.1)
    assert all(at_s >= 0.2 for at_s in fired)  # never early (a loaded machine sleeps longer)
    time.sleep(0.3)
    # it fired while the program slept, once, not before its time (how late: the machine's load)
    assert len(fired) == 1 and fired[0] >= 0.2


def test_a_negative_sleep_is_refused_as_cpython_refuses_it(loop: Any) -> None:
    with pytest.raises(ValueError, match="non-negative"):
        time.sleep(-1)


def run_for(command: list[str], seconds: float, env: dict[str, str],
            cwd: Path) -> tuple[str, str]:
    """Run a program that runs until stopped for ``seconds``, then stop it; its output."""
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env={**os.environ, **env}, cwd=cwd)
    try:
        out, err = process.communicate(timeout=seconds)
    except subprocess.TimeoutExpired:
        process.terminate()
        out, err = process.communicate(timeout=10)
    return out, err


def test_every_starter_runs_as_it_is_with_roslibpy_and_roslib(
        server: ServerProcess, tmp_path: Path) -> None:
    """The starters the panel offers are programs that run (made from the scenario files)."""
    from websim.code_starters import assignments
    found = assignments()
    assert {a["name"] for a in found} == {path.stem for path in
                                          (ROOT / "examples" / "scenarios").glob("*.yaml")}
    node = shutil.which("node")
    for assignment in found:
        env = {"WEBSIM_URL": server.ws_url, **assignment["scenarios"][0]["env"]}
        python = tmp_path / f"{assignment['name']}.py"
        python.write_text(assignment["starters"]["python"])
        for command in ([sys.executable, str(python)],
                        [sys.executable, str(RUNNER), str(python)]):
            out, err = run_for(command, 3.0, env, tmp_path)
            assert out.startswith("connected") and "Traceback" not in err, (command, out, err)
        if node is not None:
            script = tmp_path / f"{assignment['name']}.js"
            script.write_text(assignment["starters"]["javascript"])
            out, err = run_for([node, str(script)], 3.0,
                               {**env, "NODE_PATH": str(ROOT / "web-interface" /
                                                        "node_modules")}, tmp_path)
            assert out.startswith("connected") and "Error" not in err, (out, err)
