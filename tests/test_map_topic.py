"""/map over the bridge, and ``websim map``'s map_server files, held equal cell by cell.

The bridge's /map is the world's occupancy grid (``physics.occupancy``), latched: a client
that subscribes late gets it. ``websim map`` writes the nav2 map_server pair; read back the way
map_server reads it (nav2 ``map_io.cpp``: occupancy ``1 - grey/255``, thresholds, PGM row 0
the top), it is the /map a roslibpy client receives from ``websim serve``, origin and
orientation included.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cbor2
import numpy as np
import pytest
import roslibpy
import yaml
from bridge_rig import Rig, topics_of
from PIL import Image

from physics import load_world
from physics.map_grid import MAX_MAP_CELLS, GridGeometry
from physics.occupancy import OCCUPIED, OccupancyGrid, rasterise
from ros_nodes.robot_messages import occupancy_grid_msg
from rosbridge.core.encoding import to_json
from rosbridge.core.limits import ClientLimits
from websim.cli import main
from websim.map_command import PIXEL_FREE, PIXEL_OCCUPIED, PIXEL_UNKNOWN

from server_process import roslibpy_client, start_server, wait_for


def load_like_map_server(yaml_path: Path) -> dict[str, Any]:
    """The OccupancyGrid nav2's map_server makes of a YAML + image pair (trinary mode)."""
    meta = yaml.safe_load(yaml_path.read_text(encoding="utf-8"))
    assert meta["mode"] == "trinary"
    image = Image.open(yaml_path.parent / meta["image"])
    assert image.format == "PPM" and image.mode == "L"  # binary 8-bit PGM
    shade = np.asarray(image, dtype=np.float64) / 255.0
    occupancy = shade if meta["negate"] else 1.0 - shade
    cells = np.where(occupancy > meta["occupied_thresh"], 100,
                     np.where(occupancy < meta["free_thresh"], 0, -1))
    height, width = cells.shape
    data = [0] * (width * height)
    for y in range(height):  # map_server: data[width * (height - y - 1) + x] = pixel (x, y)
        for x in range(width):
            data[width * (height - y - 1) + x] = int(cells[y, x])
    x, y, yaw = meta["origin"]
    return {"info": {"resolution": meta["resolution"], "width": width, "height": height,
                     "origin": {"position": {"x": x, "y": y, "z": 0.0},
                                "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2),
                                                "w": math.cos(yaw / 2)}}},
            "data": data}


def cell_at(msg: dict[str, Any], x: float, y: float) -> int:
    """The value of the cell holding map point (x, y), read from a message's info and data."""
    info = msg["info"]  # a point on a grid line is in the cell above / to the right of it
    column = math.floor((x - info["origin"]["position"]["x"]) / info["resolution"] + 1e-9)
    row = math.floor((y - info["origin"]["position"]["y"]) / info["resolution"] + 1e-9)
    return int(msg["data"][row * info["width"] + column])


# ---- in process: the bridge --------------------------------------------------------------


def test_a_late_subscriber_gets_the_latched_map() -> None:
    rig = Rig()
    rig.tick(40)
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/map"})
    frames = rig.drain(client)
    assert topics_of(frames) == ["/map"]
    msg = frames[0]["msg"]
    grid = rasterise(load_world("empty"))
    assert msg["header"]["frame_id"] == "map"
    assert msg["info"]["map_load_time"] == msg["header"]["stamp"]
    assert (msg["info"]["width"], msg["info"]["height"]) == (123, 123)
    assert msg["info"]["resolution"] == 0.05
    assert msg["info"]["origin"] == {"position": {"x": -3.05, "y": -3.05, "z": 0.0},
                                     "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
    assert msg["data"] == grid.cells.ravel().tolist()
    assert cell_at(msg, -3.0, 0.0) == OCCUPIED and cell_at(msg, 0.0, 0.0) == 0
    assert cell_at(msg, -3.04, 0.0) == -1
    rig.tick(20)  # latched: sent once per subscription, never per tick
    assert topics_of(rig.drain(client)) == []
    assert rig.call(client, "/rosapi/topic_type", {"topic": "/map"})["values"] == {
        "type": "nav_msgs/msg/OccupancyGrid"}


def test_a_cbor_subscriber_gets_the_cells_as_an_int8_typed_array() -> None:
    rig = Rig()
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/map", "compression": "cbor"})
    data = cbor2.loads(client.outbox.pop())["msg"]["data"]
    assert isinstance(data, cbor2.CBORTag) and data.tag == 72  # RFC 8746: sint8
    cells = np.frombuffer(data.value, dtype=np.int8)
    assert (cells == rasterise(load_world("empty")).cells.ravel()).all()
    assert set(np.unique(cells).tolist()) == {-1, 0, 100}


def test_the_largest_map_fits_half_a_client_s_send_queue() -> None:
    # The bound's reason (physics.map_grid.MAX_MAP_CELLS): /map goes whole to each subscriber.
    side = math.isqrt(MAX_MAP_CELLS)
    worst = OccupancyGrid(GridGeometry(-1e3, -1e3, 0.05, side, side),
                          np.full((side, side), OCCUPIED, dtype=np.int8))
    text = to_json({"op": "publish", "topic": "/map", "msg": occupancy_grid_msg(worst, 1e9)})
    assert len(text) < ClientLimits().max_queued_bytes // 2


# ---- a real server, roslibpy, and websim map ---------------------------------------------


def test_websim_map_files_are_the_map_a_roslibpy_client_receives(tmp_path: Path) -> None:
    # The corridor: an L, 143 x 113 cells, asymmetric both ways, so a flipped, mirrored or
    # transposed image cannot pass. (--localization perfect: the flag's /tf, checked below.)
    server = start_server(["--world", "corridor", "--localization", "perfect"])
    try:
        with roslibpy_client(server) as client:
            received: list[dict[str, Any]] = []
            roslibpy.Topic(client, "/map", "nav_msgs/msg/OccupancyGrid").subscribe(
                received.append)
            tf: list[dict[str, Any]] = []
            roslibpy.Topic(client, "/tf", "tf2_msgs/msg/TFMessage").subscribe(tf.append)
            wait_for(lambda: received and tf, 10.0, "the latched /map and a /tf")
    finally:
        assert server.stop() == 0, "".join(server.output)
    assert [(t["header"]["frame_id"], t["child_frame_id"]) for t in tf[0]["transforms"]] == \
        [("map", "odom"), ("odom", "base_link"), ("base_link", "left_wheel"),
         ("base_link", "right_wheel")]
    assert main(["map", "corridor", "--out", str(tmp_path / "maps")]) == 0
    yaml_path = tmp_path / "maps" / "corridor.yaml"
    meta = yaml.safe_load(yaml_path.read_text(encoding="utf-8"))
    assert meta == {"image": "corridor.pgm", "mode": "trinary", "resolution": 0.05,
                    "origin": [-1.05, -0.55, 0.0], "negate": 0, "occupied_thresh": 0.65,
                    "free_thresh": 0.25}
    loaded = load_like_map_server(yaml_path)
    live = received[0]
    assert live["header"]["frame_id"] == "map"
    for key in ("resolution", "width", "height", "origin"):
        assert live["info"][key] == loaded["info"][key], key
    assert live["data"] == loaded["data"]
    assert np.bincount(np.asarray(live["data"]) + 1).tolist()[:2] == [508, 15151]
    # Where things are, read from each with its own origin: the wall along y = -0.5, the
    # free lanes, the wall x = 5 of the northern leg, and unknown beyond the bounds.
    for msg in (live, loaded):
        assert cell_at(msg, 2.0, -0.5) == OCCUPIED
        assert cell_at(msg, 2.0, 0.0) == 0 and cell_at(msg, 5.5, 4.5) == 0
        assert cell_at(msg, 5.0, 3.0) == OCCUPIED
        assert cell_at(msg, -1.04, 0.0) == -1
    # The PGM itself: row 0 is the map's top, so its last row is /map's row 0 (unknown).
    pixels = np.asarray(Image.open(tmp_path / "maps" / "corridor.pgm"))
    assert set(np.unique(pixels).tolist()) == {PIXEL_OCCUPIED, PIXEL_UNKNOWN, PIXEL_FREE}
    bottom_wall_row = round((-0.5 + 0.55) / 0.05)  # row 1 of /map: the wall y = -0.5
    assert (pixels[-1 - bottom_wall_row, 1:141] == PIXEL_OCCUPIED).all()


def test_websim_map_takes_the_resolution_from_the_world_or_the_flag(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    world = tmp_path / "room.yaml"
    text = ("map_resolution_m: 0.1\nstart: [0.5, 0.5, 0]\n"
            "boxes: [{center: [1.5, 1.0], size: [0.6, 0.3], yaw: 0.5236}]\n"
            "polylines: [{points: [[0, 0], [3, 0], [3, 2], [0, 2]], closed: true}]\n")
    world.write_text(text)
    assert main(["map", str(world), "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert out == (f"wrote {tmp_path / 'a' / 'room.yaml'} and {tmp_path / 'a' / 'room.pgm'}: "
                   "33 x 23 cells of 0.1 m, origin [-0.1, -0.1]\n")
    assert yaml.safe_load((tmp_path / "a" / "room.yaml").read_text())["resolution"] == 0.1
    assert main(["map", str(world), "--out", str(tmp_path / "b"), "--resolution", "0.05"]) == 0
    fine = load_like_map_server(tmp_path / "b" / "room.yaml")
    assert (fine["info"]["resolution"], fine["info"]["width"]) == (0.05, 63)
    # The box, rotated 30 deg, is solid: its centre cell is occupied.
    assert cell_at(fine, 1.5, 1.0) == OCCUPIED and cell_at(fine, 0.5, 0.5) == 0
    # Written beside the world, room.yaml would be the world file itself: refused.
    assert main(["map", str(world), "--out", str(tmp_path)]) == 2
    assert "is the world file itself; write the map to another folder" in \
        capsys.readouterr().err
    assert world.read_text() == text


def test_websim_map_refuses_bad_input_with_a_clear_error(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    cases = [
        (["map", "nowhere", "--out", str(tmp_path)],
         "nowhere: cannot read world file: No such file or directory (shipped worlds: "),
        (["map", "maze", "--out", str(blocker / "maps")],
         f"--out {blocker / 'maps'}: cannot make the folder: "),
        (["map", "maze", "--out", str(tmp_path), "--resolution", "nan"],
         "--resolution: a map resolution must be a finite number of metres > 0, got nan"),
        (["map", "maze", "--out", str(tmp_path), "--resolution", "0"], "> 0, got 0.0"),
        (["map", "maze", "--out", str(tmp_path), "--resolution", "-0.05"], "got -0.05"),
        (["map", "maze", "--out", str(tmp_path), "--resolution", "0.001"],
         "--resolution: 0.001 m over the world's 6 x 6 m gives about 36,036,009 cells, more "
         "than 500,000 (/map goes whole to every subscriber and must fit a client's send "
         "queue); use 0.0086 m or coarser"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("websim: error: ") and message in err, (argv, err)
        assert len(err.strip().splitlines()) == 1
    assert sorted(path.name for path in tmp_path.iterdir()) == ["file"]
