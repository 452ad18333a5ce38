"""An arena in a real headless Chromium: a student's page draws the world's other robots (and
not itself), where they are; the instructor's dashboard shows the arena as one map with every
robot. ``websim serve --class ROSTER --arena``, real pages, real WebSockets.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest
from page_helpers import needs_browser, open_page, wait_connected

from server_process import ADMIN_TOKEN, ServerProcess, start_arena, wait_for

ROBOTS = """\
robots:
  - {name: alice, start: [-1.0, 0.0, 0.0]}
  - {name: bob, start: [1.0, 0.5, 1.5707963267948966]}
"""


@pytest.fixture(scope="module")
def arena(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[ServerProcess,
                                                                      dict[str, str]]]:
    server, links = start_arena(tmp_path_factory.mktemp("page_arena"), ROBOTS,
                                ["alice", "bob", "carol"])
    pages = {row["name"]: row["page"] for row in links}
    yield server, pages
    server.stop()


def _local(url: str, server: ServerProcess) -> str:
    """A link of links.csv on this machine (it names the LAN address)."""
    path = url.split(f":{server.http_port}", 1)[1]
    return f"{server.http_url}{path}"


@needs_browser
def test_a_students_page_draws_the_other_robots_where_they_are(
        arena: tuple[ServerProcess, dict[str, str]], browser: Any) -> None:
    server, pages = arena
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    try:
        page, log = open_page(context, _local(pages["alice"], server))
        wait_connected(page)
        others = wait_for(
            lambda: (found := page.evaluate(
                "() => window.websim.state.others.map(o => ({...o}))")) and len(found) == 2
            and found, timeout_s=20, what="the page's other robots (/world_robots)")
        drawn = page.evaluate("() => performance.now() - window.websim.state.othersAtMs")
    finally:
        context.close()
    by_name = {other["name"]: other for other in others}
    assert set(by_name) == {"bob", "carol"}, "the others, never this page's own robot"
    assert math.dist((by_name["bob"]["x"], by_name["bob"]["y"]), (1.0, 0.5)) < 1e-3
    assert by_name["bob"]["yaw"] == pytest.approx(math.pi / 2, abs=1e-3)
    assert by_name["carol"]["radius"] > 0.0
    assert drawn < 1000, "fresh (a stale /world_robots is not drawn)"
    assert not log.page_errors, log.page_errors


@needs_browser
def test_the_dashboard_shows_the_arena_as_one_map_with_every_robot(
        arena: tuple[ServerProcess, dict[str, str]], browser: Any) -> None:
    server, _ = arena
    context = browser.new_context(viewport={"width": 1366, "height": 768})
    try:
        page, log = open_page(context, f"{server.http_url}/class?token={ADMIN_TOKEN}")
        page.wait_for_selector("#arena:not([hidden]) canvas", timeout=20000)
        names = wait_for(
            lambda: (found := page.evaluate(
                "() => (window.websim.arena?.state.robots ?? []).map(r => r.name).sort()"))
            and len(found) == 3 and found, timeout_s=20, what="every robot on the arena map")
        painted = page.evaluate(
            """() => {
              const c = document.querySelector('#arena canvas');
              const data = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
              let n = 0;
              for (let i = 3; i < data.length; i += 4) if (data[i] > 0) n += 1;
              return n;
            }""")
    finally:
        context.close()
    assert names == ["alice", "bob", "carol"]
    assert painted > 1000, "the map is drawn (walls and robots)"
    assert not log.page_errors, log.page_errors

