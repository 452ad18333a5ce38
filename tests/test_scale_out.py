"""A class spread over two worker processes behind the real nginx, routed by robot name.

``websim nginx-config`` writes the configuration; the real nginx binary runs it in front of
two ``websim serve --class ROSTER --worker`` processes on loopback. Every robot of a
20-student roster is reachable through nginx at its URL, lives on exactly one worker, and
the same name always lands on the same worker; the pages come through nginx too and name
nginx's port as their bridge.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import subprocess
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import websockets

from websim.nginx_config import Worker, nginx_config

from server_process import ServerProcess, free_port, start_server, wait_for

NGINX = shutil.which("nginx") or ("/usr/sbin/nginx" if Path("/usr/sbin/nginx").exists()
                                  else None)
pytestmark = pytest.mark.skipif(NGINX is None, reason="nginx not installed")

NAMES = [f"student{index:02d}" for index in range(1, 21)]


@dataclass
class Proxy:
    http_port: int
    ws_port: int
    workers: list[ServerProcess]


@pytest.fixture(scope="module")
def proxy(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Proxy]:
    directory = tmp_path_factory.mktemp("scale")
    roster = directory / "roster.txt"
    roster.write_text("\n".join(NAMES) + "\n")
    http_port, ws_port = free_port(), free_port()
    workers = [start_server(["--class", str(roster), "--worker", "--public-ws-port",
                             str(ws_port)]) for _ in range(2)]
    conf = nginx_config([Worker("127.0.0.1", w.http_port, w.ws_port) for w in workers],
                        f"127.0.0.1:{http_port}", f"127.0.0.1:{ws_port}")
    temp = "".join(f"    {kind}_temp_path {directory / kind};\n"
                   for kind in ("client_body", "proxy", "fastcgi", "uwsgi", "scgi"))
    conf = conf.replace("http {\n", "http {\n" + temp, 1).replace(
        "worker_processes auto;", f"worker_processes 1;\nerror_log {directory}/error.log;")
    path = directory / "nginx.conf"
    path.write_text(conf)
    directives = f"daemon off; pid {directory / 'nginx.pid'};"
    if os.geteuid() == 0:
        directives += " user root;"
    process = subprocess.Popen([str(NGINX), "-p", str(directory), "-c", str(path), "-g",
                                directives], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)

    def answers() -> bool:
        if process.poll() is not None:
            raise AssertionError((directory / "error.log").read_text())
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{http_port}/healthz", timeout=2):
                return True
        except OSError:
            return False

    try:
        wait_for(answers, 10.0, "nginx to answer")
        yield Proxy(http_port, ws_port, workers)
    finally:
        process.terminate()
        process.wait(timeout=10)
        for worker in workers:
            worker.stop()


async def odom_through(proxy: Proxy, name: str) -> str:
    """One /odom of robot ``name`` through nginx; its frame."""
    async with websockets.connect(f"ws://127.0.0.1:{proxy.ws_port}/robots/{name}") as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
        while True:
            message = json.loads(await asyncio.wait_for(ws.recv(), 5))
            if message.get("topic") == "/odom":
                return str(message["msg"]["header"]["frame_id"])


def hosted(proxy: Proxy) -> list[set[str]]:
    return [set(worker.health()["robots"]) for worker in proxy.workers]


def test_every_robot_is_reachable_through_nginx_on_exactly_one_worker(proxy: Proxy) -> None:
    async def visit_all() -> list[str]:
        return [await odom_through(proxy, name) for name in NAMES]

    assert asyncio.run(visit_all()) == ["odom"] * len(NAMES)
    first, second = hosted(proxy)
    assert first | second == set(NAMES)
    assert not first & second, "a robot lives on one worker only"
    assert first and second, "consistent hashing spread the class over both workers"
    asyncio.run(visit_all())  # again: the same names land on the same workers
    assert hosted(proxy) == [first, second]


def test_a_robots_page_through_nginx_names_nginx_as_its_bridge(proxy: Proxy) -> None:
    base = f"http://127.0.0.1:{proxy.http_port}/robots/student07/"
    with urllib.request.urlopen(base, timeout=5) as response:
        assert response.status == 200
    with urllib.request.urlopen(base + "config.json", timeout=5) as response:
        config = json.load(response)
    assert config["ws"] == f"ws://127.0.0.1:{proxy.ws_port}/robots/student07"
    with urllib.request.urlopen(base + "robot.json", timeout=5) as response:
        assert json.load(response)["topics"]["odom"]["name"] == "/odom"
