"""The controller's side of a graded run's ROS graph (``websim grade --ros``).

An rclpy controller is usually a node driven by a timer on sim time: it keeps the latest
``/odom`` and ``/scan`` from its subscriptions and publishes ``/cmd_vel`` when its timer
fires, on some ticks and not others (a 10 Hz timer on 20 Hz ticks). Lock step cannot wait
for "its answer" then: an answer is not due at every tick. It waits instead until the
controller's executor has handled everything of the tick (``ControllerGraph.deliver``):

1. the robot's node hands the tick's messages to the grader (``hold``) instead of publishing
   them; the grader publishes them one at a time (``deliver``), in the robot's order but
   ``/clock`` last, from one participant to the controller's;
2. after each message of a topic the controller subscribes to, the grader calls a service of
   each controller node (``get_parameters`` with no names, which every rclpy node serves and
   which changes nothing) and waits for the answer, ``CONFIRMING_CALLS`` times one after the
   other (once more after ``/clock``). The last answer means the message's callback has run
   (and published its ``/cmd_vel``, which the robot has by then: it was sent before the
   answer, usually a round trip before).

Why more than one call. The message and the request come from two writers of the grader's
one participant over one UDP path (the run's network namespace), and even when they arrive in
that order the controller's executor may take the request first: rmw_fastrtps's wait looks at
the subscriptions' conditions, then the services', one after the other, and when both arrive
between those two looks (the controller's thread descheduled there, which a loaded machine
does) that wait finds only the request, and the node answers before the message's callback
has run. The message is queued by then, so the next wait finds it; and rclpy's executor
handles what one wait found in order (timers, subscriptions, ..., services). The second
request is sent only once the first is answered, so it is answered after the message's
callback. After ``/clock`` a third: by the second answer the node has taken the tick's time,
which makes its timers due, and ready in its next wait; the third request is answered only
after they ran.

Measured under load (two CPU burners, a disk writer, an rclpy flood and the test suite on 2
cores), with the wall follower on a 478-tick corridor and an executor that counts the requests
it takes before each callback: one call per message let a callback run after its answer in 3
of 18 runs (5 of about 26,000 messages); two one after the other, in none of 27. They cost
the six-scenario suite (rclpy wall follower, side by side) 1.03x to 1.46x its wall time;
sending the two at once costs less (1.1x to 1.2x) and had no violation in 18 runs, but leaves no
margin: a message overtaken by both requests, or a ``/cmd_vel`` by the last answer.
One transport for both (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` for the controller too;
rmw_fastrtps publishes synchronously by default) left the race as it was (3 of 18 runs), and
so did waiting for the reader's acknowledgement before one call (``wait_for_all_acked``: a
best-effort ``/scan`` reader sends none; 2 of 6 runs).
What can still race: a message held back in transport for more than a round trip (a
retransmission, say; not seen in those runs), which no answer can tell apart.

So every tick the controller sees the same messages in the same order, one callback at a
time, and its commands apply at the same tick, whatever the machine's load: a re-grade is
identical to the last digit (a node that answers ``/odom`` from the latest ``/scan`` reads the
same scan every time: the one published before, not whichever arrived first). What it does
not cover: a controller on a ``MultiThreadedExecutor`` or a reentrant callback group (its
callbacks may still run when it answers), and one paced by the wall clock (``time.sleep``,
a timer on the steady clock), which ``websim.grade_server.LockStep`` detects.

The same graph tells what the controller subscribes to, with which QoS: a subscription the
robot's publisher cannot serve (``incompatible QoS``: a TRANSIENT_LOCAL ``/odom``, a
deadline) is named in the run's reason, not left to rclpy's warning in its output.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping
from typing import Any

from rcl_interfaces.srv import GetParameters
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    QoSCompatibility,
    ReliabilityPolicy,
    qos_check_compatible,
)

from ros_nodes.robot_interface import CLOCK, NODE_BASENAME
from rosbridge.graph.names import RELAY_NODE_NAME

OUR_NODES = frozenset({("/", NODE_BASENAME), ("/", RELAY_NODE_NAME)})
"""The simulator's nodes on the run's graph: (namespace, name)."""

CONFIRMING_CALLS = 2
"""Handshake calls after each message, one after the other (one more after ``/clock``): the
first may be answered before the message's callback, the second cannot (module docstring)."""

HANDSHAKE_SERVICE = "get_parameters"
"""The service of a controller node the handshake calls: every rclpy (and rclcpp) node has
it unless it was built with ``start_parameter_services=False``."""


def full_name(namespace: str, name: str) -> str:
    """``/ns/name`` (``/name`` in the root namespace)."""
    return f"{namespace.rstrip('/')}/{name}"


class ControllerGraph:
    """The controller's nodes as the simulator's node sees them, and the handshake.

    Args:
        node: the simulator's node that looks (the robot's): its graph queries and the
            handshake's clients; its executor spins in another thread.
        publishers: the robot's publishers, by topic.
        loop: the event loop the grader waits on.
    """

    def __init__(self, node: Node, publishers: Mapping[str, Any],
                 loop: asyncio.AbstractEventLoop) -> None:
        self.node = node
        self.publishers = dict(publishers)
        self.loop = loop
        self.clients: dict[str, Any] = {}
        self.held: list[tuple[str, Callable[[], None]]] = []
        """The tick's messages not published yet: (topic, its publishing function)."""
        self.served: set[str] = set()
        """The robot's topics the controller subscribes to (set at the run's start)."""
        self.active: list[str] = []
        """The controller nodes the handshake calls (as ``ready`` last found them)."""

    def controller_nodes(self) -> list[str]:
        """The full names of the nodes on the graph that are not the simulator's."""
        return sorted(full_name(namespace, name)
                      for name, namespace in self.node.get_node_names_and_namespaces()
                      if (namespace or "/", name) not in OUR_NODES
                      and not name.startswith("_"))

    def subscriptions(self) -> tuple[dict[str, int], list[str]]:
        """The controller's subscriptions to the robot's topics.

        Returns:
            Per topic, how many the robot's publisher can serve; and one line per
            subscription it cannot (``/scan: /wall_follower asks ...: incompatible QoS``).
        """
        served: dict[str, int] = {}
        refused: list[str] = []
        for topic in self.publishers:
            ours = [info.qos_profile for info in self.node.get_publishers_info_by_topic(topic)
                    if (info.node_namespace or "/", info.node_name) in OUR_NODES]
            if not ours:  # not discovered yet (the graph of the robot's own node)
                continue
            for info in self.node.get_subscriptions_info_by_topic(topic):
                if (info.node_namespace or "/", info.node_name) in OUR_NODES:
                    continue
                # both as discovered: a profile as created has "default" where the graph
                # has "infinite", which qos_check_compatible takes for a mismatch
                compatibility, why = qos_check_compatible(ours[0], info.qos_profile)
                if compatibility == QoSCompatibility.ERROR:
                    refused.append(
                        f"{topic}: {full_name(info.node_namespace, info.node_name)} subscribes "
                        f"{_qos_text(info.qos_profile)}, the simulator publishes "
                        f"{_qos_text(ours[0])}: incompatible QoS, it gets nothing "
                        f"({why.strip().rstrip(';') or 'rclpy says so'})")
                else:
                    served[topic] = served.get(topic, 0) + 1
        return served, refused

    def matched(self, served: Mapping[str, int]) -> bool:
        """Whether the robot's publishers have matched every subscription they can serve."""
        return all(self.publishers[topic].get_subscription_count() >= count
                   for topic, count in served.items())

    def ready(self) -> bool:
        """Whether every controller node's handshake service is reachable (clients made)."""
        nodes = self.controller_nodes()
        for name in nodes:
            if name not in self.clients:
                self.clients[name] = self.node.create_client(
                    GetParameters, f"{name}/{HANDSHAKE_SERVICE}")
        self.active = nodes
        return bool(nodes) and all(self.clients[name].service_is_ready() for name in nodes)

    async def round_trip(self, timeout_s: float) -> bool:
        """Call every controller node's service once; whether all answered in time."""
        clients = [self.clients[name] for name in self.active]
        if not clients:
            return False
        answered = asyncio.Event()
        waiting = [len(clients)]

        def one_answered() -> None:
            waiting[0] -= 1
            if waiting[0] == 0:
                answered.set()

        def on_done(_future: Any) -> None:  # in the executor's thread
            self.loop.call_soon_threadsafe(one_answered)

        futures = []
        for client in clients:
            future = client.call_async(GetParameters.Request())
            future.add_done_callback(on_done)
            futures.append((client, future))
        try:
            await asyncio.wait_for(answered.wait(), timeout_s)
        except asyncio.TimeoutError:
            for client, future in futures:
                if not future.done():
                    client.remove_pending_request(future)
            return False
        return True

    def hold(self, topic: str, publish: Callable[[], None]) -> None:
        """Keep a message of the tick for ``deliver`` (the robot node's ``publish_hook``)."""
        self.held.append((topic, publish))

    async def deliver(self, timeout_s: float) -> bool:
        """Publish the tick's messages one at a time, each handled before the next.

        Returns:
            Whether the controller answered every handshake in time (if not, the rest of the
            tick's messages are published without waiting).
        """
        held, self.held = self.held, []
        held.sort(key=lambda item: item[0] == CLOCK.name)  # stable: /clock last
        answered = True
        for topic, publish in held:
            publish()
            if answered and topic in self.served:
                calls = CONFIRMING_CALLS + (topic == CLOCK.name)
                for _ in range(calls):
                    answered = answered and await self.round_trip(timeout_s)
        return answered


def _qos_text(profile: Any) -> str:
    """``RELIABLE, TRANSIENT_LOCAL`` for a QoS profile (as the graph reports it)."""
    return (f"{ReliabilityPolicy(profile.reliability).name}, "
            f"{DurabilityPolicy(profile.durability).name}")
