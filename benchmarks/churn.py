"""Connect and disconnect many clients against a real ``websim serve`` and print what is left.

Each cycle opens a WebSocket, subscribes to /scan and /odom, advertises a topic of its own,
waits for its first frame and goes: every second cycle with a clean close, the others by
dropping the TCP connection without a close frame (a browser tab killed, Wi-Fi gone). Before
and after, it reads the server's RSS (psutil) and ``/healthz``; at the end every session must
be gone (``clients`` back to 0, nothing queued). It asserts nothing about speed; it exits 1 if
sessions leaked or RSS grew by more than ``--rss-limit-mb``.

Run it from the checkout::

    python benchmarks/churn.py --cycles 500
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import time
from pathlib import Path

import psutil
from websockets.asyncio.client import connect

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import Server, running_server

WARM_UP_CYCLES = 50
"""Cycles run before the first RSS reading, so that allocator pools and caches are filled."""


async def churn(server: Server, cycles: int) -> None:
    """Run ``cycles`` connect/subscribe/disconnect cycles, one after the other."""
    for cycle in range(cycles):
        websocket = await connect(server.ws_url)
        for topic in ("/scan", "/odom"):
            await websocket.send(json.dumps({"op": "subscribe", "topic": topic}))
        await websocket.send(json.dumps({"op": "advertise", "topic": f"/churn{cycle}",
                                         "type": "std_msgs/msg/String"}))
        async with asyncio.timeout(5):
            await websocket.recv()
        if cycle % 2:
            websocket.transport.abort()
        else:
            await websocket.close()


def settled(server: Server, timeout_s: float = 10.0) -> dict[str, object]:
    """/healthz once no client is connected any more (or after ``timeout_s``)."""
    deadline = time.monotonic() + timeout_s
    while True:
        health = server.health()
        if health["clients"] == 0 or time.monotonic() > deadline:
            return health
        time.sleep(0.05)


def main(argv: list[str] | None = None) -> int:
    """Churn, print RSS and session figures; 1 if sessions leaked or RSS grew too much."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=500, help="cycles (default 500)")
    parser.add_argument("--rss-limit-mb", type=float, default=5.0,
                        help="largest acceptable RSS growth (default 5 MB)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as log_dir, running_server(Path(log_dir)) as server:
        process = psutil.Process(server.process.pid)
        asyncio.run(churn(server, WARM_UP_CYCLES))
        settled(server)
        rss_before = process.memory_info().rss
        started = time.perf_counter()
        asyncio.run(churn(server, args.cycles))
        elapsed = time.perf_counter() - started
        health = settled(server)
        rss_after = process.memory_info().rss
    growth_mb = (rss_after - rss_before) / 1e6
    print(f"churn: {args.cycles} cycles (half closed cleanly, half dropped) in {elapsed:.1f} s "
          f"after {WARM_UP_CYCLES} warm-up cycles")
    print(f"  server RSS: {rss_before / 1e6:.1f} MB -> {rss_after / 1e6:.1f} MB "
          f"({growth_mb:+.2f} MB; limit {args.rss_limit_mb:g})")
    print(f"  after: clients {health['clients']}, queued frames {health['queued_frames']}, "
          f"ticks {health['ticks']} of {health['ticks_due']} due, "
          f"jitter p99 {health['tick_jitter_p99_ms']} ms")
    leaked = health["clients"] != 0 or health["queued_frames"] != 0
    return 1 if leaked or growth_mb > args.rss_limit_mb else 0


if __name__ == "__main__":
    sys.exit(main())
