"""``websim nginx-config``: nginx in front of several class workers, routing by robot name.

A class too big for one process runs as ``websim serve --class ROSTER --worker`` processes
(on one host or several); nginx routes ``/robots/NAME`` to one of them with
``hash $robot consistent``, so the same name always lands on the same worker, and a worker
added or removed moves only its share of the names. The WebSocket decides where a robot
lives; the pages are the same on every worker, so their upstream may pick another one.

The instructor's dashboard needs every worker's root view (``ws://HOST:PORT/?token=...``,
each worker's own robots under ``/NAME/``), which no hash can route to: nginx exposes worker
K's root at ``/workers/K/`` on the WebSocket port, and lists those paths in ``/workers.json``
on the page port, so the dashboard (``/class``) opens one root connection per worker and
shows the robots of all of them in one grid.
"""

from __future__ import annotations

import argparse
import bisect
import json
import os
import sys
import zlib
from dataclasses import dataclass
from pathlib import Path

from classroom.registry import ROBOT_NAME
from physics import ConfigError
from ros_nodes.robot_interface import ROBOTS_PREFIX

ROBOT_MAP = f'''    map $uri $robot {{
        "~^{ROBOTS_PREFIX}(?<name>{ROBOT_NAME.pattern})(/|$)" $name;
        default "";
    }}'''


@dataclass(frozen=True)
class Worker:
    """One worker process: where its pages and its WebSocket listen."""

    host: str
    http_port: int
    ws_port: int


def parse_worker(text: str) -> Worker:
    """``HOST:HTTP_PORT:WS_PORT`` (e.g. ``10.0.0.2:8081:9091``).

    Raises:
        ConfigError: not of that form, or a port out of range.
    """
    host, _, ports = text.rpartition(":")
    host, _, http = host.rpartition(":")
    try:
        http_port, ws_port = int(http), int(ports)
    except ValueError:
        raise ConfigError(f"--workers: expected HOST:HTTP_PORT:WS_PORT, got '{text}'") from None
    if not host or not all(0 < port < 65536 for port in (http_port, ws_port)):
        raise ConfigError(f"--workers: expected HOST:HTTP_PORT:WS_PORT, got '{text}'")
    return Worker(host, http_port, ws_port)


CHASH_POINTS_PER_SERVER = 160
"""nginx's ``hash ... consistent`` (ketama): points per server of weight 1 on its ring."""


def chash_ring(servers: list[str]) -> list[tuple[int, int]]:
    """The consistent-hash ring nginx makes of ``servers`` (``HOST:PORT``, as in its upstream).

    As ``ngx_http_upstream_init_chash``: for each server ``CHASH_POINTS_PER_SERVER`` points,
    the CRC-32 of HOST, a zero byte, PORT and the previous point (4 bytes little-endian, 0
    first), sorted, equal hashes kept once. Returns (hash, server index) pairs.
    """
    points: list[tuple[int, int]] = []
    for index, server in enumerate(servers):
        host, _, port = server.rpartition(":")
        base = host.encode() + b"\0" + port.encode()
        previous = 0
        for _ in range(CHASH_POINTS_PER_SERVER):
            previous = zlib.crc32(base + previous.to_bytes(4, "little"))
            points.append((previous, index))
    points.sort(key=lambda point: point[0])
    ring: list[tuple[int, int]] = []
    for point in points:
        if not ring or ring[-1][0] != point[0]:
            ring.append(point)
    return ring


def worker_ring(workers: list[Worker]) -> list[tuple[int, int]]:
    """The ring of the workers' WebSocket upstream (``chash_ring``)."""
    return chash_ring([f"{worker.host}:{worker.ws_port}" for worker in workers])


def worker_for(name: str, ring: list[tuple[int, int]]) -> int:
    """The index of the worker ``websim nginx-config``'s nginx routes robot ``name`` to.

    ``hash $robot consistent`` on the workers' ``ring`` (``worker_ring``): the first point at
    or after ``crc32(name)``, wrapping (``ngx_http_upstream_find_chash_point``), while every
    worker is up (nginx moves a down worker's names to the next point).
    """
    key = zlib.crc32(name.encode())
    position = bisect.bisect_left(ring, key, key=lambda point: point[0])
    return ring[position % len(ring)][1]


def worker_path(index: int) -> str:
    """``/workers/K/``: where worker K (0-based, in ``--workers`` order) has its root view.

    On nginx's WebSocket port; the worker itself has it at ``/``.
    """
    return f"/workers/{index}/"


def workers_json(workers: list[Worker]) -> str:
    """``/workers.json``: ``{"workers": ["/workers/0/", ...]}``, each worker's root path.

    Paths, never URLs: the dashboard joins them to its own server's WebSocket address, so the
    instructor's token goes nowhere else whatever this document says.
    """
    return json.dumps({"workers": [worker_path(index) for index in range(len(workers))]})


CLIENT_HEADERS = """            proxy_set_header X-Real-IP $remote_addr;
            proxy_set_header X-Forwarded-For $proxy_add_x_forwarded_for;
"""
"""Who the client is: a worker started with ``--trusted-proxy`` (nginx's address) gives each
student their own per-address budgets, not all of them nginx's."""


def _websocket_location(path: str, upstream: str, exact: bool = False) -> str:
    """A ``location`` proxying WebSockets at ``path`` to ``upstream``.

    ``exact``: that path only, nothing under it. With the upgrade headers, the client's
    address, and timeouts long enough for a page idle through a lesson.
    """
    match = "= " if exact else ""
    return f"""        location {match}{path} {{
            proxy_pass {upstream};
            proxy_http_version 1.1;
            proxy_set_header Upgrade $http_upgrade;
            proxy_set_header Connection $connection_upgrade;
            proxy_set_header Host $http_host;
{CLIENT_HEADERS}            proxy_read_timeout 1h;
            proxy_send_timeout 1h;
        }}
"""


def _worker_roots(workers: list[Worker]) -> str:
    """One ``location = /workers/K/`` per worker, proxied to that worker's WebSocket root.

    That path only: ``/workers/K/robots/NAME`` is no way to reach a robot on a worker its
    name does not hash to (a decoy of a classmate's robot). The query (``?token=``) is
    passed on, so the instructor's dashboard reaches every worker's robots.
    """
    return "".join(_websocket_location(worker_path(index),
                                       f"http://{worker.host}:{worker.ws_port}/", exact=True)
                   for index, worker in enumerate(workers))


def nginx_config(workers: list[Worker], http_listen: str, ws_listen: str) -> str:
    """A complete ``nginx.conf``: pages on ``http_listen``, WebSockets on ``ws_listen``.

    ``/robots/NAME`` goes to the worker NAME hashes to; ``/workers/K/`` (WebSocket) to worker
    K's root view, listed by ``/workers.json`` (page port); anything else on the WebSocket
    port is answered 404 with the ``/robots/NAME`` form.

    Raises:
        ConfigError: no worker named.
    """
    if not workers:
        raise ConfigError("--workers: name at least one worker")
    pages = "\n".join(f"        server {w.host}:{w.http_port};" for w in workers)
    sockets = "\n".join(f"        server {w.host}:{w.ws_port};" for w in workers)
    http_port, ws_port = http_listen.rpartition(":")[2], ws_listen.rpartition(":")[2]
    robots = _websocket_location(ROBOTS_PREFIX, "http://websim_sockets")
    return f"""# Generated by websim nginx-config for {len(workers)} class workers.
# Robot NAME: ws://HOST:{ws_port}{ROBOTS_PREFIX}NAME and
# http://HOST:{http_port}{ROBOTS_PREFIX}NAME/, on the worker its name hashes to.
# The dashboard, http://HOST:{http_port}/class, reads /workers.json and opens each
# worker's root view at ws://HOST:{ws_port}/workers/K/?token=INSTRUCTOR.
# Start worker K (0-based, in this order) with --trusted-proxy NGINX_ADDRESS (it then reads
# the client's address from X-Real-IP: per-address budgets are each student's, not nginx's)
# and --worker-index K --workers {" ".join(f"{w.host}:{w.http_port}:{w.ws_port}" for w in workers)}
# (it then makes only the robots this nginx routes to it).
worker_processes auto;
events {{
    worker_connections 4096;
}}
http {{
{ROBOT_MAP}
    map $http_upgrade $connection_upgrade {{
        default upgrade;
        "" close;
    }}
    upstream websim_pages {{
        hash $robot consistent;
{pages}
    }}
    upstream websim_sockets {{
        hash $robot consistent;
{sockets}
    }}
    server {{
        listen {http_listen};
        location {ROBOTS_PREFIX} {{
            proxy_pass http://websim_pages;
            proxy_set_header Host $http_host;
{CLIENT_HEADERS}        }}
        location = /workers.json {{
            default_type application/json;
            add_header Cache-Control "no-store";
            return 200 '{workers_json(workers)}\\n';
        }}
        location / {{
            proxy_pass http://websim_pages;
            proxy_set_header Host $http_host;
{CLIENT_HEADERS}        }}
    }}
    server {{
        listen {ws_listen};
{robots}{_worker_roots(workers)}        location / {{
            return 404 "robots are at {ROBOTS_PREFIX}NAME\\n";
        }}
    }}
}}
"""


TEMP_PATH_KINDS = ("client_body", "proxy", "fastcgi", "uwsgi", "scgi")
"""nginx's temporary-file directories (compiled into the binary, usually root's)."""


def in_directory(conf: str, directory: Path) -> str:
    """``conf`` with nginx's temporary files under ``directory``: it runs without root.

    For a try-out on a laptop, the tests and the benchmarks.
    """
    temp = "".join(f"    {kind}_temp_path {directory / kind};\n" for kind in TEMP_PATH_KINDS)
    return conf.replace("http {\n", "http {\n" + temp, 1)


def foreground_command(nginx: str, conf_path: Path, directory: Path,
                       test: bool = False) -> list[str]:
    """The command running nginx on ``conf_path`` in the foreground, logs in ``directory``.

    Its pid file and error log go to ``directory``; ``test``: ``nginx -t``, check the
    configuration only. As root, its workers stay root, so they can read ``directory``.
    """
    directives = f"pid {directory / 'nginx.pid'}; error_log {directory / 'error.log'};"
    if not test:
        directives = "daemon off; " + directives + (" user root;" if os.geteuid() == 0 else "")
    return [nginx, *(["-t"] if test else []), "-p", str(directory), "-c", str(conf_path),
            "-g", directives]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``websim nginx-config``."""
    parser.add_argument("--workers", nargs="+", required=True, metavar="HOST:HTTP:WS",
                        help="each worker's address, page port and WebSocket port")
    parser.add_argument("--listen-http", default="8080", metavar="[ADDR:]PORT",
                        help="where nginx serves the pages (default 8080)")
    parser.add_argument("--listen-ws", default="9090", metavar="[ADDR:]PORT",
                        help="where nginx serves the WebSockets (default 9090)")


def run(args: argparse.Namespace) -> int:
    """Print the configuration."""
    workers = [parse_worker(text) for text in args.workers]
    sys.stdout.write(nginx_config(workers, args.listen_http, args.listen_ws))
    return 0
