"""rosbridge_library/test, each test as its wire-level equivalent, or why it has none.

Upstream's library tests call the capability classes and converters in-process: a capability
given an invalid op raises (``MissingArgumentException``, ``InvalidArgumentException``, a
loader exception), which rosbridge_server turns into a ``status`` message of level ``error``
to the client that sent it; here the body sends that op over the wire and expects the error
status (and the connection kept). Conversion tests become round trips through the bridge: a
client publishes, the receiving end (an rclpy subscriber in ``ros`` mode, a second client in
``plain`` mode) must get the same values, and what cannot be represented must be refused.
Tests of the library's own Python objects (managers, caches, timers, loaders, ROS 1 TCP
experiments) do not apply to another server; each says why.
"""

from __future__ import annotations

import asyncio
import base64
import importlib
from typing import Any

from cases import Case, Context, expect, expect_equal
from ros_side import default_dict, message_class, until
from server_cases import STATUS_SUCCEEDED
from wire_client import TracedClient

LIB = "rosbridge_library/test"
INTERNAL = ("tests the library's internal Python API (not the wire); its wire-visible "
            "behaviour is covered by {}")
ROS1 = ("ROS 1 only: rospy nodes and rosbridge's experimental TCP server, not the ROS 2 "
        "WebSocket protocol")


def _error_status(message: Any) -> bool:
    return isinstance(message, dict) and message.get("op") == "status" and \
        message.get("level") == "error"


async def ask_for_errors(client: TracedClient) -> None:
    """Ask once per client for error statuses (``set_level``), see ``refused``."""
    if not client.asked_for_errors:
        client.asked_for_errors = True
        await client.send({"op": "set_level", "level": "error"})


async def refused(client: TracedClient, message: dict[str, Any], what: str = "") -> Any:
    """Send ``message``; the next message must be an error status (or a failed response).

    rosbridge 2.x only logs a refused op on the server; websim sends the error as a
    ``status`` to a client that asked with ``set_level`` (rosbridge 1's op), which makes the
    refusal visible, so each client asks once before its first refusal.
    """
    await ask_for_errors(client)
    await client.send(message)
    reply = await client.next(3.0, f"error status for {message} {what}".strip())
    failed_reply = isinstance(reply, dict) and reply.get("op") in (
        "service_response", "action_result") and reply.get("result") is False
    expect(_error_status(reply) or failed_reply,
           f"{message} {what}: expected an error status, got {reply!r}")
    expect(client.closed_reason is None, f"the server closed the connection after {message}")
    reason = str(reply.get("msg", "")) if _error_status(reply) else ""
    expect(not reason.startswith("unknown op"),
           f"{message}: refused only as an unknown op ({reason!r}), not for its fields")
    return reply


async def accepted(client: TracedClient, message: dict[str, Any], quiet_s: float = 0.5) -> None:
    """Send ``message``; nothing may come back within ``quiet_s`` (no error status)."""
    await ask_for_errors(client)
    await client.send(message)
    replies = await client.drain(quiet_s)
    expect(not any(_error_status(r) for r in replies), f"{message} refused: {replies!r}")


def _refusals(*messages: dict[str, Any]) -> Any:
    async def body(ctx: Context) -> None:
        ws = await ctx.client("ws")
        for message in messages:
            await refused(ws, message)
    return body


def installed(type_name: str) -> bool:
    """Whether this machine has the message package (the ROS side needs it)."""
    try:
        message_class(type_name)
    except (ImportError, AttributeError):
        return False
    return True


async def graph_topics(ctx: Context) -> set[str]:
    """Topics on the graph (``ros``) or in /rosapi/topics (``plain``, the bridge's view)."""
    if ctx.on_graph:
        return {name for name, _ in ctx.node.get_topic_names_and_types()}
    probe = await ctx.client("rosapi")
    await probe.send({"op": "call_service", "service": "/rosapi/topics", "id": "t",
                      "args": {}})
    reply = await probe.next(5, "/rosapi/topics response")
    await probe.close()
    ctx.clients.remove(probe)
    expect(reply.get("result") is True, f"/rosapi/topics failed: {reply!r}")
    return set(reply.get("values", {}).get("topics", []))


async def matched(ctx: Context, topic: str) -> None:
    """In ``ros`` mode, wait until the bridge's publisher of ``topic`` is discovered.

    A volatile message published before discovery is lost, on any ROS 2 bridge;
    upstream's tests sleep instead.
    """
    if ctx.on_graph:
        await until(lambda: ctx.node.count_publishers(topic) > 0, 10,
                    f"the bridge's publisher of {topic} on the graph")
        await asyncio.sleep(0.5)


class Receiver:
    """The receiving end of a topic: an rclpy subscriber (``ros``) or a peer client."""

    def __init__(self, ctx: Context, topic: str, type_name: str) -> None:
        self.ctx, self.topic, self.type_name = ctx, topic, type_name
        self.got: list[Any] = []
        self.peer: TracedClient | None = None

    async def start(self, transient_local: bool = False) -> Receiver:
        """Subscribe, and wait until the bridge can reach this end."""
        if self.ctx.on_graph:
            from rclpy.qos import DurabilityPolicy, QoSProfile

            qos = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL
                             if transient_local else DurabilityPolicy.VOLATILE)
            self.ctx.node.create_subscription(message_class(self.type_name), self.topic,
                                              lambda m: self.got.append(default_dict(m)), qos)
        else:
            self.peer = await self.ctx.client("peer")
            await self.peer.send({"op": "subscribe", "topic": self.topic,
                                  "type": self.type_name, "queue_length": 100})
        await asyncio.sleep(0.5)
        return self

    async def messages(self, count: int, timeout_s: float = 5.0) -> list[Any]:
        """Exactly ``count`` messages (their ``msg`` dicts)."""
        if self.peer is not None:
            got = await self.peer.collect(count, timeout_s, f"publish on {self.topic}")
            return [m.get("msg") for m in got]
        await until(lambda: len(self.got) >= count, timeout_s, f"{count} on {self.topic}")
        return self.got[:count]

    async def nothing(self, quiet_s: float = 0.5) -> list[Any]:
        """What arrived within ``quiet_s`` (expected: nothing)."""
        if self.peer is not None:
            return [m.get("msg") for m in await self.peer.drain(quiet_s)]
        await asyncio.sleep(quiet_s)
        return list(self.got)


async def round_trip(ctx: Context, type_name: str, good: list[Any], bad: list[Any],
                     expected: list[Any] | None = None) -> None:
    """Publish ``{data: v}`` for each value on a topic of ``type_name``.

    ``good`` values must arrive (as ``expected``); ``bad`` ones must be refused and not
    arrive.
    """
    topic = "/rt_" + type_name.split("/")[-1].lower()
    receiver = await Receiver(ctx, topic, type_name).start()
    ws = await ctx.client(f"pub_{type_name.split('/')[-1]}")
    await accepted(ws, {"op": "advertise", "topic": topic, "type": type_name})
    await matched(ctx, topic)
    for value in good:
        await ws.send({"op": "publish", "topic": topic, "msg": {"data": value}})
    got = await receiver.messages(len(good))
    expect_equal([m.get("data") for m in got], expected if expected is not None else good,
                 f"{type_name} values received")
    for value in bad:
        await refused(ws, {"op": "publish", "topic": topic, "msg": {"data": value}},
                      f"({value} does not fit {type_name})")
    expect_equal(await receiver.nothing(), [] if receiver.peer else got,
                 f"{type_name}: out-of-range values must not arrive")
    await ws.close()
    ctx.clients.remove(ws)
    if receiver.peer is not None:
        await receiver.peer.close()
        ctx.clients.remove(receiver.peer)


INT_LIMITS = {"Int8": 127, "Int16": 32767, "Int32": 2147483647, "Int64": 9223372036854775807}


async def signed_ints(ctx: Context) -> None:
    """test_signed_int_base_msgs: boundary values arrive; values too big are refused."""
    order = list(INT_LIMITS)
    for n, name in enumerate(order):
        good = [-127, 0, 127] + [v for lim in order[1:n + 1] for v in (-INT_LIMITS[lim],
                                                                        INT_LIMITS[lim])]
        bad = [v for lim in order[n + 1:] for v in (INT_LIMITS[lim],)]
        await round_trip(ctx, f"std_msgs/{name}", good, bad)


UINT_LIMITS = {"UInt8": [0, 255], "UInt16": [32767, 32768, 65535],
               "UInt32": [2147483647, 2147483648, 4294967295],
               "UInt64": [4294967296, 9223372036854775807, 9223372036854775808,
                          18446744073709551615]}


async def unsigned_ints(ctx: Context) -> None:
    """test_unsigned_int_base_msgs: std_msgs/Char and UInt8..64, as upstream's table."""
    order = list(UINT_LIMITS)
    for n, name in enumerate(order):
        good = [v for lim in order[:n + 1] for v in UINT_LIMITS[lim]]
        bad = [v for lim in order[n + 1:] for v in UINT_LIMITS[lim][-1:]]
        await round_trip(ctx, f"std_msgs/{name}", good, bad)
    await round_trip(ctx, "std_msgs/Char", [0, 1, 255], [65535])


async def bytes_msg(ctx: Context) -> None:
    """test_byte_base_msg: std_msgs/Byte 0..255 (boundaries) arrive as the same integers."""
    good = [0, 1, 127, 255]
    if ctx.on_graph:
        # rclpy holds an octet as bytes; rosbridge's JSON is the integer
        topic = "/rt_byte"
        receiver = await Receiver(ctx, topic, "std_msgs/Byte").start()
        ws = await ctx.client("pub")
        await accepted(ws, {"op": "advertise", "topic": topic, "type": "std_msgs/Byte"})
        await matched(ctx, topic)
        for value in good:
            await ws.send({"op": "publish", "topic": topic, "msg": {"data": value}})
        got = await receiver.messages(len(good))  # default_dict shows bytes as base64
        expect_equal([m.get("data") for m in got],
                     [base64.b64encode(bytes([v])).decode() for v in good], "bytes received")
        return
    await round_trip(ctx, "std_msgs/Byte", good, [])


async def bools(ctx: Context) -> None:
    """test_bool_base_msg."""
    await round_trip(ctx, "std_msgs/Bool", [True, False], [])


async def strings(ctx: Context) -> None:
    """test_string_base_msg: the primitive type names as String data."""
    names = ["bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32",
             "int64", "uint64", "float32", "float64", "string"]
    await round_trip(ctx, "std_msgs/String", names, [])


async def _dict_round_trip(ctx: Context, topic: str, type_name: str, sent: list[Any],
                           expected: list[Any]) -> None:
    receiver = await Receiver(ctx, topic, type_name).start()
    ws = await ctx.client("pub")
    await accepted(ws, {"op": "advertise", "topic": topic, "type": type_name})
    await matched(ctx, topic)
    for message in sent:
        await ws.send({"op": "publish", "topic": topic, "msg": message})
    expect_equal(await receiver.messages(len(sent)), expected, f"{type_name} received")


async def time_msg(ctx: Context) -> None:
    """test_time_msg.

    {sec, nanosec} round trip and ROS 1's {secs, nsecs} accepted as the same
    (rosbridge_test_msgs/TestTimeArray is not installed: that part is left out).
    """
    t = {"sec": 3, "nanosec": 5}
    await _dict_round_trip(ctx, "/rt_time", "builtin_interfaces/Time",
                           [t, {"secs": 3, "nsecs": 5}], [t, t])


async def duration_msg(ctx: Context) -> None:
    """test_duration_msg (the rosbridge_test_msgs part left out)."""
    d = {"sec": 3, "nanosec": 5}
    await _dict_round_trip(ctx, "/rt_duration", "builtin_interfaces/Duration", [d], [d])


async def header_msg(ctx: Context) -> None:
    """test_header_msg (the rosbridge_test_msgs parts left out)."""
    h = {"stamp": {"sec": 12347, "nanosec": 322304}, "frame_id": "2394dnfnlcx;v[p234j]"}
    await _dict_round_trip(ctx, "/rt_header", "std_msgs/Header", [h], [h])


ASSORTED = ["geometry_msgs/Pose", "action_msgs/GoalStatus", "geometry_msgs/WrenchStamped",
            "stereo_msgs/DisparityImage", "nav_msgs/OccupancyGrid", "geometry_msgs/Point32",
            "std_msgs/String", "trajectory_msgs/JointTrajectoryPoint", "diagnostic_msgs/KeyValue",
            "visualization_msgs/InteractiveMarkerUpdate", "nav_msgs/GridCells",
            "sensor_msgs/PointCloud2"]


async def assorted_msgs(ctx: Context) -> None:
    """test_assorted_msgs.

    Each type's default values arrive unchanged (types whose package
    is not installed here are left out: both ends need the package).
    """
    missing = [t for t in ASSORTED if not installed(t)]
    ctx.note(f"left out (package not installed): {missing}")
    for type_name in (t for t in ASSORTED if t not in missing):
        message = default_dict(message_class(type_name)())
        await _dict_round_trip(ctx, "/rt_" + type_name.replace("/", "_").lower(), type_name,
                               [message], [message])
        for client in list(ctx.clients):
            await client.close()
            ctx.clients.remove(client)


def _subscribed(ctx: Context, topic: str) -> Any:
    """A condition: something (the bridge) subscribes to ``topic`` on the graph."""
    return lambda: ctx.node.count_subscribers(topic) > 0


async def float_special(ctx: Context) -> None:
    """test_float_special_cases: inf, -inf and NaN from the graph arrive as JSON null."""
    for name in ("Float32", "Float64"):
        cls = message_class(f"std_msgs/{name}")
        topic = f"/special_{name.lower()}"
        ws = await ctx.client(f"ws_{name}")
        await ws.send({"op": "subscribe", "topic": topic, "type": f"std_msgs/{name}"})
        pub = ctx.node.create_publisher(cls, topic, 10)
        await until(_subscribed(ctx, topic), 10, f"the bridge's subscription to {topic}")
        for value in (float("inf"), float("-inf"), float("nan")):
            pub.publish(cls(data=value))
        got = await ws.collect(3, 5, f"publish on {topic}")
        expect_equal([m.get("msg") for m in got], [{"data": None}] * 3, f"{name} specials")


# --- CBOR: the "node" publishes, the client subscribes with compression cbor -------------

TYPED_ARRAY_TAGS = {"int8": 72, "uint16": 69, "uint32": 70, "uint64": 71, "int16": 77,
                    "int32": 78, "int64": 79, "float32": 85, "float64": 86}
"""RFC 8746 typed-array tags, little-endian, as rosbridge's CBOR encoder uses them."""


async def cbor_receive(ctx: Context, type_name: str, fields: dict[str, Any]) -> Any:
    """Publish ``fields`` as ``type_name`` from the 'node' side; the CBOR-decoded ``msg``."""
    topic = "/cbor_" + type_name.split("/")[-1].lower()
    ws = await ctx.client("ws_" + type_name.split("/")[-1])
    await ws.send({"op": "subscribe", "topic": topic, "type": type_name,
                   "compression": "cbor"})
    if ctx.on_graph:
        cls = message_class(type_name)
        pub = ctx.node.create_publisher(cls, topic, 10)
        await until(lambda: ctx.node.count_subscribers(topic) > 0, 10,
                    f"the bridge's subscription to {topic}")
        message = _build(cls, fields)
        for _ in range(25):  # until the bridge's subscription is matched (volatile QoS)
            pub.publish(message)
            if not ws.inbox.empty():
                break
            await asyncio.sleep(0.2)
    else:
        peer = await ctx.client("peer_" + type_name.split("/")[-1])
        await peer.send({"op": "advertise", "topic": topic, "type": type_name})
        await asyncio.sleep(0.3)
        await peer.send({"op": "publish", "topic": topic, "msg": fields})
    received = await ws.next_framed(5, f"CBOR publish on {topic}")
    expect_equal(received.framing, "cbor", f"{type_name}: frame")
    expect_equal(received.message.get("op"), "publish", "op")
    return received.message.get("msg")


def _build(cls: Any, fields: dict[str, Any]) -> Any:
    kinds = cls.get_fields_and_field_types()
    values = {}
    for name, value in fields.items():
        if isinstance(value, dict):
            value = _build(type(getattr(cls(), name)), value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            element = message_class(kinds[name].removeprefix("sequence<").rstrip(">"))
            value = [_build(element, v) for v in value]
        values[name] = value
    return cls(**values)


def _cbor(check: Any) -> Any:
    async def body(ctx: Context) -> None:
        await check(ctx)
    return body


async def cbor_string(ctx: Context) -> None:
    """test_string."""
    msg = await cbor_receive(ctx, "std_msgs/String", {"data": "foo"})
    expect(msg == {"data": "foo"} and type(msg["data"]) is str, f"got {msg!r}")


async def cbor_bool(ctx: Context) -> None:
    """test_bool."""
    for value in (True, False):
        msg = await cbor_receive(ctx, "std_msgs/Bool", {"data": value})
        expect(msg.get("data") is value, f"Bool {value}: got {msg!r}")
        for client in list(ctx.clients):
            await client.close()
            ctx.clients.remove(client)


async def cbor_numbers(ctx: Context) -> None:
    """test_numbers."""
    cases = [(f"std_msgs/{n}", -5, int) for n in ("Int8", "Int16", "Int32", "Int64")] + \
        [(f"std_msgs/{n}", 5, int) for n in ("UInt8", "UInt16", "UInt32", "UInt64")] + \
        [(f"std_msgs/{n}", 2.3, float) for n in ("Float32", "Float64")]
    for type_name, value, kind in cases:
        msg = await cbor_receive(ctx, type_name, {"data": value})
        data = msg.get("data")
        expect(type(data) is kind, f"{type_name}: {data!r} is not {kind.__name__}")
        if type_name.endswith("Float32"):
            expect(abs(data - value) < 1e-6, f"{type_name}: {data!r}")
        else:
            expect_equal(data, value, type_name)


async def cbor_time(ctx: Context) -> None:
    """test_time: Time and Duration keep integer sec and nanosec."""
    for type_name in ("builtin_interfaces/Time", "builtin_interfaces/Duration"):
        msg = await cbor_receive(ctx, type_name, {"sec": 0, "nanosec": 0})
        expect(type(msg.get("sec")) is int and type(msg.get("nanosec")) is int,
               f"{type_name}: got {msg!r}")


async def cbor_byte_array(ctx: Context) -> None:
    """test_byte_array: uint8[] is a CBOR byte string."""
    sent: Any = [0, 1, 2] if ctx.on_graph else base64.b64encode(bytes([0, 1, 2])).decode()
    msg = await cbor_receive(ctx, "std_msgs/UInt8MultiArray", {"data": sent})
    expect_equal(msg.get("data"), bytes([0, 1, 2]), "UInt8MultiArray data")


async def _typed_arrays(ctx: Context, kinds: list[str], fmt: dict[str, str]) -> None:
    import struct

    for kind in kinds:
        name = kind.capitalize().replace("Uint", "UInt") + "MultiArray"
        msg = await cbor_receive(ctx, f"std_msgs/{name}", {"data": [0, 1, 2]})
        tag = msg.get("data")
        expect(hasattr(tag, "tag") and isinstance(tag.value, bytes),
               f"{name}: data is {tag!r}, not a typed-array tag")
        expect_equal(tag.tag, TYPED_ARRAY_TAGS[kind], f"{name} tag")
        size = struct.calcsize(fmt[kind])
        expect_equal(list(struct.unpack(f"<{len(tag.value) // size}{fmt[kind]}", tag.value)),
                     [0, 1, 2], f"{name} values")


async def cbor_integer_array(ctx: Context) -> None:
    """test_integer_array: int8..uint64 arrays are RFC 8746 typed arrays."""
    fmt = {"int8": "b", "int16": "h", "int32": "i", "int64": "q", "uint16": "H",
           "uint32": "I", "uint64": "Q"}
    await _typed_arrays(ctx, list(fmt), fmt)


async def cbor_float_array(ctx: Context) -> None:
    """test_float_array."""
    await _typed_arrays(ctx, ["float32", "float64"], {"float32": "f", "float64": "d"})


async def cbor_nested(ctx: Context) -> None:
    """test_nested_messages: a MultiArrayLayout with two dims comes back as nested maps."""
    layout = {"data_offset": 5, "dim": [{"label": "foo", "size": 4, "stride": 4},
                                        {"label": "bar", "size": 8, "stride": 8}]}
    msg = await cbor_receive(ctx, "std_msgs/UInt8MultiArray", {"layout": layout})
    expect_equal(msg.get("layout"), layout, "layout")


async def cbor_unicode_keys(ctx: Context) -> None:
    """test_unicode_keys: map keys are text strings."""
    msg = await cbor_receive(ctx, "std_msgs/String", {"data": "foo"})
    expect(all(type(k) is str for k in msg), f"keys {list(msg)!r}")


async def png_compression(ctx: Context) -> None:
    """test_compress_decompress on the wire.

    Compression png gives an op 'png' message whose
    data is a base64 PNG of the JSON (rosbridge's protocol).
    """
    ws = await ctx.client("ws")
    await ws.send({"op": "subscribe", "topic": "/png_topic", "type": "std_msgs/String",
                   "compression": "png"})
    data = "x" * 1000
    if ctx.on_graph:
        cls = message_class("std_msgs/String")
        pub = ctx.node.create_publisher(cls, "/png_topic", 10)
        await until(lambda: ctx.node.count_subscribers("/png_topic") > 0, 10,
                    "the bridge's subscription")
        pub.publish(cls(data=data))
    else:
        peer = await ctx.client("peer")
        await peer.send({"op": "advertise", "topic": "/png_topic", "type": "std_msgs/String"})
        await asyncio.sleep(0.3)
        await peer.send({"op": "publish", "topic": "/png_topic", "msg": {"data": data}})
    message = await ws.next(5, "the png message")
    expect_equal(message.get("op"), "png", "op of a compression png message")
    raw = base64.b64decode(message["data"])
    expect(raw.startswith(b"\x89PNG"), "data is not a PNG")


# --- capabilities that act on the graph --------------------------------------------------

async def do_advertise(ctx: Context) -> None:
    """test_do_advertise: advertised -> the topic exists; unadvertised -> it goes."""
    ws = await ctx.client("ws")
    topic = "/test_do_advertise"
    await accepted(ws, {"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await until_async(lambda: graph_topics(ctx), lambda t: topic in t, 5,
                      f"{topic} to appear")
    await accepted(ws, {"op": "unadvertise", "topic": topic})
    await until_async(lambda: graph_topics(ctx), lambda t: topic not in t, 10,
                      f"{topic} to go after unadvertise")


async def until_async(get: Any, test: Any, timeout_s: float, what: str) -> None:
    """Poll the coroutine ``get()`` every 0.2 s until ``test(value)``."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    while True:
        value = await get()
        if test(value):
            return
        if loop.time() > deadline:
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what} "
                                 f"(last: {sorted(value)[:20]!r})")
        await asyncio.sleep(0.2)


async def multiclient_advertise(ctx: Context) -> None:
    """test_register_publisher_multiclient.

    Two clients advertise one topic; it stays while
    either has it, and goes when both unadvertised.
    """
    topic = "/test_register_publisher_multiclient"
    first, second = await ctx.client("ws1"), await ctx.client("ws2")
    for client in (first, second):
        await accepted(client, {"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await until_async(lambda: graph_topics(ctx), lambda t: topic in t, 5, f"{topic}")
    await accepted(first, {"op": "unadvertise", "topic": topic})
    await asyncio.sleep(1.5)
    expect(topic in await graph_topics(ctx), f"{topic} went while ws2 still advertises it")
    await accepted(second, {"op": "unadvertise", "topic": topic})
    await until_async(lambda: graph_topics(ctx), lambda t: topic not in t, 10,
                      f"{topic} to go")


async def conflicting_advertise(ctx: Context) -> None:
    """test_register_publisher_conflicting_types: a second type for a topic is refused."""
    topic = "/test_register_publisher_conflicting_types"
    first, second = await ctx.client("ws1"), await ctx.client("ws2")
    await accepted(first, {"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await refused(second, {"op": "advertise", "topic": topic, "type": "std_msgs/Int32"})


async def conflicting_subscribe(ctx: Context) -> None:
    """Subscriber manager test_register_publisher_conflicting_types.

    Subscribing with another
    type than the topic's is refused.
    """
    topic = "/test_subscriber_conflicting_types"
    first, second = await ctx.client("ws1"), await ctx.client("ws2")
    await accepted(first, {"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await refused(second, {"op": "subscribe", "topic": topic, "type": "std_msgs/Int32"})


async def publish_unknown_topic(ctx: Context) -> None:
    """test_register_no_msgtype / test_publish_not_registered.

    A publish (no advertise, no
    type) to a topic nobody has is refused: the type cannot be known.
    """
    ws = await ctx.client("ws")
    await refused(ws, {"op": "publish", "topic": "/test_publish_not_registered",
                       "msg": {"data": "test publish not registered"}})


async def subscribe_unknown_no_type(ctx: Context) -> None:
    """Subscriber manager test_register_no_msgtype.

    A subscribe with no type to a topic
    nobody has is refused (rosbridge: TopicNotEstablishedException).
    """
    ws = await ctx.client("ws")
    await refused(ws, {"op": "subscribe", "topic": "/test_subscribe_no_msgtype"})


async def publish_infers_type(ctx: Context) -> None:
    """test_publish_works / test_register_infer_topictype / test_publisher_manager_publish.

    A
    publish with no advertise to a topic whose type is known reaches the subscriber.
    """
    topic = "/test_publish_works"
    receiver = await Receiver(ctx, topic, "std_msgs/String").start(transient_local=True)
    ws = await ctx.client("ws")
    await ws.send({"op": "publish", "topic": topic, "msg": {"data": "test publish works"}})
    expect_equal(await receiver.messages(1), [{"data": "test publish works"}], "received")


async def subscribe_infers_type(ctx: Context) -> None:
    """Subscriber manager test_register_infer_topictype.

    A subscribe with no type to an
    existing topic works and gets its messages.
    """
    topic = "/test_subscribe_infer_topictype"
    ws = await ctx.client("ws")
    if ctx.on_graph:
        cls = message_class("std_msgs/String")
        pub = ctx.node.create_publisher(cls, topic, 10)
        await asyncio.sleep(1.0)
        await accepted(ws, {"op": "subscribe", "topic": topic})
        await until(lambda: ctx.node.count_subscribers(topic) > 0, 10, "the bridge")
        pub.publish(cls(data="hi"))
    else:
        peer = await ctx.client("peer")
        await peer.send({"op": "advertise", "topic": topic, "type": "std_msgs/String"})
        await asyncio.sleep(0.5)
        await accepted(ws, {"op": "subscribe", "topic": topic})
        await peer.send({"op": "publish", "topic": topic, "msg": {"data": "hi"}})
    message = await ws.next(5, "publish")
    expect_equal(message.get("msg"), {"data": "hi"}, "msg")


async def subscribe_works(ctx: Context) -> None:
    """test_subscribe_works: subscribe, then a (transient local) publisher's message arrives."""
    topic = "/test_subscribe_works"
    text = "test test_subscribe_works works"
    ws = await ctx.client("ws")
    await accepted(ws, {"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    if ctx.on_graph:
        from rclpy.qos import DurabilityPolicy, QoSProfile

        cls = message_class("std_msgs/String")
        pub = ctx.node.create_publisher(cls, topic, QoSProfile(
            depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        pub.publish(cls(data=text))
    else:
        peer = await ctx.client("peer")
        await peer.send({"op": "advertise", "topic": topic, "type": "std_msgs/String"})
        await peer.send({"op": "publish", "topic": topic, "msg": {"data": text}})
    message = await ws.next(5, "publish")
    expect_equal(message.get("msg"), {"data": text}, "msg")


async def bad_publish(ctx: Context) -> None:
    """test_publisher_manager_bad_publish: a field of the wrong type is refused."""
    topic = "/test_publisher_manager_bad_publish"
    receiver = await Receiver(ctx, topic, "std_msgs/String").start()
    ws = await ctx.client("ws")
    await accepted(ws, {"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await refused(ws, {"op": "publish", "topic": topic, "msg": {"data": 3}})
    expect_equal(await receiver.nothing(), [], "a wrongly typed message must not arrive")


async def _service_provider(ctx: Context, kind: str, name: str) -> Any:
    """Serve std_srvs/Trigger or SetBool at ``name`` as upstream's callbacks do."""
    def answer(data: bool | None) -> tuple[bool, str]:
        if data is None:
            return True, "called trigger service successfully"
        return bool(data), "set bool to true" if data else "set bool to false"
    if ctx.on_graph:
        from rclpy.callback_groups import ReentrantCallbackGroup

        srv = getattr(importlib.import_module("std_srvs.srv"), kind)

        def serve(request: Any, response: Any) -> Any:
            response.success, response.message = answer(getattr(request, "data", None))
            return response
        ctx.node.create_service(srv, name, serve, callback_group=ReentrantCallbackGroup())
        await asyncio.sleep(0.5)
        return None
    peer = await ctx.client("peer")
    await peer.send({"op": "advertise_service", "type": f"std_srvs/{kind}", "service": name})
    await asyncio.sleep(0.5)

    async def respond_once() -> None:
        request = await peer.next(5, "call_service at the provider")
        success, text = answer(request.get("args", {}).get("data") if kind == "SetBool"
                               else None)
        await peer.send({"op": "service_response", "service": name, "id": request.get("id"),
                         "result": True, "values": {"success": success, "message": text}})
    return respond_once


async def call_trigger(ctx: Context) -> None:
    """test_call_service_works: call a Trigger service with no args."""
    respond = await _service_provider(ctx, "Trigger", "/test_call_service/trigger")
    ws = await ctx.client("ws")
    await ws.send({"op": "call_service", "service": "/test_call_service/trigger"})
    if respond:
        await respond()
    reply = await ws.next(5, "service_response")
    expect_equal(reply.get("values"), {"success": True,
                                       "message": "called trigger service successfully"},
                 "values")


async def call_set_bool(ctx: Context) -> None:
    """test_call_service_args."""
    respond = await _service_provider(ctx, "SetBool", "/test_call_service/set_bool")
    ws = await ctx.client("ws")
    await ws.send({"op": "call_service", "service": "/test_call_service/set_bool",
                   "args": {"data": True}})
    if respond:
        await respond()
    reply = await ws.next(5, "service_response")
    expect_equal(reply.get("values"), {"success": True, "message": "set bool to true"},
                 "values")


async def call_bad_args(ctx: Context) -> None:
    """test_call_service_fails.

    Args of the wrong type ({data: 42.0} to SetBool) fail the call
    (service_response result false) and never reach the provider.
    """
    await _service_provider(ctx, "SetBool", "/test_call_service/set_bool")
    ws = await ctx.client("ws")
    await ws.send({"op": "call_service", "service": "/test_call_service/set_bool",
                   "args": {"data": 42.0}})
    reply = await ws.next(5, "service_response")
    expect_equal((reply.get("op"), reply.get("result")), ("service_response", False),
                 "reply to a call with wrong args")
    peer = next((c for c in ctx.clients if c.name == "peer"), None)
    if peer is not None:
        expect_equal(await peer.drain(0.5), [], "what reached the provider")


async def call_own_service(ctx: Context) -> None:
    """test_call_advertised_service: one client advertises, calls, answers, gets the answer."""
    ws = await ctx.client("ws")
    await accepted(ws, {"op": "advertise_service", "type": "std_srvs/SetBool",
                        "service": "/set_bool_2"})
    await ws.send({"op": "call_service", "id": "foo", "service": "/set_bool_2",
                   "args": {"data": True}})
    request = await ws.next(5, "call_service")
    expect_equal(request.get("op"), "call_service", "op")
    expect("id" in request, "no id")
    await ws.send({"op": "service_response", "service": "/set_bool_2", "id": request["id"],
                   "values": {"success": True, "message": "set bool to true"}, "result": True})
    reply = await ws.next(5, "service_response")
    expect_equal((reply.get("op"), reply.get("result")), ("service_response", True), "reply")


async def unadvertise_live_request(ctx: Context) -> None:
    """test_unadvertise_with_live_request.

    Unadvertising with a call pending fails that call
    ("Service /set_bool_3 was unadvertised") rather than leaving it hanging.
    """
    ws = await ctx.client("ws")
    await accepted(ws, {"op": "advertise_service", "type": "std_srvs/SetBool",
                        "service": "/set_bool_3"})
    await ws.send({"op": "call_service", "id": "foo", "service": "/set_bool_3",
                   "args": {"data": True}})
    request = await ws.next(5, "call_service")
    expect_equal(request.get("op"), "call_service", "op")
    await ws.send({"op": "unadvertise_service", "service": "/set_bool_3"})
    reply = await ws.next(5, "the pending call's failure")
    expect((reply.get("op") == "service_response" and reply.get("result") is False)
           or _error_status(reply), f"expected a failed response, got {reply!r}")


async def advertise_action_ok(ctx: Context) -> None:
    """test_advertise_action."""
    ws = await ctx.client("ws")
    await accepted(ws, {"op": "advertise_action", "type": "example_interfaces/Fibonacci",
                        "action": "/fibonacci_action_1"})


async def _own_action_goal(ws: TracedClient, action: str, goal_id: str) -> Any:
    await accepted(ws, {"op": "advertise_action", "type": "example_interfaces/Fibonacci",
                        "action": action}, quiet_s=0.2)
    await ws.send({"op": "send_action_goal", "id": goal_id, "action": action,
                   "action_type": "example_interfaces/Fibonacci", "args": {"order": 5},
                   "feedback": True})
    request = await ws.next(5, "send_action_goal")
    expect_equal(request.get("op"), "send_action_goal", "op")
    expect("id" in request, "no id in send_action_goal")
    return request


async def execute_own_action(ctx: Context) -> None:
    """test_execute_advertised_action (skipped upstream, rclpy#1195).

    Feedback and result
    from the advertiser reach the goal's sender (here the same client, asking for feedback).
    """
    ws = await ctx.client("ws")
    action = "/fibonacci_action_2"
    request = await _own_action_goal(ws, action, "foo2")
    await ws.send({"op": "action_feedback", "action": action, "id": request["id"],
                   "values": {"sequence": [0, 1, 1]}})
    feedback = await ws.next(5, "action_feedback")
    expect_equal((feedback.get("op"), feedback.get("values")),
                 ("action_feedback", {"sequence": [0, 1, 1]}), "feedback")
    await ws.send({"op": "action_result", "action": action, "id": request["id"],
                   "values": {"sequence": [0, 1, 1, 2, 3, 5]}, "status": STATUS_SUCCEEDED,
                   "result": True})
    result = await ws.next(5, "action_result")
    expect_equal((result.get("op"), result.get("values"), result.get("status")),
                 ("action_result", {"sequence": [0, 1, 1, 2, 3, 5]}, STATUS_SUCCEEDED),
                 "result")


async def cancel_own_action(ctx: Context) -> None:
    """test_cancel_advertised_action (skipped upstream).

    Cancel_action_goal reaches the
    advertiser; its canceled result reaches the sender.
    """
    ws = await ctx.client("ws")
    action = "/fibonacci_action_3"
    request = await _own_action_goal(ws, action, "foo3")
    await ws.send({"op": "cancel_action_goal", "action": action, "id": "foo3"})
    cancel = await ws.next(5, "cancel_action_goal at the advertiser")
    expect_equal(cancel.get("op"), "cancel_action_goal", "op")
    await ws.send({"op": "action_result", "action": action, "id": cancel.get("id",
                   request["id"]), "values": {"sequence": []}, "status": 5, "result": True})
    result = await ws.next(5, "action_result")
    expect_equal((result.get("op"), result.get("values"), result.get("status")),
                 ("action_result", {"sequence": []}, 5), "canceled result")


async def unadvertise_own_action(ctx: Context) -> None:
    """test_unadvertise_action (skipped upstream): unadvertising with a goal pending fails it."""
    ws = await ctx.client("ws")
    action = "/fibonacci_action_4"
    await _own_action_goal(ws, action, "foo4")
    await ws.send({"op": "unadvertise_action", "action": action})
    reply = await ws.next(5, "the pending goal's failure")
    expect((reply.get("op") == "action_result" and reply.get("result") is False)
           or _error_status(reply), f"expected a failed action_result, got {reply!r}")


BAD_TYPESTRINGS = ["", "/", "//", "///", "////", "/////", "bad", "stillbad", "better/",
                   "better//", "better///", "/better", "//better", "///better", r"this\isbad",
                   "\\"]
NO_PACKAGE = ["roslib/Time", "roslib/Duration", "roslib/Header", "std_srvs/ConflictedMsg",
              "topic_tools/MessageMessage", "wangle_msgs/Jam", "whistleblower_msgs/Document",
              "coercion_msgs/Bribe", "airconditioning_msgs/Cold", "pr2thoughts_msgs/Escape"]
NO_CLASS = ["builtin_interfaces/SpaceTime", "std_msgs/Spool", "geometry_msgs/Tetrahedron",
            "sensor_msgs/TelepathyUnit"]


def _advertise_each(types: list[str], topic: str) -> Any:
    return _refusals(*({"op": "advertise", "topic": topic, "type": t} for t in types))


async def valid_msg_classes(ctx: Context) -> None:
    """test_valid_msg_classes: every installed type is accepted (advertise, unadvertise)."""
    ws = await ctx.client("ws")
    types = ASSORTED if not ctx.on_graph else [t for t in ASSORTED if installed(t)]
    ctx.note(f"types: {types}")
    for type_name in types:
        await accepted(ws, {"op": "advertise", "topic": "/" + type_name, "type": type_name})
        await accepted(ws, {"op": "unadvertise", "topic": "/" + type_name}, quiet_s=0.1)


def _c(path: str, cls: str, test: str, body: Any = None, na: str | None = None,
       **kwargs: Any) -> Case:
    not_applicable = dict(kwargs.pop("not_applicable", {}))
    if na:
        not_applicable["both"] = na
    return Case("rosbridge_library", f"{LIB}/{path}::{cls}::{test}", body,
                not_applicable=not_applicable, **kwargs)


def _internal(path: str, cls: str, tests: list[str], covered: str) -> list[Case]:
    return [_c(path, cls, t, na=INTERNAL.format(covered)) for t in tests]


ADV, PUB, SUB, CALL = ("capabilities/test_advertise.py", "capabilities/test_publish.py",
                       "capabilities/test_subscribe.py", "capabilities/test_call_service.py")
SRV, ACT = "capabilities/test_service_capabilities.py", "capabilities/test_action_capabilities.py"
MC, CB = "internal/test_message_conversion.py", "internal/test_cbor_conversion.py"
PM, SM = "internal/publishers/test_publisher_manager.py", \
    "internal/subscribers/test_subscriber_manager.py"
GRAPH_ONLY = {"plain": "needs the ROS side to produce inf/NaN: JSON from a client cannot"}

CASES: list[Case] = [
    _c(ADV, "TestAdvertise", "test_missing_arguments", _refusals(
        {"op": "advertise"}, {"op": "advertise", "topic": "/jon"},
        {"op": "advertise", "type": "std_msgs/String"})),
    _c(ADV, "TestAdvertise", "test_invalid_arguments", _refusals(
        {"op": "advertise", "topic": 3, "type": "std_msgs/String"},
        {"op": "advertise", "topic": "/jon", "type": 3})),
    _c(ADV, "TestAdvertise", "test_invalid_msg_typestrings",
       _advertise_each(BAD_TYPESTRINGS, "/test_invalid_msg_typestrings")),
    _c(ADV, "TestAdvertise", "test_invalid_msg_package",
       _advertise_each(NO_PACKAGE, "/test_invalid_msg_package")),
    _c(ADV, "TestAdvertise", "test_invalid_msg_classes",
       _advertise_each(NO_CLASS, "/test_invalid_msg_classes")),
    _c(ADV, "TestAdvertise", "test_valid_msg_classes", valid_msg_classes),
    _c(ADV, "TestAdvertise", "test_do_advertise", do_advertise,
       note="plain: the topic list is /rosapi/topics"),
    _c(PUB, "TestAdvertise", "test_missing_arguments", _refusals(
        {"op": "publish"}, {"op": "publish", "msg": {}})),
    _c(PUB, "TestAdvertise", "test_invalid_arguments", _refusals({"op": "publish", "topic": 3})),
    _c(PUB, "TestAdvertise", "test_publish_works", publish_infers_type),
    _c(SUB, "TestSubscribe", "test_update_params",
       na=INTERNAL.format("smoke (queue_length) and the subscription modifiers")),
    _c(SUB, "TestSubscribe", "test_missing_arguments", _refusals({"op": "subscribe"})),
    _c(SUB, "TestSubscribe", "test_invalid_arguments", _refusals(
        {"op": "subscribe", "topic": 3}, {"op": "subscribe", "topic": "/jon", "type": 3},
        {"op": "subscribe", "topic": "/jon", "throttle_rate": "fast"},
        {"op": "subscribe", "topic": "/jon", "fragment_size": "five cubits"},
        {"op": "subscribe", "topic": "/jon", "queue_length": "long"},
        {"op": "subscribe", "topic": "/jon", "compression": 9000})),
    _c(SUB, "TestSubscribe", "test_subscribe_works", subscribe_works),
    _c(CALL, "TestCallService", "test_missing_arguments", _refusals({"op": "call_service"})),
    _c(CALL, "TestCallService", "test_invalid_arguments",
       _refusals({"op": "call_service", "service": 3})),
    _c(CALL, "TestCallService", "test_call_service_works", call_trigger),
    _c(CALL, "TestCallService", "test_call_service_args", call_set_bool),
    _c(CALL, "TestCallService", "test_call_service_fails", call_bad_args),
    _c(SRV, "TestServiceCapabilities", "test_advertise_missing_arguments",
       _refusals({"op": "advertise_service"})),
    _c(SRV, "TestServiceCapabilities", "test_advertise_invalid_arguments",
       _refusals({"op": "advertise_service", "type": 42, "service": None})),
    _c(SRV, "TestServiceCapabilities", "test_response_missing_arguments", _refusals(
        {"op": "service_response"},
        {"op": "service_response", "id": "dummy_service", "values": "none"})),
    _c(SRV, "TestServiceCapabilities", "test_response_invalid_arguments",
       _refusals({"op": "service_response", "service": 5, "result": "error"})),
    _c(SRV, "TestServiceCapabilities", "test_advertise_service", lambda ctx: _advertise_ok(ctx)),
    _c(SRV, "TestServiceCapabilities", "test_call_advertised_service", call_own_service),
    _c(SRV, "TestServiceCapabilities", "test_unadvertise_with_live_request",
       unadvertise_live_request),
    _c(ACT, "TestActionCapabilities", "test_advertise_missing_arguments",
       _refusals({"op": "advertise_action"})),
    _c(ACT, "TestActionCapabilities", "test_advertise_invalid_arguments",
       _refusals({"op": "advertise_action", "type": 42, "action": None})),
    _c(ACT, "TestActionCapabilities", "test_result_missing_arguments", _refusals(
        {"op": "action_result"},
        {"op": "action_result", "id": "dummy_action", "values": "none"})),
    _c(ACT, "TestActionCapabilities", "test_result_invalid_arguments",
       _refusals({"op": "action_result", "action": 5, "result": "error"})),
    _c(ACT, "TestActionCapabilities", "test_advertise_action", advertise_action_ok),
    _c(ACT, "TestActionCapabilities", "test_execute_advertised_action", execute_own_action,
       note="skipped upstream (rclpy#1195); run here anyway"),
    _c(ACT, "TestActionCapabilities", "test_cancel_advertised_action", cancel_own_action,
       note="skipped upstream (rclpy#1195); run here anyway"),
    _c(ACT, "TestActionCapabilities", "test_unadvertise_action", unadvertise_own_action,
       note="skipped upstream; run here anyway"),
    *_internal(MC, "TestMessageConversion", ["test_int_primitives", "test_byte_primitives",
               "test_bool_primitives", "test_float_primitives"],
               "test_*_base_msg(s) (the converter's per-primitive functions)"),
    _c(MC, "TestMessageConversion", "test_float_special_cases", float_special,
       not_applicable=GRAPH_ONLY),
    _c(MC, "TestMessageConversion", "test_signed_int_base_msgs", signed_ints),
    _c(MC, "TestMessageConversion", "test_unsigned_int_base_msgs", unsigned_ints),
    _c(MC, "TestMessageConversion", "test_byte_base_msg", bytes_msg),
    _c(MC, "TestMessageConversion", "test_bool_base_msg", bools),
    _c(MC, "TestMessageConversion", "test_string_base_msg", strings),
    _c(MC, "TestMessageConversion", "test_time_msg", time_msg),
    _c(MC, "TestMessageConversion", "test_duration_msg", duration_msg),
    _c(MC, "TestMessageConversion", "test_header_msg", header_msg),
    _c(MC, "TestMessageConversion", "test_assorted_msgs", assorted_msgs),
    *_internal(MC, "TestMessageConversion", ["test_int8array", "test_float32array",
               "test_float32_complexboundedarray"],
               "CBOR test_integer_array/test_float_array (they need rosbridge_test_msgs)"),
    _c(CB, "TestCBORConversion", "test_string", cbor_string),
    _c(CB, "TestCBORConversion", "test_bool", cbor_bool),
    _c(CB, "TestCBORConversion", "test_numbers", cbor_numbers),
    _c(CB, "TestCBORConversion", "test_time", cbor_time),
    _c(CB, "TestCBORConversion", "test_byte_array", cbor_byte_array),
    _c(CB, "TestCBORConversion", "test_integer_array", cbor_integer_array),
    _c(CB, "TestCBORConversion", "test_float_array", cbor_float_array),
    _c(CB, "TestCBORConversion", "test_nested_messages", cbor_nested),
    _c(CB, "TestCBORConversion", "test_unicode_keys", cbor_unicode_keys),
    _c("internal/test_compression.py", "TestCompression", "test_compress",
       na=INTERNAL.format("test_compress_decompress's wire form")),
    _c("internal/test_compression.py", "TestCompression", "test_compress_decompress",
       png_compression, note="wire form: subscribe with compression png"),
    *_internal("internal/test_outgoing_message.py", "TestOutgoingMessage",
               ["test_json_values", "test_cbor_values"], "the CBOR and JSON round trips"),
    *_internal("internal/test_ros_loader.py", "TestROSLoader", [
        "test_bad_msg_names", "test_irregular_msg_names", "test_std_msg_names",
        "test_msg_cache", "test_assorted_msg_names", "test_invalid_msg_names_primitives",
        "test_nonexistent_package_names", "test_packages_without_msgs",
        "test_nonexistent_msg_class_names", "test_bad_service_names",
        "test_irregular_service_names", "test_common_service_names", "test_srv_cache",
        "test_packages_without_srvs", "test_nonexistent_service_package_names",
        "test_nonexistent_service_class_names", "test_bad_action_names",
        "test_irregular_action_names", "test_common_action_names", "test_action_cache",
        "test_packages_without_actions", "test_nonexistent_action_package_names",
        "test_nonexistent_action_class_names"],
        "test_advertise's typestring/package/class tests"),
    *_internal("internal/services/test_services.py", "TestServices", [
        "test_populate_request_args", "test_service_call", "test_service_caller",
        "test_service_tester", "test_service_tester_alltypes", "test_random_service_types"],
        "call_service.test.py and test_call_service.py"),
    *_internal("internal/actions/test_actions.py", "TestActions", [
        "test_populate_goal_args", "test_send_action_goal", "test_action_client_handler"],
        "send_action_goal.test.py"),
    *_internal("internal/publishers/test_multi_publisher.py", "TestMultiPublisher", [
        "test_register_multipublisher", "test_unregister_multipublisher",
        "test_register_client", "test_register_multiple_clients", "test_verify_type",
        "test_publish", "test_publish_twice", "test_bad_publish"],
        "the publisher manager's wire forms"),
    *_internal(PM, "TestPublisherManager", ["test_register_publisher"], "test_do_advertise"),
    _c(PM, "TestPublisherManager", "test_register_publisher_multiclient",
       multiclient_advertise, note="plain: the topic list is /rosapi/topics"),
    _c(PM, "TestPublisherManager", "test_register_publisher_conflicting_types",
       conflicting_advertise),
    *_internal(PM, "TestPublisherManager", ["test_register_multiple_publishers",
               "test_register_multiple_notopictype"],
               "test_do_advertise and test_register_publisher_multiclient (unregister timers)"),
    _c(PM, "TestPublisherManager", "test_register_no_msgtype", publish_unknown_topic),
    _c(PM, "TestPublisherManager", "test_register_infer_topictype", publish_infers_type),
    _c(PM, "TestPublisherManager", "test_publish_not_registered", publish_unknown_topic),
    _c(PM, "TestPublisherManager", "test_publisher_manager_publish", publish_infers_type),
    _c(PM, "TestPublisherManager", "test_publisher_manager_bad_publish", bad_publish),
    *_internal(SM, "TestSubscriberManager", ["test_subscribe",
               "test_register_subscriber_multiclient", "test_register_multiple_publishers",
               "test_register_multiple_notopictype", "test_subscribe_not_registered",
               "test_publisher_manager_publish"],
               "multiple_subscribers.test.py and test_subscribe_works"),
    _c(SM, "TestSubscriberManager", "test_register_publisher_conflicting_types",
       conflicting_subscribe),
    _c(SM, "TestSubscriberManager", "test_register_no_msgtype", subscribe_unknown_no_type),
    _c(SM, "TestSubscriberManager", "test_register_infer_topictype", subscribe_infers_type),
    *_internal("internal/subscribers/test_multi_subscriber.py", "TestMultiSubscriber", [
        "test_register_multisubscriber", "test_unregister_multisubscriber",
        "test_verify_type", "test_subscribe_unsubscribe", "test_subscribe_receive_json",
        "test_subscribe_receive_json_multiple",
        "test_unsubscribe_does_not_receive_further_msgs", "test_multiple_subscribers"],
        "multiple_subscribers.test.py, test_subscribe_works, conflicting-type subscribe"),
    *_internal("internal/subscribers/test_subscription_modifiers.py", "TestMessageHandlers", [
        "test_default_message_handler", "test_throttle_message_handler",
        "test_queue_message_handler_passes_msgs", "test_queue_message_handler_stops",
        "test_queue_message_handler_queue", "test_queue_message_handler_dropping",
        "test_queue_message_handler_rate", "test_transitions",
        "test_transition_functionality"], "smoke.test.py (queue_length 0)"),
    _c("experimental/complex_srv+tcp/test_non-ros_service_client_complex-srv.py", "-",
       "(script)", na=ROS1),
    _c("experimental/complex_srv+tcp/test_non-ros_service_server_complex-srv.py", "-",
       "(script)", na=ROS1),
    _c("experimental/fragmentation+srv+tcp/test_non-ros_service_client_fragmented.py", "-",
       "(script)", na=ROS1),
    _c("experimental/fragmentation+srv+tcp/test_non-ros_service_server_fragmented.py", "-",
       "(script)", na=ROS1),
]
"""Every test of rosbridge_library/test, in upstream's file order."""


async def _advertise_ok(ctx: Context) -> None:
    """test_advertise_service."""
    ws = await ctx.client("ws")
    await accepted(ws, {"op": "advertise_service", "type": "std_srvs/SetBool",
                        "service": "/set_bool_1"})
