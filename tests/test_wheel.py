"""The wheel: built from this checkout, installed into a fresh venv, run from an empty folder.

``pip install .`` must give a websim that works anywhere: robot parameters, worlds and the page
with its libraries come with the wheel (``setup.py``, ``physics.shipped``). The venv reuses
this interpreter's installed dependencies (``--system-site-packages``; the wheel is installed
with ``--no-deps --no-index``: no network). This checkout is installed editable here, whose
import hook would shadow the wheel, so the server runs with ``python -S`` (no site hooks) and
exactly two folders on its path: the venv's (the wheel) and the dependencies'. It checks that
websim was imported from the venv, then the page, its libraries, ``robot.json``, ``/healthz``
and a roslibpy client.
"""

from __future__ import annotations

import json
import site
import subprocess
import sys
import sysconfig
import urllib.request
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import roslibpy

from websim.web_files import published_files

from server_process import ServerProcess, start_server, wait_for

PROJECT_DIR = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow

LAUNCHER = """\
import sys
sys.path[:0] = {paths!r}
import physics, websim
for module in (physics, websim):
    assert module.__file__.startswith({venv!r}), module.__file__
sys.argv[0] = "websim"
from websim.cli import main
raise SystemExit(main())
"""


WEB_SHARE = "websim/_share/web-interface/"


@dataclass
class Installed:
    """The built wheel, the command running the websim installed from it, an empty folder."""

    wheel: Path
    command: list[str]
    folder: Path


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Installed]:
    root = tmp_path_factory.mktemp("wheel")
    wheels = root / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(PROJECT_DIR), "--no-deps",
                    "-q", "-w", str(wheels)], check=True, timeout=600)
    wheel, = wheels.glob("websim-*.whl")
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)],
                   check=True, timeout=120)
    python = venv / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-index",
                    str(wheel)], check=True, timeout=300)
    venv_site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig."
                                "get_paths()['purelib'])"], capture_output=True, text=True,
                               check=True).stdout.strip()
    dependencies = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"],
                    *site.getsitepackages()]
    launcher = root / "launch_websim.py"
    launcher.write_text(LAUNCHER.format(paths=[venv_site, *dict.fromkeys(dependencies)],
                                        venv=str(venv)))
    empty = root / "elsewhere"
    empty.mkdir()
    yield Installed(wheel, [str(python), "-S", str(launcher)], empty)


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
