"""A stock ros3djs page (``tests/viewers/ros3djs.html``) against a real ``websim serve``.

ros3djs, roslib 1.4.1 and three.js come from npm (``tests/node/ros3djs/``, its own lock,
installed by scripts/test.sh) and are served with the page from this machine; nothing loads
from the internet. The page's TF client asks the embedded bridge's tf2_web_republisher for
its frames. The robot is spawned off the origin and turned, map -> odom is published and
the laser is mounted off-centre (``viewer_rig``), so no transform is the identity by chance.
The test reads the three.js scene through ``page.evaluate`` and checks each object's world
matrix against poses worked out from ``/odom`` and ``/ground_truth``, in both fixed frames
(the page's parameter): the map's corner is the grid's origin, the scan's points lie on the
arena's walls, the odometry arrow is at the robot's pose, the walls' markers are in the map.
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Iterator
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import pytest
from page_helpers import ARTIFACTS, Bridge, open_page, wait_until_still
from viewer_rig import expected_pose, viewer_server

from physics.frames import compose
from physics.snapshots import Pose2D

from chromium import launched_chromium, skip_reason
from conftest import ARENA_HALF_M
from server_process import ServerProcess, wait_for

__all__ = ["viewer_server"]  # a fixture of this module

TESTS = Path(__file__).resolve().parent
ROS3DJS = TESTS / "node" / "ros3djs" / "node_modules"
LIBRARIES = [ROS3DJS / "three" / "build" / "three.min.js",
             ROS3DJS / "roslib" / "build" / "roslib.min.js",
             ROS3DJS / "ros3d" / "build" / "ros3d.min.js"]
SKIP = skip_reason(LIBRARIES)
if SKIP is not None and "missing" in SKIP:
    SKIP = "ros3djs missing: run npm ci in tests/node/ros3djs/ (scripts/test.sh does)"

pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=SKIP or "")]

TF_TOLERANCE_M = 0.011
"""How far a drawn frame may be from the pose worked out: the page's TF client sends a frame
again only once it moved 1 cm or turned 0.01 rad (its transThres, angularThres)."""

ON_WALL_M = 0.04
"""A scan point drawn in the fixed frame is on a wall within this: the LiDAR is noiseless, but
its frame may be drawn up to 0.01 rad off (``TF_TOLERANCE_M``), 3 cm at 3 m."""

RANGE_MAX_M = 3.5
"""The shipped LiDAR's range_max: a beam towards a corner of the 6 m arena finds nothing."""

SCENE = """() => {
  const node = (sn) => sn && { visible: sn.visible, frame: sn.frameID,
                               matrix: Array.from(sn.matrixWorld.elements) };
  const points = scan.points;
  const count = points.geom ? points.geom.drawRange.count : 0;
  const arrows = odometry.sns;
  return {
    grid: grid.sceneNode && { ...node(grid.sceneNode),
                              mesh: Array.from(grid.currentGrid.matrixWorld.elements) },
    scan: node(points.sn),
    scan_points: points.positions ? Array.from(points.positions.array.slice(0, 3 * count)) : [],
    odometry: node(arrows[arrows.length - 1]),
    arrow: arrows.length ? Array.from(arrows[arrows.length - 1].children[0].matrixWorld.elements)
                         : null,
    robot: robotModel && robotModel.children.map(node),
    markers: Object.keys(markers.markers).map((key) => {
      const shape = markers.markers[key].children[0].children[0];  // SceneNode > Marker > mesh
      const vertices = shape && shape.geometry && shape.geometry.vertices;
      return { key: key, ...node(markers.markers[key]), points: vertices ? vertices.length : 0 };
    }),
  };
}"""
"""What the test reads of the page's scene: each SceneNode's world matrix (three.js,
column-major) and visibility, the map's mesh, the scan's points in the laser frame, the
odometry arrow's own matrix, the markers."""


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


@pytest.fixture(scope="module")
def robot_after_an_arc(viewer_server: ServerProcess) -> Iterator[tuple[Bridge, dict[str, Any],
                                                                       dict[str, Any]]]:
    """The robot driven along an arc and stopped: (a bridge client, its /odom, /ground_truth)."""
    bridge = Bridge(viewer_server.ws_url)
    for topic in ("/odom", "/ground_truth", "/world", "/map", "/robot_description"):
        bridge.subscribe(topic)
    bridge.send(op="publish", topic="/cmd_vel", msg={
        "linear": {"x": 0.25, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.6}})
    wait_for(lambda: len(bridge.messages("/odom")) > 30, timeout_s=20, what="1.5 s of driving")
    bridge.send(op="publish", topic="/cmd_vel", msg={
        "linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}})
    odom = wait_until_still(bridge, timeout_s=10)
    yield bridge, odom, bridge.messages("/ground_truth")[-1]  # still too: the same instant
    bridge.close()


def apply(matrix: list[float], x: float, y: float) -> tuple[float, float]:
    """(x, y) of the point (x, y, 0) moved by a three.js column-major 4x4 ``matrix``."""
    return (matrix[0] * x + matrix[4] * y + matrix[12], matrix[1] * x + matrix[5] * y + matrix[13])


def pose_of(matrix: list[float], forward: int = 0) -> Pose2D:
    """The planar pose of a three.js world matrix whose object points along its own axis
    ``forward`` (0: x, 1: y); asserts it is planar (no height, z stays z)."""
    assert matrix[14] == pytest.approx(0.0, abs=1e-6) and matrix[10] == pytest.approx(1.0)
    column = 4 * forward
    return Pose2D(matrix[12], matrix[13], math.atan2(matrix[column + 1], matrix[column]))


def assert_near(got: Pose2D, want: Pose2D, tolerance: float = TF_TOLERANCE_M) -> None:
    assert math.dist(got[:2], want[:2]) <= tolerance, (got, want)
    assert abs(math.remainder(got.theta - want.theta, 2 * math.pi)) <= tolerance, (got, want)


@pytest.mark.parametrize("fixed", ["map", "odom"])
def test_a_stock_ros3djs_page_draws_map_scan_odometry_and_walls_where_they_are(
        viewer_server: ServerProcess, page_server: str,
        robot_after_an_arc: tuple[Bridge, dict[str, Any], dict[str, Any]], fixed: str) -> None:
    bridge, odom, truth = robot_after_an_arc
    world = bridge.messages("/world")[-1]["markers"]
    info = bridge.messages("/map")[-1]["info"]

    with launched_chromium() as browser:
        context = browser.new_context()
        page, log = open_page(context, f"{page_server}/viewers/ros3djs.html?"
                                       f"ws={viewer_server.ws_url}&fixed={fixed}")
        scene: dict[str, Any] = {}

        def drawn() -> bool:
            scene.update(page.evaluate(SCENE))
            return bool(scene["grid"] and scene["grid"]["visible"] and scene["scan_points"]
                        and scene["scan"]["visible"] and scene["odometry"]
                        and scene["odometry"]["visible"] and len(scene["markers"]) == len(world)
                        and all(marker["visible"] for marker in scene["markers"])
                        and scene["robot"] and all(link["visible"] for link in scene["robot"]))

        wait_for(drawn, timeout_s=30, what=f"everything drawn in fixed frame {fixed}")
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / f"ros3djs-{fixed}.png"))
        context.close()

    def where(frame: str) -> Pose2D:
        return expected_pose(fixed, frame, odom, truth)

    # The map: its scene node is map's pose in the fixed frame; the grid's corner, drawn
    # through it, is the map's origin (the mesh is a plane of width x height cells, centred).
    assert scene["grid"]["frame"] == "map"
    assert_near(pose_of(scene["grid"]["matrix"]), where("map"))
    corner = apply(scene["grid"]["mesh"], -info["width"] / 2, -info["height"] / 2)
    origin = compose(where("map"), Pose2D(info["origin"]["position"]["x"],
                                          info["origin"]["position"]["y"], 0.0))
    assert math.dist(corner, origin[:2]) <= TF_TOLERANCE_M + 1e-9
    # The scan: its node is the laser's pose; each point drawn through it, taken to map, lies
    # on a wall of the 6 m arena, or at range_max where a beam towards a corner found nothing.
    assert scene["scan"]["frame"] == "laser"
    assert_near(pose_of(scene["scan"]["matrix"]), where("laser"))
    values = scene["scan_points"]
    points = [(values[i], values[i + 1]) for i in range(0, len(values), 3)]
    assert len(points) == 360
    to_map = expected_pose("map", fixed, odom, truth)  # the fixed frame in map
    on_wall = 0
    for x, y in points:
        in_fixed = apply(scene["scan"]["matrix"], x, y)
        in_map = compose(to_map, Pose2D(*in_fixed, 0.0))
        if abs(max(abs(in_map.x), abs(in_map.y)) - ARENA_HALF_M) <= ON_WALL_M:
            on_wall += 1
        else:
            assert math.hypot(x, y) == pytest.approx(RANGE_MAX_M, abs=1e-5), (x, y, in_map)
    assert on_wall > 200
    # The odometry: its node is odom's pose; the arrow (built along its own +y) is the robot's.
    assert scene["odometry"]["frame"] == "odom"
    assert_near(pose_of(scene["odometry"]["matrix"]), where("odom"))
    assert_near(pose_of(scene["arrow"], forward=1), where("base_link"))
    # The walls' markers: in map, drawn at map's pose, the LINE_LIST with every wall point.
    assert {marker["frame"] for marker in scene["markers"]} == {"map"}
    for marker in scene["markers"]:
        assert_near(pose_of(marker["matrix"]), where("map"))
    assert scene["markers"][0]["points"] == len(world[0]["points"])
    # The robot model: each link's visual at its frame (the wheels on /tf, the laser on
    # /tf_static), where base_link and the URDF's joint put it; the visuals' origins are
    # straight up their link's z.
    urdf = ElementTree.fromstring(bridge.messages("/robot_description")[-1]["data"])
    drawn = {link["frame"].lstrip("/"): link for link in scene["robot"]}
    assert set(drawn) == {link.get("name") for link in urdf.iter("link")
                          if link.find("visual") is not None}
    for name, link in drawn.items():
        visual_z = float(urdf.find(f"link[@name='{name}']/visual/origin").get("xyz").split()[2])
        joint = urdf.find(f"joint/child[@link='{name}']/..")
        at = Pose2D(0.0, 0.0, 0.0) if joint is None else Pose2D(
            *(float(v) for v in joint.find("origin").get("xyz").split()[:2]),
            float(joint.find("origin").get("rpy").split()[2]))
        want = compose(where("base_link"), at)
        joint_z = 0.0 if joint is None else float(joint.find("origin").get("xyz").split()[2])
        matrix = link["matrix"]
        assert math.dist((matrix[12], matrix[13]), want[:2]) <= TF_TOLERANCE_M, (name, want)
        assert matrix[14] == pytest.approx(joint_z + visual_z, abs=1e-6), name
    assert log.page_errors == [] and log.foreign_requests() == []
