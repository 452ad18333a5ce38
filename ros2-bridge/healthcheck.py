"""Health check of the ros2-web-bridge container: the robot runs and both rosbridges answer.

Healthy when the students' rosbridge delivers one /odom message (so rosbridge, DDS and the
virtual_robot node all work) and the admin rosbridge accepts a WebSocket. Exit status 0 means
healthy and 1 unhealthy, as Docker's HEALTHCHECK expects; the reason goes to stdout, which
``docker inspect`` shows. Needs only the ``websockets`` package, not ROS.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from websockets.exceptions import WebSocketException
from websockets.sync.client import connect

STUDENT_URL = "ws://127.0.0.1:9090"
"""The students' rosbridge (rosbridge_params.yaml)."""

ADMIN_URL = "ws://127.0.0.1:9091"
"""The admin rosbridge (rosbridge_params.yaml)."""

TIMEOUT_S = 5.0
"""For each check. /odom comes at 20 Hz; a Pi 4B under load still answers well within this."""


def first_odom(url: str, timeout_s: float) -> None:
    """Subscribe to /odom at ``url`` and wait for one message; raise TimeoutError if none."""
    deadline = time.monotonic() + timeout_s
    with connect(url, open_timeout=timeout_s, close_timeout=1.0) as websocket:
        websocket.send(json.dumps({"op": "subscribe", "id": "healthcheck", "topic": "/odom",
                                   "type": "nav_msgs/msg/Odometry"}))
        while True:
            frame = websocket.recv(timeout=max(0.0, deadline - time.monotonic()))
            message = json.loads(frame)
            if message.get("op") == "publish" and message.get("topic") == "/odom":
                return


def accepts_websocket(url: str, timeout_s: float) -> None:
    """Open and close a WebSocket to ``url``; raise if the handshake fails."""
    with connect(url, open_timeout=timeout_s, close_timeout=1.0):
        pass


def main(argv: list[str] | None = None) -> int:
    """Run both checks; 0 when healthy, 1 otherwise."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default=STUDENT_URL,
                        help=f"the students' rosbridge (default {STUDENT_URL})")
    parser.add_argument("--admin-url", default=ADMIN_URL,
                        help=f"the admin rosbridge (default {ADMIN_URL})")
    parser.add_argument("--timeout", type=float, default=TIMEOUT_S,
                        help=f"seconds for each check (default {TIMEOUT_S:g})")
    args = parser.parse_args(argv)
    try:
        first_odom(args.url, args.timeout)
    except (OSError, TimeoutError, WebSocketException, ValueError) as error:
        print(f"unhealthy: no /odom from {args.url}: {error!r}")
        return 1
    try:
        accepts_websocket(args.admin_url, args.timeout)
    except (OSError, TimeoutError, WebSocketException) as error:
        print(f"unhealthy: admin rosbridge {args.admin_url}: {error!r}")
        return 1
    print("healthy")
    return 0


if __name__ == "__main__":
    sys.exit(main())
