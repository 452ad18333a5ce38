"""The Code panel on a class robot's page, the instructor's submissions page, and a phone.

A real ``websim serve --class`` and Chromium: the student's program follows the student (saved
on the server with the robot's token: another browser opens it), Submit's score shows on the
student's page and on the instructor's, and the panel fits a phone's screen with targets a
finger can use.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from code_page import (
    CODEMIRROR,
    PYODIDE,
    code_context,
    editor_text,
    open_code,
    run_program,
    set_language,
    submitted,
    type_program,
    wait_output,
)
from page_helpers import LIBRARIES, ROOT
from test_phone_layout import PHONES, TOUCH_TARGET_PX

from chromium import skip_reason
from server_process import ADMIN_TOKEN, ServerProcess, start_server, wait_for

BROWSER_SKIP = skip_reason([*LIBRARIES, PYODIDE, CODEMIRROR])
pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")]

ALICE = "alice-Token.0123456789abc"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    folder = tmp_path_factory.mktemp("class")
    roster = folder / "roster.txt"
    roster.write_text(f"alice,,{ALICE}\nbob\n")
    running = start_server(["--class", str(roster), "--state", str(folder / "state.sqlite")])
    yield running
    running.stop()


def robot_page(server: ServerProcess) -> str:
    return f"{server.http_url}/robots/alice/#token={ALICE}"


def test_a_students_program_follows_them_to_another_browser(
        browser: Any, server: ServerProcess) -> None:
    program = '# alice\'s controller, saved on the server\nprint("hello from alice")\n'
    with code_context(browser, server.http_url, server.ws_url) as first:
        page = first.new_page()
        open_code(page, robot_page(server))
        set_language(page, "python")
        type_program(page, program)
        run_program(page)  # a run saves it (and so does typing, a few seconds later)
        wait_output(page, "hello from alice", timeout_s=90)
        wait_for(lambda: "Saved on the server" in page.inner_text("#code-save-status"),
                 what="the save on the server")
    with code_context(browser, server.http_url, server.ws_url) as second:  # no localStorage
        page = second.new_page()
        open_code(page, robot_page(server))
        assert editor_text(page) == program


def test_the_score_shows_to_the_student_and_to_the_instructor(
        browser: Any, server: ServerProcess) -> None:
    solution = (ROOT / "examples" / "solutions" / "heading_pid.py").read_text()
    with code_context(browser, server.http_url, server.ws_url,
                      viewport={"width": 1280, "height": 900}) as context:
        page = context.new_page()
        open_code(page, robot_page(server))
        set_language(page, "python")
        page.select_option("#code-assignment", "heading_pid")
        type_program(page, solution)
        answer = submitted(page)
        assert answer["state"] == "done" and answer["result"]["total"] == 1.0
        assert "total 1.000" in page.inner_text("#code-grade")
        instructor = context.new_page()
        instructor.goto(f"{server.http_url}/submissions?token={ADMIN_TOKEN}")
        row = instructor.locator('tr[data-student="alice"]')
        row.wait_for(timeout=15000)
        wait_for(lambda: "1.000" in row.inner_text(), what="alice's score on the page")
        assert "heading_pid (python)" in row.inner_text() and "passed" in row.inner_text()
        assert "—" in instructor.locator('tr[data-student="bob"]').inner_text()
        row.locator("button", has_text="Report heading_pid").click()
        frame = instructor.frame_locator("#subs-report iframe")
        assert "heading_pid" in frame.locator("h1").inner_text()
        row.locator("button", has_text="Code").click()
        assert instructor.inner_text("#subs-code").strip() == solution.strip()
        assert "token" not in instructor.url  # taken out of the address bar
        with instructor.expect_download() as download:
            instructor.click("#subs-export")
        assert download.value.suggested_filename == "websim-submissions.zip"


@pytest.mark.parametrize("phone", [PHONES[0], PHONES[2]], ids=lambda phone: phone.name)
def test_the_code_panel_fits_a_phone(browser: Any, server: ServerProcess, phone: Any) -> None:
    with code_context(browser, server.http_url, server.ws_url,
                      **phone.context_options()) as context:
        page = context.new_page()
        open_code(page, robot_page(server))
        set_language(page, "python")
        type_program(page, 'print("from a phone")\n')
        page.tap("#code-run")
        wait_output(page, "from a phone", timeout_s=90)
        code_targets = page.evaluate("""() => [...document.querySelectorAll(
            '#code-card button, #code-card select, #code-card a[href]')].filter(
            (el) => el.getClientRects().length).map((el) => {
              const r = el.getBoundingClientRect();
              return {name: el.id || el.textContent.trim(), width: r.width, height: r.height};
            })""")
        small = [target for target in code_targets
                 if min(target["width"], target["height"]) < TOUCH_TARGET_PX - 0.01]
        assert small == [], json.dumps(small)
        assert page.evaluate("() => document.documentElement.scrollWidth <= innerWidth + 1")
