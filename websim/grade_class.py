"""A class at a time (``websim grade SUITE --submissions DIR``), and Gradescope's results.json.

Every folder of DIR is a student's submission, named after the student, declaring its
command in ``websim-submission.yaml``::

    command: python3 wall_follower.py          # or a list: [python3, wall_follower.py]
    ros: true                                  # optional: an rclpy node (websim grade --ros)
    ros_parameters: {kp: WEBSIM_KP}            # optional, with ros: -p kp:=<WEBSIM_KP's value>

Submissions are graded in parallel (up to the machine's cores, ``--jobs``), each as
``websim grade`` grades one (its own sandbox and simulator per run), into ``OUT/STUDENT/``.
A submission that crashes, hangs or declares nothing scores 0 with the reason (and its last
output, in its reports). Then ``OUT/grades.csv`` (student, each scenario's score, total,
reason) and ``OUT/class.html`` (a sortable table, self-contained, each row linking the
student's reports).
"""

from __future__ import annotations

import csv
import dataclasses
import html
import json
import os
import re
import shlex
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, NamedTuple

from grading import Suite
from grading.results import figure
from physics import ConfigError
from physics.validation import load_yaml_file
from websim.grade_run import GradeOptions, grade_submission
from websim.sandbox.submission import SubmissionRefusedError, open_own_file

SUBMISSION_FILE = "websim-submission.yaml"
SUBMISSION_KEYS = ("command", "ros", "ros_parameters")
MAX_ROS_PARAMETERS = 32
ROS_PARAMETER_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.]{0,99}\Z")
"""A ROS parameter's name (dots for nested names)."""
SCENARIO_VARIABLE = re.compile(r"WEBSIM_[A-Z0-9_]{1,80}\Z")
"""What ``ros_parameters`` maps a parameter to: a scenario's variable (``WEBSIM_KP``)."""
MAX_COMMAND_ARGS = 64
MAX_SUBMISSION_FILE_BYTES = 64 * 1024


class Declared(NamedTuple):
    """What a submission's ``websim-submission.yaml`` declares.

    Attributes:
        command: the controller's command line, as words.
        ros: ``ros: true``: the controller is an rclpy node, graded as with ``--ros``.
        ros_parameters: ``ros_parameters``: (ROS parameter, scenario variable) pairs: the
            node gets ``-p NAME:=VALUE`` with the variable's value in each scenario.
    """

    command: list[str]
    ros: bool
    ros_parameters: tuple[tuple[str, str], ...] = ()


def submission_command(folder: Path) -> list[str]:
    """The command a submission declares in its ``websim-submission.yaml``.

    Raises:
        ConfigError: the file is missing or not ``command: ...`` (the message says which).
    """
    return submission_declaration(folder).command


def submission_declaration(folder: Path) -> Declared:
    """The command (and ``ros``) a submission declares in its ``websim-submission.yaml``.

    The file is read as the student's and nothing else: a regular file of the folder itself,
    never through a symbolic link (``websim.sandbox.submission.open_own_file``), at most
    ``MAX_SUBMISSION_FILE_BYTES``, parsed by the project's bounded YAML loader; the errors
    quote nothing but the file's own lines and its keys' names.

    Raises:
        ConfigError: the file is missing, a link, too large, not YAML, or not
            ``command: ...`` with an optional ``ros: true|false`` (the message says which).
    """
    try:
        with open_own_file(folder, SUBMISSION_FILE, MAX_SUBMISSION_FILE_BYTES) as fd:
            if fd is None:
                raise ConfigError(f"{SUBMISSION_FILE}: missing: a submission declares its "
                                  "command there (command: python3 controller.py)")
            opened = f"/proc/self/fd/{fd}"
            try:
                document = load_yaml_file(opened, "submission", MAX_SUBMISSION_FILE_BYTES)
            except ConfigError as error:
                raise ConfigError(str(error).replace(opened, SUBMISSION_FILE)) from None
            except RecursionError:
                raise ConfigError(f"{SUBMISSION_FILE}: nested too deep") from None
    except SubmissionRefusedError as error:
        raise ConfigError(f"{SUBMISSION_FILE}: {error}") from None
    if not isinstance(document, dict):
        raise ConfigError(f"{SUBMISSION_FILE}: expected 'command: ...' (and 'ros: true' for an "
                          f"rclpy node), got {_kind(document)}")
    unknown = [key for key in document if key not in SUBMISSION_KEYS]
    if unknown:
        names = ", ".join(_quoted(key) for key in unknown[:5])
        raise ConfigError(f"{SUBMISSION_FILE}: unknown key(s) {names}: expected only "
                          f"{', '.join(SUBMISSION_KEYS)}")
    ros = document.get("ros", False)
    if not isinstance(ros, bool):
        raise ConfigError(f"{SUBMISSION_FILE}: ros: expected true or false, got {_kind(ros)}")
    command = document.get("command")
    if isinstance(command, str):
        try:
            command = shlex.split(command)
        except ValueError as error:
            raise ConfigError(f"{SUBMISSION_FILE}: command: {error}") from None
    if (not isinstance(command, list) or not command or len(command) > MAX_COMMAND_ARGS
            or not all(isinstance(arg, str) and arg and len(arg) <= MAX_ARG_CHARS
                       for arg in command)):
        raise ConfigError(f"{SUBMISSION_FILE}: command: expected a command line or a list of "
                          f"at most {MAX_COMMAND_ARGS} words, got {_kind(command)}")
    return Declared(command, ros, _ros_parameters(document, ros))


def _ros_parameters(document: dict[str, Any], ros: bool) -> tuple[tuple[str, str], ...]:
    """``ros_parameters: {kp: WEBSIM_KP}``, checked: ROS names to scenario variables."""
    mapping = document.get("ros_parameters")
    if mapping is None:
        return ()
    where = f"{SUBMISSION_FILE}: ros_parameters"
    if not ros:
        raise ConfigError(f"{where}: needs 'ros: true' (an rclpy node)")
    if not isinstance(mapping, dict) or len(mapping) > MAX_ROS_PARAMETERS:
        raise ConfigError(f"{where}: expected at most {MAX_ROS_PARAMETERS} "
                          f"'parameter: WEBSIM_NAME' entries, got {_kind(mapping)}")
    pairs = []
    for parameter, variable in mapping.items():
        if not isinstance(parameter, str) or not ROS_PARAMETER_NAME.match(parameter):
            raise ConfigError(f"{where}: {_quoted(parameter)} is not a ROS parameter name")
        if not isinstance(variable, str) or not SCENARIO_VARIABLE.match(variable):
            raise ConfigError(f"{where}: {parameter}: expected a scenario's variable "
                              f"(WEBSIM_NAME, e.g. WEBSIM_KP), got {_kind(variable)}")
        pairs.append((parameter, variable))
    return tuple(pairs)


MAX_ARG_CHARS = 4096


def _kind(value: object) -> str:
    """A value of a submission file, named not quoted (an alias bomb's repr never ends)."""
    if value is None:
        return "nothing"
    if isinstance(value, (list, dict, str)):
        return f"a {type(value).__name__} of {len(value)}"
    return f"a {type(value).__name__}"


def _quoted(key: object) -> str:
    text = key if isinstance(key, str) else _kind(key)
    return repr(text[:40] + ("..." if len(text) > 40 else ""))


def grade_class(suite_file: str | Path, suite: Suite, submissions: Path, out: Path,
                options: GradeOptions, jobs: int | None = None) -> list[dict[str, Any]]:
    """Grade every submission; write grades.csv and class.html; the rows, by student.

    One student's submission (a bad file, a link, a crash) is that student's zero with the
    reason, never the class's: grades.csv and class.html are written for everyone.
    """
    students = sorted(path for path in submissions.iterdir()
                      if (path.is_dir() or path.is_symlink()) and not path.name.startswith("."))
    if not students:
        raise ConfigError(f"--submissions {submissions}: no submission folders in it")
    out.mkdir(parents=True, exist_ok=True)
    workers = max(1, jobs or os.cpu_count() or 1)

    def one(folder: Path) -> dict[str, Any]:
        try:
            return grade_student(folder)
        except Exception as error:  # a grader fault for one student must not stop the class
            return _zero_row(folder.name, suite, f"the grader failed: {_last_line(error)}")

    def grade_student(folder: Path) -> dict[str, Any]:
        if folder.is_symlink():
            return _zero_row(folder.name, suite, "the submission folder is a symbolic link: "
                                                 "not graded")
        target = out / folder.name
        try:
            declared = submission_declaration(folder)
        except ConfigError as error:
            return _zero_row(folder.name, suite, str(error))
        graded = dataclasses.replace(options, ros=options.ros or declared.ros,
                                     ros_parameters=declared.ros_parameters)
        summary = grade_submission(suite_file, declared.command, folder, target, graded,
                                   quiet=True)
        failing = [row for row in summary["scenarios"] if not row["passed"]]
        reason = (f"{failing[0]['name']}: {failing[0]['reason']}" if failing else "passed")
        return {"student": folder.name, "total": summary["total"], "reason": reason,
                "scenarios": {row["name"]: row for row in summary["scenarios"]}}

    rows: list[dict[str, Any]] = []
    try:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            rows = list(pool.map(one, students))
    finally:
        done = {row["student"] for row in rows}
        rows += [_zero_row(folder.name, suite, "not graded: grading was interrupted")
                 for folder in students if folder.name not in done]
        write_csv(out / "grades.csv", suite, rows)
        write_html(out / "class.html", suite, rows)
    return rows


def _last_line(error: BaseException) -> str:
    """An exception's type and the last line of its message."""
    lines = str(error).strip().splitlines()
    return f"{type(error).__name__}: {lines[-1] if lines else ''}"[:300]


def _zero_row(student: str, suite: Suite, reason: str) -> dict[str, Any]:
    return {"student": student, "total": 0.0, "reason": reason,
            "scenarios": {entry.scenario.name: {"name": entry.scenario.name, "score": 0.0,
                                                "passed": False, "reason": reason,
                                                "report": None}
                          for entry in suite.entries}}


def write_csv(path: Path, suite: Suite, rows: Sequence[dict[str, Any]]) -> None:
    """grades.csv: student, each scenario's score, total, reason."""
    names = [entry.scenario.name for entry in suite.entries]
    with path.open("w", newline="", encoding="utf-8") as file:
        writer = csv.writer(file)
        writer.writerow(["student", *names, "total", "reason"])
        for row in rows:
            writer.writerow([row["student"],
                             *(f"{row['scenarios'][name]['score']:.4f}" for name in names),
                             f"{row['total']:.4f}", row["reason"]])


SORT_SCRIPT = """
document.querySelectorAll('th').forEach((th, column) => th.addEventListener('click', () => {
  const body = th.closest('table').tBodies[0];
  const up = th.dataset.order !== 'up';
  th.dataset.order = up ? 'up' : 'down';
  const key = (row) => row.cells[column].dataset.value ?? row.cells[column].textContent;
  const rows = [...body.rows].sort((a, b) => {
    const x = key(a), y = key(b), nx = parseFloat(x), ny = parseFloat(y);
    const order = isNaN(nx) || isNaN(ny) ? x.localeCompare(y) : nx - ny;
    return up ? order : -order;
  });
  rows.forEach((row) => body.appendChild(row));
}));
"""

STYLE = """
body { font-family: sans-serif; margin: 1.5em; }
table { border-collapse: collapse; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }
th { cursor: pointer; background: #eee; }
td.name, td.reason { text-align: left; }
td.failed { color: #a00; }
"""


def write_html(path: Path, suite: Suite, rows: Sequence[dict[str, Any]]) -> None:
    """class.html: a sortable table (click a heading), no internet needed."""
    names = [entry.scenario.name for entry in suite.entries]
    head = "".join(f"<th>{html.escape(name)}</th>" for name in ["student", *names, "total",
                                                                 "reason"])
    lines = []
    for row in rows:
        student = html.escape(row["student"])
        cells = [f'<td class="name"><a href="{student}/summary.json">{student}</a></td>'
                 if (path.parent / row["student"] / "summary.json").is_file()
                 else f'<td class="name">{student}</td>']
        for name in names:
            scenario = row["scenarios"][name]
            score = f"{scenario['score']:.4f}"
            css = "" if scenario["passed"] else ' class="failed"'
            target = _report_link(path.parent, row["student"], scenario.get("report"))
            text = f'<a href="{html.escape(target)}">{score}</a>' if target else score
            cells.append(f'<td{css} data-value="{score}" title="'
                         f'{html.escape(scenario["reason"])}">{text}</td>')
        cells.append(f'<td data-value="{row["total"]:.4f}">{row["total"]:.4f}</td>')
        cells.append(f'<td class="reason">{html.escape(row["reason"])}</td>')
        lines.append(f"<tr>{''.join(cells)}</tr>")
    title = html.escape(f"{suite.name}: {len(rows)} submissions")
    path.write_text(
        f"<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>{title}</title>"
        f"<style>{STYLE}</style></head><body><h1>{title}</h1>"
        f"<p>Click a heading to sort; a score links to its run's report.</p>"
        f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(lines)}</tbody></table>"
        f"<script>{SORT_SCRIPT}</script></body></html>", encoding="utf-8")


def _report_link(out: Path, student: str, report: str | None) -> str | None:
    if report is None:
        return None
    page = Path(student) / Path(report).with_name("report.html")
    return str(page if (out / page).is_file() else Path(student) / report)


def gradescope_results(summary: dict[str, Any], suite: Suite, out: Path,
                       total_points: float = 100.0, *,
                       execution_time_s: float | None = None) -> dict[str, Any]:
    """Gradescope's results.json of one graded submission (its autograder specification).

    One test per scenario, ``max_score`` its share of ``total_points`` by weight, its
    ``visibility`` the suite entry's; its ``output`` (Markdown) the reason, each metric's
    figures, the controller's end and last output. ``leaderboard``: each passed scenario's
    first timed metric (time to goal, settling time), lower first. ``extra_data.receipt``:
    the hashes of the submission and the suite, and the seeds (re-run exactly).
    """
    weights = sum(entry.weight for entry in suite.entries)
    visibility = {entry.scenario.name: entry.visibility for entry in suite.entries}
    tests: list[dict[str, Any]] = []
    leaderboard: list[dict[str, Any]] = []
    for row in summary["scenarios"]:
        points = total_points * row["weight"] / weights
        report_path = out / row["report"]
        report = json.loads(report_path.read_text()) if report_path.is_file() else {}
        lines = [f"**{row['name']}**: score {row['score']:.4f}, "
                 f"{'passed' if row['passed'] else 'failed'}: {row['reason']}", ""]
        timed = False
        for metric in report.get("metrics", []):
            lines.append(f"- {metric['name']}: {figure(metric['value'], metric['unit'])} "
                         f"(limit {figure(metric.get('threshold'), metric['unit'])}), score "
                         f"{metric['score']:.4f}: {metric['reason']}")
            if (row["passed"] and not timed and metric["unit"] == "s"
                    and metric["value"] is not None):
                timed = True
                leaderboard.append({"name": f"{row['name']}: {metric['name']} (s)",
                                    "value": round(float(metric["value"]), 3),
                                    "order": "asc"})
        controller = report.get("controller") or {}
        if controller:
            lines += ["", f"controller: {controller.get('reason', '')}"]
            tail = controller.get("output_tail", "")[-2000:]
            if tail:
                fenced = tail.replace("```", "` ` `")
                lines += ["", "its last output:", "", "```", fenced, "```"]
        tests.append({"name": row["name"], "score": round(points * row["score"], 4),
                      "max_score": round(points, 4),
                      "status": "passed" if row["passed"] else "failed",
                      "visibility": visibility.get(row["name"], "visible"),
                      "output": "\n".join(lines), "output_format": "md"})
    results: dict[str, Any] = {
        "score": round(total_points * summary["total"], 4), "tests": tests,
        "output": f"websim grade, {summary['mode']} mode: {summary['suite']} total "
                  f"{summary['total']:.4f}",
        "output_format": "md", "visibility": "visible", "stdout_visibility": "visible",
        "extra_data": {"receipt": summary.get("receipt", {})}}
    if leaderboard:
        results["leaderboard"] = leaderboard
    if execution_time_s is not None:
        results["execution_time"] = round(execution_time_s)
    return results


def gradescope_refusal(suite: Suite, reason: str, total_points: float = 100.0
                       ) -> dict[str, Any]:
    """Gradescope's results.json for a submission that could not be run (every test 0)."""
    weights = sum(entry.weight for entry in suite.entries)
    tests = [{"name": entry.scenario.name, "score": 0.0,
              "max_score": round(total_points * entry.weight / weights, 4),
              "status": "failed", "visibility": entry.visibility,
              "output": f"not run: {reason}", "output_format": "text"}
             for entry in suite.entries]
    return {"score": 0.0, "tests": tests, "output": f"websim grade: not graded: {reason}",
            "output_format": "text", "visibility": "visible", "stdout_visibility": "visible"}


def write_gradescope(path: Path, results: dict[str, Any]) -> None:
    """Write results.json (its folder made if needed; atomically: all of it or none)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.tmp")
    temporary.write_text(json.dumps(results, indent=2))
    temporary.replace(path)


__all__ = ["SUBMISSION_FILE", "grade_class", "gradescope_refusal", "gradescope_results",
           "submission_command", "submission_declaration", "write_gradescope"]
