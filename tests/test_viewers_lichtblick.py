"""Lichtblick's rosbridge data source against ``websim serve --ros``: graph-only topics as CDR.

What Lichtblick's RosbridgePlayer sends (``conformance/node/rosbridge_player.js``, with
Lichtblick's own roslibjs fork, message parser and CDR reader from npm): rosapi's
``topics_and_raw_types``, then a ``cbor-raw`` subscribe without a type. The topic here is
``/chatter``, which only a real rclpy publisher on the graph publishes, latched (transient
local). Both players get its message decoded from the CDR they are sent: the first, which
subscribed without the type before anything relayed it, and the second, which came later and
gets the latched message (no new one in between); a raw client that names the type gets the
same bytes, decoded with rosbags. Then a new message reaches all three.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import subprocess
import threading
from pathlib import Path
from typing import Any

import cbor2
import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)
"""Fixtures domain, graph, test_world, ros_server."""

from rosbags.typesys import Stores, get_typestore  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

from ros_fixtures import LATCHED, Graph  # noqa: E402
from server_process import ServerProcess, wait_for  # noqa: E402

NODE = shutil.which("node")
PLAYER_JS = Path(__file__).parent / "conformance" / "node" / "rosbridge_player.js"
LICHTBLICK = Path(__file__).parent / "node" / "lichtblick" / "node_modules" / "@lichtblick"
SKIP = ("node not installed" if NODE is None else None if (LICHTBLICK / "roslibjs").exists()
        else "Lichtblick's packages missing: run npm ci in tests/node/lichtblick/ "
             "(scripts/test.sh does)")
TIMEOUT_S = 30.0
"""Discovery and a Node start on a loaded machine: generous."""


class Player:
    """``node rosbridge_player.js``: what it printed, as JSON lines."""

    def __init__(self, url: str, topic: str) -> None:
        assert NODE is not None
        self.process = subprocess.Popen([NODE, str(PLAYER_JS), url, topic],
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True)
        self._lock = threading.Lock()
        self._events: list[dict[str, Any]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            with self._lock:
                self._events.append(json.loads(line))

    def events(self) -> list[dict[str, Any]]:
        if self.process.poll() not in (None, -9):
            assert self.process.stderr is not None
            raise AssertionError(f"the player exited: {self.process.stderr.read()}")
        with self._lock:
            return list(self._events)

    def heard(self) -> list[str]:
        return [event["message"]["data"] for event in self.events() if "message" in event]

    def stop(self) -> None:
        self.process.kill()
        self.process.communicate(timeout=10)


class TypedRawClient:
    """A rosbridge client that subscribes with the type, cbor-raw, and decodes with rosbags."""

    def __init__(self, url: str, topic: str) -> None:
        self._stack = contextlib.ExitStack()
        self._ws = self._stack.enter_context(connect(url, max_size=None))
        self._ws.send(json.dumps({"op": "subscribe", "topic": topic, "compression": "cbor-raw",
                                  "type": "std_msgs/msg/String"}))
        self._store = get_typestore(Stores.ROS2_HUMBLE)

    def next_data(self) -> str:
        frame = self._ws.recv(timeout=TIMEOUT_S)
        assert isinstance(frame, bytes), frame  # an error status would be JSON text
        envelope = cbor2.loads(frame)
        return str(self._store.deserialize_cdr(envelope["msg"]["bytes"],
                                               "std_msgs/msg/String").data)

    def close(self) -> None:
        self._stack.close()


@pytest.mark.skipif(SKIP is not None, reason=SKIP or "")
def test_lichtblicks_rosbridge_player_decodes_a_graph_only_latched_topic(
        graph: Graph, ros_server: ServerProcess) -> None:
    chatter = graph.node.create_publisher(String, "/chatter", LATCHED)
    chatter.publish(String(data="latched hello"))
    first = Player(ros_server.ws_url, "/chatter")
    late: Player | None = None
    typed: TypedRawClient | None = None
    try:
        wait_for(lambda: first.heard(), TIMEOUT_S, "the first player's /chatter")
        assert first.events()[0] == {"subscribed": "/chatter", "schema": "std_msgs/msg/String"}
        assert first.heard() == ["latched hello"]
        late = Player(ros_server.ws_url, "/chatter")  # the same latched message, no new one
        wait_for(lambda: late.heard() if late else None, TIMEOUT_S, "the late player's /chatter")
        assert late.heard() == ["latched hello"]
        typed = TypedRawClient(ros_server.ws_url, "/chatter")
        assert typed.next_data() == "latched hello"

        chatter.publish(String(data="second"))
        for player in (first, late):
            wait_for(lambda player=player: len(player.heard()) == 2, TIMEOUT_S,
                     "the second message")
            assert player.heard() == ["latched hello", "second"]
        assert typed.next_data() == "second"
    finally:
        for player in (first, late):
            if player is not None:
                player.stop()
        if typed is not None:
            typed.close()
