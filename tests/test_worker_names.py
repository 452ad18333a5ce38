"""Behind nginx, a worker makes only its own robots (issue 20, section 8).

Two ``websim serve --class ROSTER --worker --worker-index K --workers ...`` behind the real
nginx of ``websim nginx-config``: every name nginx routes to a worker is one the worker
computes as its own (``nginx_config.worker_for``, nginx's consistent hash), a name sent to
the other worker directly is refused there (404) and made nowhere, and
``/workers/K/robots/NAME`` (the decoy route) is refused by nginx itself.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass

import pytest
from deployment import NGINX, running_nginx
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from classroom.nginx_config import (
    Worker,
    worker_for,
    worker_ring,
)

from server_process import ServerProcess, free_port, start_server

pytestmark = pytest.mark.skipif(NGINX is None, reason="nginx not installed")

NAMES = [f"student{index:02d}" for index in range(1, 17)]


@dataclass
class Proxy:
    ws_port: int
    workers: list[ServerProcess]
    specs: list[Worker]


@pytest.fixture(scope="module")
def proxy(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Proxy]:
    directory = tmp_path_factory.mktemp("names")
    roster = directory / "roster.txt"
    roster.write_text("\n".join(NAMES) + "\n")
    specs = [Worker("127.0.0.1", free_port(), free_port()) for _ in range(2)]
    listed = [f"{w.host}:{w.http_port}:{w.ws_port}" for w in specs]
    http_port, ws_port = free_port(), free_port()
    workers = [start_server(["--class", str(roster), "--worker", "--worker-index", str(k),
                             "--workers", *listed, "--trusted-proxy", "127.0.0.1",
                             "--public-ws-port", str(ws_port)],
                            ws_port=spec.ws_port, http_port=spec.http_port)
               for k, spec in enumerate(specs)]
    try:
        with running_nginx(directory, specs, http_port, ws_port):
            yield Proxy(ws_port, workers, specs)
    finally:
        for worker in workers:
            worker.stop()


def subscribe_once(url: str) -> None:
    with connect(url, open_timeout=5) as ws:
        ws.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
        while json.loads(ws.recv(timeout=5)).get("topic") != "/odom":
            pass


def test_nginx_routes_every_name_to_the_worker_that_computes_it_as_its_own(
        proxy: Proxy) -> None:
    for name in NAMES:
        subscribe_once(f"ws://127.0.0.1:{proxy.ws_port}/robots/{name}")
    hosted = [set(worker.health()["robots"]) for worker in proxy.workers]
    ring = worker_ring(proxy.specs)
    expected = [{name for name in NAMES if worker_for(name, ring) == k} for k in (0, 1)]
    assert hosted == expected
    assert expected[0] and expected[1]


def test_a_worker_refuses_a_name_that_is_not_its_own(proxy: Proxy) -> None:
    ring = worker_ring(proxy.specs)
    name = next(name for name in NAMES if worker_for(name, ring) == 1)
    with pytest.raises(InvalidStatus) as refused:
        connect(f"ws://127.0.0.1:{proxy.specs[0].ws_port}/robots/{name}", open_timeout=5)
    assert refused.value.response.status_code == 404
    assert b"not this worker's" in refused.value.response.body
    assert name not in proxy.workers[0].health()["robots"]


def test_the_decoy_route_under_workers_k_is_refused_by_nginx(proxy: Proxy) -> None:
    ring = worker_ring(proxy.specs)
    name = next(name for name in NAMES if worker_for(name, ring) == 1)
    with pytest.raises(InvalidStatus) as refused:
        connect(f"ws://127.0.0.1:{proxy.ws_port}/workers/0/robots/{name}", open_timeout=5)
    assert refused.value.response.status_code == 404
    assert name not in proxy.workers[0].health()["robots"]
