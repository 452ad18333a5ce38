"""A class robot's own pages in real Chromium: the page at /robots/NAME/ drives robot NAME.

A real ``websim serve --class`` and headless Chromium: the student page of one robot finds
its bridge through the ``config.json`` the server fills for it and drives that robot only;
its admin page, opened with the robot's own token from the links file, changes that robot's
mass and no other's.
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import connect

from chromium import skip_reason
from server_process import ServerProcess, start_server, wait_for

ROOT = Path(__file__).resolve().parent.parent
LIBRARIES = [ROOT / "web-interface" / "node_modules" / "roslib" / "build" / "roslib.min.js"]
BROWSER_SKIP = skip_reason(LIBRARIES)
pytestmark = pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")


@pytest.fixture(scope="module")
def links(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("links") / "links.csv"


@pytest.fixture(scope="module")
def server(links: Path) -> Iterator[ServerProcess]:
    running = start_server(["--class", "3", "--links", str(links)])
    yield running
    running.stop()


def robot_state(server: ServerProcess, name: str) -> dict[str, Any]:
    """One /ground_truth of robot ``name`` and its mass, from a raw client."""
    with connect(f"ws://127.0.0.1:{server.ws_port}/robots/{name}") as ws:
        ws.send(json.dumps({"op": "subscribe", "topic": "/ground_truth"}))
        ws.send(json.dumps({"op": "call_service", "id": "m", "args": {"names": ["mass_kg"]},
                            "service": "/virtual_robot/get_parameters"}))
        state: dict[str, Any] = {}
        while len(state) < 2:
            message = json.loads(ws.recv(timeout=5))
            if message.get("topic") == "/ground_truth":
                state["x"] = message["msg"]["pose"]["pose"]["position"]["x"]
            elif message.get("op") == "service_response":
                state["mass_kg"] = message["values"]["values"][0]["double_value"]
        return state


def test_a_robots_page_drives_that_robot_only(server: ServerProcess, links: Path,
                                             browser: Any) -> None:
    rows = {row["name"]: row for row in csv.DictReader(links.open())}
    context = browser.new_context(viewport={"width": 1280, "height": 860})
    try:
        page = context.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto(rows["robot02"]["page"].replace("localhost", "127.0.0.1"))  # #token=...
        page.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
        assert "token" not in page.url  # taken out of the address bar, kept for the student
        assert page.evaluate("localStorage.getItem('websim.robotToken:/robots/robot02/')") \
            == rows["robot02"]["token"]
        assert page.input_value("#ws-url") == \
            f"ws://127.0.0.1:{server.ws_port}/robots/robot02"  # from its config.json
        page.click("#view")  # focus the page, not a field
        page.keyboard.down("ArrowUp")
        wait_for(lambda: robot_state(server, "robot02")["x"] > 0.05, 10.0, "robot02 to move",
                 interval_s=0.2)
        page.keyboard.up("ArrowUp")
        time.sleep(0.3)
        assert robot_state(server, "robot01")["x"] == 0.0
        assert robot_state(server, "robot03")["x"] == 0.0
        assert errors == []
    finally:
        context.close()


def test_a_robots_page_says_whose_robot_it_is_and_copies_the_url_for_the_students_code(
        server: ServerProcess, links: Path, browser: Any) -> None:
    rows = {row["name"]: row for row in csv.DictReader(links.open())}
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    context.grant_permissions(["clipboard-read", "clipboard-write"])
    try:
        page = context.new_page()
        page.goto(rows["robot01"]["page"].replace("localhost", "127.0.0.1"))  # #token=...
        page.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
        url = f"ws://127.0.0.1:{server.ws_port}/robots/robot01"
        assert page.title() == "robot01 \u2014 websim"
        line = page.text_content("#your-robot-text") or ""
        assert line == f"Your robot: robot01 \u2014 your code connects to {url}?token=\u2026"
        assert rows["robot01"]["token"] not in line  # shown elided, copied whole
        page.click("#your-robot-copy")
        wait_for(lambda: page.text_content("#your-robot-copy") == "Copied", 5.0, "the copy")
        assert page.evaluate("navigator.clipboard.readText()") == \
            f"{url}?token={rows['robot01']['token']}"
        box = page.locator("#your-robot").bounding_box()
        assert box is not None and box["y"] + box["height"] <= 800  # on the first screen
    finally:
        context.close()


def test_a_robots_admin_page_with_its_token_sets_that_robots_mass(server: ServerProcess,
                                                                 links: Path,
                                                                 browser: Any) -> None:
    rows = {row["name"]: row for row in csv.DictReader(links.open())}
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    try:
        page = context.new_page()
        page.goto(rows["robot03"]["admin_page"].replace("localhost", "127.0.0.1"))
        page.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
        assert "token=" not in page.url  # taken and stripped from the address bar
        page.wait_for_selector("#param-mass_kg")
        page.fill("#param-mass_kg", "2.5")
        page.click("#params-apply")
        wait_for(lambda: robot_state(server, "robot03")["mass_kg"] == 2.5, 10.0,
                 "robot03's mass to change", interval_s=0.2)
        assert robot_state(server, "robot01")["mass_kg"] == 1.2
    finally:
        context.close()


def test_a_robots_page_without_its_token_watches_but_does_not_drive(server: ServerProcess,
                                                                    browser: Any) -> None:
    context = browser.new_context(viewport={"width": 1280, "height": 860})
    try:
        page = context.new_page()
        page.goto(f"{server.http_url}/robots/robot01/")
        page.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
        page.click("#view")
        page.keyboard.down("ArrowUp")
        time.sleep(1.0)
        page.keyboard.up("ArrowUp")
        assert robot_state(server, "robot01")["x"] == 0.0, "a classmate's page drove robot01"
    finally:
        context.close()


def test_an_open_class_page_keeps_the_token_of_the_name_it_enrolled(tmp_path: Path,
                                                                     browser: Any) -> None:
    roster = tmp_path / "roster.txt"
    roster.write_text("alice\n")
    server = start_server(["--class", str(roster), "--open-class"])
    context = browser.new_context(viewport={"width": 1280, "height": 860})
    try:
        page = context.new_page()
        page.goto(f"{server.http_url}/robots/newbie/")
        page.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
        key = "websim.robotToken:/robots/newbie/"
        for _ in range(50):
            token = page.evaluate(f"localStorage.getItem('{key}')")
            if token:
                break
            page.wait_for_timeout(100)
        assert token and len(token) == 24, "the enrolling page was handed its robot's token"
        # its reconnections send it: a reload drives newbie
        page.reload()
        page.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
        page.click("#view")
        page.keyboard.down("ArrowUp")
        wait_for(lambda: robot_state(server, "newbie")["x"] > 0.05, 10.0, "newbie to move",
                 interval_s=0.2)
        page.keyboard.up("ArrowUp")
        # another browser (a classmate) cannot take the name
        other = browser.new_context().new_page()
        other.goto(f"{server.http_url}/robots/newbie/")
        other.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
        other.wait_for_timeout(1000)
        assert other.evaluate(f"localStorage.getItem('{key}')") is None
        other.context.close()
    finally:
        context.close()
        server.stop()
