"""Benchmark ``websim serve`` end to end with real WebSocket clients and print the figures.

It asserts nothing about speed. For each client count N (``--clients``, default 1 and 40) it:

1. starts a real ``websim serve`` process (empty world, kinematic mode) on two free ports of
   127.0.0.1, and waits until its ``/healthz`` answers;
2. connects N rosbridge v2 clients from this one process (the ``websockets`` asyncio client).
   Each subscribes to /odom, /tf and /scan as JSON. To leave the CPU to the server, a client
   only counts its frames: the topic is read from the fixed prefix the server writes
   (``{"op":"publish","topic":"/odom",...``) and a frame is parsed only if the prefix differs;
3. waits until every client has received each topic once, then measures over a window of
   ``--seconds``, bounded by two ``/healthz`` readings:

   * **latency**: client 0 (the driver) also advertises /cmd_vel and publishes a sequence of
     speeds, each different from the one before; in kinematic mode the odometry speed equals
     the command exactly from the next tick on. A sample is the monotonic time from sending
     the Twist to receiving the first /odom whose ``twist.twist.linear.x`` equals it (the
     driver parses its /odom frames). The next command follows a random 1-4 ticks after the
     answer, so sends land at random phases of the 50 ms tick: expect about half a tick plus
     the server's and clients' overhead. The sign of each command points back at the spawn
     pose, so the robot shuttles around it and never reaches a wall. To split that latency,
     the driver also notes, for every /odom frame, its receipt time minus the frame's header
     stamp (both this host's wall clock): the fan-out and client delay without the tick wait;
   * **delivery**: per client and topic, frames received during the window divided by the
     frames the server published in it (from the ``ticks`` count of ``/healthz``: /odom and
     /tf every tick, /scan every second tick); the minimum and median over clients, and the
     share of clients at >= 99 % on all three topics;
   * **tick jitter**: ``tick_jitter_p99_ms`` of ``/healthz`` at the end of the window (the
     server's p99 over its last 1200 ticks, so it also covers the clients' connection),
     and the same from the driver's /odom header stamps in the window alone: each stamp's
     offset from the 50 ms grid, relative to the least late one;
   * **server CPU and memory**: CPU time of the server process over the window, as a percent
     of one core, and its peak RSS (psutil, sampled every 0.25 s); the CPU of this benchmark
     process is printed too, since on a small machine the clients compete with the server;
   * **frame sizes**: bytes of one /scan frame as JSON, and as CBOR from one extra short-lived
     client that subscribes with ``"compression": "cbor"`` (binary frames) before the window.

The server is always stopped (SIGTERM, then SIGKILL after 10 s), also on errors and Ctrl+C;
every wait has a time limit. Run it from the checkout::

    python benchmarks/bench_server.py                       # N = 1 and 40, 15 s windows
    python benchmarks/bench_server.py --clients 1 10 40 --seconds 30
    python benchmarks/bench_server.py --quick               # smoke run: 4 s windows
    python benchmarks/bench_server.py --markdown            # a Markdown table for the README

Figures depend on the machine and its load; the targets (stated for 40 clients) are printed
alongside and checked for every N.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import json
import multiprocessing
import multiprocessing.process
import os
import platform
import random
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Callable, Iterator, Sequence
from importlib.metadata import version
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import psutil
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from physics import TICK_PERIOD_S
from ros_nodes.robot_interface import CMD_VEL, ODOM, SCAN, TF, TopicSpec

PROJECT_DIR = Path(__file__).resolve().parent.parent
"""The checkout: the server runs as ``python -m websim.cli`` from here."""

SPARE_CLIENTS = 10
"""Connections the server admits beyond the measured clients (the CBOR probe, /healthz)."""

HOST = "127.0.0.1"
"""The only address the benchmark binds or connects to."""

ADMIN_TOKEN = "Bench-admin-token-2026-runs"
"""Admin secret of the benchmarked server (no admin operation is used)."""

SUBSCRIBED = (ODOM, TF, SCAN)
"""Every client's subscriptions."""

PUBLISH_PREFIX = '{"op":"publish","topic":"'
"""How the server's compact JSON starts a topic frame; the topic name follows it."""

PUBLISH_PREFIX_BYTES = PUBLISH_PREFIX.encode()
"""The same, of a text frame read undecoded (``recv(decode=False)``)."""

SPEEDS_MPS = (0.2, 0.1)
"""Commanded |linear.x| (m/s), well below the 0.5 m/s limit, so odometry shows them unclamped."""

SPEED_TOLERANCE_MPS = 1e-9
"""An /odom speed within this of the command reflects it (kinematic odometry is exact)."""

GAP_TICKS = (1.0, 4.0)
"""Random wait between an answered command and the next one, in ticks: a uniform tick phase."""

SAMPLE_TIMEOUT_S = 2.0
"""A command whose /odom has not come within this is counted as lost."""

DELIVERED_TARGET = 0.99
"""Target: every client receives at least this share of every topic's frames."""

LATENCY_P99_TARGET_MS = 60.0
"""Target: p99 of the /cmd_vel -> /odom latency (ms), about a tick plus 10 ms."""

JITTER_P99_TARGET_MS = 5.0
"""Target: p99 of how late a tick starts (ms), a tenth of the 50 ms period."""

RSS_PEAK_TARGET_MB = 150.0
"""Target: the server's resident memory (MB), small enough for a classroom laptop or a Pi."""

SERVER_START_TIMEOUT_S = 30.0
"""Longest wait for the server to answer /healthz."""

SERVER_STOP_TIMEOUT_S = 10.0
"""Wait after SIGTERM before the server is killed."""

CONNECT_TIMEOUT_S = 20.0
"""Longest wait for all clients to connect and receive every topic once."""

CLIENTS_PER_READER_PROCESS = 100
"""Up to this many clients, all run in the benchmark's process; beyond, the subscribers other
than the driver run in two processes of their own: one Python event loop receiving 500
clients' frames would queue the driver's /odom behind them and time itself, not the server."""

RSS_SAMPLE_PERIOD_S = 0.25
"""Sampling period of the server's resident memory."""


# ---- the server process -------------------------------------------------------------------

def free_port() -> int:
    """A TCP port of 127.0.0.1 that was free a moment ago."""
    with socket.socket() as probe:
        probe.bind((HOST, 0))
        return int(probe.getsockname()[1])


@dataclasses.dataclass
class Server:
    """A running ``websim serve``.

    Attributes:
        process: the server process.
        ws_port: its rosbridge WebSocket port.
        http_port: its HTTP port (web pages and /healthz).
        log_path: file receiving its stdout and stderr.
    """

    process: subprocess.Popen[bytes]
    ws_port: int
    http_port: int
    log_path: Path

    @property
    def ws_url(self) -> str:
        """The rosbridge URL."""
        return f"ws://{HOST}:{self.ws_port}/"

    def health(self, timeout_s: float = 2.0) -> dict[str, Any]:
        """The server's /healthz report (blocking)."""
        url = f"http://{HOST}:{self.http_port}/healthz?token={ADMIN_TOKEN}"
        with urllib.request.urlopen(url, timeout=timeout_s) as response:
            return dict(json.load(response))

    def log_tail(self, lines: int = 20) -> str:
        """The last lines the server printed."""
        text = self.log_path.read_text(errors="replace").splitlines()
        return "\n".join(text[-lines:])


@contextlib.contextmanager
def running_server(log_dir: Path, extra_args: Sequence[str] = ()) -> Iterator[Server]:
    """Start ``websim serve`` on free ports, wait until healthy, and always stop it.

    ``extra_args`` are appended to its command line (e.g. ``--class 40``).
    """
    ws_port = free_port()
    http_port = free_port()
    while http_port == ws_port:
        http_port = free_port()
    log_path = log_dir / f"websim-serve-{ws_port}.log"
    command = [sys.executable, "-m", "websim.cli", "serve", "--world", "empty",
               "--host", HOST, "--ws-port", str(ws_port), "--http-port", str(http_port),
               "--admin-token", ADMIN_TOKEN, *extra_args]
    env = {**os.environ, "PYTHONUNBUFFERED": "1",
           # a class's state file of this run's own (a run never restores the last one's)
           "XDG_DATA_HOME": str(log_dir / f"websim-data-{ws_port}"),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(PROJECT_DIR),
                                                       os.environ.get("PYTHONPATH")]))}
    with log_path.open("wb") as log:
        process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                   cwd=PROJECT_DIR, env=env)
    server = Server(process, ws_port, http_port, log_path)
    try:
        wait_until_healthy(server)
        yield server
    finally:
        stop_server(process)


def wait_until_healthy(server: Server) -> None:
    """Poll /healthz until it says ok; raise if the server exits or takes too long."""
    deadline = time.monotonic() + SERVER_START_TIMEOUT_S
    while time.monotonic() < deadline:
        if server.process.poll() is not None:
            raise RuntimeError(f"websim serve exited with {server.process.returncode}:\n"
                               f"{server.log_tail()}")
        with contextlib.suppress(OSError, ValueError):
            if server.health(timeout_s=1.0).get("status") == "ok":
                return
        time.sleep(0.05)
    raise RuntimeError(f"websim serve not healthy after {SERVER_START_TIMEOUT_S:g} s:\n"
                       f"{server.log_tail()}")


def stop_server(process: subprocess.Popen[bytes]) -> None:
    """SIGTERM, then SIGKILL if it has not exited within SERVER_STOP_TIMEOUT_S."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=SERVER_STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=SERVER_STOP_TIMEOUT_S)


# ---- the clients --------------------------------------------------------------------------

def subscribe_frame(spec: TopicSpec, compression: str = "none") -> str:
    """A rosbridge ``subscribe`` operation for ``spec``."""
    message = {"op": "subscribe", "topic": spec.name, "type": spec.type}
    if compression != "none":
        message["compression"] = compression
    return json.dumps(message)


def twist_frame(linear_mps: float) -> str:
    """A rosbridge ``publish`` of a /cmd_vel Twist: ``linear.x`` in m/s, no rotation."""
    return json.dumps({"op": "publish", "topic": CMD_VEL.name, "msg": {
        "linear": {"x": linear_mps, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}})


def topic_of(frame: str | bytes) -> str | None:
    """The topic of a published frame, cheaply; None for anything that is not a publish."""
    if isinstance(frame, str) and frame.startswith(PUBLISH_PREFIX):
        end = frame.find('"', len(PUBLISH_PREFIX))
        return frame[len(PUBLISH_PREFIX):end]
    if isinstance(frame, bytes) and frame.startswith(PUBLISH_PREFIX_BYTES):
        end = frame.find(b'"', len(PUBLISH_PREFIX_BYTES))
        return frame[len(PUBLISH_PREFIX_BYTES):end].decode()
    try:
        message = json.loads(frame)
    except ValueError:
        return None
    topic = message.get("topic") if isinstance(message, dict) else None
    return topic if message.get("op") == "publish" and isinstance(topic, str) else None


class Client:
    """One connection that counts the frames and bytes it receives per topic.

    Args:
        connection: the open WebSocket.
        on_odom: called with each /odom frame and its receipt time (monotonic s), or None.
    """

    def __init__(self, connection: ClientConnection,
                 on_odom: Callable[[str | bytes, float], None] | None = None) -> None:
        self.connection = connection
        self.on_odom = on_odom
        self.counts = {spec.name: 0 for spec in SUBSCRIBED}
        self.received_bytes = 0
        self.first_frame: dict[str, str | bytes] = {}

    async def read(self) -> None:
        """Count frames until the connection closes.

        Text frames are read as their UTF-8 bytes: counting them needs no decoding, and the
        clients' own CPU competes with the server on a small machine.
        """
        counts, on_odom = self.counts, self.on_odom
        with contextlib.suppress(ConnectionClosed):
            while True:
                frame = await self.connection.recv(decode=False)
                received_s = time.perf_counter()
                topic = topic_of(frame)
                if topic not in counts:
                    continue
                counts[topic] += 1
                self.received_bytes += len(frame)
                if topic not in self.first_frame:
                    self.first_frame[topic] = frame
                if on_odom is not None and topic == ODOM.name:
                    on_odom(frame, received_s)

    def snapshot(self) -> dict[str, int]:
        """The counts so far, per topic."""
        return dict(self.counts)


class Driver:
    """Publishes /cmd_vel speeds and times the first /odom that shows each one.

    Args:
        rng: source of the random gaps between commands.
    """

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        self.odom_x_m = 0.0
        self.speed_mps = 0.0
        self.latencies_s: list[float] = []
        self.lost = 0
        self.delivery_s: list[float] = []
        """Per /odom frame: receipt minus header stamp (s, wall clock of this host)."""
        self.stamps_s: list[float] = []
        """Per /odom frame: its header stamp (s since the epoch)."""
        self._target_mps: float | None = None
        self._answer: asyncio.Future[float] | None = None

    def on_odom(self, frame: str | bytes, received_s: float) -> None:
        """Note the odometry pose and speed; answer the command in flight if it matches."""
        received_wall_s = time.time()
        msg = json.loads(frame)["msg"]
        stamp = msg["header"]["stamp"]
        stamp_s = stamp["sec"] + 1e-9 * stamp["nanosec"]
        self.stamps_s.append(stamp_s)
        self.delivery_s.append(received_wall_s - stamp_s)
        self.odom_x_m = msg["pose"]["pose"]["position"]["x"]
        speed = msg["twist"]["twist"]["linear"]["x"]
        answer = self._answer
        if (answer is not None and not answer.done() and self._target_mps is not None
                and abs(speed - self._target_mps) <= SPEED_TOLERANCE_MPS):
            answer.set_result(received_s)

    def next_speed(self) -> float:
        """A speed toward the spawn pose (odom x = 0), different from the one in force."""
        sign = -1.0 if self.odom_x_m > 0 else 1.0
        first, second = (sign * speed for speed in SPEEDS_MPS)
        return second if first == self.speed_mps else first

    async def drive(self, connection: ClientConnection, duration_s: float) -> None:
        """Send commands for ``duration_s``, one at a time, timing each answer."""
        await connection.send(json.dumps({"op": "advertise", "topic": CMD_VEL.name,
                                          "type": CMD_VEL.type}))
        loop = asyncio.get_running_loop()
        end_s = time.perf_counter() + duration_s
        while True:
            gap_s = self.rng.uniform(*GAP_TICKS) * TICK_PERIOD_S
            if time.perf_counter() + gap_s >= end_s:
                break
            await asyncio.sleep(gap_s)
            speed = self.next_speed()
            self._target_mps, self._answer = speed, loop.create_future()
            sent_s = time.perf_counter()
            await connection.send(twist_frame(speed))
            remaining_s = end_s - sent_s
            try:
                received_s = await asyncio.wait_for(self._answer,
                                                    min(SAMPLE_TIMEOUT_S, remaining_s))
            except asyncio.TimeoutError:
                if remaining_s > SAMPLE_TIMEOUT_S:  # not merely cut off by the window's end
                    self.lost += 1
            else:
                self.latencies_s.append(received_s - sent_s)
            self.speed_mps = speed
        await asyncio.sleep(max(0.0, end_s - time.perf_counter()))


async def cbor_scan_bytes(url: str, timeout_s: float = 5.0) -> int:
    """Size of one /scan frame sent as CBOR to a client that asked for it (bytes)."""
    async with connect(url, compression=None, ping_interval=None, close_timeout=2,
                       open_timeout=timeout_s) as connection:
        await connection.send(subscribe_frame(SCAN, compression="cbor"))

        async def first_binary() -> int:
            async for frame in connection:
                if isinstance(frame, bytes):
                    return len(frame)
            raise RuntimeError("connection closed before a CBOR /scan frame arrived")

        return await asyncio.wait_for(first_binary(), timeout_s)


# ---- one measurement ----------------------------------------------------------------------

@dataclasses.dataclass
class Result:
    """The figures of one run with ``clients`` connections.

    Attributes:
        clients: number of subscribing clients (the driver included).
        window_s: length of the measurement window (s).
        ticks: ticks the server ran in the window.
        latencies_ms: /cmd_vel -> /odom latency of each answered command (ms).
        lost: commands with no matching /odom within SAMPLE_TIMEOUT_S.
        stamp_to_receipt_ms: per /odom frame the driver received in the window, receipt
            time minus the header stamp (taken right after the tick's step), in ms: the
            server's fan-out and the clients' own delay, without the wait for the tick.
        stamp_lateness_ms: per /odom frame in the window, how much later than the least
            late one its tick started, from the header stamps on the 50 ms grid (ms): the
            tick jitter of the window alone.
        delivered: per topic, each client's received / expected frames.
        jitter_p99_ms: the server's tick lateness p99 at the end of the window (ms).
        server_cpu_percent: server CPU time over the window / window length (% of one core).
        server_rss_peak_mb: the server's peak resident memory in the window (MB).
        client_cpu_percent: the same CPU figure for the benchmark's processes (% of one core).
        received_mbps: bytes all clients received per second (MB/s).
        scan_json_bytes: one /scan frame as JSON text (bytes).
        scan_cbor_bytes: one /scan frame as CBOR (bytes).
    """

    clients: int
    window_s: float
    ticks: int
    latencies_ms: list[float]
    lost: int
    stamp_to_receipt_ms: list[float]
    stamp_lateness_ms: list[float]
    delivered: dict[str, list[float]]
    jitter_p99_ms: float
    server_cpu_percent: float
    server_rss_peak_mb: float
    client_cpu_percent: float
    received_mbps: float
    scan_json_bytes: int
    scan_cbor_bytes: int

    def served_well(self) -> int:
        """Clients with at least DELIVERED_TARGET of every topic."""
        per_client = zip(*self.delivered.values(), strict=True)
        return sum(all(share >= DELIVERED_TARGET for share in shares) for shares in per_client)


def expected_frames(spec: TopicSpec, ticks_before: int, ticks_after: int) -> int:
    """Frames of ``spec`` published by ticks ``ticks_before + 1 .. ticks_after``."""
    return ticks_after // spec.every_ticks - ticks_before // spec.every_ticks


def grid_lateness_ms(stamps_s: Sequence[float]) -> list[float]:
    """How late each stamp is on a grid of ticks, relative to the least late stamp (ms)."""
    if not stamps_s:
        return []
    first = stamps_s[0]
    offsets = [stamp - first - round((stamp - first) / TICK_PERIOD_S) * TICK_PERIOD_S
               for stamp in stamps_s]
    earliest = min(offsets)
    return [1e3 * (offset - earliest) for offset in offsets]


async def wait_for_condition(condition: Callable[[], bool], timeout_s: float,
                             what: str) -> None:
    """Poll ``condition`` every 20 ms; raise after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out after {timeout_s:g} s waiting for {what}")
        await asyncio.sleep(0.02)


async def sample_rss(process: psutil.Process, peak: list[int]) -> None:
    """Keep ``peak[0]`` at the largest resident memory seen (bytes), until cancelled."""
    while True:
        peak[0] = max(peak[0], process.memory_info().rss)
        await asyncio.sleep(RSS_SAMPLE_PERIOD_S)


def cpu_seconds(process: psutil.Process) -> float:
    """User plus system CPU time of ``process`` (s)."""
    times = process.cpu_times()
    return float(times.user + times.system)


async def connect_subscribers(url: str, n_clients: int,
                              on_odom: Callable[[str | bytes, float], None] | None = None,
                              ) -> tuple[list[Client], list[asyncio.Task[None]]]:
    """Connect ``n_clients`` that subscribe to every topic and count what they receive.

    ``on_odom`` is given the first client's /odom frames (the driver's).
    """
    connections = await asyncio.wait_for(asyncio.gather(*(
        connect(url, compression=None, ping_interval=None, close_timeout=2,
                open_timeout=CONNECT_TIMEOUT_S) for _ in range(n_clients))),
        CONNECT_TIMEOUT_S)
    clients, readers = [], []
    for index, connection in enumerate(connections):
        client = Client(connection, on_odom if index == 0 else None)
        clients.append(client)
        readers.append(asyncio.create_task(client.read()))
        for spec in SUBSCRIBED:
            await connection.send(subscribe_frame(spec))
    await wait_for_condition(
        lambda: all(min(client.counts.values()) > 0 for client in clients),
        CONNECT_TIMEOUT_S, "every client to receive every topic")
    return clients, readers


async def close_clients(clients: Sequence[Client], readers: Sequence[asyncio.Task[None]]) -> None:
    """Close every client's connection and stop its reader."""
    await asyncio.gather(*(client.connection.close() for client in clients),
                         return_exceptions=True)
    for reader in readers:
        reader.cancel()
    await asyncio.gather(*readers, return_exceptions=True)


def reader_process(url: str, n_clients: int, pipe: Connection) -> None:
    """A process of ``n_clients`` subscribers (``multiprocessing`` target).

    It sends ``"ready"`` once every client received every topic, then answers each
    ``"snapshot"`` with (per client: counts per topic, bytes received), until ``"stop"``.
    """
    async def serve() -> None:
        clients, readers = await connect_subscribers(url, n_clients)
        pipe.send("ready")
        try:
            while (request := await asyncio.to_thread(pipe.recv)) != "stop":
                assert request == "snapshot", request
                pipe.send([(client.snapshot(), client.received_bytes) for client in clients])
        finally:
            await close_clients(clients, readers)

    try:
        run = client_runner()
        run(serve())
    except Exception as error:  # the parent reads this instead of "ready"
        pipe.send(f"reader process failed: {type(error).__name__}: {error}")


def client_runner() -> Callable[[Any], Any]:
    """The reader processes' ``run``: uvloop's where it is installed, else asyncio's.

    The load then costs less CPU, which on a small machine is CPU the server does not get.
    The server's loop is its own choice (``--event-loop``).
    """
    try:
        import uvloop
    except ImportError:
        return asyncio.run
    return uvloop.run


class ReaderPool:
    """Subscribers in processes of their own.

    So the driver's latency is not queued behind the other clients' frames in one event loop.

    Args:
        url: the server's WebSocket URL.
        n_clients: subscribers over all the processes.
        n_processes: how many processes share them.
    """

    def __init__(self, url: str, n_clients: int, n_processes: int) -> None:
        context = multiprocessing.get_context("spawn")
        shares = [n_clients // n_processes + (i < n_clients % n_processes)
                  for i in range(n_processes)]
        self._pipes: list[Connection] = []
        self.processes: list[multiprocessing.process.BaseProcess] = []
        for share in filter(None, shares):
            parent_end, child_end = context.Pipe()
            process = context.Process(target=reader_process, args=(url, share, child_end),
                                      daemon=True)
            process.start()
            self._pipes.append(parent_end)
            self.processes.append(process)

    def _ask(self, pipe: Connection, timeout_s: float) -> Any:
        if not pipe.poll(timeout_s):
            raise RuntimeError(f"a reader process did not answer within {timeout_s:g} s")
        answer = pipe.recv()
        if isinstance(answer, str) and answer.startswith("reader process failed"):
            raise RuntimeError(answer)
        return answer

    def wait_ready(self) -> None:
        """Block until every process's clients received every topic."""
        for pipe in self._pipes:
            self._ask(pipe, CONNECT_TIMEOUT_S + 10.0)

    def snapshot(self) -> list[tuple[dict[str, int], int]]:
        """Every subscriber's (counts per topic, bytes received) now."""
        for pipe in self._pipes:
            pipe.send("snapshot")
        return [entry for pipe in self._pipes for entry in self._ask(pipe, 10.0)]

    def cpu_seconds(self) -> float:
        """CPU time of the reader processes so far (s)."""
        return sum(cpu_seconds(psutil.Process(process.pid)) for process in self.processes)

    def stop(self) -> None:
        """Close every subscriber and end the processes."""
        for pipe in self._pipes:
            with contextlib.suppress(OSError):
                pipe.send("stop")
        for process in self.processes:
            process.join(timeout=10.0)
            if process.is_alive():
                process.kill()


async def measure(server: Server, n_clients: int, window_s: float, seed: int,
                  reader_processes: int) -> Result:
    """Connect ``n_clients``, measure one window, disconnect; the server keeps running.

    The driver (client 0) runs in this process; the other clients in ``reader_processes``
    processes of their own (none: here too).
    """
    driver = Driver(random.Random(seed))
    clients: list[Client] = []
    readers: list[asyncio.Task[None]] = []
    pool = ReaderPool(server.ws_url, n_clients - 1, reader_processes) \
        if reader_processes > 0 and n_clients > 1 else None
    in_process = 1 if pool is not None else n_clients
    try:
        clients, readers = await connect_subscribers(server.ws_url, in_process, driver.on_odom)
        if pool is not None:
            await asyncio.to_thread(pool.wait_ready)
        scan_cbor_bytes = await cbor_scan_bytes(server.ws_url)
        first_scan = clients[0].first_frame[SCAN.name]
        scan_json_bytes = len(first_scan.encode() if isinstance(first_scan, str)
                              else first_scan)

        def snapshot() -> list[tuple[dict[str, int], int]]:
            here = [(client.snapshot(), client.received_bytes) for client in clients]
            return here + (pool.snapshot() if pool is not None else [])

        def client_cpu_s() -> float:
            return cpu_seconds(this_process) + (pool.cpu_seconds() if pool is not None else 0)

        server_process = psutil.Process(server.process.pid)
        this_process = psutil.Process()
        rss_peak = [0]
        rss_sampler = asyncio.create_task(sample_rss(server_process, rss_peak))
        before = await asyncio.to_thread(server.health)
        counts_before = await asyncio.to_thread(snapshot)
        cpu_before = (cpu_seconds(server_process), client_cpu_s())
        delivery_start = len(driver.delivery_s)
        start_s = time.perf_counter()

        await asyncio.wait_for(driver.drive(clients[0].connection, window_s),
                               window_s + SAMPLE_TIMEOUT_S + 5.0)

        after = await asyncio.to_thread(server.health)
        counts_after = await asyncio.to_thread(snapshot)
        delivery_end = len(driver.delivery_s)
        elapsed_s = time.perf_counter() - start_s
        cpu_after = (cpu_seconds(server_process), client_cpu_s())
        rss_sampler.cancel()
    finally:
        await close_clients(clients, readers)
        if pool is not None:
            await asyncio.to_thread(pool.stop)

    ticks_before, ticks_after = int(before["ticks"]), int(after["ticks"])
    in_window = slice(delivery_start, delivery_end)
    delivered = {}
    for spec in SUBSCRIBED:
        expected = expected_frames(spec, ticks_before, ticks_after)
        delivered[spec.name] = [(late[spec.name] - early[spec.name]) / expected
                                for (early, _), (late, _) in zip(counts_before, counts_after,
                                                                 strict=True)]
    bytes_before = sum(received for _, received in counts_before)
    bytes_after = sum(received for _, received in counts_after)
    return Result(
        clients=n_clients, window_s=elapsed_s, ticks=ticks_after - ticks_before,
        latencies_ms=[1e3 * latency for latency in driver.latencies_s], lost=driver.lost,
        stamp_to_receipt_ms=[1e3 * delay for delay in driver.delivery_s[in_window]],
        stamp_lateness_ms=grid_lateness_ms(driver.stamps_s[in_window]),
        delivered=delivered, jitter_p99_ms=float(after["tick_jitter_p99_ms"]),
        server_cpu_percent=100.0 * (cpu_after[0] - cpu_before[0]) / elapsed_s,
        server_rss_peak_mb=rss_peak[0] / 1e6,
        client_cpu_percent=100.0 * (cpu_after[1] - cpu_before[1]) / elapsed_s,
        received_mbps=(bytes_after - bytes_before) / elapsed_s / 1e6,
        scan_json_bytes=scan_json_bytes, scan_cbor_bytes=scan_cbor_bytes)


def reader_processes_for(n_clients: int) -> int:
    """How many processes the subscribers other than the driver get by default."""
    return 0 if n_clients <= CLIENTS_PER_READER_PROCESS else 2


def run_one(n_clients: int, window_s: float, seed: int, log_dir: Path,
            reader_processes: int | None = None, server_args: Sequence[str] = ()) -> Result:
    """Start a fresh server, measure with ``n_clients``, and stop the server."""
    if reader_processes is None:
        reader_processes = reader_processes_for(n_clients)
    with running_server(log_dir, ["--max-clients", str(n_clients + SPARE_CLIENTS),
                                  "--max-connections-per-address",
                                  str(n_clients + SPARE_CLIENTS), *server_args]) as server:
        try:
            return asyncio.run(asyncio.wait_for(
                measure(server, n_clients, window_s, seed, reader_processes),
                CONNECT_TIMEOUT_S + window_s + SAMPLE_TIMEOUT_S + 30.0))
        except Exception:
            print(f"websim serve output (last lines):\n{server.log_tail()}", file=sys.stderr)
            raise


# ---- the table ----------------------------------------------------------------------------

def percentile(values: Sequence[float], q: float) -> float:
    """The ``q``-th percentile (0-100), interpolated between the nearest ranks."""
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    position = (len(ordered) - 1) * q / 100.0
    low = int(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (position - low)


@dataclasses.dataclass(frozen=True)
class Row:
    """One figure for every run, with its target and the check of the target."""

    figure: str
    values: tuple[str, ...]
    target: str = ""
    missed: tuple[bool, ...] = ()


def rows_of(results: Sequence[Result]) -> list[Row]:
    """The printed figures of every run, one column per run."""
    def row(figure: str, value: Callable[[Result], str], target: str = "",
            meets: Callable[[Result], bool] | None = None) -> Row:
        missed = tuple(not meets(r) for r in results) if meets else ()
        return Row(figure, tuple(value(r) for r in results), target, missed)

    def delivery(topic: str) -> Callable[[Result], str]:
        def shares(r: Result) -> str:
            received = r.delivered[topic]
            return f"{100.0 * min(received):.1f} / {100.0 * statistics.median(received):.1f}"
        return shares

    rows = [
        row("window (s) / server ticks", lambda r: f"{r.window_s:.1f} / {r.ticks}"),
        row("latency /cmd_vel -> /odom p50 (ms)",
            lambda r: f"{percentile(r.latencies_ms, 50):.1f}"),
        row("latency /cmd_vel -> /odom p99 (ms)",
            lambda r: f"{percentile(r.latencies_ms, 99):.1f}",
            f"<= {LATENCY_P99_TARGET_MS:g}",
            lambda r: percentile(r.latencies_ms, 99) <= LATENCY_P99_TARGET_MS and r.lost == 0),
        row("latency max (ms) / samples / lost",
            lambda r: f"{max(r.latencies_ms, default=float('nan')):.1f} / "
                      f"{len(r.latencies_ms)} / {r.lost}"),
        row("/odom stamp -> driver receipt p50 / p99 (ms)",
            lambda r: f"{percentile(r.stamp_to_receipt_ms, 50):.1f} / "
                      f"{percentile(r.stamp_to_receipt_ms, 99):.1f}"),
    ]
    for spec in SUBSCRIBED:
        rows.append(row(f"{spec.name} received, min / median over clients (%)",
                        delivery(spec.name)))
    rows += [
        row(f"clients with >= {100 * DELIVERED_TARGET:g} % of every topic",
            lambda r: f"{r.served_well()} of {r.clients}", "all",
            lambda r: r.served_well() == r.clients),
        row("tick jitter p99, /healthz (ms)", lambda r: f"{r.jitter_p99_ms:.2f}",
            f"<= {JITTER_P99_TARGET_MS:g}", lambda r: r.jitter_p99_ms <= JITTER_P99_TARGET_MS),
        row("tick jitter p99, /odom stamps, window only (ms)",
            lambda r: f"{percentile(r.stamp_lateness_ms, 99):.2f}"),
        row("server CPU (% of one core)", lambda r: f"{r.server_cpu_percent:.0f}"),
        row("server RSS peak (MB)", lambda r: f"{r.server_rss_peak_mb:.0f}",
            f"<= {RSS_PEAK_TARGET_MB:g}", lambda r: r.server_rss_peak_mb <= RSS_PEAK_TARGET_MB),
        row("benchmark clients CPU (% of one core)", lambda r: f"{r.client_cpu_percent:.0f}"),
        row("received by all clients (MB/s)", lambda r: f"{r.received_mbps:.2f}"),
        row("/scan frame, JSON (bytes)", lambda r: f"{r.scan_json_bytes}"),
        row("/scan frame, CBOR (bytes)", lambda r: f"{r.scan_cbor_bytes}"),
    ]
    return rows


def cell(row: Row, index: int) -> str:
    """A figure, marked when it misses its target."""
    return row.values[index] + (" (missed)" if row.missed and row.missed[index] else "")


def plain_table(results: Sequence[Result], rows: Sequence[Row]) -> str:
    """An aligned text table: one column per client count, then the target."""
    header = ("figure", *(f"N={r.clients}" for r in results), "target (N=40)")
    lines = [header, *((row.figure, *(cell(row, i) for i in range(len(results))), row.target)
                       for row in rows)]
    widths = [max(len(line[i]) for line in lines) for i in range(len(header))]
    text = []
    for line in lines:
        cells = [f"{line[0]:<{widths[0]}}"]
        cells += [f"{value:>{width}}" for value, width in zip(line[1:-1], widths[1:-1],
                                                              strict=True)]
        cells.append(line[-1])
        text.append("  ".join(cells).rstrip())
    return "\n".join(text)


def markdown_table(results: Sequence[Result], rows: Sequence[Row]) -> str:
    """The same table in Markdown."""
    header = ("figure", *(f"N = {r.clients}" for r in results), "target (N = 40)")
    lines = ["| " + " | ".join(header) + " |",
             "|---|" + "--:|" * len(results) + "---|"]
    for row in rows:
        cells = (row.figure, *(cell(row, i) for i in range(len(results))), row.target)
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark for every client count and print one table; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clients", type=int, nargs="+", default=[1, 40],
                        help="client counts to measure, one fresh server each (default 1 40)")
    parser.add_argument("--seconds", type=float, default=15.0,
                        help="measurement window per client count (s, default 15)")
    parser.add_argument("--quick", action="store_true", help="smoke run: 4 s windows")
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table")
    parser.add_argument("--seed", type=int, default=1, help="seed of the command timing")
    parser.add_argument("--reader-processes", type=int, default=None,
                        help="processes for the subscribers other than the driver (default: "
                             f"none up to {CLIENTS_PER_READER_PROCESS} clients, else 2)")
    parser.add_argument("--event-loop", choices=("uvloop", "asyncio"), default=None,
                        help="the server's event loop (default: websim serve's)")
    args = parser.parse_args(argv)
    if any(n < 1 for n in args.clients):
        parser.error("--clients: every count must be at least 1")
    window_s = 4.0 if args.quick else args.seconds
    if window_s < 2 * SAMPLE_TIMEOUT_S:
        parser.error(f"--seconds: at least {2 * SAMPLE_TIMEOUT_S:g}")

    server_args = ["--event-loop", args.event_loop] if args.event_loop else []
    signal.signal(signal.SIGTERM, _interrupt)  # so the server is stopped on SIGTERM too
    results = []
    try:
        with tempfile.TemporaryDirectory(prefix="bench-server-") as log_dir:
            for n_clients in args.clients:
                print(f"measuring {n_clients} client(s) for {window_s:g} s ...",
                      file=sys.stderr, flush=True)
                results.append(run_one(n_clients, window_s, args.seed, Path(log_dir),
                                       args.reader_processes, server_args))
    except KeyboardInterrupt:
        print("interrupted; the server was stopped", file=sys.stderr)
        return 130

    print(f"websim serve benchmark{' (quick)' if args.quick else ''}: empty world, kinematic, "
          f"{window_s:g} s window per client count, clients subscribe /odom /tf /scan (JSON)"
          f"{', event loop ' + args.event_loop if args.event_loop else ''}")
    print(f"Python {platform.python_version()}, websockets {version('websockets')}, "
          f"{os.cpu_count()} CPUs, {platform.platform()}\n")
    rows = rows_of(results)
    print(markdown_table(results, rows) if args.markdown else plain_table(results, rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
