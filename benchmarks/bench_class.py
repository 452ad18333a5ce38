"""A class in one process: ``websim serve --class N`` against N separate single-robot servers.

For each robot count N (``--robots``, default 40 100) it starts ONE real
``websim serve --class N`` and connects, from this one other process, one client per robot
(``ws://127.0.0.1:PORT/robots/NAME``) that subscribes to /odom, /scan and /tf and publishes
/cmd_vel at 10 Hz (random gaps of 0.05-0.15 s, as ``load.py``), every command with a speed no
other command has. Each robot has this one driver, so its cmd_vel→odom latency is unbiased
(no command is answered early by another driver's). Plus an instructor's "dashboard": the
root connection ``ws://127.0.0.1:PORT/?token=ADMIN`` subscribing every robot's ``/NAME/odom``
with ``throttle_rate`` 200 ms (5 Hz each), found by calling ``/websim/robots`` there; if the
server has no such view, one admin connection per robot (``/robots/NAME?token=ADMIN``)
subscribing /odom the same way (the table says which).

For comparison (today's workaround), for N up to ``--compare-max`` (40) it also starts N
separate single-robot ``websim serve`` processes, each with its one driver and one dashboard
connection, same load.

Over a window of ``--seconds`` after every client received every topic and ``--warmup``
seconds more, per setup:

* delivery: per client and topic, frames received over frames the robot published (from the
  robot's ``ticks`` in /healthz: /odom and /tf every tick, /scan every second); the worst
  client. The dashboard's share per robot is over ticks / 4 (5 Hz); being one frame short of
  that is the throttle's phase, not a loss, and passes;
* latency: from a driver sending a /cmd_vel to it receiving the first /odom with that speed,
  p50 / p99 over every robot's samples (it includes the wait for the next 50 ms tick), and
  commands lost (unanswered after 1 s, not superseded by a later one of the same driver);
* /odom stamp→receipt p99 (wall clock of this host: the fan-out delay without the tick wait);
* tick jitter p99 (/healthz, worst robot or process), ticks missed, scans shed;
* the server's part of the latency: how long after its step began a robot's /odom and /tf
  were handed to its clients (/healthz ``tick_delivery_p99_ms``: the robots stepped before it,
  in a world of one robot its scan), p99 of the worst robot and of the median one;
* server CPU (% of one core; the sum over processes), server peak RSS (the sum of the
  processes' peaks) and PSS at the end (shared pages counted once), and this client
  process's CPU (it competes with the server on a small machine: near 100 % the figures
  are the clients' limit, not the server's).

Targets (one process, N = 40 and N = 100): every client >= 99 % delivered, latency
p99 <= 60 ms, RSS <= 60 MB + 1 MB per robot. Each setup's table marks figures that miss them
and ends PASS or FAIL (the separate processes are held to the same targets, total RSS
included, for comparison). ``--search`` then doubles N from 40 (40, 80, 160, 320, capped at
``--search-max`` 400) until the one process fails a target, or halves it (20, 10, 5, ...)
until it passes if N = 40 already fails, and reports the largest N it held and, per target,
the counts that met it. The host's other processes' CPU over the window is printed too: the
machine may be shared, and a busy neighbour makes any setup miss. Loopback only; every loop
and wait is bounded. It asserts nothing.

Run it from the checkout::

    python benchmarks/bench_class.py                         # N = 40 and 100, separate at 40
    python benchmarks/bench_class.py --robots 40 --seconds 20 --json
    python benchmarks/bench_class.py --robots 40 100 --search
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import contextlib
import dataclasses
import json
import random
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import psutil
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import (
    ADMIN_TOKEN,
    CONNECT_TIMEOUT_S,
    HOST,
    SUBSCRIBED,
    Client,
    Server,
    close_clients,
    cpu_seconds,
    expected_frames,
    free_port,
    percentile,
    running_server,
    sample_rss,
    subscribe_frame,
    topic_of,
    twist_frame,
    wait_for_condition,
)
from load import Commands

from classroom.nginx_config import Worker, foreground_command, in_directory, nginx_config
from classroom.registry import numbered_roster
from ros_nodes.robot_interface import ODOM

PUBLISH_PERIOD_S = 0.1
"""Each driver publishes /cmd_vel at 10 Hz on average."""

PUBLISH_GAP_SPREAD = 0.5
"""Gaps between commands are uniform in (1 ± this) periods, so commands land at every phase
of the 50 ms tick."""

LOST_AFTER_S = 1.0
"""A command neither answered nor superseded this long after it was sent is lost."""

DASHBOARD_THROTTLE_MS = 200
"""The dashboard's /odom throttle: 5 Hz per robot."""

DASHBOARD_EVERY_TICKS = 4
"""Ticks per dashboard frame (200 ms throttle on the 50 ms tick)."""

SUBSCRIBES_PER_S = 100.0
"""Pace of the root dashboard's subscribes, under the 200 messages/s client rate limit."""

DELIVERED_TARGET_PCT = 99.0
"""Target: every client gets at least this share of every topic."""

LATENCY_P99_TARGET_MS = 60.0
"""Target: cmd_vel→odom latency p99 (ms)."""

RSS_BASE_MB = 60.0
RSS_PER_ROBOT_MB = 1.0
"""Target: the server's RSS at most RSS_BASE_MB + RSS_PER_ROBOT_MB per robot."""

BUSY_HOST_CPU_PCT = 20.0
"""Other processes of the host using more than this (% of one core) mark a verdict busy."""

SEARCH_START = 40
"""``--search`` starts here and doubles (or halves, if this fails)."""

STARTERS = 4
"""Separate servers started at once (each waits for its own /healthz)."""

SPEED_MARKER = '"twist":{"twist":{"linear":{"x":'
STAMP_MARKER = '"stamp":{"sec":'
NANOSEC_MARKER = ',"nanosec":'
"""How the server's compact JSON writes an /odom's speed and stamp (parsed without json)."""


def odom_speed_and_stamp(frame: str | bytes) -> tuple[float, float]:
    """``twist.twist.linear.x`` (m/s) and the header stamp (s) of an /odom frame, cheaply."""
    if isinstance(frame, str):
        with contextlib.suppress(ValueError):
            start = frame.index(SPEED_MARKER) + len(SPEED_MARKER)
            speed = float(frame[start:frame.index(",", start)])
            sec_at = frame.index(STAMP_MARKER) + len(STAMP_MARKER)
            nanosec_at = frame.index(NANOSEC_MARKER, sec_at)
            nanosec_end = frame.index("}", nanosec_at)
            return speed, (int(frame[sec_at:nanosec_at])
                           + 1e-9 * int(frame[nanosec_at + len(NANOSEC_MARKER):nanosec_end]))
    msg = json.loads(frame)["msg"]
    stamp = msg["header"]["stamp"]
    return float(msg["twist"]["twist"]["linear"]["x"]), stamp["sec"] + 1e-9 * stamp["nanosec"]


class Driver(Commands):
    """One robot's only driver: commands with speeds no other command has, and their latency.

    Args:
        index: the driver's number, so that its speeds differ from every other driver's.
    """

    def __init__(self, index: int) -> None:
        super().__init__(index, [])
        self.stamp_delays_s: list[float] = []

    def on_odom(self, frame: str | bytes, received_s: float) -> None:
        """Time the command this /odom shows, if new; note how late the /odom came."""
        speed, stamp_s = odom_speed_and_stamp(frame)
        self.stamp_delays_s.append(time.time() - stamp_s)
        self.on_speed(speed, received_s)

    def lost(self, since_s: float, now_s: float) -> int:
        """Commands sent since ``since_s`` still unanswered LOST_AFTER_S before ``now_s``."""
        return sum(since_s <= sent_s <= now_s - LOST_AFTER_S for sent_s in self._sent_s.values())

    def reset_window(self) -> None:
        """Forget the samples so far (the window starts)."""
        self.latencies_s.clear()
        self.stamp_delays_s.clear()


async def publish(connection: ClientConnection, driver: Driver, offset_s: float) -> None:
    """Send /cmd_vel every PUBLISH_PERIOD_S on average, from ``offset_s`` on, until cancelled."""
    await asyncio.sleep(offset_s)
    loop = asyncio.get_running_loop()
    deadline = loop.time()
    rng = random.Random(driver.seed)
    with contextlib.suppress(ConnectionClosed):
        while True:
            speed_mps = driver.next_speed()
            driver.sent(speed_mps)
            await connection.send(twist_frame(speed_mps))
            deadline += PUBLISH_PERIOD_S * rng.uniform(1 - PUBLISH_GAP_SPREAD,
                                                       1 + PUBLISH_GAP_SPREAD)
            await asyncio.sleep(max(0.0, deadline - loop.time()))


class Dashboard:
    """The instructor's connections, counting /odom frames per robot.

    Args:
        connections: each open WebSocket with the robots it carries, topic -> robot name.
        mode: how it is connected, for the table.
    """

    def __init__(self, connections: list[tuple[ClientConnection, dict[str, str]]],
                 mode: str) -> None:
        self.connections = connections
        self.mode = mode
        self.counts = {name: 0 for _, topics in connections for name in topics.values()}

    async def read(self, connection: ClientConnection, topics: dict[str, str]) -> None:
        """Count one connection's frames until it closes."""
        counts = self.counts
        with contextlib.suppress(ConnectionClosed):
            async for frame in connection:
                name = topics.get(topic_of(frame) or "")
                if name is not None:
                    counts[name] += 1

    async def close(self) -> None:
        """Close every connection."""
        await asyncio.gather(*(connection.close() for connection, _ in self.connections),
                             return_exceptions=True)


def dashboard_subscribe(topic: str) -> str:
    """A throttled /odom subscribe."""
    return json.dumps({"op": "subscribe", "topic": topic, "type": ODOM.type,
                       "throttle_rate": DASHBOARD_THROTTLE_MS})


async def open_connection(url: str) -> ClientConnection:
    """A client connection as the benchmarks make them (no compression, no pings)."""
    return await connect(url, compression=None, ping_interval=None, close_timeout=2,
                         open_timeout=CONNECT_TIMEOUT_S, max_size=None)


async def root_view(ws_port: int) -> tuple[ClientConnection, list[str]] | None:
    """The instructor's root connection and the robots it lists, if the server has one."""
    try:
        connection = await open_connection(f"ws://{HOST}:{ws_port}/?token={ADMIN_TOKEN}")
    except (InvalidHandshake, OSError):
        return None
    try:
        await connection.send(json.dumps({"op": "call_service", "service": "/websim/robots",
                                          "id": "robots"}))
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            reply = json.loads(await asyncio.wait_for(connection.recv(), 3.0))
            if reply.get("op") == "service_response" and reply.get("id") == "robots":
                if reply.get("result"):
                    return connection, list(reply.get("values", {}).get("names", []))
                break
    except (ConnectionClosed, TimeoutError, ValueError, AttributeError):
        pass
    await connection.close()
    return None


async def subscribe_robots(root: ClientConnection, names: Sequence[str]) -> dict[str, str]:
    """Subscribe ``root`` to every ``/NAME/odom``, paced under the rate limit."""
    for index, name in enumerate(names):
        await root.send(dashboard_subscribe(f"/{name}/odom"))
        if index % 10 == 9:
            await asyncio.sleep(10 / SUBSCRIBES_PER_S)
    return {f"/{name}/odom": name for name in names}


async def class_dashboard(server: Server, names: Sequence[str]) -> Dashboard:
    """The root view subscribing every ``/NAME/odom``, else one admin connection per robot."""
    root = await root_view(server.ws_port)
    if root is None or not set(names) <= set(root[1]):
        if root is not None:
            await root[0].close()
        return await per_robot_dashboard(
            [f"ws://{HOST}:{server.ws_port}/robots/{name}?token={ADMIN_TOKEN}"
             for name in names], names, "one admin connection per robot (no root view)")
    return Dashboard([(root[0], await subscribe_robots(root[0], names))],
                     "root view, /NAME/odom")


async def workers_dashboard(servers: Sequence[Server], names: Sequence[str]) -> Dashboard:
    """Each worker's root view, subscribing the robots that live there."""
    connections = []
    for server in servers:
        root = await root_view(server.ws_port)
        if root is None:
            raise RuntimeError(f"worker on port {server.ws_port} has no root view")
        connection, listed = root
        connections.append((connection, await subscribe_robots(
            connection, [name for name in names if name in listed])))
    covered = {name for _, topics in connections for name in topics.values()}
    if covered != set(names):
        raise RuntimeError(f"{len(set(names) - covered)} robots are on no worker's root view")
    return Dashboard(connections, "each worker's root view")


async def per_robot_dashboard(urls: Sequence[str], names: Sequence[str],
                              mode: str) -> Dashboard:
    """One admin connection per robot, each subscribing its /odom throttled."""
    connections = await asyncio.gather(*(open_connection(url) for url in urls))
    for connection in connections:
        await connection.send(dashboard_subscribe(ODOM.name))
    return Dashboard([(connection, {ODOM.name: name})
                      for connection, name in zip(connections, names, strict=True)], mode)


@dataclasses.dataclass
class Setup:
    """Servers under test: per robot, its client URL and a reading of its /healthz part.

    Attributes:
        kind: ``one process`` or ``separate``.
        servers: the server processes.
        names: the robots, in client order.
        urls: each robot's client URL.
        robot_health: reads every robot's /healthz report, in ``names`` order (blocking).
        proxy_pids: processes in front of the servers (nginx).
    """

    kind: str
    servers: list[Server]
    names: list[str]
    urls: list[str]
    robot_health: Callable[[], list[dict[str, Any]]]
    proxy_pids: list[int] = dataclasses.field(default_factory=list)
    """Processes in front of the servers (nginx): their CPU counts as the server's."""


def class_setup(server: Server) -> Setup:
    """The robots of one ``websim serve --class N``."""
    names = sorted(server.health()["robots"])

    def health() -> list[dict[str, Any]]:
        robots = server.health(timeout_s=5.0)["robots"]
        return [robots[name] for name in names]

    return Setup("one process", [server], names,
                 [f"ws://{HOST}:{server.ws_port}/robots/{name}" for name in names], health)


def workers_setup(workers: list[Server], nginx_ws_port: int, n_robots: int) -> Setup:
    """``websim serve --class N --worker`` processes behind nginx at ``nginx_ws_port``."""
    names = [student.name for student in numbered_roster(n_robots)]

    def health() -> list[dict[str, Any]]:
        robots: dict[str, dict[str, Any]] = {}
        for worker in workers:
            robots.update(worker.health(timeout_s=5.0)["robots"])
        return [robots[name] for name in names]

    return Setup(f"{len(workers)} workers behind nginx", workers, names,
                 [f"ws://{HOST}:{nginx_ws_port}/robots/{name}" for name in names], health)


@contextlib.contextmanager
def running_nginx(directory: Path, workers: Sequence[Server], http_port: int,
                  ws_port: int) -> Iterator[subprocess.Popen[bytes]]:
    """The real nginx, configured by ``websim nginx-config``, in front of ``workers``."""
    nginx = shutil.which("nginx") or "/usr/sbin/nginx"
    if not Path(nginx).exists():
        raise RuntimeError("nginx is not installed (apt-get install nginx)")
    directory.mkdir(parents=True, exist_ok=True)
    conf = nginx_config([Worker(HOST, w.http_port, w.ws_port) for w in workers],
                        f"{HOST}:{http_port}", f"{HOST}:{ws_port}")
    path = directory / "nginx.conf"
    path.write_text(in_directory(conf, directory))
    process = subprocess.Popen(foreground_command(nginx, path, directory),
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 10.0
        while True:
            try:
                with urllib.request.urlopen(f"http://{HOST}:{http_port}/healthz", timeout=2):
                    break
            except OSError:
                if process.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError("nginx did not start: " + (
                        (directory / "error.log").read_text()[-500:]
                        if (directory / "error.log").exists() else "no log")) from None
                time.sleep(0.1)
        yield process
    finally:
        process.terminate()
        process.wait(timeout=10)


def separate_setup(servers: list[Server]) -> Setup:
    """N single-robot servers, robot i on server i."""
    names = [f"server{index + 1:02d}" for index in range(len(servers))]

    def health() -> list[dict[str, Any]]:
        return [server.health(timeout_s=5.0) for server in servers]

    return Setup("separate", servers, names, [server.ws_url for server in servers], health)


def delivery_pct(received: int, expected: float) -> float:
    """Received over expected (%)."""
    return 100.0 * received / expected if expected > 0 else 100.0


def dashboard_held(received: int, expected: float) -> bool:
    """At least the target share, or at most one frame short (the throttle's phase)."""
    return received >= min(DELIVERED_TARGET_PCT / 100.0 * expected, expected - 1.0)


async def measure(setup: Setup, seconds: float, warmup_s: float) -> dict[str, Any]:
    """Connect the drivers and the dashboard, warm up, measure one window, disconnect."""
    n_robots = len(setup.names)
    drivers = [Driver(index) for index in range(n_robots)]
    clients: list[Client] = []
    dashboard: Dashboard | None = None
    tasks: list[asyncio.Task[None]] = []
    try:
        connections = await asyncio.wait_for(asyncio.gather(
            *(open_connection(f"{url}?token={ADMIN_TOKEN}") for url in setup.urls)),
            CONNECT_TIMEOUT_S)  # a token: in a class only a robot's owner (or admin) drives
        clients = [Client(connection, driver.on_odom)
                   for connection, driver in zip(connections, drivers, strict=True)]
        tasks += [asyncio.create_task(client.read()) for client in clients]
        for client in clients:
            for spec in SUBSCRIBED:
                await client.connection.send(subscribe_frame(spec))
        tasks += [asyncio.create_task(publish(client.connection, driver,
                                              PUBLISH_PERIOD_S * index / n_robots))
                  for index, (client, driver) in enumerate(zip(clients, drivers, strict=True))]
        if setup.kind == "one process":
            dashboard = await class_dashboard(setup.servers[0], setup.names)
        elif setup.kind.endswith("behind nginx"):
            dashboard = await workers_dashboard(setup.servers, setup.names)
        else:
            dashboard = await per_robot_dashboard(
                [f"{url}?token={ADMIN_TOKEN}" for url in setup.urls], setup.names,
                "one admin connection per process")
        tasks += [asyncio.create_task(dashboard.read(connection, topics))
                  for connection, topics in dashboard.connections]
        board = dashboard
        await wait_for_condition(
            lambda: all(min(client.counts.values()) > 0 for client in clients)
            and min(board.counts.values()) > 0,
            CONNECT_TIMEOUT_S, "every client to receive every topic")
        await asyncio.sleep(warmup_s)
        return await window(setup, clients, drivers, dashboard, seconds)
    finally:
        await close_clients(clients, tasks)
        if dashboard is not None:
            await dashboard.close()


async def window(setup: Setup, clients: list[Client], drivers: list[Driver],
                 dashboard: Dashboard, seconds: float) -> dict[str, Any]:
    """Measure ``seconds`` of the running load."""
    processes = [psutil.Process(server.process.pid) for server in setup.servers]
    proxies = [psutil.Process(pid) for pid in setup.proxy_pids]
    proxies += [child for proxy in proxies for child in proxy.children(recursive=True)]
    this_process = psutil.Process()
    peaks = [[0] for _ in processes]
    samplers = [asyncio.create_task(sample_rss(process, peak))
                for process, peak in zip(processes, peaks, strict=True)]
    before = await asyncio.to_thread(setup.robot_health)
    counts_before = [client.snapshot() for client in clients]
    board_before = dict(dashboard.counts)
    cpu_before = (sum(cpu_seconds(process) for process in processes + proxies),
                  cpu_seconds(this_process))
    host_before = busy_seconds()
    superseded_before = sum(driver.superseded for driver in drivers)
    for driver in drivers:
        driver.reset_window()
    start_s = time.perf_counter()
    await asyncio.sleep(seconds)
    after = await asyncio.to_thread(setup.robot_health)
    counts_after = [client.snapshot() for client in clients]
    board_after = dict(dashboard.counts)
    elapsed_s = time.perf_counter() - start_s
    cpu_after = (sum(cpu_seconds(process) for process in processes + proxies),
                 cpu_seconds(this_process))
    host_after = busy_seconds()
    end_s = time.perf_counter()
    for sampler in samplers:
        sampler.cancel()
    pss_mb = sum(process.memory_full_info().pss for process in processes) / 1e6

    per_client = []
    per_topic: dict[str, list[float]] = {spec.name: [] for spec in SUBSCRIBED}
    board_pct = []
    board_held = 0
    for name, early, late, h0, h1 in zip(setup.names, counts_before, counts_after, before,
                                         after, strict=True):
        ticks0, ticks1 = int(h0["ticks"]), int(h1["ticks"])
        for spec in SUBSCRIBED:
            per_topic[spec.name].append(delivery_pct(late[spec.name] - early[spec.name],
                                                     expected_frames(spec, ticks0, ticks1)))
        per_client.append(min(shares[-1] for shares in per_topic.values()))
        board_received = board_after[name] - board_before[name]
        board_expected = (ticks1 - ticks0) / DASHBOARD_EVERY_TICKS
        board_pct.append(delivery_pct(board_received, board_expected))
        board_held += dashboard_held(board_received, board_expected)
    latencies_ms = [1e3 * sample for driver in drivers for sample in driver.latencies_s]
    stamp_ms = [1e3 * delay for driver in drivers for delay in driver.stamp_delays_s]
    n_robots = len(setup.names)
    return {
        "setup": setup.kind, "robots": n_robots, "processes": len(processes),
        "dashboard": dashboard.mode, "window_s": round(elapsed_s, 2),
        "delivered_worst_pct": min(per_client),
        "delivered_median_pct": percentile(per_client, 50),
        "delivered_worst_by_topic_pct": {topic: min(shares)
                                         for topic, shares in per_topic.items()},
        "dashboard_worst_pct": min(board_pct),
        "dashboard_held": board_held,
        "latency_p50_ms": percentile(latencies_ms, 50),
        "latency_p99_ms": percentile(latencies_ms, 99),
        "latency_max_ms": max(latencies_ms, default=float("nan")),
        "latency_samples": len(latencies_ms),
        "lost": sum(driver.lost(start_s, end_s) for driver in drivers),
        "superseded": sum(driver.superseded for driver in drivers) - superseded_before,
        "stamp_to_receipt_p99_ms": percentile(stamp_ms, 99),
        "jitter_p99_ms": max(float(report["tick_jitter_p99_ms"]) for report in after),
        "delivery_p99_worst_ms": max(float(report.get("tick_delivery_p99_ms", "nan"))
                                     for report in after),
        "delivery_p99_median_ms": percentile(
            [float(report.get("tick_delivery_p99_ms", "nan")) for report in after], 50),
        "missed_ticks": max(int(report["ticks_due"]) - int(report["ticks"])
                            for report in after),
        "scans_shed": sum(int(a["scans_shed"]) - int(b["scans_shed"])
                          for a, b in zip(after, before, strict=True)),
        "server_cpu_pct": 100.0 * (cpu_after[0] - cpu_before[0]) / elapsed_s,
        "client_cpu_pct": 100.0 * (cpu_after[1] - cpu_before[1]) / elapsed_s,
        "others_cpu_pct": max(0.0, 100.0 * (host_after - host_before - cpu_after[0]
                                            + cpu_before[0] - cpu_after[1] + cpu_before[1])
                              / elapsed_s),
        "rss_mb": sum(peak[0] for peak in peaks) / 1e6,
        "pss_mb": pss_mb,
        "rss_budget_mb": RSS_BASE_MB * (len(processes) if setup.proxy_pids else 1)
        + RSS_PER_ROBOT_MB * n_robots,
        "closed": sum(client.connection.close_code is not None for client in clients)
        + sum(connection.close_code is not None for connection, _ in dashboard.connections),
    }


def busy_seconds() -> float:
    """CPU time every process of this host has spent (s, all cores)."""
    times = psutil.cpu_times()
    return float(sum(times) - times.idle - getattr(times, "iowait", 0.0))


def verdict(row: dict[str, Any]) -> dict[str, bool]:
    """Which targets the row meets."""
    return {"delivery": row["delivered_worst_pct"] >= DELIVERED_TARGET_PCT,
            "dashboard": row["dashboard_held"] == row["robots"],
            "lost": row["lost"] == 0,
            "latency": row["latency_p99_ms"] <= LATENCY_P99_TARGET_MS,
            "rss": row["rss_mb"] <= row["rss_budget_mb"]}


def passed(row: dict[str, Any]) -> bool:
    """Whether the row meets every target (a failed run meets none)."""
    return "error" not in row and all(verdict(row).values())


FIGURES: tuple[tuple[str, str, str, str], ...] = (
    ("dashboard", "dashboard", "{}", ""),
    ("delivered, worst / median client (%)", "delivered_worst_pct",
     "{:.1f} / {delivered_median_pct:.1f}", "delivery"),
    ("dashboard delivered, worst robot (%) / held", "dashboard_worst_pct",
     "{:.1f} / {dashboard_held}", "dashboard"),
    ("latency cmd_vel->odom p50 / p99 (ms)", "latency_p99_ms",
     "{latency_p50_ms:.1f} / {:.1f}", "latency"),
    ("latency max (ms) / samples / lost", "latency_max_ms",
     "{:.1f} / {latency_samples} / {lost}", "lost"),
    ("/odom stamp->receipt p99 (ms)", "stamp_to_receipt_p99_ms", "{:.1f}", ""),
    ("tick jitter p99, worst (ms)", "jitter_p99_ms", "{:.2f}", ""),
    ("server: /odom out after its step, p99 worst / median robot (ms)",
     "delivery_p99_worst_ms", "{:.1f} / {delivery_p99_median_ms:.1f}", ""),
    ("ticks missed / scans shed / closed", "missed_ticks", "{} / {scans_shed} / {closed}", ""),
    ("server CPU (% of one core, total)", "server_cpu_pct", "{:.0f}", ""),
    ("server RSS peak, total (MB)", "rss_mb", "{:.1f}", "rss"),
    ("server PSS at end, total (MB)", "pss_mb", "{:.1f}", ""),
    ("client process CPU (% of one core)", "client_cpu_pct", "{:.0f}", ""),
    ("other processes of the host CPU (% of one core)", "others_cpu_pct", "{:.0f}", ""),
)
TARGETS = {"delivery": f">= {DELIVERED_TARGET_PCT:g} %",
           "dashboard": f"all; >= {DELIVERED_TARGET_PCT:g} % or 1 frame short",
           "lost": "0 lost",
           "latency": f"<= {LATENCY_P99_TARGET_MS:g}",
           "rss": f"<= {RSS_BASE_MB:g} + {RSS_PER_ROBOT_MB:g}/robot"}


def verdict_text(row: dict[str, Any]) -> str:
    """PASS or FAIL, and whether the host was busy with other work meanwhile."""
    if "error" in row:
        return "FAIL: " + row["error"][:60]
    busy = " (busy)" if row["others_cpu_pct"] > BUSY_HOST_CPU_PCT else ""
    return ("PASS" if passed(row) else "FAIL") + busy


def table(rows: Sequence[dict[str, Any]]) -> str:
    """One setup's figures, one column per robot count, misses marked, then the verdict."""
    header = ["figure", *(f"N={row['robots']}" for row in rows), "target"]
    lines = [header]
    for title, key, form, target in FIGURES:
        cells = []
        for row in rows:
            if "error" in row:
                cells.append("-")
                continue
            text = form.format(row[key], **row)
            if target and not verdict(row)[target]:
                text += " (missed)"
            cells.append(text)
        lines.append([title, *cells, TARGETS.get(target, "")])
    lines.append(["verdict", *(verdict_text(row) for row in rows),
                  f"busy: others > {BUSY_HOST_CPU_PCT:g} % of a core"])
    widths = [max(len(line[i]) for line in lines) for i in range(len(header))]
    return "\n".join("  ".join([f"{line[0]:<{widths[0]}}",
                                *(f"{cell:>{width}}" for cell, width in
                                  zip(line[1:-1], widths[1:-1], strict=True)),
                                line[-1]]).rstrip() for line in lines)


ARENA_WORLD = """\
name: bench arena
start: [0.0, 0.0, 0.0]
polylines:
  - points: [[-10, -10], [10, -10], [10, 10], [-10, 10]]
    closed: true
"""
"""The arena of ``--arena``: a 20 x 20 m box (bench_world.py's open box), every robot of the
class in it, placed by the server so that no two footprints overlap."""


def extra_server_args(args: argparse.Namespace) -> list[str]:
    """What every server of this run is started with beyond its setup's own arguments."""
    return ["--event-loop", args.event_loop] if args.event_loop else []


def run_setup(kind: str, n_robots: int, seconds: float, warmup_s: float,
              log_dir: Path, workers: int = 2,
              server_args: Sequence[str] = ()) -> dict[str, Any]:
    """Start the servers of one setup, measure, stop them; a failure is a row with ``error``.

    ``server_args`` are added to every server's command line (``--event-loop``).
    """
    budget_s = 2 * CONNECT_TIMEOUT_S + warmup_s + seconds + 30.0
    with contextlib.ExitStack() as stack:
        try:
            if kind == "one process":
                server = stack.enter_context(running_server(
                    log_dir, ["--class", str(n_robots), *server_args]))
                setup = class_setup(server)
            elif kind == "arena":
                world = log_dir / "arena.yaml"
                world.write_text(ARENA_WORLD)
                server = stack.enter_context(running_server(
                    log_dir, ["--class", str(n_robots), "--arena", "--world", str(world),
                              *server_args]))
                setup = class_setup(server)
            elif kind == "workers":
                http_port, ws_port = free_port(), free_port()
                args = ["--class", str(n_robots), "--worker", "--public-ws-port", str(ws_port),
                        "--max-robots", str(n_robots), *server_args]
                with concurrent.futures.ThreadPoolExecutor(STARTERS) as pool:
                    starting = [pool.submit(stack.enter_context, running_server(log_dir, args))
                                for _ in range(workers)]
                    servers = [future.result() for future in starting]
                nginx = stack.enter_context(running_nginx(log_dir / f"nginx-{ws_port}",
                                                          servers, http_port, ws_port))
                setup = workers_setup(servers, ws_port, n_robots)
                setup.proxy_pids.append(nginx.pid)
            else:
                with concurrent.futures.ThreadPoolExecutor(STARTERS) as pool:
                    starting = [pool.submit(stack.enter_context,
                                            running_server(log_dir, server_args))
                                for _ in range(n_robots)]
                    servers = [future.result() for future in starting]
                setup = separate_setup(servers)
            return asyncio.run(asyncio.wait_for(measure(setup, seconds, warmup_s), budget_s))
        except Exception as error:  # a setup that cannot even be measured fails
            tail = "".join(f"\n  {line}" for line in error_tail(log_dir))
            print(f"{kind} N={n_robots}: {type(error).__name__}: {error}{tail}",
                  file=sys.stderr, flush=True)
            return {"setup": kind, "robots": n_robots, "error": f"{type(error).__name__}"}


def error_tail(log_dir: Path, lines: int = 5) -> list[str]:
    """The last lines of the newest server log, to say why a setup failed."""
    logs = sorted(log_dir.glob("*.log"), key=lambda path: path.stat().st_mtime)
    return logs[-1].read_text(errors="replace").splitlines()[-lines:] if logs else []


def search_counts(start: int, cap: int) -> list[int]:
    """``start``, doubling, then ``cap``."""
    counts = []
    count = start
    while count < cap:
        counts.append(count)
        count *= 2
    return [*counts, cap]


def search(results: dict[tuple[str, int], dict[str, Any]], args: argparse.Namespace,
           emit: Callable[[dict[str, Any]], None], log_dir: Path) -> int | None:
    """The largest N (of 40 doubling up to the cap) at which one process meets every target.

    If N = 40 already fails, N is halved instead (20, 10, 5, 2, 1) until one passes.
    """
    def measured(n_robots: int) -> dict[str, Any]:
        if ("one process", n_robots) not in results:
            print(f"searching: one process, {n_robots} robots ...", file=sys.stderr,
                  flush=True)
            results["one process", n_robots] = run_setup(
                "one process", n_robots, args.seconds, args.warmup, log_dir,
                server_args=extra_server_args(args))
            emit(results["one process", n_robots])
        return results["one process", n_robots]

    held: int | None = None
    for n_robots in search_counts(SEARCH_START, args.search_max):
        if not passed(measured(n_robots)):
            break
        held = n_robots
    n_robots = SEARCH_START
    while held is None and n_robots > 1:
        n_robots = max(1, n_robots // 2)
        if passed(measured(n_robots)):
            held = n_robots
    return held


def main(argv: Sequence[str] | None = None) -> int:
    """Measure every setup and print a table per setup (or JSON rows)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[40, 100],
                        help="robot counts (default 40 100)")
    parser.add_argument("--seconds", type=float, default=10.0, help="window (default 10 s)")
    parser.add_argument("--warmup", type=float, default=2.0,
                        help="after every client got every topic (default 2 s)")
    parser.add_argument("--compare-max", type=int, default=40,
                        help="separate processes only up to this N (default 40; 0: never)")
    parser.add_argument("--search", action="store_true",
                        help="then double N from 40 until one process fails a target "
                        "(or halve it until it passes)")
    parser.add_argument("--search-max", type=int, default=400, help="cap of --search (400)")
    parser.add_argument("--workers", type=int, default=0, metavar="K",
                        help="also measure K `--worker` processes behind the real nginx "
                             "(websim nginx-config) for every N (default 0: not)")
    parser.add_argument("--arena", action="store_true",
                        help="also measure one `websim serve --class N --arena` (every robot "
                             "in one 20 x 20 m world: they see each other) for every N")
    parser.add_argument("--event-loop", choices=("uvloop", "asyncio"), default=None,
                        help="the servers' event loop (default: websim serve's)")
    parser.add_argument("--json", action="store_true", help="print rows as JSON objects")
    args = parser.parse_args(argv)
    if any(n < 1 for n in args.robots) or args.search_max < 1:
        parser.error("robot counts must be at least 1")

    def emit(row: dict[str, Any]) -> None:
        if args.json:
            print(json.dumps({**row, "passed": passed(row)}), flush=True)
        else:
            print(f"  {row['setup']} N={row['robots']}: "
                  f"{'PASS' if passed(row) else 'FAIL'}", file=sys.stderr, flush=True)

    results: dict[tuple[str, int], dict[str, Any]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-classroom-") as log_dir:
        plan = [("one process", n) for n in args.robots]
        plan += [("separate", n) for n in args.robots if n <= args.compare_max]
        plan += [("workers", n) for n in args.robots if args.workers > 0]
        plan += [("arena", n) for n in args.robots if args.arena]
        for kind, n_robots in plan:
            print(f"measuring {kind}, {n_robots} robots ...", file=sys.stderr, flush=True)
            results[kind, n_robots] = run_setup(kind, n_robots, args.seconds, args.warmup,
                                                Path(log_dir), args.workers,
                                                extra_server_args(args))
            emit(results[kind, n_robots])
        held: int | None = None
        if args.search:
            held = search(results, args, emit, Path(log_dir))
    if args.json:
        if args.search:
            print(json.dumps({"search_largest_passing": held}))
        return 0
    print(f"classroom benchmark: {args.seconds:g} s window after {args.warmup:g} s warm-up; "
          f"per robot one driver (/odom /scan /tf, /cmd_vel 10 Hz) and the dashboard "
          f"(/odom at 5 Hz); {psutil.cpu_count()} CPUs")
    titles = {"one process": "ONE `websim serve --class N`",
              "separate": "N separate single-robot `websim serve` processes",
              "workers": f"{args.workers} `websim serve --class N --worker` processes behind "
                         "the real nginx (websim nginx-config)",
              "arena": "ONE `websim serve --class N --arena`: every robot in one world"}
    for kind, title in titles.items():
        rows = [row for (each, _), row in sorted(results.items()) if each == kind]
        if rows:
            print(f"\n{title}\n{table(rows)}")
    if args.search:
        print(f"\nsearch (from {SEARCH_START}, doubling up to {args.search_max}, or halving):"
              f" largest N meeting every target in one process: {held}")
        measured = sorted(n for kind, n in results if kind == "one process")
        for target in TARGETS:
            met = [n for n in measured if "error" not in results["one process", n]
                   and verdict(results["one process", n])[target]]
            print(f"  {target:<9} met at N = {' '.join(map(str, met)) or 'none'} "
                  f"(measured: {' '.join(map(str, measured))})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
