"""Clients that subscribe to everything and never read, against a real ``websim serve``.

``--clients`` N (default 300) attacker connections each open a WebSocket, subscribe to every
robot topic (/odom /scan /tf /tf_static /ground_truth /world /cmd_vel) and then never read
their socket again. They are raw TCP sockets whose kernel receive buffer is set small
(``SO_RCVBUF`` 4096, before connecting) with the WebSocket handshake and the masked subscribe
frames written by hand, so the server meets backpressure within a second or two instead of
after the tens of seconds a loopback receive buffer would absorb. They are opened 50 per 0.1 s.
Meanwhile one healthy client (the ``websockets`` library, reading normally) subscribes to
/odom and counts its messages per 1-second window, for the whole run of ``--seconds``
(default 60) after the first attacker connects.

What it prints:

* server RSS (psutil) before the attack, its peak during it, at the end, and the growth
  (peak minus start);
* when the server's send buffer to each attacker filled and when the server closed each
  attacker connection, both from the kernel's loopback socket table (``/proc/net/tcp``: the
  server socket's send queue, and its leaving ESTABLISHED), in seconds after the attack start;
  the ``/healthz`` view (``clients`` back down to 1), and the attacker side at the end (each
  socket is finally drained: EOF or RST means the server dropped it, data still flowing means
  it did not);
* the healthy client's minimum and median per-second /odom rate (Hz);
* ``tick_jitter_p99_ms`` from ``/healthz`` (its last 1200 ticks, which covers the attack),
  missed ticks, shed scans, the server's CPU and ERROR lines in its log.

Targets, printed as PASS or FAIL: RSS growth < 50 MB; every attacker dropped within 15 s of
the server's send buffer to it filling; the healthy client at >= 19 Hz in every window.

Run it from the checkout::

    python benchmarks/nonreaders.py
    python benchmarks/nonreaders.py --clients 100 --seconds 30 --json
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import json
import os
import resource
import socket
import statistics
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import psutil
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import HOST, Server, cpu_seconds, running_server

TOPICS = ("/odom", "/scan", "/tf", "/tf_static", "/ground_truth", "/world", "/cmd_vel")
"""Every robot topic; each attacker subscribes to all of them."""

RCVBUF_BYTES = 4096
"""Attackers' kernel receive buffer (Linux doubles it), set before connect."""

BATCH = 50
"""Attackers opened at once ..."""

BATCH_PERIOD_S = 0.1
"""... every this often."""

SAMPLE_PERIOD_S = 0.5
"""Period of the /healthz, RSS and socket-table samples."""

DRAIN_S = 3.0
"""At the end, how long the attacker sockets are read to tell dropped from open ones."""

RSS_GROWTH_TARGET_MB = 50.0
"""Target: the server's peak RSS during the attack less its RSS before (MB)."""

DROP_TARGET_S = 15.0
"""Target: each attacker is dropped within this long after its send buffer filled (s)."""

HEALTHY_HZ_TARGET = 19.0
"""Target: the healthy client's /odom rate in every 1-second window (Hz, nominal 20)."""

FULL_SHARE = 0.9
"""A send queue at this share of the largest it ever got counts as full."""

ESTABLISHED = 1
"""TCP state code of an established connection in /proc/net/tcp."""


# ---- hand-made WebSocket client frames ----------------------------------------------------

def upgrade_request(port: int) -> bytes:
    """An HTTP/1.1 WebSocket upgrade request for ``ws://HOST:port/``."""
    key = base64.b64encode(os.urandom(16)).decode()
    return (f"GET / HTTP/1.1\r\nHost: {HOST}:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n").encode()


def text_frame(text: str) -> bytes:
    """One final, masked client text frame (RFC 6455 section 5.2) carrying ``text``."""
    payload = text.encode()
    size = len(payload)
    if size < 126:
        header = bytes([0x81, 0x80 | size])
    elif size < 1 << 16:
        header = bytes([0x81, 0x80 | 126]) + size.to_bytes(2, "big")
    else:
        header = bytes([0x81, 0x80 | 127]) + size.to_bytes(8, "big")
    mask = os.urandom(4)
    masked = bytes(byte ^ mask[index % 4] for index, byte in enumerate(payload))
    return header + mask + masked


SUBSCRIBES = b"".join(text_frame(json.dumps({"op": "subscribe", "topic": topic, "id": f"s{i}"}))
                      for i, topic in enumerate(TOPICS, start=1))
"""What every attacker sends after the handshake, and the last thing it sends."""


async def open_attacker(port: int) -> socket.socket:
    """Connect a small-buffered raw socket, upgrade it and subscribe; it is never read again."""
    loop = asyncio.get_running_loop()
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        sock.setblocking(False)
        await loop.sock_connect(sock, (HOST, port))
        await loop.sock_sendall(sock, upgrade_request(port))
        response = b""
        while b"\r\n\r\n" not in response:
            chunk = await loop.sock_recv(sock, 1024)
            if not chunk:
                raise ConnectionError("server closed during the handshake")
            response += chunk
        status = response.split(b"\r\n", 1)[0]
        if b" 101 " not in status:
            raise ConnectionError(f"handshake refused: {status.decode(errors='replace')}")
        await loop.sock_sendall(sock, SUBSCRIBES)
    except BaseException:
        sock.close()
        raise
    return sock


async def final_state(sock: socket.socket, deadline_s: float) -> str:
    """Read ``sock`` until EOF or RST ("eof", "reset") or ``deadline_s`` ("open")."""
    loop = asyncio.get_running_loop()
    try:
        while True:
            remaining = deadline_s - loop.time()
            if remaining <= 0:
                return "open"
            if not await asyncio.wait_for(loop.sock_recv(sock, 1 << 16), remaining):
                return "eof"
    except TimeoutError:
        return "open"
    except ConnectionResetError:
        return "reset"
    except OSError:
        return "error"


# ---- observation --------------------------------------------------------------------------

def tcp_table(port: int) -> dict[int, tuple[int, int]] | None:
    """Server-side loopback sockets of ``port``: {client port: (state, send queue bytes)}.

    None where /proc/net/tcp does not exist (not Linux).
    """
    table: dict[int, tuple[int, int]] = {}
    try:
        with open("/proc/net/tcp") as lines:
            next(lines)
            for line in lines:
                parts = line.split()
                if int(parts[1].rsplit(":", 1)[1], 16) != port:
                    continue
                tx_queue = int(parts[4].split(":")[0], 16)
                table[int(parts[2].rsplit(":", 1)[1], 16)] = (int(parts[3], 16), tx_queue)
    except OSError:
        return None
    return table


@dataclass
class Attacker:
    """One non-reading connection and what the socket table showed of it (s after start)."""

    sock: socket.socket
    port: int
    send_queue: list[tuple[float, int]] = field(default_factory=list)
    closed_s: float | None = None

    def full_s(self) -> float | None:
        """When the server's send queue to it first reached FULL_SHARE of its largest."""
        largest = max((queued for _, queued in self.send_queue), default=0)
        if largest == 0:
            return None
        return next(at for at, queued in self.send_queue if queued >= FULL_SHARE * largest)


class OdomCounter:
    """The healthy client: subscribes to /odom, reads normally, notes each receipt time."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.received_s: list[float] = []
        self.reconnects = 0

    async def run(self, until_s: float) -> None:
        """Read /odom until ``until_s`` (monotonic); reconnect if the server closes us."""
        while time.monotonic() < until_s:
            try:
                async with connect(self.url, compression=None, ping_interval=None,
                                   close_timeout=1, open_timeout=5, proxy=None) as websocket:
                    await websocket.send(json.dumps({"op": "subscribe", "topic": "/odom",
                                                     "id": "healthy"}))
                    while (remaining := until_s - time.monotonic()) > 0:
                        with contextlib.suppress(TimeoutError):
                            await asyncio.wait_for(websocket.recv(), remaining)
                            self.received_s.append(time.monotonic())
                    return
            except (OSError, ConnectionClosed, TimeoutError):
                self.reconnects += 1
                await asyncio.sleep(0.2)

    def rates(self, start_s: float, seconds: int) -> list[int]:
        """Messages received in each whole second from ``start_s`` (monotonic)."""
        counts = [0] * seconds
        for received in self.received_s:
            index = int(received - start_s)
            if received >= start_s and index < seconds:
                counts[index] += 1
        return counts


async def health(server: Server) -> dict[str, Any] | None:
    """/healthz, or None when it did not answer within 2 s."""
    try:
        return await asyncio.to_thread(server.health, 2.0)
    except (OSError, ValueError):
        return None


# ---- the run ------------------------------------------------------------------------------

async def attack(server: Server, n_clients: int, seconds: float) -> dict[str, Any]:
    """Run the healthy client and N attackers for ``seconds``; the figures as a dict."""
    process = psutil.Process(server.process.pid)
    healthy, reader = await start_healthy(server, seconds + DRAIN_S + 20.0)
    rss_start = process.memory_info().rss
    cpu_start = cpu_seconds(process)

    start_s = time.monotonic()
    end_s = start_s + seconds
    attackers: list[Attacker] = []
    failures: list[str] = []
    opened_s: list[float] = []

    async def opener() -> None:
        for first in range(0, n_clients, BATCH):
            batch = range(first, min(first + BATCH, n_clients))
            results = await asyncio.gather(
                *(asyncio.wait_for(open_attacker(server.ws_port), 10.0) for _ in batch),
                return_exceptions=True)
            for result in results:
                if isinstance(result, socket.socket):
                    attackers.append(Attacker(result, result.getsockname()[1]))
                else:
                    failures.append(f"{type(result).__name__}: {result}")
            await asyncio.sleep(BATCH_PERIOD_S)
        opened_s.append(time.monotonic() - start_s - BATCH_PERIOD_S)

    opening = asyncio.create_task(opener())
    rss_peak = rss_start
    samples: list[tuple[float, dict[str, Any] | None]] = []
    has_table = True
    while (now := time.monotonic()) < end_s:
        at = now - start_s
        with contextlib.suppress(psutil.Error):
            rss_peak = max(rss_peak, process.memory_info().rss)
        table = tcp_table(server.ws_port)
        has_table = table is not None
        for attacker in attackers if table is not None else ():
            state, queued = table.get(attacker.port, (0, 0))
            if attacker.closed_s is None:
                if state != ESTABLISHED:
                    attacker.closed_s = at
                else:
                    attacker.send_queue.append((at, queued))
        samples.append((at, await health(server)))
        if server.process.poll() is not None:
            break
        await asyncio.sleep(max(0.0, SAMPLE_PERIOD_S - (time.monotonic() - now)))
    await opening
    alive = server.process.poll() is None
    rss_end = process.memory_info().rss if alive else 0
    cpu_pct = 100.0 * (cpu_seconds(process) - cpu_start) / seconds if alive else float("nan")
    final_health = await health(server) if alive else None
    loop = asyncio.get_running_loop()
    states = await asyncio.gather(*(final_state(attacker.sock, loop.time() + DRAIN_S)
                                    for attacker in attackers))
    for attacker in attackers:
        attacker.sock.close()
    reader.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await reader

    rates = healthy.rates(start_s, int(seconds))
    closed = sorted(a.closed_s for a in attackers if a.closed_s is not None)
    fills = sorted(f for a in attackers if (f := a.full_s()) is not None)
    after_fill = [a.closed_s - full for a in attackers
                  if a.closed_s is not None and (full := a.full_s()) is not None]
    answered = [(at, sample) for at, sample in samples if sample is not None]
    peak_clients = max((sample["clients"] for _, sample in answered), default=0)
    back_to_one = next((at for at, sample in answered
                        if peak_clients > 1 and sample["clients"] <= 1
                        and opened_s and at > opened_s[0]), None)
    jitter = [float(sample["tick_jitter_p99_ms"]) for _, sample in answered]
    last = final_health or (answered[-1][1] if answered else {})
    log_text = server.log_path.read_text(errors="replace").splitlines()
    all_dropped = has_table and len(closed) == n_clients
    drop_ok = all_dropped and len(after_fill) == n_clients and max(after_fill) <= DROP_TARGET_S
    return {
        "clients": n_clients, "seconds": seconds, "opened": len(attackers),
        "open_failures": len(failures), "open_failure_example": failures[0] if failures else "",
        "opened_in_s": opened_s[0] if opened_s else None,
        "rss_start_mb": rss_start / 1e6, "rss_peak_mb": rss_peak / 1e6,
        "rss_end_mb": rss_end / 1e6, "rss_growth_mb": (rss_peak - rss_start) / 1e6,
        "rss_pass": (rss_peak - rss_start) / 1e6 < RSS_GROWTH_TARGET_MB,
        "socket_table": has_table,
        "send_buffer_full_median_s": statistics.median(fills) if fills else None,
        "send_buffer_full_last_s": fills[-1] if fills else None,
        "send_queue_max_bytes": max((q for a in attackers for _, q in a.send_queue), default=0),
        "dropped": len(closed),
        "dropped_first_s": closed[0] if closed else None,
        "dropped_median_s": statistics.median(closed) if closed else None,
        "dropped_last_s": closed[-1] if closed else None,
        "dropped_after_full_max_s": max(after_fill) if after_fill else None,
        "drop_pass": drop_ok,
        "healthz_peak_clients": peak_clients, "healthz_back_to_1_s": back_to_one,
        "healthz_timeouts": len(samples) - len(answered),
        "attacker_side": {state: states.count(state) for state in sorted(set(states))},
        "healthy_windows": len(rates), "healthy_min_hz": min(rates, default=0),
        "healthy_median_hz": statistics.median(rates) if rates else 0,
        "healthy_windows_below": sum(rate < HEALTHY_HZ_TARGET for rate in rates),
        "healthy_rates": rates, "healthy_reconnects": healthy.reconnects,
        "healthy_pass": bool(rates) and min(rates) >= HEALTHY_HZ_TARGET,
        "jitter_p99_ms": float(last.get("tick_jitter_p99_ms", float("nan"))),
        "jitter_p99_worst_sample_ms": max(jitter, default=float("nan")),
        "ticks_missed": int(last.get("ticks_due", 0)) - int(last.get("ticks", 0)),
        "tick_resyncs": int(last.get("tick_resyncs", 0)),
        "scans_shed": int(last.get("scans_shed", 0)),
        "server_alive": alive, "server_cpu_pct": cpu_pct,
        "server_errors": sum(" ERROR " in line or line.startswith("Traceback")
                             for line in log_text),
    }


def verdict(passed: bool) -> str:
    return "PASS" if passed else "FAIL"


def seconds_text(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f} s"


def report(row: dict[str, Any]) -> str:
    """The figures as text, a target's verdict next to it."""
    side = ", ".join(f"{count} {state}" for state, count in row["attacker_side"].items())
    drops = (f"{row['dropped']} of {row['clients']}; first {seconds_text(row['dropped_first_s'])}"
             f", median {seconds_text(row['dropped_median_s'])}"
             f", last {seconds_text(row['dropped_last_s'])}"
             if row["socket_table"] else "unknown (no /proc/net/tcp)")
    lines = [
        f"nonreaders: {row['clients']} attackers (SO_RCVBUF {RCVBUF_BYTES}, {len(TOPICS)} topics,"
        f" never read) for {row['seconds']:g} s; times are s after the first attacker connected",
        f"  opened: {row['opened']} in {seconds_text(row['opened_in_s'])}, "
        f"{row['open_failures']} failed {row['open_failure_example']}",
        f"  server RSS: start {row['rss_start_mb']:.1f} MB, peak {row['rss_peak_mb']:.1f} MB, "
        f"end {row['rss_end_mb']:.1f} MB; growth {row['rss_growth_mb']:+.1f} MB"
        f"   target < {RSS_GROWTH_TARGET_MB:g} MB: {verdict(row['rss_pass'])}",
        f"  server send queue to attackers full: median "
        f"{seconds_text(row['send_buffer_full_median_s'])}, last "
        f"{seconds_text(row['send_buffer_full_last_s'])} "
        f"(largest {row['send_queue_max_bytes'] / 1e3:.0f} kB)",
        f"  dropped by the server: {drops}; at most "
        f"{seconds_text(row['dropped_after_full_max_s'])} after its send queue filled"
        f"   target all within {DROP_TARGET_S:g} s: {verdict(row['drop_pass'])}",
        f"  /healthz clients: peak {row['healthz_peak_clients']}, back to 1 at "
        f"{seconds_text(row['healthz_back_to_1_s'])}; attacker side at the end: {side}",
        f"  healthy /odom: min {row['healthy_min_hz']} Hz, median {row['healthy_median_hz']:g} Hz"
        f" over {row['healthy_windows']} windows, {row['healthy_windows_below']} below"
        f" {HEALTHY_HZ_TARGET:g} Hz, {row['healthy_reconnects']} reconnects"
        f"   target >= {HEALTHY_HZ_TARGET:g} Hz every window: {verdict(row['healthy_pass'])}",
        f"  per-second /odom: {' '.join(str(rate) for rate in row['healthy_rates'])}",
        f"  tick jitter p99 (/healthz): {row['jitter_p99_ms']:.2f} ms at the end, worst sample "
        f"{row['jitter_p99_worst_sample_ms']:.2f} ms; ticks missed {row['ticks_missed']}, "
        f"resyncs {row['tick_resyncs']}, scans shed {row['scans_shed']}, "
        f"/healthz timeouts {row['healthz_timeouts']}",
        f"  server: {'alive' if row['server_alive'] else 'EXITED'}, CPU "
        f"{row['server_cpu_pct']:.0f} % of one core, {row['server_errors']} ERROR lines in log",
    ]
    return "\n".join(lines)


def raise_fd_limit(needed: int) -> None:
    """Raise this process's (and so the server's) open-file soft limit to the hard limit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != resource.RLIM_INFINITY and soft < needed:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
        if hard != resource.RLIM_INFINITY and hard < needed:
            print(f"warning: open-file limit {hard} < {needed}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run once; print the figures; 0 even when a target fails (it measures, not asserts)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=300, help="attackers (default 300)")
    parser.add_argument("--seconds", type=float, default=60.0,
                        help="run length after the first attacker connects (default 60 s)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    if args.clients < 1 or args.seconds < 2:
        parser.error("--clients at least 1, --seconds at least 2")
    raise_fd_limit(2 * args.clients + 100)
    row = run_against_server(lambda server: attack(server, args.clients, args.seconds),
                             args.seconds + 60.0)
    print(json.dumps(row) if args.json else report(row), flush=True)
    return 0


async def start_healthy(server: Server,
                        run_s: float) -> tuple[OdomCounter, asyncio.Task[None]]:
    """A healthy /odom listener for ``run_s``, once it has received for a second."""
    healthy = OdomCounter(server.ws_url)
    reader = asyncio.create_task(healthy.run(time.monotonic() + run_s))
    deadline = time.monotonic() + 10.0
    while not healthy.received_s:
        if time.monotonic() > deadline:
            raise RuntimeError("the healthy client received no /odom within 10 s")
        await asyncio.sleep(0.05)
    await asyncio.sleep(1.0)
    return healthy, reader


def run_against_server(attack_on: Callable[[Any], Awaitable[dict[str, Any]]],
                       timeout_s: float) -> dict[str, Any]:
    """Start a server, run ``attack_on(server)`` within ``timeout_s``; its figures.

    The server's last log lines are printed when the attack fails or the server died.
    """
    with tempfile.TemporaryDirectory() as log_dir, running_server(Path(log_dir)) as server:
        try:
            row = asyncio.run(asyncio.wait_for(attack_on(server), timeout_s))
        except Exception:
            print(f"websim serve output (last lines):\n{server.log_tail()}", file=sys.stderr)
            raise
        if not row["server_alive"]:
            print(f"websim serve exited; last lines:\n{server.log_tail()}", file=sys.stderr)
    return row


if __name__ == "__main__":
    sys.exit(main())
