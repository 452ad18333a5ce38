"""The Code panel's Submit: a bounded queue of gradings, each ``websim grade`` in its sandbox.

A student's program is graded on the server exactly as the instructor would grade it by hand:
``websim grade ASSIGNMENT --submission DIR --out DIR --mode deterministic -- python3 FILE``
(``node FILE`` for JavaScript, roslib copied into the submission), in a subprocess, at a lower
CPU priority than the class it runs beside. The command line and what it writes
(``summary.json``, each scenario's ``report.json`` and ``report.html``) are the interface relied
on: the grader itself is not imported, so it may change inside without this module changing.
Nothing a student wrote runs on the server but there, in ``websim grade``'s sandbox; where the
sandbox cannot run (not root, no bubblewrap) Submit is off and says why, and the rest of the
panel works.

Bounded by construction (``SubmitLimits``): at most ``jobs`` gradings at once, ``waiting``
submissions queued, one per student (a new one replaces the one still waiting), ``per_hour``
accepted per student in any hour, programs of at most ``code_bytes``, a grading's wall time by
its suite's length, the reports kept of at most ``report_bytes`` each.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import logging
import os
import shutil
import signal
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from grading import load_suite
from physics import ConfigError
from websim.node_roslib import LOCK_FILE, has_roslib, roslib_closure
from websim.sandbox import SandboxUnavailableError, find_tools

log = logging.getLogger("websim.submissions")

GRADED_EXIT_CODES = (0, 1)
"""``websim grade``'s exit status when it graded the program: 0, every scenario passed; 1, one
failed (2 is bad input: not graded)."""

LANGUAGES = {"python": ("py", "python3"), "javascript": ("js", "node")}
"""A submission's language: its file's extension and the program that runs it."""

SUBMISSION_FILE = "websim-submission.yaml"
"""What a submission folder declares its command in (``websim grade --submissions``)."""

OUTPUT_TAIL_BYTES = 4096
"""The last bytes of ``websim grade``'s own output kept when it fails (its reason)."""

PROGRAM_OUTPUT_CHARS = 2000
"""The last characters of the program's output shown with each scenario's result."""

GRADE_NICENESS = 10
"""Gradings run at this lower CPU priority: the class's robots tick first."""

START_MARGIN_S = 120.0
"""A grading may take its scenarios' wall-time bounds and this (its interpreter, a slow
disk); then it is ended."""

RATE_WINDOW_S = 3600.0


@dataclass(frozen=True)
class SubmitLimits:
    """The bounds of Submit (``websim serve --grade-jobs``, ``--grade-per-hour``).

    Attributes:
        jobs: gradings at once (0: Submit is off).
        per_hour: submissions one student may make in any hour.
        waiting: submissions waiting at once, all students together.
        code_bytes: the largest program (UTF-8 bytes), saved or submitted.
        report_bytes: the largest report.html kept per scenario (a larger one is left out).
    """

    jobs: int = 2
    per_hour: int = 10
    waiting: int = 200
    code_bytes: int = 128 * 1024
    report_bytes: int = 1024 * 1024


class RefusedError(Exception):
    """A submission the queue does not take: an HTTP status and the reason, for the student."""

    def __init__(self, status: int, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason


@dataclass
class Submission:
    """One student's program on its way through the queue.

    Attributes:
        key: whose it is (the robot's name; on a single robot, the client's address).
        language: ``python`` or ``javascript``.
        text: the program.
        assignment: the shipped scenario or suite it is graded on (``heading_pid``).
        submitted_at: when (s since the epoch).
        state: ``queued``, ``running``, ``done`` or ``failed``.
        reason: why it failed (``failed``).
        result: ``done``: the suite's total and each scenario's score, verdict, reason and
            metrics, and the program's last output.
        reports: ``done``: each scenario's report.html (those within the limit).
        finished_at: when it was graded.
    """

    key: str
    language: str
    text: str
    assignment: str
    submitted_at: float
    state: str = "queued"
    reason: str = ""
    result: dict[str, Any] | None = None
    reports: dict[str, str] = field(default_factory=dict)
    finished_at: float | None = None

    def summary(self) -> dict[str, Any]:
        """What the student's page and the instructor's see (not the program's text)."""
        return {"state": self.state, "language": self.language, "assignment": self.assignment,
                "submitted_at": self.submitted_at, "finished_at": self.finished_at,
                "reason": self.reason, "result": self.result,
                "bytes": len(self.text.encode("utf-8"))}


class Grader:
    """Grades a submission with ``websim grade``, through its command line.

    Args:
        roslib_modules: the folder holding roslib 1.4.1 and its dependencies with npm's
            record of them (``websim.node_roslib.roslib_modules()``: a checkout's, or the
            wheel's), of which a JavaScript submission gets a copy; None: there is none.
        python: the interpreter that runs ``websim grade`` (this one) and, found first on the
            grading's PATH, the student's Python (it has roslibpy).
        node: Node's path (None: not installed).
        sandboxed: False only in tests of this module that must run where no sandbox can
            (never from ``websim serve``).
    """

    def __init__(self, roslib_modules: Path | None, python: str = sys.executable,
                 node: str | None = None, sandboxed: bool = True) -> None:
        self.roslib_modules = roslib_modules
        self.python = python
        self.node = node if node is not None else shutil.which("node")
        self.sandboxed = sandboxed

    def unavailable(self) -> str | None:
        """Why nothing can be graded here (the sandbox cannot run), or None."""
        if not self.sandboxed:
            return None
        try:
            find_tools(sandboxed=True)
        except SandboxUnavailableError as error:
            return f"the server cannot sandbox submissions: {error}"
        return None

    def language_unavailable(self, language: str) -> str | None:
        """Why programs of ``language`` cannot be graded here, or None."""
        if language == "javascript":
            if self.node is None:
                return "Node is not installed on this server, so JavaScript is not graded here"
            if self.roslib_modules is None or not has_roslib(self.roslib_modules) or \
                    not (self.roslib_modules / LOCK_FILE).is_file():
                return ("roslib's Node package is not installed on this server (a wheel "
                        "carries it; a checkout has it after npm ci in web-interface/), so "
                        "JavaScript is not graded here")
        return None

    def time_limit_s(self, assignment: str) -> float:
        """How long the grading of ``assignment`` may take (wall time, s)."""
        suite = load_suite(assignment)
        return START_MARGIN_S + sum(60.0 + 30.0 + 4.0 * entry.scenario.duration_s
                                    for entry in suite.entries)

    def command(self, submission: Submission, folder: Path, out: Path) -> list[str]:
        """The ``websim grade`` command line for ``submission`` in ``folder``."""
        extension, program = LANGUAGES[submission.language]
        return [self.python, "-m", "websim.cli", "grade", submission.assignment,
                "--submission", str(folder), "--out", str(out), "--mode", "deterministic",
                *([] if self.sandboxed else ["--no-sandbox"]),
                "--", program, f"controller.{extension}"]

    async def grade(self, submission: Submission, limits: SubmitLimits
                    ) -> tuple[dict[str, Any], dict[str, str]]:
        """Grade one submission: its result and its reports.

        Raises:
            RefusedError: it could not be graded (the reason says why; the grader's last words).
        """
        workspace = Path(tempfile.mkdtemp(prefix="websim-submission-"))
        try:
            folder = workspace / "submission"
            write_submission(folder, submission.language, submission.text,
                             self.roslib_modules)
            out = workspace / "out"
            env = {**os.environ,
                   "PATH": os.pathsep.join([str(Path(self.python).parent),
                                            os.environ.get("PATH", "")])}
            argv = self.command(submission, folder, out)
            nice = shutil.which("nice")
            if nice is not None:  # not preexec_fn: unsafe in a process with threads
                argv = [nice, "-n", str(GRADE_NICENESS), *argv]
            process = await asyncio.create_subprocess_exec(
                *argv, cwd=workspace, env=env, stdin=asyncio.subprocess.DEVNULL,
                stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
                start_new_session=True)
            tail: collections.deque[bytes] = collections.deque(maxlen=64)

            async def finish() -> int:
                assert process.stdout is not None
                async for line in process.stdout:
                    tail.append(line[-OUTPUT_TAIL_BYTES:])
                return await process.wait()

            try:
                code = await asyncio.wait_for(finish(),
                                              self.time_limit_s(submission.assignment))
            except asyncio.TimeoutError:
                _kill(process)
                await process.wait()
                raise RefusedError(504, "the grading took too long and was ended") from None
            except asyncio.CancelledError:
                _kill(process)
                raise
            said = b"".join(tail).decode("utf-8", "replace")[-OUTPUT_TAIL_BYTES:]
            summary_file = out / "summary.json"
            if code not in GRADED_EXIT_CODES or not summary_file.is_file():
                last = said.strip().splitlines()[-1:] or [f"exit status {code}"]
                raise RefusedError(500, f"websim grade could not grade it: {last[0]}")
            return read_results(out, json.loads(summary_file.read_text()), limits)
        finally:
            shutil.rmtree(workspace, ignore_errors=True)


def _kill(process: asyncio.subprocess.Process) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, signal.SIGKILL)


def write_submission(folder: Path, language: str, text: str,
                     roslib_modules: Path | None) -> Path:
    """A submission folder as ``websim grade --submissions`` takes one; the program's path.

    ``controller.py`` (or ``.js``, with a copy of roslib and its dependencies in
    ``node_modules``) and ``websim-submission.yaml`` declaring its command.
    """
    extension, program = LANGUAGES[language]
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"controller.{extension}"
    path.write_text(text, encoding="utf-8")
    (folder / SUBMISSION_FILE).write_text(f"command: {program} controller.{extension}\n")
    if language == "javascript" and roslib_modules is not None:
        for name in roslib_closure(roslib_modules):
            shutil.copytree(roslib_modules / name, folder / "node_modules" / name,
                            dirs_exist_ok=True)
    return path


def read_results(out: Path, summary: dict[str, Any], limits: SubmitLimits
                 ) -> tuple[dict[str, Any], dict[str, str]]:
    """The result of a grading from what ``websim grade`` wrote in ``out``."""
    scenarios = []
    reports: dict[str, str] = {}
    for row in summary.get("scenarios", []):
        name = str(row["name"])
        report_file = out / str(row.get("report") or f"{name}/report.json")
        report = json.loads(report_file.read_text()) if report_file.is_file() else {}
        page = report_file.with_name("report.html")
        if page.is_file() and page.stat().st_size <= limits.report_bytes:
            reports[name] = page.read_text(encoding="utf-8", errors="replace")
        controller = report.get("controller") or {}
        scenarios.append({
            "name": name, "weight": row.get("weight"), "score": row["score"],
            "passed": row["passed"], "reason": row["reason"],
            "metrics": [{key: metric.get(key) for key in ("name", "value", "unit", "score",
                                                          "reason")}
                        for metric in report.get("metrics", [])],
            "output_tail": str(controller.get("output_tail", ""))[-PROGRAM_OUTPUT_CHARS:],
            "has_report": name in reports})
    return {"suite": summary.get("suite"), "total": summary.get("total", 0.0),
            "mode": summary.get("mode"), "scenarios": scenarios}, reports


class SubmissionQueue:
    """Submissions waiting and being graded; ``run()`` grades them, ``jobs`` at once.

    Args:
        limits: its bounds.
        grader: what grades one (``Grader``).
        assignments: the names that may be submitted to (the shipped scenarios and suites).
        on_done: told of each finished submission (the class state keeps it).
        clock: wall time, s since the epoch.
    """

    def __init__(self, limits: SubmitLimits, grader: Grader, assignments: set[str],
                 on_done: Callable[[Submission], None] | None = None,
                 clock: Callable[[], float] = time.time) -> None:
        self.limits = limits
        self.grader = grader
        self.assignments = assignments
        self.on_done = on_done
        self.clock = clock
        self._waiting: list[Submission] = []
        self._latest: dict[str, Submission] = {}
        self._accepted: dict[str, collections.deque[float]] = {}
        self._wake = asyncio.Event()
        self._why_off = None if limits.jobs > 0 else "the server grades nothing (--grade-jobs 0)"
        if self._why_off is None:
            self._why_off = grader.unavailable()
            if self._why_off is not None:
                log.warning("Submit is off: %s", self._why_off)

    def availability(self) -> dict[str, Any]:
        """Whether Submit works here, and per language (the page greys it out with the why)."""
        languages = {}
        for language in LANGUAGES:
            why = self.grader.language_unavailable(language)
            languages[language] = {"enabled": why is None, "reason": why or ""}
        return {"enabled": self._why_off is None, "reason": self._why_off or "",
                "languages": languages}

    def submit(self, key: str, language: str, text: str, assignment: str) -> Submission:
        """Queue a program (replacing this student's still waiting, if any).

        Raises:
            RefusedError: Submit is off, a bad language or assignment, too large, too many this
                hour, or the queue is full; the reason says which.
        """
        if self._why_off is not None:
            raise RefusedError(503, f"Submit is off: {self._why_off}")
        if language not in LANGUAGES:
            raise RefusedError(400, f"language: expected one of {', '.join(LANGUAGES)}")
        if (why := self.grader.language_unavailable(language)) is not None:
            raise RefusedError(503, why)
        if assignment not in self.assignments:
            raise RefusedError(400, f"no assignment '{assignment[:60]}' here (one of "
                                    f"{', '.join(sorted(self.assignments))})")
        if len(text.encode("utf-8")) > self.limits.code_bytes:
            raise RefusedError(413, f"the program is larger than {self.limits.code_bytes} bytes")
        now = self.clock()
        times = self._accepted.setdefault(key, collections.deque())
        while times and times[0] <= now - RATE_WINDOW_S:
            times.popleft()
        if len(times) >= self.limits.per_hour:
            wait_min = max(1, round((times[0] + RATE_WINDOW_S - now) / 60))
            raise RefusedError(429, f"{self.limits.per_hour} submissions an hour at most: "
                                    f"try again in {wait_min} min")
        replaced = next((s for s in self._waiting if s.key == key), None)
        if replaced is None and len(self._waiting) >= self.limits.waiting:
            raise RefusedError(503, f"the grading queue is full ({self.limits.waiting} "
                                    "waiting): try again in a few minutes")
        previous = self._latest.get(key)
        if previous is not None and previous.state == "running":
            raise RefusedError(409, "your previous submission is being graded: wait for "
                                    "its score, then submit again")
        submission = Submission(key, language, text, assignment, now)
        if replaced is not None:
            self._waiting[self._waiting.index(replaced)] = submission
        else:
            self._waiting.append(submission)
        times.append(now)
        self._latest[key] = submission
        self._forget_idle_keys(now)
        self._wake.set()
        return submission

    def _forget_idle_keys(self, now: float) -> None:
        """Drop the rate counts of keys with nothing in the last hour.

        A single robot's clients' addresses would otherwise pile up.
        """
        idle = [key for key, times in self._accepted.items()
                if not times or times[-1] <= now - RATE_WINDOW_S]
        for key in idle:
            del self._accepted[key]

    def latest(self, key: str) -> Submission | None:
        """This student's latest submission this server run (None: none)."""
        return self._latest.get(key)

    def position(self, submission: Submission) -> int:
        """1 for the next to be graded; 0 when it is not waiting."""
        for index, waiting in enumerate(self._waiting):
            if waiting is submission:
                return index + 1
        return 0

    async def run(self) -> None:
        """Grade forever, ``jobs`` at once (cancel to stop; gradings in progress end)."""
        if self._why_off is not None:
            return
        workers = [asyncio.create_task(self._work()) for _ in range(self.limits.jobs)]
        try:
            await asyncio.gather(*workers)
        finally:
            for worker in workers:
                worker.cancel()
            await asyncio.gather(*workers, return_exceptions=True)

    async def _work(self) -> None:
        while True:
            while not self._waiting:
                self._wake.clear()
                await self._wake.wait()
            submission = self._waiting.pop(0)
            submission.state = "running"
            try:
                submission.result, submission.reports = await self.grader.grade(
                    submission, self.limits)
                submission.state = "done"
            except RefusedError as refused:
                submission.state, submission.reason = "failed", refused.reason
            except (ConfigError, OSError) as error:
                submission.state, submission.reason = "failed", f"{error}"
            submission.finished_at = self.clock()
            if self.on_done is not None:
                try:
                    self.on_done(submission)
                except Exception:  # keeping it failed (a full disk): the grading stands
                    log.exception("a finished submission of %s could not be kept",
                                  submission.key)
