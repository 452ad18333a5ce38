"""The Code panel in a real headless Chromium against a real ``websim serve``: JavaScript.

The same as test_page_code_python.py for a program written for ``node`` with roslib 1.4.1
(``require('roslib')``, ``new ROSLIB.Ros({url})``, ``process.env``): it runs in a Web Worker of
its own, against the page's robot, under the page's own policies with every other host refused.
"""

from __future__ import annotations

import math
import shutil
import time
from pathlib import Path
from typing import Any

import pytest
from code_page import (
    CODEMIRROR,
    code_context,
    editor_text,
    grade_file,
    open_code,
    output,
    problems,
    run_program,
    set_language,
    state,
    submitted,
    type_program,
    wait_output,
    wait_state,
)
from page_helpers import (
    LIBRARIES,
    ROOT,
    WEB_DIR,
    Bridge,
    latest_odom,
    reset_robot,
    twist_pairs,
    wait_until_still,
    yaw_of,
)

from websim.node_roslib import roslib_closure

from chromium import skip_reason
from server_process import ServerProcess, wait_for

BROWSER_SKIP = skip_reason([*LIBRARIES, CODEMIRROR])
NODE = shutil.which("node")
pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or ""),
              pytest.mark.skipif(NODE is None, reason="node not installed (grading a .js)")]

DEG = math.pi / 180

P_CONTROLLER = """'use strict';
const ROSLIB = require('roslib');

const SETPOINT_RAD = Number(process.env.WEBSIM_SETPOINT_RAD);
const KP = 3.0;

const ros = new ROSLIB.Ros({ url: process.env.WEBSIM_URL || 'ws://localhost:9090' });
const cmdVel = new ROSLIB.Topic({ ros, name: '/cmd_vel', messageType: 'geometry_msgs/msg/Twist' });
const odom = new ROSLIB.Topic({ ros, name: '/odom', messageType: 'nav_msgs/msg/Odometry' });

function wrap(angle) {
  return angle - 2 * Math.PI * Math.round(angle / (2 * Math.PI));
}

ros.on('connection', () => console.log('P controller connected, setpoint',
  Math.round(SETPOINT_RAD * 180 / Math.PI), 'deg'));
ros.on('close', () => process.exit(0));
odom.subscribe((message) => {
  const q = message.pose.pose.orientation;
  const error = wrap(SETPOINT_RAD - 2 * Math.atan2(q.z, q.w));
  const angular = Math.max(-2, Math.min(2, KP * error));
  cmdVel.publish(new ROSLIB.Message({
    linear: { x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: angular },
  }));
});
"""


@pytest.fixture(scope="module")
def context(browser: Any, server: ServerProcess) -> Any:
    with code_context(browser, server.http_url, server.ws_url,
                      viewport={"width": 1280, "height": 900}) as opened:
        yield opened


@pytest.fixture(scope="module")
def page(context: Any, server: ServerProcess) -> Any:
    opened = context.new_page()
    open_code(opened, f"{server.http_url}/")
    set_language(opened, "javascript")
    yield opened


def test_a_p_controller_typed_in_javascript_turns_the_robot_to_its_setpoint(
        page: Any, bridge: Bridge) -> None:
    reset_robot(bridge)
    page.select_option("#code-assignment", "heading_pid")
    type_program(page, P_CONTROLLER)
    run_program(page)
    wait_output(page, "P controller connected, setpoint 90 deg")
    assert wait_state(page, ("connected",)) == "connected"
    wait_for(lambda: abs(yaw_of(latest_odom(bridge)) - 90 * DEG) < 1 * DEG, timeout_s=20,
             what="the robot to turn to 90°")
    page.click("#code-stop")
    assert wait_state(page, ("stopped",)) == "stopped"
    wait_until_still(bridge)
    assert twist_pairs(bridge.messages("/cmd_vel"))[-1] == (0.0, 0.0)


def test_an_exception_in_a_callback_is_shown_at_its_line(page: Any) -> None:
    type_program(page, "'use strict';\nconsole.log('before');\n\nfunction speed(scan) {\n"
                       "  return scan.ranges.length;\n}\n\nsetTimeout(() => speed({}), 50);\n")
    run_program(page)
    assert wait_state(page, ("crashed",)) == "crashed"
    wait_output(page, "TypeError")
    assert "before" in output(page)
    assert "heading_pid.js:5" in output(page)  # its file's name, not a blob: URL
    assert page.inner_text("#code-state") == "crashed at line 5"
    assert [(p["line"], p["severity"]) for p in problems(page)] == [(5, "error")]


def test_a_syntax_error_is_shown_at_its_line(page: Any) -> None:
    type_program(page, "'use strict';\nconst a = 1;\nconst b = (a + ;\nconsole.log(b);\n")
    wait_for(lambda: [p["line"] for p in problems(page)] == [3],
             what="the syntax error marked as it is typed")
    run_program(page)
    assert wait_state(page, ("crashed",)) == "crashed"
    assert "SyntaxError" in output(page)
    assert [(p["line"], p["severity"]) for p in problems(page)] == [(3, "error")]


def test_an_endless_loop_leaves_the_page_responsive_and_stop_ends_it_and_stops_the_robot(
        page: Any, bridge: Bridge) -> None:
    reset_robot(bridge)
    type_program(page, "const ROSLIB = require('roslib');\n"
                       "const ros = new ROSLIB.Ros({ url: process.env.WEBSIM_URL });\n"
                       "ros.on('connection', () => {\n"
                       "  new ROSLIB.Topic({ ros, name: '/cmd_vel', messageType: "
                       "'geometry_msgs/msg/Twist' }).publish(new ROSLIB.Message({ linear: "
                       "{ x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 1 } }));\n"
                       "  console.log('turning, then looping forever');\n"
                       "  setTimeout(() => { for (;;) { /* nothing */ } }, 200);\n});\n")
    run_program(page)
    wait_output(page, "turning, then looping forever")
    wait_for(lambda: abs(latest_odom(bridge)["twist"]["twist"]["angular"]["z"] - 1.0) < 1e-6,
             what="the robot to turn")
    time.sleep(0.5)  # the loop has begun
    readings = []
    for _ in range(5):
        readings.append(page.inner_text("[data-readout=theta]"))
        time.sleep(0.3)
    assert len(set(readings)) > 1, readings
    page.click("#code-stop")
    assert wait_state(page, ("stopped",), timeout_s=10) == "stopped"
    still = wait_until_still(bridge)
    assert still["twist"]["twist"]["angular"]["z"] == 0.0


def test_submit_scores_as_websim_grade_scores_the_downloaded_file(
        page: Any, tmp_path: Path) -> None:
    page.select_option("#code-assignment", "heading_pid")
    type_program(page, P_CONTROLLER)
    with page.expect_download() as download:
        page.click("#code-download")
    folder = tmp_path / "student"
    path = folder / download.value.suggested_filename
    folder.mkdir()
    download.value.save_as(path)
    assert path.name == "heading_pid.js" and path.read_text() == P_CONTROLLER
    assert "npm install roslib@1.4.1" in page.inner_text("#code-laptop")
    modules = WEB_DIR / "node_modules"  # what npm install roslib@1.4.1 puts beside it
    for name in roslib_closure(modules):
        shutil.copytree(modules / name, folder / "node_modules" / name)
    answer = submitted(page)
    assert answer["state"] == "done", answer
    by_hand = grade_file(path, "heading_pid", tmp_path / "out", "node", path.name)
    assert answer["result"]["total"] == by_hand["total"] > 0.9


def test_the_course_snippets_run_unchanged_in_the_browser(page: Any, bridge: Bridge) -> None:
    reset_robot(bridge)
    page.select_option("#code-load", "example:course_snippets.js")
    assert editor_text(page) == (ROOT / "examples" / "course_snippets.js").read_text()
    run_program(page)
    assert wait_state(page, ("exited", "crashed"), timeout_s=30) == "exited", output(page)
    text = output(page)
    assert "Connected to ROS 2" in text and "stop: published a zero Twist" in text
    assert "odom end: x=" in text and "exit status 0" in text


def test_the_reference_solution_runs_unchanged_in_the_browser(
        page: Any, bridge: Bridge) -> None:
    reset_robot(bridge)
    set_language(page, "javascript")
    page.select_option("#code-assignment", "heading_pid")
    type_program(page, (ROOT / "examples" / "solutions" / "heading_pid.js").read_text())
    run_program(page)
    assert wait_state(page, ("connected",)) == "connected"
    wait_for(lambda: abs(yaw_of(latest_odom(bridge)) - 90 * DEG) < 2 * DEG, timeout_s=20,
             what="the reference PID to turn the robot to 90°")
    assert state(page) == "connected"
    page.click("#code-stop")
    wait_state(page, ("stopped",))


def test_a_program_that_allocates_forever_ends_the_tab_and_the_code_survives(
        context: Any, server: ServerProcess) -> None:
    """A JavaScript program's memory is the browser's to bound: Chromium ends the renderer
    when a worker's heap is full (Python's is capped: MemoryError, test_page_code_python.py).
    The program was saved before it ran; the reloaded page has it and says what happened."""
    doomed = context.new_page()
    open_code(doomed, f"{server.http_url}/")
    set_language(doomed, "javascript")
    program = "const blocks = [];\nfor (;;) blocks.push(new Array(1e6).fill(1.5));\n"
    type_program(doomed, program)
    with doomed.expect_event("crash", timeout=120_000):
        doomed.click("#code-run")
    doomed.close()
    again = context.new_page()
    open_code(again, f"{server.http_url}/")
    assert editor_text(again) == program
    assert "ended while your JavaScript program ran" in output(again)
    again.close()
