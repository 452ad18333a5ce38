"""One submission graded on a suite: its runs, their reports (``websim grade``'s work).

For each scenario of the suite (a scenario file is a suite of one), and each of ``--runs``:

1. a sandbox for the submission (``websim.sandbox.SubmissionSandbox``; ``--no-sandbox``
   without), and in it the private simulator, ``python -m websim.grade_server`` (the
   scenario's robot and world, its timed changes, lock step in deterministic mode, the
   recording, ``run.json``);
2. the controller, ``COMMAND`` in a copy of ``--submission`` (default: this folder), with
   ``WEBSIM_URL`` and the scenario's ``WEBSIM_<NAME>``, until it exits or the run ends;
3. the score, from the recording's ground truth (``grading.recorded``) by the scenario's
   metrics (``grading.evaluate``); a run that did not run its course (the controller never
   subscribed, stopped answering, or crashed first) scores 0 with the reason; a controller
   that exits with code 0 ends the run, which is scored until its last command.

Each run writes ``report.json`` in ``DIR/SCENARIO/`` (``DIR/SCENARIO/run-K/`` with
``--runs``), prints one line per scenario, and the suite's total; the exit code is 0 when
the runs ran, whatever their scores, 2 for bad input.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import importlib.util
import json
import os
import random
import re
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from grading import Scenario, Suite, controller_environment, evaluate, load_suite
from grading.recorded import (
    TRUTH_FILE,
    IncompleteRecordError,
    bag_folder,
    trajectory_from_truth,
)
from grading.report_page import report_html
from grading.scenario import resolve_scenario_path
from grading.trajectory import Sample, until
from physics import ConfigError
from websim.grade_server import (
    MAX_MISSED_STEPS,
    PROBE_S,
    RECORDING_DIR,
    RUN_FILE,
    STARTUP_TIMEOUT_S,
    STEP_TIMEOUT_S,
    on_robot,
)
from websim.node_roslib import has_roslib, node_modules_found
from websim.sandbox import (
    SandboxLimits,
    SimulatorStartError,
    SubmissionRefusedError,
    SubmissionSandbox,
)
from websim.sandbox.submission import submission_digest

REPORT_FILE = "report.json"
PAGE_FILE = "report.html"

WALL_CLOCK_MARGIN_S = 30.0
"""Wall-clock mode: a run's wall-clock limit is its duration, the controller's start and this."""

WALL_CLOCK_SCORE_TOLERANCE = 0.05
"""Wall-clock mode: how far apart (range) the scores of re-runs of a sound controller may be.
Measured: the reference heading PID 0 (its settling time 1.10-1.15 s, within every limit); a
controller near a limit moves with the host's load, which is why deterministic mode exists."""

ROS_ARGS = ("--ros-args", "-p", "use_sim_time:=true")
"""``--ros``: appended to the controller's command, so an rclpy node (``rclpy.init()`` reads
``sys.argv``) runs on the simulator's ``/clock``."""

ROS_DOMAIN_IDS = range(1, 102)
"""``--ros``: a run's ROS domain is drawn from these (ROS 2's safe range on Linux): in the
sandbox the graph is the run's network namespace's alone anyway; with ``--no-sandbox`` it
keeps parallel runs apart (with discovery on this machine only)."""

DETERMINISTIC_WALL_FACTOR = 4.0
"""Deterministic mode: a run may take this many times its duration in wall time (a
controller answering in 0.2 s each 0.05 s tick), besides its start and missed steps."""


@dataclass(frozen=True)
class GradeOptions:
    """How the submission's runs are made.

    Attributes:
        mode: ``deterministic`` or ``wall-clock`` (``websim.grade_server.MODES``).
        step_on: what a deterministic controller answers (``grade_server.STEP_ON``).
        sandboxed: in a sandbox (False: ``--no-sandbox``).
        runs: runs per scenario (the score is their median; the spread is reported).
        startup_timeout_s: how long the controller may take to connect (wall time, s).
        ros: the controller is an rclpy node (``--ros``): the simulator starts the ROS graph,
            the controller gets ``ROS_DOMAIN_ID`` and ``ROS_ARGS``.
        params: a parameter file whose robot the runs use (``--params``, e.g. ``websim
            fit``'s); None: each scenario's own.
        ros_parameters: (ROS parameter, scenario variable) pairs: with ``ros``, the node
            gets ``-p NAME:=VALUE`` after ``ROS_ARGS``, the variable's value in each scenario
            (``websim-submission.yaml``'s ``ros_parameters``).
        node_modules: folders of Node modules a controller may ``require`` (roslib for Node:
            ``NODE_PATH``); default ``node_modules_found()``.
    """

    mode: str = "deterministic"
    step_on: str = "auto"
    sandboxed: bool = True
    runs: int = 1
    startup_timeout_s: float = STARTUP_TIMEOUT_S
    ros: bool = False
    params: str | None = None
    ros_parameters: tuple[tuple[str, str], ...] = ()
    node_modules: tuple[str, ...] | None = None


def ros_arguments(scenario: Scenario, options: GradeOptions) -> list[str]:
    """What ``--ros`` appends to the controller's command: sim time and its parameters.

    Raises:
        ConfigError: a parameter is mapped to a variable the scenario does not set.
    """
    told = controller_environment(scenario)
    arguments = list(ROS_ARGS)
    for parameter, variable in options.ros_parameters:
        if variable not in told:
            known = ", ".join(sorted(told)) or "none"
            raise ConfigError(f"ros_parameters: {parameter}: {variable} is not set in "
                              f"scenario {scenario.name} (it sets: {known})")
        arguments += ["-p", f"{parameter}:={told[variable]}"]
    return arguments


def python_runtime_paths() -> tuple[str, ...]:
    """Folders a controller must see for websim's Python to import roslibpy.

    Raises:
        RuntimeError: websim's Python has no roslibpy (the message says how to get it).
    """
    spec = importlib.util.find_spec("roslibpy")
    if spec is None or spec.origin is None:
        raise RuntimeError(f"websim's Python ({sys.executable}) has no roslibpy, which a "
                           "graded controller is promised: pip install roslibpy into it "
                           "(it is a dependency of websim: reinstall websim)")
    return (str(Path(spec.origin).resolve().parent.parent),)


def check_runtime(commands: Sequence[Sequence[str]], options: GradeOptions) -> None:
    """Check, before grading, that the runtime the controllers are promised is here.

    Python with roslibpy always; roslib for Node when a command runs ``node``.

    Raises:
        RuntimeError: what is missing, and how to get it.
    """
    python_runtime_paths()
    uses_node = any(command and os.path.basename(command[0]) in ("node", "nodejs")
                    for command in commands)
    if not uses_node:
        return
    if options.node_modules is not None:
        if not any(has_roslib(Path(folder)) for folder in options.node_modules):
            raise RuntimeError(f"--node-modules {', '.join(options.node_modules)}: no "
                               "roslib there (roslib/package.json), which a controller "
                               "running node requires")
    elif not node_modules_found():
        raise RuntimeError(
            "a controller runs node, but this websim has no roslib for Node (neither a "
            "checkout's web-interface/node_modules nor a wheel's websim/_share/node_modules): "
            "npm install roslib@1.4.1 into a folder and give its node_modules with "
            "--node-modules DIR")


def ros_environment(sandboxed: bool) -> dict[str, str]:
    """``--ros``: the ROS variables the simulator and the controller of one run share."""
    env = {"ROS_DOMAIN_ID": str(random.SystemRandom().choice(ROS_DOMAIN_IDS))}
    if not sandboxed:  # the sandbox sets the simulator's discovery (SANDBOXED_SERVER_DDS)
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


def grade_submission(suite_file: str | Path, command: Sequence[str], submission: Path,
                     out: Path, options: GradeOptions, *,
                     quiet: bool = False) -> dict[str, Any]:
    """Grade one submission on every scenario of a suite; writes ``out/summary.json``.

    Returns:
        The summary: the suite's name, ``total`` (the weighted scores), and per scenario its
        name, weight, score, passed, reason and report's path.

    Raises:
        ConfigError: the suite file is invalid.
        SandboxUnavailableError: the sandbox cannot run here (and ``sandboxed``).
    """
    suite = load_suite(suite_file)
    suite_path = resolve_scenario_path(suite_file).resolve()
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for entry in suite.entries:
        report = grade_scenario(suite_path, on_robot(entry.scenario, options.params), command,
                                submission, out / entry.scenario.name, options)
        if not quiet:
            print(summary_line(report), flush=True)
        rows.append({"name": entry.scenario.name, "weight": entry.weight,
                     "score": report["score"], "passed": report["passed"],
                     "reason": report["reason"],
                     "report": str(Path(entry.scenario.name) / REPORT_FILE)})
    total = sum(row["weight"] * row["score"] for row in rows) / sum(row["weight"] for row in rows)
    summary = {"suite": suite.name, "total": min(1.0, total), "mode": options.mode,
               "scenarios": rows, "receipt": receipt(suite_path, suite, submission, options)}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def receipt(suite_path: Path, suite: Suite, submission: Path,
            options: GradeOptions) -> dict[str, Any]:
    """What makes a grade re-runnable exactly: hashes of the submission and the suite, seeds.

    The submission's hash is of what the controller got (``submission_digest``: the ignored
    names left out); the suite's, of its file and every scenario file it names.
    """
    try:
        submission_sha256: str | None = submission_digest(
            submission, SandboxLimits().home_bytes // 2)
    except SubmissionRefusedError:
        submission_sha256 = None
    suite_files = dict.fromkeys([suite_path, *(Path(entry.scenario.source) for entry in
                                               suite.entries)])
    digest = hashlib.sha256()
    for path in suite_files:
        if path.is_file():
            digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    try:
        version = importlib.metadata.version("websim")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    return {"submission_sha256": submission_sha256, "suite_sha256": digest.hexdigest(),
            "seeds": {entry.scenario.name: entry.scenario.seed for entry in suite.entries},
            "mode": options.mode, "step_on": options.step_on, "runs": options.runs,
            "ros": options.ros, "websim": version}


def grade_scenario(suite_path: Path, scenario: Scenario, command: Sequence[str],
                   submission: Path, out: Path, options: GradeOptions) -> dict[str, Any]:
    """Grade one scenario (``options.runs`` runs); writes and returns its ``report.json``."""
    out.mkdir(parents=True, exist_ok=True)
    if options.runs == 1:
        report = grade_run(suite_path, scenario, command, submission, out, options)
    else:
        runs = [grade_run(suite_path, scenario, command, submission, out / f"run-{k + 1}",
                          options) for k in range(options.runs)]
        scores = [run_report["score"] for run_report in runs]
        median = statistics.median(scores)
        chosen = min(runs, key=lambda run_report: abs(run_report["score"] - median))
        report = {**chosen, "score": median,
                  "runs": [{"score": r["score"], "passed": r["passed"], "reason": r["reason"],
                            "report": str(Path(f"run-{k + 1}") / REPORT_FILE)}
                           for k, r in enumerate(runs)],
                  "spread": {"scores": scores, "median": median,
                             "range": round(max(scores) - min(scores), 9),
                             "stdev": statistics.pstdev(scores),
                             "metric_values": _metric_spread(runs)}}
        (out / REPORT_FILE).write_text(json.dumps(report, indent=2))
    return report


def grade_run(suite_path: Path, scenario: Scenario, command: Sequence[str],
              submission: Path, out: Path, options: GradeOptions) -> dict[str, Any]:
    """One run of one scenario: sandbox, simulator, controller, score; writes report.json."""
    out.mkdir(parents=True, exist_ok=True)
    for stale in (out / RUN_FILE, out / REPORT_FILE, out / TRUTH_FILE):
        stale.unlink(missing_ok=True)
    recording_dir = out / RECORDING_DIR
    if recording_dir.exists():
        for bag in recording_dir.iterdir():
            if bag.is_dir():
                for item in bag.iterdir():
                    item.unlink()
                bag.rmdir()
    limits = SandboxLimits(wall_time_s=wall_time_limit_s(scenario, options))
    started = time.monotonic()
    node_modules = options.node_modules if options.node_modules is not None \
        else node_modules_found()
    with contextlib.ExitStack() as stack:
        try:
            sandbox = stack.enter_context(SubmissionSandbox(
                submission, limits=limits, no_sandbox=not options.sandboxed,
                hidden_paths=[out.resolve()], visible_paths=python_runtime_paths(),
                node_path=node_modules))
        except SubmissionRefusedError as error:
            return _write(out, {"scenario": scenario.name, "mode": options.mode, "run": None,
                                "controller": None, **_zero(f"not run: {error}")})
        argv = [sys.executable, "-m", "websim.grade_server", str(suite_path),
                "--scenario", scenario.name, "--out", str(out.resolve()),
                "--mode", options.mode, "--step-on", options.step_on,
                "--startup-timeout", repr(options.startup_timeout_s),
                "--ws-port", str(sandbox.ws_port), "--http-port", str(sandbox.http_port)]
        if options.params is not None:
            argv += ["--params", str(Path(options.params).resolve())]
        ros_env = ros_environment(options.sandboxed) if options.ros else {}
        if options.ros:
            argv.append("--ros")
            try:
                command = [*command, *ros_arguments(scenario, options)]
            except ConfigError as error:
                return _write(out, {"scenario": scenario.name, "mode": options.mode,
                                    "run": None, "controller": None, **_zero(str(error))})
        try:
            sandbox.start_server(argv, env={**os.environ, **ros_env})
        except SimulatorStartError as error:
            return _write(out, _grader_error(scenario, options, f"{error}"))
        controller = sandbox.run_controller(
            command, env={**controller_environment(scenario), **ros_env})
        server = sandbox.stop_server(ending=(out / RUN_FILE).is_file())  # it ended the run
    wall_s = time.monotonic() - started
    report, trajectory = score_run(
        scenario, out, options, controller=asdict_controller(controller),
        controller_reason=controller.reason, server_tail=server.output_tail)
    report["wall_time_s"] = round(wall_s, 3)
    sim_s = report["run"]["sim_time_s"] if report.get("run") else 0.0
    report["real_time_factor"] = round(sim_s / wall_s, 3) if wall_s > 0 else None
    if trajectory:
        report["report_html"] = PAGE_FILE
        (out / PAGE_FILE).write_text(report_html(scenario, trajectory, report),
                                     encoding="utf-8")
    return _write(out, report)


def _metric_spread(runs: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Each metric's value over the runs: the values, their range (None if one is None)."""
    spread: dict[str, dict[str, Any]] = {}
    for run_report in runs:
        for metric in run_report.get("metrics", []):
            spread.setdefault(metric["name"], {"values": []})["values"].append(metric["value"])
    for entry in spread.values():
        values = entry["values"]
        entry["range"] = round(max(values) - min(values), 9) if None not in values else None
    return spread


def wall_time_limit_s(scenario: Scenario, options: GradeOptions) -> float:
    """The controller's wall-clock limit for one run of ``scenario``."""
    start_s = options.startup_timeout_s + WALL_CLOCK_MARGIN_S
    if options.mode == "wall-clock":
        return start_s + scenario.duration_s
    return (start_s + DETERMINISTIC_WALL_FACTOR * scenario.duration_s
            + MAX_MISSED_STEPS * STEP_TIMEOUT_S)


def score_run(scenario: Scenario, out: Path, options: GradeOptions, *,
              controller: dict[str, Any], controller_reason: str,
              server_tail: str) -> tuple[dict[str, Any], list[Sample]]:
    """The report of a run that has ended, and its trajectory (empty without a recording).

    The report: its scenario's metrics measured on the recording's ground truth.
    """
    base = {"scenario": scenario.name, "description": scenario.description,
            "source": scenario.source, "mode": options.mode, "step_on": options.step_on,
            "seed": scenario.seed, "duration_s": scenario.duration_s,
            "controller": controller}
    run_file = out / RUN_FILE
    if not run_file.is_file():
        return {**base, **_zero(f"the simulator did not say how the run ended; its output "
                                f"ended with: {server_tail[-400:]}"), "run": None}, []
    run_end = json.loads(run_file.read_text())
    base["run"] = run_end
    completed = run_end["ended_by"] in ("duration", "end_point")
    try:
        trajectory, notes = trajectory_from_truth(out / TRUTH_FILE, scenario)
        _check_complete(trajectory, run_end, scenario)
    except IncompleteRecordError as error:
        if completed:
            return {**base, **_zero(f"invalid run: {error}"), "invalid": True}, []
        return {**base, **_zero(_early_end_reason(run_end, scenario, controller,
                                                  controller_reason))}, []
    try:
        base["recording"] = str(bag_folder(out / RECORDING_DIR))
    except FileNotFoundError as error:
        base["recording"] = None
        base["recording_note"] = str(error)
    for health in notes.get("recording", []):
        if health.get("messages_lost") or health.get("state") not in (None, "closed"):
            base["recording_note"] = (
                f"the recording is incomplete ({health.get('state')}"
                f"{': ' + health['reason'] if health.get('reason') else ''}; "
                f"{health.get('messages_lost', 0)} messages lost): the score is from the "
                "simulation's own record, which is complete")
    exited = run_end["ended_by"] == "stopped" and exited_cleanly(controller)
    last_s = run_end.get("last_command_s")
    if exited and last_s is not None and trajectory and trajectory[0].t_s <= last_s:
        trajectory = list(until(trajectory, last_s))  # a clean exit ends the run
    result = evaluate(scenario, trajectory)
    graded = result.to_json()
    graded.pop("name", None)
    said = run_notes(run_end)
    if said:
        graded["reason"] = "; ".join([graded["reason"], *said])
    if completed:
        if not graded["passed"] and scenario.changes:
            graded["reason"] += changes_hint(scenario)
        return {**base, **graded}, trajectory
    if exited:
        when = "before its first command" if last_s is None else \
            f"after its last command at t = {last_s:.2f} s"
        graded["reason"] = (f"{graded['reason']} (the controller exited with code 0 {when}, "
                            f"of {scenario.duration_s:g} s: scored on the run until then)")
        return {**base, **graded}, trajectory
    why = "; ".join([_early_end_reason(run_end, scenario, controller, controller_reason),
                     *said])
    return {**base, **graded, "score": 0.0, "passed": False, "reason": why,
            "score_if_completed": graded["score"]}, trajectory


def exited_cleanly(controller: dict[str, Any]) -> bool:
    """Whether the controller ended the run itself, with exit code 0."""
    return controller.get("ended_by") == "exit" and controller.get("exit_code") == 0


def run_notes(run_end: dict[str, Any]) -> list[str]:
    """What the report must say about how the controller took part (``run.json``)."""
    notes = list(run_end.get("incompatible_qos", []))
    if run_end.get("wall_paced"):
        notes.append(
            f"not deterministic: the controller published {run_end['probe_commands']} "
            f"/cmd_vel in {PROBE_S:g} s while the simulator sent it nothing (it paces itself "
            f"by the wall clock: time.sleep, a steady timer), so a re-grade can differ: grade "
            f"it with --mode wall-clock")
    return notes


def _early_end_reason(run_end: dict[str, Any], scenario: Scenario,
                      controller: dict[str, Any], controller_reason: str) -> str:
    """Why a run that did not run its course scores 0 (with the controller's last error)."""
    if run_end["ended_by"] != "stopped":
        return str(run_end["reason"])
    why = (f"the controller ended before the run did (at t = {run_end['sim_time_s']:.2f} "
           f"s of {scenario.duration_s:g} s): {controller_reason}")
    last = last_error_line(controller.get("output_tail", ""))
    return f"{why}: {last}" if last else why


def _check_complete(trajectory: Sequence[Sample], run_end: dict[str, Any],
                    scenario: Scenario) -> None:
    """Raise unless the record reaches the run's end (its sim time, or the end point).

    Raises:
        IncompleteRecordError: the record stops short of the run's end.
    """
    if run_end["ended_by"] != "duration":
        return
    last_s = trajectory[-1].t_s
    if last_s < min(run_end["sim_time_s"], scenario.duration_s) - 1e-6:
        raise IncompleteRecordError(f"the record of the ground truth ends at t = {last_s:.2f} s, "
                                    f"before the run's end at {run_end['sim_time_s']:.2f} s")


ERROR_LINE = re.compile(r"^\s*(?:[\w.]+(?:Error|Exception|Exit|Interrupt)\b.*|Error: .+|"
                        r"[\w./-]+: (?:line \d+: )?.*(?:not found|No such file).*)$")


def last_error_line(output: str) -> str | None:
    """The last line of ``output`` that says what went wrong (an exception's last line).

    Python's ``ModuleNotFoundError: No module named 'roslibpy'``, Node's ``Error: ...``, a
    shell's ``python4: not found``; None if no line says so. At most 300 characters.
    """
    for line in reversed(output.splitlines()[-200:]):
        if ERROR_LINE.match(line):
            return line.strip()[:300]
    return None


def changes_hint(scenario: Scenario) -> str:
    """What the scenario changed during the run, for a failure's reason (one clause)."""
    said = []
    for change in scenario.changes:
        parts = [f"{name} to {value!r}" for name, value in change.parameters]
        if change.payload is not None:
            parts.append("the payload")
        if change.mode is not None:
            parts.append(f"the mode to {change.mode}")
        if parts:
            said.append(f"{' and '.join(parts)} at t = {change.at_s:g} s")
    told = [name for name in controller_environment(scenario) if name.endswith("_CHANGES")]
    tells = f" ({', '.join(told)} tells the controller; docs/grading.md)" if told else ""
    return f" (the scenario changed {'; '.join(said)}{tells})" if said else ""


def asdict_controller(result: Any) -> dict[str, Any]:
    """The controller's sandbox result as JSON, its limits and reason included."""
    data = asdict(result)
    data["reason"] = result.reason
    data["output_truncated"] = result.output_truncated
    data["command"] = list(result.command)
    return data


def summary_line(report: dict[str, Any]) -> str:
    """One line per scenario: score, verdict, reason, and how the run went."""
    verdict = "passed" if report["passed"] else "failed"
    line = f"{report['scenario']}: {report['score']:.4f} {verdict}: {report['reason']}"
    run_end = report.get("run")
    if run_end:
        line += (f" [{report['mode']}, {run_end['sim_time_s']:.1f} s of sim time in "
                 f"{report.get('wall_time_s', 0.0):.1f} s")
        if report.get("real_time_factor"):
            line += f", {report['real_time_factor']:.1f}x real time"
        line += "]"
    spread = report.get("spread")
    if spread:
        line += (f" median of {len(spread['scores'])} runs, spread {spread['range']:.4f} "
                 f"(scores {', '.join(f'{s:.4f}' for s in spread['scores'])})")
    return line


def _zero(reason: str) -> dict[str, Any]:
    return {"score": 0.0, "passed": False, "reason": reason, "metrics": []}


def _grader_error(scenario: Scenario, options: GradeOptions, reason: str) -> dict[str, Any]:
    return {"scenario": scenario.name, "mode": options.mode, "run": None,
            "controller": None, "grader_error": True, **_zero(reason)}


def _write(out: Path, report: dict[str, Any]) -> dict[str, Any]:
    (out / REPORT_FILE).write_text(json.dumps(report, indent=2))
    return report

