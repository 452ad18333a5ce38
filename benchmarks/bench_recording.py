"""What ``--record`` costs a class: CPU and tick jitter with and without it, and bag sizes.

For each scenario it starts one real ``websim serve --class N --open-drive`` (N = ``--robots``,
default 40; empty world, kinematic mode) twice, without and with ``--record DIR``, and
measures over a window of ``--seconds`` (default 60) after ``--warmup`` seconds (10):

* **driven**: one client per robot (from this process, the ``websockets`` asyncio client)
  subscribes to /odom, /scan and /tf and publishes /cmd_vel at 10 Hz, as a class does;
* **idle**: no client at all. The worst case for recording: without it, nobody subscribes and
  the robots build no message; with it, the tap makes every robot build every message (its
  LiDAR cast every second tick), which is what any client subscribed to /scan costs too.

Figures per run: the server process's CPU (% of one core) and the recordings' writer
process's (its child), tick jitter p99 (``/healthz``: each robot's p99 over its last 1200
ticks, i.e. the window's 60 s; the worst robot and the median robot), ticks run, and with
``--record``: messages written and lost (a full queue), bytes on disk and the size per
robot-minute. The machine may be shared: the host's other CPU use over the window is printed
too. It asserts nothing; every wait is bounded; servers are always stopped.

Run it from the checkout::

    python benchmarks/bench_recording.py
    python benchmarks/bench_recording.py --robots 40 --seconds 30 --scenarios driven
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import psutil
import yaml
from websockets.asyncio.client import connect

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import HOST, Server, cpu_seconds, running_server

SCENARIOS = ("driven", "idle")


async def drive(url: str, stop: asyncio.Event, counts: list[int]) -> None:
    """One robot's client: watch /odom, /scan, /tf; publish /cmd_vel at 10 Hz until ``stop``."""
    async with connect(url, compression=None, ping_interval=None, max_size=None) as ws:
        for topic in ("/odom", "/scan", "/tf"):
            await ws.send(json.dumps({"op": "subscribe", "topic": topic}))
        await ws.send(json.dumps({"op": "advertise", "topic": "/cmd_vel",
                                  "type": "geometry_msgs/Twist"}))

        async def read() -> None:
            async for _ in ws:
                counts[0] += 1

        reader = asyncio.create_task(read())
        rng = random.Random(url)
        while not stop.is_set():
            twist = {"linear": {"x": rng.uniform(-0.2, 0.2), "y": 0.0, "z": 0.0},
                     "angular": {"x": 0.0, "y": 0.0, "z": rng.uniform(-1.0, 1.0)}}
            await ws.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": twist}))
            await asyncio.sleep(0.1)
        reader.cancel()


async def window(server: Server, n_robots: int, driven: bool, seconds: float,
                 warmup_s: float) -> dict[str, Any]:
    """Run the clients (if ``driven``) and measure the server over the window."""
    stop = asyncio.Event()
    counts = [0]
    tasks = []
    if driven:
        names = [f"robot{index:02d}" for index in range(1, n_robots + 1)]
        tasks = [asyncio.create_task(drive(f"ws://{HOST}:{server.ws_port}/robots/{name}",
                                           stop, counts)) for name in names]
    await asyncio.sleep(warmup_s)
    main = psutil.Process(server.process.pid)
    me = psutil.Process()
    before = (cpu_seconds(main), sum(cpu_seconds(child) for child in main.children(True)),
              cpu_seconds(me), psutil.cpu_times(), time.monotonic(), counts[0])
    ticks_before = {name: report["ticks"]
                    for name, report in server.health()["robots"].items()}
    await asyncio.sleep(seconds)
    health = server.health()
    after = (cpu_seconds(main), sum(cpu_seconds(child) for child in main.children(True)),
             cpu_seconds(me), psutil.cpu_times(), time.monotonic(), counts[0])
    stop.set()
    await asyncio.gather(*tasks, return_exceptions=True)
    elapsed_s = after[4] - before[4]
    host_busy_s = sum(getattr(after[3], field) - getattr(before[3], field)
                      for field in ("user", "system", "nice", "irq", "softirq"))
    robots = health["robots"]
    jitter = [report["tick_jitter_p99_ms"] for report in robots.values()]
    recordings = [report["recording"] for report in robots.values() if "recording" in report]
    server_s, writer_s, client_s = (after[i] - before[i] for i in range(3))
    return {
        "server_cpu_pct": 100 * server_s / elapsed_s,
        "writer_cpu_pct": 100 * writer_s / elapsed_s,
        "client_cpu_pct": 100 * client_s / elapsed_s,
        "others_cpu_pct": 100 * (host_busy_s - server_s - writer_s - client_s) / elapsed_s,
        "jitter_p99_worst_ms": max(jitter),
        "jitter_p99_median_ms": statistics.median(jitter),
        "ticks_per_robot": statistics.median(report["ticks"] - ticks_before[name]
                                             for name, report in robots.items()),
        "frames_received_per_s": (after[5] - before[5]) / elapsed_s,
        "window_s": elapsed_s,
        "recordings": recordings,
    }


def server_args(n_robots: int, record_dir: Path | None, state: Path) -> list[str]:
    """The class's options (with ``--record record_dir`` unless None)."""
    extra = ["--class", str(n_robots), "--open-drive", "--state", str(state), "--fresh"]
    return extra + (["--record", str(record_dir)] if record_dir is not None else [])


def finish(row: dict[str, Any], scenario: str, n_robots: int, bags: Path | None) -> None:
    """Label a window's row; with a recording, its bags' sizes, messages written and lost."""
    row.update(scenario=scenario, record=bags is not None, robots=n_robots)
    if bags is not None:
        per_minute = []
        for bag in bags.iterdir():
            size = sum(path.stat().st_size for path in bag.iterdir())
            info = yaml.safe_load((bag / "metadata.yaml").read_text())
            duration_s = info["rosbag2_bagfile_information"]["duration"]["nanoseconds"] / 1e9
            per_minute.append(size / 1e6 / (duration_s / 60))
            row["bag_bytes"] = row.get("bag_bytes", 0) + size
        row["mb_per_robot_minute"] = statistics.median(per_minute)
        row["messages_written"] = sum(r["messages_written"] for r in row["recordings"])
        row["messages_lost"] = sum(r["messages_lost"] for r in row["recordings"])
    del row["recordings"]


def run(n_robots: int, scenario: str, record: bool, seconds: float, warmup_s: float,
        log_dir: Path) -> dict[str, Any]:
    """One server, one scenario, with or without ``--record``."""
    bags = log_dir / f"bags-{scenario}-{n_robots}-{time.monotonic_ns()}" if record else None
    state = log_dir / f"state-{scenario}-{record}-{time.monotonic_ns()}.sqlite"
    with running_server(log_dir, server_args(n_robots, bags, state)) as server:
        row = asyncio.run(window(server, n_robots, scenario == "driven", seconds, warmup_s))
    finish(row, scenario, n_robots, bags)
    return row


def run_paired(n_robots: int, scenario: str, seconds: float, warmup_s: float,
               log_dir: Path) -> list[dict[str, Any]]:
    """Both servers at once, without and with ``--record``: the same host load for both.

    Each row's others' CPU then includes the other server and its clients.
    """
    stamp = time.monotonic_ns()
    bags = log_dir / f"bags-{scenario}-{n_robots}-{stamp}"
    with running_server(log_dir, server_args(n_robots, None, log_dir / f"a-{stamp}.sqlite")) \
            as plain, running_server(log_dir, server_args(
                n_robots, bags, log_dir / f"b-{stamp}.sqlite")) as recorded:

        async def both() -> list[dict[str, Any]]:
            return list(await asyncio.gather(
                window(plain, n_robots, scenario == "driven", seconds, warmup_s),
                window(recorded, n_robots, scenario == "driven", seconds, warmup_s)))

        rows = asyncio.run(both())
    finish(rows[0], scenario, n_robots, None)
    finish(rows[1], scenario, n_robots, bags)
    return rows


def tick_cost(ticks: int = 4000) -> dict[str, float]:
    """CPU time of one robot's tick in this process (µs), with a do-nothing tap and recorded.

    Both build every message (a tap listens); the recorded robot's ``Recording`` queues them
    (its writer not running: the queue is emptied by hand, as the feeder would). The
    difference is what recording costs the tick.
    """
    from physics import Simulation, load_world
    from ros_nodes.recording import Recorder
    from ros_nodes.virtual_robot_core import VirtualRobot

    def per_tick_us(robot: VirtualRobot, drain: Any) -> float:
        robot.on_cmd_vel({"linear": {"x": 0.1, "y": 0.0, "z": 0.0},
                          "angular": {"x": 0.0, "y": 0.0, "z": 0.4}})
        best = float("inf")
        for _ in range(5):
            started = time.process_time()
            for _ in range(ticks // 5):
                robot.step()
                drain()
            best = min(best, (time.process_time() - started) / (ticks // 5) * 1e6)
        return best

    nothing = VirtualRobot(Simulation(load_world("maze"), seed=0))
    nothing.tap.add(lambda *crossing: None)
    recorded = VirtualRobot(Simulation(load_world("maze"), seed=0))
    with tempfile.TemporaryDirectory() as folder:
        recorder = Recorder(Path(folder), max_queued=10**9)
        recording = recorder.record("robot", recorded)
        results = {"tick_null_tap_us": per_tick_us(nothing, lambda: None),
                   "tick_recorded_us": per_tick_us(recorded, recording.queue.clear)}
        recorder.close()
    results["recording_per_tick_us"] = results["tick_recorded_us"] - \
        results["tick_null_tap_us"]
    results["messages_per_tick"] = recording.stats.queued / recorded.sim.tick
    return results


def table(rows: Sequence[dict[str, Any]]) -> str:
    """The figures, one line per run."""
    lines = ["scenario  robots  record  server CPU  writer CPU  jitter p99 worst/median  "
             "ticks  lost  MB/robot-min  (client CPU, others' CPU)"]
    for row in rows:
        lines.append(
            f"{row['scenario']:8s}  {row['robots']:6d}  {'yes' if row['record'] else 'no':6s}"
            f"  {row['server_cpu_pct']:8.1f} %  {row['writer_cpu_pct']:8.1f} %"
            f"  {row['jitter_p99_worst_ms']:9.2f} / {row['jitter_p99_median_ms']:5.2f} ms"
            f"  {row['ticks_per_robot']:5.0f}  {row.get('messages_lost', 0):4d}"
            f"  {row.get('mb_per_robot_minute', 0.0):12.3f}"
            f"  ({row['client_cpu_pct']:.0f} %, {row['others_cpu_pct']:.0f} %)")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=40)
    parser.add_argument("--seconds", type=float, default=60.0,
                        help="measured window (s); /healthz's jitter covers the last 60 s")
    parser.add_argument("--warmup", type=float, default=10.0)
    parser.add_argument("--scenarios", nargs="+", choices=SCENARIOS, default=list(SCENARIOS))
    parser.add_argument("--repeat", type=int, default=1,
                        help="runs of each pair, alternating without and with --record")
    parser.add_argument("--json", action="store_true", help="also print the rows as JSON")
    parser.add_argument("--paired", action="store_true",
                        help="run the two servers (without, with --record) at the same time, "
                             "under the same host load")
    parser.add_argument("--tick-cost-only", action="store_true",
                        help="only the in-process tick cost (no server)")
    args = parser.parse_args(argv)
    cost = tick_cost()
    print(f"one robot's tick, every message built (maze; CPU time, best of 5): "
          f"{cost['tick_null_tap_us']:.1f} µs with a tap listener that does nothing, "
          f"{cost['tick_recorded_us']:.1f} µs recorded: the recording costs the tick "
          f"{cost['recording_per_tick_us']:.1f} µs ({cost['messages_per_tick']:.1f} messages "
          "per tick)", flush=True)
    if args.tick_cost_only:
        return 0
    rows = []
    with tempfile.TemporaryDirectory(prefix="websim-bench-recording-") as folder:
        for scenario in args.scenarios:
            for _ in range(args.repeat):
                if args.paired:
                    pair = run_paired(args.robots, scenario, args.seconds, args.warmup,
                                      Path(folder))
                else:
                    pair = [run(args.robots, scenario, record, args.seconds, args.warmup,
                                Path(folder)) for record in (False, True)]
                rows.extend(pair)
                for row in pair:
                    print(table([row]).splitlines()[1], flush=True)
    print(table(rows))
    if args.json:
        print(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
