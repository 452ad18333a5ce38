"""``websim grade --submissions``: a class graded at once (grades.csv, class.html), and the
Gradescope example's run_autograder on a fake /autograder tree, its results.json checked."""

from __future__ import annotations

import csv
import json
import os
import shutil
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from physics import ConfigError
from websim import cli
from websim.grade_class import SUBMISSION_FILE, submission_command, submission_declaration

ROOT = Path(__file__).resolve().parent.parent
SOLUTION = ROOT / "examples" / "solutions" / "heading_pid.py"
GRADESCOPE = ROOT / "examples" / "gradescope"
SANDBOXED = shutil.which("bwrap") is not None and os.geteuid() == 0
"""Where the sandbox can run, the tests grade in it; elsewhere with --no-sandbox (no skip)."""


def student(folder: Path, command: str | None, **files: str) -> None:
    folder.mkdir(parents=True)
    shutil.copy(SOLUTION, folder / SOLUTION.name)
    if command is not None:
        (folder / SUBMISSION_FILE).write_text(f"command: {command}\n")
    for name, text in files.items():
        (folder / name).write_text(text)


def test_a_class_is_graded_into_grades_csv_and_class_html(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    submissions = tmp_path / "submissions"
    student(submissions / "alice", "python3 heading_pid.py")
    student(submissions / "bob", "env WEBSIM_KP=-4 python3 heading_pid.py")
    student(submissions / "carol", "python3 crash.py", **{"crash.py": "print('oops')\n1/0\n"})
    student(submissions / "dave", None)
    out = tmp_path / "out"
    sandbox = () if SANDBOXED else ("--no-sandbox",)
    assert cli.main(["grade", "heading_pid", "--submissions", str(submissions), "--out",
                     str(out), *sandbox]) == 1  # bob, carol and dave failed
    assert "4 submissions graded" in capsys.readouterr().out
    with (out / "grades.csv").open() as file:
        rows = {row["student"]: row for row in csv.DictReader(file)}
    assert list(rows) == ["alice", "bob", "carol", "dave"]
    assert float(rows["alice"]["heading_pid"]) == 1.0 and rows["alice"]["reason"] == "passed"
    assert float(rows["alice"]["total"]) == 1.0
    assert float(rows["bob"]["total"]) == 0.0
    assert rows["bob"]["reason"].startswith("heading_pid: heading_step: ")
    assert float(rows["carol"]["total"]) == 0.0
    assert "ZeroDivisionError" in json.loads(
        (out / "carol" / "heading_pid" / "report.json").read_text())["controller"]["output_tail"]
    assert "exited with code 1" in rows["carol"]["reason"]
    assert float(rows["dave"]["total"]) == 0.0
    assert f"{SUBMISSION_FILE}: missing" in rows["dave"]["reason"]
    page = (out / "class.html").read_text()
    assert 'href="alice/heading_pid/report.html"' in page
    assert "addEventListener('click'" in page  # sortable
    assert "http://" not in page and "https://" not in page  # self-contained


def test_a_submission_file_is_checked(tmp_path: Path) -> None:
    (tmp_path / SUBMISSION_FILE).write_text("command: [python3, a.py]\n")
    assert submission_command(tmp_path) == ["python3", "a.py"]
    (tmp_path / SUBMISSION_FILE).write_text("comand: python3 a.py\n")
    with pytest.raises(ConfigError, match=r"unknown key\(s\) 'comand': expected only "
                                          r"command, ros"):
        submission_command(tmp_path)
    (tmp_path / SUBMISSION_FILE).write_text("command: python3 a.py\nros: true\n")
    assert submission_declaration(tmp_path) == (["python3", "a.py"], True, ())
    (tmp_path / SUBMISSION_FILE).write_text("command: python3 a.py\nros: yes please\n")
    with pytest.raises(ConfigError, match="ros: expected true or false"):
        submission_command(tmp_path)
    (tmp_path / SUBMISSION_FILE).write_text("command: 'python3 \"a.py'\n")
    with pytest.raises(ConfigError, match="command: No closing quotation"):
        submission_command(tmp_path)


def test_run_autograder_writes_gradescope_results(tmp_path: Path) -> None:
    root = tmp_path / "autograder"
    source, submission = root / "source", root / "submission"
    shutil.copytree(GRADESCOPE, source)
    submission.mkdir(parents=True)
    shutil.copy(SOLUTION, submission / SOLUTION.name)
    shutil.copy(GRADESCOPE / SUBMISSION_FILE, submission / SUBMISSION_FILE)
    (root / "results").mkdir()
    env = {**os.environ, "AUTOGRADER_ROOT": str(root),
           "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
           "WEBSIM_GRADE_OPTIONS": "--points 10" + ("" if SANDBOXED else " --no-sandbox")}
    done = subprocess.run(["bash", str(source / "run_autograder")], env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr
    results = json.loads((root / "results" / "results.json").read_text())
    tests = results["tests"]
    assert [test["name"] for test in tests] == ["heading_pid", "heading_pid_payload"]
    for test in tests:
        assert set(test) >= {"name", "score", "max_score", "status", "output"}
        assert test["status"] in ("passed", "failed")
        assert 0.0 <= test["score"] <= test["max_score"]
    assert [test["max_score"] for test in tests] == pytest.approx([20 / 3, 10 / 3], abs=1e-3)
    assert tests[0]["status"] == "passed" and tests[0]["score"] == tests[0]["max_score"]
    assert tests[1]["status"] == "failed" and "heading_step" in tests[1]["output"]
    assert results["score"] == pytest.approx(sum(test["score"] for test in tests), abs=1e-3)
    # Gradescope's conventions: Markdown output, per-test visibility (suite.yaml hides the
    # bonus until the due date), the time a run took, a leaderboard, a receipt to re-run
    assert results["output_format"] == "md" and results["execution_time"] > 0
    assert [test["visibility"] for test in tests] == ["visible", "after_due_date"]
    assert all(test["output_format"] == "md" for test in tests)
    assert results["leaderboard"][0]["name"] == "heading_pid: heading_step (s)"
    assert results["leaderboard"][0]["order"] == "asc"
    receipt = results["extra_data"]["receipt"]
    assert len(receipt["submission_sha256"]) == 64 and len(receipt["suite_sha256"]) == 64
    assert receipt["seeds"] == {"heading_pid": 0, "heading_pid_payload": 0}
    assert "value None" not in json.dumps(results)
    assert stat.S_IMODE((root / "results" / "results.json").stat().st_mode) == 0o600


def test_run_autograder_without_a_submission_file_gives_a_readable_zero(tmp_path: Path) -> None:
    root = tmp_path / "autograder"
    shutil.copytree(GRADESCOPE, root / "source")
    (root / "submission").mkdir(parents=True)
    shutil.copy(SOLUTION, root / "submission" / SOLUTION.name)
    env = {**os.environ, "AUTOGRADER_ROOT": str(root),
           "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
           "WEBSIM_GRADE_OPTIONS": "" if SANDBOXED else "--no-sandbox"}
    done = subprocess.run(["bash", str(root / "source" / "run_autograder")], env=env,
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    results = json.loads((root / "results" / "results.json").read_text())
    assert results["score"] == 0.0
    assert all(test["status"] == "failed" and test["score"] == 0.0 for test in results["tests"])
    assert f"{SUBMISSION_FILE}: missing" in results["output"]


# --- hostile submission files: the student's own zero, never the grader's secrets --------

SECRET = "hidden-suite-secret: solution = 42"


def test_a_submission_file_that_is_a_link_is_refused_unread(tmp_path: Path) -> None:
    """The Gradescope leak: websim-submission.yaml a link to the hidden suite. Refused
    without reading it (O_NOFOLLOW); the message quotes nothing of the target."""
    secret = tmp_path / "autograder" / "source" / "suite.yaml"
    secret.parent.mkdir(parents=True)
    secret.write_text(f"comand: {SECRET}\n")
    folder = tmp_path / "mallory"
    folder.mkdir()
    (folder / SUBMISSION_FILE).symlink_to(secret)
    with pytest.raises(ConfigError) as refusal:
        submission_declaration(folder)
    assert "is a symbolic link" in str(refusal.value)
    assert "42" not in str(refusal.value) and "secret" not in str(refusal.value)
    (folder / SUBMISSION_FILE).unlink()
    os.mkfifo(folder / SUBMISSION_FILE)  # a pipe would block a plain open() for ever
    with pytest.raises(ConfigError, match="not a regular file"):
        submission_declaration(folder)


@pytest.mark.parametrize(("name", "text", "expected"), [
    ("alias bomb", "a: &a [x, x, x, x, x, x, x, x, x, x]\n"
                   + "".join(f"{chr(98 + k)}: &{chr(98 + k)} [*{chr(97 + k)}, *{chr(97 + k)}, "
                             f"*{chr(97 + k)}, *{chr(97 + k)}, *{chr(97 + k)}, *{chr(97 + k)}, "
                             f"*{chr(97 + k)}, *{chr(97 + k)}, *{chr(97 + k)}, "
                             f"*{chr(97 + k)}]\n" for k in range(8))
                   + "command: *i\n", "websim-submission.yaml"),
    ("recursion", "command: &a [*a]\n", "websim-submission.yaml"),
    ("binary", None, "websim-submission.yaml"),
    ("1 GB", "big", "more than the 64 KiB"),
])
def test_a_bad_submission_file_is_a_zero_with_the_reason_quickly(
        tmp_path: Path, name: str, text: str | None, expected: str) -> None:
    """Each refused in well under a second with a reason that quotes no content: an alias
    bomb's 10^9 leaves are never expanded (nothing repr()s or walks the document)."""
    folder = tmp_path / "mallory"
    folder.mkdir()
    path = folder / SUBMISSION_FILE
    if text is None:
        path.write_bytes(bytes(range(256)) * 64)
    elif text == "big":
        with path.open("wb") as file:
            file.truncate(1 << 30)  # sparse: a gigabyte on paper, nothing on the disk
    else:
        path.write_text(text)
    started = time.monotonic()
    with pytest.raises(ConfigError) as refusal:
        submission_declaration(folder)
    assert time.monotonic() - started < 5.0, name
    message = str(refusal.value)
    assert expected in message and len(message) < 400, message


def test_one_students_hostile_files_do_not_stop_the_class(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A link, an alias bomb, a folder that is a link to the grader's files: each that
    student's zero with the reason; grades.csv and class.html hold everyone, and no output
    holds the secret."""
    secret_dir = tmp_path / "grader-secrets"
    secret_dir.mkdir()
    (secret_dir / SUBMISSION_FILE).write_text(f"command: echo {SECRET}\n")
    submissions = tmp_path / "submissions"
    student(submissions / "alice", "python3 heading_pid.py")
    (submissions / "mallory").mkdir(parents=True)
    (submissions / "mallory" / SUBMISSION_FILE).symlink_to(secret_dir / SUBMISSION_FILE)
    (submissions / "oscar").mkdir()
    (submissions / "oscar" / SUBMISSION_FILE).write_text(
        "a: &a [x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a]\n"
        "c: &c [*b, *b, *b, *b, *b, *b, *b, *b]\ncommand: *c\n")
    (submissions / "trudy").symlink_to(secret_dir)
    out = tmp_path / "out"
    sandbox = () if SANDBOXED else ("--no-sandbox",)
    assert cli.main(["grade", "heading_pid", "--submissions", str(submissions), "--out",
                     str(out), *sandbox]) == 1
    printed = capsys.readouterr().out
    rows = {row["student"]: row for row in csv.DictReader((out / "grades.csv").open())}
    assert sorted(rows) == ["alice", "mallory", "oscar", "trudy"]
    assert float(rows["alice"]["total"]) == 1.0
    assert "is a symbolic link" in rows["mallory"]["reason"]
    assert "unknown key(s) 'a', 'b', 'c'" in rows["oscar"]["reason"]
    assert "the submission folder is a symbolic link" in rows["trudy"]["reason"]
    page = (out / "class.html").read_text()
    for text in (printed, (out / "grades.csv").read_text(), page):
        assert "42" not in text and "hidden-suite" not in text
    assert not (out / "trudy").exists()
    assert stat.S_IMODE((out / "grades.csv").stat().st_mode) == 0o600
    assert stat.S_IMODE((out / "class.html").stat().st_mode) == 0o600
    assert stat.S_IMODE((out / "alice").stat().st_mode) == 0o700
    report = out / "alice" / "heading_pid" / "report.json"
    assert stat.S_IMODE(report.stat().st_mode) == 0o600
