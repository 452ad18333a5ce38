"""rosbridge_server/test/websocket/*.test.py, each as a body against websim.

Upstream starts rosbridge_websocket, gives the test an rclpy node and a Twisted WebSocket
client, and exchanges JSON. Here the client is ``wire_client.TracedClient`` on websim's URL;
in ``ros`` mode the node is rclpy (``ros_side``) against ``websim serve --ros``; in ``plain``
mode a second rosbridge client (``peer``) does what the node did, through the bridge (what a
rosbridge client sees of another rosbridge client is what it sees of a ROS node). The
expectations are upstream's: the same messages, the same counts, the same fields.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from cases import Case, Context, expect, expect_equal
from ros_side import until

SERVER = "rosbridge_server/test/websocket"
STATUS_SUCCEEDED = 4
"""action_msgs/GoalStatus STATUS_SUCCEEDED."""


def _std_string() -> Any:
    from std_msgs.msg import String

    return String


async def smoke(ctx: Context) -> None:
    """smoke.test.py: 10 publishes each way, the websocket side with queue_length 0."""
    count, a_string, b_string = 10, "A" * 10, "B" * 10
    ws = await ctx.client("ws")
    ros_received: list[Any] = []
    if ctx.on_graph:
        string = _std_string()
        ctx.node.create_subscription(string, "/a_topic", lambda m: ros_received.append(m.data),
                                     count)
        pub_b = ctx.node.create_publisher(string, "/b_topic", count)
    else:
        peer = await ctx.client("peer")
        await peer.send({"op": "subscribe", "topic": "/a_topic", "type": "std_msgs/String",
                         "queue_length": count})
        await peer.send({"op": "advertise", "topic": "/b_topic", "type": "std_msgs/String"})
    await ws.send({"op": "subscribe", "topic": "/b_topic", "type": "std_msgs/String",
                   "queue_length": 0})
    await ws.send({"op": "advertise", "topic": "/a_topic", "type": "std_msgs/String"})
    await asyncio.sleep(1.0)
    await ws.send({"op": "publish", "topic": "/a_topic", "msg": {"data": a_string}}, times=count)
    if ctx.on_graph:
        for _ in range(count):
            pub_b.publish(string(data=b_string))
    else:
        await peer.send({"op": "publish", "topic": "/b_topic", "msg": {"data": b_string}},
                        times=count)
    ws_received = await ws.collect(count, 10, "publish on /b_topic")
    for message in ws_received:
        expect_equal((message.get("op"), message.get("topic"), message.get("msg")),
                     ("publish", "/b_topic", {"data": b_string}), "websocket message")
    if ctx.on_graph:
        await until(lambda: len(ros_received) >= count, 10, f"{count} messages on the graph")
        expect_equal(ros_received, [a_string] * count, "what the ROS subscriber received")
    else:
        got = await peer.collect(count, 10, "publish on /a_topic")
        expect_equal([m.get("msg") for m in got], [{"data": a_string}] * count,
                     "what the peer subscriber received")


async def _action_client_goals(ctx: Context, orders: list[int], feedback: bool) -> Any:
    """Send goals from the 'node' side; returns a function awaiting (results, feedbacks)."""
    if ctx.on_graph:
        from example_interfaces.action import Fibonacci
        from rclpy.action.client import ActionClient

        client: Any = ActionClient(ctx.node, Fibonacci, "/test_fibonacci_action")
        await until(lambda: client.server_is_ready(), 10,
                    "the advertised action server on the graph")
        feedbacks: list[Any] = []
        handles = [client.send_goal_async(
            Fibonacci.Goal(order=order),
            feedback_callback=(lambda m: feedbacks.append(list(m.feedback.sequence)))
            if feedback else None) for order in orders]

        async def results() -> tuple[list[Any], list[Any]]:
            goals: list[Any] = []
            for handle in handles:
                await until(handle.done, 10, "the goal response")
                goals.append(handle.result())
                expect(goals[-1].accepted, "goal not accepted")
            futures: list[Any] = [goal.get_result_async() for goal in goals]
            for future in futures:
                await until(future.done, 10, "the action result")
            return [list(f.result().result.sequence) for f in futures], feedbacks
        return results
    peer = await ctx.client("peer")
    for n, order in enumerate(orders, 1):
        await peer.send({"op": "send_action_goal", "id": f"goal{n}",
                         "action": "/test_fibonacci_action",
                         "action_type": "example_interfaces/Fibonacci",
                         "args": {"order": order}, "feedback": feedback})

    async def peer_results() -> tuple[list[Any], list[Any]]:
        results: dict[str, Any] = {}
        feedbacks: list[Any] = []
        deadline = time.monotonic() + 10
        while len(results) < len(orders):
            message = await peer.next(max(0.1, deadline - time.monotonic()), "action_result")
            if message.get("op") == "action_feedback":
                feedbacks.append(message.get("values", {}).get("sequence"))
            elif message.get("op") == "action_result":
                expect_equal(message.get("status"), STATUS_SUCCEEDED, "action_result status")
                expect_equal(message.get("result"), True, "action_result result")
                results[message.get("id")] = message.get("values", {}).get("sequence")
            else:
                raise AssertionError(f"peer: unexpected {message!r}")
        return [results.get(f"goal{n}") for n in range(1, len(orders) + 1)], feedbacks
    return peer_results


def _check_goal_request(request: Any, order: int) -> None:
    expect_equal(request.get("op"), "send_action_goal", "op")
    expect_equal(request.get("action"), "/test_fibonacci_action", "action")
    expect_equal(request.get("action_type"), "example_interfaces/Fibonacci", "action_type")
    expect_equal(request.get("args"), {"order": order}, "args")


async def advertise_action(ctx: Context) -> None:
    """advertise_action.test.py: two concurrent goals to a websocket-advertised action."""
    ws = await ctx.client("ws")
    await ws.send({"op": "advertise_action", "action": "/test_fibonacci_action",
                   "type": "example_interfaces/Fibonacci"})
    await asyncio.sleep(0.5)
    results = await _action_client_goals(ctx, [3, 5], feedback=False)
    requests = await ws.collect(2, 10, "send_action_goal")
    requests.sort(key=lambda r: r.get("args", {}).get("order", 0))
    sequences = [[0, 1, 1, 2], [0, 1, 1, 2, 3, 5]]
    for request, order, sequence in zip(requests, [3, 5], sequences, strict=False):
        _check_goal_request(request, order)
        await ws.send({"op": "action_result", "action": "/test_fibonacci_action",
                       "values": {"sequence": sequence}, "status": STATUS_SUCCEEDED,
                       "id": request.get("id"), "result": True})
    got, _ = await results()
    expect_equal(got, sequences, "action results")


async def advertise_action_feedback(ctx: Context) -> None:
    """advertise_action_feedback.test.py: feedback then result from the websocket server."""
    ws = await ctx.client("ws")
    await ws.send({"op": "advertise_action", "action": "/test_fibonacci_action",
                   "type": "example_interfaces/Fibonacci"})
    await asyncio.sleep(0.5)
    results = await _action_client_goals(ctx, [5], feedback=True)
    (request,) = await ws.collect(1, 10, "send_action_goal")
    _check_goal_request(request, 5)
    await ws.send({"op": "action_feedback", "action": "/test_fibonacci_action",
                   "values": {"sequence": [0, 1, 1, 2]}, "id": request.get("id")})
    await ws.send({"op": "action_result", "action": "/test_fibonacci_action",
                   "values": {"sequence": [0, 1, 1, 2, 3, 5]}, "status": STATUS_SUCCEEDED,
                   "id": request.get("id"), "result": True})
    got, feedbacks = await results()
    expect(bool(feedbacks), "no feedback reached the action client")
    expect_equal(feedbacks[-1], [0, 1, 1, 2], "latest feedback")
    expect_equal(got, [[0, 1, 1, 2, 3, 5]], "action result")


async def _service_calls(ctx: Context, datas: list[bool]) -> Any:
    """Call /test_service (std_srvs/SetBool) from the 'node' side; returns an awaiter."""
    if ctx.on_graph:
        from std_srvs.srv import SetBool

        client = ctx.node.create_client(SetBool, "/test_service")
        await until(client.service_is_ready, 10, "/test_service on the graph")
        futures = [client.call_async(SetBool.Request(data=d)) for d in datas]

        async def responses() -> list[Any]:
            for future in futures:
                await until(future.done, 10, "the service response")
            return [(f.result().success, f.result().message) for f in futures]
        return responses
    peer = ctx.clients[-1] if ctx.clients and ctx.clients[-1].name == "peer" else \
        await ctx.client("peer")
    for n, data in enumerate(datas, 1):
        await peer.send({"op": "call_service", "service": "/test_service", "id": f"call{n}",
                         "args": {"data": data}})

    async def peer_responses() -> list[Any]:
        got = await peer.collect(len(datas), 10, "service_response")
        by_id = {m.get("id"): m for m in got}
        out = []
        for n in range(1, len(datas) + 1):
            message = by_id.get(f"call{n}", {})
            expect_equal(message.get("result"), True, f"call{n} result")
            values = message.get("values", {})
            out.append((values.get("success"), values.get("message")))
        return out
    return peer_responses


async def advertise_service(ctx: Context) -> None:
    """advertise_service.test.py: two concurrent calls to a websocket-advertised service."""
    ws = await ctx.client("ws")
    await ws.send({"op": "advertise_service", "type": "std_srvs/SetBool",
                   "service": "/test_service"})
    await asyncio.sleep(0.5)
    responses = await _service_calls(ctx, [True, False])
    requests = await ws.collect(2, 10, "call_service")
    texts = ["Hello world 1", "Hello world 2"]
    for request, data, text in zip(requests, [True, False], texts, strict=False):
        expect_equal(request.get("op"), "call_service", "op")
        expect_equal(request.get("service"), "/test_service", "service")
        expect_equal(request.get("args"), {"data": data}, "args")
        await ws.send({"op": "service_response", "service": "/test_service",
                       "values": {"success": True, "message": text},
                       "id": request.get("id"), "result": True})
    expect_equal(await responses(), [(True, "Hello world 1"), (True, "Hello world 2")],
                 "responses")


async def advertise_service_duplicate(ctx: Context) -> None:
    """advertise_service_duplicate.test.py: a second client re-advertises after the first left."""
    ws1 = await ctx.client("ws1")
    await ws1.send({"op": "advertise_service", "type": "std_srvs/SetBool",
                    "service": "/test_service"})
    await asyncio.sleep(0.5)
    await _service_calls(ctx, [True])
    requests1 = await ws1.collect(1, 10, "call_service")
    expect_equal(requests1, [{"op": "call_service", "service": "/test_service",
                              "id": "service_request:/test_service:1",
                              "args": {"data": True}}], "request to ws1")
    await ws1.close()
    ws2 = await ctx.client("ws2")
    await ws2.send({"op": "advertise_service", "type": "std_srvs/SetBool",
                    "service": "/test_service"})
    await asyncio.sleep(1.0)
    if ctx.on_graph:
        responses = await _service_calls(ctx, [False])
    else:
        peer = next(c for c in ctx.clients if c.name == "peer")
        await peer.drain(0.2)  # the first call's failure, if the server answered it
        await peer.send({"op": "call_service", "service": "/test_service", "id": "call2",
                         "args": {"data": False}})
    requests2 = await ws2.collect(1, 10, "call_service")
    expect_equal(requests2, [{"op": "call_service", "id": "service_request:/test_service:1",
                              "service": "/test_service", "args": {"data": False}}],
                 "request to ws2")
    await ws2.send({"op": "service_response", "service": "/test_service",
                    "values": {"success": True, "message": "Hello world 2"},
                    "id": "service_request:/test_service:1", "result": True})
    if ctx.on_graph:
        expect_equal(await responses(), [(True, "Hello world 2")], "response")
    else:
        message = await peer.next(10, "service_response")
        expect_equal((message.get("id"), message.get("result"), message.get("values")),
                     ("call2", True, {"success": True, "message": "Hello world 2"}), "response")


async def best_effort_publisher(ctx: Context) -> None:
    """best_effort_publisher.test.py: a BEST_EFFORT publisher reaches a websocket subscriber."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    string = _std_string()
    qos = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT,
                     history=HistoryPolicy.SYSTEM_DEFAULT)
    pub = ctx.node.create_publisher(string, "/a_topic", qos_profile=qos)
    await asyncio.sleep(1.0)
    ws = await ctx.client("ws1")
    await ws.send({"op": "subscribe", "topic": "/a_topic", "type": "std_msgs/String"})
    await asyncio.sleep(1.0)
    pub.publish(string(data="hello"))
    expect_equal(await ws.collect(1, 10, "publish"),
                 [{"op": "publish", "topic": "/a_topic", "msg": {"data": "hello"}}], "received")


async def call_service(ctx: Context) -> None:
    """call_service.test.py: a websocket call to a service the 'node' provides."""
    ws = await ctx.client("ws")
    if ctx.on_graph:
        from rclpy.callback_groups import ReentrantCallbackGroup
        from std_srvs.srv import SetBool

        def serve(request: Any, response: Any) -> Any:
            response.success = bool(request.data)
            response.message = "Hello, world!"
            return response
        ctx.node.create_service(SetBool, "/test_service", serve,
                                callback_group=ReentrantCallbackGroup())
        await asyncio.sleep(0.5)
    else:
        peer = await ctx.client("peer")
        await peer.send({"op": "advertise_service", "type": "std_srvs/SetBool",
                         "service": "/test_service"})
        await asyncio.sleep(0.5)
    await ws.send({"op": "call_service", "type": "std_srvs/SetBool",
                   "service": "/test_service", "args": {"data": True}})
    if not ctx.on_graph:
        request = await peer.next(10, "call_service")
        expect_equal(request.get("args"), {"data": True}, "request args")
        await peer.send({"op": "service_response", "service": "/test_service",
                         "id": request.get("id"), "result": True,
                         "values": {"success": True, "message": "Hello, world!"}})
    (response,) = await ws.collect(1, 10, "service_response")
    expect_equal(response.get("op"), "service_response", "op")
    expect_equal(response.get("service"), "/test_service", "service")
    expect_equal(response.get("values"), {"success": True, "message": "Hello, world!"},
                 "values")
    expect_equal(response.get("result"), True, "result")


async def _publish_hello_from_node(ctx: Context, peer_name: str = "peer") -> Any:
    """Create the 'node' publisher of /a_topic; returns an async function publishing 'hello'."""
    if ctx.on_graph:
        string = _std_string()
        pub = ctx.node.create_publisher(string, "/a_topic", 1)

        async def publish() -> None:
            pub.publish(string(data="hello"))
        return publish
    peer = await ctx.client(peer_name)
    await peer.send({"op": "advertise", "topic": "/a_topic", "type": "std_msgs/String"})

    async def peer_publish() -> None:
        await peer.send({"op": "publish", "topic": "/a_topic", "msg": {"data": "hello"}})
    return peer_publish


async def multiple_subscribers(ctx: Context) -> None:
    """multiple_subscribers.test.py: two websocket subscribers both get the one message."""
    subscribers = []
    for name in ("ws1", "ws2"):
        client = await ctx.client(name)
        await client.send({"op": "subscribe", "topic": "/a_topic", "type": "std_msgs/String"})
        subscribers.append(client)
    publish = await _publish_hello_from_node(ctx)
    await asyncio.sleep(1.0)
    await publish()
    for client in subscribers:
        expect_equal(await client.collect(1, 10, "publish"),
                     [{"op": "publish", "topic": "/a_topic", "msg": {"data": "hello"}}],
                     f"{client.name} received")


async def multiple_subscribers_raw(ctx: Context) -> None:
    """multiple_subscribers_raw.test.py: the same with compression cbor-raw (any message)."""
    subscribers = []
    for name in ("ws1", "ws2"):
        client = await ctx.client(name)
        await client.send({"op": "subscribe", "topic": "/a_topic", "type": "std_msgs/String",
                           "compression": "cbor-raw"})
        subscribers.append(client)
    publish = await _publish_hello_from_node(ctx)
    await asyncio.sleep(1.0)
    await publish()
    await asyncio.sleep(1.0)
    for client in subscribers:
        received = await client.next_framed(10, "publish")
        expect(bool(received.message), f"{client.name}: empty message")
        ctx.note(f"{client.name} got a {received.framing} frame (upstream sends CBOR with "
                 "msg {secs, nsecs, bytes}; the test asserts only that one arrives)")


async def send_action_goal(ctx: Context) -> None:
    """send_action_goal.test.py: a websocket goal to the 'node's action server, with feedback."""
    expected = [0, 1, 1, 2, 3, 5]
    if ctx.on_graph:
        from example_interfaces.action import Fibonacci
        from rclpy.action.server import ActionServer, CancelResponse
        from rclpy.callback_groups import ReentrantCallbackGroup

        def execute(goal: Any) -> Any:
            feedback = Fibonacci.Feedback()
            feedback.sequence = [0, 1]
            for i in range(1, goal.request.order):
                if goal.is_cancel_requested:
                    goal.canceled()
                    return Fibonacci.Result()
                feedback.sequence.append(feedback.sequence[i] + feedback.sequence[i - 1])
                goal.publish_feedback(feedback)
                time.sleep(0.5)
            goal.succeed()
            return Fibonacci.Result(sequence=feedback.sequence)
        server = ActionServer(ctx.node, Fibonacci, "/test_fibonacci_action",
                              execute_callback=execute,
                              cancel_callback=lambda _: CancelResponse.ACCEPT,
                              callback_group=ReentrantCallbackGroup())
        del server
    else:
        peer = await ctx.client("peer")
        await peer.send({"op": "advertise_action", "action": "/test_fibonacci_action",
                         "type": "example_interfaces/Fibonacci"})
    await asyncio.sleep(0.5)
    ws = await ctx.client("ws")
    await ws.send({"op": "send_action_goal", "action": "/test_fibonacci_action",
                   "action_type": "example_interfaces/Fibonacci", "args": {"order": 5},
                   "feedback": True})
    if not ctx.on_graph:
        request = await peer.next(10, "send_action_goal")
        _check_goal_request(request, 5)
        for n in range(3, 7):
            await peer.send({"op": "action_feedback", "action": "/test_fibonacci_action",
                             "id": request.get("id"), "values": {"sequence": expected[:n]}})
        await peer.send({"op": "action_result", "action": "/test_fibonacci_action",
                         "id": request.get("id"), "values": {"sequence": expected},
                         "status": STATUS_SUCCEEDED, "result": True})
    responses = await ws.collect(5, 15, "action_feedback/action_result")
    for idx in range(4):
        expect_equal(responses[idx].get("op"), "action_feedback", f"message {idx} op")
        expect_equal(responses[idx].get("values", {}).get("sequence"), expected[: idx + 3],
                     f"feedback {idx}")
    last = responses[-1]
    expect_equal(last.get("op"), "action_result", "last op")
    expect_equal(last.get("action"), "/test_fibonacci_action", "action")
    expect_equal(last.get("values", {}).get("sequence"), expected, "result sequence")
    expect_equal(last.get("status"), STATUS_SUCCEEDED, "status")
    expect_equal(last.get("result"), True, "result")


async def transient_local_publisher(ctx: Context) -> None:
    """transient_local_publisher.test.py: three late subscribers each get the latched message."""
    if ctx.on_graph:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile

        string = _std_string()
        qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         history=HistoryPolicy.KEEP_LAST)
        pub = ctx.node.create_publisher(string, "/a_topic", qos_profile=qos)
        await asyncio.sleep(1.0)
        pub.publish(string(data="hello"))
    else:
        peer = await ctx.client("peer")
        await peer.send({"op": "advertise", "topic": "/a_topic", "type": "std_msgs/String",
                         "latch": True})
        await asyncio.sleep(1.0)
        await peer.send({"op": "publish", "topic": "/a_topic", "msg": {"data": "hello"}})
    await asyncio.sleep(1.0)
    for num in range(3):
        ws = await ctx.client(f"ws{num}")
        await ws.send({"op": "subscribe", "topic": "/a_topic", "type": "std_msgs/String"})
        expect_equal(await ws.collect(1, 10, "publish"),
                     [{"op": "publish", "topic": "/a_topic", "msg": {"data": "hello"}}],
                     f"ws{num} received")


def _case(file: str, cls: str, test: str, body: Any, **kwargs: Any) -> Case:
    return Case("rosbridge_server", f"{SERVER}/{file}::{cls}::{test}", body, **kwargs)


CASES = [
    _case("advertise_action.test.py", "TestAdvertiseAction", "test_two_concurrent_calls",
          advertise_action),
    _case("advertise_action_feedback.test.py", "TestActionFeedback", "test_feedback",
          advertise_action_feedback),
    _case("advertise_service.test.py", "TestAdvertiseService", "test_two_concurrent_calls",
          advertise_service),
    _case("advertise_service_duplicate.test.py", "TestAdvertiseService",
          "test_double_advertise", advertise_service_duplicate,
          note="not in upstream's CMakeLists (not run by upstream's CI)"),
    _case("best_effort_publisher.test.py", "TestBestEffortPublisher",
          "test_best_effort_publisher", best_effort_publisher,
          not_applicable={"plain": "QoS reliability exists only between ROS 2 nodes: without "
                                   "a graph there is no BEST_EFFORT publisher"}),
    _case("call_service.test.py", "TestCallService", "test_one_call", call_service),
    _case("multiple_subscribers.test.py", "TestMultipleSubscribers",
          "test_multiple_subscribers", multiple_subscribers,
          note="not in upstream's CMakeLists (not run by upstream's CI)"),
    _case("multiple_subscribers_raw.test.py", "TestMultipleSubscribers",
          "test_multiple_subscribers", multiple_subscribers_raw),
    _case("send_action_goal.test.py", "TestSendActionGoal", "test_one_call", send_action_goal),
    _case("smoke.test.py", "TestWebsocketSmoke", "test_smoke", smoke),
    _case("transient_local_publisher.test.py", "TestTransientLocalPublisher",
          "test_transient_local_publisher", transient_local_publisher),
]
"""Every test of rosbridge_server/test/websocket (common.py holds no test)."""
