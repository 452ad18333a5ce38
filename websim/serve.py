"""``websim serve``: the simulator in real time behind rosbridge, and the web interface.

The whole platform with one command and no ROS install: a rosbridge v2 WebSocket on
``--ws-port`` (9090) and the browser pages on ``--http-port`` (8080).
"""

from __future__ import annotations

import argparse
import asyncio
import errno
import logging
import secrets
import signal
import sys
from pathlib import Path

from physics.params import PROJECT_DIR
from ros_nodes.rosbridge.server import SimServer, start_websocket
from ros_nodes.virtual_robot_core import VirtualRobot
from websim.http_static import start_http

WEB_DIR = PROJECT_DIR / "web-interface"
"""The static frontend."""

log = logging.getLogger("websim.serve")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``websim serve`` (besides world, mode, params and seed)."""
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to bind (default 127.0.0.1; 0.0.0.0 serves a classroom)")
    parser.add_argument("--ws-port", type=int, default=9090,
                        help="rosbridge WebSocket port (default 9090)")
    parser.add_argument("--http-port", type=int, default=8080,
                        help="web interface port (default 8080)")
    parser.add_argument("--admin-token", default=None,
                        help="secret for admin rights (default: random, printed at start)")
    parser.add_argument("--web-dir", type=Path, default=WEB_DIR, help=argparse.SUPPRESS)
    parser.add_argument("--log-level", default="warning",
                        choices=["debug", "info", "warning", "error"],
                        help="logging level (default warning)")


def _url_host(host: str) -> str:
    return "localhost" if host in ("0.0.0.0", "::", "127.0.0.1", "") else host


async def serve_forever(args: argparse.Namespace, robot: VirtualRobot) -> int:
    """Run until SIGINT or SIGTERM; returns the exit code."""
    token = args.admin_token or secrets.token_urlsafe(16)
    server = SimServer(robot, token)
    try:
        websocket = await start_websocket(server, args.host, args.ws_port)
    except OSError as error:
        return _port_error("WebSocket", args.host, args.ws_port, error)
    try:
        http = start_http(args.host, args.http_port, args.web_dir, server.health)
    except OSError as error:
        websocket.close()
        return _port_error("HTTP", args.host, args.http_port, error)

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(signum, stop.set)
    ticker = asyncio.create_task(server.run_ticks())

    host = _url_host(args.host)
    print(f"websim: world '{robot.sim.world.name}', {robot.sim.mode} mode", flush=True)
    print(f"  page:      http://{host}:{args.http_port}/", flush=True)
    print(f"  websocket: ws://{host}:{args.ws_port}/", flush=True)
    print(f"  admin:     http://{host}:{args.http_port}/admin?token={token}", flush=True)
    if args.host in ("0.0.0.0", "::"):
        print("  listening on every network interface: anyone who can reach this machine can "
              "drive the robot; only the admin token can change its parameters", flush=True)
    print("websim: ready (Ctrl+C to stop)", flush=True)

    await stop.wait()
    ticker.cancel()
    websocket.close()
    await websocket.wait_closed()
    http.shutdown()
    http.server_close()
    print("websim: stopped", flush=True)
    return 0


def _port_error(what: str, host: str, port: int, error: OSError) -> int:
    if error.errno == errno.EADDRINUSE:
        reason = "is already in use (is another websim running?)"
    else:
        reason = f"cannot be opened: {error.strerror or error}"
    print(f"websim: error: {what} port {host}:{port} {reason}", file=sys.stderr)
    return 1


def run(args: argparse.Namespace, robot: VirtualRobot) -> int:
    """Entry point of ``websim serve`` after the simulation was built."""
    logging.basicConfig(level=args.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return asyncio.run(serve_forever(args, robot))
