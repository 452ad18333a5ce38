"""A burst from a ROS node to a browser subscriber through ``websim serve --ros``: all of it?

rosbridge's promise for ``queue_length`` 0 (both client libraries' default) with no throttle
is that every message is sent. This publishes ``--count`` ``std_msgs/msg/String`` messages
("0", "1", ...) from an rclpy node as fast as rclpy publishes them, to a WebSocket client
subscribed the way roslibjs subscribes by default (no throttle, queue_length 0), and prints
per run: messages received, whether they came complete and in order, the first missing one,
and how long the burst took to publish and to arrive.

The publisher's QoS is reliable with a history as deep as the burst (``--depth``, default the
count): a shallower one lets DDS drop what the relay has not taken yet, before websim sees it.

Needs the ``[ros]`` extra. Run it from the checkout::

    python benchmarks/ros_burst.py --count 1000 --runs 3
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import running_server

IDLE_S = 3.0
"""A burst is over when nothing arrives for this long."""

TOPIC = "/burst"


def receive(url: str, count: int, ready: threading.Event, got: list[str]) -> None:
    """Subscribe as roslibjs does by default and append every message's data to ``got``."""
    from websockets.sync.client import connect

    with connect(url, max_size=None) as websocket:
        websocket.send(json.dumps({"op": "subscribe", "topic": TOPIC, "id": "subscribe:1",
                                   "type": "std_msgs/msg/String", "compression": "none",
                                   "throttle_rate": 0, "queue_length": 0}))
        ready.set()
        while len(got) < count:
            try:
                frame = websocket.recv(timeout=IDLE_S if got else 30.0)
            except TimeoutError:
                return
            message = json.loads(frame)
            if message.get("op") == "publish":
                got.append(message["msg"]["data"])


def run_once(server_url: str, node: Any, publisher: Any, count: int) -> dict[str, Any]:
    from std_msgs.msg import String

    ready = threading.Event()
    got: list[str] = []
    listener = threading.Thread(target=receive, args=(server_url, count, ready, got))
    listener.start()
    ready.wait(10)
    deadline = time.monotonic() + 30
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)  # the relay subscribes on the graph once the client has
    time.sleep(0.5)  # discovery both ways
    started = time.perf_counter()
    for index in range(count):
        publisher.publish(String(data=str(index)))
    published_s = time.perf_counter() - started
    listener.join()
    arrived_s = time.perf_counter() - started - (IDLE_S if len(got) < count else 0.0)
    expected = [str(index) for index in range(count)]
    pairs = enumerate(zip(got, expected, strict=False))
    missing = next((index for index, (a, b) in pairs if a != b),
                   len(got) if len(got) < count else None)
    return {"received": len(got), "complete_in_order": got == expected,
            "first_missing": missing, "published_ms": published_s * 1000,
            "arrived_ms": arrived_s * 1000}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--depth", type=int, default=None,
                        help="publisher history depth (default: --count)")
    args = parser.parse_args()

    import rclpy
    from rclpy.context import Context
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    domain_id = random.randint(1, 100)
    os.environ.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                      ROS_LOCALHOST_ONLY="1")
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node("burst_publisher", context=context)
    qos = QoSProfile(depth=args.depth or args.count, reliability=ReliabilityPolicy.RELIABLE)
    publisher = node.create_publisher(String, TOPIC, qos)
    print(f"{args.count} std_msgs/String from an rclpy node (reliable, depth "
          f"{qos.depth}) to a WebSocket subscriber with queue_length 0, no throttle")
    failures = 0
    with tempfile.TemporaryDirectory() as log_dir, \
            running_server(Path(log_dir), ["--ros"]) as server:
        for run in range(args.runs):
            row = run_once(server.ws_url, node, publisher, args.count)
            failures += not row["complete_in_order"]
            print(f"run {run + 1}: received {row['received']}/{args.count}, complete and in "
                  f"order: {row['complete_in_order']}, first missing: {row['first_missing']}, "
                  f"published in {row['published_ms']:.0f} ms, arrived in "
                  f"{row['arrived_ms']:.0f} ms")
    node.destroy_node()
    context.try_shutdown()
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
