"""The Code panel in a real headless Chromium against a real ``websim serve``: Python.

A student types a program into the robot's page, runs it in the browser (Pyodide in a Web
Worker, websim's roslibpy), and the robot does what it says, as the bridge sees it (``/odom``,
``/cmd_vel``). The page runs under its own policies with every other host refused
(code_page.py), so nothing here may load from the internet; Submit is graded by the server's
``websim grade`` and must score as ``websim grade`` scores the downloaded file. The browser's
roslibpy is held to the real one on CPython in test_code_shim.py.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import pytest
from code_page import (
    CODEMIRROR,
    PYODIDE,
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
    Bridge,
    latest_odom,
    reset_robot,
    twist_pairs,
    wait_until_still,
    yaw_of,
)

from chromium import skip_reason
from server_process import ServerProcess, wait_for

BROWSER_SKIP = skip_reason([*LIBRARIES, PYODIDE, CODEMIRROR])
pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")]

DEG = math.pi / 180

P_CONTROLLER = '''import math
import os
import time

import roslibpy

SETPOINT_RAD = float(os.environ["WEBSIM_SETPOINT_RAD"])
KP = 3.0

ros = roslibpy.Ros(host=os.environ["WEBSIM_URL"])
ros.run()
print("P controller connected, setpoint", round(math.degrees(SETPOINT_RAD)), "deg")
cmd_vel = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")


def on_odom(odom):
    q = odom["pose"]["pose"]["orientation"]
    error = math.remainder(SETPOINT_RAD - 2.0 * math.atan2(q["z"], q["w"]), 2 * math.pi)
    angular = max(-2.0, min(2.0, KP * error))
    cmd_vel.publish(roslibpy.Message({"linear": {"x": 0.0, "y": 0.0, "z": 0.0},
                                      "angular": {"x": 0.0, "y": 0.0, "z": angular}}))


roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(on_odom)
while ros.is_connected:
    time.sleep(0.1)
'''


@pytest.fixture(scope="module")
def context(browser: Any, server: ServerProcess) -> Any:
    with code_context(browser, server.http_url, server.ws_url,
                      viewport={"width": 1280, "height": 900}) as opened:
        yield opened


@pytest.fixture(scope="module")
def page(context: Any, server: ServerProcess) -> Any:
    opened = context.new_page()
    errors: list[str] = []
    opened.on("pageerror", lambda error: errors.append(str(error)))
    open_code(opened, f"{server.http_url}/")
    yield opened
    assert errors == []


def test_a_p_controller_typed_in_python_turns_the_robot_to_its_setpoint(
        page: Any, bridge: Bridge) -> None:
    reset_robot(bridge)
    set_language(page, "python")
    page.select_option("#code-assignment", "heading_pid")
    type_program(page, P_CONTROLLER)
    run_program(page)
    wait_output(page, "P controller connected, setpoint 90 deg", timeout_s=60)
    assert wait_state(page, ("connected",)) == "connected"
    assert page.get_attribute("#code-nav-state", "data-state") == "connected"  # the top bar
    wait_for(lambda: abs(yaw_of(latest_odom(bridge)) - 90 * DEG) < 1 * DEG, timeout_s=20,
             what="the robot to turn to 90°")
    time.sleep(1.0)  # and hold it
    assert abs(yaw_of(latest_odom(bridge)) - 90 * DEG) < 1 * DEG
    page.click("#code-stop")
    assert wait_state(page, ("stopped",)) == "stopped"
    wait_until_still(bridge)
    assert twist_pairs(bridge.messages("/cmd_vel"))[-1] == (0.0, 0.0)


def test_the_editor_works_from_the_keyboard_and_its_keys_do_not_drive_the_robot(
        page: Any, bridge: Bridge) -> None:
    reset_robot(bridge)
    type_program(page, "")
    commands = len(bridge.messages("/cmd_vel"))
    page.keyboard.type("def total(a, b):\nreturn a + b\n")  # Enter indents the body
    page.keyboard.press("Shift+Tab")  # back out of the body
    page.keyboard.type('print("sum", total(2, 3')  # the closing quote and brackets: put there
    page.keyboard.press("ArrowUp")  # in the editor: the cursor, not the robot
    page.keyboard.press("ArrowDown")
    assert editor_text(page) == 'def total(a, b):\n    return a + b\nprint("sum", total(2, 3))'
    page.keyboard.press("Control+Enter")  # Run
    wait_output(page, "sum 5", timeout_s=60)
    time.sleep(0.5)
    # the arrows drove nothing (the zeros: Run stands the page's teleop down, the end stops)
    assert set(twist_pairs(bridge.messages("/cmd_vel")[commands:])) <= {(0.0, 0.0)}


def test_an_exception_is_shown_with_its_line_in_the_output_and_the_editor(page: Any) -> None:
    set_language(page, "python")
    type_program(page, 'import time\nprint("before")\n\n\ndef speed(distance_m):\n'
                       '    return 0.5 / distance_m\n\n\nprint(speed(0.0))\n')
    run_program(page)
    assert wait_state(page, ("crashed",)) == "crashed"
    text = output(page)
    assert "before" in text
    assert 'File "heading_pid.py", line 6, in speed' in text
    assert "ZeroDivisionError" in text.splitlines()[-2]
    assert page.inner_text("#code-state") == "crashed at line 6"
    assert [(p["line"], p["severity"]) for p in problems(page)] == [(6, "error")]


def test_a_callbacks_exception_is_shown_and_the_program_goes_on(page: Any) -> None:
    type_program(page, 'import os, time\nimport roslibpy\n\n'
                       'ros = roslibpy.Ros(host=os.environ["WEBSIM_URL"])\nros.run()\n'
                       'seen = []\n\n\ndef on_odom(odom):\n    seen.append(1)\n'
                       '    if len(seen) == 3:\n        raise KeyError("no such field")\n\n\n'
                       'roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(on_odom)\n'
                       'time.sleep(1.0)\nprint("still running after", len(seen), "messages")\n')
    run_program(page)
    assert wait_state(page, ("exited", "crashed")) == "exited"
    text = output(page)
    assert "Exception in a callback (the program goes on)" in text
    assert "KeyError: 'no such field'" in text
    assert "still running after" in text
    assert {(p["line"], p["severity"]) for p in problems(page)} == {(12, "warning")}


def test_an_endless_loop_leaves_the_page_responsive_and_stop_ends_it_and_stops_the_robot(
        page: Any, bridge: Bridge) -> None:
    reset_robot(bridge)
    type_program(page, 'import os\nimport roslibpy\n\n'
                       'ros = roslibpy.Ros(host=os.environ["WEBSIM_URL"])\nros.run()\n'
                       'roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist").publish('
                       'roslibpy.Message({"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, '
                       '"angular": {"x": 0.0, "y": 0.0, "z": 1.0}}))\n'
                       'print("turning, then looping forever")\nwhile True:\n    pass\n')
    run_program(page)
    wait_output(page, "turning, then looping forever", timeout_s=60)
    turning = wait_for(lambda: latest_odom(bridge) if abs(
        latest_odom(bridge)["twist"]["twist"]["angular"]["z"] - 1.0) < 1e-6 else None,
        what="the robot to turn (the robot keeps the last command)")
    assert turning
    # the page's own thread is free: its view keeps up with /odom while the loop spins
    readings = []
    for _ in range(5):
        started = time.monotonic()
        readings.append(page.inner_text("[data-readout=theta]"))
        assert time.monotonic() - started < 2.0
        time.sleep(0.3)
    assert len(set(readings)) > 1, readings  # the heading readout moved: the page draws
    started = time.monotonic()
    page.click("#code-stop")
    assert wait_state(page, ("stopped",), timeout_s=10) == "stopped"
    assert time.monotonic() - started < 5.0
    still = wait_until_still(bridge)
    assert still["twist"]["twist"]["angular"]["z"] == 0.0
    assert twist_pairs(bridge.messages("/cmd_vel"))[-1] == (0.0, 0.0)


def test_restart_ends_a_program_stuck_in_a_loop_and_runs_it_again(page: Any) -> None:
    type_program(page, 'import time\nprint("started at", time.time())\nwhile True:\n'
                       '    pass\n')
    run_program(page)
    wait_output(page, "started at", timeout_s=60)
    page.click("#code-restart")
    wait_for(lambda: output(page).count("started at") == 2, timeout_s=30,
             what="the program to start again")
    assert state(page) == "running"
    page.click("#code-stop")
    assert wait_state(page, ("stopped",), timeout_s=10) == "stopped"


def test_a_print_flood_keeps_the_newest_lines_and_the_page_usable(page: Any) -> None:
    type_program(page, 'i = 0\nwhile True:\n    print("line", i)\n    i += 1\n')
    run_program(page)
    wait_for(lambda: newest_line(page) > 200000, timeout_s=60, what="200000 lines printed")
    started = time.monotonic()
    page.click("#code-stop")
    wait_state(page, ("stopped",), timeout_s=10)
    assert time.monotonic() - started < 5.0
    lines = page.evaluate("() => window.websim.code.panel.output.lines.length")
    assert lines <= 1000
    assert page.evaluate("() => window.websim.code.panel.output.dropped") > 0
    assert newest_line(page) > 200000  # the newest are kept
    wait_for(lambda: "earlier lines not shown" in page.inner_text("#code-output"),
             what="the pane to say it let the oldest go")


def newest_line(page: Any) -> int:
    numbers = [int(line.split()[1]) for line in output(page).splitlines()
               if line.startswith("line ")]
    return max(numbers, default=-1)


def test_a_program_that_allocates_forever_gets_memory_error_at_its_line(page: Any) -> None:
    type_program(page, 'blocks = []\nwhile True:\n    blocks.append(bytearray(8 * 1024 * 1024))\n')
    run_program(page)
    assert wait_state(page, ("crashed",), timeout_s=60) == "crashed"
    assert "MemoryError" in output(page)
    assert page.inner_text("#code-state") == "crashed at line 3"
    # the next run starts at once: the same Python, its memory given back
    type_program(page, 'print("after", sum(range(10)))\n')
    run_program(page)
    wait_output(page, "after 45")


def test_reload_keeps_the_code(context: Any, server: ServerProcess) -> None:
    first = context.new_page()
    open_code(first, f"{server.http_url}/")
    set_language(first, "python")
    program = '# kept across a reload\nprint("kept")\n'
    type_program(first, program)
    time.sleep(1.0)  # the browser's save follows the typing by half a second
    first.reload()
    first.wait_for_selector(".cm-content", timeout=30000)  # the panel reopens by itself
    assert editor_text(first) == program
    first.close()


def test_submit_scores_as_websim_grade_scores_the_downloaded_file(
        page: Any, tmp_path: Path) -> None:
    set_language(page, "python")
    page.select_option("#code-assignment", "heading_pid")
    type_program(page, P_CONTROLLER)
    with page.expect_download() as download:
        page.click("#code-download")
    path = tmp_path / "student" / download.value.suggested_filename
    path.parent.mkdir()
    download.value.save_as(path)
    assert path.name == "heading_pid.py" and path.read_text() == P_CONTROLLER
    assert "pip install roslibpy" in page.inner_text("#code-laptop")
    answer = submitted(page)
    assert answer["state"] == "done", answer
    by_hand = grade_file(path, "heading_pid", tmp_path / "out", "python3", path.name)
    assert answer["result"]["total"] == by_hand["total"] > 0.9
    rows = page.locator("#code-grade tbody tr")
    assert rows.count() == 1 and "heading_pid" in rows.first.inner_text()
    rows.first.locator("button").click()  # the report, in the page, sandboxed
    frame = page.frame_locator("#code-grade iframe")
    assert "heading_pid" in frame.locator("h1").inner_text()


def test_the_course_snippets_run_unchanged_in_the_browser(page: Any, bridge: Bridge) -> None:
    reset_robot(bridge)
    page.select_option("#code-load", "example:course_snippets.py")
    assert editor_text(page) == (ROOT / "examples" / "course_snippets.py").read_text()
    run_program(page)
    assert wait_state(page, ("exited", "crashed"), timeout_s=60) == "exited", output(page)
    text = output(page)
    assert "Connected to ROS 2" in text and "stop: published a zero Twist" in text
    assert "odom end: x=" in text and "exit status 0" in text


@pytest.mark.parametrize(("solution", "assignment"), [
    ("heading_pid.py", "heading_pid"),
    ("wall_follower.py", "wall_following_suite"),
    ("go_to_goal.py", "go_to_goal"),
])
def test_the_reference_solutions_run_unchanged_in_the_browser(
        page: Any, bridge: Bridge, solution: str, assignment: str) -> None:
    reset_robot(bridge)
    set_language(page, "python")
    page.select_option("#code-assignment", assignment)
    type_program(page, (ROOT / "examples" / "solutions" / solution).read_text())
    commands_before = len(bridge.messages("/cmd_vel"))
    run_program(page)
    assert wait_state(page, ("connected",), timeout_s=60) == "connected"
    if solution == "heading_pid.py":
        wait_for(lambda: abs(yaw_of(latest_odom(bridge)) - 90 * DEG) < 2 * DEG, timeout_s=20,
                 what="the reference PID to turn the robot to 90°")
    else:  # it answers each /odom with a command, and moves the robot
        wait_for(lambda: len(bridge.messages("/cmd_vel")) > commands_before + 20,
                 what=f"{solution} to command the robot")
        assert any(linear > 0 for linear, _ in
                   twist_pairs(bridge.messages("/cmd_vel")[commands_before:]))
    assert state(page) == "connected", output(page)
    page.click("#code-stop")
    wait_state(page, ("stopped",))
    wait_until_still(bridge)
