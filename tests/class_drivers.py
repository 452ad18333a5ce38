"""Students driving a class: one raw WebSocket client per robot, each with its robot's token,
each publishing ``/cmd_vel`` at 10 Hz, as a student's teleop or controller does.

Run as a process of its own, so that the drivers keep their rate whatever the test process
does (a Playwright call blocks it)::

    python tests/class_drivers.py LINKS_CSV SECONDS

``LINKS_CSV`` is a ``websim serve --links`` file (its WebSocket URL and token per robot). It
prints ``ready N`` once every robot's client is connected, then ``go`` when the first commands
leave, and drives until ``SECONDS`` have passed (or it is terminated). The command is zero: a robot
driven so stands still, so only its commands' age says it is driven (a moving robot counts as
driven on the dashboard anyway).
"""

from __future__ import annotations

import asyncio
import csv
import json
import sys
from collections.abc import Sequence

import websockets

RATE_HZ = 10.0
"""How often each driver publishes (a teleop page's rate)."""

TWIST = json.dumps({"op": "publish", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist",
                    "msg": {"linear": {"x": 0.0}, "angular": {"z": 0.0}}})


def robot_urls(links_csv: str) -> list[str]:
    """Each robot's WebSocket URL with its token, from a links file (the handout)."""
    with open(links_csv, newline="", encoding="utf-8") as links:
        return [f"{row['websocket']}?token={row['token']}" for row in csv.DictReader(links)]


async def drive(ws: websockets.ClientConnection, start_s: float, stop_s: float) -> None:
    loop = asyncio.get_running_loop()
    due_s = start_s
    while due_s < stop_s:
        await asyncio.sleep(max(0.0, due_s - loop.time()))
        await ws.send(TWIST)
        due_s += 1.0 / RATE_HZ


async def drain(ws: websockets.ClientConnection) -> None:
    async for _ in ws:  # a driver reads what the bridge says (status messages) and drops it
        pass


async def main(argv: Sequence[str]) -> None:
    links_csv, seconds = argv[0], float(argv[1])
    urls = robot_urls(links_csv)
    connections = [await websockets.connect(url.replace("localhost", "127.0.0.1"))
                   for url in urls]
    print(f"ready {len(connections)}", flush=True)
    loop = asyncio.get_running_loop()
    start_s = loop.time()
    print("go", flush=True)
    readers = [asyncio.create_task(drain(ws)) for ws in connections]
    await asyncio.gather(*(drive(ws, start_s, start_s + seconds) for ws in connections))
    for reader in readers:
        reader.cancel()
    for ws in connections:
        await ws.close()


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1:]))
