"""ROS 2 actions: advertise_action, send_action_goal, cancel_action_goal, feedback, results.

A client that sends ``advertise_action`` is the action's server. Another client's
``send_action_goal`` is forwarded to it under a goal id of the bridge's
(``action_goal:<action>:<n>``, as rosbridge's ``AdvertisedActionHandler`` names them); the
server's ``action_feedback`` and ``action_result`` for that id go back to the goal's sender
with the sender's own id, and the sender's ``cancel_action_goal`` goes to the server. With
``websim serve --ros`` (``attach``), a goal to an action no client provides goes to the ROS
graph's action server, and a client's action is also offered on the graph.

What the sender gets is what rosbridge 2.x sends: ``action_result`` with ``result: true``,
the server's terminal ``status`` (SUCCEEDED, CANCELED; any other, or the server's
``result: false``, is ABORTED, as rosbridge's ROS action server ends it) and its ``values``.
A goal that no server took gets ``result: false``, status UNKNOWN and the reason in
``values`` at once (rosbridge's failure answer, never a hang), and a goal whose server
leaves or unadvertises gets ``result: false``, status ABORTED and the reason.

An action may also be served in-process (``add``: the TF republisher's), as services are:
its goals go to a handler on the bridge's thread, which answers through the goal's
``GoalSender`` and is told when the goal is cancelled or its sender leaves.

An action belongs to whoever advertised it first, as a service does. Goals are bounded per
sender (``ClientLimits.max_goals``) and per action (``max_goals_per_action``, the server's).
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from rosbridge.core import relay
from rosbridge.core.context import BridgeContext
from rosbridge.core.errors import BridgeError
from rosbridge.core.schema import GoalStatus
from rosbridge.core.session import Session
from rosbridge.msgs import definitions
from rosbridge.msgs.values import normalize_type

Cancel = Callable[[], None]
"""Asks a goal's server to cancel it; its result still comes (status CANCELED, say)."""


def normalize_action_type(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/action/Type`` -> ``pkg/action/Type``.

    Raises:
        ValueError: not an action type name.
    """
    parts = type_name.strip("/").split("/")
    if len(parts) == 2 and all(parts):
        return f"{parts[0]}/action/{parts[1]}"
    normalized = normalize_type(type_name)
    if normalized.split("/")[1] != "action":
        raise ValueError(f"not an action type: {type_name!r} (expected pkg/action/Type)")
    return normalized


class GoalSender(Protocol):
    """Whoever sent a goal, as its server's answers reach it (on the bridge's thread)."""

    def goal_feedback(self, values: Mapping[str, Any]) -> None:
        """A feedback message of the goal's action."""

    def goal_result(self, values: Any, status: GoalStatus, result: bool) -> None:
        """The goal ended: its result (or the failure's reason), status and success."""


GoalHandler = Callable[[Any, GoalSender], Cancel]
"""Takes a goal from the graph to a client's action: (args, sender) -> how to cancel it."""

LocalGoalHandler = Callable[[Any, GoalSender, Session], Cancel]
"""An in-process action server (``Actions.add``): (goal args in canonical form, the sender
its feedback and result go to, the client that sent it) -> how to cancel the goal. Called on
the bridge's thread; it raises one of ``Bridge.refusals`` to refuse the goal with a reason.
Cancelling it (the sender's ``cancel_action_goal``, or the sender leaving) must stop its
feedback; it may still answer with a result (CANCELED)."""


class ActionGraph(Protocol):
    """The ROS 2 graph's actions, as the bridge uses them; called on the bridge's thread.

    What it calls back (a ``GoalSender``, a ``GoalHandler``, a ``Cancel``) it calls on the
    bridge's thread too. Each method raises ``BridgeError`` with the reason when it cannot
    do what is asked.
    """

    def action_types(self) -> Mapping[str, str]:
        """The action servers on the graph and their types (``pkg/action/Type``)."""

    def send_goal(self, action: str, type_name: str, args: Any,
                  sender: GoalSender) -> Cancel:
        """Send a goal to the graph's server of ``action``; its answers go to ``sender``."""

    def advertise_action(self, action: str, type_name: str, on_goal: GoalHandler) -> None:
        """Serve ``action`` on the graph: each goal goes to ``on_goal``."""

    def unadvertise_action(self, action: str) -> None:
        """Stop serving ``action`` on the graph (its goals were answered already)."""


@dataclass
class _ClientSender:
    """A client that sent a goal: it hears of it under its own id, as rosbridge replies."""

    session: Session
    goal_id: Any
    action: str
    wants_feedback: bool

    def goal_feedback(self, values: Mapping[str, Any]) -> None:
        if self.wants_feedback:
            self.session.reply(self._with_id({"op": "action_feedback", "action": self.action,
                                              "values": values}))

    def goal_result(self, values: Any, status: GoalStatus, result: bool) -> None:
        self.session.reply(self._with_id({"op": "action_result", "action": self.action,
                                          "values": values, "status": int(status),
                                          "result": result}))

    def _with_id(self, message: dict[str, Any]) -> dict[str, Any]:
        if self.goal_id is not None:
            message["id"] = self.goal_id
        return message


@dataclass
class _Goal:
    """A goal sent and not yet answered.

    Attributes:
        sender: who hears its feedback and result.
        owner: the client that sent it (None: a node on the ROS graph).
        owner_id: its id in the owner's ``send_action_goal`` (None: none given).
        action: the action's name.
        server: the client serving it (None: the graph's action server, or an in-process
            one).
        local: it is served in-process (``Actions.add``).
        cancel_elsewhere: how to cancel it where it runs: on the graph, or in-process.
    """

    sender: GoalSender
    owner: Session | None
    owner_id: Any
    action: str
    server: Session | None
    local: bool = False
    cancel_elsewhere: Cancel | None = None


class Actions:
    """The action capability of one bridge.

    Args:
        context: what it shares with the bridge's other capabilities (its sessions).
    """

    OPS = ("advertise_action", "unadvertise_action", "send_action_goal",
           "cancel_action_goal", "action_feedback", "action_result")

    def __init__(self, context: BridgeContext) -> None:
        self._context = context
        self._spelled: dict[str, str] = {}
        """Each served action's type as its server spelled it: goals echo it (rosbridge)."""
        self._graph: ActionGraph | None = None
        self._servers: dict[str, tuple[Session, str]] = {}
        self._offered: set[str] = set()
        self._goals: dict[str, _Goal] = {}
        self._by_owner: dict[tuple[Session, Any], str] = {}
        self._sent_counts: dict[Session, int] = {}
        self._served_counts: dict[str, int] = {}
        self._numbers = itertools.count(1)
        self._local: dict[str, tuple[str, LocalGoalHandler]] = {}

    def handlers(self) -> dict[str, Callable[[Session, dict[str, Any]], None]]:
        """This capability's ops."""
        return {"advertise_action": self._advertise, "unadvertise_action": self._unadvertise,
                "send_action_goal": self._send_goal, "cancel_action_goal": self._cancel_goal,
                "action_feedback": self._feedback, "action_result": self._result}

    def add(self, action: str, type_name: str, handler: LocalGoalHandler) -> None:
        """Serve ``action`` (of ``type_name``, ``pkg/action/Type``) in-process."""
        self._local[action] = (normalize_action_type(type_name), handler)

    def types(self) -> dict[str, str]:
        """Every action served here and its type: the in-process ones and clients'."""
        listed = {action: type_name for action, (type_name, _) in self._local.items()}
        listed.update({action: type_name for action, (_, type_name) in self._servers.items()})
        return listed

    def attach(self, graph: ActionGraph | None) -> None:
        """Send goals to and offer client actions on ``graph`` from now on (None: stop).

        Goals the previous graph was serving fail (ABORTED); goals it had sent are dropped.
        """
        for key, goal in list(self._goals.items()):
            if goal.server is None and not goal.local:
                self._finish(key, "the ROS graph relay stopped", GoalStatus.ABORTED, False)
            elif goal.owner is None:
                self._drop(key)
        self._graph = graph
        self._offered.clear()
        for action, (session, type_name) in list(self._servers.items()):
            self._offer(session, action, type_name)

    def disconnect(self, session: Session) -> None:
        """Withdraw ``session``'s actions (failing their goals) and cancel its own goals."""
        for action in list(session.actions):
            self._withdraw(session, action, f"the action server of {action} disconnected")
        for key, goal in list(self._goals.items()):
            if goal.owner is session:
                self._drop(key)
                self._cancel(key, goal)

    # ---- sending goals --------------------------------------------------------------------

    def _send_goal(self, session: Session, message: dict[str, Any]) -> None:
        action, goal_id = message["action"], message.get("id")
        type_name = _action_type(action, message["action_type"])
        if goal_id is not None and (session, goal_id) in self._by_owner:
            raise BridgeError(f"send_action_goal {action}: a goal with id "
                              f"{str(goal_id)[:80]!r} is already pending")
        if self._sent_counts.get(session, 0) >= session.limits.max_goals:
            raise BridgeError(f"send_action_goal {action}: a client may have at most "
                              f"{session.limits.max_goals} goals pending")
        sender = _ClientSender(session, goal_id, action, bool(message.get("feedback", False)))
        args = goal_args(type_name, message.get("args", {}))
        server = self._servers.get(action)
        relay.charge(session, f"send_action_goal {action}",
                     None if server is None else server[0])
        if action in self._servers:
            self._forward(sender, session, goal_id, action, type_name, args)
            return
        if action in self._local:
            self._serve_here(sender, session, goal_id, action, type_name, args)
            return
        if self._graph is None:
            raise BridgeError(f"Action {action} does not exist")
        # A server the graph has not shown yet may be starting: as rosbridge, the goal goes
        # out with the type the client names and waits a moment for the server.
        graph_type = self._graph.action_types().get(action)
        if graph_type is not None and graph_type != type_name:
            raise BridgeError(f"{action} is of type {graph_type}, not {type_name}")
        key = self._register(_Goal(sender, session, goal_id, action, None))
        try:
            cancel = self._graph.send_goal(action, type_name, args, _Relay(self, key))
        except BridgeError:
            self._drop(key)
            raise
        if key in self._goals:
            self._goals[key].cancel_elsewhere = cancel

    def _serve_here(self, sender: GoalSender, owner: Session, owner_id: Any, action: str,
                    type_name: str, args: Any) -> None:
        """Hand a goal to ``action`` 's in-process server."""
        local_type, handler = self._local[action]
        if local_type != type_name:
            raise BridgeError(f"{action} is of type {local_type}, not {type_name}")
        key = self._register(_Goal(sender, owner, owner_id, action, None, local=True))
        try:
            cancel = handler(args, _Relay(self, key), owner)
        except self._context.refusals:
            self._drop(key)
            raise
        if key in self._goals:
            self._goals[key].cancel_elsewhere = cancel

    def _forward(self, sender: GoalSender, owner: Session | None, owner_id: Any, action: str,
                 type_name: str, args: Any) -> str:
        """Send a goal to the client serving ``action``; the bridge's goal id."""
        server, server_type = self._servers[action]
        if server_type != type_name:
            raise BridgeError(f"{action} is of type {server_type}, not {type_name}")
        limit = server.limits.max_goals_per_action
        if self._served_counts.get(action, 0) >= limit:
            raise BridgeError(f"send_action_goal {action}: {limit} goals are pending on it "
                              "already, the most one action may hold")
        key = self._register(_Goal(sender, owner, owner_id, action, server))
        server.reply({"op": "send_action_goal", "id": key, "action": action,
                      "action_type": self._spelled.get(action, server_type), "args": args,
                      "feedback": True})
        return key

    def _cancel_goal(self, session: Session, message: dict[str, Any]) -> None:
        action, goal_id = message["action"], message["id"]
        key = self._by_owner.get((session, goal_id))
        goal = None if key is None else self._goals.get(key)
        if key is None or goal is None or goal.action != action:
            raise BridgeError(f"cancel_action_goal {action}: no goal with id "
                              f"{str(goal_id)[:80]!r} is pending")
        self._cancel(key, goal)

    def _cancel(self, key: str, goal: _Goal) -> None:
        if goal.server is not None:
            if goal.server in self._context.sessions:
                goal.server.reply({"op": "cancel_action_goal", "id": key,
                                   "action": goal.action})
        elif goal.cancel_elsewhere is not None:
            goal.cancel_elsewhere()

    # ---- serving goals --------------------------------------------------------------------

    def _feedback(self, session: Session, message: dict[str, Any]) -> None:
        goal = self._goals[self._served_by(session, message)]
        relay.charge(session, f"action_feedback {goal.action}", goal.owner)
        goal.sender.goal_feedback(message.get("values", {}))

    def _result(self, session: Session, message: dict[str, Any]) -> None:
        key = self._served_by(session, message)
        try:
            relay.charge(session, f"action_result {message['action']}", self._goals[key].owner)
        except BridgeError as error:  # the sender still hears of its goal's end
            self._finish(key, f"the server's result was refused: {error}",
                         GoalStatus.ABORTED, False)
            raise
        status = GoalStatus(message["status"])
        if not message["result"] or status not in (GoalStatus.SUCCEEDED, GoalStatus.CANCELED):
            status = GoalStatus.ABORTED
        self._finish(key, message.get("values", {}), status, True)

    def _served_by(self, session: Session, message: dict[str, Any]) -> str:
        """The key of the goal ``message`` answers, which ``session`` must be serving."""
        key = str(message["id"])
        goal = self._goals.get(key)
        if goal is None or goal.server is not session or goal.action != message["action"]:
            raise BridgeError(f"{message['op']} {message['action']}: no goal with id "
                              f"{key[:80]!r} is waiting for this client's answer")
        return key

    def _goal_from_graph(self, action: str, args: Any, sender: GoalSender) -> Cancel:
        """A node on the graph sent a goal to a client's action: forward it."""
        if action not in self._servers:
            sender.goal_result(f"Action {action} is no longer provided", GoalStatus.ABORTED,
                               False)
            return _nothing
        _, type_name = self._servers[action]
        try:
            key = self._forward(sender, None, None, action, type_name, args)
        except BridgeError as error:
            sender.goal_result(str(error), GoalStatus.ABORTED, False)
            return _nothing

        def cancel() -> None:
            goal = self._goals.get(key)
            if goal is not None:
                self._cancel(key, goal)

        return cancel

    # ---- providing ------------------------------------------------------------------------

    def _advertise(self, session: Session, message: dict[str, Any]) -> None:
        action = message["action"]
        type_name = _action_type(action, message["type"])
        if action in self._local:
            raise BridgeError(f"{action} is served by the simulator")
        server = self._servers.get(action)
        if server is not None and server[0] is not session:
            raise BridgeError(f"{action} is already provided by another client; it stays "
                              "theirs until they unadvertise it or disconnect")
        if server is not None and server[1] != type_name:
            self._withdraw(session, action, f"{action} was advertised again as {type_name}")
        self._servers[action] = (session, type_name)
        self._spelled[action] = message["type"]
        session.actions[action] = type_name
        self._offer(session, action, type_name)

    def _offer(self, session: Session, action: str, type_name: str) -> None:
        """Offer a client's action on the graph too, if one is attached."""
        if self._graph is None or action in self._offered:
            return
        on_goal: GoalHandler = functools.partial(self._goal_from_graph, action)
        try:
            self._graph.advertise_action(action, type_name, on_goal)
        except BridgeError as error:
            session.report(f"{error}; {action} is served to clients only")
            return
        self._offered.add(action)

    def _unadvertise(self, session: Session, message: dict[str, Any]) -> None:
        action = message["action"]
        if action in session.actions:
            self._withdraw(session, action, f"{action} was unadvertised by its action server")

    def _withdraw(self, session: Session, action: str, reason: str) -> None:
        session.actions.pop(action, None)
        self._servers.pop(action, None)
        self._spelled.pop(action, None)
        for key, goal in list(self._goals.items()):
            if goal.server is session and goal.action == action:
                self._finish(key, reason, GoalStatus.ABORTED, False)
        if action in self._offered:
            self._offered.discard(action)
            if self._graph is not None:
                self._graph.unadvertise_action(action)

    # ---- the goal table -------------------------------------------------------------------

    def _register(self, goal: _Goal) -> str:
        key = f"action_goal:{goal.action}:{next(self._numbers)}"
        self._goals[key] = goal
        if goal.owner is not None:
            self._sent_counts[goal.owner] = self._sent_counts.get(goal.owner, 0) + 1
            if goal.owner_id is not None:
                self._by_owner[(goal.owner, goal.owner_id)] = key
        if goal.server is not None:
            self._served_counts[goal.action] = self._served_counts.get(goal.action, 0) + 1
        return key

    def _drop(self, key: str) -> _Goal | None:
        """Forget a goal without answering it."""
        goal = self._goals.pop(key, None)
        if goal is None:
            return None
        if goal.owner is not None:
            left = self._sent_counts.pop(goal.owner, 1) - 1
            if left:
                self._sent_counts[goal.owner] = left
            self._by_owner.pop((goal.owner, goal.owner_id), None)
        if goal.server is not None:
            left = self._served_counts.pop(goal.action, 1) - 1
            if left:
                self._served_counts[goal.action] = left
        return goal

    def _finish(self, key: str, values: Any, status: GoalStatus, result: bool) -> None:
        """Answer a goal's sender with its end, and forget the goal."""
        goal = self._drop(key)
        if goal is not None:
            goal.sender.goal_result(values, status, result)

    def _graph_feedback(self, key: str, values: Mapping[str, Any]) -> None:
        goal = self._goals.get(key)
        if goal is not None:
            goal.sender.goal_feedback(values)


@dataclass
class _Relay:
    """The sender the graph answers for a client's goal: it finds the goal by key."""

    actions: Actions
    key: str

    def goal_feedback(self, values: Mapping[str, Any]) -> None:
        self.actions._graph_feedback(self.key, values)

    def goal_result(self, values: Any, status: GoalStatus, result: bool) -> None:
        self.actions._finish(self.key, values, status, result)


def goal_args(action_type: str, args: Any) -> Any:
    """A goal's args in canonical form, where the action's type is known (as requests are).

    rosbridge fills the ROS goal from them: a field the type lacks or a value of the wrong
    type fails the goal, missing fields take defaults; an unknown type's args pass as they
    are (its server checks them).

    Raises:
        BridgeError: the args do not fit the goal type.
    """
    goal_type = f"{action_type}_Goal"
    if not definitions.known(goal_type):
        return args
    if args in ([], None):  # roslibpy and roslibjs send [] for an empty goal
        args = {}
    try:
        return definitions.canonical(goal_type, args)
    except ValueError as error:  # MessageError
        raise BridgeError(f"the goal does not fit {action_type}: {error}") from None


def _action_type(action: str, type_name: str) -> str:
    try:
        return normalize_action_type(type_name)
    except ValueError as error:
        raise BridgeError(f"{action}: {error}") from None


def _nothing() -> None:
    """Cancels nothing: the goal was answered already."""
