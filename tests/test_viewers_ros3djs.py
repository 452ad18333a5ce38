"""A stock ros3djs page (``tests/viewers/ros3djs.html``) against a real ``websim serve``.

ros3djs, roslib 1.4.1 and three.js come from npm (``tests/node/ros3djs/``, its own lock,
installed by scripts/test.sh) and are served with the page from this machine; nothing loads
from the internet. The page's TF client asks the embedded bridge's tf2_web_republisher for
its frames; the test reads the three.js scene through ``page.evaluate`` and checks each
object's world matrix against the robot's pose worked out from ``/odom`` and the laser's
mount (``viewer_rig``): the scan's points lie on the arena's walls, the odometry arrow is at
the robot's pose, the world's markers are in the scene.

The fixed frame is the page's parameter. Today's TF tree is odom -> base_link -> laser, so
the page's fixed frame is ``odom``: the /world markers (frame ``map``) are made but stay
hidden, as ros3djs hides an object whose frame the tree lacks, until map -> odom is on /tf.
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Iterator
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest
from page_helpers import ARTIFACTS, Bridge, open_page, wait_until_still
from viewer_rig import MOUNT, expected_pose, mounted_server, planar_pose

from chromium import launched_chromium, skip_reason
from conftest import ARENA_HALF_M
from server_process import ServerProcess, wait_for

__all__ = ["mounted_server"]  # a fixture of this module

TESTS = Path(__file__).resolve().parent
ROS3DJS = TESTS / "node" / "ros3djs" / "node_modules"
LIBRARIES = [ROS3DJS / "three" / "build" / "three.min.js",
             ROS3DJS / "roslib" / "build" / "roslib.min.js",
             ROS3DJS / "ros3d" / "build" / "ros3d.min.js"]
SKIP = skip_reason(LIBRARIES)
if SKIP is not None and "missing" in SKIP:
    SKIP = "ros3djs missing: run npm ci in tests/node/ros3djs/ (scripts/test.sh does)"

pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=SKIP or "")]

FIXED_FRAME = "odom"
"""The page's fixed frame: ``map`` once map -> odom is on /tf (then the markers show too)."""

ON_WALL_M = 0.01
"""A scan point drawn in the fixed frame is on a wall within this (the LiDAR is noiseless;
float32 ranges and the 10 mm translation threshold of the page's TF client)."""

SCENE = """() => {
  const node = (sn) => sn && { visible: sn.visible, frame: sn.frameID,
                               matrix: Array.from(sn.matrixWorld.elements) };
  const points = scan.points;
  const count = points.geom ? points.geom.drawRange.count : 0;
  const arrows = odometry.sns;
  return {
    scan: node(points.sn),
    scan_points: points.positions ? Array.from(points.positions.array.slice(0, 3 * count)) : [],
    odometry: node(arrows[arrows.length - 1]),
    arrow: arrows.length ? Array.from(arrows[arrows.length - 1].children[0].matrixWorld.elements)
                         : null,
    markers: Object.keys(markers.markers).map((key) => {
      const shape = markers.markers[key].children[0].children[0];  // SceneNode > Marker > mesh
      const vertices = shape && shape.geometry && shape.geometry.vertices;
      return { key: key, ...node(markers.markers[key]), points: vertices ? vertices.length : 0 };
    }),
  };
}"""
"""What the test reads of the page's scene: each SceneNode's world matrix (column-major) and
visibility, the scan's points in the laser frame, the odometry arrow's own matrix, the
markers."""


class QuietHandler(SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: Any) -> None:  # the base class names it so
        pass


@pytest.fixture(scope="module")
def page_server() -> Iterator[str]:
    """This machine serving ``tests/`` over HTTP (the page and its npm libraries)."""
    server = ThreadingHTTPServer(("127.0.0.1", 0),
                                 functools.partial(QuietHandler, directory=str(TESTS)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    thread.join(timeout=5)


def apply(matrix: list[float], x: float, y: float, z: float = 0.0) -> tuple[float, float]:
    """(x, y) of the point (x, y, z) moved by a three.js column-major 4x4 ``matrix``."""
    return (matrix[0] * x + matrix[4] * y + matrix[8] * z + matrix[12],
            matrix[1] * x + matrix[5] * y + matrix[9] * z + matrix[13])


def planar(matrix: list[float]) -> tuple[float, float, float]:
    """(x, y, yaw) of a planar three.js world matrix; asserts it is planar."""
    assert matrix[14] == pytest.approx(0.0, abs=1e-6)  # no height
    assert matrix[10] == pytest.approx(1.0, abs=1e-6)  # z stays z: no roll, no pitch
    return matrix[12], matrix[13], math.atan2(matrix[1], matrix[0])


def close(got: tuple[float, float, float], want: tuple[float, float, float],
          tolerance_m: float) -> bool:
    return (math.dist(got[:2], want[:2]) <= tolerance_m
            and abs(math.remainder(got[2] - want[2], 2 * math.pi)) <= 0.011)


@pytest.fixture
def bridge(mounted_server: ServerProcess) -> Iterator[Bridge]:
    client = Bridge(mounted_server.ws_url)
    client.subscribe("/odom")
    client.subscribe("/world")
    yield client
    client.close()


def test_a_stock_ros3djs_page_draws_scan_odometry_and_markers_where_the_robot_is(
        mounted_server: ServerProcess, page_server: str, bridge: Bridge) -> None:
    twist = {"linear": {"x": 0.25, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0,
                                                                     "z": 0.6}}
    bridge.send(op="publish", topic="/cmd_vel", msg=twist)  # drive an arc, then stop
    wait_for(lambda: any(planar_pose(odom)[2] > 0.8 for odom in bridge.messages("/odom")[-1:]),
             timeout_s=20, what="the robot to turn")
    bridge.send(op="publish", topic="/cmd_vel", msg={
        "linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}})
    odom = wait_until_still(bridge, timeout_s=10)
    robot = expected_pose(odom, "base_link")
    laser = expected_pose(odom, "laser")
    world = bridge.messages("/world")[-1]["markers"]

    with launched_chromium() as browser:
        context = browser.new_context()
        url = f"{page_server}/viewers/ros3djs.html?ws={mounted_server.ws_url}&fixed={FIXED_FRAME}"
        page, log = open_page(context, url)
        scene: dict[str, Any] = {}

        def drawn() -> bool:
            scene.update(page.evaluate(SCENE))
            return bool(scene["scan"] and scene["scan"]["visible"] and scene["scan_points"]
                        and scene["odometry"] and scene["odometry"]["visible"]
                        and len(scene["markers"]) == len(world))

        wait_for(drawn, timeout_s=30, what="the scan, the odometry and the markers in the scene")
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "ros3djs.png"))
        context.close()

    # The scan: its scene node is the laser's pose in the fixed frame ...
    assert scene["scan"]["frame"] == "laser"
    assert close(planar(scene["scan"]["matrix"]), laser, ON_WALL_M), (scene["scan"], laser)
    # ... so each point, drawn through it, lies on a wall of the 6 m arena (or at range_max,
    # where a beam towards a corner found nothing).
    values = scene["scan_points"]
    points = [(values[i], values[i + 1]) for i in range(0, len(values), 3)]
    assert len(points) == 360
    on_wall = 0
    for x, y in points:
        wx, wy = apply(scene["scan"]["matrix"], x, y)
        if abs(max(abs(wx), abs(wy)) - ARENA_HALF_M) <= ON_WALL_M:
            on_wall += 1
        else:
            assert math.hypot(x, y) == pytest.approx(3.5, abs=1e-5), (x, y, wx, wy)
    assert on_wall > 200
    # The odometry: the arrow sits at the robot's pose, pointing where it heads.
    assert scene["odometry"]["frame"] == "odom"
    assert close(planar(scene["odometry"]["matrix"]), (0.0, 0.0, 0.0), 1e-9)
    arrow = scene["arrow"]  # ros3djs builds its Arrow along its own +y axis
    assert (*planar(arrow)[:2], math.atan2(arrow[5], arrow[4])) == pytest.approx(robot)
    # The world's markers: made from /world, in frame map, hidden while the tree lacks map.
    assert {marker["frame"] for marker in scene["markers"]} == {"map"}
    walls = next(marker for marker in scene["markers"] if marker["points"])
    assert walls["points"] == len(world[0]["points"])
    assert not any(marker["visible"] for marker in scene["markers"])
    assert MOUNT["mount_yaw_rad"] != 0.0  # the laser's yaw was in the check
    assert log.page_errors == [] and log.foreign_requests() == []
