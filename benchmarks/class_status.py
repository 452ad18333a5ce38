"""What the dashboard's status costs a class: one call per root, against a call per robot.

It starts ONE real ``websim serve --class N`` (``--robots``, default 30 100) and drives every
robot at 10 Hz from this process, one client per robot with its robot's token, each sending a
zero command (a robot driven so stands still: only the command's age says it is driven). Then
an instructor's root connection (``ws://127.0.0.1:PORT/?token=ADMIN``) asks for the robots'
status, for ``--seconds`` (10) each way:

* ``none``: nobody asks (the drivers' own cost);
* ``class``: ``/websim/class_status`` every 0.5 s after the answer, as the dashboard does
  now (``web-interface/js/class-poller.js``);
* ``each``: ``/NAME/websim/status`` of one robot after another, a round of 2 s (one call per
  2 s / N, at least 20 ms apart), as the dashboard did before.

Per way: the server's CPU (% of one core), status calls per second, answer time p50 / p99
(ms), bytes per answer, and, from the answers, the age of each robot's last command as the
dashboard would show it (the answer's age plus the time until the robot's next answer): its
p99 and the share of readings over the dashboard's 2 s "driving" window. Loopback only; it
asserts nothing.

Run it from the checkout::

    python benchmarks/class_status.py
    python benchmarks/class_status.py --robots 100 --seconds 20
"""

from __future__ import annotations

import argparse
import asyncio
import csv
import itertools
import json
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import psutil
from websockets.asyncio.client import ClientConnection, connect

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import ADMIN_TOKEN, HOST, cpu_seconds, percentile, running_server, twist_frame

DRIVE_PERIOD_S = 0.1
"""Each robot's driver sends a command every 0.1 s (10 Hz)."""

CLASS_PERIOD_S = 0.5
"""``class``: the next ``/websim/class_status`` this long after an answer (class-poller.js)."""

ROUND_S = 2.0
MIN_GAP_S = 0.02
"""``each``: every robot once per ROUND_S, one call per ROUND_S / N, at least MIN_GAP_S apart."""

DRIVING_WINDOW_S = 2.0
"""The dashboard counts a robot as driving while its last command is at most this old."""


async def drive(connection: ClientConnection, stop_s: float) -> None:
    """Zero commands at 10 Hz until ``stop_s`` (the loop's time); reads and drops the rest."""
    loop = asyncio.get_running_loop()
    frame = twist_frame(0.0)
    due_s = loop.time()
    while due_s < stop_s:
        await asyncio.sleep(max(0.0, due_s - loop.time()))
        await connection.send(frame)
        due_s += DRIVE_PERIOD_S


async def drain(connection: ClientConnection) -> None:
    async for _ in connection:
        pass


class Root:
    """The instructor's root connection: one call at a time, answered by id."""

    def __init__(self, connection: ClientConnection) -> None:
        self.connection = connection
        self._ids = itertools.count()

    async def call(self, service: str) -> tuple[dict[str, Any], float, int]:
        """``service``'s values, the answer's time (s) and size (bytes)."""
        call_id = f"c{next(self._ids)}"
        sent_s = time.perf_counter()
        await self.connection.send(json.dumps({"op": "call_service", "id": call_id,
                                               "service": service}))
        while True:
            frame = await self.connection.recv()
            message = json.loads(frame)
            if message.get("id") == call_id:
                if not message.get("result"):
                    raise RuntimeError(f"{service}: {message.get('values')}")
                return message["values"], time.perf_counter() - sent_s, len(frame)


class Ages:
    """The age each robot's card would show, sampled every 0.1 s between its answers."""

    def __init__(self) -> None:
        self.last: dict[str, tuple[float, float]] = {}  # name -> (age at answer, answer time)
        self.readings: list[float] = []

    def answer(self, name: str, age_s: float | None, now_s: float) -> None:
        """Robot ``name``'s answer at ``now_s``: its last command ``age_s`` old (None: none)."""
        self.last[name] = (float("inf") if age_s is None else age_s, now_s)

    def sample(self, now_s: float) -> None:
        """Every robot's shown age at ``now_s``: its answer's age plus the time since."""
        for age_s, at_s in self.last.values():
            self.readings.append(age_s + now_s - at_s)


async def measure(way: str, root: Root, names: Sequence[str], seconds: float,
                  server: psutil.Process) -> dict[str, Any]:
    ages = Ages()
    times: list[float] = []
    sizes: list[int] = []
    loop = asyncio.get_running_loop()
    stop_s = loop.time() + seconds

    async def sampler() -> None:
        while loop.time() < stop_s:
            await asyncio.sleep(0.1)
            ages.sample(loop.time())

    async def ask() -> None:
        gap_s = max(MIN_GAP_S, ROUND_S / len(names))
        for index in itertools.count():
            if loop.time() >= stop_s:
                return
            if way == "class":
                values, took_s, size = await root.call("/websim/class_status")
                for robot in values["robots"]:
                    ages.answer(robot["name"], robot["last_drive_age_s"], loop.time())
                pause_s = CLASS_PERIOD_S
            else:
                name = names[index % len(names)]
                values, took_s, size = await root.call(f"/{name}/websim/status")
                ages.answer(name, values["last_drive_age_s"], loop.time())
                pause_s = max(0.0, gap_s - took_s)
            times.append(took_s)
            sizes.append(size)
            await asyncio.sleep(pause_s)

    cpu_before = cpu_seconds(server)
    started = time.perf_counter()
    await asyncio.gather(sampler(), *([ask()] if way != "none" else []))
    elapsed = time.perf_counter() - started
    cpu_pct = 100.0 * (cpu_seconds(server) - cpu_before) / elapsed
    readings = ages.readings
    return {
        "way": way, "cpu_pct": round(cpu_pct, 1),
        "calls_per_s": round(len(times) / elapsed, 1),
        "answer_p50_ms": round(1000 * percentile(times, 50), 2) if times else None,
        "answer_p99_ms": round(1000 * percentile(times, 99), 2) if times else None,
        "answer_bytes": round(sum(sizes) / len(sizes)) if sizes else None,
        "shown_age_p99_s": round(percentile(readings, 99), 2) if readings else None,
        "over_window_pct": round(100.0 * sum(r > DRIVING_WINDOW_S for r in readings)
                                 / len(readings), 1) if readings else None,
    }


async def run(n_robots: int, seconds: float, log_dir: Path) -> list[dict[str, Any]]:
    links = log_dir / f"links-{n_robots}.csv"
    with running_server(log_dir, ["--class", str(n_robots), "--links", str(links)]) as server:
        with links.open(newline="") as file:
            rows = list(csv.DictReader(file))
        names = [row["name"] for row in rows]
        drivers = [await connect(f"ws://{HOST}:{server.ws_port}/robots/{row['name']}"
                                 f"?token={row['token']}", compression=None)
                   for row in rows]
        root_connection = await connect(f"ws://{HOST}:{server.ws_port}/?token={ADMIN_TOKEN}",
                                        compression=None, max_size=None)
        loop = asyncio.get_running_loop()
        stop_s = loop.time() + 3 * seconds + 5.0
        tasks = [asyncio.create_task(drive(ws, stop_s)) for ws in drivers]
        tasks += [asyncio.create_task(drain(ws)) for ws in drivers]
        await asyncio.sleep(2.0)  # every robot driven, its host warm
        process = psutil.Process(server.process.pid)
        root = Root(root_connection)
        rows_out = []
        for way in ("none", "class", "each"):
            rows_out.append({"robots": n_robots,
                             **await measure(way, root, names, seconds, process)})
        for task in tasks:
            task.cancel()
        for ws in [*drivers, root_connection]:
            await ws.close()
        return rows_out


COLUMNS = ("robots", "way", "cpu_pct", "calls_per_s", "answer_p50_ms", "answer_p99_ms",
           "answer_bytes", "shown_age_p99_s", "over_window_pct")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[30, 100])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--json", action="store_true", help="one JSON object per line")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="websim-class-status-") as folder:
        for n_robots in args.robots:
            rows = asyncio.run(run(n_robots, args.seconds, Path(folder)))
            if args.json:
                for row in rows:
                    print(json.dumps(row), flush=True)
                continue
            print("  ".join(f"{column:>15}" for column in COLUMNS))
            for row in rows:
                print("  ".join(f"{'-' if row[c] is None else row[c]!s:>15}" for c in COLUMNS),
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
