"""``websim serve --ros``: rosbridge clients' action goals on the ROS 2 graph, and back.

The ``ActionGraph`` behind ``capabilities.actions``: a client's goal to an action no client
provides goes to the graph's server through an rclpy ``ActionClient`` (one per action,
kept), its feedback and result come back; a client's advertised action is offered on the
graph through an rclpy ``ActionServer`` whose goals go to that client. Types are imported
from their packages by name (``action_class``), as ``rclpy_conversion.message_class`` does for
messages, so any installed action type works.

Threads, as in ``relay``: the methods run on the event loop that owns the bridge;
rclpy's callbacks run on the executor thread and hand everything to the loop
(``LoopAccess.post``). A served goal's execute callback is a coroutine that awaits a future
the loop completes, so the single-threaded executor goes on meanwhile.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable, Mapping
from typing import Any

import rclpy.task
from rclpy.action.client import ActionClient
from rclpy.action.graph import (
    get_action_names_and_types,
    get_action_server_names_and_types_by_node,
)
from rclpy.action.server import ActionServer, CancelResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import Executor
from rclpy.node import Node

from rosbridge.core.capabilities.actions import (
    Cancel,
    GoalHandler,
    GoalSender,
    normalize_action_type,
)
from rosbridge.core.errors import BridgeError
from rosbridge.core.schema import GoalStatus
from rosbridge.msgs.rclpy_conversion import MessageConversionError, to_dict, to_message

log = logging.getLogger("websim.ros")

SERVER_WAIT_S = 2.0
"""How long a new ``ActionClient`` may take to discover its server before a goal fails
(rosbridge waits 1 s); later goals to the same action reuse it."""

SERVER_POLL_S = 0.02


def action_class(type_name: str) -> Any:
    """The Python class of ``pkg/action/Type`` (``pkg/Type`` too).

    Raises:
        BridgeError: not an action type, or its package is not installed (which wheel).
    """
    try:
        package, _, name = normalize_action_type(type_name).split("/")
    except ValueError as error:
        raise BridgeError(str(error)) from None
    try:
        module = importlib.import_module(f"{package}.action")
    except ImportError:
        raise BridgeError(f"{package}/action/{name}: package {package} is not installed "
                          f"(pip install ros-{package.replace('_', '-')})") from None
    cls = getattr(module, name, None)
    if cls is None or not hasattr(cls, "Goal"):
        raise BridgeError(f"{package}/action/{name}: no such action in {package}")
    return cls


def _goal_message(cls: Any, args: Any) -> Any:
    """The Goal of ``cls`` from rosbridge ``args``: named fields, or a list in field order."""
    if isinstance(args, list):
        args = dict(zip(cls.Goal.get_fields_and_field_types(), args, strict=False))
    try:
        return to_message(cls.Goal, args)
    except MessageConversionError as error:
        raise BridgeError(f"goal: {error}") from None


class RosActions:
    """The graph's actions for one bridge, through one node.

    Args:
        node: the relay node (``rosbridge_websocket``).
        post: runs a function on the event loop soon (``LoopAccess.post``).
        call_later: ``loop.call_later`` of that loop (s, function).
        executor: the executor spinning ``node`` (wakes it for served goals).
    """

    def __init__(self, node: Node, post: Callable[[Callable[[], None]], None],
                 call_later: Callable[[float, Callable[[], None]], Any],
                 executor: Executor) -> None:
        self._node = node
        self._post = post
        self._call_later = call_later
        self._executor = executor
        self._group = ReentrantCallbackGroup()
        self._clients: dict[str, tuple[str, Any, Any]] = {}
        self._servers: dict[str, Any] = {}
        self._cancels: dict[bytes, Cancel] = {}

    def action_types(self) -> Mapping[str, str]:
        """Action servers on the graph (not those offered here), each with its first type."""
        return {name: normalize_action_type(types[0])
                for name, types in get_action_names_and_types(self._node)
                if types and name not in self._servers}

    def _graph_servers(self) -> set[str]:
        """Actions that another node's action server serves.

        A client alone lists a name in ``action_types`` too: a node waiting for the server
        it is about to get must not keep a client's action off the graph.
        """
        own = self._node.get_fully_qualified_name()
        served: set[str] = set()
        for name, namespace in self._node.get_node_names_and_namespaces():
            if f"{namespace.rstrip('/')}/{name}" == own:
                continue
            try:
                served.update(action for action, _ in get_action_server_names_and_types_by_node(
                    self._node, name, namespace))
            except Exception:  # the node left between the two questions
                continue
        return served

    # ---- goals to the graph's servers -----------------------------------------------------

    def send_goal(self, action: str, type_name: str, args: Any,
                  sender: GoalSender) -> Cancel:
        """Send a client's goal to the graph's server of ``action``.

        Raises:
            BridgeError: the type's package is missing or the goal does not fit it.
        """
        entry = self._clients.get(action)
        if entry is None or entry[0] != type_name:
            if entry is not None:
                entry[2].destroy()
            cls = action_class(type_name)
            entry = (type_name, cls, ActionClient(self._node, cls, action,
                                                  callback_group=self._group))
            self._clients[action] = entry
        _, cls, client = entry
        goal = _GraphGoal(self._post, sender)
        goal_msg = _goal_message(cls, args)
        deadline_s = [SERVER_WAIT_S]

        def send_when_ready() -> None:
            if goal.canceled:
                sender.goal_result("canceled before its server was found",
                                   GoalStatus.CANCELED, True)
            elif client.server_is_ready():
                future = client.send_goal_async(goal_msg, feedback_callback=goal.on_feedback)
                future.add_done_callback(goal.on_response)
            elif deadline_s[0] <= 0:
                sender.goal_result(f"the action server of {action} did not answer within "
                                   f"{SERVER_WAIT_S:g} s", GoalStatus.UNKNOWN, False)
            else:
                deadline_s[0] -= SERVER_POLL_S
                self._call_later(SERVER_POLL_S, send_when_ready)

        send_when_ready()
        return goal.cancel

    # ---- clients' actions on the graph ----------------------------------------------------

    def advertise_action(self, action: str, type_name: str, on_goal: GoalHandler) -> None:
        """Offer a client's ``action`` on the graph; each goal goes to ``on_goal``.

        Raises:
            BridgeError: a node on the graph serves it already, or the type is missing.
        """
        if action in self._graph_servers():
            raise BridgeError(f"{action} is served on the ROS graph already")
        cls = action_class(type_name)

        async def execute(goal_handle: Any) -> Any:
            done: rclpy.task.Future[tuple[Any, GoalStatus, bool]] = rclpy.task.Future(
                executor=self._executor)
            done.add_done_callback(lambda _: None)  # completing it wakes the executor
            key = bytes(goal_handle.goal_id.uuid)
            served = _ServedGoal(goal_handle, cls, done)
            request = to_dict(goal_handle.request)

            def start() -> None:
                self._cancels[key] = on_goal(request, served)

            self._post(start)
            outcome = await done
            self._post(lambda: self._forget(key))
            assert outcome is not None  # only ``goal_result`` completes it
            return served.finish(*outcome)

        def cancel(goal_handle: Any) -> CancelResponse:
            key = bytes(goal_handle.goal_id.uuid)
            self._post(lambda: self._cancels.get(key, _nothing)())
            return CancelResponse.ACCEPT

        self._servers[action] = ActionServer(self._node, cls, action, execute,
                                             cancel_callback=cancel,
                                             callback_group=self._group)

    def _forget(self, key: bytes) -> None:
        self._cancels.pop(key, None)

    def unadvertise_action(self, action: str) -> None:
        """Stop offering ``action`` (its goals were answered): destroyed on the executor."""
        server = self._servers.pop(action, None)
        if server is not None:
            self._executor.create_task(server.destroy)


class _GraphGoal:
    """A client's goal on the graph: rclpy's answers (executor thread) go to the loop."""

    def __init__(self, post: Callable[[Callable[[], None]], None], sender: GoalSender) -> None:
        self._post = post
        self._sender = sender
        self._handle: Any = None
        self.canceled = False

    def on_feedback(self, feedback_msg: Any) -> None:
        values = to_dict(feedback_msg.feedback)
        self._post(lambda: self._sender.goal_feedback(values))

    def on_response(self, future: Any) -> None:
        try:
            handle = future.result()
        except Exception as error:  # handed to the client as the goal's failure
            self._fail(f"sending the goal failed: {error}")
            return
        if not handle.accepted:
            self._fail("Action goal was rejected")
            return
        self._post(lambda: self._accepted(handle))
        handle.get_result_async().add_done_callback(self.on_result)

    def _accepted(self, handle: Any) -> None:
        self._handle = handle
        if self.canceled:
            handle.cancel_goal_async()

    def on_result(self, future: Any) -> None:
        try:
            response = future.result()
            values, status = to_dict(response.result), GoalStatus(response.status)
        except Exception as error:  # handed to the client as the goal's failure
            self._fail(f"getting the result failed: {error}")
            return
        self._post(lambda: self._sender.goal_result(values, status, True))

    def _fail(self, reason: str) -> None:
        self._post(lambda: self._sender.goal_result(reason, GoalStatus.UNKNOWN, False))

    def cancel(self) -> None:
        """The client canceled (on the loop)."""
        self.canceled = True
        if self._handle is not None:
            self._handle.cancel_goal_async()


class _ServedGoal:
    """A graph node's goal to a client's action: the client's answers (loop) go to rclpy."""

    def __init__(self, goal_handle: Any, cls: Any,
                 done: rclpy.task.Future[tuple[Any, GoalStatus, bool]]) -> None:
        self._goal_handle = goal_handle
        self._cls = cls
        self._done = done

    def goal_feedback(self, values: Mapping[str, Any]) -> None:
        try:
            self._goal_handle.publish_feedback(to_message(self._cls.Feedback, values,
                                                          strict=False))
        except MessageConversionError as error:
            log.warning("feedback does not fit %s: %s", self._cls.__name__, error)

    def goal_result(self, values: Any, status: GoalStatus, result: bool) -> None:
        if not self._done.done():
            self._done.set_result((values, status, result))

    def finish(self, values: Any, status: GoalStatus, result: bool) -> Any:
        """End the goal on the graph as the client did (executor thread); its Result."""
        handle = self._goal_handle
        if result and status == GoalStatus.SUCCEEDED:
            handle.succeed()
        elif result and status == GoalStatus.CANCELED and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        try:
            return to_message(self._cls.Result, values if isinstance(values, dict) else {},
                              strict=False)
        except MessageConversionError as error:
            log.warning("result does not fit %s: %s", self._cls.__name__, error)
            return self._cls.Result()


def _nothing() -> None:
    """No cancel: the goal is not (or no longer) with a client."""
