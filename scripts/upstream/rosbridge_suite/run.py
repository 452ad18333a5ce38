"""Run rosbridge_suite's own tests, as wire-level bodies, against websim; print each result.

Usage (from the repository root; ``--ros`` mode needs the ROS 2 wheels, tf2_msgs and
example_interfaces, see README.md next to this file):

    python3 scripts/upstream/rosbridge_suite/run.py [--mode plain|ros|both]
        [--suite server|library|all] [-k SUBSTRING] [--out DIR]

Every test gets a fresh ``websim serve`` (``--ros`` in ros mode) on free ports, as upstream
launches a fresh rosbridge_websocket per test file. Results: one line per test (PASS, FAIL
with the reason, N/A with the reason), totals per suite and mode, and in ``--out`` (default
/tmp/websim-upstream-rosbridge) ``results-MODE.json`` and one ``.trace`` per failed test:
every frame each client sent and received, and the server's warnings.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime
import itertools
import json
import os
import subprocess
import sys
import traceback
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[2]
sys.path[:0] = [str(HERE), str(REPO / "tests")]

from cases import MODES, Case, Context  # noqa: E402
from wire_client import Trace  # noqa: E402

from server_process import start_server  # noqa: E402

NODE_NUMBERS = itertools.count(1)
"""Each test's node has a name of its own (rosout warns about reused names)."""

TEST_TIMEOUT_S = 60.0
"""Longest one test body may take (upstream's launch tests have 60 s too)."""


def all_cases() -> list[Case]:
    """Every upstream test, server suite first."""
    import library_cases
    import server_cases

    return [*server_cases.CASES, *library_cases.CASES]


async def run_body(case: Case, ctx: Context) -> None:
    """Run one body with the test timeout, then close its clients."""
    assert case.body is not None
    try:
        await asyncio.wait_for(case.body(ctx), TEST_TIMEOUT_S)
    finally:
        for client in ctx.clients:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(client.close(), 5)


def run_case(case: Case, mode: str, ros: Any) -> tuple[str, str, Trace, str]:
    """(result, reason, trace, server log) of one case in one mode."""
    trace = Trace()
    reason_na = case.reason_not_applicable(mode)
    if reason_na:
        return "N/A", reason_na, trace, ""
    try:
        server = start_server(["--ros"] if mode == "ros" else [], cwd=str(WEBSIM_DIR))
    except AssertionError as failure:
        return "ERROR", f"websim serve did not start: {str(failure)[-300:]}", trace, ""
    ctx = Context(mode, server.ws_url, trace, ros)
    if ros is not None:
        ctx.node = ros.node(f"upstream_{os.getpid()}_{next(NODE_NUMBERS)}")
    try:
        asyncio.run(run_body(case, ctx))
        result, reason = "PASS", ""
    except AssertionError as failure:
        result, reason = "FAIL", str(failure) or "assertion failed"
    except Exception as error:
        result, reason = "FAIL", f"{type(error).__name__}: {error}"
        trace.add("runner", "--", traceback.format_exc())
    finally:
        if ros is not None:
            ros.drop(ctx.node)
        server.stop()
    log = "".join(server.output)
    return result, reason, trace, log


WEBSIM_DIR = REPO
"""The websim tree the servers run from: the checkout, or a ``--snapshot`` of its HEAD."""


def snapshot(commit: str) -> Path:
    """Export ``commit`` of the checkout to /tmp (git archive: the tree is not touched)."""
    target = Path(f"/tmp/websim-snapshot-{commit}")
    if not target.exists():
        target.mkdir()
        archive = subprocess.run(["git", "-C", str(REPO), "archive", commit],
                                 capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(target)], input=archive, check=True)
    return target


def git_commit() -> str:
    """The websim checkout's commit, with '+dirty' when its tracked files have changes."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(REPO), *args], capture_output=True,
                              text=True, check=False).stdout.strip()
    return git("rev-parse", "--short", "HEAD") + ("+dirty" if git("status", "--porcelain",
                                                                  "-uno") else "")


def main(argv: list[str] | None = None) -> int:
    """Run the selected tests; exit 1 when any failed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=(*MODES, "both"), default="both")
    parser.add_argument("--suite", choices=("server", "library", "all"), default="all")
    parser.add_argument("-k", dest="substring", default="", help="only tests whose id has it")
    parser.add_argument("--snapshot", action="store_true",
                        help="serve from an export of HEAD (others' uncommitted edits out)")
    parser.add_argument("--out", type=Path, default=Path("/tmp/websim-upstream-rosbridge"))
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    global WEBSIM_DIR
    if args.snapshot:
        WEBSIM_DIR = snapshot(git_commit().removesuffix("+dirty"))
    cases = [c for c in all_cases() if args.substring in c.test_id
             and args.suite in ("all", c.suite.removeprefix("rosbridge_"))]
    modes = MODES if args.mode == "both" else (args.mode,)
    any_failed = False
    for mode in modes:
        started = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
        commit = git_commit()
        if args.snapshot:
            commit = WEBSIM_DIR.name.removeprefix("websim-snapshot-")
        print(f"== mode {mode}: websim {commit}, started {started}", flush=True)
        ros = None
        if mode == "ros":
            os.environ.setdefault("ROS_DOMAIN_ID", str(90 + os.getpid() % 10))
            os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
            from ros_side import RosSide

            ros = RosSide()
        rows = []
        try:
            for case in cases:
                result, reason, trace, log = run_case(case, mode, ros)
                print(f"{result:4} {case.test_id}" + (f"  -- {reason}" if reason else ""),
                      flush=True)
                rows.append({"test": case.test_id, "suite": case.suite, "result": result,
                             "reason": reason})
                if result in ("FAIL", "ERROR"):
                    any_failed = True
                    name = case.test_id.replace("/", "_").replace("::", "__")
                    warnings = [line for line in log.splitlines()
                                if "WARNING" in line or "ERROR" in line or "Traceback" in line]
                    (args.out / f"{mode}-{name}.trace").write_text(
                        "\n".join([case.test_id, reason, "", *trace.lines, "",
                                   "server log (warnings):", *warnings]) + "\n")
        finally:
            if ros is not None:
                ros.shutdown()
        totals: dict[str, dict[str, int]] = {}
        for row in rows:
            suite = totals.setdefault(row["suite"], {"PASS": 0, "FAIL": 0, "N/A": 0,
                                                     "ERROR": 0})
            suite[row["result"]] += 1
        for suite_name, counts in totals.items():
            ran = counts["PASS"] + counts["FAIL"]
            print(f"-- {mode} {suite_name}: ran {ran}, passed {counts['PASS']}, failed "
                  f"{counts['FAIL']}, not applicable {counts['N/A']}, server did not start "
                  f"{counts['ERROR']}")
        (args.out / f"results-{mode}.json").write_text(json.dumps(
            {"mode": mode, "commit": commit, "started": started, "totals": totals,
             "tests": rows}, indent=1))
    return 1 if any_failed else 0


if __name__ == "__main__":
    sys.exit(main())
