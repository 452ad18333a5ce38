"""roslib 2.x's ROS2TFClient against a real ``websim serve``, unmodified, under Node.

The client asks the action ``/tf2_web_republisher`` for base_link, then laser and odom (each a
new goal, the previous one cancelled, as a page adding objects does) in fixed frame ``map``;
the robot (spawned off the origin, map -> odom published: ``viewer_rig``) drives an arc and
stops; what the client handed its callbacks last must be where ``/ground_truth``, ``/odom``
and the laser's mount put each frame, composed by hand.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from page_helpers import Bridge, wait_until_still
from viewer_rig import expected_pose, planar, same_pose, viewer_server

from server_process import ServerProcess, wait_for

__all__ = ["viewer_server"]  # a fixture of this module

NODE = shutil.which("node")
CLIENT_JS = Path(__file__).parent / "conformance" / "node" / "ros2_tf_client.mjs"
ROSLIB2 = Path(__file__).parent / "node" / "roslib2" / "node_modules" / "roslib"
SKIP = ("node not installed" if NODE is None else None if ROSLIB2.exists() else
        "roslib 2.x missing: run npm ci in tests/node/roslib2/ (scripts/test.sh does)")

FRAMES = ("base_link", "laser", "odom")


class NodeTfClient:
    """``node ros2_tf_client.mjs``: every transform it was handed, per frame, in order."""

    def __init__(self, url: str, fixed_frame: str, frames: tuple[str, ...]) -> None:
        assert NODE is not None
        self.process = subprocess.Popen([NODE, str(CLIENT_JS), url, fixed_frame, *frames],
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True)
        self._lock = threading.Lock()
        self._seen: dict[str, list[Any]] = {frame: [] for frame in frames}
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            event = json.loads(line)
            with self._lock:
                self._seen[event["frame"]].append(planar(event["translation"],
                                                         event["rotation"]))

    def seen(self, frame: str) -> list[Any]:
        with self._lock:
            return list(self._seen[frame])

    def stop(self) -> str:
        self.process.kill()
        _, stderr = self.process.communicate(timeout=10)
        return stderr


@pytest.fixture
def bridge(viewer_server: ServerProcess) -> Iterator[Bridge]:
    client = Bridge(viewer_server.ws_url)
    client.subscribe("/odom")
    client.subscribe("/ground_truth")
    yield client
    client.close()


@pytest.mark.skipif(SKIP is not None, reason=SKIP or "")
def test_ros2_tf_client_gets_the_robots_frames_in_map(viewer_server: ServerProcess,
                                                      bridge: Bridge) -> None:
    client = NodeTfClient(viewer_server.ws_url, "map", FRAMES)
    try:
        for frame in FRAMES:
            wait_for(lambda frame=frame: client.seen(frame), timeout_s=20,
                     what=f"the client's first {frame} transform")
        bridge.send(op="publish", topic="/cmd_vel", msg={
            "linear": {"x": 0.3, "y": 0.0, "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": 0.8}})
        wait_for(lambda: len(client.seen("base_link")) > 10, timeout_s=20,
                 what="transforms while driving")
        bridge.send(op="publish", topic="/cmd_vel", msg={
            "linear": {"x": 0.0, "y": 0.0, "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": 0.0}})
        odom = wait_until_still(bridge, timeout_s=10)
        truth = bridge.messages("/ground_truth")[-1]  # still too: of the same instant
        assert abs(expected_pose("odom", "base_link", odom, truth).theta) > 0.3  # it turned
        for frame in FRAMES:
            wait_for(lambda frame=frame: client.seen(frame) and same_pose(
                client.seen(frame)[-1], expected_pose("map", frame, odom, truth)),
                timeout_s=10, what=f"{frame} in the client where the messages put it in map")
        assert viewer_server.health()["status"] == "ok"
    finally:
        stderr = client.stop()
    assert "connection closed" not in stderr
