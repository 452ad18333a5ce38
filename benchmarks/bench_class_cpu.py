"""A class's server CPU per driven robot, in-process: the load of ``bench_class.py``, no sockets.

``bench_class.py`` measures the real server, but on a shared machine whose other processes
take the cores its server gets only what is left: it sheds scans and misses ticks, and its CPU
share then measures the neighbours. This measures the same work in CPU time of one process,
which the neighbours slow down but do not change: N robots (``--robots``, each in its own
"empty" world, as ``websim serve --class N``), each with one driver that subscribes /odom,
/scan and /tf and publishes a /cmd_vel (a JSON frame, a different speed each time) every
other tick (10 Hz), and the instructor's dashboard (a session per robot, named ``/NAME``,
/odom at 200 ms throttle). Ticks run as the server's tick driver runs them
(``TickDriver.tick``: step every world, one scan pass, deliver), on a manual clock moved
50 ms per tick (throttles and budgets see real-time pacing); every frame is written as the
connection writes it (``Outbox.take``, ``WireFrames``, one join per client and flush).
What it leaves out: the event loop, websockets' reading of a frame, the budgets of the
connection, the socket writes.

With ``--arena`` every robot is in one world, as ``--class N --arena``. Each row also gives
when a driver's frames of a tick were written, from the tick's start (p50 / p99 over
every driver and tick): the part of the cmd_vel → odom latency the tick itself adds.

With ``--against DIR`` (another checkout, e.g. ``git worktree add /tmp/base BASE``) it runs
each checkout's code in turn, interleaved, ``--rounds`` times, each in a fresh process, and
prints both and their ratio: how a change compares, measured side by side. It asserts
nothing.

    python benchmarks/bench_class_cpu.py --robots 100
    python benchmarks/bench_class_cpu.py --robots 100 --against /tmp/base --rounds 3
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

PROJECT_DIR = Path(__file__).resolve().parent.parent

TICK_S = 0.05
"""The tick (s): the manual clock moves this much per tick."""

REPEATS = 5
"""Timed runs of ``--ticks`` / REPEATS ticks each; the best and the median are reported."""


def measure(robots: int, ticks: int, arena: bool = False) -> dict[str, Any]:
    """CPU time per tick of ``robots`` driven robots in this process (``PYTHONPATH``'s code).

    With ``arena``, every robot is in one "empty" world (``websim serve --class N --arena``:
    a crowd around its start) instead of each in its own.
    """
    logging.disable(logging.CRITICAL)
    from heartbeat.driver import TickDriver
    from physics import Simulation, WorldSim, load_world
    from ros_nodes.robot_interface import CMD_VEL, ODOM, SCAN, TF
    from ros_nodes.virtual_robot_core import VirtualRobot
    from ros_nodes.world_host import WorldHost
    from rosbridge.core.clock import ManualClock
    from rosbridge.core.limits import ClientLimits
    from rosbridge.core.session import Flush, Session
    from rosbridge.transport.wire import WireFrames

    clock = ManualClock()
    limits = ClientLimits()
    wire = WireFrames()
    written = [0, 0]  # bytes, writes
    worlds, drivers = [], []
    shared = WorldHost(WorldSim(load_world("empty"), seed=0)) if arena else None
    written_at: dict[int, float] = {}  # a driver's session -> when its tick's frames left
    tick_started = [0.0]
    for index in range(robots):
        if shared is not None:
            shared.world.spawn(f"robot{index}")
            host = shared.add(VirtualRobot(Simulation.of(shared.world, f"robot{index}"), clock))
            world = shared
        else:
            sim = Simulation(load_world("empty"), seed=index)
            world, host = WorldHost.of(VirtualRobot(sim, clock))
        driver = Session(f"10.0.{index // 250}.{index % 250}:5000", True, limits=limits,
                         clock=clock)
        host.bridge.connect(driver)
        for spec in (ODOM, SCAN, TF):
            host.bridge.handle(driver, json.dumps({"op": "subscribe", "topic": spec.name,
                                                   "type": spec.type}))
        dashboard = Session("10.1.0.1:5000", True, limits=limits, clock=clock,
                            namespace=f"/robot{index}")
        host.bridge.connect(dashboard)
        host.bridge.handle(dashboard, json.dumps({"op": "subscribe", "topic": ODOM.name,
                                                  "throttle_rate": 200}))
        if world not in worlds:
            worlds.append(world)
        drivers.append((host.bridge, driver))

    def write(flush: Flush) -> None:
        for session in (*flush.now, *flush.later):
            frames = [wire.of(frame) for frame in session.outbox.take(1 << 30)]
            if frames:
                data = b"".join(frames)
                written[0] += len(data)
                written[1] += 1
                written_at.setdefault(id(session), time.perf_counter() - tick_started[0])

    tick_driver = TickDriver(clock=clock)
    tick_driver.write = write  # type: ignore[method-assign]  # no sockets: drained here
    sent = [0]
    delays_ms: list[float] = []

    def tick() -> None:
        clock.advance(TICK_S)
        sent[0] += 1
        for index, (bridge, driver) in enumerate(drivers):
            if (index + sent[0]) % 2 == 0:  # 10 Hz, half the robots each tick
                frame = json.dumps({"op": "publish", "topic": CMD_VEL.name, "msg": {
                    "linear": {"x": 0.2 + 1e-6 * sent[0], "y": 0.0, "z": 0.0},
                    "angular": {"x": 0.0, "y": 0.0, "z": 0.1}}})
                write(bridge.handle(driver, frame))
        written_at.clear()
        tick_started[0] = time.perf_counter()
        tick_driver.tick(worlds)
        delays_ms.extend(1e3 * written_at.get(id(driver), math.nan)
                         for _, driver in drivers)

    for _ in range(20):  # warm-up: every topic flowing
        tick()
    written[:] = [0, 0]
    delays_ms.clear()
    per_tick_s = []
    for _ in range(REPEATS):
        started = time.process_time()
        for _ in range(max(1, ticks // REPEATS)):
            tick()
        per_tick_s.append((time.process_time() - started) / max(1, ticks // REPEATS))
    best, median = min(per_tick_s), statistics.median(per_tick_s)
    return {"robots": robots, "tick_ms_best": best * 1e3, "tick_ms_median": median * 1e3,
            "robot_pct_best": 100 * best / TICK_S / robots,
            "robot_pct_median": 100 * median / TICK_S / robots,
            "bytes_per_tick": written[0] / (REPEATS * max(1, ticks // REPEATS)),
            "writes_per_tick": written[1] / (REPEATS * max(1, ticks // REPEATS)),
            "driver_written_p50_ms": percentile(delays_ms, 50),
            "driver_written_p99_ms": percentile(delays_ms, 99)}


def percentile(values: list[float], pct: float) -> float:
    """The ``pct`` percentile of the finite ``values`` (nan if none)."""
    finite = sorted(value for value in values if math.isfinite(value))
    if not finite:
        return math.nan
    return finite[min(len(finite) - 1, int(pct / 100 * len(finite)))]


def run_child(checkout: Path, robots: int, ticks: int, arena: bool) -> dict[str, Any]:
    """``measure`` in a fresh process running ``checkout``'s code."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child",
                           "--robots", str(robots), "--ticks", str(ticks),
                           *(["--arena"] if arena else [])],
                          cwd=checkout, env=env, capture_output=True, text=True, check=False,
                          timeout=1800)
    if done.returncode != 0:
        raise RuntimeError(f"{checkout}: {done.stderr.strip()[-2000:]}")
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[100],
                        help="robot counts (default 100)")
    parser.add_argument("--ticks", type=int, default=400, help="ticks timed (default 400)")
    parser.add_argument("--against", type=Path, default=None, metavar="DIR",
                        help="another checkout to measure interleaved with this one")
    parser.add_argument("--rounds", type=int, default=2, help="rounds with --against (2)")
    parser.add_argument("--arena", action="store_true",
                        help="every robot in one world (--class N --arena)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(measure(args.robots[0], args.ticks, args.arena)))
        return 0
    checkouts = [("this", PROJECT_DIR)]
    if args.against is not None:
        checkouts.insert(0, ("against", args.against.resolve()))
    rounds = args.rounds if args.against is not None else 1
    print(f"{'robots':>6} {'round':>5} {'code':>8} {'tick ms best/median':>20} "
          f"{'% of a core per robot':>22} {'kB/tick':>8} {'writes/tick':>11} "
          f"{'written p50/p99 ms':>19}")
    results: dict[tuple[int, str], list[dict[str, Any]]] = {}
    for robots in args.robots:
        for number in range(1, rounds + 1):
            for name, checkout in checkouts:
                row = run_child(checkout, robots, args.ticks, args.arena)
                results.setdefault((robots, name), []).append(row)
                print(f"{robots:>6} {number:>5} {name:>8} "
                      f"{row['tick_ms_best']:>9.2f} / {row['tick_ms_median']:<8.2f} "
                      f"{row['robot_pct_best']:>10.3f} / {row['robot_pct_median']:<9.3f} "
                      f"{row['bytes_per_tick'] / 1e3:>8.1f} {row['writes_per_tick']:>11.1f} "
                      f"{row['driver_written_p50_ms']:>9.2f} / "
                      f"{row['driver_written_p99_ms']:<7.2f}",
                      flush=True)
        if args.against is not None:
            mine = [row["tick_ms_best"] for row in results[(robots, "this")]]
            base = [row["tick_ms_best"] for row in results[(robots, "against")]]
            print(f"{robots} robots: this / against, best of each round's best: "
                  f"{min(mine) / min(base):.3f}; medians: "
                  f"{statistics.median(mine) / statistics.median(base):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

