"""``websim serve --ros``: rclpy inside the server, the robots' nodes and the bridge's relay.

Threads: the asyncio event loop of ``websim serve`` owns the simulation and the bridge, as
without ROS; its tick loop stays the one clock, and each tick's messages go to the browser and,
through the robot's tap (``VirtualRobot.tap``, which the node listens to; rclpy publishers are
thread-safe), onto the ROS graph.
rclpy has no asyncio executor, so a ``SingleThreadedExecutor`` spins in one background thread;
everything its callbacks do to the robot or the bridge is handed to the loop
(``LoopAccess``), and whatever needs an answer (a parameter change, a reset) waits for it
there.

Each tick's ``/clock`` goes onto the graph after the tick's other messages (``clock_after``):
a node on sim time then has the tick's ``/odom`` and ``/scan`` before its timers see the
tick's time (``websim grade``'s lock step goes further: ``VirtualRobotNode.publish_hook``).

Two nodes share one rclpy ``Context`` (no global state; rclpy's signal handlers stay off, the
server handles SIGINT and SIGTERM): ``virtual_robot`` and ``rosbridge_websocket``, the relay
(``rosbridge.graph.relay``), as a real rosbridge deployment names them.

Read-only (``read_only``, a graded run's): the graph is the bridge's equal, so what the
bridge refuses a client the graph refuses a node: setting either node's parameters (rclpy's
parameter services answer ``successful: false`` with the reason) and ``/reset_simulation``
(answered without resetting, the refusal logged: ``std_srvs/Empty`` has no way to say no).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Mapping
from typing import Any

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from std_srvs.srv import Empty

from heartbeat.driver import TickDriver
from ros_nodes.robot_interface import CLOCK, RESET_SERVICE
from ros_nodes.robot_messages import clock_msg
from ros_nodes.simulation_node import SimulationNode
from ros_nodes.simulation_services import SimulationServices
from ros_nodes.virtual_robot import VirtualRobotNode, qos_profile
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Bridge
from rosbridge.graph.actions import RosActions
from rosbridge.graph.names import RELAY_NODE_NAME
from rosbridge.graph.relay import GraphRelay, LoopAccess
from rosbridge.graph.services import GraphServices
from rosbridge.msgs.rclpy_conversion import message_class, to_message
from rosbridge.msgs.values import Message
from rosbridge.transport.writers import Writers


def spin_until_shutdown(executor: SingleThreadedExecutor, context: Context) -> None:
    """Spin ``executor`` until its context shuts down (the executor thread's body)."""
    try:
        executor.spin()
    except ExternalShutdownException:
        pass
    except RuntimeError:
        if context.ok():
            raise
        # rclpy can fail taking a message whose entity the shutdown destroyed mid-take.


class RosRuntime:
    """rclpy inside ``websim serve``: a context, the two nodes and the executor thread.

    Build it on the event loop's thread (``start``), stop it before the loop ends.

    Args:
        robot: the robot the server ticks.
        bridge: the server's bridge, which gets the relay attached.
        loop: the server's event loop.
        writers: where the bridge's flushes are written (the tick driver's ``writers``):
            a graph topic's messages, an action's or a graph service's answers and the robot
            node's parameter events go out at once. None: with the next tick
            (``Writers.sweep``).
        parameters: overrides of the robot node's parameters (``websim grade --ros``:
            ``scan_reliability: reliable``).
    """

    def __init__(self, robot: VirtualRobot, bridge: Bridge,
                 loop: asyncio.AbstractEventLoop, writers: Writers | None = None,
                 parameters: Mapping[str, Any] | None = None, *,
                 simulation: SimulationServices | None = None,
                 read_only: str | None = None) -> None:
        self._bridge = bridge
        self.refusals = 0
        """Changes refused on the graph (``read_only``)."""

        def write_queued() -> None:  # what a function handed to the loop queued, at once
            if writers is not None:
                writers.write(bridge.take_flush())

        access = LoopAccess(loop, after=write_queued)
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self.robot_node = VirtualRobotNode(
                robot, access=access, own_timer=False, ignore_cmd_vel_from=RELAY_NODE_NAME,
                clock_after=loop.call_soon, context=self.context,
                parameter_overrides=[Parameter(name, value=value)
                                     for name, value in (parameters or {}).items()])
            self.relay_node = Node(RELAY_NODE_NAME, context=self.context)
        except BaseException:
            self.context.try_shutdown()
            raise

        def publish(topic: str, type_name: str, msg: Message, latched: bool) -> None:
            flush = bridge.publish(topic, msg, latched, type_name)
            if writers is not None:
                writers.write(flush)

        def deliver(topic: str, type_name: str, msg: Message, latched: bool) -> None:
            with contextlib.suppress(RuntimeError):  # the loop closed while shutting down
                loop.call_soon_threadsafe(publish, topic, type_name, msg, latched)

        if read_only is not None:
            self._refuse_changes(read_only)
        self.relay = GraphRelay(self.relay_node, deliver)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.relay.services = GraphServices(self.relay_node, self.executor, loop,
                                            post=access.post)
        self.executor.add_node(self.robot_node)
        self.executor.add_node(self.relay_node)
        self.actions = RosActions(self.relay_node, access.post, loop.call_later, self.executor)
        self._thread = threading.Thread(target=self._spin, name="rclpy-executor", daemon=True)
        # The simulation services in an executor of their own: a step waits for ticks.
        self.simulation_node = None if simulation is None else SimulationNode(
            simulation, access, context=self.context)
        self.simulation_executor = SingleThreadedExecutor(context=self.context)
        if self.simulation_node is not None:
            self.simulation_executor.add_node(self.simulation_node)
        self._simulation_thread = threading.Thread(
            target=spin_until_shutdown, args=(self.simulation_executor, self.context),
            name="rclpy-simulation", daemon=True)

    def _refuse_changes(self, reason: str) -> None:
        """Nothing on the graph may change the robot: parameters and reset refused."""
        logger = self.robot_node.get_logger()

        def refuse_parameters(parameters: list[Any]) -> SetParametersResult:
            self.refusals += 1
            logger.error(f"parameters {[p.name for p in parameters]} refused: {reason}")
            return SetParametersResult(successful=False, reason=reason)

        for node in (self.robot_node, self.relay_node):
            node.add_on_set_parameters_callback(refuse_parameters)
        for service in list(self.robot_node.services):
            if service.srv_name == RESET_SERVICE:
                self.robot_node.destroy_service(service)

        def refuse_reset(request: Any, response: Any) -> Any:
            self.refusals += 1
            logger.error(f"{RESET_SERVICE} refused: {reason}")
            return response

        self.robot_node.create_service(Empty, RESET_SERVICE, refuse_reset)

    def start(self) -> None:
        """Spin the executor and relay the bridge's topics and actions from now on."""
        self._thread.start()
        self._simulation_thread.start()
        self._bridge.graph.attach(self.relay)
        self._bridge.actions.attach(self.actions)

    def _spin(self) -> None:
        spin_until_shutdown(self.executor, self.context)

    def poll(self) -> None:
        """Let subscriptions to graph topics nobody publishes yet start (``relay.poll``)."""
        self.relay.poll()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Detach from the bridge, stop the executor and destroy the nodes."""
        self._bridge.graph.attach(None)
        self._bridge.actions.attach(None)
        self.executor.shutdown(timeout_sec=timeout_s)
        self.simulation_executor.shutdown(timeout_sec=timeout_s)
        self.robot_node.destroy_node()
        self.relay_node.destroy_node()
        if self.simulation_node is not None:
            self.simulation_node.destroy_node()
        self.context.try_shutdown()
        self._thread.join(timeout_s)
        self._simulation_thread.join(timeout_s)


CLOCK_NODE_NAME = "websim_clock"
"""The node that publishes a class's one ``/clock`` on the ROS graph."""


class ClassRosRuntime:
    """rclpy inside ``websim serve --class --ros``: a ``virtual_robot`` node per robot.

    Robot NAME's node is ``/NAME/virtual_robot``, its topics and services under ``/NAME``
    (``/alice/cmd_vel``, ``/alice/odom``, ``/alice/reset_simulation``) and its frames
    prefixed (``alice/odom``, ``alice/base_link``, ``alice/laser``), as multi-robot ROS 2
    stacks name them, so a student's node runs with ``--ros-args -r __ns:=/alice``. The
    browsers' rosbridge topics are not relayed to the graph in a class (each robot's page
    talks to its bridge; the graph talks to its node).

    The class has one clock on the graph (its robots share one: ``websim serve --ros``), so
    one ``/clock`` (at the root, what ``use_sim_time`` nodes read): published after every
    tick of the class's tick driver by the node ``/CLOCK_NODE_NAME``, not by each robot's
    node.

    Args:
        robots: (name, robot) of every robot of the class.
        loop: the server's event loop.
        schedule: the class's tick driver.
    """

    def __init__(self, robots: list[tuple[str, VirtualRobot]],
                 loop: asyncio.AbstractEventLoop, schedule: TickDriver) -> None:
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.nodes: list[VirtualRobotNode] = []
        self._schedule = schedule
        try:
            for name, robot in robots:
                self.nodes.append(VirtualRobotNode(
                    robot, access=LoopAccess(loop), own_timer=False, frame_prefix=f"{name}/",
                    publish_clock=False, namespace=f"/{name}", context=self.context))
            self.clock_node = Node(CLOCK_NODE_NAME, context=self.context)
        except BaseException:
            for node in self.nodes:
                node.destroy_node()
            self.context.try_shutdown()
            raise
        clock_type = message_class(CLOCK.type)
        publisher = self.clock_node.create_publisher(clock_type, CLOCK.name, qos_profile(CLOCK))
        clock = robots[0][1].clock if robots else schedule.clock

        def publish_clock() -> None:
            publisher.publish(to_message(clock_type, clock_msg(clock.stamp_s())))

        self._publish_clock = publish_clock
        self.executor = SingleThreadedExecutor(context=self.context)
        for node in self.nodes:
            self.executor.add_node(node)
        self._thread = threading.Thread(target=self._spin, name="rclpy-executor", daemon=True)

    def start(self) -> None:
        """Spin the executor; publish ``/clock`` after every tick from now on."""
        self._thread.start()
        self._schedule.tick_listeners.append(self._publish_clock)

    def poll(self) -> None:
        """Nothing waits for graph topics here (no relay in a class)."""

    def _spin(self) -> None:
        spin_until_shutdown(self.executor, self.context)

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop publishing ``/clock``, stop the executor and destroy the nodes."""
        if self._publish_clock in self._schedule.tick_listeners:
            self._schedule.tick_listeners.remove(self._publish_clock)
        self.executor.shutdown(timeout_sec=timeout_s)
        for node in self.nodes:
            node.destroy_node()
        self.clock_node.destroy_node()
        self.context.try_shutdown()
        self._thread.join(timeout_s)
