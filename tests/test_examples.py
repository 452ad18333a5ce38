"""The course examples in ``examples/`` run unmodified against a real ``websim serve``.

Each test starts its own server on the empty world (|x|, |y| <= 3 m), runs one example as a
student would, checks what it printed against the motion it commanded (forward 0.3 m/s, left
0.5 rad/s: an arc of radius 0.6 m), and asks the server itself, with a raw rosbridge client,
whether the robot was left standing.
"""

from __future__ import annotations

import importlib.util
import json
import math
import re
import shutil
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import connect

from chromium import launched_chromium, skip_reason
from conftest import ARENA_HALF_M
from server_process import ServerProcess, start_server

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
ROSLIB = ROOT / "web-interface" / "node_modules" / "roslib" / "build" / "roslib.min.js"
ROSLIB1_MODULES = ROOT / "web-interface" / "node_modules"
"""roslib 1.4.1 and what it needs, as ``npm install roslib@1.4.1`` leaves them (the page's)."""
PAGE_ARGS = ["--disable-features=LocalNetworkAccessChecks"]
"""The page is answered by Playwright, which Chromium counts as a public site: let it reach
the local rosbridge as the served copy would."""
NODE = shutil.which("node")
RUN_TIMEOUT_S = 30.0

ROSLIB2_MODULES = ROOT / "tests" / "node" / "roslib2" / "node_modules"
"""roslib 2.x (ES modules only), installed by scripts/test.sh from tests/node/roslib2's lock."""
ROSLIB2_MIN_NODE = 20
"""roslib 2.x's package.json asks for Node >= 20 (its ES modules use newer syntax)."""


def _node_major() -> int:
    if NODE is None:
        return 0
    version = subprocess.run([NODE, "--version"], capture_output=True, text=True,
                             check=False).stdout
    match = re.match(r"v(\d+)", version)
    return int(match.group(1)) if match else 0


ROSLIB2_SKIP = ("node not installed" if NODE is None else
                f"roslib 2.x needs Node >= {ROSLIB2_MIN_NODE}"
                if _node_major() < ROSLIB2_MIN_NODE else
                None if (ROSLIB2_MODULES / "roslib" / "package.json").exists() else
                "roslib 2.x missing: run npm ci in tests/node/roslib2/ (scripts/test.sh does)")

ARC_RADIUS_M = 0.3 / 0.5
"""The scripts drive at 0.3 m/s and 0.5 rad/s: a circle of radius v/ω through the spawn."""
ARC_TOLERANCE_M = 0.02
"""Odometry integrates with Euler steps (Eq. 1-3, 50 ms): about 1 % off the exact arc."""

ODOM_LINE = re.compile(r"odom (start|end): x=(\S+) m y=(\S+) m yaw=(\S+) rad")


@pytest.fixture
def server() -> Iterator[ServerProcess]:
    running = start_server()
    yield running
    running.stop()


def standing_odom(server: ServerProcess, timeout_s: float = 5.0) -> dict[str, Any]:
    """The first /odom with zero speed, over a raw rosbridge connection; fails after a while."""
    deadline = time.monotonic() + timeout_s
    with connect(server.ws_url, open_timeout=5) as ws:
        ws.send(json.dumps({"op": "subscribe", "topic": "/odom",
                            "type": "nav_msgs/msg/Odometry"}))
        while time.monotonic() < deadline:
            message = json.loads(ws.recv(timeout=timeout_s))
            if message.get("op") != "publish" or message.get("topic") != "/odom":
                continue
            twist = message["msg"]["twist"]["twist"]
            if twist["linear"]["x"] == 0.0 and twist["angular"]["z"] == 0.0:
                return dict(message["msg"])
    raise AssertionError(f"the robot still moves {timeout_s} s after the script stopped it")


def check_drive_output(stdout: str, server: ServerProcess) -> None:
    """The script connected, saw the scan and odometry, drove an arc and stopped the robot."""
    assert "Connected to ROS 2 at" in stdout
    # Spawn at the centre of the 6 m arena: every beam reads at least 3 m (the wall).
    scan = re.search(r"scan: (\d+) beams, nearest (\S+) m, straight ahead (\S+) m", stdout)
    assert scan, stdout
    assert int(scan[1]) == 360
    assert float(scan[2]) == pytest.approx(ARENA_HALF_M, abs=1e-3)
    assert float(scan[3]) == pytest.approx(ARENA_HALF_M, abs=1e-3)
    poses = {match[1]: tuple(float(v) for v in match.groups()[1:])
             for match in ODOM_LINE.finditer(stdout)}
    assert poses["start"] == (0.0, 0.0, 0.0), stdout
    x, y, yaw = poses["end"]
    assert 0.5 < yaw < 1.5, stdout  # about 2 s at 0.5 rad/s
    assert math.hypot(x, y - ARC_RADIUS_M) == pytest.approx(ARC_RADIUS_M, abs=ARC_TOLERANCE_M)
    assert "stop: published a zero Twist" in stdout
    assert re.search(r"received (\d+) scans", stdout)

    odom = standing_odom(server)
    assert odom["pose"]["pose"]["position"]["x"] == pytest.approx(x, abs=0.02)


@pytest.mark.skipif(NODE is None, reason="node not installed")
@pytest.mark.skipif(not ROSLIB.exists(), reason="roslib missing: run npm ci in web-interface/")
def test_node_course_snippets_drive_the_robot(server: ServerProcess, tmp_path: Path) -> None:
    """As a student runs it: copied into a folder of theirs, roslib 1.4.1 installed beside it."""
    assert NODE is not None
    script = student_folder(tmp_path, "course_snippets.js", ROSLIB1_MODULES)
    result = subprocess.run([NODE, script.name, server.ws_url], cwd=tmp_path,
                            capture_output=True, text=True, timeout=RUN_TIMEOUT_S, check=False)
    assert result.returncode == 0, result.stderr
    check_drive_output(result.stdout, server)


def test_roslibpy_course_snippets_drive_the_robot(server: ServerProcess) -> None:
    pytest.importorskip("roslibpy")
    result = subprocess.run([sys.executable, str(EXAMPLES / "course_snippets.py"),
                             "127.0.0.1", str(server.ws_port)],
                            capture_output=True, text=True, timeout=RUN_TIMEOUT_S, check=False)
    assert result.returncode == 0, result.stderr
    check_drive_output(result.stdout, server)


def test_scripts_fail_with_the_reason_when_nothing_listens(tmp_path: Path) -> None:
    from server_process import free_port

    url = f"ws://127.0.0.1:{free_port()}"
    commands = [[sys.executable, str(EXAMPLES / "course_snippets.py"), url]]
    if NODE is not None and ROSLIB.exists():
        script = student_folder(tmp_path, "course_snippets.js", ROSLIB1_MODULES)
        commands.append([NODE, str(script), url])
    for command in commands:
        result = subprocess.run(command, capture_output=True, text=True,
                                timeout=RUN_TIMEOUT_S, check=False)
        assert result.returncode != 0, command
        assert result.stderr, command


def student_folder(tmp_path: Path, script: str, node_modules: Path) -> Path:
    """A student's folder: ``examples/<script>`` copied in, with ``node_modules`` beside it
    (as ``npm install roslib`` leaves it; a link to ours). Node resolves ``import 'roslib'``
    from the script's folder upwards, NODE_PATH aside; returns the copied script."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    copied = tmp_path / script
    shutil.copyfile(EXAMPLES / script, copied)
    (tmp_path / "node_modules").symlink_to(node_modules, target_is_directory=True)
    return copied


def run_roslib2_snippets(tmp_path: Path, url: str) -> subprocess.CompletedProcess[str]:
    """``node course_snippets.mjs URL`` in a student's folder with roslib 2.x installed."""
    assert NODE is not None
    script = student_folder(tmp_path, "course_snippets.mjs", ROSLIB2_MODULES)
    return subprocess.run([NODE, script.name, url], cwd=tmp_path, capture_output=True,
                          text=True, timeout=RUN_TIMEOUT_S, check=False)


@pytest.mark.skipif(ROSLIB2_SKIP is not None, reason=ROSLIB2_SKIP or "")
@pytest.mark.skipif(not ROSLIB.exists(), reason="roslib missing: run npm ci in web-interface/")
def test_each_roslib_loads_only_with_its_own_line(tmp_path: Path) -> None:
    """examples/README.md's one-line difference, in a folder with each version installed:
    1.4.1 is ``require``d and has ROSLIB.Message; 2.x (pinned by the test package) has no
    CommonJS entry, so ``require`` fails (why course_snippets.mjs exists), is ``import``ed, and
    has no ROSLIB.Message (publish plain objects)."""
    assert NODE is not None
    show = "console.log(ROSLIB.REVISION, typeof ROSLIB.Ros, typeof ROSLIB.Message)"

    def node(folder: Path, *args: str) -> subprocess.CompletedProcess[str]:
        assert NODE is not None
        return subprocess.run([NODE, *args], cwd=folder, capture_output=True, text=True,
                              timeout=RUN_TIMEOUT_S, check=False)

    classic, modular = tmp_path / "roslib1", tmp_path / "roslib2"
    for folder, modules in ((classic, ROOT / "web-interface" / "node_modules"),
                            (modular, ROSLIB2_MODULES)):
        folder.mkdir()
        (folder / "node_modules").symlink_to(modules, target_is_directory=True)

    required = node(classic, "-e", f"const ROSLIB = require('roslib'); {show}")
    assert required.stdout.split() == ["1.4.1", "function", "function"], required.stderr
    imported = node(modular, "--input-type=module", "-e",
                    f"import * as ROSLIB from 'roslib'; {show}")
    assert imported.returncode == 0, imported.stderr
    revision, ros, message = imported.stdout.split()
    assert (revision.split(".")[0], ros, message) == ("2", "function", "undefined")
    not_required = node(modular, "-e", "require('roslib')")
    assert not_required.returncode != 0
    assert "ERR_PACKAGE_PATH_NOT_EXPORTED" in not_required.stderr or (
        "ERR_REQUIRE" in not_required.stderr), not_required.stderr


@pytest.mark.skipif(ROSLIB2_SKIP is not None, reason=ROSLIB2_SKIP or "")
def test_roslib2_course_snippets_drive_the_robot(server: ServerProcess, tmp_path: Path) -> None:
    result = run_roslib2_snippets(tmp_path, server.ws_url)
    assert result.returncode == 0, result.stderr
    check_drive_output(result.stdout, server)


@pytest.mark.skipif(ROSLIB2_SKIP is not None, reason=ROSLIB2_SKIP or "")
def test_roslib2_snippets_fail_with_the_reason_when_nothing_listens(tmp_path: Path) -> None:
    from server_process import free_port

    result = run_roslib2_snippets(tmp_path, f"ws://127.0.0.1:{free_port()}")
    assert result.returncode == 1
    assert result.stderr.startswith("Error: "), result.stderr
    assert "ECONNREFUSED" in result.stderr, result.stderr


BROWSER_SKIP = skip_reason([ROSLIB])


@pytest.mark.browser
@pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")
def test_roslibjs_page_drives_the_robot_in_chromium(server: ServerProcess) -> None:
    """The page as its comment says to use it: copied into web-interface/, served by websim
    serve. The copy is simulated by answering that one URL with the file from examples/."""
    from playwright.sync_api import expect

    page_url = f"{server.http_url}/roslibjs_page.html"
    with launched_chromium(PAGE_ARGS) as browser:
        page = browser.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.route(lambda url: url.startswith(page_url), lambda route: route.fulfill(
            path=str(EXAMPLES / "roslibjs_page.html"), content_type="text/html"))
        page.goto(f"{page_url}?url={server.ws_url}")
        expect(page.locator("#status")).to_have_text(
            f"Connected to ROS 2 at {server.ws_url}", timeout=10_000)
        expect(page.locator("#scan")).to_have_text("/scan: 360 beams, nearest 3.000 m",
                                                   timeout=10_000)
        expect(page.locator("#odom")).to_contain_text("x=0.000 m y=0.000 m",
                                                      timeout=10_000)
        page.click("#forward")
        # Polled every animation frame: expect()'s back-off (up to 1 s) can step over
        # the 0.3 m the robot passes at 0.3 m/s.
        page.wait_for_function(
            "parseFloat(document.querySelector('#odom').textContent.split('x=')[1]) >= 0.3",
            timeout=10_000)
        page.click("#stop")
        odom_text = page.locator("#odom").text_content() or ""
        assert errors == []
        # it names its icon (else browsers ask for /favicon.ico, which is not served: a 404)
        icon = page.evaluate("document.querySelector('link[rel=icon]')?.href ?? null")
        assert icon is not None and icon.startswith(server.http_url)
        with urllib.request.urlopen(icon, timeout=10) as response:
            assert response.status == 200
    assert "y=0.000 m yaw=0.000 rad" in odom_text
    odom = standing_odom(server)
    assert 0.3 <= odom["pose"]["pose"]["position"]["x"] < 0.5


# ---- a class robot, with its token (issue 20, section 4) -------------------------------------

def test_the_snippets_drive_a_class_robot_with_its_token_and_say_so_without_it(
        tmp_path: Path) -> None:
    """roslibpy and roslibjs (1.4.1 and 2.x) reach ``ws://HOST:9090/robots/NAME?token=T`` and
    drive it; the token is never printed. Without the token the bridge refuses the commands,
    which none of the libraries shows: the snippet says the robot did not move and why, and
    exits 1 (it used to print its lines and exit 0)."""
    import csv

    links = tmp_path / "links.csv"
    server = start_server(["--class", "2", "--links", str(links)])
    try:
        token = {row["name"]: row["token"] for row in csv.DictReader(links.open())}["robot01"]
        url = f"ws://127.0.0.1:{server.ws_port}/robots/robot01"
        commands = []
        if importlib.util.find_spec("roslibpy") is not None:
            commands.append(([sys.executable, str(EXAMPLES / "course_snippets.py")], None))
        if NODE is not None and ROSLIB.exists():
            script = student_folder(tmp_path / "student", "course_snippets.js", ROSLIB1_MODULES)
            commands.append(([NODE, str(script)], None))
        if ROSLIB2_SKIP is None:
            script = student_folder(tmp_path / "student2", "course_snippets.mjs",
                                    ROSLIB2_MODULES)
            commands.append(([NODE or "node", script.name], script.parent))
        if not commands:
            pytest.skip("neither roslibpy nor node with roslib installed")
        for command, cwd in commands:
            result = subprocess.run([*command, f"{url}?token={token}"], capture_output=True,
                                    text=True, timeout=RUN_TIMEOUT_S, check=False, cwd=cwd)
            assert result.returncode == 0, result.stderr
            assert "Connected to ROS 2 at ws://127.0.0.1" in result.stdout
            assert token not in result.stdout + result.stderr
            end = [match for match in ODOM_LINE.finditer(result.stdout) if match[1] == "end"]
            assert end and abs(float(end[0][4])) > 0.5, result.stdout  # it turned: it drove
            robot = server.health()["robots"]["robot01"]
            assert robot["last_driver"] is not None

            watched = subprocess.run([*command, url], capture_output=True, text=True,
                                     timeout=RUN_TIMEOUT_S, check=False, cwd=cwd)
            assert watched.returncode == 1, (command, watched.stdout, watched.stderr)
            assert "the robot did not move: the bridge refused the commands" in watched.stderr
            assert "ws://HOST:9090/robots/NAME?token=TOKEN" in watched.stderr
    finally:
        server.stop()
