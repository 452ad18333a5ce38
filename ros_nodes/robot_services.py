"""The services the embedded bridge offers, in the request and response shapes of ROS 2.

* ``/virtual_robot/{get,set,list,describe}_parameters`` and ``get_parameter_types``
  (``rcl_interfaces/srv``), so the admin page and ``ros2 param`` speak one language;
* ``/reset_simulation`` (``std_srvs/srv/Empty``), as gazebo_ros offers it;
* rosapi's services (``rosapi``), parameter names in ROS 2's ``/node:param`` form and values
  as JSON strings;
* the node's ``/rosout`` and ``/parameter_events`` (``rosout.RobotLog``).

Changing parameters needs admin rights (the token in the WebSocket URL); reading does not.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from physics import ConfigError
from physics.validation import shown
from ros_nodes.parameters import (
    PARAMETER_DOUBLE,
    PARAMETER_INTEGER,
    PARAMETER_NOT_SET,
    RobotParameters,
    parameter_value_msg,
    shorten_value,
    value_from_parameter_value,
)
from ros_nodes.robot_interface import NODE_NAME, PARAMETER_SERVICES, RESET_SERVICE
from ros_nodes.rosapi import add_rosapi, require_admin
from ros_nodes.rosout import RobotLog
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Bridge
from rosbridge.core.errors import ServiceError
from rosbridge.core.session import Session

__all__ = ["add_robot_services", "require_admin"]


def _names(args: Mapping[str, Any], field: str = "names") -> list[str]:
    names = args.get(field, [])
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ServiceError(f"{field}: expected a list of parameter names, got "
                           f"{shorten_value(names)}")
    return names


def add_robot_services(bridge: Bridge, robot: VirtualRobot) -> RobotLog:
    """Register every embedded service on ``bridge`` for ``robot``; its node's log."""
    params = robot.parameters
    log = RobotLog(bridge, robot)
    prefix = NODE_NAME

    def get_parameters(args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        values = []
        for name in _names(args):
            value = params.get(name) if name in params.names() else None
            values.append(parameter_value_msg(value))
        return {"values": values}

    def set_parameters(args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        require_admin(session, "set_parameters")
        entries = args.get("parameters", [])
        if not isinstance(entries, list):
            raise ServiceError(f"parameters: expected a list, got {shown(entries)}")
        results = []
        for index, entry in enumerate(entries):
            try:
                if not isinstance(entry, Mapping) or not isinstance(entry.get("name"), str):
                    raise ConfigError(f"parameters[{index}]: expected {{name, value}}")
                params.set(entry["name"], value_from_parameter_value(entry.get("value")))
                results.append({"successful": True, "reason": ""})
            except ConfigError as error:
                results.append({"successful": False, "reason": str(error)})
        return {"results": results}

    def list_parameters(args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        prefixes = _names(args, "prefixes")
        names = [n for n in params.names()
                 if not prefixes or any(n.startswith(p) for p in prefixes)]
        return {"result": {"names": names, "prefixes": []}}

    def describe_parameters(args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        descriptors = []
        for name in _names(args):
            known = name in params.names()
            spec = RobotParameters.spec(name) if known else None
            bounds = [] if spec is None or spec.minimum is None else [
                {"from_value": spec.minimum, "to_value": spec.maximum, "step": 0}]
            description = "" if spec is None else \
                f"{spec.description}{f' ({spec.unit})' if spec.unit else ''}"
            descriptors.append({
                "name": name, "type": spec.type_code if spec else PARAMETER_NOT_SET,
                "description": description,
                "additional_constraints": f"one of {spec.range_text()}"
                if spec is not None and spec.choices else "",
                "read_only": spec is not None and not spec.runtime, "dynamic_typing": False,
                "floating_point_range": bounds
                if spec is not None and spec.type_code == PARAMETER_DOUBLE else [],
                "integer_range": bounds
                if spec is not None and spec.type_code == PARAMETER_INTEGER else []})
        return {"descriptors": descriptors}

    def get_parameter_types(args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        return {"types": [RobotParameters.spec(n).type_code if n in params.names()
                          else PARAMETER_NOT_SET for n in _names(args)]}

    def reset(args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        robot.reset()
        log.info(f"{RESET_SERVICE}: back to the spawn pose, odometry zeroed")
        return {}

    handlers = {"get_parameters": get_parameters, "set_parameters": set_parameters,
                "list_parameters": list_parameters, "describe_parameters": describe_parameters,
                "get_parameter_types": get_parameter_types}
    for name, type_name in PARAMETER_SERVICES.items():
        bridge.services.add(f"{prefix}/{name}", type_name, handlers[name])
    bridge.services.add(RESET_SERVICE, "std_srvs/srv/Empty", reset)
    add_rosapi(bridge, robot)
    return log
