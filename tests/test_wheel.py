"""The wheel: built from this checkout, installed into a fresh venv, run from an empty folder.

``pip install .`` must give a websim that works anywhere: robot parameters, worlds, the page
with its libraries and roslib for Node come with the wheel (``setup.py``, ``physics.shipped``,
``websim.node_roslib``). The wheel is installed with ``--no-deps --no-index`` (no network);
the venv reuses this interpreter's installed dependencies through a ``.pth`` file naming their
folder, whose lines are plain path entries after the venv's own: the import hook of this
checkout's editable install, itself a ``.pth`` file there, never runs, so the venv's ``websim``
command (and every ``python -m websim...`` a grading starts) runs the wheel, as from pipx. It
checks that, then the page, its libraries, ``robot.json``, ``/healthz``, a roslibpy client,
and grading a roslibjs controller with Node, on the command line and by the Code panel's
Submit, with nothing of the checkout (its ``node_modules``) in reach.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import urllib.error
import urllib.request
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import roslibpy

from websim.node_roslib import LEFT_OUT, LOCK_FILE, roslib_closure
from websim.web_files import published_files

from server_process import ServerProcess, start_server, wait_for

PROJECT_DIR = Path(__file__).resolve().parent.parent
CHECKOUT_MODULES = PROJECT_DIR / "web-interface" / "node_modules"
SOLUTIONS = PROJECT_DIR / "examples" / "solutions"
NODE = shutil.which("node")
SANDBOXED = shutil.which("bwrap") is not None and os.geteuid() == 0
"""Where the sandbox can run, grading is sandboxed (as the Code panel's Submit must be)."""

pytestmark = pytest.mark.slow


WEB_SHARE = "websim/_share/web-interface/"
NODE_SHARE = "websim/_share/node_modules/"


@dataclass
class Installed:
    """The built wheel, the command running the websim installed from it, an empty folder."""

    wheel: Path
    command: list[str]
    folder: Path
    site_packages: Path


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Installed]:
    root = tmp_path_factory.mktemp("wheel")
    wheels = root / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(PROJECT_DIR), "--no-deps",
                    "-q", "-w", str(wheels)], check=True, timeout=600)
    wheel, = wheels.glob("websim-*.whl")
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-index",
                    str(wheel)], check=True, timeout=300)
    venv_site = Path(subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True).stdout.strip())
    dependencies = dict.fromkeys([sysconfig.get_paths()["purelib"],
                                  sysconfig.get_paths()["platlib"]])
    (venv_site / "websim_test_dependencies.pth").write_text("\n".join(dependencies) + "\n")
    imported = subprocess.run(
        [str(python), "-c", "import physics, websim; print(physics.__file__, websim.__file__)"],
        cwd=root, capture_output=True, text=True, check=True).stdout.split()
    assert all(path.startswith(str(venv_site)) for path in imported), imported
    empty = root / "elsewhere"
    empty.mkdir()
    yield Installed(wheel, [str(venv / "bin" / "websim")], empty, venv_site)


@pytest.fixture(scope="module")
def server(installed: Installed) -> Iterator[ServerProcess]:
    running = start_server(launcher=installed.command, cwd=str(installed.folder))
    yield running
    running.stop()


def get(url: str) -> tuple[int, bytes]:
    with urllib.request.urlopen(url, timeout=10) as response:
        return response.status, response.read()


def test_the_wheel_carries_parameters_worlds_and_exactly_the_published_page(
        installed: Installed) -> None:
    names = set(zipfile.ZipFile(installed.wheel).namelist())
    assert "physics/_share/config/pi4b_params.yaml" in names
    assert {f"physics/_share/examples/commands/{commands.name}" for commands in
            (PROJECT_DIR / "examples" / "commands").glob("*.yaml")} <= names
    assert {f"physics/_share/worlds/{world.name}" for world in
            (PROJECT_DIR / "worlds").glob("*.yaml")} <= names
    assert {f"physics/_share/examples/scenarios/{scenario.name}" for scenario in
            (PROJECT_DIR / "examples" / "scenarios").glob("*.yaml")} <= names
    assert "grading/scenario.py" in names
    page = {name.removeprefix(WEB_SHARE) for name in names if name.startswith(WEB_SHARE)}
    assert page == set(published_files(PROJECT_DIR / "web-interface"))
    assert "node_modules/roslib/build/roslib.min.js" in page
    assert not any(name.startswith(("tests/", "benchmarks/")) for name in names)


def package_of(name: str) -> str:
    """The top-level package of a path below node_modules (``@scope/name`` or ``name``)."""
    segments = name.split("/")
    return "/".join(segments[:2] if name.startswith("@") else segments[:1])


def test_the_wheel_carries_roslib_for_node_with_its_dependencies_and_no_more(
        installed: Installed) -> None:
    names = {name.removeprefix(NODE_SHARE) for name in
             zipfile.ZipFile(installed.wheel).namelist() if name.startswith(NODE_SHARE)}
    packages = roslib_closure(CHECKOUT_MODULES)
    assert {"roslib", "ws", "socket.io", "eventemitter2"} <= set(packages)
    assert "pyodide" not in packages and "codemirror" not in packages
    assert {package_of(name) for name in names - {LOCK_FILE}} == set(packages)
    for package in packages:
        assert f"{package}/package.json" in names, package
    assert "roslib/src/RosLibNode.js" in names  # roslib's "main" for Node
    assert "engine.io/node_modules/ws/package.json" in names  # npm's nested copy
    assert not any(name.endswith((".d.ts", ".map", ".png")) for name in names), LEFT_OUT
    wheel_modules = installed.site_packages / NODE_SHARE
    assert roslib_closure(wheel_modules) == packages  # its lock: exactly what it carries
    lock = json.loads((wheel_modules / LOCK_FILE).read_text())["packages"]
    assert {package_of(key.removeprefix("node_modules/")) for key in lock} == set(packages)
    assert lock["node_modules/roslib"]["version"] == "1.4.1"


def test_the_installed_server_serves_the_page_and_its_libraries(server: ServerProcess) -> None:
    status, page = get(f"{server.http_url}/")
    assert status == 200 and b"<html" in page
    for library in ("/node_modules/roslib/build/roslib.min.js",
                    "/node_modules/uplot/dist/uPlot.esm.js",
                    "/node_modules/nipplejs/dist/index.js", "/js/main.js", "/css/style.css"):
        assert get(f"{server.http_url}{library}")[0] == 200, library
    status, robot = get(f"{server.http_url}/robot.json")
    assert status == 200 and json.loads(robot)["robot"]["max_linear_mps"] > 0
    assert server.health()["status"] == "ok"


def test_a_roslibpy_client_drives_the_installed_server(server: ServerProcess) -> None:
    client = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
    client.run(timeout=10)
    try:
        received: list[dict] = []
        listener = roslibpy.Topic(client, "/odom", "nav_msgs/msg/Odometry")
        listener.subscribe(received.append)
        wait_for(lambda: received, timeout_s=10, what="/odom from the installed server")
        assert received[-1]["header"]["frame_id"] == "odom"
    finally:
        client.close()  # not terminate(): that stops the one Twisted reactor of the process


def test_worlds_load_by_name_from_the_installed_package(installed: Installed) -> None:
    result = subprocess.run([*installed.command, "demo", "--world", "maze", "--seconds", "1"],
                            cwd=installed.folder, capture_output=True, text=True, timeout=120,
                            check=False)
    assert result.returncode == 0, result.stdout + result.stderr


def test_command_files_load_by_name_from_the_installed_package(installed: Installed) -> None:
    out = installed.folder / "results"
    result = subprocess.run([*installed.command, "compare", "--commands", "step", "--out",
                             str(out)], cwd=installed.folder, capture_output=True, text=True,
                            timeout=300, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert (out / "summary.json").is_file()


def status_of(url: str) -> int:
    try:
        return get(url)[0]
    except urllib.error.HTTPError as error:
        return error.code


def test_the_page_server_publishes_nothing_of_roslib_for_node(server: ServerProcess) -> None:
    for path in ("/node_modules/roslib/package.json", "/node_modules/roslib/src/RosLibNode.js",
                 "/node_modules/.package-lock.json", "/node_modules/ws/lib/websocket.js",
                 "/../node_modules/roslib/package.json", "/%2e%2e/node_modules/ws/index.js"):
        assert status_of(f"{server.http_url}{path}") == 404, path


@pytest.mark.skipif(NODE is None, reason="node not installed (grading a roslibjs controller)")
def test_a_roslibjs_controller_grades_with_the_wheels_roslib(
        installed: Installed, tmp_path: Path) -> None:
    python = str(Path(installed.command[0]).with_name("python"))
    found = subprocess.run([python, "-c", "from websim.node_roslib import node_modules_found; "
                            "print(*node_modules_found())"], cwd=installed.folder,
                           capture_output=True, text=True, check=True).stdout.split()
    assert found == [str(installed.site_packages / NODE_SHARE.rstrip("/"))]
    folder = tmp_path / "student"  # the program alone: no node_modules of its own
    folder.mkdir()
    shutil.copy(SOLUTIONS / "heading_pid.js", folder)
    out = tmp_path / "out"
    result = subprocess.run(
        [*installed.command, "grade", "heading_pid", "--submission", str(folder), "--out",
         str(out), *(() if SANDBOXED else ("--no-sandbox",)), "--", "node", "heading_pid.js"],
        cwd=installed.folder, capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads((out / "heading_pid" / "report.json").read_text())
    assert report["passed"] is True and report["score"] == 1.0, report["reason"]


def submission_done(server: ServerProcess) -> dict[str, Any] | None:
    answer = json.loads(get(f"{server.http_url}/code/submission")[1])
    return answer if answer["state"] in ("done", "failed") else None


@pytest.mark.skipif(NODE is None, reason="node not installed (grading a roslibjs controller)")
def test_the_code_panels_javascript_submit_is_on_and_grades(server: ServerProcess) -> None:
    starters = json.loads(get(f"{server.http_url}/code/starters.json")[1])
    assert starters["submitting"]["languages"]["javascript"] == {"enabled": True, "reason": ""}
    if not SANDBOXED:
        pytest.skip("bubblewrap or root missing: Submit is off where nothing can be sandboxed")
    assert starters["submitting"]["enabled"] is True, starters["submitting"]
    program = {"language": "javascript", "assignment": "heading_pid",
               "text": (SOLUTIONS / "heading_pid.js").read_text()}
    request = urllib.request.Request(f"{server.http_url}/code/submit", method="POST",
                                     data=json.dumps(program).encode(),
                                     headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=10) as response:
        assert response.status == 202
    done = wait_for(lambda: submission_done(server), timeout_s=300,
                    what="the JavaScript submission to be graded")
    assert done["state"] == "done", done
    assert done["result"]["total"] == 1.0, done["result"]
