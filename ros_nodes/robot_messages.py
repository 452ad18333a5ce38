"""The one definition of every ROS message the robot sends or reads, as plain dicts.

The embedded bridge and the rclpy node share these builders, so both publish the same shapes.
Field names and nesting are those of ROS 2 (``builtin_interfaces/Time`` is ``{sec,
nanosec}``); the value conventions (``TypedSequence``, ``Base64Bytes``) are
``rosbridge.msgs.values``'. Non-finite floats are the encoders' concern
(``rosbridge.core.encoding``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

from physics import ConfigError, LaserScan, Odometry, World
from physics.occupancy import OccupancyGrid, rasterise
from physics.validation import as_finite_float, shown
from rosbridge.msgs.values import Base64Bytes, Float32Sequence, Message, stamp, typed_sequence

ODOM_FRAME = "odom"
BASE_FRAME = "base_link"
LASER_FRAME = "laser"
MAP_FRAME = "map"

UNUSED_COVARIANCE = 1e6
"""Variance of the degrees of freedom a planar robot does not measure (z, roll, pitch)."""

ODOM_POSE_VARIANCE = 1e-3
"""Variance reported for odometry x, y and yaw when no noise model says otherwise (m^2, rad^2)."""

ODOM_TWIST_VARIANCE = 1e-4
"""Variance reported for odometry speeds when no noise model says otherwise."""


def prefixed_frames(msg: Message, prefix: str) -> Message:
    """A copy of a robot message with ``prefix`` before every frame id it names.

    Covers what the robot publishes: ``header.frame_id``, ``child_frame_id``, the transforms
    of a ``TFMessage`` and the markers of a ``MarkerArray`` (``alice/`` + ``odom``).
    """
    def renamed(item: Any) -> Any:
        if isinstance(item, dict):
            out = {key: renamed(value) for key, value in item.items()}
            for key in ("frame_id", "child_frame_id"):
                if isinstance(out.get(key), str) and out[key]:
                    out[key] = prefix + out[key]
            return out
        if isinstance(item, list) and item and isinstance(item[0], dict):
            return [renamed(value) for value in item]
        return item

    result: Message = renamed(msg)
    return result


def header(time_s: float, frame_id: str) -> Message:
    """``std_msgs/Header``."""
    return {"stamp": stamp(time_s), "frame_id": frame_id}


def vector3(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Message:
    """``geometry_msgs/Vector3`` (also the shape of ``Point``)."""
    return {"x": x, "y": y, "z": z}


def yaw_quaternion(theta: float) -> Message:
    """``geometry_msgs/Quaternion`` of a yaw ``theta`` (course text: w = cos, z = sin of θ/2)."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(theta / 2.0), "w": math.cos(theta / 2.0)}


def diagonal_covariance(diagonal: tuple[float, ...]) -> list[float]:
    """A row-major 6 x 6 covariance (``float64[36]``) with ``diagonal`` on its diagonal."""
    return typed_sequence("float64", _diagonal_matrix(diagonal))


@functools.lru_cache(maxsize=64)
def _diagonal_matrix(diagonal: tuple[float, ...]) -> tuple[float, ...]:
    """Built once per diagonal: the same few diagonals come every tick."""
    matrix = [0.0] * 36
    for index, value in enumerate(diagonal):
        matrix[index * 7] = value
    return tuple(matrix)


def odometry_msg(odom: Odometry, time_s: float, frame_id: str,
                 pose_variance: tuple[float, float, float] | None = None,
                 twist_variance: tuple[float, float] | None = None) -> Message:
    """``nav_msgs/Odometry`` of a pose in ``frame_id`` with body-frame speeds in base_link.

    Args:
        odom: pose (m, rad) and speeds (m/s, rad/s).
        time_s: stamp (s).
        frame_id: ``odom`` for odometry, ``map`` for ground truth.
        pose_variance: variances of x, y, yaw; ``None`` gives zeros (exact ground truth).
        twist_variance: variances of v and omega; ``None`` gives zeros.
    """
    px, py, pyaw = pose_variance or (0.0, 0.0, 0.0)
    tv, tw = twist_variance or (0.0, 0.0)
    unused = UNUSED_COVARIANCE if pose_variance else 0.0
    return {
        "header": header(time_s, frame_id),
        "child_frame_id": BASE_FRAME,
        "pose": {
            "pose": {"position": vector3(odom.x, odom.y),
                     "orientation": yaw_quaternion(odom.theta)},
            "covariance": diagonal_covariance((px, py, unused, unused, unused, pyaw)),
        },
        "twist": {
            "twist": {"linear": vector3(odom.v), "angular": vector3(z=odom.omega)},
            "covariance": diagonal_covariance((tv, tv if twist_variance else 0.0, unused,
                                               unused, unused, tw)),
        },
    }


def laser_scan_msg(scan: LaserScan, time_s: float, frame_id: str = LASER_FRAME) -> Message:
    """``sensor_msgs/LaserScan``; ``ranges`` keep their floats (inf included)."""
    return {
        "header": header(time_s, frame_id),
        "angle_min": scan.angle_min,
        "angle_max": scan.angle_max,
        "angle_increment": scan.angle_increment,
        "time_increment": scan.time_increment,
        "scan_time": scan.scan_time,
        "range_min": scan.range_min,
        "range_max": scan.range_max,
        "ranges": Float32Sequence(scan.ranges),
        "intensities": Float32Sequence(),
    }


def transform_stamped_msg(time_s: float, parent: str, child: str, x: float, y: float,
                          theta: float) -> Message:
    """``geometry_msgs/TransformStamped`` of a planar pose of ``child`` in ``parent``."""
    return {
        "header": header(time_s, parent),
        "child_frame_id": child,
        "transform": {"translation": vector3(x, y), "rotation": yaw_quaternion(theta)},
    }


def transform_msg(time_s: float, parent: str, child: str,
                  translation: tuple[float, float, float],
                  rotation: tuple[float, float, float, float]) -> Message:
    """``geometry_msgs/TransformStamped`` of ``child`` in ``parent``.

    Args:
        time_s: stamp (s).
        parent: the parent frame.
        child: the child frame.
        translation: (x, y, z) of the child's origin in the parent (m).
        rotation: the child's orientation as a quaternion (x, y, z, w).
    """
    x, y, z = translation
    qx, qy, qz, qw = rotation
    return {
        "header": header(time_s, parent),
        "child_frame_id": child,
        "transform": {"translation": vector3(x, y, z),
                      "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}},
    }


def axis_quaternion(axis: tuple[float, float, float],
                    angle_rad: float) -> tuple[float, float, float, float]:
    """The quaternion (x, y, z, w) of a turn by ``angle_rad`` about a unit ``axis``."""
    half = angle_rad / 2.0
    sin_half = math.sin(half)
    return axis[0] * sin_half, axis[1] * sin_half, axis[2] * sin_half, math.cos(half)


def clock_msg(time_s: float) -> Message:
    """``rosgraph_msgs/Clock``: the time of the tick (s since the epoch)."""
    return {"clock": stamp(time_s)}


def tf_msg(transforms: Sequence[Message]) -> Message:
    """``tf2_msgs/TFMessage``."""
    return {"transforms": list(transforms)}


def joint_state_msg(time_s: float, names: Sequence[str], positions: Sequence[float],
                    velocities: Sequence[float]) -> Message:
    """``sensor_msgs/JointState`` of joints by name: positions (rad), velocities (rad/s).

    No ``header.frame_id`` (joint states have none, as joint_state_publisher sends them) and
    no efforts.
    """
    return {
        "header": header(time_s, ""),
        "name": list(names),
        "position": typed_sequence("float64", positions),
        "velocity": typed_sequence("float64", velocities),
        "effort": typed_sequence("float64", ()),
    }


def robot_description_msg(urdf: str) -> Message:
    """``std_msgs/String`` holding the robot's URDF, as robot_state_publisher sends it."""
    return {"data": urdf}


MARKER_LINE_LIST = 5
MARKER_CYLINDER = 3
MARKER_CUBE = 1
MARKER_ADD = 0


def _marker(time_s: float, marker_id: int, marker_type: int, pose: Message, scale: Message,
            color: Message, points: list[Message]) -> Message:
    return {
        "header": header(time_s, MAP_FRAME), "ns": "world", "id": marker_id,
        "type": marker_type, "action": MARKER_ADD,
        "pose": pose, "scale": scale, "color": color,
        "lifetime": {"sec": 0, "nanosec": 0}, "frame_locked": False,
        "points": points, "colors": [], "texture_resource": "",
        "texture": {"header": header(0.0, ""), "format": "", "data": Base64Bytes()},
        "uv_coordinates": [], "text": "", "mesh_resource": "",
        "mesh_file": {"filename": "", "data": Base64Bytes()}, "mesh_use_embedded_materials": False,
    }


WALL_COLOR = {"r": 0.2, "g": 0.2, "b": 0.25, "a": 1.0}
WALL_LINE_WIDTH_M = 0.02


def world_markers_msg(world: World, time_s: float) -> Message:
    """``visualization_msgs/MarkerArray`` of the world, in ``map``.

    The walls as one LINE_LIST, each disc a CYLINDER, each box a CUBE (drawn filled; its
    sides are in the LINE_LIST too).
    """
    identity = {"position": vector3(), "orientation": yaw_quaternion(0.0)}
    points = []
    for wall in world.walls:
        points += [vector3(wall.x1, wall.y1), vector3(wall.x2, wall.y2)]
    markers = [_marker(time_s, 0, MARKER_LINE_LIST, identity, vector3(WALL_LINE_WIDTH_M),
                       WALL_COLOR, points)]
    for index, disc in enumerate(world.circles, start=1):
        pose = {"position": vector3(disc.x, disc.y), "orientation": yaw_quaternion(0.0)}
        size = 2.0 * disc.radius_m
        markers.append(_marker(time_s, index, MARKER_CYLINDER, pose, vector3(size, size, 0.3),
                               WALL_COLOR, []))
    for index, box in enumerate(world.boxes, start=1 + len(world.circles)):
        pose = {"position": vector3(box.x, box.y), "orientation": yaw_quaternion(box.yaw_rad)}
        markers.append(_marker(time_s, index, MARKER_CUBE, pose,
                               vector3(box.width_m, box.height_m, 0.3), WALL_COLOR, []))
    return {"markers": markers}


ROBOT_MARKER_HEIGHT_M = 0.12
"""How tall a robot's cylinder in ``/world_robots`` is drawn (m): about the chassis."""

ROBOT_COLOR = {"r": 0.15, "g": 0.39, "b": 0.92, "a": 0.8}


def world_robots_msg(names: Sequence[str], poses: Sequence[Sequence[float]],
                     radii_m: Sequence[float], time_s: float) -> Message:
    """``visualization_msgs/MarkerArray`` of a world's robots at a tick, in ``map``.

    One CYLINDER per robot (namespace ``world_robots``, its id its place in the world's spawn
    order, its ``text`` its name), the footprint's diameter wide, turned to the robot's yaw.

    Args:
        names: the robots' names.
        poses: each robot's (x, y, yaw) in the map frame (m, rad).
        radii_m: each robot's footprint radius (m).
        time_s: the stamp (s).
    """
    markers = []
    for index, (name, (x, y, yaw), radius) in enumerate(zip(names, poses, radii_m,
                                                             strict=True)):
        size = 2.0 * float(radius)
        pose = {"position": vector3(float(x), float(y), 0.5 * ROBOT_MARKER_HEIGHT_M),
                "orientation": yaw_quaternion(float(yaw))}
        marker = _marker(time_s, index, MARKER_CYLINDER, pose,
                         vector3(size, size, ROBOT_MARKER_HEIGHT_M), ROBOT_COLOR, [])
        marker["ns"] = WORLD_ROBOTS_NAMESPACE
        marker["text"] = name
        markers.append(marker)
    return {"markers": markers}


WORLD_ROBOTS_NAMESPACE = "world_robots"
"""The marker namespace of ``/world_robots`` (``/world``'s is ``world``)."""


MAPS_KEPT = 32
"""Worlds whose maps (grid and message data) are kept for the next robot in the same world:
a class's robots share one map per world instead of each holding ~0.1 MB of it."""


@functools.lru_cache(maxsize=MAPS_KEPT)
def world_map(world: World) -> OccupancyGrid:
    """``world``'s occupancy grid at its ``map_resolution_m``, made once per world (read-only).

    Raises:
        ConfigError: the world's grid is beyond ``physics.map_grid.MAX_MAP_CELLS``.
    """
    return rasterise(world)


@functools.lru_cache(maxsize=MAPS_KEPT)
def _map_data(grid: OccupancyGrid) -> list[Any]:
    """``OccupancyGrid.data`` of ``grid``, made once per grid and shared: never modify it."""
    return typed_sequence("int8", grid.cells.ravel().tolist())


def occupancy_grid_msg(grid: OccupancyGrid, time_s: float) -> Message:
    """``nav_msgs/OccupancyGrid`` of a rasterised world, in ``map``.

    ``info.origin`` is the lower-left corner of cell (0, 0), unrotated; ``data`` is row-major
    with row 0 at the origin's y (``physics.occupancy``). ``info.map_load_time`` is when it
    was made, as map_server stamps it.
    """
    geometry = grid.geometry
    return {
        "header": header(time_s, MAP_FRAME),
        "info": {
            "map_load_time": stamp(time_s),
            "resolution": geometry.resolution_m,
            "width": geometry.width,
            "height": geometry.height,
            "origin": {"position": vector3(geometry.origin_x_m, geometry.origin_y_m),
                       "orientation": yaw_quaternion(0.0)},
        },
        "data": _map_data(grid),
    }


def twist_from_msg(msg: Any, stamped: bool = False) -> tuple[float, float]:
    """``(linear.x, angular.z)`` from a ``geometry_msgs/Twist`` (or ``TwistStamped``) dict.

    Missing fields count as 0, as rosbridge fills them.

    Raises:
        ConfigError: a field is not an object, or a speed is not a finite number.
    """
    if stamped:
        msg = _field(msg, "twist", "TwistStamped")
    linear = _field(msg, "linear", "Twist")
    angular = _field(msg, "angular", "Twist")
    for name, part in (("linear", linear), ("angular", angular)):
        for axis in ("x", "y", "z"):
            if axis in part:
                value = part[axis]
                if type(value) is not float or not math.isfinite(value):  # else: fine
                    as_finite_float(f"{name}.{axis}", value)
    return (as_finite_float("linear.x", linear.get("x", 0.0)),
            as_finite_float("angular.z", angular.get("z", 0.0)))


def _field(msg: Any, name: str, type_name: str) -> Mapping[str, Any]:
    if not isinstance(msg, Mapping):
        raise ConfigError(f"{type_name}: expected an object, got {type(msg).__name__}")
    value = msg.get(name, {})
    if not isinstance(value, Mapping):
        raise ConfigError(f"{name}: expected an object, got {type(value).__name__} {shown(value)}")
    return value
