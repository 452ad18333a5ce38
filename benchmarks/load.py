"""Classroom load: N clients that all subscribe and all drive, against a real ``websim serve``.

Unlike ``bench_server.py`` (one driver among N readers), here every client subscribes to
/odom, /scan and /tf and publishes /cmd_vel at 10 Hz (a teleop page does), from one other
process. Per client count (``--clients``, default 1 10 40 100) it prints, over a window of
``--seconds`` after every client received every topic:

* delivery: frames received per client and topic over frames published (from /healthz ticks),
  the worst client's share; and the server's ledger of them, ``unaccounted``: the frames
  published to the clients that the server neither handed to their sockets, nor dropped for a
  client that was behind (its outbox keeps a topic's newest frame), nor holds waiting
  (/healthz ``frames_sent``, ``frames_dropped``, ``queued_frames``). It is 0 whatever the
  machine's load: a loaded machine's client process that falls behind lowers delivery (the
  frames wait in its socket's buffers, or are dropped for newer ones), never this;
* latency: cmd_vel→odom, from a client sending a /cmd_vel to that client receiving the first
  /odom whose speed is that command's (every command carries a speed no other one has), p50
  and p99 over all clients. It includes the wait for the next 50 ms tick. With many drivers
  only the last command before a tick takes effect; the others are counted as superseded;
* answered: the share of commands that took effect (the rest were superseded);
* tick jitter p99 (/healthz), server CPU (% of one core), server peak RSS, queued frames,
  ticks missed (due minus run), /scan messages shed because a tick was late, client
  connections the server closed, and ERROR lines or tracebacks in the server's log.

``--soak SECONDS`` runs one client count for that long and prints a row every ``--seconds``,
to see memory or lateness creep. The helpers (server start and stop, frames, percentiles, RSS
sampling) are ``bench_server.py``'s. It asserts nothing; ``tests/test_soak.py`` runs a
60-second soak at N = 40 with ``--json`` and asserts on the rows.

Run it from the checkout::

    python benchmarks/load.py --clients 1 10 40 100 --seconds 10
    python benchmarks/load.py --clients 40 --soak 600 --seconds 30
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import sys
import tempfile
import time
from pathlib import Path

import psutil
from websockets.asyncio.client import connect

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import (
    CONNECT_TIMEOUT_S,
    SUBSCRIBED,
    Client,
    Server,
    close_clients,
    cpu_seconds,
    expected_frames,
    percentile,
    running_server,
    sample_rss,
    subscribe_frame,
    twist_frame,
    wait_for_condition,
)

PUBLISH_PERIOD_S = 0.1
"""Each client publishes /cmd_vel at 10 Hz on average."""

PUBLISH_GAP_SPREAD = 0.5
"""Gaps between one client's commands are uniform in (1 ± this) periods, so that commands
do not lock onto a phase of the server's 50 ms tick (which would fake a constant latency)."""

SPEED_MPS = 0.05
"""About the speed every client commands (m/s), alternating in sign."""

SPEED_STEP_MPS = 1e-7
"""Speeds of different commands differ by this much (m/s); /odom echoes them exactly."""

COMMANDS_PER_CLIENT = 1000
"""Distinct speeds per client before they repeat (100 s at 10 Hz; a command is answered or
superseded within a tick)."""


HEADER = ("clients deliv% lat_p50 lat_p99 answered% jitter_p99 cpu% rss_MB queued missed"
          " scans_shed closed errors")
"""Column names: worst client's delivery, latency and jitter in ms, missed ticks, closed
connections, server log errors."""
ROW = ("{clients:>7.0f} {delivered_worst_pct:>6.1f} {latency_p50_ms:>7.1f} {latency_p99_ms:>7.1f}"
       " {answered_pct:>9.1f} {jitter_p99_ms:>10.2f} {cpu_pct:>4.1f} {rss_mb:>6.1f} {queued:>6.0f}"
       " {missed_ticks:>6.0f} {scans_shed:>10.0f} {closed:>6.0f} {server_errors:>6.0f}")


class Commands:
    """One client's /cmd_vel commands in flight, each with a speed no other command has.

    Args:
        index: the client's number, so that its speeds differ from every other client's.
        latencies_s: where cmd_vel→odom latencies (s) are appended (shared by all clients).
    """

    def __init__(self, index: int, latencies_s: list[float]) -> None:
        self.seed = index
        self._base_mps = SPEED_MPS + index * SPEED_STEP_MPS * COMMANDS_PER_CLIENT
        self._sequence = 0
        self._sent_s: dict[float, float] = {}
        self.latencies_s = latencies_s
        self.superseded = 0

    def next_speed(self) -> float:
        """A fresh speed (m/s), alternating in sign so the robot stays near spawn."""
        self._sequence += 1
        magnitude = self._base_mps + (self._sequence % COMMANDS_PER_CLIENT) * SPEED_STEP_MPS
        return magnitude if self._sequence % 2 else -magnitude

    def sent(self, speed_mps: float) -> None:
        """Note the time a command left."""
        self._sent_s[speed_mps] = time.perf_counter()

    def on_odom(self, frame: str | bytes, received_s: float) -> None:
        """Time the command this /odom shows, if it is ours; older ones were superseded."""
        self.on_speed(json.loads(frame)["msg"]["twist"]["twist"]["linear"]["x"], received_s)

    def on_speed(self, speed: float, received_s: float) -> None:
        """An /odom showing ``speed`` arrived at ``received_s`` (perf_counter s)."""
        sent_s = self._sent_s.get(speed)
        if sent_s is None:
            return
        self.latencies_s.append(received_s - sent_s)
        older = [key for key, value in self._sent_s.items() if value <= sent_s]
        self.superseded += len(older) - 1
        for key in older:
            del self._sent_s[key]


async def publish(client: Client, commands: Commands, offset_s: float) -> None:
    """Send /cmd_vel every PUBLISH_PERIOD_S, starting ``offset_s`` in, until cancelled."""
    await asyncio.sleep(offset_s)
    loop = asyncio.get_running_loop()
    deadline = loop.time()
    rng = random.Random(commands.seed)
    while True:
        speed_mps = commands.next_speed()
        commands.sent(speed_mps)
        await client.connection.send(twist_frame(speed_mps))
        deadline += PUBLISH_PERIOD_S * rng.uniform(1 - PUBLISH_GAP_SPREAD, 1 + PUBLISH_GAP_SPREAD)
        await asyncio.sleep(max(0.0, deadline - loop.time()))


def server_errors(server: Server) -> int:
    """ERROR lines and tracebacks in the server's log so far."""
    text = server.log_path.read_text(errors="replace")
    return sum(" ERROR " in line or line.startswith("Traceback") for line in text.splitlines())


async def window(server: Server, clients: list[Client], commands: list[Commands],
                 latencies_s: list[float], seconds: float) -> dict[str, float]:
    """Measure one window of ``seconds``; the clients keep running."""
    server_process = psutil.Process(server.process.pid)
    rss_peak = [0]
    sampler = asyncio.create_task(sample_rss(server_process, rss_peak))
    before = await asyncio.to_thread(server.health)
    counts_before = [client.snapshot() for client in clients]
    cpu_before = cpu_seconds(server_process)
    latencies_s.clear()
    superseded_before = sum(each.superseded for each in commands)
    start_s = time.perf_counter()
    await asyncio.sleep(seconds)
    after = await asyncio.to_thread(server.health)
    elapsed_s = time.perf_counter() - start_s
    cpu_after = cpu_seconds(server_process)
    counts_after = [client.snapshot() for client in clients]
    sampler.cancel()
    worst = min((late[spec.name] - early[spec.name]) /
                expected_frames(spec, int(before["ticks"]), int(after["ticks"]))
                for early, late in zip(counts_before, counts_after, strict=True)
                for spec in SUBSCRIBED)
    published = len(clients) * (sum(expected_frames(spec, int(before["ticks"]),
                                                    int(after["ticks"])) for spec in SUBSCRIBED)
                                - int(after["scans_shed"] - before["scans_shed"]))
    ledger = {key: int(after.get(key, 0)) - int(before.get(key, 0))
              for key in ("frames_sent", "frames_dropped", "queued_frames")}
    samples_ms = [1e3 * sample for sample in latencies_s]
    superseded = sum(each.superseded for each in commands) - superseded_before
    return {"clients": len(clients), "delivered_worst_pct": 100.0 * worst,
            "dropped_frames": float(ledger["frames_dropped"]),
            "unaccounted": float(published - sum(ledger.values())),
            "latency_p50_ms": percentile(samples_ms, 50),
            "latency_p99_ms": percentile(samples_ms, 99),
            "answered_pct": 100.0 * len(samples_ms) / max(1, len(samples_ms) + superseded),
            "jitter_p99_ms": float(after["tick_jitter_p99_ms"]),
            "cpu_pct": 100.0 * (cpu_after - cpu_before) / elapsed_s,
            "rss_mb": rss_peak[0] / 1e6, "queued": float(after["queued_frames"]),
            "missed_ticks": float(after["ticks_due"] - after["ticks"]),
            "scans_shed": float(after["scans_shed"] - before["scans_shed"]),
            "closed": float(sum(client.connection.close_code is not None for client in clients)),
            "server_errors": float(server_errors(server))}


async def run(server: Server, n_clients: int, seconds: float, soak_s: float,
              as_json: bool) -> None:
    """Connect ``n_clients`` drivers and print one row per window."""
    latencies_s: list[float] = []
    commands = [Commands(index, latencies_s) for index in range(n_clients)]
    connections = await asyncio.wait_for(asyncio.gather(*(
        connect(server.ws_url, compression=None, ping_interval=None, close_timeout=2)
        for _ in range(n_clients))), CONNECT_TIMEOUT_S)
    clients = [Client(connection, each.on_odom)
               for connection, each in zip(connections, commands, strict=True)]
    tasks = [asyncio.create_task(client.read()) for client in clients]
    try:
        for client in clients:
            for spec in SUBSCRIBED:
                await client.connection.send(subscribe_frame(spec))
        tasks += [asyncio.create_task(publish(client, each, PUBLISH_PERIOD_S * i / n_clients))
                  for i, (client, each) in enumerate(zip(clients, commands, strict=True))]
        await wait_for_condition(
            lambda: all(min(client.counts.values()) > 0 for client in clients),
            CONNECT_TIMEOUT_S, "every client to receive every topic")
        end_s = time.monotonic() + max(soak_s, seconds)
        while time.monotonic() < end_s - 1e-3:
            row = await window(server, clients, commands, latencies_s, seconds)
            print(json.dumps(row) if as_json else ROW.format(**row), flush=True)
    finally:
        await close_clients(clients, tasks)


def main(argv: list[str] | None = None) -> int:
    """Print one row per client count (or per soak window)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, nargs="+", default=[1, 10, 40, 100])
    parser.add_argument("--seconds", type=float, default=10.0, help="window (default 10 s)")
    parser.add_argument("--soak", type=float, default=0.0, metavar="SECONDS",
                        help="run each client count this long, a row per window")
    parser.add_argument("--json", action="store_true", help="print rows as JSON objects")
    args = parser.parse_args(argv)
    if not args.json:
        print(HEADER)
    for n_clients in args.clients:
        with tempfile.TemporaryDirectory() as log_dir, running_server(Path(log_dir)) as server:
            asyncio.run(run(server, n_clients, args.seconds, args.soak, args.json))
    return 0


if __name__ == "__main__":
    sys.exit(main())
