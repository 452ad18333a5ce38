"""Start a real ``websim serve`` process on free ports and wait until it answers /healthz."""

from __future__ import annotations

import contextlib
import csv
import functools
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ADMIN_TOKEN = "Test-admin-token-2026-suite"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_for(condition: Callable[[], Any], timeout_s: float = 10.0, what: str = "condition",
             interval_s: float = 0.02, pause: Callable[[], Any] | None = None) -> Any:
    """Poll ``condition`` until it returns something truthy; fail after ``timeout_s``.

    Between polls it sleeps ``interval_s``, or calls ``pause`` (spinning an executor, say).
    """
    deadline = time.monotonic() + timeout_s
    while True:
        result = condition()
        if result:
            return result
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        if pause is None:
            time.sleep(interval_s)
        else:
            pause()


@dataclass
class ServerProcess:
    """A running ``websim serve``; ``stop()`` sends SIGTERM and waits."""

    ws_port: int
    http_port: int
    process: subprocess.Popen[str]
    output: list[str] = field(default_factory=list)

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.ws_port}/"

    @property
    def admin_ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.ws_port}/?token={ADMIN_TOKEN}"

    @property
    def http_url(self) -> str:
        return f"http://127.0.0.1:{self.http_port}"

    def health(self) -> dict[str, Any]:
        """The full /healthz (with the instructor's token: robots by name, addresses)."""
        with urllib.request.urlopen(f"{self.http_url}/healthz?token={ADMIN_TOKEN}",
                                    timeout=2) as response:
            return dict(json.load(response))

    def stop(self, timeout_s: float = 10.0) -> int:
        """SIGTERM, as Docker and systemd send it; returns the exit code."""
        return stop_process(self.process, self.output, signal.SIGTERM, timeout_s)


STARTED_BY_TESTS: list[ServerProcess] = []
"""Servers a test's body started (not a fixture's): ``stop_leftovers`` ends those still running
after their test, so a test that fails before its ``stop()`` leaves no server behind (one at
``--speed max --record`` once ran on for half an hour, two cores busy, under the next tests)."""


def stop_leftovers() -> int:
    """Stop every server a test's body started and left running; how many there were."""
    left = [server for server in STARTED_BY_TESTS if server.process.poll() is None]
    STARTED_BY_TESTS.clear()
    for server in left:
        stop_process(server.process, server.output, signal.SIGKILL, timeout_s=5.0)
    return len(left)


def stop_process(process: subprocess.Popen[str], output: list[str], signum: int,
                 timeout_s: float = 10.0) -> int:
    """Send ``signum``, wait up to ``timeout_s`` (then kill), keep the output; exit code."""
    if process.poll() is None:
        process.send_signal(signum)
    try:
        out, _ = process.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    output.append(out or "")
    return process.returncode


def limit_open_files(limit: int) -> None:
    """Set this process's RLIMIT_NOFILE, soft and hard, to ``limit`` (a Popen preexec_fn)."""
    import resource

    resource.setrlimit(resource.RLIMIT_NOFILE, (limit, limit))


ARENA_BOX = """\
name: arena
start: [0.0, -2.0, 0.0]
polylines:
  - points: [[-3, -3], [3, -3], [3, 3], [-3, 3]]
    closed: true
"""
"""The arena tests' world: a closed 6 x 6 m box, its start off the centre line."""


def start_arena(folder: Path, robots: str, names: Sequence[str],
                extra_args: Sequence[str] = ()) -> tuple[ServerProcess, list[dict[str, str]]]:
    """``websim serve --class ROSTER --arena --world WORLD`` in ``folder``, and its links.

    The world is ``ARENA_BOX`` with ``robots`` (its ``robots:`` section, YAML text);
    ``names``: the roster. Returns the server (healthy) and the rows of its links file
    (name, token, page...).
    """
    (folder / "arena.yaml").write_text(ARENA_BOX + robots)
    (folder / "roster.txt").write_text("".join(f"{name}\n" for name in names))
    links = folder / "links.csv"
    server = start_server(["--class", str(folder / "roster.txt"), "--arena", "--world",
                           str(folder / "arena.yaml"), "--links", str(links), *extra_args])
    with links.open(newline="") as file:
        return server, list(csv.DictReader(file))


def start_server(extra_args: Sequence[str] = (), ws_port: int | None = None,
                 http_port: int | None = None, open_files: int | None = None,
                 launcher: Sequence[str] = (sys.executable, "-m", "websim.cli"),
                 cwd: str | None = None,
                 admin_token: str | None = ADMIN_TOKEN) -> ServerProcess:
    """Launch ``websim serve`` (``launcher``: ``python -m websim.cli``) and wait until healthy.

    ``open_files`` limits the server process to that many file descriptors (soft and hard);
    ``cwd``: the folder it runs in (default this one); ``admin_token``: its
    ``--admin-token`` (None: none given).
    """
    ws_port = ws_port or free_port()
    http_port = http_port or free_port()
    command = [*launcher, "serve", "--ws-port", str(ws_port), "--http-port", str(http_port),
               *(("--admin-token", admin_token) if admin_token else ()), *extra_args]
    preexec = None if open_files is None else functools.partial(limit_open_files, open_files)
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, env={**os.environ, "PYTHONUNBUFFERED": "1",
                                               # a class's default state file: the server's own
                                               "XDG_DATA_HOME": tempfile.mkdtemp(
                                                   prefix="websim-data-")},
                               preexec_fn=preexec, cwd=cwd)
    server = ServerProcess(ws_port, http_port, process)
    if os.environ.get("PYTEST_CURRENT_TEST", "").endswith("(call)"):  # a test's own server
        STARTED_BY_TESTS.append(server)

    def healthy() -> bool:
        if process.poll() is not None:
            out, _ = process.communicate()
            raise AssertionError(f"websim serve exited with {process.returncode}:\n{out}")
        try:
            return server.health()["status"] == "ok"
        except OSError:
            return False

    wait_for(healthy, timeout_s=20.0, what="websim serve to become healthy")
    return server


@contextlib.contextmanager
def roslibpy_client(server: ServerProcess) -> Iterator[Any]:
    """A roslibpy client connected to ``server``, closed (never terminated) at the end."""
    import roslibpy

    client = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
    client.run(timeout=10)
    try:
        yield client
    finally:
        client.close()
