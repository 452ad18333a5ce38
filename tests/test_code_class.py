"""The Code panel's server side in a class: saving per student, Submit, the instructor's view.

A real ``websim serve --class`` and real HTTP clients (and, once, the page in Chromium): each
student's program is kept in the class state with a few versions and survives a restart; only
the robot's token (or the instructor's) reads or writes it; Submit grades it with ``websim
grade`` in its sandbox, keeps the last result and its reports across a restart, and the
instructor sees every student's and exports them for ``websim grade --submissions``. Bounds
as a hostile student tests them: a 10 MB save, a thousand submits.
"""

from __future__ import annotations

import csv
import http.client
import io
import json
import os
import shutil
import socket
import subprocess
import sys
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from classroom.state import AUTOSAVE, ClassState
from websim.code_routes import KEEP_VERSIONS
from websim.submissions import SubmitLimits

from server_process import ADMIN_TOKEN, ServerProcess, free_port, start_server, wait_for

ROOT = Path(__file__).resolve().parent.parent
SOLUTIONS = ROOT / "examples" / "solutions"
ALICE = "alice-Token.0123456789abc"
BOB = "bob-Token.0123456789abcdef"


def call(server: ServerProcess, method: str, path: str, token: str | None = None,
         body: Any = None) -> tuple[int, Any]:
    """One request; (status, the JSON answer or the text)."""
    connection = http.client.HTTPConnection("127.0.0.1", server.http_port, timeout=30)
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    data = None if body is None else json.dumps(body).encode()
    if data is not None:
        headers["Content-Type"] = "application/json"
    try:
        connection.request(method, path, body=data, headers=headers)
        response = connection.getresponse()
        raw = response.read()
        if response.getheader("Content-Type", "").startswith("application/json"):
            return response.status, json.loads(raw)
        return response.status, raw
    finally:
        connection.close()


@pytest.fixture
def roster(tmp_path: Path) -> Path:
    path = tmp_path / "roster.txt"
    path.write_text(f"alice,,{ALICE}\nbob,,{BOB}\n")
    return path


def class_server(roster: Path, *args: str) -> ServerProcess:
    return start_server(["--class", str(roster), "--state", str(roster.with_suffix(".sqlite")),
                         *args])


@pytest.fixture
def server(roster: Path) -> Iterator[ServerProcess]:
    running = class_server(roster)
    yield running
    running.stop()


def test_a_students_program_is_kept_with_its_versions_and_only_for_its_tokens(
        server: ServerProcess, roster: Path) -> None:
    path = "/robots/alice/code/saved"
    assert call(server, "GET", path)[0] == 401
    assert call(server, "GET", path, BOB)[0] == 403  # a classmate's token
    for index in range(KEEP_VERSIONS + 2):
        status, answer = call(server, "POST", path, ALICE,
                              {"language": "python", "text": f"print({index})", "reason": "run"})
        assert status == 200 and answer["version"] == index + 1
    # typing saves by itself: one autosave version, replaced while the student types on
    for text in ("print('a')", "print('ab')", "print('abc')"):
        call(server, "POST", path, ALICE, {"language": "python", "text": text,
                                           "reason": AUTOSAVE})
    call(server, "POST", path, ALICE, {"language": "javascript", "text": "console.log(1);",
                                       "reason": "run"})
    status, answer = call(server, "GET", path, ALICE)
    versions = answer["versions"]
    python = [v for v in versions if v["language"] == "python"]
    assert [v["text"] for v in python] == ["print('abc')", *[f"print({i})" for i in
                                                             (6, 5, 4, 3)]]
    assert len(python) == KEEP_VERSIONS
    assert versions[0]["language"] == "javascript"
    assert call(server, "GET", path, ADMIN_TOKEN)[1]["versions"] == versions  # the instructor
    assert call(server, "GET", "/robots/bob/code/saved", BOB)[1] == {"versions": []}
    server.stop()
    again = class_server(roster)
    try:
        assert call(again, "GET", path, ALICE)[1]["versions"] == versions
    finally:
        again.stop()


def test_a_ten_megabyte_save_is_refused_unread_and_the_server_goes_on(
        server: ServerProcess) -> None:
    size = 10 * 1024 * 1024
    started = time.monotonic()
    with socket.create_connection(("127.0.0.1", server.http_port), timeout=10) as raw:
        raw.sendall(f"POST /robots/alice/code/saved HTTP/1.1\r\nHost: x\r\n"
                    f"Authorization: Bearer {ALICE}\r\nContent-Type: application/json\r\n"
                    f"Content-Length: {size}\r\n\r\n".encode())
        raw.sendall(b'{"language": "python", "text": "' + b"x" * 65536)
        answer = raw.recv(65536).decode(errors="replace")
    assert answer.startswith("HTTP/1.1 413"), answer[:200]
    assert "larger than" in answer
    assert time.monotonic() - started < 5.0
    # without a length (chunked): read up to the limit, then refused
    status, answer = call(server, "POST", "/robots/alice/code/saved", ALICE,
                          {"language": "python", "text": "x" * size})
    assert status == 413 and "larger than" in answer["reason"]
    limit = SubmitLimits().code_bytes
    assert call(server, "POST", "/robots/alice/code/saved", ALICE,
                {"language": "python", "text": "x" * (limit + 1)})[0] == 413
    assert call(server, "POST", "/robots/alice/code/saved", ALICE,
                {"language": "python", "text": "x" * limit})[0] == 200
    assert server.health()["status"] == "ok"


def test_bad_requests_get_their_reason(server: ServerProcess) -> None:
    path = "/robots/alice/code/saved"
    assert call(server, "POST", path, ALICE, {"language": "cobol", "text": ""})[0] == 400
    assert call(server, "POST", path, ALICE, {"language": "python"})[0] == 400
    assert call(server, "POST", path, ALICE, ["not", "an", "object"])[0] == 400
    assert call(server, "DELETE", path, ALICE)[0] == 405
    assert call(server, "GET", "/robots/nobody/code/saved", ALICE)[0] == 404
    status, answer = call(server, "POST", "/robots/alice/code/submit", ALICE,
                          {"language": "python", "text": "", "assignment": "../../etc/passwd"})
    assert status == 400 and "no assignment" in answer["reason"]
    assert call(server, "GET", "/class/submissions.json", ALICE)[0] == 403
    assert call(server, "GET", "/class/code.zip")[0] == 403


def test_a_thousand_submits_are_bounded(roster: Path) -> None:
    server = class_server(roster, "--grade-jobs", "1", "--grade-per-hour", "5")
    try:
        program = {"language": "python", "assignment": "heading_pid",
                   "text": "import time\ntime.sleep(30)\n"}  # never connects: holds its job
        status, answer = call(server, "POST", "/robots/bob/code/submit", BOB, program)
        assert status == 202
        wait_for(lambda: call(server, "GET", "/robots/bob/code/submission", BOB)[1]["state"]
                 == "running", what="bob's submission to take the one job")
        statuses = [call(server, "POST", "/robots/alice/code/submit", ALICE, program)[0]
                    for _ in range(1000)]
        # each replaced the one still waiting, until the hour's five; then refused
        assert statuses == [202] * 5 + [429] * 995
        answer = call(server, "GET", "/robots/alice/code/submission", ALICE)[1]
        assert answer["state"] == "queued" and answer["position"] == 1
        status, answer = call(server, "POST", "/robots/alice/code/submit", ALICE, program)
        assert status == 429 and "5 submissions an hour" in answer["reason"]
        status, answer = call(server, "POST", "/robots/bob/code/submit", BOB, program)
        assert status == 409 and "being graded" in answer["reason"]
        assert server.health()["status"] == "ok"
    finally:
        server.stop()


def test_submissions_are_graded_kept_across_a_restart_and_seen_by_the_instructor(
        roster: Path, tmp_path: Path) -> None:
    server = class_server(roster)
    try:
        text = (SOLUTIONS / "heading_pid.py").read_text()
        status, answer = call(server, "POST", "/robots/alice/code/submit", ALICE,
                              {"language": "python", "text": text,
                               "assignment": "heading_pid"})
        assert status == 202 and answer["state"] == "queued" and answer["position"] == 1
        done = wait_for(lambda: (lambda a: a if a["state"] in ("done", "failed") else None)(
            call(server, "GET", "/robots/alice/code/submission", ALICE)[1]), timeout_s=300,
            what="alice's submission to be graded")
        assert done["state"] == "done", done
        assert done["result"]["total"] == 1.0
        assert done["result"]["scenarios"][0]["metrics"][0]["name"] == "heading_step"
        report = call(server, "GET", "/robots/alice/code/report/heading_pid", ALICE)
        assert report[0] == 200 and b"heading_pid" in report[1]
        # submitting saved the program too
        saved = call(server, "GET", "/robots/alice/code/saved", ALICE)[1]["versions"]
        assert saved[0]["text"] == text and saved[0]["reason"] == "submit"
    finally:
        server.stop()
    again = class_server(roster)
    try:
        kept = call(again, "GET", "/robots/alice/code/submission", ALICE)[1]
        assert kept["state"] == "done" and kept["result"] == done["result"]
        assert call(again, "GET", "/robots/alice/code/report/heading_pid", ALICE)[1] == report[1]
        assert call(again, "GET", "/robots/bob/code/submission", BOB)[1] == {"state": "none"}
        overview = call(again, "GET", "/class/submissions.json", ADMIN_TOKEN)[1]
        by_name = {student["name"]: student for student in overview["students"]}
        assert by_name["alice"]["submission"]["result"]["total"] == 1.0
        assert by_name["alice"]["saved"]["text"] == text
        assert by_name["bob"]["submission"] is None and by_name["bob"]["saved"] is None
    finally:
        again.stop()


@pytest.mark.skipif(shutil.which("node") is None, reason="node not installed")
def test_the_class_export_grades_in_one_go_with_websim_grade_submissions(
        server: ServerProcess, tmp_path: Path) -> None:
    for robot, token, solution, language in (("alice", ALICE, "heading_pid.py", "python"),
                                             ("bob", BOB, "heading_pid.js", "javascript")):
        assert call(server, "POST", f"/robots/{robot}/code/saved", token,
                    {"language": language, "text": (SOLUTIONS / solution).read_text(),
                     "reason": "save"})[0] == 200
    status, data = call(server, "GET", "/class/code.zip", ADMIN_TOKEN)
    assert status == 200
    folder = tmp_path / "class"
    zipfile.ZipFile(io.BytesIO(data)).extractall(folder)
    assert (folder / "alice" / "websim-submission.yaml").read_text() == \
        "command: python3 controller.py\n"
    assert (folder / "bob" / "websim-submission.yaml").read_text() == \
        "command: node controller.js\n"
    assert (folder / "bob" / "node_modules" / "roslib" / "package.json").is_file()
    result = subprocess.run([sys.executable, "-m", "websim.cli", "grade", "heading_pid",
                             "--submissions", str(folder), "--out", str(tmp_path / "grades")],
                            capture_output=True, text=True, timeout=900, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    with (tmp_path / "grades" / "grades.csv").open() as grades:
        totals = {row["student"]: float(row["total"]) for row in csv.DictReader(grades)}
    assert totals == {"alice": 1.0, "bob": 1.0}


def test_submit_says_why_when_the_sandbox_cannot_run_and_saving_still_works(
        roster: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    tools = tmp_path / "bin"  # util-linux's tools, and no bubblewrap
    tools.mkdir()
    for name in ("prlimit", "setpriv", "nsenter", "nice"):
        found = shutil.which(name)
        if found:
            (tools / name).symlink_to(found)
    monkeypatch.setenv("PATH", str(tools))
    server = class_server(roster)
    try:
        starters = call(server, "GET", "/robots/alice/code/starters.json")[1]
        assert starters["submitting"]["enabled"] is False
        assert "bubblewrap" in starters["submitting"]["reason"]
        status, answer = call(server, "POST", "/robots/alice/code/submit", ALICE,
                              {"language": "python", "text": "print(1)",
                               "assignment": "heading_pid"})
        assert status == 503 and "bubblewrap" in answer["reason"]
        assert call(server, "POST", "/robots/alice/code/saved", ALICE,
                    {"language": "python", "text": "print(1)", "reason": "run"})[0] == 200
    finally:
        server.stop()


def test_the_state_file_keeps_versions_per_language_and_autosaves_replace_autosaves(
        tmp_path: Path) -> None:
    state = ClassState(tmp_path / "state.sqlite", "robots:2")
    try:
        assert state.save_code("alice", "python", "a", AUTOSAVE, 1.0, keep=3) == 1
        assert state.save_code("alice", "python", "ab", AUTOSAVE, 2.0, keep=3) == 1
        assert state.save_code("alice", "python", "ab", "run", 3.0, keep=3) == 1  # same text
        assert state.save_code("alice", "python", "abc", AUTOSAVE, 4.0, keep=3) == 2
        assert state.save_code("alice", "python", "abcd", "run", 5.0, keep=3) == 3
        assert state.save_code("alice", "python", "abcde", "run", 6.0, keep=3) == 4
        assert state.save_code("alice", "javascript", "x", "run", 7.0, keep=3) == 5
        versions = state.code_versions("alice")
        assert [(v["version"], v["text"]) for v in versions] == [
            (5, "x"), (4, "abcde"), (3, "abcd"), (2, "abc")]
        assert state.newest_code()["alice"]["text"] == "x"
        assert state.code_versions("bob") == []
    finally:
        state.close()
    fresh = ClassState(tmp_path / "state.sqlite", "robots:2", fresh=True)
    try:
        assert fresh.code_versions("alice") == [] and fresh.submissions() == {}
    finally:
        fresh.close()


def test_the_port_of_a_stopped_server_is_free_again(roster: Path) -> None:
    """A server with Submit's workers stops cleanly on SIGTERM (its queue's tasks end)."""
    port = free_port()
    server = start_server(["--class", str(roster), "--state",
                           str(roster.with_suffix(".sqlite"))], http_port=port)
    assert server.stop() == 0, "".join(server.output)
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        probe.bind(("127.0.0.1", port))
    assert os.path.exists(roster.with_suffix(".sqlite"))
