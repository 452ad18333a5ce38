"""ROS 2 actions over rosbridge (send_action_goal ... action_result) against real ``websim serve``.

Real clients only: roslibpy's ``ActionClient``, roslib 2.x's ``ROSLIB.Action`` under Node
(``node/fibonacci.mjs``; roslib 1.4.1 has no ROS 2 actions) and raw ``websockets``
connections for the edge cases. roslibpy 2.1 has no action server (its protocol answers a
``send_action_goal`` with "Action server capabilities not yet implemented"), so the Python
action servers here speak the protocol over ``websockets``. The action is
example_interfaces' Fibonacci (goal ``order``, feedback and result ``sequence``), computed
here; with ``--ros`` it is test_msgs' Fibonacci, the same fields, on a real rclpy graph.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import roslibpy
from websockets.sync.client import ClientConnection, connect

from rosbridge.core.limits import ClientLimits
from rosbridge.core.schema import GoalStatus

from server_process import ServerProcess, start_server, wait_for

FIBONACCI = "example_interfaces/action/Fibonacci"
NODE = shutil.which("node")
FIBONACCI_JS = Path(__file__).parent / "node" / "fibonacci.mjs"
ROSLIB2 = Path(__file__).parent.parent / "node" / "roslib2" / "node_modules" / "roslib"
ROSLIB2_SKIP = ("node not installed" if NODE is None else None if ROSLIB2.exists() else
                "roslib 2.x missing: run npm ci in tests/node/roslib2/ (scripts/test.sh does)")
TIMEOUT_S = 20.0
"""Every wait's bound: generous, the machine is shared and loaded."""


def fibonacci(order: int) -> list[int]:
    """The Fibonacci action's result for ``order``: 0, 1 and ``order - 1`` more terms."""
    sequence = [0, 1]
    for _ in range(1, order):
        sequence.append(sequence[-1] + sequence[-2])
    return sequence


class Raw:
    """A raw rosbridge connection: send dicts, await the next message of an op."""

    def __init__(self, connection: ClientConnection) -> None:
        self.connection = connection
        self.seen: list[dict[str, Any]] = []

    def send(self, **message: Any) -> None:
        self.connection.send(json.dumps(message))

    def next(self, op: str, timeout_s: float = TIMEOUT_S) -> dict[str, Any]:
        """The next message with ``op``; the others are kept in ``seen``."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"no {op} within {timeout_s} s; seen: {self.seen[-5:]}")
            try:
                message = json.loads(self.connection.recv(timeout=left))
            except TimeoutError:
                continue
            if message.get("op") == op:
                return dict(message)
            self.seen.append(message)

    def advertise(self, action: str, type_name: str = FIBONACCI) -> None:
        """Advertise ``action`` and wait until the bridge has it (a goal of its own comes)."""
        self.send(op="advertise_action", action=action, type=type_name)
        self.send(op="send_action_goal", id="probe", action=action, action_type=type_name,
                  args={"order": 0})
        probe = self.next("send_action_goal")
        self.send(op="action_result", id=probe["id"], action=action,
                  values={"sequence": [0]}, status=int(GoalStatus.SUCCEEDED), result=True)
        assert self.next("action_result")["id"] == "probe"

    def close(self) -> None:
        self.connection.close()


@pytest.fixture
def raw(server: ServerProcess) -> Iterator[Any]:
    """Opens raw connections to the module's server; closes them after the test."""
    with contextlib.ExitStack() as stack:
        yield lambda: Raw(stack.enter_context(connect(server.ws_url, open_timeout=TIMEOUT_S)))


def serve_fibonacci(connection: Raw, action: str, goals: int) -> threading.Thread:
    """Serve ``goals`` Fibonacci goals on ``connection`` in a thread, with feedback per term."""
    def run() -> None:
        for _ in range(goals):
            goal = connection.next("send_action_goal")
            sequence = [0, 1]
            for term in fibonacci(goal["args"]["order"])[2:]:
                sequence.append(term)
                connection.send(op="action_feedback", id=goal["id"], action=action,
                                values={"sequence": list(sequence)})
            connection.send(op="action_result", id=goal["id"], action=action,
                            values={"sequence": sequence}, status=int(GoalStatus.SUCCEEDED),
                            result=True)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


class NodeServer:
    """``node fibonacci.mjs server``: a roslib 2.x action server; its events as JSON lines."""

    def __init__(self, url: str, action: str, step_ms: int) -> None:
        assert NODE is not None
        self.process = subprocess.Popen([NODE, str(FIBONACCI_JS), "server", url, action,
                                         str(step_ms)], stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True)
        self.events: list[dict[str, Any]] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        wait_for(lambda: self._alive() and {"ready": True} in self.events, TIMEOUT_S,
                 "the roslibjs action server to be ready")

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.events.append(json.loads(line))

    def _alive(self) -> bool:
        if self.process.poll() is not None:
            raise AssertionError(f"fibonacci.mjs server exited with {self.process.returncode}:"
                                 f"\n{self.process.communicate()[1]}")
        return True

    def stop(self) -> None:
        self.process.terminate()
        self.process.communicate(timeout=TIMEOUT_S)


def run_node_client(url: str, action: str, order: int) -> dict[str, Any]:
    assert NODE is not None
    result = subprocess.run([NODE, str(FIBONACCI_JS), "client", url, action, str(order)],
                            capture_output=True, text=True, timeout=TIMEOUT_S + 10, check=False)
    assert result.returncode == 0, f"fibonacci.mjs client failed:\n{result.stderr}"
    return dict(json.loads(result.stdout))


class RoslibpyGoal:
    """One goal through roslibpy's ActionClient: its feedback, then result or error."""

    def __init__(self, server: ServerProcess, action: str, order: int,
                 action_type: str = FIBONACCI) -> None:
        self.ros = roslibpy.Ros("127.0.0.1", server.ws_port)
        self.ros.run(timeout=TIMEOUT_S)
        self.client = roslibpy.ActionClient(self.ros, action, action_type)
        self.feedback: list[dict[str, Any]] = []
        self.result: dict[str, Any] | None = None
        self.error: dict[str, Any] | None = None
        self.goal_id = self.client.send_goal(
            roslibpy.Goal({"order": order}), self._on_result,
            lambda feedback: self.feedback.append(dict(feedback)), self._on_error)

    def _on_result(self, result: Any) -> None:
        self.result = dict(result)

    def _on_error(self, error: Any) -> None:
        self.error = dict(error)

    def wait(self) -> None:
        self.client.wait_goal(self.goal_id, timeout=TIMEOUT_S)

    def close(self) -> None:
        self.ros.close()


# ---- real clients --------------------------------------------------------------------------


@pytest.mark.skipif(ROSLIB2_SKIP is not None, reason=ROSLIB2_SKIP or "")
def test_roslibpy_action_client_gets_feedback_and_result_from_a_roslibjs_action_server(
        server: ServerProcess) -> None:
    node_server = NodeServer(server.ws_url, "/fibonacci_js", step_ms=5)
    goal = RoslibpyGoal(server, "/fibonacci_js", order=6)
    try:
        goal.wait()
    finally:
        goal.close()
        node_server.stop()
    assert goal.error is None
    assert goal.result is not None
    assert goal.result["status"] == roslibpy.GoalStatus.SUCCEEDED
    assert goal.result["values"] == {"sequence": fibonacci(6)}
    assert [f["sequence"] for f in goal.feedback] == [fibonacci(n) for n in range(2, 7)]
    received = [e for e in node_server.events if "goal" in e and e["goal"] == {"order": 6}]
    assert len(received) == 1
    assert received[0]["id"].startswith("action_goal:/fibonacci_js:")


@pytest.mark.skipif(ROSLIB2_SKIP is not None, reason=ROSLIB2_SKIP or "")
def test_roslibjs_action_client_gets_feedback_and_result_from_a_python_action_server(
        server: ServerProcess, raw: Any) -> None:
    provider = raw()
    provider.advertise("/fibonacci_py")
    serving = serve_fibonacci(provider, "/fibonacci_py", goals=1)
    answer = run_node_client(server.ws_url, "fibonacci_py", 5)  # relative: resolved to /...
    serving.join(TIMEOUT_S)
    assert answer["ok"], answer
    assert answer["result"] == {"sequence": fibonacci(5)}
    assert answer["feedback"] == [{"sequence": fibonacci(n)} for n in range(2, 6)]


@pytest.mark.skipif(ROSLIB2_SKIP is not None, reason=ROSLIB2_SKIP or "")
def test_roslibjs_goal_to_an_action_nobody_provides_fails_with_status_unknown(
        server: ServerProcess) -> None:
    answer = run_node_client(server.ws_url, "/nobody_serves_this", 3)
    assert not answer["ok"]
    assert answer["reason"] == ("GoalError: Action status unknown: "
                                "Action /nobody_serves_this does not exist")


def test_roslibpy_goal_to_an_action_nobody_provides_fails_at_once(
        server: ServerProcess) -> None:
    goal = RoslibpyGoal(server, "/nobody_here", order=3)
    try:
        goal.wait()
    finally:
        goal.close()
    assert goal.result is None
    assert goal.error == {"status": roslibpy.GoalStatus.UNKNOWN,
                          "values": "Action /nobody_here does not exist"}


# ---- protocol edge cases, raw ------------------------------------------------------------


def test_cancel_action_goal_reaches_the_server_and_the_sender_gets_status_canceled(
        raw: Any) -> None:
    provider, sender = raw(), raw()
    provider.advertise("/cancellable")
    sender.send(op="send_action_goal", id=7, action="/cancellable", action_type=FIBONACCI,
                args={"order": 50}, feedback=True)
    goal = provider.next("send_action_goal")
    assert goal["args"] == {"order": 50} and goal["feedback"] is True
    provider.send(op="action_feedback", id=goal["id"], action="/cancellable",
                  values={"sequence": [0, 1, 1]})
    assert sender.next("action_feedback") == {"op": "action_feedback", "id": 7,
                                              "action": "/cancellable",
                                              "values": {"sequence": [0, 1, 1]}}
    sender.send(op="cancel_action_goal", id=7, action="/cancellable")
    assert provider.next("cancel_action_goal") == {"op": "cancel_action_goal",
                                                   "id": goal["id"], "action": "/cancellable"}
    provider.send(op="action_result", id=goal["id"], action="/cancellable",
                  values={"sequence": [0, 1, 1]}, status=int(GoalStatus.CANCELED), result=True)
    assert sender.next("action_result") == {
        "op": "action_result", "id": 7, "action": "/cancellable",
        "values": {"sequence": [0, 1, 1]}, "status": GoalStatus.CANCELED, "result": True}


def test_a_server_result_false_reaches_the_sender_as_status_aborted(raw: Any) -> None:
    """rosbridge aborts the goal on the server's ``result: false`` (roslib's setFailed)."""
    provider, sender = raw(), raw()
    provider.advertise("/failing")
    sender.send(op="send_action_goal", id="g", action="/failing", action_type=FIBONACCI,
                args={"order": 2})
    goal = provider.next("send_action_goal")
    provider.send(op="action_result", id=goal["id"], action="/failing",
                  status=int(GoalStatus.ABORTED), result=False)
    answer = sender.next("action_result")
    assert (answer["status"], answer["result"], answer["values"]) == (GoalStatus.ABORTED,
                                                                      True, {})


def test_a_server_that_disconnects_mid_goal_fails_the_goal_with_status_aborted(
        raw: Any) -> None:
    provider, sender = raw(), raw()
    provider.advertise("/leaving")
    sender.send(op="send_action_goal", id="g1", action="/leaving", action_type=FIBONACCI,
                args={"order": 9}, feedback=True)
    provider.next("send_action_goal")
    provider.close()
    answer = sender.next("action_result")
    assert answer == {"op": "action_result", "id": "g1", "action": "/leaving",
                      "values": "the action server of /leaving disconnected",
                      "status": GoalStatus.ABORTED, "result": False}
    sender.send(op="send_action_goal", id="g2", action="/leaving", action_type=FIBONACCI)
    assert sender.next("action_result")["values"] == "Action /leaving does not exist"


def test_unadvertise_action_fails_pending_goals_and_frees_the_name(raw: Any) -> None:
    provider, sender, successor = raw(), raw(), raw()
    provider.advertise("/handover")
    sender.send(op="send_action_goal", id="g", action="/handover", action_type=FIBONACCI)
    provider.next("send_action_goal")
    provider.send(op="unadvertise_action", action="/handover")
    answer = sender.next("action_result")
    assert (answer["status"], answer["result"]) == (GoalStatus.ABORTED, False)
    assert answer["values"] == "/handover was unadvertised by its action server"
    successor.advertise("/handover")  # its own probe goal reached it: the name is free


def test_a_second_client_cannot_advertise_an_action_already_provided(raw: Any) -> None:
    first, second, sender = raw(), raw(), raw()
    first.advertise("/taken")
    second.send(op="set_level", level="error")
    second.send(op="advertise_action", action="/taken", type=FIBONACCI)
    status = second.next("status")
    assert "already provided by another client" in status["msg"]
    sender.send(op="send_action_goal", id="g", action="/taken", action_type=FIBONACCI)
    assert first.next("send_action_goal")["action"] == "/taken"


def test_actions_in_the_simulators_namespaces_are_refused(raw: Any) -> None:
    client = raw()
    client.send(op="set_level", level="error")
    client.send(op="advertise_action", action="/websim/mine", type=FIBONACCI)
    assert "belong to the simulator" in client.next("status")["msg"]


def test_more_goals_than_max_goals_fail_at_once_the_earlier_stay_pending(raw: Any) -> None:
    limit = ClientLimits().max_goals
    provider, sender = raw(), raw()
    provider.advertise("/busy")
    for n in range(limit + 1):
        sender.send(op="send_action_goal", id=n, action="/busy", action_type=FIBONACCI,
                    args={"order": 1})
    refused = sender.next("action_result")
    assert refused["id"] == limit and refused["result"] is False
    assert refused["status"] == GoalStatus.UNKNOWN
    assert f"at most {limit} goals pending" in refused["values"]
    forwarded = [provider.next("send_action_goal") for _ in range(limit)]
    provider.send(op="action_result", id=forwarded[0]["id"], action="/busy",
                  values={"sequence": [0, 1]}, status=int(GoalStatus.SUCCEEDED), result=True)
    assert sender.next("action_result")["id"] == 0


@pytest.mark.parametrize(("fields", "reason"), [
    ({"args": 5}, "field 'args' must be dict or list"),
    ({"action_type": "example_interfaces/msg/Fibonacci"}, "not an action type"),
    ({"action": "/bad name"}, "is not a ROS name"),
    ({"feedback": "yes"}, "field 'feedback' must be bool"),
])
def test_a_goal_with_bad_fields_is_answered_with_the_reason(raw: Any, fields: dict[str, Any],
                                                            reason: str) -> None:
    client = raw()
    goal = {"op": "send_action_goal", "id": "bad", "action": "/x", "action_type": FIBONACCI,
            **fields}
    client.send(**goal)
    answer = client.next("action_result")
    assert (answer["id"], answer["result"], answer["status"]) == ("bad", False,
                                                                  GoalStatus.UNKNOWN)
    assert reason in answer["values"]


def test_answers_to_goals_a_client_is_not_serving_are_refused(raw: Any) -> None:
    provider, sender, stranger = raw(), raw(), raw()
    provider.advertise("/guarded")
    sender.send(op="send_action_goal", id="g", action="/guarded", action_type=FIBONACCI)
    goal = provider.next("send_action_goal")
    stranger.send(op="set_level", level="error")
    stranger.send(op="action_result", id=goal["id"], action="/guarded", values={},
                  status=int(GoalStatus.SUCCEEDED), result=True)
    assert "is waiting for this client's answer" in stranger.next("status")["msg"]
    stranger.send(op="action_result", id=goal["id"], action="/guarded", status=9, result=True)
    assert "'status' must be between 0 and 6" in stranger.next("status")["msg"]
    provider.send(op="action_result", id=goal["id"], action="/guarded",
                  values={"sequence": [0]}, status=int(GoalStatus.SUCCEEDED), result=True)
    answer = sender.next("action_result")
    assert (answer["values"], answer["status"]) == ({"sequence": [0]}, GoalStatus.SUCCEEDED)


# ---- websim serve --ros: the ROS 2 graph's actions ----------------------------------------

ROS_FIBONACCI = "test_msgs/action/Fibonacci"
"""The Fibonacci action PyPI's ROS 2 wheels carry (ros-test-msgs); example_interfaces'
has the same fields."""


FEEDBACK_PERIOD_S = 0.1
"""Between two feedbacks of the graph's test server (the ROS tutorials' server waits 1 s)."""


def assert_feedback_in_order(feedback: list[list[int]], order: int) -> None:
    """Feedback crossed the graph: each a longer Fibonacci prefix than the one before.

    On ROS 2, feedback is a topic and the result a service: the last feedback may arrive
    after the result (and be dropped with the goal), so not every step is required.
    """
    assert feedback, "no feedback crossed the graph"
    assert feedback == sorted(feedback, key=len)
    assert all(steps == fibonacci(len(steps) - 1) for steps in feedback)
    assert len(feedback[-1]) <= order + 1


@pytest.fixture
def ros_graph(monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """An rclpy node of this test's own domain (``ros_fixtures.Graph``), spun while waiting."""
    pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
    pytest.importorskip("test_msgs.action", reason="test_msgs not installed "
                                                   "(pip install ros-test-msgs)")
    import ros_fixtures

    domain_id = next(ros_fixtures.DOMAIN_IDS)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain_id))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOCALHOST_ONLY", "1")
    graph = ros_fixtures.Graph(domain_id)
    yield graph
    graph.close()


@pytest.fixture
def ros_server(ros_graph: Any) -> Iterator[ServerProcess]:
    running = start_server(["--ros"])
    yield running
    code = running.stop()
    assert code == 0, f"websim serve --ros exited with {code}:\n{''.join(running.output)}"


def test_serve_ros_roslibpy_goal_reaches_an_rclpy_action_server_on_the_graph(
        ros_graph: Any, ros_server: ServerProcess) -> None:
    from rclpy.action.server import ActionServer
    from test_msgs.action import Fibonacci

    def execute(goal_handle: Any) -> Any:
        sequence = [0, 1]
        for term in fibonacci(goal_handle.request.order)[2:]:
            sequence.append(term)
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
            time.sleep(FEEDBACK_PERIOD_S)  # as the tutorials' server; its feedback topic may
            # match the client a moment after the goal's service does
        goal_handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    ActionServer(ros_graph.node, Fibonacci, "/fibonacci_ros", execute)

    def answered_goal() -> RoslibpyGoal | None:
        """A goal's answer, once websim has discovered the server (before: "does not exist")."""
        goal = RoslibpyGoal(ros_server, "/fibonacci_ros", 5, ROS_FIBONACCI)
        try:
            ros_graph.spin_until(lambda: goal.result or goal.error, TIMEOUT_S, "an answer")
        finally:
            goal.close()
        reason = str(goal.error["values"]) if goal.error else ""
        if "does not exist" in reason or "did not answer within" in reason:
            # not discovered yet (a loaded machine's DDS discovery may take longer than the
            # bridge's 2 s wait for a new action client): send another goal
            ros_graph.executor.spin_once(timeout_sec=0.2)
            return None
        return goal

    goal = wait_for(answered_goal, TIMEOUT_S * 2, "websim to send a goal to the graph")
    assert goal.error is None, goal.error
    assert goal.result is not None
    assert goal.result["status"] == roslibpy.GoalStatus.SUCCEEDED
    assert goal.result["values"] == {"sequence": fibonacci(5)}
    assert_feedback_in_order([f["sequence"] for f in goal.feedback], order=5)


def test_serve_ros_a_client_provided_action_serves_rclpy_goals_on_the_graph(
        ros_graph: Any, ros_server: ServerProcess) -> None:
    from rclpy.action.client import ActionClient
    from test_msgs.action import Fibonacci

    with connect(ros_server.ws_url, open_timeout=TIMEOUT_S) as connection:
        provider = Raw(connection)
        provider.advertise("/fibonacci_offered", ROS_FIBONACCI)
        serving = serve_fibonacci(provider, "/fibonacci_offered", goals=1)
        client = ActionClient(ros_graph.node, Fibonacci, "/fibonacci_offered")
        ros_graph.spin_until(client.server_is_ready, TIMEOUT_S, "the offered action server")
        feedback: list[list[int]] = []
        sent = client.send_goal_async(Fibonacci.Goal(order=4), feedback_callback=lambda
                                      message: feedback.append(list(message.feedback.sequence)))
        ros_graph.spin_until(sent.done, TIMEOUT_S, "the goal to be accepted")
        handle = sent.result()
        assert handle.accepted
        result = handle.get_result_async()
        ros_graph.spin_until(result.done, TIMEOUT_S, "the result")
        serving.join(TIMEOUT_S)
    assert result.result().status == GoalStatus.SUCCEEDED
    assert list(result.result().result.sequence) == fibonacci(4)
    assert_feedback_in_order(feedback, order=4)


def test_the_server_gets_the_action_type_as_it_advertised_it(raw: Any) -> None:
    """rosbridge echoes the server's own spelling (``pkg/Type``), not a normalised one."""
    provider, sender = raw(), raw()
    provider.send(op="advertise_action", action="/spelled", type="example_interfaces/Fibonacci")
    time.sleep(0.1)
    sender.send(op="send_action_goal", id="s", action="/spelled", action_type=FIBONACCI,
                args={"order": 1})
    assert provider.next("send_action_goal")["action_type"] == "example_interfaces/Fibonacci"
