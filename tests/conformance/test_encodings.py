"""rosbridge's encodings against a real ``websim serve``: fragments, PNG, cbor-raw, typed arrays.

What each client does with them was read in its source: roslibjs 1.4.1 decodes ``op: "png"``
(pngparse under Node, a canvas in a browser) and CBOR typed arrays (``cborTypedArrayTags``),
and has no handler for ``op: "fragment"``; roslibpy 2.1 has neither (an unknown op raises).
So fragments are read here by a raw ``websockets`` client, as a rosbridge client that asks
for them must: concatenate the ``data`` of ``num`` 0 .. ``total`` - 1.
"""

from __future__ import annotations

import base64
import io
import json
import math
import shutil
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cbor2
import pytest
from PIL import Image
from rosbags.typesys import Stores, get_typestore
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from rosbridge.core.bridge import Bridge
from rosbridge.core.capabilities.topics import Encoded
from rosbridge.core.clock import ManualClock
from rosbridge.core.encoding import CBOR_TYPED_ARRAYS, to_cbor
from rosbridge.core.limits import ClientLimits
from rosbridge.core.outbox import Outbox
from rosbridge.core.session import Session
from rosbridge.msgs.values import Base64Bytes, typed_sequence

from server_process import ServerProcess, wait_for

NODE = shutil.which("node")
NODE_PROGRAMS = Path(__file__).parent / "node"
NODE_TIMEOUT_S = 30.0
RECEIVE_TIMEOUT_S = 10.0

LIMITS = ClientLimits()


@pytest.fixture
def client(server: ServerProcess) -> Iterator[ClientConnection]:
    with connect(server.ws_url, max_size=None) as connection:
        yield connection


def send(connection: ClientConnection, message: dict[str, Any]) -> None:
    connection.send(json.dumps(message))


def receive_until(connection: ClientConnection, accept: Any,
                  timeout_s: float = RECEIVE_TIMEOUT_S) -> Any:
    """Frames until ``accept(frame)`` is truthy; that value."""
    deadline = time.monotonic() + timeout_s
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise AssertionError(f"timed out after {timeout_s} s")
        frame = connection.recv(timeout=remaining)
        value = accept(frame)
        if value:
            return value


def text_op(op: str) -> Any:
    """An ``accept`` for ``receive_until``: a JSON text frame of ``op``, decoded."""
    def accept(frame: str | bytes) -> Any:
        if isinstance(frame, str):
            message = json.loads(frame)
            if message.get("op") == op:
                return message
        return None
    return accept


def reassemble(connection: ClientConnection) -> tuple[list[dict[str, Any]], str]:
    """Read one fragmented message: its fragments, as they came, and the text they make."""
    first = receive_until(connection, text_op("fragment"))
    while first["num"] != 0:  # subscribed mid-message: wait for the next one
        first = receive_until(connection, text_op("fragment"))
    fragments = [first]
    while len(fragments) < first["total"]:
        fragments.append(receive_until(connection, text_op("fragment")))
    assert {fragment["id"] for fragment in fragments} == {first["id"]}
    return fragments, "".join(fragment["data"] for fragment in fragments)


def run_node(program: str, *args: str) -> Any:
    assert NODE is not None
    result = subprocess.run([NODE, str(NODE_PROGRAMS / program), *args], capture_output=True,
                            text=True, timeout=NODE_TIMEOUT_S, check=False)
    assert result.returncode == 0, f"node {program}:\n{result.stderr}"
    return json.loads(result.stdout)


def stamp_of(message: dict[str, Any]) -> tuple[int, int]:
    stamp = message["header"]["stamp"]
    return stamp["sec"], stamp["nanosec"]


# ---- PNG --------------------------------------------------------------------------------------

@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_png_compression_decodes_in_roslibjs_under_node_to_the_json_message(
        server: ServerProcess) -> None:
    pair = run_node("png_subscriber.js", server.ws_url, "/odom", "nav_msgs/msg/Odometry")
    assert pair["png"] == pair["json"]
    assert pair["png"]["child_frame_id"] == "base_link"


def test_png_frame_is_rosbridges_rgb_image_of_the_json_text_padded_with_newlines(
        client: ClientConnection) -> None:
    send(client, {"op": "subscribe", "topic": "/odom", "compression": "png"})
    frame = receive_until(client, text_op("png"))
    assert set(frame) == {"op", "data"}
    image = Image.open(io.BytesIO(base64.b64decode(frame["data"])), formats=("PNG",))
    pixels = image.tobytes()
    text = pixels.rstrip(b"\n")
    assert image.mode == "RGB"
    assert image.width == math.floor(math.sqrt(len(text) / 3))  # pngcompression.encode
    assert len(pixels) - len(text) < 3 * image.width  # padding fills the last row only
    message = json.loads(text)
    assert (message["op"], message["topic"]) == ("publish", "/odom")
    assert message["msg"]["header"]["frame_id"] == "odom"


# ---- fragments out ----------------------------------------------------------------------------

def test_fragment_size_sends_scan_as_rosbridge_fragments_one_frame_each(
        client: ClientConnection) -> None:
    fragment_size = 300
    send(client, {"op": "subscribe", "topic": "/scan", "fragment_size": fragment_size})
    fragments, text = reassemble(client)
    total = fragments[0]["total"]
    assert [fragment["num"] for fragment in fragments] == list(range(total))
    assert all(set(fragment) == {"op", "id", "data", "num", "total"} for fragment in fragments)
    assert all(len(fragment["data"]) <= fragment_size for fragment in fragments)
    cut_by = 256  # rounded down to a power of two (fragments.topic_fragment_size)
    assert total == math.ceil(len(text) / cut_by) > 1
    message = json.loads(text)
    assert (message["op"], message["topic"]) == ("publish", "/scan")
    assert len(message["msg"]["ranges"]) == 360


def test_fragment_size_of_call_service_fragments_its_response_under_the_call_id(
        client: ClientConnection) -> None:
    send(client, {"op": "call_service", "service": "/rosapi/topics", "id": "call-1",
                  "fragment_size": 40})
    fragments, text = reassemble(client)
    assert fragments[0]["id"] == "call-1"
    response = json.loads(text)
    assert (response["op"], response["id"], response["result"]) == (
        "service_response", "call-1", True)
    assert "/odom" in response["values"]["topics"]


def test_fragment_size_null_turns_fragmenting_off_again(client: ClientConnection) -> None:
    send(client, {"op": "subscribe", "topic": "/odom", "fragment_size": 100})
    reassemble(client)
    send(client, {"op": "subscribe", "topic": "/odom", "fragment_size": None})
    message = receive_until(client, text_op("publish"))
    assert message["topic"] == "/odom"


# ---- fragments in -----------------------------------------------------------------------------

def odom_x(connection: ClientConnection) -> float:
    message = receive_until(connection, text_op("publish"))
    return float(message["msg"]["pose"]["pose"]["position"]["x"])


def test_a_publish_sent_in_5_fragments_moves_the_robot(server: ServerProcess) -> None:
    with connect(server.ws_url) as driver, connect(server.ws_url) as watcher:
        send(watcher, {"op": "subscribe", "topic": "/odom"})
        start_x = odom_x(watcher)
        send(driver, {"op": "advertise", "topic": "/cmd_vel",
                      "type": "geometry_msgs/msg/Twist"})
        text = json.dumps({"op": "publish", "topic": "/cmd_vel",
                           "msg": {"linear": {"x": 0.3, "y": 0, "z": 0},
                                   "angular": {"x": 0, "y": 0, "z": 0}}})
        size = math.ceil(len(text) / 5)
        for round_number in range(10):
            for num in range(5):
                send(driver, {"op": "fragment", "id": f"twist-{round_number}",
                              "data": text[num * size:(num + 1) * size], "num": num,
                              "total": 5})
            time.sleep(0.1)  # a teleop page's 10 Hz
        wait_for(lambda: odom_x(watcher) > start_x + 0.1, 10.0, "the robot to move 0.1 m")


def statuses(connection: ClientConnection, count: int) -> list[str]:
    return [receive_until(connection, text_op("status"))["msg"] for _ in range(count)]


def test_hostile_fragments_get_clear_errors_and_the_server_stays_fine(
        server: ServerProcess) -> None:
    with connect(server.ws_url, max_size=None) as hostile:
        send(hostile, {"op": "set_level", "level": "error"})
        send(hostile, {"op": "fragment", "id": "huge", "data": "{", "num": 0, "total": 10**9})
        send(hostile, {"op": "fragment", "id": "past", "data": "{", "num": 3, "total": 3})
        send(hostile, {"op": "fragment", "id": "mixed", "data": "{", "num": 0, "total": 3})
        send(hostile, {"op": "fragment", "id": "mixed", "data": "}", "num": 1, "total": 4})
        first, second, third = statuses(hostile, 3)
        assert f"more than the {LIMITS.max_fragments} fragments" in first
        assert "num must be below total (3)" in second
        assert "its first fragment said 3" in third
        for index in range(LIMITS.max_partial_messages):  # "mixed" is one already
            send(hostile, {"op": "fragment", "id": f"never-{index}", "data": "{", "num": 0,
                           "total": 2})
        assert "are already incomplete" in statuses(hostile, 1)[0]
        big = "x" * (LIMITS.max_frame_bytes // 2)  # two of them and more: over the bound
        send(hostile, {"op": "fragment", "id": "mixed", "data": big, "num": 2, "total": 3})
        send(hostile, {"op": "fragment", "id": "never-2", "data": big, "num": 1, "total": 2})
        assert "would hold more than" in statuses(hostile, 1)[0]
    with connect(server.ws_url) as flood:  # 10 000 one-byte fragments: past the rate limit
        send(flood, {"op": "set_level", "level": "error"})
        with pytest.raises(ConnectionClosed) as closed:
            for num in range(10_000):
                send(flood, {"op": "fragment", "id": "flood", "data": "x", "num": num,
                             "total": 10_000})
            receive_until(flood, lambda frame: False, timeout_s=10.0)
        received = closed.value.rcvd  # 1008, or none: aborted for not reading its close
        assert received is None or received.code == 1008
    assert server.health()["status"] == "ok"
    with connect(server.ws_url) as after:
        send(after, {"op": "subscribe", "topic": "/odom"})
        assert receive_until(after, text_op("publish"))["topic"] == "/odom"


def test_an_incomplete_message_is_dropped_after_fragment_timeout_with_an_error() -> None:
    clock = ManualClock()
    limits = ClientLimits(fragment_timeout_s=5.0)
    bridge = Bridge(clock=clock)
    outbox = Outbox()
    session = Session("test", False, outbox, limits=limits, clock=clock)
    bridge.connect(session)
    bridge.handle(session, '{"op": "set_level", "level": "error"}')
    bridge.handle(session, '{"op": "fragment", "id": 7, "data": "{", "num": 0, "total": 2}')
    clock.advance(6.0)
    bridge.handle(session, '{"op": "set_level", "level": "error"}')
    status = json.loads(str(outbox.pop()))
    assert "fragmented message 7: incomplete after 5 s (1 of 2 fragments" in status["msg"]
    assert len(session.fragments) == 0 and session.fragments.held_bytes == 0


# ---- binary frames in -------------------------------------------------------------------------

def test_json_in_a_binary_frame_is_accepted_as_rosbridge_server_reads_it(
        client: ClientConnection) -> None:
    client.send(json.dumps({"op": "subscribe", "topic": "/odom"}).encode())
    assert receive_until(client, text_op("publish"))["topic"] == "/odom"


def test_a_cbor_op_in_a_binary_frame_is_refused_as_not_utf8_json(
        client: ClientConnection) -> None:
    send(client, {"op": "set_level", "level": "error"})
    client.send(cbor2.dumps({"op": "subscribe", "topic": "/odom"}))
    assert "must hold JSON text in UTF-8" in receive_until(client, text_op("status"))["msg"]


# ---- cbor-raw ---------------------------------------------------------------------------------

def test_cbor_raw_odom_is_cdr_that_rosbags_decodes_to_the_json_odom_of_the_same_stamp(
        server: ServerProcess) -> None:
    store = get_typestore(Stores.ROS2_HUMBLE)
    with connect(server.ws_url) as raw, connect(server.ws_url) as text:
        send(text, {"op": "subscribe", "topic": "/odom"})
        send(raw, {"op": "subscribe", "topic": "/odom", "compression": "cbor-raw"})
        frame = cbor2.loads(receive_until(raw, lambda frame: isinstance(frame, bytes) and frame))
        assert (frame["op"], frame["topic"]) == ("publish", "/odom")
        assert set(frame["msg"]) == {"secs", "nsecs", "bytes"}
        assert abs(frame["msg"]["secs"] + frame["msg"]["nsecs"] / 1e9 - time.time()) < 60
        odom = store.deserialize_cdr(frame["msg"]["bytes"], "nav_msgs/msg/Odometry")
        stamp = (odom.header.stamp.sec, odom.header.stamp.nanosec)

        def same_stamp(candidate: str | bytes) -> Any:
            message = text_op("publish")(candidate)
            return message["msg"] if message and stamp_of(message["msg"]) == stamp else None

        json_odom = receive_until(text, same_stamp)
    assert odom.header.frame_id == json_odom["header"]["frame_id"]
    assert odom.child_frame_id == json_odom["child_frame_id"]
    for part in ("pose", "twist"):
        decoded, expected = getattr(odom, part), json_odom[part]
        assert list(decoded.covariance) == expected["covariance"]
        inner = getattr(decoded, part)
        for field, values in expected[part].items():
            assert {key: getattr(getattr(inner, field), key) for key in values} == values


def test_cbor_raw_of_a_message_that_cannot_be_serialized_is_an_error_status() -> None:
    frame = Encoded("/custom", {"data": 1}, "my_pkg/msg/Custom").frame("cbor-raw")
    assert isinstance(frame, str)
    status = json.loads(frame)
    assert status["op"] == "status" and status["level"] == "error"
    assert "my_pkg/msg/Custom is not a type websim can serialize" in status["msg"]


# ---- CBOR typed arrays ------------------------------------------------------------------------

ROSLIBJS_CLASSES = {"uint8": "Uint8Array", "int8": "Int8Array", "uint16": "Uint16Array",
                    "int16": "Int16Array", "uint32": "Uint32Array", "int32": "Int32Array",
                    "float32": "Float32Array", "float64": "Float64Array",
                    "uint64": "Array", "int64": "Array"}
"""What roslibjs's ``cborTypedArrayTags`` makes of each tag: 64-bit integers as plain arrays."""


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_cbor_typed_arrays_decode_in_roslibjs_as_their_typed_array_class() -> None:
    values = {element: [0, 1, 100] if element.startswith("u") else [-100, 0, 100]
              for element in CBOR_TYPED_ARRAYS}
    values["float32"], values["float64"] = [0.5, -1.25, 3e38], [0.1, -2.5, 1e300]
    message = {element: typed_sequence(element, items) for element, items in values.items()}
    message["data"] = Base64Bytes(base64.b64encode(bytes([0, 7, 255])).decode())
    decoded = run_node("cbor_decode.js", to_cbor({"msg": message}).hex())["msg"]
    for element, items in values.items():
        assert decoded[element]["typed"] == ROSLIBJS_CLASSES[element], element
        assert decoded[element]["values"] == pytest.approx(items, rel=1e-7), element
    assert decoded["data"] == {"typed": "Uint8Array", "values": [0, 7, 255]}


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_scan_ranges_over_cbor_decode_in_roslibjs_as_a_float32array(
        server: ServerProcess) -> None:
    with connect(server.ws_url) as client:
        send(client, {"op": "subscribe", "topic": "/scan", "compression": "cbor"})
        frame = receive_until(client, lambda frame: isinstance(frame, bytes) and frame)
    decoded = run_node("cbor_decode.js", frame.hex())
    assert decoded["msg"]["ranges"]["typed"] == "Float32Array"
    assert len(decoded["msg"]["ranges"]["values"]) == 360
