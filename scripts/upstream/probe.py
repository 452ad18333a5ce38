"""Send rosbridge messages on one connection and print the exchange (a raw trace for reports).

Usage: python3 scripts/upstream/probe.py '[{"op": "call_service", ...}]' [--url URL] [--wait-s 1.5]
Prints each message sent (">>") and every frame received ("<<") until none came for --wait-s.
"""

from __future__ import annotations

import argparse
import asyncio
import json

import websockets


async def exchange(url: str, messages: list[dict[str, object]], wait_s: float) -> None:
    """Send ``messages`` in order, then print frames until ``wait_s`` passes without one."""
    async with websockets.connect(url) as ws:
        for message in messages:
            print(">>", json.dumps(message), flush=True)
            await ws.send(json.dumps(message))
        try:
            while True:
                frame = await asyncio.wait_for(ws.recv(), wait_s)
                print("<<", frame[:600] if isinstance(frame, str) else f"<{len(frame)} bytes>",
                      flush=True)
        except asyncio.TimeoutError:
            pass


def main() -> None:
    """Parse the command line and run the exchange."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("messages", help="a JSON list of rosbridge messages")
    parser.add_argument("--url", default="ws://127.0.0.1:9090")
    parser.add_argument("--wait-s", type=float, default=1.5)
    args = parser.parse_args()
    asyncio.run(exchange(args.url, json.loads(args.messages), args.wait_s))


if __name__ == "__main__":
    main()
