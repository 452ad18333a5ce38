"""HTTP load: a class loading the page at once, and a browser next to a thousand stalled sockets.

Starts real ``websim serve`` processes and prints:

* **class**: ``--browsers`` (40) page loads started at the same instant. Each is a browser:
  it fetches ``/``, then everything the page and its modules reference (styles, scripts, the
  libraries, ES module imports), and what the scripts fetch (config.json, robot.json), wave
  after wave as a browser discovers them, over at most 6 connections (Chrome's per-host
  limit), gzip accepted. Per-load wall time p50 and max; target: each < 1 s.
  Also the server's tick jitter p99 since it started (/healthz): the pages are served on the
  loop that runs the simulation.
* **stalled**: a server limited to 1024 file descriptors (soft and hard). ``--repeats``
  sequential page loads (each a new browser, so new connections) without, then with
  ``--stalled`` (1000) connections that sent half a request line and wait; p50 and max of
  each, and how much slower the p50 is (target: at most 100 ms). Also how many of the
  stalled connections the server still holds (its cap, a quarter of its file limit; it
  evicted the rest to make room). The stalled sockets are measured within the server's idle
  timeout, after which it closes them all anyway.

The browsers all run in this one process (asyncio, aiohttp's client), so on a small machine
their own CPU time is part of the figures. It asserts nothing. Run it from the checkout::

    python benchmarks/http_load.py
    python benchmarks/http_load.py --browsers 40 --repeats 20 --json
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import re
import resource
import select
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urljoin, urlsplit

import aiohttp

PROJECT_DIR = Path(__file__).resolve().parent.parent
HOST = "127.0.0.1"

CONNECTIONS_PER_BROWSER = 6
"""Chrome's and Firefox's limit of parallel HTTP/1.1 connections to one host."""

FETCHED_BY_SCRIPTS = ("config.json", "robot.json")
"""What the pages' modules fetch(); the crawl does not find these names."""

REFERENCE = re.compile(
    r"""(?:src|href)="([^"#?]+)"|(?:from|import)\s*\(?\s*['"](\.{1,2}/[^'"]+)['"]""")
"""What a page or module loads: src/href attributes, ES module imports (static and dynamic)."""

LOAD_TARGET_S = 1.0
STALLED_SLOWDOWN_TARGET_S = 0.1
SERVER_OPEN_FILES = 1024
START_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 10.0


@dataclass
class Server:
    """A running ``websim serve``."""

    process: subprocess.Popen[bytes]
    http_port: int

    @property
    def url(self) -> str:
        """The page's URL."""
        return f"http://{HOST}:{self.http_port}/"

    def health(self) -> dict[str, Any]:
        """The server's /healthz report."""
        with urllib.request.urlopen(f"{self.url}healthz", timeout=5) as response:
            return dict(json.load(response))


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind((HOST, 0))
        return int(probe.getsockname()[1])


def _limit_open_files(limit: int) -> None:
    resource.setrlimit(resource.RLIMIT_NOFILE, (limit, limit))


@contextlib.contextmanager
def running_server(log_dir: Path, open_files: int | None = None) -> Iterator[Server]:
    """``websim serve`` on free ports (``open_files``: its file limit), healthy; stopped after."""
    http_port = free_port()
    command = [sys.executable, "-m", "websim.cli", "serve", "--host", HOST,
               "--ws-port", str(free_port()), "--http-port", str(http_port)]
    env = {**os.environ, "PYTHONUNBUFFERED": "1",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(PROJECT_DIR),
                                                       os.environ.get("PYTHONPATH")]))}
    log_path = log_dir / f"websim-serve-{http_port}.log"
    with log_path.open("wb") as log:
        process = subprocess.Popen(
            command, stdout=log, stderr=subprocess.STDOUT, cwd=PROJECT_DIR, env=env,
            preexec_fn=None if open_files is None else lambda: _limit_open_files(open_files))
    server = Server(process, http_port)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            if process.poll() is not None:
                raise RuntimeError(f"websim serve exited:\n{log_path.read_text()}")
            try:
                if server.health()["status"] == "ok":
                    break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError("websim serve did not become healthy")
            time.sleep(0.05)
        yield server
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


async def discover(url: str) -> list[list[str]]:
    """What a browser fetches to load the page at ``url``, in waves.

    The page; what it references and what its scripts fetch; what those modules import; and
    so on.
    """
    waves: list[list[str]] = []
    seen = {url}
    wave = [url]
    async with aiohttp.ClientSession() as session:
        async def references(target: str) -> list[str]:
            async with session.get(target) as response:
                if response.status != 200:
                    raise RuntimeError(f"{target}: HTTP {response.status}")
                body = await response.text()
                kind = response.headers.get("Content-Type", "")
            if not kind.startswith(("text/html", "text/javascript")):
                return []
            found = []
            for groups in REFERENCE.findall(body):
                link = urlsplit(urljoin(target, next(filter(None, groups))))
                if link.netloc == urlsplit(url).netloc:
                    found.append(link._replace(query="", fragment="").geturl())
            return found

        while wave:
            waves.append(wave)
            results = await asyncio.gather(*(references(target) for target in wave))
            if len(waves) == 1:  # the page's scripts fetch these once they run
                results.append([urljoin(url, name) for name in FETCHED_BY_SCRIPTS])
            wave = sorted({link for links in results for link in links} - seen)
            seen.update(wave)
    return waves


async def load_page(waves: list[list[str]]) -> tuple[float, int]:
    """One browser loading a page: (wall time in s, bytes received).

    A fresh browser (new connections, empty cache): each wave's files in parallel over at
    most 6 connections, gzip accepted but not inflated (that is the student's CPU, not the
    server's).
    """
    started = time.perf_counter()
    received = 0
    connector = aiohttp.TCPConnector(limit_per_host=CONNECTIONS_PER_BROWSER)
    async with aiohttp.ClientSession(connector=connector, auto_decompress=False,
                                     headers={"Accept-Encoding": "gzip, deflate"}) as session:
        async def fetch(target: str) -> None:
            nonlocal received
            async with session.get(target) as response:
                received += len(await response.read())
                if response.status != 200:
                    raise RuntimeError(f"{target}: HTTP {response.status}")

        for wave in waves:
            await asyncio.gather(*(fetch(target) for target in wave))
    return time.perf_counter() - started, received


async def class_loads(waves: list[list[str]], browsers: int) -> list[tuple[float, int]]:
    """``browsers`` page loads started together."""
    return list(await asyncio.gather(*(load_page(waves) for _ in range(browsers))))


def sequential_loads(waves: list[list[str]], repeats: int) -> list[float]:
    return [asyncio.run(load_page(waves))[0] for _ in range(repeats)]


def open_stalled(port: int, count: int) -> list[socket.socket]:
    """``count`` connections that send half a request line and then wait."""
    stalled = []
    for _ in range(count):
        sock = socket.create_connection((HOST, port), timeout=10)
        sock.sendall(b"GET /index.ht")
        stalled.append(sock)
    return stalled


def still_open(sockets: list[socket.socket]) -> int:
    """How many of ``sockets`` the server has not closed (none of them is sent anything)."""
    poller = select.poll()  # not select(): these descriptors go beyond FD_SETSIZE
    for sock in sockets:
        poller.register(sock, select.POLLIN)
    return len(sockets) - len(poller.poll(0))


def raise_own_file_limit(needed: int) -> None:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < needed:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))


def summary(times_s: list[float]) -> dict[str, float]:
    return {"p50_ms": round(statistics.median(times_s) * 1e3, 1),
            "max_ms": round(max(times_s) * 1e3, 1)}


def run(args: argparse.Namespace) -> dict[str, Any]:
    raise_own_file_limit(args.stalled + 256)
    results: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as log_dir:
        with running_server(Path(log_dir)) as server:
            waves = asyncio.run(discover(server.url))  # also warms the server's file cache
            loads = asyncio.run(class_loads(waves, args.browsers))
            times = [wall for wall, _ in loads]
            health = server.health()
            results["class"] = {"browsers": args.browsers, **summary(times),
                                "tick_jitter_p99_ms": health.get("tick_jitter_p99_ms"),
                                "ticks_missed": health["ticks_due"] - health["ticks"],
                                "files_per_load": sum(map(len, waves)),
                                "kB_per_load": round(loads[0][1] / 1e3, 1),
                                "target_ms": LOAD_TARGET_S * 1e3,
                                "met": max(times) < LOAD_TARGET_S}
        with running_server(Path(log_dir), open_files=SERVER_OPEN_FILES) as server:
            waves = asyncio.run(discover(server.url))
            quiet = sequential_loads(waves, args.repeats)
            opened = time.monotonic()
            stalled = open_stalled(server.http_port, args.stalled)
            busy = sequential_loads(waves, args.repeats)
            measured_s = time.monotonic() - opened
            held = still_open(stalled)
            for sock in stalled:
                sock.close()
            slowdown_s = statistics.median(busy) - statistics.median(quiet)
            results["stalled"] = {
                "server_open_files": SERVER_OPEN_FILES, "stalled": args.stalled,
                "held_by_server": held, "repeats": args.repeats,
                "without": summary(quiet), "with": summary(busy),
                "p50_slowdown_ms": round(slowdown_s * 1e3, 1),
                "seconds_from_opening_to_last_load": round(measured_s, 2),
                "target_ms": STALLED_SLOWDOWN_TARGET_S * 1e3,
                "met": slowdown_s <= STALLED_SLOWDOWN_TARGET_S}
    return results


def print_table(results: dict[str, Any]) -> None:
    crowd = results["class"]
    print(f"class: {crowd['browsers']} simultaneous page loads "
          f"({crowd['files_per_load']} files, {crowd['kB_per_load']} kB on the wire each)")
    print(f"  wall time p50 {crowd['p50_ms']} ms, max {crowd['max_ms']} ms "
          f"(target each < {crowd['target_ms']:.0f} ms: {'met' if crowd['met'] else 'MISSED'})")
    print(f"  the simulation meanwhile (same event loop): tick jitter p99 "
          f"{crowd['tick_jitter_p99_ms']} ms since start, {crowd['ticks_missed']} ticks behind")
    stalled = results["stalled"]
    print(f"stalled: server limited to {stalled['server_open_files']} files, "
          f"{stalled['repeats']} sequential page loads each")
    print(f"  without stalled connections: p50 {stalled['without']['p50_ms']} ms, "
          f"max {stalled['without']['max_ms']} ms")
    print(f"  with {stalled['stalled']} half-open connections: p50 "
          f"{stalled['with']['p50_ms']} ms, max {stalled['with']['max_ms']} ms "
          f"(server held {stalled['held_by_server']}, closed the rest)")
    print(f"  p50 slower by {stalled['p50_slowdown_ms']} ms (target <= "
          f"{stalled['target_ms']:.0f} ms: {'met' if stalled['met'] else 'MISSED'})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--browsers", type=int, default=40,
                        help="simultaneous page loads (default 40)")
    parser.add_argument("--stalled", type=int, default=1000,
                        help="half-open connections next to the measured loads (default 1000)")
    parser.add_argument("--repeats", type=int, default=20,
                        help="sequential page loads per stalled-phase figure (default 20)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    results = run(args)
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        print_table(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
