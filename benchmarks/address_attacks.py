"""One address against a class: budgets per person, not per connection (issue 20, section 3).

A real ``websim serve --class N`` on 127.0.0.1. The attacker's connections come from
127.0.0.2 (their sockets bound there before connecting), the healthy clients from 127.0.0.1,
so the server sees two client addresses, as it would see two machines.

* **flood**: ``--flooders`` (80) connections from the attacker, spread over three robots of
  its own (robot01, robot22, robot23: at most 64 connections from one address reach one
  robot, ``address_max_robot_connections``), each publishing ``/cmd_vel`` at
  ``--flood-rate`` (190 messages/s: within the per-connection ``max_rate`` of 200, so no
  single one is ever closed), while each of 20 other robots has one healthy client
  subscribed to ``/odom``. Printed: every healthy client's ``/odom`` rate over the window
  (from the stamps it received), how many flooders were admitted and how the others were
  refused, and the messages/s the attacker sent. Target: every healthy client >= 19 Hz.
  With ``--addresses 8`` the flooders come from 127.0.0.2 to 127.0.0.9, each address within
  its own budgets: only the budget of the robots they flood (``robot_handling_share``) holds
  them.
* **idle**: ``--idlers`` (500) idle sockets from the attacker to a classmate's robot
  (robot02), then its owner connects from 127.0.0.1. Printed: admitted and refused sockets,
  the refusal, and whether the owner got in. Target: the owner connects.

Run it from the checkout::

    python benchmarks/address_attacks.py
    python benchmarks/address_attacks.py --seconds 5 --json
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import running_server

ATTACKER = "127.0.0.2"
HEALTHY = "127.0.0.1"
TWIST = {"linear": {"x": 0.1, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.2}}


async def open_from(url: str, source: str) -> ClientConnection | str:
    """A WebSocket to ``url`` from address ``source``, or why it was refused."""
    try:
        return await connect(url, local_addr=(source, 0), max_size=None, open_timeout=10,
                             ping_interval=None)
    except InvalidStatus as refused:
        body = refused.response.body.decode(errors="replace").strip()
        return f"HTTP {refused.response.status_code}: {body}"
    except (OSError, TimeoutError) as error:
        return f"{type(error).__name__}: {error}"


class Listener:
    """A healthy client: subscribes to /odom and keeps the stamps it receives."""

    def __init__(self, connection: ClientConnection) -> None:
        self.connection = connection
        self.stamps_s: list[float] = []
        self.task = asyncio.create_task(self._listen())

    async def _listen(self) -> None:
        await self.connection.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
        with contextlib.suppress(ConnectionClosed):
            async for frame in self.connection:
                message = json.loads(frame)
                if message.get("topic") == "/odom":
                    stamp = message["msg"]["header"]["stamp"]
                    self.stamps_s.append(stamp["sec"] + stamp["nanosec"] * 1e-9)

    def rate_since(self, start: int) -> float:
        """/odom messages/s by their stamps since the ``start``-th."""
        stamps = self.stamps_s[start:]
        if len(stamps) < 2:
            return 0.0
        return (len(stamps) - 1) / (stamps[-1] - stamps[0])


async def flood(connection: ClientConnection, rate: float, sent: list[int]) -> str | None:
    """Publish /cmd_vel at ``rate`` until cancelled; the close reason if the server closed."""
    frame = json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST})
    period = 1.0 / rate
    next_s = time.monotonic()
    try:
        while True:
            await connection.send(frame)
            sent[0] += 1
            next_s += period
            await asyncio.sleep(max(0.0, next_s - time.monotonic()))
    except ConnectionClosed as closed:
        return f"closed {closed.rcvd.code if closed.rcvd else '?'}: " \
               f"{closed.rcvd.reason if closed.rcvd else ''}"


async def drain(connection: ClientConnection) -> None:
    with contextlib.suppress(ConnectionClosed):
        async for _ in connection:
            pass


def attacker_addresses(count: int) -> list[str]:
    """``count`` attacker addresses: 127.0.0.2, 127.0.0.3, ..."""
    return [f"127.0.0.{2 + k}" for k in range(count)]


async def flood_run(ws_port: int, flooders: int, rate: float, seconds: float,
                    robots: int, addresses: int = 1) -> dict[str, Any]:
    base = f"ws://{HEALTHY}:{ws_port}/robots/"
    listeners = []
    for index in range(2, robots + 2):
        opened = await open_from(f"{base}robot{index:02d}", HEALTHY)
        assert not isinstance(opened, str), opened
        listeners.append(Listener(opened))
    await asyncio.sleep(1.0)
    own = [f"robot{index:02d}" for index in (1, robots + 2, robots + 3)]
    sources = attacker_addresses(addresses)
    attempts = await asyncio.gather(*(open_from(f"{base}{own[k % len(own)]}",
                                                sources[k % len(sources)])
                                      for k in range(flooders)))
    admitted = [a for a in attempts if not isinstance(a, str)]
    refusals = sorted({a for a in attempts if isinstance(a, str)})
    sent = [0]
    tasks = [asyncio.create_task(flood(c, rate, sent)) for c in admitted]
    readers = [asyncio.create_task(drain(c)) for c in admitted]
    await asyncio.sleep(1.0)  # the flood starts
    marks = [listener.stamps_s.__len__() for listener in listeners]
    sent_at_mark, started = sent[0], time.monotonic()
    await asyncio.sleep(seconds)
    rates = [listener.rate_since(mark) for listener, mark in zip(listeners, marks, strict=True)]
    sent_rate = (sent[0] - sent_at_mark) / (time.monotonic() - started)
    closes = sorted({result for task in tasks if task.done()
                     and (result := task.result()) is not None})
    for task in itertools.chain(tasks, readers, (listener.task for listener in listeners)):
        task.cancel()
    for connection in itertools.chain(admitted, (listener.connection for listener in listeners)):
        with contextlib.suppress(Exception):
            await asyncio.wait_for(connection.close(), 2)
    return {"healthy_min_hz": round(min(rates), 2),
            "healthy_rates_hz": [round(rate, 1) for rate in rates],
            "flooders_admitted": len(admitted), "flooders_refused": len(attempts) - len(admitted),
            "refusals": refusals[:3], "attacker_sent_per_s": round(sent_rate),
            "flooders_closed": closes[:3], "pass": min(rates) >= 19.0}


async def idle_run(ws_port: int, idlers: int) -> dict[str, Any]:
    url = f"ws://{HEALTHY}:{ws_port}/robots/robot02"
    attempts = []
    for start in range(0, idlers, 50):  # 50 at a time: a loop of connects, not a SYN flood
        attempts += await asyncio.gather(*(open_from(url, ATTACKER)
                                           for _ in range(start, min(idlers, start + 50))))
    admitted = [a for a in attempts if not isinstance(a, str)]
    refusals = sorted({a for a in attempts if isinstance(a, str)})
    owner = await open_from(url, HEALTHY)
    owner_in = not isinstance(owner, str)
    odom = 0
    if not isinstance(owner, str):
        listener = Listener(owner)
        await asyncio.sleep(2.0)
        odom = len(listener.stamps_s)
        listener.task.cancel()
        await owner.close()
    for connection in admitted:
        with contextlib.suppress(Exception):
            await asyncio.wait_for(connection.close(), 2)
    return {"idlers_admitted": len(admitted), "idlers_refused": len(attempts) - len(admitted),
            "refusals": refusals[:3], "owner_connected": owner_in,
            "owner_odom_in_2_s": odom, "owner_refusal": None if owner_in else owner,
            "pass": owner_in and odom >= 20}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flooders", type=int, default=80)
    parser.add_argument("--flood-rate", type=float, default=190.0)
    parser.add_argument("--robots", type=int, default=20, help="healthy robots (default 20)")
    parser.add_argument("--idlers", type=int, default=500)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--addresses", type=int, default=1,
                        help="spread the flooders over this many addresses, 127.0.0.2 on "
                             "(default 1: one student; 8: a crowd, each address within "
                             "its own budget, held by the robots' budgets)")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--handling-share-per-robot", default=None, metavar="FRACTION",
                        help="passed to websim serve (e.g. 100: no robot budget, to compare)")
    args = parser.parse_args(argv)
    import resource

    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    with tempfile.TemporaryDirectory() as log_dir, \
            running_server(Path(log_dir), ["--class", str(args.robots + 3), *(
                ["--handling-share-per-robot", args.handling_share_per_robot]
                if args.handling_share_per_robot else [])]) as server:
        flooded = asyncio.run(flood_run(server.ws_port, args.flooders, args.flood_rate,
                                        args.seconds, args.robots, args.addresses))
        time.sleep(1.0)
        idle = asyncio.run(idle_run(server.ws_port, args.idlers))
        errors = [line for line in server.log_tail(100000).splitlines() if " ERROR " in line]
    result = {"flood": flooded, "idle": idle, "server_errors": errors[:5]}
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        sources = attacker_addresses(args.addresses)
        print(f"flood: {args.flooders} connections from {', '.join(sources)} at "
              f"{args.flood_rate:g} msg/s each, {args.robots} healthy robots on {HEALTHY}")
        for key, value in flooded.items():
            print(f"  {key}: {value}")
        print(f"idle: {args.idlers} idle sockets from {ATTACKER} to robot02, then its owner")
        for key, value in idle.items():
            print(f"  {key}: {value}")
        print(f"  {'PASS' if flooded['pass'] else 'FAIL'} flood: every healthy client >= 19 Hz")
        print(f"  {'PASS' if idle['pass'] else 'FAIL'} idle: the owner connects")
    return 0 if flooded["pass"] and idle["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
