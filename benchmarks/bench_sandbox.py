"""What the sandbox per submission costs (issue 23, section 3): the time it adds to each run.

Printed, as medians over ``--runs`` (5):

* **controller**: a controller that does nothing (``python3 -c pass``) from ``run_controller``
  to its result, sandboxed and not: the sandbox's own cost per run (bubblewrap, the copy of
  the submission home, the user, the limits).
* **open and close**: a ``SubmissionSandbox`` opened and closed without running anything
  (the copy of the submission on the machine, a user's lease).
* **simulator**: ``websim serve`` started in its namespace until it prints that it is ready,
  then stopped (sandboxed and not).
* **sampling**: one scan of the machine's processes (what the sandbox does every 0.1 s while
  a controller runs), in ms, and how many processes it read.

Needs root and bubblewrap. Run it from the checkout::

    python benchmarks/bench_sandbox.py
    python benchmarks/bench_sandbox.py --runs 10 --json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from websim.sandbox import SandboxLimits, SubmissionSandbox
from websim.sandbox.watch import usage


def median_s(action: Callable[[], object], runs: int) -> float:
    """The median wall time of ``action`` over ``runs`` calls, s."""
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        action()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    """Print the figures; exit code 0."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5, help="runs per figure (default 5)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    folder = Path(tempfile.mkdtemp(prefix="websim-bench-sandbox-"))
    (folder / "main.py").write_text("pass\n")
    limits = SandboxLimits(wall_time_s=60.0)
    figures: dict[str, float | int] = {}
    for sandboxed in (True, False):
        label = "sandboxed" if sandboxed else "unsandboxed"
        with SubmissionSandbox(folder, limits=limits, no_sandbox=not sandboxed) as box:
            figures[f"controller_{label}_s"] = median_s(
                lambda box=box: box.run_controller(["python3", "-c", "pass"]), args.runs)

            def simulator(box: SubmissionSandbox = box) -> None:
                box.start_server([sys.executable, "-m", "websim.cli", "serve", "--ws-port",
                                  str(box.ws_port), "--http-port", str(box.http_port)])
                box.stop_server()

            figures[f"simulator_{label}_s"] = median_s(simulator, args.runs)

        def open_and_close(sandboxed: bool = sandboxed) -> None:
            with SubmissionSandbox(folder, limits=limits, no_sandbox=not sandboxed):
                pass

        figures[f"open_and_close_{label}_s"] = median_s(open_and_close, args.runs)
    figures["sampling_ms"] = median_s(lambda: usage(uid=0), args.runs * 10) * 1000
    figures["processes_read"] = len(usage().pids)
    if args.json:
        print(json.dumps({name: round(value, 4) for name, value in figures.items()}))
    else:
        for name, value in figures.items():
            print(f"{name:32s} {value:.4g}" if isinstance(value, float)
                  else f"{name:32s} {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
