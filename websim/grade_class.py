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

import yaml

from grading import Suite
from physics import ConfigError
from websim.grade_run import GradeOptions, grade_submission

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

    Raises:
        ConfigError: the file is missing or not ``command: ...`` with an optional
            ``ros: true|false`` (the message says which).
    """
    path = folder / SUBMISSION_FILE
    if not path.is_file():
        raise ConfigError(f"{path.name}: missing: a submission declares its command there "
                          f"(command: python3 controller.py)")
    if path.stat().st_size > MAX_SUBMISSION_FILE_BYTES:
        raise ConfigError(f"{path.name}: larger than {MAX_SUBMISSION_FILE_BYTES} bytes")
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as error:
        raise ConfigError(f"{path.name}: not YAML: {error}") from None
    if not isinstance(document, dict) or set(document) - set(SUBMISSION_KEYS):
        raise ConfigError(f"{path.name}: expected only 'command: ...' (and 'ros: true' for an "
                          f"rclpy node), got {document!r:.80}")
    ros = document.get("ros", False)
    if not isinstance(ros, bool):
        raise ConfigError(f"{path.name}: ros: expected true or false, got {ros!r:.40}")
    command = document.get("command")
    if isinstance(command, str):
        try:
            command = shlex.split(command)
        except ValueError as error:
            raise ConfigError(f"{path.name}: command: {error}") from None
    if (not isinstance(command, list) or not command or len(command) > MAX_COMMAND_ARGS
            or not all(isinstance(arg, str) and arg for arg in command)):
        raise ConfigError(f"{path.name}: command: expected a command line or a list of "
                          f"words, got {command!r:.80}")
    return Declared(command, ros, _ros_parameters(path.name, document, ros))


def _ros_parameters(name: str, document: dict[str, Any],
                    ros: bool) -> tuple[tuple[str, str], ...]:
    """``ros_parameters: {kp: WEBSIM_KP}``, checked: ROS names to scenario variables."""
    mapping = document.get("ros_parameters")
    if mapping is None:
        return ()
    if not ros:
        raise ConfigError(f"{name}: ros_parameters: needs 'ros: true' (an rclpy node)")
    if not isinstance(mapping, dict) or len(mapping) > MAX_ROS_PARAMETERS:
        raise ConfigError(f"{name}: ros_parameters: expected at most {MAX_ROS_PARAMETERS} "
                          f"'parameter: WEBSIM_NAME' entries, got {mapping!r:.80}")
    pairs = []
    for parameter, variable in mapping.items():
        if not isinstance(parameter, str) or not ROS_PARAMETER_NAME.match(parameter):
            raise ConfigError(f"{name}: ros_parameters: {parameter!r:.40} is not a ROS "
                              "parameter name")
        if not isinstance(variable, str) or not SCENARIO_VARIABLE.match(variable):
            raise ConfigError(f"{name}: ros_parameters: {parameter}: expected a scenario's "
                              f"variable (WEBSIM_NAME, e.g. WEBSIM_KP), got {variable!r:.40}")
        pairs.append((parameter, variable))
    return tuple(pairs)


def grade_class(suite_file: str | Path, suite: Suite, submissions: Path, out: Path,
                options: GradeOptions, jobs: int | None = None) -> list[dict[str, Any]]:
    """Grade every submission; write grades.csv and class.html; the rows, by student."""
    students = sorted(path for path in submissions.iterdir()
                      if path.is_dir() and not path.name.startswith("."))
    if not students:
        raise ConfigError(f"--submissions {submissions}: no submission folders in it")
    out.mkdir(parents=True, exist_ok=True)
    workers = max(1, jobs or os.cpu_count() or 1)

    def one(folder: Path) -> dict[str, Any]:
        target = out / folder.name
        try:
            declared = submission_declaration(folder)
        except ConfigError as error:
            return _zero_row(folder.name, suite, str(error))
        command = declared.command
        graded = dataclasses.replace(options, ros=options.ros or declared.ros,
                                     ros_parameters=declared.ros_parameters)
        try:
            summary = grade_submission(suite_file, command, folder, target, graded, quiet=True)
        except Exception as error:  # a grader fault for one student must not stop the class
            return _zero_row(folder.name, suite, f"the grader failed: {error}")
        failing = [row for row in summary["scenarios"] if not row["passed"]]
        reason = (f"{failing[0]['name']}: {failing[0]['reason']}" if failing else "passed")
        return {"student": folder.name, "total": summary["total"], "reason": reason,
                "scenarios": {row["name"]: row for row in summary["scenarios"]}}

    with ThreadPoolExecutor(max_workers=workers) as pool:
        rows = list(pool.map(one, students))
    write_csv(out / "grades.csv", suite, rows)
    write_html(out / "class.html", suite, rows)
    return rows


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
                       total_points: float = 100.0) -> dict[str, Any]:
    """Gradescope's results.json of one graded submission (its autograder specification).

    One test per scenario, ``max_score`` its share of ``total_points`` by weight; its
    ``output`` the reason, the run's figures and the controller's last output.
    """
    weights = sum(entry.weight for entry in suite.entries)
    tests = []
    for row in summary["scenarios"]:
        points = total_points * row["weight"] / weights
        report_path = out / row["report"]
        report = json.loads(report_path.read_text()) if report_path.is_file() else {}
        lines = [f"{row['name']}: score {row['score']:.4f}: {row['reason']}"]
        for metric in report.get("metrics", []):
            lines.append(f"  {metric['name']}: value {metric['value']} {metric['unit']}, "
                         f"score {metric['score']:.4f}, {metric['reason']}")
        controller = report.get("controller") or {}
        if controller:
            lines.append(f"controller: {controller.get('reason', '')}")
            tail = controller.get("output_tail", "")[-2000:]
            if tail:
                lines.append("its last output:\n" + tail)
        tests.append({"name": row["name"], "score": round(points * row["score"], 4),
                      "max_score": round(points, 4),
                      "status": "passed" if row["passed"] else "failed",
                      "output": "\n".join(lines)})
    return {"score": round(total_points * summary["total"], 4), "tests": tests,
            "output": f"websim grade, {summary['mode']} mode: {summary['suite']} total "
                      f"{summary['total']:.4f}",
            "visibility": "visible", "stdout_visibility": "visible"}


def gradescope_refusal(suite: Suite, reason: str, total_points: float = 100.0
                       ) -> dict[str, Any]:
    """Gradescope's results.json for a submission that could not be run (every test 0)."""
    weights = sum(entry.weight for entry in suite.entries)
    tests = [{"name": entry.scenario.name, "score": 0.0,
              "max_score": round(total_points * entry.weight / weights, 4),
              "status": "failed", "output": f"not run: {reason}"} for entry in suite.entries]
    return {"score": 0.0, "tests": tests, "output": f"websim grade: not graded: {reason}",
            "visibility": "visible", "stdout_visibility": "visible"}


def write_gradescope(path: Path, results: dict[str, Any]) -> None:
    """Write results.json (its folder made if needed)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results, indent=2))


__all__ = ["SUBMISSION_FILE", "grade_class", "gradescope_refusal", "gradescope_results",
           "submission_command", "submission_declaration", "write_gradescope"]
