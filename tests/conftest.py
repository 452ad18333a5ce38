"""Shared fixtures: shipped worlds and small hand-made worlds for analytic checks."""

from __future__ import annotations

import pytest

from physics import RobotParams, Simulation, World, load_world
from physics.world import WORLDS_DIR, world_from_dict

pytest.register_assert_rewrite("ros_fixtures")  # a plugin the ROS test modules import first

SHIPPED_WORLDS = sorted(path.stem for path in WORLDS_DIR.glob("*.yaml"))

ARENA_HALF_M = 3.0
"""worlds/empty.yaml is the closed square |x|, |y| <= 3 m."""


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
    running.stop()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark every test that drives Chromium (it uses the ``browser`` fixture) as ``browser``."""
    for item in items:
        if "browser" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.browser)
