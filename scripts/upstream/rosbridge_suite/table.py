"""Print README.md's result tables from run.py's ``results-MODE.json``: totals, then every test.

Usage (from the repository root, after a run of both modes):

    python3 scripts/upstream/rosbridge_suite/table.py [--out DIR | --log FILE] > /tmp/tables.md

``--out`` is run.py's output directory (default /tmp/websim-upstream-rosbridge); ``--log`` reads
run.py's printed lines instead (``run.py --snapshot > FILE``), which a later run with ``-k``
into the same directory cannot overwrite. The first
table has one row per suite and mode with the run's commit and start time; the second one row
per upstream test: its result in plain and in --ros mode, then its category. A test that passes
in both modes reads ``pass``; a test not applicable gives run.py's reason; a failed test gives
its entry in ``CATEGORY`` (README.md's list of what still fails), or ``UNCLASSIFIED`` and run.py's
reason when it has none, so that a new failure shows up in the table instead of hiding.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

MODE_LABELS = {"plain": "plain", "ros": "--ros"}
"""Each mode as README.md's tables name it."""

SUITE_PREFIXES = {
    "rosbridge_server/test/websocket/": "server: ",
    "rosbridge_library/test/": "library: ",
}
"""Upstream's path of each suite, and the short prefix a test id gets in the table."""

_INFERRED_PUBLISHER = (
    "2, websim defect (items 3, 5): the publisher websim creates on the graph for a publish without"
    " advertise is VOLATILE; upstream's subscriber is TRANSIENT_LOCAL, rosbridge's default"
    " publisher QoS is TRANSIENT_LOCAL with a 1 s lifespan ('offering incompatible QoS ..."
    " DURABILITY')")

CATEGORY = {
    "server: advertise_action_feedback.test.py::TestActionFeedback::test_feedback":
        "1, websim defect (item 1): advertise_action kept off the graph ('is served on the ROS"
        " graph already') after the previous test's rclpy ActionClient of the same name;"
        " passes alone",
    "server: smoke.test.py::TestWebsocketSmoke::test_smoke":
        "5, flaky/environment: 0 of 10 from the rclpy publisher within upstream's 1 s discovery"
        " sleep, under load; passed alone at 359e954 and in runs 2-4",
    "library: capabilities/test_publish.py::TestAdvertise::test_publish_works":
        _INFERRED_PUBLISHER,
    "library: internal/publishers/test_publisher_manager.py::TestPublisherManager::"
    "test_register_infer_topictype": _INFERRED_PUBLISHER,
    "library: internal/publishers/test_publisher_manager.py::TestPublisherManager::"
    "test_publisher_manager_publish": _INFERRED_PUBLISHER,
    "library: internal/test_message_conversion.py::TestMessageConversion::test_assorted_msgs":
        "4, the runner (not websim): uint8[16] of action_msgs/GoalStatus arrives as base64, as"
        " rosbridge 2.x sends every uint8[N]; the round-trip compares it with the list",
    "library: internal/subscribers/test_subscriber_manager.py::TestSubscriberManager::"
    "test_register_no_msgtype":
        "3, deliberate difference: a subscribe with no type to an unknown topic is accepted and"
        " waits for the topic; rosbridge refuses it (TopicNotEstablished)",
}
"""Our classification of each test that failed in the latest run (README.md, "What still fails")."""


def short_id(test_id: str) -> str:
    """A test id as the table shows it: ``server:`` or ``library:`` and the file in the suite."""
    for path, prefix in SUITE_PREFIXES.items():
        if test_id.startswith(path):
            return prefix + test_id.removeprefix(path)
    return test_id


def load(out: Path) -> dict[str, dict[str, Any]]:
    """Each mode's results JSON found in ``out``, by mode."""
    runs = {}
    for mode in MODE_LABELS:
        path = out / f"results-{mode}.json"
        if path.exists():
            runs[mode] = json.loads(path.read_text())
    return runs


HEADER = re.compile(r"== mode (\S+): websim (\S+), started (\S+)")
"""The line run.py prints before each mode's tests."""

RESULT = re.compile(r"(PASS|FAIL|N/A|ERROR)\s+(\S+)(?:  -- (.*))?$")
"""One test's line: result, upstream test id, and after ``  -- `` the reason."""


def load_log(path: Path) -> dict[str, dict[str, Any]]:
    """The same as ``load`` from run.py's printed output (other lines are skipped)."""
    runs: dict[str, dict[str, Any]] = {}
    run: dict[str, Any] | None = None
    for line in path.read_text().splitlines():
        header = HEADER.match(line)
        if header:
            mode, commit, started = header.groups()
            run = runs[mode] = {"mode": mode, "commit": commit, "started": started,
                                "totals": {}, "tests": []}
            continue
        result = RESULT.match(line)
        if result is None or run is None:
            continue
        outcome, test, reason = result.groups()
        suite = test.split("/")[0]
        run["tests"].append({"test": test, "suite": suite, "result": outcome,
                             "reason": reason or ""})
        counts = run["totals"].setdefault(suite, {"PASS": 0, "FAIL": 0, "N/A": 0, "ERROR": 0})
        counts[outcome] += 1
    return runs


def totals_table(runs: dict[str, dict[str, Any]]) -> list[str]:
    """The totals: one row per suite and mode, with that run's commit and start time."""
    lines = ["| suite | mode | websim | started | tests | ran | passed | failed |"
             " not applicable | server did not start |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    suites = [path.rstrip("/") for path in SUITE_PREFIXES]
    for suite_path in suites:
        suite = suite_path.split("/")[0]
        for mode, run in runs.items():
            counts = run["totals"].get(suite)
            if counts is None:
                continue
            ran = counts["PASS"] + counts["FAIL"]
            lines.append(f"| {suite_path} | {MODE_LABELS[mode]} | {run['commit']} |"
                         f" {run['started']} | {sum(counts.values())} | {ran} |"
                         f" {counts['PASS']} | {counts['FAIL']} | {counts['N/A']} |"
                         f" {counts['ERROR']} |")
    return lines


def category(test: str, results: dict[str, dict[str, str]]) -> str:
    """The table's last column for one test, from its result in each mode."""
    outcomes = {mode: row["result"] for mode, row in results.items()}
    if set(outcomes.values()) == {"PASS"}:
        return "pass"
    parts = []
    reasons_na = {row["reason"] for row in results.values() if row["result"] == "N/A"}
    if reasons_na:
        na_modes = [m for m, r in outcomes.items() if r == "N/A"]
        where = "" if len(na_modes) == len(outcomes) else " ".join(
            MODE_LABELS[m] for m in na_modes) + " "
        parts.append(f"{where}n/a: " + "; ".join(sorted(reasons_na)))
    failed = [m for m, r in outcomes.items() if r in ("FAIL", "ERROR")]
    if failed:
        where = "" if len(failed) == len(outcomes) else " ".join(
            MODE_LABELS[m] for m in failed) + ": "
        known = CATEGORY.get(test)
        if known is None:
            reasons = "; ".join(f"{MODE_LABELS[m]}: {results[m]['reason'][:160]}"
                                for m in failed)
            known = f"UNCLASSIFIED ({reasons})"
        parts.append(where + known)
    return "; ".join(parts)


def tests_table(runs: dict[str, dict[str, Any]]) -> list[str]:
    """Every test: its result per mode, then its category or why it does not apply."""
    by_test: dict[str, dict[str, dict[str, str]]] = {}
    for mode, run in runs.items():
        for row in run["tests"]:
            by_test.setdefault(short_id(row["test"]), {})[mode] = row
    header = " | ".join(MODE_LABELS[m] for m in runs)
    lines = [f"| test | {header} | category / reason |",
             "|---|" + "---|" * len(runs) + "---|"]
    for test, results in by_test.items():
        cells = " | ".join(results[m]["result"] if m in results else "–" for m in runs)
        text = category(test, results).replace("|", "\\|")
        lines.append(f"| {test} | {cells} | {text} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    """Print both tables; exit 1 when no results are found."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("/tmp/websim-upstream-rosbridge"))
    parser.add_argument("--log", type=Path, help="run.py's printed output instead of --out")
    args = parser.parse_args(argv)
    runs = load_log(args.log) if args.log else load(args.out)
    if not runs:
        print(f"no results in {args.log or args.out}", file=sys.stderr)
        return 1
    print("\n".join([*totals_table(runs), "", *tests_table(runs)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
