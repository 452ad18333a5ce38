"""Test-only helper "nodes" the upstream roslibpy and roslibjs suites expect beside rosbridge.

Their CI runs rosbridge next to ROS nodes: a Fibonacci action server on ``/fibonacci``
(``example_interfaces/action/Fibonacci``; roslibpy's ``tests/ros2/test_actions.py``), an
``add_two_ints`` service and a 1 Hz ``std_msgs/String`` publisher on ``/listener``
(roslibjs's ``test/examples/setup_examples_ros2.launch.xml``). websim has no such nodes, so
this one rosbridge client provides them over the bridge itself, as a rosbridge client may:
``advertise_action``, ``advertise_service`` and ``publish``. It is our own code, written from
the rosbridge v2 protocol, not upstream's.

Usage: python3 scripts/upstream/fixture_nodes.py [--url ws://127.0.0.1:9090] [--step-s 0.5]
       [--without-action]
It retries the connection until the bridge answers and runs until killed.
"""

from __future__ import annotations

import argparse
import asyncio
import json
from typing import Any

import websockets

FIBONACCI_ACTION = "/fibonacci"
FIBONACCI_TYPE = "example_interfaces/action/Fibonacci"
ADD_TWO_INTS_SERVICE = "/add_two_ints"
ADD_TWO_INTS_TYPE = "example_interfaces/srv/AddTwoInts"
LISTENER_TOPIC = "/listener"
LISTENER_PERIOD_S = 1.0
STATUS_SUCCEEDED = 4
STATUS_CANCELED = 5


class Fixture:
    """One connection serving the action and the service and publishing ``/listener``."""

    def __init__(self, ws: Any, step_s: float, with_action: bool = True) -> None:
        self.ws = ws
        self.step_s = step_s
        self.with_action = with_action
        self.goals: dict[str, asyncio.Task[None]] = {}

    async def send(self, message: dict[str, Any]) -> None:
        """Send one rosbridge message as JSON text."""
        await self.ws.send(json.dumps(message))

    async def start(self) -> None:
        """Advertise the action (unless the graph serves it), the service and the topic."""
        if self.with_action:
            await self.send({"op": "advertise_action", "action": FIBONACCI_ACTION,
                             "type": FIBONACCI_TYPE})
        await self.send({"op": "advertise_service", "service": ADD_TWO_INTS_SERVICE,
                         "type": ADD_TWO_INTS_TYPE})
        await self.send({"op": "advertise", "topic": LISTENER_TOPIC, "type": "std_msgs/String"})

    async def publish_listener(self) -> None:
        """Publish "Hello, World" on /listener once a period, as `ros2 topic pub --rate 1`."""
        while True:
            await self.send({"op": "publish", "topic": LISTENER_TOPIC,
                             "msg": {"data": "Hello, World"}})
            await asyncio.sleep(LISTENER_PERIOD_S)

    async def run_goal(self, goal_id: str, order: int) -> None:
        """Fibonacci as ROS 2's action tutorial server computes it: one step per period."""
        sequence = [0, 1]
        status = STATUS_SUCCEEDED
        try:
            for i in range(1, order):
                sequence.append(sequence[i] + sequence[i - 1])
                await self.send({"op": "action_feedback", "action": FIBONACCI_ACTION,
                                 "id": goal_id, "values": {"sequence": list(sequence)}})
                await asyncio.sleep(self.step_s)
        except asyncio.CancelledError:
            status = STATUS_CANCELED
        await self.send({"op": "action_result", "action": FIBONACCI_ACTION, "id": goal_id,
                         "values": {"sequence": sequence}, "status": status, "result": True})
        self.goals.pop(goal_id, None)

    async def handle(self, message: dict[str, Any]) -> None:
        """Answer what the bridge forwards: goals, cancels and service calls."""
        op = message.get("op")
        if op == "send_action_goal":
            goal_id = str(message["id"])
            order = int(message.get("args", {}).get("order", 0))
            self.goals[goal_id] = asyncio.create_task(self.run_goal(goal_id, order))
        elif op == "cancel_action_goal":
            task = self.goals.get(str(message.get("id")))
            if task is not None:
                task.cancel()
        elif op == "call_service":
            args = message.get("args", {})
            await self.send({"op": "service_response", "service": message["service"],
                             "id": message.get("id"), "result": True,
                             "values": {"sum": int(args.get("a", 0)) + int(args.get("b", 0))}})


async def serve(url: str, step_s: float, with_action: bool) -> None:
    """Connect (again after a drop) and serve until killed."""
    while True:
        try:
            async with websockets.connect(url) as ws:
                fixture = Fixture(ws, step_s, with_action)
                await fixture.start()
                publisher = asyncio.create_task(fixture.publish_listener())
                served = ([FIBONACCI_ACTION] if with_action else []) + [ADD_TWO_INTS_SERVICE,
                                                                         LISTENER_TOPIC]
                print(f"fixture_nodes: serving {', '.join(served)} on {url}", flush=True)
                try:
                    async for raw in ws:
                        await fixture.handle(json.loads(raw))
                finally:
                    publisher.cancel()
        except (OSError, websockets.exceptions.WebSocketException) as error:
            print(f"fixture_nodes: {error!r}; retrying", flush=True)
            await asyncio.sleep(0.5)


def main() -> None:
    """Parse the command line and serve."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="ws://127.0.0.1:9090")
    parser.add_argument("--step-s", type=float, default=0.5,
                        help="seconds between Fibonacci steps (feedback period)")
    parser.add_argument("--without-action", action="store_true",
                        help="do not serve /fibonacci (fixture_rclpy.py serves it on the graph)")
    args = parser.parse_args()
    asyncio.run(serve(args.url, args.step_s, not args.without_action))


if __name__ == "__main__":
    main()
