"""ROS 2's ``simulation_interfaces`` standard, and turtlesim's names, over a world.

Each service of the standard is a function of a request (a dict of its fields, in either
generation's shape) and a ``Caller`` (its rights) to a response with the standard's result
codes; the same functions answer over rosbridge (``add_simulation_services``) and on the ROS
graph (``ros_nodes.simulation_node``). The world is a ``SimulatorControl``
(``ros_nodes.simulator_control``).

* Names: the root names Isaac Sim and O3DE give them (``SERVICES``, ``ACTION``), but
  ``ResetSimulation``: ``/reset_simulation`` is the robot's ``std_srvs/srv/Empty`` reset
  (gazebo_ros's name, the real robot's, every websim client's), and one name has one type, so
  the standard's lives at ``/websim/reset_simulation``.
* Shapes: the definitions are the package of today's ROS releases (Humble 1.4 to Kilted 1.6,
  ``rosbridge/msgs/interfaces/simulation_interfaces``: rosapi describes them, the ROS graph's
  package is built from them); requests of the development version (2.x:
  ``entity_resource``, ``SetEntityState``'s ``set_pose`` / ``set_twist`` /
  ``set_acceleration``; its files in ``.../simulation_interfaces/v2``) are accepted too, and a
  ``Spawnable`` is answered with both generations' fields.
* Results: every response carries a ``Result``; a request that does not fit its type is
  refused as rosbridge refuses it (the call fails with the reason). Rights refused are
  ``RESULT_OPERATION_FAILED`` with the reason.
* turtlesim's ``/spawn``, ``/kill``, ``/reset`` and ``/NAME/teleport_absolute``,
  ``/NAME/teleport_relative`` (``TURTLESIM_SERVICES``) call the same functions; they have no
  result field, so a refusal fails the call with the reason.

Rights (``Caller``): anyone may read. Moving or resetting a robot needs the right to drive
it; deleting a spawned entity, having spawned it (or the instructor's rights); spawning, the
instructor's rights or a student's quota (``--student-spawn N``); pausing, playing, stopping
and stepping, admin rights on the world (the instructor's; a student's in a world of their own
robot only). A reset needs the right to change everything it resets.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import re2

from physics import ConfigError
from physics.snapshots import Pose2D
from ros_nodes.simulator_control import (
    CATEGORY_ROBOT,
    ROBOT_DESCRIPTION,
    Caller,
    Entity,
    SimulatorControl,
    UnsupportedError,
)
from rosbridge.core.bridge import Bridge
from rosbridge.core.capabilities.actions import Cancel, GoalSender
from rosbridge.core.capabilities.services import Answer, Later
from rosbridge.core.errors import ServiceError, shorten
from rosbridge.core.schema import GoalStatus
from rosbridge.core.session import Session
from rosbridge.msgs import definitions
from rosbridge.msgs.checks import MessageError
from rosbridge.msgs.values import stamp

PACKAGE = "simulation_interfaces"

SERVICES = {
    "/get_simulator_features": "GetSimulatorFeatures",
    "/spawn_entity": "SpawnEntity",
    "/spawn_entities": "SpawnEntities",
    "/delete_entity": "DeleteEntity",
    "/get_entities": "GetEntities",
    "/get_entities_states": "GetEntitiesStates",
    "/get_entity_state": "GetEntityState",
    "/set_entity_state": "SetEntityState",
    "/get_entity_info": "GetEntityInfo",
    "/get_entity_bounds": "GetEntityBounds",
    "/websim/reset_simulation": "ResetSimulation",
    "/get_simulation_state": "GetSimulationState",
    "/set_simulation_state": "SetSimulationState",
    "/step_simulation": "StepSimulation",
    "/get_named_poses": "GetNamedPoses",
    "/get_spawnables": "GetSpawnables",
}
"""The standard's services websim offers: name -> type (``simulation_interfaces/srv/...``)."""

ACTION = "/simulate_steps"
ACTION_TYPE = f"{PACKAGE}/action/SimulateSteps"

TURTLESIM_SERVICES = {"/spawn": "turtlesim/srv/Spawn", "/kill": "turtlesim/srv/Kill",
                      "/reset": "std_srvs/srv/Empty"}
TELEPORT_ABSOLUTE = "teleport_absolute"
TELEPORT_RELATIVE = "teleport_relative"
"""Each entity NAME's ``/NAME/teleport_absolute`` and ``/NAME/teleport_relative``
(``turtlesim/srv/TeleportAbsolute``, ``TeleportRelative``)."""

TELEPORT_TYPES = {True: "turtlesim/srv/TeleportAbsolute", False: "turtlesim/srv/TeleportRelative"}

WATCHABLE_SERVICES = (*SERVICES, *TURTLESIM_SERVICES)
"""The names a client without the drive right may call (the rights are checked inside)."""

# Result.msg
FEATURE_UNSUPPORTED, OK, NOT_FOUND, INCORRECT_STATE, OPERATION_FAILED = 0, 1, 2, 3, 4
# SpawnEntity.srv / SpawnResult.msg
NAME_NOT_UNIQUE, NAME_INVALID, UNSUPPORTED_FORMAT, NO_RESOURCE = 101, 102, 103, 104
NAMESPACE_INVALID, INVALID_POSE = 105, 109
SET_INVALID_POSE = 101  # SetEntityState.srv
ENTITIES_SPAWN_FAILED = 150  # SpawnEntities.srv
ALREADY_IN_TARGET_STATE, INCORRECT_TRANSITION = 101, 103  # SetSimulationState.srv
# SimulationState.msg
STATE_STOPPED, STATE_PLAYING, STATE_PAUSED, STATE_QUITTING = 0, 1, 2, 3
# ResetSimulation.srv
SCOPE_DEFAULT, SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED, SCOPE_ALL = 0, 1, 2, 4, 255
# Bounds.msg, TagsFilter.msg
BOUNDS_EMPTY, BOUNDS_BOX, BOUNDS_CONVEX_HULL, BOUNDS_SPHERE = 0, 1, 2, 3
FILTER_MODE_ANY, FILTER_MODE_ALL = 0, 1

# SimulatorFeatures.msg
SPAWNING, DELETING, NAMED_POSES, ENTITY_TAGS, ENTITY_BOUNDS = 0, 1, 2, 4, 5
ENTITY_BOUNDS_BOX, ENTITY_CATEGORIES = 6, 8
ENTITY_STATE_GETTING, ENTITY_STATE_SETTING, ENTITY_INFO_GETTING, SPAWNABLES = 10, 11, 12, 14
SIMULATION_RESET, SIMULATION_RESET_STATE, SIMULATION_RESET_SPAWNED = 20, 22, 23
SIMULATION_STATE_GETTING, SIMULATION_STATE_SETTING, SIMULATION_STATE_PAUSE = 24, 25, 26
STEP_SIMULATION_SINGLE, STEP_SIMULATION_MULTIPLE, STEP_SIMULATION_ACTION = 31, 32, 33
SPAWNING_ENTITIES = 50

ALWAYS_FEATURES = (NAMED_POSES, ENTITY_TAGS, ENTITY_BOUNDS, ENTITY_BOUNDS_BOX, ENTITY_CATEGORIES,
                   ENTITY_STATE_GETTING, ENTITY_STATE_SETTING, ENTITY_INFO_GETTING,
                   SIMULATION_RESET, SIMULATION_RESET_STATE, SIMULATION_STATE_GETTING,
                   SIMULATION_STATE_SETTING, SIMULATION_STATE_PAUSE, STEP_SIMULATION_SINGLE,
                   STEP_SIMULATION_MULTIPLE, STEP_SIMULATION_ACTION)
SPAWN_FEATURES = (SPAWNING, DELETING, SPAWNABLES, SIMULATION_RESET_SPAWNED, SPAWNING_ENTITIES)
"""The features websim lists: ``ALWAYS_FEATURES``, and ``SPAWN_FEATURES`` in a world that
spawns (``SimulatorControl.can_spawn``). Not: POSE_BOUNDS, ENTITY_BOUNDS_CONVEX,
SPAWNING_RESOURCE_STRING, ENTITY_INFO_SETTING, SIMULATION_RESET_TIME (published time never
goes back: ``/clock`` and every stamp count on across resets), the world services."""

ROBOT_URI = "websim://robot"
"""The one spawnable: the course's robot, with the server's parameters."""

SPAWN_FORMAT = "websim"

WORLD_FRAMES = ("", "world", "map")
"""The frames a pose may be given in: the world's (websim calls it ``map``)."""

STATE_FRAME = "map"

MAX_FILTER_CHARS = 256
"""Longest ``EntityFilters.filter`` (RE2 matches in linear time; this bounds the compile)."""

MAX_STEPS = 72_000
"""Most steps one StepSimulation or SimulateSteps asks for: an hour of simulated time."""

MAX_SPAWN_REQUESTS = 64
"""Most entities one SpawnEntities spawns."""

MAX_COORDINATE_M = 1000.0
"""A pose farther from the origin than this on either axis is INVALID_POSE (m)."""

PLANAR_TOLERANCE = 1e-6
"""How far from the ground plane (z, m) or from upright (roll, pitch: quaternion x, y) a pose
may be: websim is planar."""

FEATURE_REASONS = {
    SCOPE_TIME: "SCOPE_TIME: websim never sets time back (/clock and every stamp count on "
                "across resets); reset SCOPE_STATE",
}


def result(code: int, message: str = "") -> dict[str, Any]:
    """A ``simulation_interfaces/msg/Result``."""
    return {"result": code, "error_message": shorten(message)}


class ResultError(Exception):
    """A call answered with a result code other than OK (the code and the reason)."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


# ---- requests ---------------------------------------------------------------------------------

def request(service_type: str, args: Any) -> dict[str, Any]:
    """``args`` as a ``service_type`` request (its fields only, defaults filled in).

    Raises:
        ServiceError: a field the type lacks, or a value of the wrong type (as rosbridge
            refuses a request it cannot fill in).
    """
    try:
        return definitions.canonical(f"{service_type}_Request",
                                     {} if args in ([], None) else args)
    except MessageError as error:
        raise ServiceError(f"{service_type}: {error}") from None


def _v2_resource(args: Mapping[str, Any], field: str) -> dict[str, Any]:
    """A 2.x request (``entity_resource``) in 1.x shape (``uri``, ``resource_string``)."""
    if not isinstance(args, Mapping) or field not in args:
        return dict(args) if isinstance(args, Mapping) else args
    out = {key: value for key, value in args.items() if key != field}
    if "uri" in out or "resource_string" in out:
        raise ServiceError(f"{field}: give either {field} (simulation_interfaces 2.x) or uri "
                           "and resource_string (1.x), not both")
    try:
        resource = definitions.canonical(f"{PACKAGE}/msg/Resource", args[field])
    except MessageError as error:
        raise ServiceError(f"{field}.{error}") from None
    out.update(resource)
    return out


def spawn_request(args: Any) -> dict[str, Any]:
    """A SpawnEntity request of either generation, in the 1.x shape."""
    return request(f"{PACKAGE}/srv/SpawnEntity", _v2_resource(args or {}, "entity_resource"))


SET_FLAGS = ("set_pose", "set_twist", "set_acceleration")
"""SetEntityState's 2.x flags; a 1.x request (none of them) sets pose and twist."""


def set_state_request(args: Any) -> tuple[dict[str, Any], dict[str, bool]]:
    """A SetEntityState request of either generation and which parts to set."""
    args = dict(args) if isinstance(args, Mapping) else args
    flags = {"set_pose": True, "set_twist": True, "set_acceleration": False}
    if isinstance(args, dict) and any(flag in args for flag in SET_FLAGS):
        for flag in SET_FLAGS:
            value = args.pop(flag, False)
            if not isinstance(value, bool):
                raise ServiceError(f"{flag}: expected a bool, got {type(value).__name__}")
            flags[flag] = value
    return request(f"{PACKAGE}/srv/SetEntityState", args), flags


# ---- poses ------------------------------------------------------------------------------------

def quaternion(yaw_rad: float) -> dict[str, float]:
    """The quaternion of a rotation of ``yaw_rad`` about z."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw_rad / 2.0), "w": math.cos(yaw_rad / 2.0)}


def planar_pose(pose: Mapping[str, Any], frame_id: str, what: str, code: int) -> Pose2D:
    """A ``geometry_msgs/Pose`` in a world frame as a planar pose (x, y, yaw).

    An all-zero quaternion is the identity (ROS 2's default ``w: 1`` a JSON client left out).

    Raises:
        ResultError: another frame (OPERATION_FAILED), or not on the ground plane, upright and
            within ``MAX_COORDINATE_M`` (``code``: the service's INVALID_POSE).
    """
    if frame_id not in WORLD_FRAMES:
        raise ResultError(OPERATION_FAILED, f"{what}: frame '{frame_id[:40]}' is not the "
                                        "world's: give poses in 'map' (or 'world', or '')")
    position, orientation = pose["position"], pose["orientation"]
    qx, qy, qz, qw = (orientation[key] for key in ("x", "y", "z", "w"))
    values = (position["x"], position["y"], position["z"], qx, qy, qz, qw)
    if not all(math.isfinite(value) for value in values):
        raise ResultError(code, f"{what}: not a finite pose")
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if norm == 0.0:
        qw, norm = 1.0, 1.0
    if abs(qx) / norm > PLANAR_TOLERANCE or abs(qy) / norm > PLANAR_TOLERANCE:
        raise ResultError(code, f"{what}: the orientation is not a rotation about z (websim is "
                            "planar: robots stay upright)")
    if abs(position["z"]) > PLANAR_TOLERANCE:
        raise ResultError(code, f"{what}: z is {position['z']:g}; websim is planar (z = 0)")
    if max(abs(position["x"]), abs(position["y"])) > MAX_COORDINATE_M:
        raise ResultError(code, f"{what}: ({position['x']:g}, {position['y']:g}) is beyond "
                            f"{MAX_COORDINATE_M:g} m of the origin")
    return Pose2D(position["x"], position["y"], 2.0 * math.atan2(qz / norm, qw / norm))


def entity_state(control: SimulatorControl, name: str) -> dict[str, Any]:
    """An ``EntityState``: ground truth in the map frame, the twist in it too."""
    truth = control.state(name)
    return {
        "header": {"stamp": stamp(control.stamp_s()), "frame_id": STATE_FRAME},
        "pose": {"position": {"x": truth.x, "y": truth.y, "z": 0.0},
                 "orientation": quaternion(truth.theta)},
        "twist": {"linear": {"x": truth.v * math.cos(truth.theta),
                             "y": truth.v * math.sin(truth.theta), "z": 0.0},
                  "angular": {"x": 0.0, "y": 0.0, "z": truth.omega}},
        "acceleration": {"linear": {"x": 0.0, "y": 0.0, "z": 0.0},
                         "angular": {"x": 0.0, "y": 0.0, "z": 0.0}},
    }


def _zero_twist(twist: Mapping[str, Any]) -> bool:
    return all(twist[part][axis] == 0.0 for part in ("linear", "angular")
               for axis in ("x", "y", "z"))


# ---- filters ----------------------------------------------------------------------------------

def _name_filter(pattern: str) -> Callable[[str], bool]:
    """``EntityFilters.filter``: POSIX extended regular expression, searched in a name."""
    if not pattern:
        return lambda name: True
    if len(pattern) > MAX_FILTER_CHARS:
        raise ResultError(OPERATION_FAILED, f"filter: at most {MAX_FILTER_CHARS} characters")
    options = re2.Options()
    options.posix_syntax = True
    options.longest_match = True
    options.log_errors = False
    try:
        compiled = re2.compile(pattern, options)
    except re2.error as error:
        why = error.args[0].decode(errors="replace") if error.args and \
            isinstance(error.args[0], bytes) else str(error)
        raise ResultError(OPERATION_FAILED, f"filter: not a POSIX extended regular expression: "
                                            f"{why}") from None
    return lambda name: compiled.search(name) is not None


def _tags_match(tags: tuple[str, ...], wanted: Mapping[str, Any]) -> bool:
    asked = wanted["tags"]
    if not asked:
        return True
    mode = wanted["filter_mode"]
    if mode == FILTER_MODE_ANY:
        return any(tag in tags for tag in asked)
    if mode == FILTER_MODE_ALL:
        return all(tag in tags for tag in asked)
    raise ResultError(OPERATION_FAILED, f"tags.filter_mode: {mode} is neither FILTER_MODE_ANY (0) "
                                    "nor FILTER_MODE_ALL (1)")


def _overlap(bounds: Mapping[str, Any]) -> Callable[[Entity, float, float], bool] | None:
    """The overlap test of ``EntityFilters.bounds`` (None: empty bounds, everything)."""
    kind, points = bounds["type"], bounds["points"]
    coordinates = [(p["x"], p["y"], p["z"]) for p in points]
    if not all(math.isfinite(value) for point in coordinates for value in point):
        raise ResultError(OPERATION_FAILED, "bounds: not finite")
    if kind == BOUNDS_EMPTY:
        return None
    if kind == BOUNDS_SPHERE:
        if len(coordinates) < 2 or coordinates[1][0] < 0.0:
            raise ResultError(OPERATION_FAILED, "bounds: TYPE_SPHERE takes the centre and a point "
                                            "whose x is the radius (>= 0)")
        (cx, cy, cz), radius = coordinates[0], float(coordinates[1][0])

        def in_sphere(entity: Entity, x: float, y: float) -> bool:
            radial = max(0.0, math.hypot(cx - x, cy - y) - entity.radius_m)
            vertical = max(0.0, -cz, cz - entity.height_m)
            return bool(math.hypot(radial, vertical) <= radius)
        return in_sphere
    if kind == BOUNDS_BOX:
        if len(coordinates) != 2:
            raise ResultError(OPERATION_FAILED, "bounds: TYPE_BOX takes two opposite corners")
        (x1, y1, z1), (x2, y2, z2) = coordinates
        low, high = (min(x1, x2), min(y1, y2), min(z1, z2)), (max(x1, x2), max(y1, y2),
                                                              max(z1, z2))

        def in_box(entity: Entity, x: float, y: float) -> bool:
            nearest_x = min(max(x, low[0]), high[0])
            nearest_y = min(max(y, low[1]), high[1])
            return (math.hypot(x - nearest_x, y - nearest_y) <= entity.radius_m
                    and low[2] <= entity.height_m and high[2] >= 0.0)
        return in_box
    if kind == BOUNDS_CONVEX_HULL:
        raise ResultError(FEATURE_UNSUPPORTED, "bounds: TYPE_CONVEX_HULL is not supported "
                                           "(ENTITY_BOUNDS_CONVEX is not listed); use "
                                           "TYPE_BOX or TYPE_SPHERE")
    raise ResultError(OPERATION_FAILED, f"bounds: unknown type {kind}")


def filtered(control: SimulatorControl, filters: Mapping[str, Any]) -> list[Entity]:
    """The entities matching ``EntityFilters`` (name, categories, tags and bounds, all)."""
    name_ok = _name_filter(filters["filter"])
    categories = {entry["category"] for entry in filters["categories"]}
    overlap = _overlap(filters["bounds"])
    out = []
    for entity in control.entities():
        if not name_ok(entity.name) or (categories and entity.category not in categories):
            continue
        if not _tags_match(entity.tags, filters["tags"]):
            continue
        if overlap is not None:
            truth = control.state(entity.name)
            if not overlap(entity, truth.x, truth.y):
                continue
        out.append(entity)
    return out


# ---- rights ------------------------------------------------------------------------------------

def may_change(caller: Caller, entity: Entity) -> bool:
    """Whether ``caller`` may move or reset ``entity``."""
    if caller.admin:
        return True
    if entity.spawned and entity.owner is not None:
        return entity.owner == caller.name
    return entity.category == CATEGORY_ROBOT and (caller.drives is None
                                                  or entity.name in caller.drives)


def may_delete(caller: Caller, entity: Entity) -> bool:
    """Whether ``caller`` may delete ``entity``: the instructor, or who spawned it."""
    return caller.admin or (entity.spawned and entity.owner is not None
                            and entity.owner == caller.name)


def _denied(what: str) -> ResultError:
    return ResultError(OPERATION_FAILED, f"{what}: not yours to change (it needs the token of its "
                                     "robot, or the instructor's)")


# ---- the services ------------------------------------------------------------------------------

@dataclass
class SimulationServices:
    """The standard's services over ``control``: ``call(service, args, caller)``.

    Args:
        control: the world.
    """

    control: SimulatorControl

    def features(self) -> list[int]:
        """The features this world supports, exactly."""
        extra = SPAWN_FEATURES if self.control.can_spawn else ()
        return sorted((*ALWAYS_FEATURES, *extra))

    def call(self, type_name: str, args: Any, caller: Caller) -> Mapping[str, Any] | Later:
        """Answer a call of ``simulation_interfaces/srv/TYPE_NAME``.

        Raises:
            ServiceError: the request does not fit the type.
        """
        handler = getattr(self, TYPE_HANDLERS[type_name])
        try:
            response: Mapping[str, Any] | Later = handler(args, caller)
        except ResultError as refusal:
            return {"result": result(refusal.code, str(refusal))}
        except UnsupportedError as error:
            return {"result": result(FEATURE_UNSUPPORTED, str(error))}
        return response

    def _entity(self, name: str) -> Entity:
        for entity in self.control.entities():
            if entity.name == name:
                return entity
        raise ResultError(NOT_FOUND, f"no entity '{name[:60]}' (GetEntities lists them)")

    # -- features, entities ----------------------------------------------------------------

    def get_simulator_features(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetSimulatorFeatures: exactly the features this world supports."""
        request(f"{PACKAGE}/srv/GetSimulatorFeatures", args)
        return {"features": {
            "features": self.features(),
            "spawn_formats": [SPAWN_FORMAT] if self.control.can_spawn else [],
            "custom_info": "websim: simulation_interfaces 1.x and 2.x requests; "
                           "ResetSimulation at /websim/reset_simulation (docs/arena.md)"}}

    def get_entities(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetEntities: the names of the entities matching the filters."""
        fields = request(f"{PACKAGE}/srv/GetEntities", args)
        entities = filtered(self.control, fields["filters"])
        return {"result": result(OK), "entities": [entity.name for entity in entities]}

    def get_entities_states(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetEntitiesStates: the entities matching the filters, and their states."""
        fields = request(f"{PACKAGE}/srv/GetEntitiesStates", args)
        entities = filtered(self.control, fields["filters"])
        return {"result": result(OK), "entities": [entity.name for entity in entities],
                "states": [entity_state(self.control, entity.name) for entity in entities]}

    def get_entity_state(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetEntityState: an entity's ground truth (map frame)."""
        fields = request(f"{PACKAGE}/srv/GetEntityState", args)
        entity = self._entity(fields["entity"])
        return {"result": result(OK), "state": entity_state(self.control, entity.name)}

    def get_entity_info(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetEntityInfo: an entity's category, description and tags."""
        fields = request(f"{PACKAGE}/srv/GetEntityInfo", args)
        entity = self._entity(fields["entity"])
        return {"result": result(OK), "info": {"category": {"category": entity.category},
                                               "description": entity.description,
                                               "tags": list(entity.tags)}}

    def get_entity_bounds(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetEntityBounds: an entity's box about its origin (TYPE_BOX)."""
        fields = request(f"{PACKAGE}/srv/GetEntityBounds", args)
        entity = self._entity(fields["entity"])
        r = entity.radius_m
        return {"result": result(OK), "bounds": {"type": BOUNDS_BOX, "points": [
            {"x": r, "y": r, "z": entity.height_m}, {"x": -r, "y": -r, "z": 0.0}]}}

    def set_entity_state(self, args: Any, caller: Caller) -> dict[str, Any]:
        """SetEntityState: an entity put at rest at a pose (its twist must be zero)."""
        fields, flags = set_state_request(args)
        entity = self._entity(fields["entity"])
        if not may_change(caller, entity):
            raise _denied(f"setting the state of '{entity.name}'")
        state = fields["state"]
        if flags["set_twist"] and not _zero_twist(state["twist"]):
            raise ResultError(OPERATION_FAILED, "state.twist: websim sets an entity at rest (a "
                                            "zero twist); a robot's velocity comes from its "
                                            "/cmd_vel")
        if flags["set_pose"]:
            pose = planar_pose(state["pose"], state["header"]["frame_id"], "state.pose",
                               SET_INVALID_POSE)
        elif flags["set_twist"]:  # at rest where it is
            truth = self.control.state(entity.name)
            pose = Pose2D(truth.x, truth.y, truth.theta)
        else:
            return {"result": result(OK)}
        self._teleport(entity.name, pose, SET_INVALID_POSE)
        return {"result": result(OK)}

    def _teleport(self, name: str, pose: Pose2D, code: int) -> None:
        try:
            self.control.teleport(name, pose)
        except ConfigError as error:
            raise ResultError(code, f"'{name}' cannot be put at ({pose.x:g}, {pose.y:g}): "
                                    f"{error}") from None

    # -- spawning ----------------------------------------------------------------------------

    def _spawnables(self) -> list[dict[str, Any]]:
        return [{"uri": ROBOT_URI, "entity_resource": {"uri": ROBOT_URI, "resource_string": ""},
                 "description": ROBOT_DESCRIPTION,
                 "spawn_bounds": {"type": BOUNDS_EMPTY, "points": []}}]

    def get_spawnables(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetSpawnables: what SpawnEntity's uri may name (both generations' fields)."""
        fields = request(f"{PACKAGE}/srv/GetSpawnables", args)
        if not self.control.can_spawn:
            raise UnsupportedError("this world spawns nothing (a world of several robots does: "
                              "websim serve --class --arena)")
        note = f"sources not searched (websim spawns {ROBOT_URI} only): " \
            f"{', '.join(fields['sources'])}" if fields["sources"] else ""
        return {"result": result(OK, note), "spawnables": self._spawnables()}

    def spawn_one(self, fields: Mapping[str, Any], caller: Caller) -> str:
        """Spawn one entity of a 1.x-shaped request; its name (ResultError: why not)."""
        control = self.control
        if not control.can_spawn:
            raise UnsupportedError("this world spawns nothing (a world of several robots does: "
                              "websim serve --class --arena)")
        entities = control.entities()
        if not caller.admin:
            owned = sum(1 for entity in entities if entity.spawned and entity.owner
                        is not None and entity.owner == caller.name)
            if caller.name is None or owned >= caller.spawn_quota:
                raise ResultError(OPERATION_FAILED, "spawning: the instructor's, or a student's "
                                                f"up to --student-spawn ({caller.spawn_quota}"
                                                f"; {owned} spawned)")
        uri, resource = fields["uri"], fields["resource_string"]
        if not uri and not resource:
            raise ResultError(NO_RESOURCE, f"uri: empty (GetSpawnables lists {ROBOT_URI})")
        if not uri:
            raise UnsupportedError("resource_string: websim spawns by uri only "
                              "(SPAWNING_RESOURCE_STRING is not listed)")
        if uri != ROBOT_URI:
            raise ResultError(UNSUPPORTED_FORMAT, f"uri '{uri[:60]}': websim spawns "
                                              f"{ROBOT_URI}")
        names = {entity.name for entity in entities}
        name: str = fields["name"]
        if not name or name in names:
            if not fields["allow_renaming"]:
                raise ResultError(NAME_NOT_UNIQUE if name else NAME_INVALID,
                              f"name '{name}' is taken" if name else
                              "name: empty (give one, or allow_renaming)")
            base = name or "robot"
            name = next(f"{base}{index}" for index in range(1, len(names) + 2)
                        if f"{base}{index}" not in names)
        if not ENTITY_NAME.fullmatch(name):
            raise ResultError(NAME_INVALID, f"name '{name[:40]}': 1 to 32 of a-z, 0-9 and "
                                        "_, a letter first (it becomes a ROS namespace)")
        namespace = fields["entity_namespace"].strip("/")
        if namespace and namespace != name:
            raise ResultError(NAMESPACE_INVALID, f"entity_namespace: a websim robot's namespace is "
                                             f"its name ('/{name}')")
        initial = fields["initial_pose"]
        pose = planar_pose(initial["pose"], initial["header"]["frame_id"], "initial_pose",
                           INVALID_POSE)
        try:
            control.spawn(name, pose, None if caller.admin else caller.name)
        except ConfigError as error:
            raise ResultError(INVALID_POSE, str(error)) from None
        return name

    def spawn_entity(self, args: Any, caller: Caller) -> dict[str, Any]:
        """SpawnEntity: one robot, by uri, at a pose."""
        fields = spawn_request(args)
        return {"result": result(OK), "entity_name": self.spawn_one(fields, caller)}

    def spawn_entities(self, args: Any, caller: Caller) -> dict[str, Any]:
        """SpawnEntities: several, each with its own result."""
        fields = request(f"{PACKAGE}/srv/SpawnEntities", args)
        wanted = fields["spawn_requests"]
        if not self.control.can_spawn:
            raise UnsupportedError("this world spawns nothing (a world of several robots does: "
                              "websim serve --class --arena)")
        if len(wanted) > MAX_SPAWN_REQUESTS:
            raise ResultError(OPERATION_FAILED, f"spawn_requests: at most {MAX_SPAWN_REQUESTS} "
                                            "at once")
        results: list[dict[str, Any]] = []
        for one in wanted:
            flat = {key: value for key, value in one.items() if key != "entity_resource"}
            flat.update(one["entity_resource"])
            try:
                results.append({"result": result(OK),
                                "entity_name": self.spawn_one(flat, caller)})
            except ResultError as refusal:
                results.append({"result": result(refusal.code, str(refusal)),
                                "entity_name": ""})
            except UnsupportedError as error:
                results.append({"result": result(FEATURE_UNSUPPORTED, str(error)),
                                "entity_name": ""})
        failed = sum(entry["result"]["result"] != OK for entry in results)
        overall = result(ENTITIES_SPAWN_FAILED, f"{failed} of {len(results)} failed") \
            if failed else result(OK)
        return {"result": overall, "results": results}

    def delete_entity(self, args: Any, caller: Caller) -> dict[str, Any]:
        """DeleteEntity: a spawned entity removed."""
        fields = request(f"{PACKAGE}/srv/DeleteEntity", args)
        if not self.control.can_spawn:
            raise UnsupportedError("this world deletes nothing (a world of several robots does: "
                              "websim serve --class --arena)")
        entity = self._entity(fields["entity"])
        if not may_delete(caller, entity):
            raise _denied(f"deleting '{entity.name}'")
        self.control.delete(entity.name)
        return {"result": result(OK)}

    def get_named_poses(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetNamedPoses: the world's start pose (``start``, tag ``spawn``)."""
        fields = request(f"{PACKAGE}/srv/GetNamedPoses", args)
        start = self.control.start_pose()
        poses = [{"name": "start", "description": "where the world's robot starts",
                  "tags": ["spawn"],
                  "pose": {"position": {"x": start.x, "y": start.y, "z": 0.0},
                           "orientation": quaternion(start.theta)}}]
        return {"result": result(OK), "poses": [pose for pose in poses
                                                if _tags_match(tuple(pose["tags"]),
                                                               fields["tags"])]}

    # -- the simulation ----------------------------------------------------------------------

    def reset_simulation(self, args: Any, caller: Caller) -> dict[str, Any]:
        """ResetSimulation: the state (and the spawned entities) reset, by scope."""
        scope = request(f"{PACKAGE}/srv/ResetSimulation", args)["scope"]
        if scope in (SCOPE_DEFAULT, SCOPE_ALL):
            scope = SCOPE_STATE | (SCOPE_SPAWNED if self.control.can_spawn else 0)
        if scope & SCOPE_TIME:
            raise UnsupportedError(FEATURE_REASONS[SCOPE_TIME])
        if scope & ~(SCOPE_STATE | SCOPE_SPAWNED):
            raise ResultError(OPERATION_FAILED, f"scope {scope}: unknown bits (SCOPE_STATE 2, "
                                            "SCOPE_SPAWNED 4)")
        if scope & SCOPE_SPAWNED and not self.control.can_spawn:
            raise UnsupportedError("SCOPE_SPAWNED: this world spawns nothing")
        self.reset(scope, caller)
        return {"result": result(OK)}

    def reset(self, scope: int, caller: Caller) -> None:
        """Reset what ``scope`` says, if ``caller`` may change all of it (ResultError if not)."""
        entities = self.control.entities()
        for entity in entities:
            if entity.spawned and scope & SCOPE_SPAWNED:
                if not may_delete(caller, entity):
                    raise _denied(f"resetting removes '{entity.name}'")
            elif not may_change(caller, entity):
                raise _denied(f"resetting moves '{entity.name}'")
        self.control.reset(spawned=bool(scope & SCOPE_SPAWNED))

    def get_simulation_state(self, args: Any, caller: Caller) -> dict[str, Any]:
        """GetSimulationState: playing, paused or stopped."""
        request(f"{PACKAGE}/srv/GetSimulationState", args)
        return {"state": {"state": self.state()}, "result": result(OK)}

    def state(self) -> int:
        """The world's ``SimulationState``: playing, paused or stopped."""
        control = self.control
        if not control.paused:
            return STATE_PLAYING
        return STATE_STOPPED if control.stopped else STATE_PAUSED

    def _require_admin(self, caller: Caller, what: str) -> None:
        if not caller.admin:
            raise ResultError(OPERATION_FAILED, f"{what} the world needs admin rights (the "
                                            "instructor's token; in a world of one robot, "
                                            "its token)")

    def set_simulation_state(self, args: Any, caller: Caller) -> dict[str, Any]:
        """SetSimulationState: play, pause or stop (reset and hold) the world."""
        target = request(f"{PACKAGE}/srv/SetSimulationState", args)["state"]["state"]
        now = self.state()
        if target == STATE_QUITTING:
            raise UnsupportedError("STATE_QUITTING: websim is not quit by its clients (stop the "
                              "server)")
        if target not in (STATE_PLAYING, STATE_PAUSED, STATE_STOPPED):
            raise ResultError(INCORRECT_TRANSITION, f"state {target}: a client sets "
                                                "STATE_PLAYING (1), STATE_PAUSED (2) or "
                                                "STATE_STOPPED (0)")
        self._require_admin(caller, "playing, pausing or stopping")
        if target == now:
            raise ResultError(ALREADY_IN_TARGET_STATE, "already in that state")
        if target == STATE_PAUSED and now == STATE_STOPPED:
            raise ResultError(INCORRECT_TRANSITION, "pausing a stopped simulation: play it "
                                                "(or step it)")
        if target == STATE_STOPPED:
            self.reset(SCOPE_STATE | (SCOPE_SPAWNED if self.control.can_spawn else 0), caller)
            self.control.set_paused(True, stopped=True)
        else:
            self.control.set_paused(target == STATE_PAUSED)
        return {"result": result(OK)}

    def start_steps(self, args: Any, caller: Caller, progress: Callable[[int, int], None],
                    done: Callable[[dict[str, Any]], None]) -> Cancel:
        """Step the world ``steps`` ticks (StepSimulation, SimulateSteps).

        ``progress(completed, remaining)`` after each step; ``done(result)`` once, at the end
        (at once when refused).
        """
        try:
            steps = self._steps(args, caller)
        except ResultError as refusal:
            done(result(refusal.code, str(refusal)))
            return _nothing
        if steps == 0:
            done(result(OK))
            return _nothing

        def stepped(completed: int, failure: str | None) -> None:
            if failure is not None:
                done(result(OPERATION_FAILED, failure))
                return
            progress(completed, steps - completed)
            if completed >= steps:
                done(result(OK))

        try:
            return self.control.step(steps, stepped)
        except ConfigError as error:
            done(result(OPERATION_FAILED, str(error)))
            return _nothing

    def _steps(self, args: Any, caller: Caller) -> int:
        raw = args if isinstance(args, Mapping) else {}
        fields = request(f"{PACKAGE}/srv/StepSimulation", args)
        steps = int(fields["steps"]) if "steps" in raw else 1  # the definition's default
        self._require_admin(caller, "stepping")
        if steps > MAX_STEPS:
            raise ResultError(OPERATION_FAILED, f"steps: at most {MAX_STEPS} at once (an hour of "
                                            "simulated time)")
        if not self.control.paused:
            raise ResultError(OPERATION_FAILED, "the simulation is not paused "
                                            "(SetSimulationState STATE_PAUSED first)")
        return steps

    def step_simulation(self, args: Any, caller: Caller) -> Later:
        """StepSimulation: answered once the held world has run its steps."""
        def start(answer: Answer) -> None:
            def done(outcome: dict[str, Any]) -> None:
                answer(True, {"result": outcome})
                self.control.answered()
            self.start_steps(args, caller, lambda completed, remaining: None, done)
        return Later(start)

    # -- turtlesim ---------------------------------------------------------------------------

    def turtlesim_spawn(self, args: Any, caller: Caller) -> dict[str, Any]:
        """``/spawn`` (x, y, theta, name) -> name: SpawnEntity of the robot."""
        fields = request("turtlesim/srv/Spawn", args)
        pose = {"position": {"x": fields["x"], "y": fields["y"], "z": 0.0},
                "orientation": quaternion(fields["theta"])}
        spawn = {"name": fields["name"], "allow_renaming": not fields["name"], "uri": ROBOT_URI,
                 "resource_string": "", "entity_namespace": "",
                 "initial_pose": {"header": {"frame_id": ""}, "pose": pose}}
        return {"name": _or_fail("/spawn", lambda: self.spawn_one(spawn, caller))}

    def turtlesim_kill(self, args: Any, caller: Caller) -> dict[str, Any]:
        """``/kill`` (name): DeleteEntity."""
        fields = request("turtlesim/srv/Kill", args)
        _check(self.call("DeleteEntity", {"entity": fields["name"]}, caller), "/kill")
        return {}

    def turtlesim_reset(self, args: Any, caller: Caller) -> dict[str, Any]:
        """``/reset``: everything back to its start, the spawned entities removed."""
        request("std_srvs/srv/Empty", args)
        scope = SCOPE_STATE | (SCOPE_SPAWNED if self.control.can_spawn else 0)
        _or_fail("/reset", lambda: self.reset(scope, caller))
        return {}

    def teleport(self, name: str, absolute: bool, args: Any, caller: Caller) -> dict[str, Any]:
        """``/NAME/teleport_absolute`` (x, y, theta) or ``teleport_relative``.

        ``teleport_relative`` (linear, angular) turns, then moves along the new heading, as
        turtlesim does.
        """
        service = f"/{name}/{TELEPORT_ABSOLUTE if absolute else TELEPORT_RELATIVE}"
        fields = request(TELEPORT_TYPES[absolute], args)

        def move() -> None:
            entity = self._entity(name)
            if not may_change(caller, entity):
                raise _denied(f"teleporting '{name}'")
            if absolute:
                pose = Pose2D(fields["x"], fields["y"], fields["theta"])
            else:
                truth = self.control.state(name)
                theta = truth.theta + fields["angular"]
                pose = Pose2D(truth.x + fields["linear"] * math.cos(theta),
                              truth.y + fields["linear"] * math.sin(theta), theta)
            self._teleport(name, pose, SET_INVALID_POSE)
        _or_fail(service, move)
        return {}


TYPE_HANDLERS = {type_name: re.sub(r"(?<!^)([A-Z])", r"_\1", type_name).lower()
                 for type_name in SERVICES.values()}
"""The method of ``SimulationServices`` answering each service type (``GetEntities``:
``get_entities``)."""

ENTITY_NAME = re.compile(r"[a-z_][a-z0-9_]{0,31}")
"""What a spawned entity's name may be: a robot name that is also a ROS namespace."""


def _nothing() -> None:
    """Cancels nothing: the request was answered already."""


def _or_fail(service: str, action: Callable[[], Any]) -> Any:
    """``action()``, a refusal failing the call (turtlesim's services have no result)."""
    try:
        return action()
    except (ResultError, UnsupportedError) as refusal:
        raise ServiceError(f"{service}: {refusal}") from None


def _check(response: Mapping[str, Any] | Later, service: str) -> None:
    assert not isinstance(response, Later)  # only StepSimulation answers later
    outcome = response["result"]
    if outcome["result"] != OK:
        raise ServiceError(f"{service}: {outcome['error_message']}")


# ---- over rosbridge -----------------------------------------------------------------------------

def add_simulation_services(bridge: Bridge, control: SimulatorControl) -> SimulationServices:
    """Offer the standard's services, its SimulateSteps action and turtlesim's names."""
    services = SimulationServices(control)

    def serve(type_name: str) -> Callable[[Mapping[str, Any], Session], Any]:
        def handle(args: Mapping[str, Any], session: Session) -> Mapping[str, Any] | Later:
            return services.call(type_name, args, control.caller(session))
        return handle

    for name, type_name in SERVICES.items():
        bridge.services.add(name, f"{PACKAGE}/srv/{type_name}", serve(type_name))
    turtlesim = {"/spawn": services.turtlesim_spawn, "/kill": services.turtlesim_kill,
                 "/reset": services.turtlesim_reset}
    for name, handler in turtlesim.items():
        bridge.services.add(name, TURTLESIM_SERVICES[name], _with_caller(control, handler))
    for entity in control.entities():
        add_teleports(bridge, services, entity.name)

    def goal(args: Any, sender: GoalSender, session: Session) -> Cancel:
        def progress(completed: int, remaining: int) -> None:
            sender.goal_feedback({"completed_steps": completed, "remaining_steps": remaining})
            control.answered()

        def done(outcome: dict[str, Any]) -> None:
            status = GoalStatus.SUCCEEDED if outcome["result"] == OK else GoalStatus.ABORTED
            sender.goal_result({"result": outcome}, status, True)
            control.answered()

        cancel = services.start_steps(args, control.caller(session), progress, done)

        def cancelled() -> None:
            cancel()
            sender.goal_result({"result": result(OPERATION_FAILED, "cancelled")},
                               GoalStatus.CANCELED, True)
        return cancelled

    bridge.actions.add(ACTION, ACTION_TYPE, goal)
    return services


def add_teleports(bridge: Bridge, services: SimulationServices, name: str) -> None:
    """Turtlesim's ``/NAME/teleport_absolute`` and ``/NAME/teleport_relative`` of an entity."""
    for absolute, service in ((True, TELEPORT_ABSOLUTE), (False, TELEPORT_RELATIVE)):
        bridge.services.add(f"/{name}/{service}", TELEPORT_TYPES[absolute],
                            _with_caller(services.control, functools.partial(
                                services.teleport, name, absolute)))


def _with_caller(control: SimulatorControl, handler: Callable[[Any, Caller], Any]
                 ) -> Callable[[Mapping[str, Any], Session], Any]:
    """A bridge's service handler: ``handler`` with the rights of the calling session."""
    def handle(args: Mapping[str, Any], session: Session) -> Any:
        return handler(args, control.caller(session))
    return handle
