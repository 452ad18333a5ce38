"""The simulator's node on the ROS graph: ``simulation_interfaces`` and turtlesim's names.

``websim serve --ros`` runs it beside ``virtual_robot``: the same services as over rosbridge
(``ros_nodes.simulation_services``: ``/spawn_entity``, ``/get_entities``, ...,
``/websim/reset_simulation``, the ``/simulate_steps`` action, ``/spawn``, ``/kill``,
``/reset``, ``/NAME/teleport_absolute`` and ``teleport_relative``), answered by the same
functions on the server's event loop (``RobotAccess``). The graph has no tokens: a node on it
has the instructor's rights, as it already may call every robot's services.

It spins in an executor of its own: a ``StepSimulation`` waits for its steps (a tick each)
and a ``SimulateSteps`` goal runs for as many ticks, without holding up the robot's node.
The interface packages are not on PyPI: ``scripts/build_simulation_interfaces.sh`` builds
them (without them the node offers nothing and says so).
"""

from __future__ import annotations

import concurrent.futures
import logging
from collections.abc import Mapping
from typing import Any

from rclpy.action.server import ActionServer, CancelResponse
from rclpy.node import Node

from ros_nodes.simulation_services import (
    ACTION,
    ACTION_TYPE,
    PACKAGE,
    SERVICES,
    TELEPORT_ABSOLUTE,
    TELEPORT_RELATIVE,
    TELEPORT_TYPES,
    TURTLESIM_SERVICES,
    SimulationServices,
    result,
)
from ros_nodes.simulator_control import Caller
from ros_nodes.virtual_robot import RobotAccess
from rosbridge.core.errors import ServiceError
from rosbridge.msgs.rclpy_conversion import (
    MessageConversionError,
    message_class,
    to_dict,
    to_message,
)

log = logging.getLogger("websim.simulation")

SIMULATION_NODE_NAME = "websim_simulation"

GRAPH_CALLER = Caller(admin=True, drives=None)
"""Whoever calls from the ROS graph: it has no token, and it reaches every robot already."""

STEP_WAIT_S = 120.0
"""Longest a graph StepSimulation waits for its steps before it answers OPERATION_FAILED (the
steps go on); a SimulateSteps goal reports its progress instead."""

MISSING = ("simulation_interfaces and turtlesim are not installed, so their services are not "
           "on the ROS graph (rosbridge clients still have them): build them with "
           "'bash scripts/build_simulation_interfaces.sh' (needs cmake and a C compiler)")


class SimulationNode(Node):
    """``simulation_interfaces``' services and action, turtlesim's names, on the graph.

    Args:
        services: what answers them (the world's).
        access: how to reach the world on its thread.
        namespace: where the names go (a class robot's world: ``/NAME``).
        context: the rclpy context.
    """

    def __init__(self, services: SimulationServices, access: RobotAccess, *,
                 namespace: str = "", context: Any = None) -> None:
        super().__init__(SIMULATION_NODE_NAME, namespace=namespace or None, context=context)
        self._simulation = services
        self._world_access = access
        try:
            self._offer()
        except MessageConversionError as error:
            log.warning("%s (%s)", MISSING, error)
            self.get_logger().warning(MISSING)

    def _offer(self) -> None:
        for name, type_name in SERVICES.items():
            cls = message_class(f"{PACKAGE}/srv/{type_name}")
            if type_name == "StepSimulation":
                self.create_service(cls, name.lstrip("/"), self._step)
            else:
                self.create_service(cls, name.lstrip("/"), self._answer(type_name))
        turtlesim = {"/spawn": self._simulation.turtlesim_spawn,
                     "/kill": self._simulation.turtlesim_kill,
                     "/reset": self._simulation.turtlesim_reset}
        for name, handler in turtlesim.items():
            self.create_service(message_class(TURTLESIM_SERVICES[name]), name.lstrip("/"),
                                self._turtlesim(name, handler))
        for entity in self._world_access.call(self._simulation.control.entities):
            for absolute, service in ((True, TELEPORT_ABSOLUTE), (False, TELEPORT_RELATIVE)):
                def teleport(args: Any, caller: Caller, name: str = entity.name,
                             absolute: bool = absolute) -> Any:
                    return self._simulation.teleport(name, absolute, args, caller)
                self.create_service(message_class(TELEPORT_TYPES[absolute]),
                                    f"{entity.name}/{service}",
                                    self._turtlesim(f"/{entity.name}/{service}", teleport))
        self._action = ActionServer(self, message_class(ACTION_TYPE), ACTION.lstrip("/"),
                                    self._simulate_steps,
                                    cancel_callback=lambda goal: CancelResponse.ACCEPT)

    def _answer(self, type_name: str) -> Any:
        def callback(request: Any, response: Any) -> Any:
            args = to_dict(request)
            try:
                values = self._world_access.call(
                    lambda: self._simulation.call(type_name, args, GRAPH_CALLER))
            except ServiceError as error:  # rclpy filled the request: cannot happen
                values = {"result": result(4, str(error))}
            assert isinstance(values, Mapping)  # StepSimulation alone answers later
            return to_message(type(response), values)
        return callback

    def _turtlesim(self, name: str, handler: Any) -> Any:
        def callback(request: Any, response: Any) -> Any:
            args = to_dict(request)
            try:
                values = self._world_access.call(lambda: handler(args, GRAPH_CALLER))
            except ServiceError as error:  # turtlesim's services have no result: say so
                self.get_logger().error(str(error))
                return response
            return to_message(type(response), values)
        return callback

    def _start(self, args: Any, progress: Any) -> concurrent.futures.Future[dict[str, Any]]:
        """Start stepping on the world's thread; the future of its final ``Result``."""
        finished: concurrent.futures.Future[dict[str, Any]] = concurrent.futures.Future()

        def start() -> None:
            cancel = self._simulation.start_steps(args, GRAPH_CALLER, progress,
                                                finished.set_result)
            finished.cancel_steps = cancel  # type: ignore[attr-defined]
        self._world_access.call(start)
        return finished

    def _step(self, request: Any, response: Any) -> Any:
        finished = self._start(to_dict(request), lambda completed, remaining: None)
        try:
            outcome = finished.result(STEP_WAIT_S)
        except concurrent.futures.TimeoutError:
            outcome = result(4, f"the steps took longer than {STEP_WAIT_S:g} s to run; they "
                                "go on (SimulateSteps reports its progress)")
        return to_message(type(response), {"result": outcome})

    def _simulate_steps(self, goal: Any) -> Any:
        action = message_class(ACTION_TYPE)

        def progress(completed: int, remaining: int) -> None:
            goal.publish_feedback(to_message(action.Feedback, {
                "completed_steps": completed, "remaining_steps": remaining}))

        finished = self._start(to_dict(goal.request), progress)
        while True:
            try:
                outcome = finished.result(0.05)
                break
            except concurrent.futures.TimeoutError:
                if goal.is_cancel_requested:
                    self._world_access.call(finished.cancel_steps)  # type: ignore[attr-defined]
                    goal.canceled()
                    return to_message(action.Result, {"result": result(4, "cancelled")})
        if outcome["result"] == 1:
            goal.succeed()
        else:
            goal.abort()
        return to_message(action.Result, {"result": outcome})
