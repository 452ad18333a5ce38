"""The sandbox per submission (websim.sandbox): real bubblewrap, real processes, a real
``websim serve`` inside the namespace, hostile controllers contained and reported."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from websim.sandbox import (
    INSTALL_HINT,
    PRIVATE_HTTP_PORT,
    PRIVATE_WS_PORT,
    ControllerResult,
    SandboxLimits,
    SandboxUnavailableError,
    SimulatorStartError,
    SubmissionSandbox,
)
from websim.sandbox.identity import FIRST_UID, UID_COUNT
from websim.sandbox.limits import CPU_KILL_GRACE_S, MIB
from websim.sandbox.mounts import controller_environment, visible_paths
from websim.sandbox.outcome import Observed, size_text
from websim.sandbox.sandbox import READY_TEXT, SERVER_STOP_TIMEOUT_S
from websim.sandbox.submission import SubmissionRefusedError
from websim.sandbox.watch import SAMPLE_PERIOD_S, usage

HAVE_SANDBOX = shutil.which("bwrap") is not None and os.geteuid() == 0
needs_sandbox = pytest.mark.skipif(
    not HAVE_SANDBOX,
    reason="bubblewrap (bwrap) not installed, or not root (the sandbox needs both): "
           f"{INSTALL_HINT}")

ADMIN_TOKEN = "Sandbox-test-admin-token-2026"
GENEROUS_WALL_S = 120.0
"""Wall-clock limit of runs that should end by themselves (a loaded 2-core machine)."""


def submission(folder: Path, code: str, **files: str) -> Path:
    """A submission folder with ``main.py`` (``code``) and ``files``."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "main.py").write_text(textwrap.dedent(code))
    for name, text in files.items():
        (folder / name).write_text(text)
    return folder


def run(folder: Path, limits: SandboxLimits | None = None,
        env: Mapping[str, str] | None = None, **options: Any) -> ControllerResult:
    """Run ``python3 main.py`` of ``folder`` in a sandbox without a simulator."""
    with SubmissionSandbox(folder, limits=limits, **options) as box:
        return box.run_controller(["python3", "main.py"], env=env)


def serve_argv(box: SubmissionSandbox, world: str) -> list[str]:
    return [sys.executable, "-m", "websim.cli", "serve", "--ws-port", str(box.ws_port),
            "--http-port", str(box.http_port), "--world", world, "--admin-token", ADMIN_TOKEN]


def server_env() -> dict[str, str]:
    return {**os.environ, "PYTHONUNBUFFERED": "1",
            "XDG_DATA_HOME": tempfile.mkdtemp(prefix="websim-data-")}


def last_json(result: ControllerResult) -> Any:
    """The JSON document a controller printed last."""
    lines = [line for line in result.output_tail.splitlines() if line.startswith("{")]
    assert lines, result.output_tail
    return json.loads(lines[-1])


# --- the network: its own simulator and nothing else -------------------------------------

SIMULATOR_CLIENT = """
    import json, os, socket, time, urllib.request
    import roslibpy

    report = {"started": time.time()}
    url = os.environ["WEBSIM_URL"]
    host, port = url.split("//")[1].split(":")
    client = roslibpy.Ros(host=host, port=int(port))
    client.run(timeout=30)
    odom = []
    topic = roslibpy.Topic(client, "/odom", "nav_msgs/Odometry")
    topic.subscribe(odom.append)
    deadline = time.time() + 30
    while len(odom) < 3 and time.time() < deadline:
        time.sleep(0.05)
    report["odom"] = len(odom)
    client.terminate()
    with urllib.request.urlopen("http://127.0.0.1:8080/healthz", timeout=10) as answer:
        report["world"] = json.load(answer)["world"]
    with open("/proc/net/dev") as devices:
        report["interfaces"] = sorted(line.split(":")[0].strip()
                                      for line in devices.readlines()[2:])
    report["host_port"] = {}
    for port in map(int, os.environ.get("HOST_PORTS", "").split(",") if os.environ.get(
            "HOST_PORTS") else []):
        try:
            socket.create_connection(("127.0.0.1", port), timeout=5).close()
            report["host_port"][port] = "connected"
        except OSError as error:
            report["host_port"][port] = type(error).__name__
    seen = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            seen.append(open(f"/proc/{pid}/cmdline", "rb").read().replace(b"\\0", b" ").decode())
        except OSError:
            pass
    report["processes"] = seen
    time.sleep(float(os.environ.get("HOLD_S", "0")))
    report["ended"] = time.time()
    print(json.dumps(report), flush=True)
"""


@needs_sandbox
def test_the_controller_reaches_its_own_simulator_and_nothing_else(tmp_path: Path) -> None:
    """A roslibpy controller gets /odom from the websim serve started inside its network
    namespace, at WEBSIM_URL; a server on the host's 127.0.0.1 refuses it (it is not
    there: the namespace has only its own loopback), and it sees no simulator process."""
    folder = submission(tmp_path / "alice", SIMULATOR_CLIENT)
    accepted: list[object] = []
    with socket.create_server(("127.0.0.1", 0)) as host_server:
        host_port = host_server.getsockname()[1]
        host_server.settimeout(0.1)
        with SubmissionSandbox(folder, limits=SandboxLimits(wall_time_s=GENEROUS_WALL_S)) as box:
            box.start_server(serve_argv(box, "maze"), env=server_env())
            result = box.run_controller(["python3", "main.py"],
                                        env={"HOST_PORTS": str(host_port)})
            server = box.stop_server()
        with contextlib.suppress(TimeoutError):
            accepted.append(host_server.accept())
    assert result.ended_by == "exit" and result.exit_code == 0, result.output_tail
    report = last_json(result)
    assert report["odom"] >= 3
    assert report["world"] == "maze"
    assert report["interfaces"] == ["lo"]
    assert report["host_port"] == {str(host_port): "ConnectionRefusedError"}
    assert accepted == []
    assert not any("websim" in command for command in report["processes"]), report
    assert result.sandboxed and "bubblewrap" in result.isolation
    assert server.exit_code == 0, server.output_tail
    assert "websim: ready" in server.output_tail


@needs_sandbox
def test_two_sandboxes_run_at_once_on_the_same_ports(tmp_path: Path) -> None:
    """Two simulators listen on 9090 and 8080 at the same time, each in its own namespace;
    two controllers, running at once, each reach their own (worlds maze and corridor)."""
    boxes = [SubmissionSandbox(submission(tmp_path / name, SIMULATOR_CLIENT),
                               limits=SandboxLimits(wall_time_s=GENEROUS_WALL_S))
             for name in ("alice", "bob")]
    results: dict[str, ControllerResult] = {}
    with boxes[0] as first, boxes[1] as second:
        assert first.ws_port == second.ws_port and first.http_port == second.http_port
        first.start_server(serve_argv(first, "maze"), env=server_env())
        second.start_server(serve_argv(second, "corridor"), env=server_env())

        def grade(name: str, box: SubmissionSandbox) -> None:
            results[name] = box.run_controller(["python3", "main.py"], env={"HOLD_S": "3"})

        threads = [threading.Thread(target=grade, args=("maze", first)),
                   threading.Thread(target=grade, args=("corridor", second))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        for box in (first, second):
            assert box.stop_server().exit_code == 0
    reports = {name: last_json(result) for name, result in results.items()}
    for name, report in reports.items():
        assert results[name].exit_code == 0, results[name].output_tail
        assert report["world"] == name
        assert report["odom"] >= 3
    maze, corridor = reports["maze"], reports["corridor"]
    assert maze["started"] < corridor["ended"] and corridor["started"] < maze["ended"], \
        "the two controllers did not run at the same time"


FINISHING_SIMULATOR = """
import signal, sys, time
from pathlib import Path
signal.signal(signal.SIGTERM, lambda *_: sys.exit(15))  # cut short: exits 15, no record
print("{ready}", flush=True)
time.sleep(0.5)  # the run ends; its record takes a while to write
time.sleep(float(sys.argv[2]))
Path(sys.argv[1]).write_text("the whole record")
"""


@needs_sandbox
@pytest.mark.parametrize("ending", [True, False])
def test_a_simulator_that_ended_its_run_is_let_finish_its_record(tmp_path: Path,
                                                                 ending: bool) -> None:
    """A graded run's simulator ends the run itself, then writes its record (truth.json's
    notes, the recording's end) while it exits; the controller may be gone before that. The
    grader waits for a simulator that is ending (``stop_server(ending=True)``: its run.json is
    written) before any SIGTERM, which would cut the record short; one that is not ending is
    stopped at once."""
    record = tmp_path / "record.txt"
    script = tmp_path / "simulator.py"
    script.write_text(FINISHING_SIMULATOR.replace("{ready}", READY_TEXT))
    folder = submission(tmp_path / "alice", "print('done')")
    with SubmissionSandbox(folder, limits=SandboxLimits(wall_time_s=GENEROUS_WALL_S)) as box:
        box.start_server([sys.executable, str(script), str(record), "1.5"], env=server_env())
        assert box.run_controller(["python3", "main.py"]).exit_code == 0
        started = time.monotonic()
        outcome = box.stop_server(ending=ending)
    if ending:
        assert outcome.exit_code == 0 and record.read_text() == "the whole record"
        assert time.monotonic() - started < SERVER_STOP_TIMEOUT_S
    else:
        assert outcome.exit_code == 15 and not record.exists()


RCLPY_CLIENT = """
    import time
    import rclpy
    from nav_msgs.msg import Odometry

    rclpy.init()
    node = rclpy.create_node("student")
    odom = []
    node.create_subscription(Odometry, "/odom", odom.append, 10)
    deadline = time.time() + 60
    while len(odom) < 3 and time.time() < deadline:
        rclpy.spin_once(node, timeout_sec=0.2)
    print("odom", len(odom), odom[-1].header.frame_id if odom else None, flush=True)
"""


@needs_sandbox
def test_an_rclpy_controller_reaches_its_simulators_ros_graph(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """websim serve --ros in the namespace and an rclpy node in the sandbox find each other
    over DDS (the grader's environment keeping discovery on LOCALHOST, as the ROS tests and
    websim serve's default do)."""
    pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
    monkeypatch.setenv("ROS_DOMAIN_ID", "0")  # a namespace of its own: no other test is there
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    folder = submission(tmp_path / "alice", RCLPY_CLIENT)
    with SubmissionSandbox(folder, limits=SandboxLimits(wall_time_s=GENEROUS_WALL_S)) as box:
        box.start_server([*serve_argv(box, "empty"), "--ros"], env=server_env())
        result = box.run_controller(["python3", "main.py"])
        assert box.stop_server().exit_code == 0
    assert result.exit_code == 0, result.output_tail
    assert "odom 3 odom" in result.output_tail


@needs_sandbox
def test_a_simulator_that_does_not_start_is_reported_with_its_output(tmp_path: Path) -> None:
    folder = submission(tmp_path / "alice", "print('never run')")
    with SubmissionSandbox(folder) as box, pytest.raises(SimulatorStartError) as failure:
        box.start_server([sys.executable, "-m", "websim.cli", "serve", "--world", "nowhere"],
                         env=server_env())
    assert "exited with code" in str(failure.value)
    assert "nowhere" in str(failure.value)


@needs_sandbox
def test_the_simulator_ending_its_run_stops_the_controller(tmp_path: Path) -> None:
    folder = submission(tmp_path / "alice", "import time; time.sleep(3600)")
    with SubmissionSandbox(folder, limits=SandboxLimits(wall_time_s=GENEROUS_WALL_S)) as box:
        box.start_server([sys.executable, "-c", "import time; print('ready', flush=True); "
                          "time.sleep(1)"], ready="ready")
        result = box.run_controller(["python3", "main.py"])
    assert result.ended_by == "server_exit"
    assert result.reason == "stopped when its simulator's run ended"


# --- files: its own copy, nothing of anyone else's ---------------------------------------

PRYING = """
    import json, os
    report = {}
    def attempt(name, action):
        try:
            report[name] = repr(action())
        except OSError as error:
            report[name] = type(error).__name__
    for name, path in json.loads(os.environ["READ"]).items():
        attempt("read " + name, lambda: open(path).read())
    for name, path in json.loads(os.environ["LIST"]).items():
        attempt("list " + name, lambda: sorted(os.listdir(path)))
    for name, path in json.loads(os.environ["WRITE"]).items():
        attempt("write " + name, lambda: open(path, "w").write("mine"))
    report["env"] = sorted(os.environ)
    report["uid"] = os.getuid()
    report["cwd"] = os.getcwd()
    print(json.dumps(report), flush=True)
"""


@needs_sandbox
def test_a_submission_reads_and_writes_nothing_but_its_copy(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Another student's folder, the instructor's token, the grade output (where the
    recording goes), the system, /root and /proc of others: absent or refused; its own copy
    and its private /tmp: writable, without touching the original or the host's /tmp."""
    submissions = tmp_path / "submissions"
    bob = submission(submissions / "bob", "print('bob')", **{"secret.txt": "bob's answer"})
    token = tmp_path / "instructor" / "token.txt"
    token.parent.mkdir()
    token.write_text("instructor-token")
    grade_out = tmp_path / "grade-out" / "alice"
    grade_out.mkdir(parents=True)
    (grade_out / "recording.mcap").write_text("the recording")
    course = tmp_path / "course"  # made visible (a shared library), with a private folder in it
    (course / "private").mkdir(parents=True)
    (course / "shared.txt").write_text("for everyone")
    (course / "private" / "key.txt").write_text("course key")
    marker = f"websim-sandbox-test-{os.getpid()}"
    monkeypatch.setenv("INSTRUCTOR_TOKEN", "instructor-token")
    alice = submission(submissions / "alice", PRYING, **{"notes.txt": "alice's notes"})
    env = {
        "READ": json.dumps({
            "bob": str(bob / "secret.txt"), "token": str(token), "own": "notes.txt",
            "recording": str(grade_out / "recording.mcap"), "shadow": "/etc/shadow",
            "init environ": "/proc/1/environ", "course": str(course / "shared.txt"),
            "course private": str(course / "private" / "key.txt")}),
        "LIST": json.dumps({"submissions": str(submissions), "root": "/root",
                            "home": "/home", "var": "/var"}),
        "WRITE": json.dumps({
            "own": "output.txt", "tmp": f"/tmp/{marker}", "handed in": "/submission/x.txt",
            "recording": str(grade_out / "recording.mcap"), "usr": "/usr/websim-sandbox",
            "etc": "/etc/websim-sandbox", "python": f"{sys.prefix}/websim-sandbox",
            "bob": str(bob / "secret.txt")}),
    }
    result = run(alice, env=env, visible_paths=[course], hidden_paths=[course / "private",
                                                                       submissions, grade_out])
    assert result.exit_code == 0, result.output_tail
    report = last_json(result)
    for name in ("bob", "token", "recording"):
        assert report[f"read {name}"] == "FileNotFoundError", name
    assert report["read own"] == repr("alice's notes")
    assert report["read course"] == repr("for everyone")
    assert report["read course private"] == "PermissionError"
    assert report["read shadow"] == "PermissionError"
    assert report["read init environ"] == "PermissionError"
    assert report["list submissions"] == "FileNotFoundError"
    assert report["list home"] == "['student']"  # its own, not the machine's /home
    assert report["list var"] == "FileNotFoundError"
    python_in_root = sorted({Path(path).parts[2] for path in visible_paths([])
                             if path.startswith("/root/")})
    assert report["list root"] == repr(python_in_root)  # only the Python that runs websim
    assert report["write own"] == "4" and report["write tmp"] == "4"
    for name in ("usr", "etc", "python"):
        assert report[f"write {name}"] in ("OSError", "PermissionError"), name
    for name in ("recording", "bob"):
        assert report[f"write {name}"] == "FileNotFoundError", name
    assert report["write handed in"] == "OSError"  # read-only: the copy home is writable
    assert report["uid"] >= 60000 and report["cwd"] == "/home/student"
    assert "INSTRUCTOR_TOKEN" not in report["env"]
    assert set(report["env"]) >= {"WEBSIM_URL", "READ", "PATH", "HOME"}
    # nothing escaped: the original folders, the recording and the host's /tmp unchanged
    assert sorted(path.name for path in alice.iterdir()) == ["main.py", "notes.txt"]
    assert (bob / "secret.txt").read_text() == "bob's answer"
    assert (grade_out / "recording.mcap").read_text() == "the recording"
    assert not (Path(tempfile.gettempdir()) / marker).exists()


def test_the_controller_environment_is_cleared_to_what_it_needs() -> None:
    grader = {"PATH": f"{sys.prefix}/bin:/root/.cargo/bin:/usr/bin", "HOME": "/root",
              "INSTRUCTOR_TOKEN": "secret", "ROS_DOMAIN_ID": "7",
              "PYTHONPATH": f"/work/checkout:{sys.prefix}/lib/extra"}
    env = controller_environment({"WEBSIM_SETPOINT_RAD": "1.5"}, home="/home/student",
                                 visible=visible_paths([]), sandboxed=True, grader_env=grader)
    assert env["PATH"] == f"{os.path.realpath(sys.prefix)}/bin:/usr/bin" or \
        env["PATH"] == f"{sys.prefix}/bin:/usr/bin"
    assert env["HOME"] == "/home/student" and env["WEBSIM_SETPOINT_RAD"] == "1.5"
    assert env["ROS_DOMAIN_ID"] == "7"
    assert "INSTRUCTOR_TOKEN" not in env
    assert env["PYTHONPATH"] == f"{sys.prefix}/lib/extra"  # the checkout's entry dropped
    with pytest.raises(ValueError, match="invalid environment variable"):
        controller_environment({"A=B": "1"}, home="/h", visible=(), sandboxed=True)


def test_visible_paths_are_absolute_existing_and_never_the_whole_system(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="whole file system"):
        visible_paths(["/"])
    with pytest.raises(ValueError, match="absolute"):
        visible_paths(["relative/folder"])
    with pytest.raises(ValueError, match="does not exist"):
        visible_paths([str(tmp_path / "missing")])
    (tmp_path / "outer" / "inner").mkdir(parents=True)
    paths = visible_paths([tmp_path / "outer" / "inner", tmp_path / "outer", "/usr/share"])
    assert str(tmp_path / "outer") in paths
    assert str(tmp_path / "outer" / "inner") not in paths and "/usr/share" not in paths


# --- limits ------------------------------------------------------------------------------

@needs_sandbox
def test_a_fork_bomb_is_held_at_the_process_limit_and_cleaned_up(tmp_path: Path) -> None:
    """A fork bomb that retries reaches the process limit and no further; the wall-clock
    limit ends it, and no process of its user is left on the machine."""
    folder = submission(tmp_path / "bomb", """
        import os, time
        while True:
            try:
                os.fork()
            except OSError:
                time.sleep(0.01)
    """)
    limits = SandboxLimits(processes=32, wall_time_s=5.0)
    with SubmissionSandbox(folder, limits=limits) as box:
        result = box.run_controller(["python3", "main.py"])
        assert box.uid is not None and usage(uid=box.uid).pids == ()
    assert result.ended_by == "wall_time"
    assert "processes" in result.limits_hit
    assert result.peak_tasks is not None and result.peak_tasks <= limits.processes
    assert "the process limit (32 processes and threads)" in result.reason


@needs_sandbox
def test_a_shell_fork_bomb_is_contained(tmp_path: Path) -> None:
    folder = submission(tmp_path / "bomb", "")
    limits = SandboxLimits(processes=40, wall_time_s=4.0)
    with SubmissionSandbox(folder, limits=limits) as box:
        result = box.run_controller(["bash", "-c", "bomb() { bomb | bomb & }; bomb; wait"])
    assert result.ended_by in ("wall_time", "exit")
    assert "processes" in result.limits_hit
    assert result.peak_tasks is not None and result.peak_tasks <= limits.processes


@needs_sandbox
def test_allocating_8_gb_fails_and_is_reported(tmp_path: Path) -> None:
    folder = submission(tmp_path / "greedy", "block = bytearray(8 * 1024 ** 3)")
    result = run(folder, SandboxLimits(wall_time_s=GENEROUS_WALL_S))
    assert result.ended_by == "exit" and result.exit_code == 1
    assert "MemoryError" in result.output_tail
    assert "memory" in result.limits_hit
    assert result.reason == "exited with code 1; reached the memory limit (4 GiB)"


@needs_sandbox
def test_processes_over_the_memory_limit_together_are_stopped(tmp_path: Path) -> None:
    """Four processes of 100 MiB each, every one within its address-space limit, hold more
    than the 256 MiB all of them may: the sampled sum stops the run."""
    folder = submission(tmp_path / "greedy", """
        import os, time
        for _ in range(3):
            if os.fork() == 0:
                break
        block = b"\\1" * (100 * 1024 * 1024)
        time.sleep(3600)
    """)
    with SubmissionSandbox(folder, limits=SandboxLimits(memory_bytes=256 * MIB,
                                                        wall_time_s=GENEROUS_WALL_S)) as box:
        result = box.run_controller(["python3", "main.py"])
        counted_by_cgroup = box._cgroup is not None
    assert result.ended_by == "memory" and result.peak_memory_bytes is not None
    if counted_by_cgroup:  # the kernel holds the limit: it kills one, the sandbox the rest
        assert result.oom_killed and result.peak_memory_bytes > 100 * MIB
        assert result.reason.startswith("stopped: its processes needed more than the memory "
                                        "limit (256 MiB) together")
    else:
        assert result.peak_memory_bytes > 256 * MIB
        assert result.reason.startswith("stopped: its processes held ")
        assert "over the memory limit (256 MiB)" in result.reason


@needs_sandbox
def test_100_mb_of_output_is_truncated_to_its_tail(tmp_path: Path) -> None:
    folder = submission(tmp_path / "loud", """
        import sys
        line = b"x" * 1023 + b"\\n"
        for _ in range(100 * 1024 - 1):
            sys.stdout.buffer.write(line)
        sys.stdout.buffer.write(b"the end".ljust(1023, b".") + b"\\n")
    """)
    limits = SandboxLimits(wall_time_s=GENEROUS_WALL_S)
    result = run(folder, limits)
    assert result.exit_code == 0
    assert result.output_bytes == 100 * MIB
    assert result.output_truncated and "output" in result.limits_hit
    assert len(result.output_tail) == limits.output_tail_bytes
    assert result.output_tail.rstrip().endswith("the end" + "." * 1016)
    assert "the last 64 KiB of 100 MiB kept" in result.reason


@needs_sandbox
def test_a_hanging_controller_is_stopped_at_the_wall_clock_limit(tmp_path: Path) -> None:
    """It and the daemon it left in a session of its own are killed; the reason says so."""
    folder = submission(tmp_path / "hang", """
        import os, time
        if os.fork() == 0:
            os.setsid()
            if os.fork() == 0:
                time.sleep(3600)
            os._exit(0)
        print("waiting forever", flush=True)
        time.sleep(3600)
    """)
    with SubmissionSandbox(folder, limits=SandboxLimits(wall_time_s=2.0)) as box:
        result = box.run_controller(["python3", "main.py"])
        assert box.uid is not None and usage(uid=box.uid).pids == ()
    assert result.ended_by == "wall_time"
    assert 2.0 <= result.wall_time_s < 60.0
    (folder / "main.py").write_text(textwrap.dedent("""
        import os, time
        if os.fork() == 0:
            os.setsid()
            time.sleep(3600)
        print("leaving a daemon", flush=True)
    """))
    with SubmissionSandbox(folder, limits=SandboxLimits(wall_time_s=GENEROUS_WALL_S)) as box:
        left = box.run_controller(["python3", "main.py"])
        assert left.exit_code == 0 and "leaving a daemon" in left.output_tail
        assert box.uid is not None and usage(uid=box.uid).pids == ()
    assert result.reason == "stopped at the wall-clock limit (2 s)"
    assert "waiting forever" in result.output_tail


@needs_sandbox
def test_cpu_time_and_file_size_limits_are_reported(tmp_path: Path) -> None:
    spin = submission(tmp_path / "spin", "while True: pass")
    result = run(spin, SandboxLimits(cpu_time_s=1, wall_time_s=GENEROUS_WALL_S))
    assert result.signal == "SIGXCPU" and "cpu_time" in result.limits_hit
    assert result.reason == "killed by SIGXCPU; reached the CPU-time limit (1 s per process)"
    big = submission(tmp_path / "big", "open('big.bin', 'wb').write(b'x' * 2 * 1024 * 1024)")
    result = run(big, SandboxLimits(file_size_bytes=MIB, wall_time_s=GENEROUS_WALL_S))
    assert result.exit_code == 1 and "File too large" in result.output_tail
    assert "file_size" in result.limits_hit


@needs_sandbox
def test_what_a_controller_writes_is_bounded_in_all(tmp_path: Path) -> None:
    """Files within the file-size limit, but more of them than its home holds: the home
    fills, not the machine's disk; a submission larger than the home does not start."""
    folder = submission(tmp_path / "writer", """
        for index in range(8):
            with open(f"part{index}.bin", "wb") as part:
                part.write(b"x" * 1024 * 1024)
    """)
    limits = SandboxLimits(home_bytes=4 * MIB, wall_time_s=GENEROUS_WALL_S)
    result = run(folder, limits)
    assert result.exit_code == 1 and "No space left on device" in result.output_tail
    assert result.limits_hit == ("disk",)
    assert "the disk limit (4 MiB for its home, 64 MiB for /tmp)" in result.reason
    (folder / "data.bin").write_bytes(b"x" * 5 * MIB)
    with pytest.raises(SubmissionRefusedError, match=r"the submission is more than 5 MiB .*"
                       r"more than the 2 MiB a submission may be"):
        run(folder, limits)  # refused before anything is copied: half the home at most


# --- without bubblewrap -----------------------------------------------------------------

def test_without_bubblewrap_the_sandbox_refuses_with_the_install_hint(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A PATH without bwrap (prlimit only): refused with the hint, unless no_sandbox, whose
    run is recorded as unsandboxed and still stopped at its wall-clock limit with its
    whole process group."""
    tools = tmp_path / "bin"
    tools.mkdir()
    prlimit = shutil.which("prlimit")
    assert prlimit is not None, "prlimit (util-linux) is part of every Debian"
    (tools / "prlimit").symlink_to(prlimit)
    folder = submission(tmp_path / "alice", """
        import os, subprocess, sys, time
        subprocess.Popen([sys.executable, "-c", "import time; time.sleep(3600)"])
        print("pid", os.getpid(), flush=True)
        time.sleep(3600)
    """)
    monkeypatch.setenv("PATH", f"{tools}:{os.path.dirname(sys.executable)}")
    with pytest.raises(SandboxUnavailableError) as refusal:
        SubmissionSandbox(folder)
    assert "apt-get install bubblewrap" in str(refusal.value)
    assert "--no-sandbox" in str(refusal.value)
    with SubmissionSandbox(folder, no_sandbox=True,
                           limits=SandboxLimits(wall_time_s=3.0)) as box:
        assert box.ws_port != box.http_port
        result = box.run_controller([sys.executable, "main.py"])
    assert not result.sandboxed
    assert result.isolation.startswith("none (--no-sandbox)")
    assert result.reason == "stopped at the wall-clock limit (3 s) (ran without a sandbox)"
    session = int(result.output_tail.split("pid ")[1].split()[0])
    assert usage(session=session).pids == ()


# --- the results, from what was observed -------------------------------------------------

def observed(**fields: Any) -> Observed:
    defaults: dict[str, Any] = dict(exit_status=0, by_signal_code=True, stopped_by=None,
                                    wall_time_s=1.0, peak_tasks=1, peak_memory_bytes=MIB,
                                    output_tail=b"", output_bytes=0)
    return Observed(**{**defaults, **fields})


def result_of(sandboxed: bool = True, **fields: Any) -> ControllerResult:
    return ControllerResult.build(observed(**fields), sandboxed=sandboxed, isolation="test",
                                  command=("python3", "main.py"), limits=SandboxLimits())


def test_results_decode_signals_as_bubblewrap_and_subprocess_report_them() -> None:
    killed = result_of(exit_status=137)
    assert (killed.ended_by, killed.signal, killed.exit_code) == ("signal", "SIGKILL", None)
    assert killed.reason == "killed by SIGKILL"
    unsandboxed = result_of(sandboxed=False, by_signal_code=False, exit_status=-9)
    assert unsandboxed.signal == "SIGKILL"
    assert unsandboxed.reason == "killed by SIGKILL (ran without a sandbox)"
    plain = result_of(sandboxed=False, by_signal_code=False, exit_status=200)
    assert (plain.exit_code, plain.signal) == (200, None)
    assert result_of(exit_status=0).reason == "exited with code 0"
    assert result_of(exit_status=None, stopped_by="wall_time").limits_hit == ("wall_time",)


def test_results_name_the_limits_a_controller_reached() -> None:
    bomb = result_of(exit_status=1, peak_tasks=128,
                     output_tail=b"BlockingIOError: [Errno 11] Resource temporarily unavailable")
    assert bomb.limits_hit == ("processes",)
    assert bomb.reason == ("exited with code 1; reached the process limit (128 processes and "
                           "threads)")
    files = result_of(exit_status=1, output_tail=b"OSError: [Errno 24] Too many open files")
    assert files.limits_hit == ("open_files",)
    assert result_of(exit_status=128 + 25).limits_hit == ("file_size",)  # SIGXFSZ
    assert result_of(exit_status=0, output_bytes=65 * 1024).limits_hit == ("output",)
    assert result_of(exit_status=0).limits_hit == ()


def test_the_docs_state_the_limits_in_force() -> None:
    """docs/grading.md's table of limits and the figures around it are the code's."""
    doc = (Path(__file__).resolve().parent.parent / "docs" / "grading.md").read_text()
    limits = SandboxLimits()
    rows = {
        "wall_time_s": f"{limits.wall_time_s:g} s",
        "cpu_time_s": f"{limits.cpu_time_s} s per process",
        "memory_bytes": size_text(limits.memory_bytes),
        "processes": f"{limits.processes} processes and threads",
        "open_files": f"{limits.open_files} per process",
        "file_size_bytes": f"{size_text(limits.file_size_bytes)} per file",
        "home_bytes": size_text(limits.home_bytes),
        "tmp_bytes": f"{size_text(limits.tmp_bytes)} each",
        "output_tail_bytes": size_text(limits.output_tail_bytes),
    }
    for name, default in rows.items():
        assert f"| `{name}` | {default} |" in doc, name
    assert f"SIGKILL {CPU_KILL_GRACE_S} s later" in doc
    assert f"sampled every {SAMPLE_PERIOD_S:g} s" in doc
    assert f"ids {FIRST_UID}-{FIRST_UID + UID_COUNT - 1}" in doc
    assert f"same ports inside ({PRIVATE_WS_PORT}, {PRIVATE_HTTP_PORT})" in doc


def test_limits_refuse_nonsense() -> None:
    with pytest.raises(ValueError, match="wall_time_s"):
        SandboxLimits(wall_time_s=0)
    with pytest.raises(ValueError, match="processes"):
        SandboxLimits(processes=0)
    with pytest.raises(ValueError, match="open_files must be at least 16"):
        SandboxLimits(open_files=3)


# --- the kernel: namespaces, system calls, socket buffers ---------------------------------

ESCAPES = """
    import ctypes, errno, json, os, socket, subprocess
    libc = ctypes.CDLL(None, use_errno=True)
    report = {}
    def errno_of(call, *args):
        result = call(*args)
        return 0 if result >= 0 else errno.errorcode[ctypes.get_errno()]
    report["unshare_command"] = subprocess.run(
        ["unshare", "--user", "--map-root-user", "id"], capture_output=True,
        text=True).returncode
    report["unshare_user"] = errno_of(libc.unshare, 0x10000000)
    report["unshare_net"] = errno_of(libc.unshare, 0x40000000)
    report["mount"] = errno_of(libc.mount, b"none", b"/tmp", b"tmpfs", 0, None)
    report["ptrace"] = errno_of(libc.ptrace, 16, 1, None, None)  # PTRACE_ATTACH to pid 1
    report["bpf"] = errno_of(libc.syscall, 321, 0, None, 0)
    report["io_uring_setup"] = errno_of(libc.syscall, 425, 8, None)
    report["keyctl"] = errno_of(libc.syscall, 250, 0, 0, 0, 0, 0)
    for name, family, kind in (("packet", 17, socket.SOCK_RAW),
                               ("bluetooth", 31, socket.SOCK_STREAM),
                               ("alg", 38, socket.SOCK_SEQPACKET)):
        try:
            socket.socket(family, kind).close()
            report[name] = 0
        except OSError as error:
            report[name] = errno.errorcode[error.errno]
    ordinary = socket.socket(); ordinary.close()
    a, b = socket.socketpair(); a.close(); b.close()
    child = os.fork()
    if child == 0:
        os._exit(7)
    report["fork"] = os.waitstatus_to_exitcode(os.waitpid(child, 0)[1])
    import threading
    thread = threading.Thread(target=lambda: None); thread.start(); thread.join()
    report["thread"] = "ran"
    report["seccomp"] = open("/proc/self/status").read().split("Seccomp:")[1].split()[0]
    print(json.dumps(report), flush=True)
"""


@needs_sandbox
def test_no_namespace_mount_or_kernel_facility_is_reachable_inside(tmp_path: Path) -> None:
    """``unshare --user --map-root-user`` worked inside before (every capability in a new
    namespace): refused now, as are mounts, ptrace, bpf, io_uring, keyrings and exotic
    sockets; forks, threads and ordinary sockets work."""
    folder = submission(tmp_path / "mallory", ESCAPES)
    result = run(folder, SandboxLimits(wall_time_s=GENEROUS_WALL_S))
    assert result.exit_code == 0, result.output_tail
    report = last_json(result)
    assert report["unshare_command"] != 0
    for name in ("unshare_user", "unshare_net", "mount", "ptrace", "bpf", "io_uring_setup",
                 "keyctl"):
        assert report[name] == "EPERM", (name, report[name])
    for name in ("packet", "bluetooth", "alg"):
        assert report[name] == "EAFNOSUPPORT", (name, report[name])
    assert report["fork"] == 7 and report["thread"] == "ran"
    assert report["seccomp"] == "2"  # a filter is in force
    assert "system-call filter (seccomp)" in result.isolation


SOCKET_HOG = """
    import socket, sys, time
    kind = sys.argv[1]
    server = socket.socket(); server.bind(("127.0.0.1", 0)); server.listen(512)
    held, queued = [], 0
    try:
        for _ in range(400):
            if kind == "unix":
                a, b = socket.socketpair()
            else:
                a = socket.create_connection(server.getsockname()); b, _ = server.accept()
            for sock in (a, b):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 24)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 24)
            a.setblocking(False)
            try:
                while True:
                    queued += a.send(b"x" * 65536)
            except OSError:
                pass
            held += [a, b]
            print("queued", queued, flush=True)
    except OSError as error:
        print("refused", error, flush=True)
    time.sleep(3600)
"""


@needs_sandbox
@pytest.mark.parametrize("kind", ["unix", "tcp"])
def test_socket_buffers_count_against_the_memory_limit(tmp_path: Path, kind: str) -> None:
    """Sockets that are written and never read held 753 MiB against a 256 MiB limit,
    unseen. Now the kernel's count (the cgroup's: local sockets with the rest of its kernel
    memory, which ends the run; TCP's buffers under a quarter of the limit, where sends
    block) or the sampled socket queues stop it: what it queued stays within the limit."""
    folder = submission(tmp_path / "hog", SOCKET_HOG)
    limits = SandboxLimits(memory_bytes=256 * MIB, wall_time_s=30.0)
    with SubmissionSandbox(folder, limits=limits) as box:
        result = box.run_controller(["python3", "main.py", kind])
    lines = [line for line in result.output_tail.splitlines() if line.startswith("queued")]
    queued = int(lines[-1].split()[1]) if lines else 0
    assert 0 < queued < 256 * MIB + 16 * MIB, (queued, result.reason)
    if kind == "unix":  # counted with its memory: the run ends at the limit (the sandbox
        # stops it, or the kernel kills it first at its cgroup's limit)
        assert result.ended_by == "memory" or (
            result.signal == "SIGKILL" and "memory" in result.limits_hit), result.reason


def test_the_system_call_filter_builds_here() -> None:
    """The BPF program bubblewrap loads (pyseccomp and libseccomp are installed)."""
    from websim.sandbox.syscalls import seccomp_program
    program = seccomp_program()
    assert len(program) % 8 == 0 and len(program) > 200  # BPF instructions are 8 bytes


# --- unprivileged: a grader that is not root ---------------------------------------------

UNPRIVILEGED_UID = 64999
"""The user the unprivileged tests run the grader as (setpriv; no account needed)."""

UNPRIVILEGED_GRADER = """
import json, os, sys, tempfile, textwrap
from pathlib import Path
from websim.sandbox import SandboxLimits, SubmissionSandbox
folder = Path(sys.argv[1])
with SubmissionSandbox(folder, limits=SandboxLimits(processes=64, wall_time_s=120)) as box:
    server_argv = [sys.executable, "-m", "websim.cli", "serve", "--ws-port", "9090",
                   "--http-port", "8080", "--world", "empty"]
    box.start_server(server_argv, env={**os.environ, "PYTHONUNBUFFERED": "1",
                                       "XDG_DATA_HOME": tempfile.mkdtemp()})
    result = box.run_controller(["python3", "main.py"])
    box.stop_server()
print(json.dumps({"reason": result.reason, "uid": box.uid, "tail": result.output_tail,
                  "isolation": result.isolation, "peak_tasks": result.peak_tasks}))
"""

UNPRIVILEGED_CONTROLLER = """
    import json, os, subprocess, time, urllib.request
    report = {"uid": os.getuid()}
    with urllib.request.urlopen("http://127.0.0.1:8080/healthz", timeout=30) as answer:
        report["world"] = json.load(answer)["world"]
    report["unshare"] = subprocess.run(["unshare", "--user", "--map-root-user", "id"],
                                       capture_output=True).returncode
    children = []
    try:
        for _ in range(200):
            pid = os.fork()
            if pid == 0:
                time.sleep(30)
                os._exit(0)
            children.append(pid)
    except OSError as error:
        report["fork_refused_after"] = len(children)
    for pid in children:
        os.kill(pid, 9)
    print(json.dumps(report), flush=True)
"""


@needs_sandbox
def test_a_grader_that_is_not_root_sandboxes_with_user_namespaces(tmp_path: Path) -> None:
    """A student grading on a laptop: the grader as an ordinary user (setpriv to a uid of
    no account). bubblewrap runs unprivileged in a user namespace of its own; the controller
    reaches its simulator, cannot make a user namespace, and its process limit counts its
    own processes (the kernel counts them per user namespace)."""
    work = Path(tempfile.mkdtemp(prefix="websim-unprivileged-"))
    try:
        folder = submission(work / "alice", UNPRIVILEGED_CONTROLLER)
        script = work / "grade.py"
        script.write_text(UNPRIVILEGED_GRADER)
        for path in (work, folder, folder / "main.py", script):
            os.chown(path, UNPRIVILEGED_UID, UNPRIVILEGED_UID)
        python = unprivileged_python(work)
        env = {"PATH": os.environ["PATH"], "HOME": str(work), "LANG": "C.UTF-8",
               "TMPDIR": str(work)}
        done = subprocess.run(
            ["setpriv", f"--reuid={UNPRIVILEGED_UID}", f"--regid={UNPRIVILEGED_UID}",
             "--clear-groups", "--", python, str(script), str(folder)],
            env=env, cwd=work, capture_output=True, text=True, timeout=300, check=False)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
        outcome = json.loads(done.stdout.strip().splitlines()[-1])
        assert outcome["uid"] == UNPRIVILEGED_UID
        assert "in a user namespace of its own" in outcome["isolation"]
        report = json.loads([line for line in outcome["tail"].splitlines()
                             if line.startswith("{")][-1])
        assert report["uid"] == UNPRIVILEGED_UID and report["world"] == "empty arena"
        assert report["unshare"] != 0
        assert 0 < report.get("fork_refused_after", 999) < 64, report
    finally:
        shutil.rmtree(work, ignore_errors=True)


def unprivileged_python(work: Path) -> str:
    """A Python the unprivileged user can run with websim and its dependencies importable.

    This interpreter may live where that user cannot go (pyenv under /root): then a venv of
    the system's Python 3 of the same version, with this environment's packages and this
    checkout added (a .pth file; they are readable by all).
    """
    here = Path(sys.executable).resolve()
    if all(os.access(parent, os.X_OK, effective_ids=False) and parent.stat().st_mode & 0o001
           for parent in here.parents):
        return sys.executable
    system = shutil.which("python3", path="/usr/bin")
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    probe = subprocess.run([system or "false", "-c", "import sys; print(sys.version[:4])"],
                           capture_output=True, text=True, check=False)
    if system is None or not probe.stdout.startswith(version):
        pytest.skip(f"this Python ({here}) is not readable by other users and there is no "
                    f"system python{version} to stand in for it")
    venv = work / "venv"
    subprocess.run([system, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    site_packages = next(path for path in sys.path if path.endswith("site-packages"))
    purelib = next(venv.glob("lib/python*/site-packages"))
    (purelib / "websim-test.pth").write_text(
        f"import site; site.addsitedir({site_packages!r})\n{Path(__file__).parent.parent}\n")
    for path in [venv, *venv.rglob("*")]:
        os.lchown(path, UNPRIVILEGED_UID, UNPRIVILEGED_UID)
    return str(venv / "bin" / "python")
