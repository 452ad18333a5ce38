"""What grading costs (issue 23): the six-scenario wall-following suite, per student.

Grades the reference roslibpy wall follower (``examples/solutions/wall_follower.py``) on
``examples/scenarios/wall_following_suite.yaml`` in deterministic mode, ``--students`` times
one after the other (default 1), and with ``--class N`` also N copies of it as a class
(``--submissions``, in parallel up to the cores). Printed: per scenario the sim time, the
wall time and the real-time factor (sim time / wall time, the sandbox and the simulator's
start included), the score; per student the wall time (target: at most 30 s on a 2-core
machine) and the suite's total; for a class its wall time.

In the sandbox where bubblewrap and root are here, else ``--no-sandbox`` (printed)::

    python benchmarks/bench_grade.py
    python benchmarks/bench_grade.py --students 3 --class 40 --json
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from grading import load_suite
from websim.grade_class import SUBMISSION_FILE, grade_class
from websim.grade_run import GradeOptions, check_runtime, grade_submission

ROOT = Path(__file__).resolve().parent.parent
SUITE = ROOT / "examples" / "scenarios" / "wall_following_suite.yaml"
SOLUTION = ROOT / "examples" / "solutions" / "wall_follower.py"
COMMAND = ["python3", "wall_follower.py"]


def main() -> None:
    """Grade, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--students", type=int, default=1)
    parser.add_argument("--class", dest="class_size", type=int, default=0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    sandboxed = shutil.which("bwrap") is not None and os.geteuid() == 0
    options = GradeOptions(sandboxed=sandboxed)
    check_runtime([COMMAND], options)  # no roslibpy: say so now, not as a total of 0
    figures: dict[str, Any] = {"sandboxed": sandboxed, "cores": os.cpu_count(),
                               "students": []}
    with tempfile.TemporaryDirectory(prefix="bench-grade-") as temporary:
        folder = Path(temporary) / "submission"
        folder.mkdir()
        shutil.copy(SOLUTION, folder / SOLUTION.name)
        for k in range(args.students):
            out = Path(temporary) / f"out-{k}"
            started = time.perf_counter()
            summary = grade_submission(SUITE, COMMAND, folder, out, options, quiet=True)
            wall_s = time.perf_counter() - started
            scenarios = []
            for row in summary["scenarios"]:
                report = json.loads((out / row["report"]).read_text())
                sim_s = report["run"]["sim_time_s"]
                scenarios.append({"name": row["name"], "sim_time_s": sim_s,
                                  "wall_time_s": report["wall_time_s"],
                                  "real_time_factor": report["real_time_factor"],
                                  "score": row["score"], "passed": row["passed"],
                                  "reason": row["reason"]})
            sim_total = sum(s["sim_time_s"] for s in scenarios)
            figures["students"].append({"wall_time_s": round(wall_s, 2),
                                        "sim_time_s": round(sim_total, 2),
                                        "real_time_factor": round(sim_total / wall_s, 2),
                                        "total": summary["total"], "scenarios": scenarios})
        if args.class_size:
            submissions = Path(temporary) / "class"
            for k in range(args.class_size):
                student = submissions / f"student{k + 1:02d}"
                student.mkdir(parents=True)
                shutil.copy(SOLUTION, student / SOLUTION.name)
                (student / SUBMISSION_FILE).write_text(f"command: {' '.join(COMMAND)}\n")
            started = time.perf_counter()
            rows = grade_class(SUITE, load_suite(SUITE), submissions,
                               Path(temporary) / "class-out", options)
            figures["class"] = {"submissions": len(rows),
                                "wall_time_s": round(time.perf_counter() - started, 1),
                                "totals": sorted({round(r["total"], 6) for r in rows})}
    if args.json:
        print(json.dumps(figures, indent=2))
    else:
        print_figures(figures)
    failed = [(k + 1, scenario["name"], scenario["reason"])
              for k, result in enumerate(figures["students"])
              for scenario in result["scenarios"] if not scenario["passed"]]
    failed += [(0, "class", f"totals {figures['class']['totals']}")
               for _ in [0] if "class" in figures and figures["class"]["totals"] != [1.0]]
    if failed:  # a benchmark of a reference that fails measures nothing: say so, loudly
        for student, name, reason in failed:
            print(f"bench_grade: FAILED: the reference's {name} (student {student}): {reason}",
                  file=sys.stderr)
        raise SystemExit(1)


def print_figures(figures: dict[str, Any]) -> None:
    """The figures, one line per student and per scenario."""
    sandboxed = figures["sandboxed"]
    print(f"sandbox: {'bubblewrap' if sandboxed else 'none (--no-sandbox)'}; "
          f"{figures['cores']} cores")
    for k, result in enumerate(figures["students"]):
        print(f"student {k + 1}: {result['wall_time_s']:.1f} s wall for "
              f"{result['sim_time_s']:.1f} s of sim time ({result['real_time_factor']:.1f}x real "
              f"time), total {result['total']:.4f}")
        for scenario in result["scenarios"]:
            print(f"  {scenario['name']:28s} {scenario['sim_time_s']:6.1f} s sim "
                  f"{scenario['wall_time_s']:5.1f} s wall "
                  f"{scenario['real_time_factor']:5.1f}x  score {scenario['score']:.4f}")
    if "class" in figures:
        result = figures["class"]
        print(f"class of {result['submissions']}: {result['wall_time_s']:.1f} s wall; "
              f"totals {result['totals']}")


if __name__ == "__main__":
    main()
