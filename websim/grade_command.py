"""``websim grade SCENARIO_OR_SUITE [--out DIR] -- COMMAND...``: the command's arguments.

One submission (``--submission DIR``, default this folder; its command after ``--``, else
the one its ``websim-submission.yaml`` declares), a class (``--submissions DIR``: a folder
per student, ``websim.grade_class``), and Gradescope's ``results.json`` (``--gradescope``).
The work is ``websim.grade_run`` (a submission's runs and reports); exit status 0 when every
scenario passed (or the total reaches ``--fail-under``), 1 when one failed, 2 for bad input.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

from grading import Suite, load_suite
from physics import ConfigError, load_params
from websim.grade_class import (
    SUBMISSION_FILE,
    grade_class,
    gradescope_refusal,
    gradescope_results,
    submission_declaration,
    write_gradescope,
)
from websim.grade_run import GradeOptions, check_runtime, grade_submission
from websim.grade_server import MODES, STARTUP_TIMEOUT_S, STEP_ON
from websim.sandbox import SandboxUnavailableError

GRADESCOPE_RESULTS = Path("/autograder/results/results.json")
"""Where Gradescope reads an autograder's results."""

DEFAULT_OUTPUT_MODE = 0o600
"""What ``websim grade`` writes is the grader's alone unless asked (``--output-mode``):
grades, reports and recordings are students' records."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``websim grade``'s options."""
    parser.add_argument("suite", metavar="SCENARIO_OR_SUITE",
                        help="a scenario or suite file, or a shipped one's name (heading_pid)")
    parser.set_defaults(controller=[])  # what follows --: websim.cli.main splits it off
    parser.add_argument("--out", type=Path, default=Path("grade-out"), metavar="DIR",
                        help="where reports and recordings go (default grade-out)")
    parser.add_argument("--submission", type=Path, default=Path("."), metavar="DIR",
                        help="the submission's folder: the controller runs in a copy of it "
                             "(default: this folder); without a command after --, the one "
                             f"its {SUBMISSION_FILE} declares")
    parser.add_argument("--submissions", type=Path, default=None, metavar="DIR",
                        help=f"grade a class: every folder of DIR is a student's submission "
                             f"with its {SUBMISSION_FILE}; writes grades.csv and class.html")
    parser.add_argument("--jobs", type=_positive_int, default=None, metavar="N",
                        help="with --submissions: submissions graded at once (default: the "
                             "machine's cores)")
    parser.add_argument("--gradescope", nargs="?", type=Path, const=GRADESCOPE_RESULTS,
                        default=None, metavar="RESULTS_JSON",
                        help="also write Gradescope's results.json (default path "
                             f"{GRADESCOPE_RESULTS})")
    parser.add_argument("--points", type=float, default=100.0,
                        help="with --gradescope: the suite's points (default 100)")
    parser.add_argument("--mode", choices=MODES, default="deterministic",
                        help="deterministic (default): on sim time, the simulation waits for "
                             "the controller's command each time it is due; wall-clock: at 1x, "
                             "for any program")
    parser.add_argument("--step-on", choices=tuple(STEP_ON), default="auto",
                        help="deterministic mode: auto (default): what the controller "
                             "subscribes to (an rclpy node: every tick, once its executor "
                             "handled it); or a /cmd_vel after each /odom, each /scan, or at "
                             "the scenario's controller_rate_hz")
    parser.add_argument("--runs", type=_positive_int, default=1, metavar="N",
                        help="runs per scenario: the score is their median, their spread is "
                             "printed (default 1)")
    parser.add_argument("--startup-timeout", type=float, default=STARTUP_TIMEOUT_S,
                        metavar="S",
                        help="how long the controller may take to connect (and, in "
                             "deterministic mode, subscribe) before the run is scored 0 "
                             f"(default {STARTUP_TIMEOUT_S:g} s of wall time)")
    parser.add_argument("--ros", action="store_true",
                        help="the controller is an rclpy node: the simulator starts the ROS "
                             "graph, the controller gets a ROS_DOMAIN_ID of its run and "
                             "--ros-args -p use_sim_time:=true after its command")
    parser.add_argument("--params", default=None, metavar="FILE",
                        help="grade on the robot of this parameter file (e.g. websim fit's: "
                             "the real robot's lag, scales and ramps); a scenario's payload is "
                             "kept (default: the shipped robot)")
    parser.add_argument("--no-sandbox", action="store_true",
                        help="run the controller without a sandbox (only for code you trust)")
    parser.add_argument("--fail-under", type=float, default=None, metavar="TOTAL",
                        help="exit 0 when the total (each student's, for a class) is at "
                             "least TOTAL (0 to 1), 1 below it; default: 0 only when every "
                             "scenario passed")
    parser.add_argument("--output-mode", type=_output_mode, default=DEFAULT_OUTPUT_MODE,
                        metavar="MODE",
                        help="the mode of what it writes (grades, reports, recordings), "
                             "octal; folders get x where r (default 600: the grader's "
                             "alone; 640 or 644 to share them)")
    parser.add_argument("--node-modules", type=Path, default=None, metavar="DIR",
                        help="a node_modules folder with roslib for Node, for roslibjs "
                             "controllers (default: websim's own roslib 1.4.1: a "
                             "checkout's web-interface/node_modules, else the wheel's)")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got '{text}'") from None
    if not 1 <= value <= 100:
        raise argparse.ArgumentTypeError(f"expected 1 to 100, got {value}")
    return value


def run(args: argparse.Namespace) -> int:
    """Grade a submission or a class; the exit status (``EXIT_*``).

    0 when every scenario passed (every student's, for a class) and the total is at least
    ``--fail-under``; 1 when one failed; 2 for bad input (the caller's ``ConfigError``).
    """
    suite = load_suite(args.suite)
    if not 0.0 < args.startup_timeout <= 3600.0:
        raise ConfigError(f"--startup-timeout: expected 0 to 3600 s, got {args.startup_timeout}")
    if args.fail_under is not None and not 0.0 <= args.fail_under <= 1.0:
        raise ConfigError(f"--fail-under: expected a total from 0 to 1, got {args.fail_under}")
    if args.params is not None:
        load_params(args.params)  # a bad file is refused before any run
    node_modules = None if args.node_modules is None else (str(args.node_modules.resolve()),)
    if node_modules is not None and not args.node_modules.is_dir():
        raise ConfigError(f"--node-modules {args.node_modules}: not a folder")
    options = GradeOptions(args.mode, args.step_on, not args.no_sandbox, args.runs,
                           args.startup_timeout, args.ros, args.params,
                           node_modules=node_modules)
    previous_umask = os.umask(umask_for(args.output_mode))
    try:
        return _grade(args, suite, options)
    except SandboxUnavailableError as error:
        raise ConfigError(str(error)) from None
    finally:
        os.umask(previous_umask)


def _grade(args: argparse.Namespace, suite: Suite, options: GradeOptions) -> int:
    started = time.monotonic()
    if args.submissions is not None:
        if args.controller or args.gradescope is not None:
            raise ConfigError("--submissions takes each command from its folder's "
                              f"{SUBMISSION_FILE} (no -- COMMAND, no --gradescope)")
        if not args.submissions.is_dir():
            raise ConfigError(f"--submissions {args.submissions}: not a folder")
        commands = [_declared_command(folder) for folder in args.submissions.iterdir()
                    if folder.is_dir() and not folder.is_symlink()]
        _check_runtime(commands, options)
        rows = grade_class(args.suite, suite, args.submissions, args.out, options, args.jobs)
        for row in rows:
            print(f"{row['student']}: {row['total']:.4f} {row['reason']}", flush=True)
        print(f"{suite.name}: {len(rows)} submissions graded; {args.out / 'grades.csv'}, "
              f"{args.out / 'class.html'}", flush=True)
        passed = all(row["reason"] == "passed" for row in rows)
        lowest = min(row["total"] for row in rows)
        return _status(passed, lowest, args.fail_under)
    if not args.submission.is_dir():
        raise ConfigError(f"--submission {args.submission}: not a folder")
    command = list(args.controller)
    if not command:
        if args.gradescope is None and not (args.submission / SUBMISSION_FILE).exists():
            raise ConfigError("no controller command: give it after --, e.g. websim grade "
                              "heading_pid.yaml -- python3 controller.py (or declare it "
                              f"in the submission's {SUBMISSION_FILE})")
        try:
            declared = submission_declaration(args.submission)
            command = declared.command
            options = dataclasses.replace(options, ros=options.ros or declared.ros,
                                          ros_parameters=declared.ros_parameters)
        except ConfigError as error:
            if args.gradescope is None:
                raise
            # the student's mistake, not the grader's: a 0 they can read, not a crash
            write_gradescope(args.gradescope, gradescope_refusal(suite, str(error),
                                                                 args.points))
            print(f"{suite.name}: not graded: {error}", flush=True)
            return EXIT_FAILED
    _check_runtime([command], options)
    try:
        summary = grade_submission(args.suite, command, args.submission, args.out, options)
    except Exception as error:
        if args.gradescope is not None:  # results.json is always written
            write_gradescope(args.gradescope, gradescope_refusal(
                suite, f"the grader failed: {type(error).__name__}: {error}", args.points))
        raise
    if args.gradescope is not None:
        write_gradescope(args.gradescope, gradescope_results(
            summary, suite, args.out, args.points,
            execution_time_s=time.monotonic() - started))
    print(f"{suite.name}: total {summary['total']:.3f} "
          f"({len(summary['scenarios'])} scenario(s); reports in {args.out})", flush=True)
    passed = all(row["passed"] for row in summary["scenarios"])
    return _status(passed, summary["total"], args.fail_under)


EXIT_PASSED = 0
EXIT_FAILED = 1
"""``websim grade``'s exit status: every scenario passed (0), or one failed (1); bad input
is 2 (``websim.cli``), as CI systems and GitHub Classroom read it."""


def _status(passed: bool, total: float, fail_under: float | None) -> int:
    """0 when every scenario passed (or, with ``--fail-under``, the total reaches it)."""
    if fail_under is not None:
        return EXIT_PASSED if total >= fail_under - 1e-12 else EXIT_FAILED
    return EXIT_PASSED if passed else EXIT_FAILED


def _declared_command(folder: Path) -> list[str]:
    try:
        return submission_declaration(folder).command
    except ConfigError:
        return []  # that student's zero, with the reason, comes later


def _check_runtime(commands: list[list[str]], options: GradeOptions) -> None:
    try:
        check_runtime(commands, options)
    except RuntimeError as error:
        raise ConfigError(str(error)) from None


def umask_for(mode: int) -> int:
    """The umask that writes files ``mode`` and folders ``mode`` with x where r."""
    folders = mode | (mode & 0o444) >> 2
    return 0o777 & ~folders


def _output_mode(text: str) -> int:
    try:
        mode = int(text, 8)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an octal mode (600, 640, 644), got "
                                         f"'{text}'") from None
    if not 0o400 <= mode <= 0o666 or not mode & 0o600 == 0o600:
        raise argparse.ArgumentTypeError(f"expected a file mode the grader can read and "
                                         f"write (600 to 666), got {text}")
    return mode
