"""Shared fixtures: shipped worlds, small hand-made worlds, a real server and its clients."""

from __future__ import annotations

import functools
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from physics import RobotParams, Simulation, World, load_world, raycast_kernel
from physics.world import WORLDS_DIR, world_from_dict

pytest.register_assert_rewrite("ros_fixtures")  # a plugin the ROS test modules import first

SHIPPED_WORLDS = sorted(path.stem for path in WORLDS_DIR.glob("*.yaml"))

ARENA_HALF_M = 3.0
"""worlds/empty.yaml is the closed square |x|, |y| <= 3 m."""


@pytest.fixture(autouse=True)
def no_server_outlives_its_test() -> Iterator[None]:
    """A server a test's body started is gone when the test is, passed or failed."""
    yield
    from server_process import stop_leftovers

    stop_leftovers()


@functools.cache
def compiled_raycast() -> raycast_kernel.Kernel | None:
    """numba's kernel of ``physics.raycast_kernel``, compiled once for the run; None without
    numba."""
    return raycast_kernel._compile()


@pytest.fixture
def numpy_raycast(monkeypatch: pytest.MonkeyPatch) -> None:
    """``physics.raycast`` casts in numpy, where numba's kernel would otherwise cast: for the
    tests of the numpy path's own parts (its dense and arc paths, its culling of discs)."""
    monkeypatch.setattr(raycast_kernel, "_loaded", [None])


@pytest.fixture(params=["numpy", "compiled"])
def raycast_path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Each cast of the test in numpy, then in numba's kernel (``websim[fast]``)."""
    kernel = None if request.param == "numpy" else compiled_raycast()
    if request.param == "compiled" and kernel is None:
        pytest.skip("numba is not installed (the optional [fast] extra): the numpy path only")
    monkeypatch.setattr(raycast_kernel, "_loaded", [kernel])
    return str(request.param)


@pytest.fixture
def arena() -> World:
    return load_world("empty")


@pytest.fixture
def open_world() -> World:
    """No walls at all."""
    return world_from_dict({"name": "open"}, source="open")


def make_sim(world: World, **kwargs: object) -> Simulation:
    params = kwargs.pop("params", None) or RobotParams()
    return Simulation(world, params, seed=0, **kwargs)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def server():
    """A real ``websim serve`` on the empty world, shared by a test module."""
    from server_process import start_server

    running = start_server()
    yield running
    assert running.stop() == 0, "".join(running.output)


@pytest.fixture
def ros(server: Any) -> Iterator[Any]:
    """roslibpy connected to the module's ``server``, closed after the test."""
    from server_process import roslibpy_client

    with roslibpy_client(server) as client:
        yield client


@pytest.fixture(scope="module")
def bridge(server: Any) -> Iterator[Any]:
    """A raw rosbridge client (page_helpers.Bridge) on the module's ``server``, recording
    /odom and /cmd_vel: the robot's side of the web interface's browser tests."""
    from page_helpers import Bridge

    client = Bridge(server.ws_url)
    client.subscribe("/odom")
    client.subscribe("/cmd_vel")
    yield client
    client.close()


class _EvalAllowed:
    """A browser whose contexts let Playwright's ``wait_for_function`` evaluate its predicates
    (``bypass_csp``): the pages' CSP forbids eval, which only the tests use. The pages' own
    code runs under the CSP in ``test_front_door.py`` (``bypass_csp=False``)."""

    def __init__(self, browser: Any) -> None:
        self._browser = browser

    def new_context(self, **options: Any) -> Any:
        return self._browser.new_context(**{"bypass_csp": True, **options})

    def new_page(self, **options: Any) -> Any:
        return self._browser.new_page(**{"bypass_csp": True, **options})

    def __getattr__(self, name: str) -> Any:
        return getattr(self._browser, name)


@pytest.fixture
def tiny_disk(tmp_path: Path) -> Iterator[Path]:
    """A 16 KiB tmpfs: a disk that fills up (mounting one needs root)."""
    mount = tmp_path / "tiny"
    mount.mkdir()
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16k", "tmpfs", str(mount)],
                            capture_output=True, text=True, check=False)
    if result.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs (needs root): {result.stderr.strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Debian's chromium under Playwright; each launch gets a fresh temporary profile."""
    from chromium import launched_chromium

    with launched_chromium() as launched:
        yield _EvalAllowed(launched)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark every test that drives Chromium (this file's ``browser`` fixture) ``browser``."""
    for item in items:
        info = getattr(item, "_fixtureinfo", None)
        definitions = info.name2fixturedefs.get("browser", ()) if info is not None else ()
        if definitions and definitions[-1].func is browser.__wrapped__:  # type: ignore[attr-defined]
            item.add_marker(pytest.mark.browser)
