"""Worlds: YAML files of walls and obstacles, loaded into immutable dataclasses.

The format (every coordinate in the ``map`` frame, metres and radians)::

    name: maze                   # optional, shown in the browser
    start: [x, y, theta]         # spawn pose; default [0, 0, 0]
    walls:                       # thin line segments
      - [x1, y1, x2, y2]
    polylines:                   # chains of thin walls
      - {points: [[x, y], ...], closed: false}
    boxes:                       # solid rectangles
      - {center: [x, y], size: [width, height], yaw: 0.0}
    circles:                     # solid discs
      - {center: [x, y], radius: r}
    map_resolution_m: 0.05       # /map's cell side (m); default DEFAULT_MAP_RESOLUTION_M
    localization: none           # none | perfect: websim publishes map -> odom itself
    noise:                       # overrides the parameter file's noise section, key by key
      odom_linear_sigma_mps: 0.02
    lidar:                       # overrides the parameter file's lidar section (LIDAR_KEYS)
      angle_min_rad: -pi         # the first beam's angle: -pi gives -pi..pi, as rplidar_ros
    robots:                      # robots this world places (a shared world: --arena)
      - {name: alice, start: [x, y, theta], params: {mass_kg: 2.0}}

Boxes and polylines become wall segments; circles stay circles. Every error raises
``ConfigError`` naming the file and the entry, e.g. ``worlds/maze.yaml: walls[3]: ...``.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from physics.map_grid import (
    DEFAULT_MAP_RESOLUTION_M,
    check_resolution,
    default_resolution_m,
    grid_over,
)
from physics.params import LidarParams, NoiseParams, RobotParams
from physics.shipped import by_name, shipped
from physics.snapshots import Pose2D
from physics.validation import (
    ConfigError,
    as_finite_float,
    as_mapping,
    as_number_list,
    as_positive_float,
    check_keys,
    fail,
    load_yaml_file,
    shown,
    type_name,
)

WORLDS_DIR = shipped("physics", "worlds")
"""Where the shipped worlds live; ``load_world("maze")`` looks here."""

MIN_WALL_LENGTH_M = 1e-6
"""Shorter walls are refused: they have no direction, and the ray-cast normal is undefined."""

LOCALIZATIONS = ("none", "perfect")
"""What localizes the robot: ``none`` (the default: AMCL or SLAM publishes map -> odom, as on
the real robot, and websim must not fight them) or ``perfect`` (websim publishes map -> odom
from the ground truth, so map-frame tools work without a localizer)."""

_TOP_LEVEL_KEYS = ("name", "start", "walls", "polylines", "boxes", "circles",
                   "map_resolution_m", "localization", "noise", "lidar", "robots")
_NOISE_KEYS = tuple(item.name for item in dataclasses.fields(NoiseParams))
_ROBOT_KEYS = ("name", "start", "params")
_PARAM_KEYS = tuple(item.name for item in dataclasses.fields(RobotParams))

MAX_PLACED_ROBOTS = 1000
"""Most robots a world file may place (each is a body and a LiDAR: a bound on the file)."""

LIDAR_KEYS = ("angle_min_rad",)
"""What a world (or a scenario) may set of the LiDAR: the scan's angle range. The beams
always cover a full turn (``LidarParams.angle_increment_rad`` = 2 pi / num_rays), so the first
beam's angle sets the range: 0 (the default) gives 0..2pi, as the course's platform; -pi gives
-pi..pi (less one increment), as rplidar_ros and most course code that reads sectors expect."""

PI_ANGLE = re.compile(r"([+-]?)pi(?:/([1-9][0-9]?))?\Z")
"""An angle given as a multiple of pi in a file: ``pi``, ``-pi``, ``pi/2``, ``-pi/4``."""


@dataclass(frozen=True)
class Wall:
    """A thin wall segment in the map frame.

    Attributes:
        x1: first end x (m).
        y1: first end y (m).
        x2: second end x (m).
        y2: second end y (m).
        origin: the file entry it came from, e.g. ``"boxes[2]"``, for error messages.
    """

    x1: float
    y1: float
    x2: float
    y2: float
    origin: str

    @property
    def length_m(self) -> float:
        """Length of the segment (m)."""
        return math.hypot(self.x2 - self.x1, self.y2 - self.y1)


@dataclass(frozen=True)
class BoxObstacle:
    """A solid rectangle in the map frame (its sides are also walls, for the physics).

    Attributes:
        x: centre x (m).
        y: centre y (m).
        width_m: size along its own x axis (m).
        height_m: size along its own y axis (m).
        yaw_rad: its rotation (rad).
        origin: the file entry it came from, e.g. ``"boxes[0]"``.
    """

    x: float
    y: float
    width_m: float
    height_m: float
    yaw_rad: float
    origin: str


@dataclass(frozen=True)
class CircleObstacle:
    """A solid disc in the map frame.

    Attributes:
        x: centre x (m).
        y: centre y (m).
        radius_m: radius (m).
        origin: the file entry it came from, e.g. ``"circles[0]"``.
    """

    x: float
    y: float
    radius_m: float
    origin: str


@dataclass(frozen=True)
class PlacedRobot:
    """A robot a world file places (its ``robots`` list): where it starts, and how it differs.

    Attributes:
        name: its name (the class robot it is, in ``websim serve --class ROSTER --arena``).
        start: its spawn pose in the map frame (m, rad).
        params: robot parameters that override the parameter file's, as (``RobotParams``
            field, value) pairs (``params_over``).
        origin: the file entry it came from, e.g. ``"robots[1]"``.
    """

    name: str
    start: Pose2D
    params: tuple[tuple[str, float], ...]
    origin: str

    def params_over(self, base: RobotParams) -> RobotParams:
        """``base`` (the parameter file's robot) with this robot's values in place of its."""
        return dataclasses.replace(base, **dict(self.params))


@dataclass(frozen=True)
class World:
    """An immutable world.

    Attributes:
        name: a short display name.
        start: spawn pose in the map frame.
        walls: every wall segment, boxes and polylines included.
        circles: every solid disc.
        source: the file it was loaded from (or a label), for error messages.
        boxes: every solid rectangle (as walls already; kept for drawing them filled).
        map_resolution_m: the side of a cell of its occupancy map, /map (m).
        localization: one of ``LOCALIZATIONS``: who publishes map -> odom.
        noise: noise sigmas that override the parameter file's, as (``NoiseParams`` field,
            value) pairs (``noise_over``).
        lidar: LiDAR parameters that override the parameter file's, as (``LidarParams``
            field, value) pairs (``lidar_over``; ``LIDAR_KEYS``).
        robots: the robots it places, by name (a shared world; ``PlacedRobot``).
    """

    name: str
    start: Pose2D
    walls: tuple[Wall, ...]
    circles: tuple[CircleObstacle, ...]
    source: str
    boxes: tuple[BoxObstacle, ...] = ()
    map_resolution_m: float = DEFAULT_MAP_RESOLUTION_M
    localization: str = LOCALIZATIONS[0]
    noise: tuple[tuple[str, float], ...] = ()
    lidar: tuple[tuple[str, float], ...] = ()
    robots: tuple[PlacedRobot, ...] = ()

    def placed(self, name: str) -> PlacedRobot | None:
        """The robot of that name this world places, or None."""
        return next((robot for robot in self.robots if robot.name == name), None)

    def noise_over(self, base: NoiseParams) -> NoiseParams:
        """``base`` (the parameter file's noise) with this world's sigmas in place of its."""
        return dataclasses.replace(base, **dict(self.noise))

    def lidar_over(self, base: LidarParams) -> LidarParams:
        """``base`` (the parameter file's LiDAR) with this world's values in place of its."""
        values: dict[str, Any] = dict(self.lidar)
        return dataclasses.replace(base, **values) if values else base

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """Axis-aligned bounds ``(min_x, min_y, max_x, max_y)`` of all shapes and the start (m)."""
        xs = [self.start.x, *(robot.start.x for robot in self.robots)]
        ys = [self.start.y, *(robot.start.y for robot in self.robots)]
        for wall in self.walls:
            xs += [wall.x1, wall.x2]
            ys += [wall.y1, wall.y2]
        for circle in self.circles:
            xs += [circle.x - circle.radius_m, circle.x + circle.radius_m]
            ys += [circle.y - circle.radius_m, circle.y + circle.radius_m]
        return min(xs), min(ys), max(xs), max(ys)


def resolve_world_path(name_or_path: str | Path) -> Path:
    """Return the file for a path, or for the name of a shipped world (``"maze"``)."""
    return by_name(name_or_path, WORLDS_DIR)


def load_world(path: str | Path) -> World:
    """Load and validate a world file (or a shipped world by name, e.g. ``"maze"``).

    Raises:
        ConfigError: unreadable file, bad YAML, or an invalid entry; the message names both.
    """
    resolved = resolve_world_path(path)
    source = str(path)
    try:
        document = load_yaml_file(resolved, "world", source=source)
    except ConfigError as error:
        if resolved.exists():
            raise
        known = ", ".join(sorted(p.stem for p in WORLDS_DIR.glob("*.yaml")))
        raise ConfigError(f"{error} (shipped worlds: {known})") from None
    return world_from_dict(document, source=source)


def world_from_dict(document: Any, *, source: str = "<world>") -> World:
    """Validate a parsed world document (the YAML format above) and build a ``World``."""
    top = as_mapping(source, {} if document is None else document)
    check_keys(source, top, _TOP_LEVEL_KEYS)
    name = top.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise fail(f"{source}: name", f"expected text, got {shown(name)}")
    start = Pose2D(*as_number_list(f"{source}: start", top.get("start", [0, 0, 0]), 3))

    walls: list[Wall] = []
    for index, entry in enumerate(_as_list(source, top, "walls")):
        where = f"walls[{index}]"
        x1, y1, x2, y2 = as_number_list(f"{source}: {where}", entry, 4)
        walls.append(_checked_wall(source, Wall(x1, y1, x2, y2, where)))
    for index, entry in enumerate(_as_list(source, top, "polylines")):
        walls += _polyline_walls(source, f"polylines[{index}]", entry)
    boxes = [_box(source, f"boxes[{index}]", entry)
             for index, entry in enumerate(_as_list(source, top, "boxes"))]
    for box in boxes:
        where, corners = box.origin, box_corners(box)
        for side in range(4):
            (ax, ay), (bx, by) = corners[side], corners[(side + 1) % 4]
            walls.append(Wall(ax, ay, bx, by, where))
    circles = [_circle(source, f"circles[{index}]", entry)
               for index, entry in enumerate(_as_list(source, top, "circles"))]

    robots = _robots(source, top)
    for where, pose in (("start", start), *((f"{robot.origin} ({robot.name}).start",
                                             robot.start) for robot in robots)):
        for box in boxes:
            if _inside_convex(box_corners(box), pose.x, pose.y):
                raise fail(f"{source}: {where}", f"{list(pose)} is inside the box {box.origin}")
        for circle in circles:
            if math.hypot(pose.x - circle.x, pose.y - circle.y) < circle.radius_m:
                raise fail(f"{source}: {where}",
                           f"{list(pose)} is inside the circle {circle.origin}")
    world = World(name=name, start=start, walls=tuple(walls), circles=tuple(circles),
                  source=source, boxes=tuple(boxes),
                  map_resolution_m=check_resolution(
                      f"{source}: map_resolution_m",
                      top.get("map_resolution_m", DEFAULT_MAP_RESOLUTION_M)),
                  localization=_localization(source, top.get("localization", LOCALIZATIONS[0])),
                  noise=_noise(source, top.get("noise")),
                  lidar=lidar_overrides(f"{source}: lidar", top.get("lidar")), robots=robots)
    if "map_resolution_m" not in top:  # a large world's default map is coarser, not an error
        world = dataclasses.replace(world, map_resolution_m=default_resolution_m(world.bounds))
    grid_over(world.bounds, world.map_resolution_m, f"{source}: map_resolution_m")
    return world


def _localization(source: str, value: Any) -> str:
    if value not in LOCALIZATIONS:
        raise fail(f"{source}: localization", f"must be one of {', '.join(LOCALIZATIONS)}, "
                                              f"got {shown(value)}")
    return str(value)


def _noise(source: str, value: Any) -> tuple[tuple[str, float], ...]:
    """The world's ``noise`` section: sigmas checked as the parameter file's are."""
    if value is None:
        return ()
    where = f"{source}: noise"
    mapping = as_mapping(where, value)
    check_keys(where, mapping, _NOISE_KEYS)
    try:
        checked = NoiseParams(**mapping)
    except ConfigError as error:
        raise ConfigError(f"{where}.{error}") from None
    return tuple((name, float(getattr(checked, name))) for name in _NOISE_KEYS
                 if name in mapping)


def lidar_overrides(where: str, value: Any) -> tuple[tuple[str, float], ...]:
    """A ``lidar`` section (a world's, a scenario's): ``LIDAR_KEYS`` values, checked.

    An angle is a number (rad) or a multiple of pi (``PI_ANGLE``: ``-pi``, ``pi/2``).
    """
    if value is None:
        return ()
    mapping = as_mapping(where, value)
    check_keys(where, mapping, LIDAR_KEYS)
    values: dict[str, Any] = {}
    for key, given in mapping.items():
        match = PI_ANGLE.match(given) if isinstance(given, str) else None
        if match:
            values[key] = (-1.0 if match.group(1) == "-" else 1.0) * math.pi \
                / int(match.group(2) or 1)
        elif isinstance(given, str):
            raise fail(f"{where}.{key}", f"expected an angle in rad or a multiple of pi "
                                         f"(pi, -pi, pi/2), got {given!r:.40}")
        else:
            values[key] = as_finite_float(f"{where}.{key}", given)
    try:
        LidarParams(**values)
    except ConfigError as error:
        raise ConfigError(f"{where}.{error}") from None
    return tuple(values.items())


def _robots(source: str, top: Any) -> tuple[PlacedRobot, ...]:
    """The world's ``robots``, checked.

    Names unique, starts finite, params checked as the parameter file's robot section is, and
    no two footprints overlapping at their starts.
    """
    entries = _as_list(source, top, "robots")
    if len(entries) > MAX_PLACED_ROBOTS:
        raise fail(f"{source}: robots", f"at most {MAX_PLACED_ROBOTS} robots, got "
                                        f"{len(entries)}")
    robots: list[PlacedRobot] = []
    for index, entry in enumerate(entries):
        where = f"{source}: robots[{index}]"
        mapping = as_mapping(where, entry)
        check_keys(where, mapping, _ROBOT_KEYS)
        name = mapping.get("name")
        if not isinstance(name, str) or not name.strip() or len(name) > 64:
            raise fail(f"{where}.name", f"expected a robot's name (text), got {shown(name)}")
        if any(robot.name == name for robot in robots):
            raise fail(f"{where}.name", f"'{name}' is placed twice")
        if "start" not in mapping:
            raise fail(f"{where}.start", "missing: [x, y, theta]")
        pose = Pose2D(*as_number_list(f"{where}.start", mapping["start"], 3))
        params = as_mapping(f"{where}.params", mapping.get("params") or {})
        check_keys(f"{where}.params", params, _PARAM_KEYS)
        try:
            checked = RobotParams(**params)
        except ConfigError as error:
            raise ConfigError(f"{where}.params.{error}") from None
        robots.append(PlacedRobot(name, pose, tuple((key, float(getattr(checked, key)))
                                                    for key in _PARAM_KEYS if key in params),
                                  f"robots[{index}]"))
    default_radius = RobotParams().footprint_radius_m
    for index, robot in enumerate(robots):
        radius = dict(robot.params).get("footprint_radius_m", default_radius)
        for other in robots[:index]:
            reach = radius + dict(other.params).get("footprint_radius_m", default_radius)
            if math.hypot(robot.start.x - other.start.x, robot.start.y - other.start.y) < reach:
                raise fail(f"{source}: {robot.origin}.start",
                           f"{list(robot.start)}: the footprint of '{robot.name}' overlaps "
                           f"that of '{other.name}' ({other.origin})")
    return tuple(robots)


def _as_list(source: str, top: Any, key: str) -> list[Any]:
    value = top.get(key, [])
    if value is None:
        return []
    if not isinstance(value, list):
        raise fail(f"{source}: {key}", f"expected a list, got {type_name(value)} {shown(value)}")
    return value


def _checked_wall(source: str, wall: Wall) -> Wall:
    if wall.length_m < MIN_WALL_LENGTH_M:
        raise fail(f"{source}: {wall.origin}", "zero-length wall "
                   f"[{wall.x1}, {wall.y1}, {wall.x2}, {wall.y2}]")
    return wall


def _polyline_walls(source: str, where: str, entry: Any) -> list[Wall]:
    mapping = as_mapping(f"{source}: {where}", entry)
    check_keys(f"{source}: {where}", mapping, ("points", "closed"))
    raw_points = mapping.get("points")
    if not isinstance(raw_points, list) or len(raw_points) < 2:
        raise fail(f"{source}: {where}.points", f"expected a list of 2 or more [x, y] points, "
                   f"got {shown(raw_points)}")
    points = [as_number_list(f"{source}: {where}.points[{i}]", point, 2)
              for i, point in enumerate(raw_points)]
    closed = mapping.get("closed", False)
    if not isinstance(closed, bool):
        raise fail(f"{source}: {where}.closed", f"expected true or false, got {shown(closed)}")
    if closed and len(points) >= 3:
        points.append(points[0])
    return [_checked_wall(source, Wall(a[0], a[1], b[0], b[1], f"{where}.points[{i}]"))
            for i, (a, b) in enumerate(itertools.pairwise(points))]


def _box(source: str, where: str, entry: Any) -> BoxObstacle:
    mapping = as_mapping(f"{source}: {where}", entry)
    check_keys(f"{source}: {where}", mapping, ("center", "size", "yaw"))
    cx, cy = as_number_list(f"{source}: {where}.center", mapping.get("center"), 2)
    width, height = as_number_list(f"{source}: {where}.size", mapping.get("size"), 2)
    for label, value in (("width", width), ("height", height)):
        if value <= 0.0:
            raise fail(f"{source}: {where}.size", f"{label} must be > 0, got {shown(value)}")
    yaw = as_finite_float(f"{source}: {where}.yaw", mapping.get("yaw", 0.0))
    return BoxObstacle(cx, cy, width, height, yaw, where)


def box_corners(box: BoxObstacle) -> list[tuple[float, float]]:
    """The box's corners in the map frame (m), counter-clockwise."""
    cos_yaw, sin_yaw = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    corners = []
    for ux, uy in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
        dx, dy = ux * box.width_m, uy * box.height_m
        corners.append((box.x + cos_yaw * dx - sin_yaw * dy, box.y + sin_yaw * dx + cos_yaw * dy))
    return corners


def _circle(source: str, where: str, entry: Any) -> CircleObstacle:
    mapping = as_mapping(f"{source}: {where}", entry)
    check_keys(f"{source}: {where}", mapping, ("center", "radius"))
    x, y = as_number_list(f"{source}: {where}.center", mapping.get("center"), 2)
    radius = as_positive_float(f"{source}: {where}.radius", mapping.get("radius"))
    return CircleObstacle(x, y, radius, where)


def _inside_convex(corners: list[tuple[float, float]], x: float, y: float) -> bool:
    """True if (x, y) is strictly inside the counter-clockwise convex polygon ``corners``."""
    for (ax, ay), (bx, by) in zip(corners, corners[1:] + corners[:1], strict=True):
        if (bx - ax) * (y - ay) - (by - ay) * (x - ax) <= 0.0:
            return False
    return True
