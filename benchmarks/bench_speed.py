"""The real-time factor of ``websim serve --speed``: sim seconds per wall second, client or not.

It asserts nothing about speed. For each ``--speed`` (default ``max``) and each client count
(``--clients``, 0 or 1, default both) it:

1. starts a real ``websim serve --speed S`` (maze, kinematic by default) on free ports of
   127.0.0.1 and waits until its ``/healthz`` answers;
2. with one client: connects a rosbridge v2 client (the ``websockets`` asyncio client, in this
   process) that subscribes to /odom and /scan as JSON, reads every frame, parses each /odom
   for its stamp and counts each /scan, as a student's logger would;
3. measures over ``--seconds`` of wall time, between two ``/healthz`` readings:

   * **real-time factor**: ticks run in the window times the 50 ms tick, over the window's
     wall time (``--speed max``: as fast as the host and the client allow; a number: that pace
     at most);
   * **delivery**: the client's /odom stamps must be one tick apart each (a gap is a dropped
     message; above real time there must be none), and its /scan count against the scans
     the window's ticks published;
   * **CPU**: of the server process and of this (client) process over the window, in percent
     of one core (psutil).

With no client the robot builds no message (nobody subscribes): that is the tick loop and the
physics alone; ``benchmarks/bench_physics.py`` gives the physics alone, without a server.

Run it from the checkout::

    python benchmarks/bench_speed.py                      # --speed max, 0 and 1 client, 10 s
    python benchmarks/bench_speed.py --speed max 10 --clients 1 --seconds 20
    python benchmarks/bench_speed.py --quick --markdown   # 3 s windows, a Markdown table
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import itertools
import json
import os
import platform
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import psutil
from bench_server import Server, running_server
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from physics import TICK_PERIOD_S
from ros_nodes.robot_interface import ODOM, SCAN

TICK_NS = round(TICK_PERIOD_S * 1e9)

FIRST_FRAMES_TIMEOUT_S = 20.0
"""How long the client may take to receive its first /odom and /scan."""


@dataclasses.dataclass
class Result:
    """One speed and client count, measured over one window."""

    speed: str
    clients: int
    window_s: float
    ticks: int
    odom: int = 0
    odom_gaps: int = 0
    scans: int = 0
    server_cpu_pct: float = 0.0
    client_cpu_pct: float = 0.0

    @property
    def rtf(self) -> float:
        """Sim time over wall time in the window."""
        return self.ticks * TICK_PERIOD_S / self.window_s


class OdomReader:
    """A client that reads every frame, parses /odom for its stamp and counts /scan."""

    def __init__(self) -> None:
        self.stamps_ns: list[int] = []
        self.scans = 0

    async def read(self, url: str, ready: asyncio.Event) -> None:
        """Subscribe and read until cancelled or closed."""
        async with connect(url, max_size=None) as connection:
            for spec in (ODOM, SCAN):
                await connection.send(json.dumps({"op": "subscribe", "topic": spec.name,
                                                  "type": spec.type}))
            with contextlib.suppress(ConnectionClosed):
                async for frame in connection:
                    message = json.loads(frame)
                    topic = message.get("topic")
                    if topic == ODOM.name:
                        stamp = message["msg"]["header"]["stamp"]
                        self.stamps_ns.append(stamp["sec"] * 1_000_000_000 + stamp["nanosec"])
                    elif topic == SCAN.name:
                        self.scans += 1
                    if self.stamps_ns and self.scans:
                        ready.set()


async def measure(server: Server, speed: str, clients: int, window_s: float) -> Result:
    """Measure one running server over one window."""
    reader = OdomReader()
    task = None
    if clients:
        ready = asyncio.Event()
        task = asyncio.create_task(reader.read(server.ws_url, ready))
        await asyncio.wait_for(ready.wait(), FIRST_FRAMES_TIMEOUT_S)
    server_process = psutil.Process(server.process.pid)
    this_process = psutil.Process()
    first = await asyncio.to_thread(server.health)
    odom_from, scans_from = len(reader.stamps_ns), reader.scans
    cpu_server, cpu_client = server_process.cpu_times(), this_process.cpu_times()
    started = time.monotonic()
    await asyncio.sleep(window_s)
    last = await asyncio.to_thread(server.health)
    elapsed_s = time.monotonic() - started
    cpu_server_after, cpu_client_after = server_process.cpu_times(), this_process.cpu_times()
    stamps = reader.stamps_ns[odom_from:]
    result = Result(speed, clients, elapsed_s, last["ticks"] - first["ticks"],
                    odom=len(stamps),
                    odom_gaps=sum(b - a != TICK_NS for a, b in itertools.pairwise(stamps)),
                    scans=reader.scans - scans_from)
    result.server_cpu_pct = 100 * (sum(cpu_server_after[:2]) - sum(cpu_server[:2])) / elapsed_s
    if clients:
        result.client_cpu_pct = 100 * (sum(cpu_client_after[:2]) - sum(cpu_client[:2])) \
            / elapsed_s
    if task is not None:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    return result


def run_one(speed: str, clients: int, window_s: float, world: str, mode: str,
            log_dir: Path) -> Result:
    """A fresh server at ``speed``, measured with ``clients`` clients."""
    args = ["--speed", speed, "--world", world, "--mode", mode]
    with running_server(log_dir, args) as server:
        return asyncio.run(measure(server, speed, clients, window_s))


HEADER = ("--speed", "clients", "real-time factor", "/odom received (gaps)", "/scan received",
          "server CPU (% of a core)", "client CPU (%)")


def cells(result: Result) -> tuple[str, ...]:
    """One result's row."""
    delivery = f"{result.odom} ({result.odom_gaps})" if result.clients else "-"
    scans = f"{result.scans} of ~{result.ticks // 2}" if result.clients else "-"
    client_cpu = f"{result.client_cpu_pct:.0f}" if result.clients else "-"
    return (result.speed, str(result.clients), f"{result.rtf:.0f}", delivery, scans,
            f"{result.server_cpu_pct:.0f}", client_cpu)


def plain_table(results: Sequence[Result]) -> str:
    """Results as an aligned text table."""
    lines = [HEADER, *(cells(result) for result in results)]
    widths = [max(len(line[i]) for line in lines) for i in range(len(HEADER))]
    return "\n".join("  ".join(f"{cell:>{widths[i]}}" for i, cell in enumerate(line))
                     for line in lines)


def markdown_table(results: Sequence[Result]) -> str:
    """Results as a Markdown table."""
    lines = ["| " + " | ".join(HEADER) + " |", "|---|--:|--:|--:|--:|--:|--:|"]
    lines += ["| " + " | ".join(cells(result)) + " |" for result in results]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Measure every speed and client count; print one table; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--speed", nargs="+", default=["max"],
                        help="speeds to measure, as websim serve --speed takes them "
                             "(default max)")
    parser.add_argument("--clients", type=int, nargs="+", choices=(0, 1), default=[0, 1],
                        help="0: no client; 1: one client on /odom and /scan (default both)")
    parser.add_argument("--seconds", type=float, default=10.0,
                        help="measurement window (wall s, default 10)")
    parser.add_argument("--world", default="maze", help="world (default maze)")
    parser.add_argument("--mode", default="kinematic", help="motion model (default kinematic)")
    parser.add_argument("--quick", action="store_true", help="smoke run: 3 s windows")
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table")
    args = parser.parse_args(argv)
    window_s = 3.0 if args.quick else args.seconds
    results = []
    with tempfile.TemporaryDirectory(prefix="bench-speed-") as log_dir:
        for speed in args.speed:
            for clients in args.clients:
                print(f"measuring --speed {speed} with {clients} client(s) for {window_s:g} s",
                      file=sys.stderr, flush=True)
                results.append(run_one(speed, clients, window_s, args.world, args.mode,
                                       Path(log_dir)))
    print(f"websim serve --speed benchmark{' (quick)' if args.quick else ''}: {args.world}, "
          f"{args.mode}, {window_s:g} s windows; the client subscribes /odom and /scan (JSON)")
    print(f"Python {platform.python_version()}, {os.cpu_count()} CPUs, "
          f"{platform.platform()}\n")
    print(markdown_table(results) if args.markdown else plain_table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
