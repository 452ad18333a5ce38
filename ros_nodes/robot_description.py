"""What the web page needs to know of the robot, in one JSON document (``robot.json``).

The page must not restate the robot: its speed limits, footprint, topic names and types,
services and parameter table all come from here, served by the server that served the page
(``websim serve`` fills it from the running robot; the Docker stack's nginx serves the
committed ``web-interface/robot.json``, which ``websim robot-json`` writes and a test holds
equal to the shipped parameters).
"""

from __future__ import annotations

import json
from typing import Any

from physics import LidarParams, RobotParams
from ros_nodes.parameters import (
    PARAMETER_BOOL,
    PARAMETER_DOUBLE,
    PARAMETER_INTEGER,
    PARAMETER_NOT_SET,
    PARAMETER_STRING,
    PARAMETERS,
)
from ros_nodes.robot_interface import NODE_NAME, PARAMETER_SERVICES, RESET_SERVICE, ROBOT_TOPICS

ROBOT_FIELDS = ("max_linear_mps", "max_angular_rps", "footprint_radius_m", "wheelbase_m",
                "wheel_radius_m", "mass_kg", "inertia_kg_m2", "max_wheel_force_n")
"""The ``RobotParams`` fields the page uses (limits, drawing, the admin page's defaults)."""

LIDAR_FIELDS = ("num_rays", "range_min_m", "range_max_m")


def robot_description(robot: RobotParams | None = None,
                      lidar: LidarParams | None = None) -> dict[str, Any]:
    """The ``robot.json`` document for a robot (default: the shipped Pi 4B robot).

    Keys: ``robot`` and ``lidar`` (SI values), ``topics`` (by role: ``{name, type,
    direction, rate_hz}``), ``services`` (by role), ``node``, ``parameter_types``
    (``rcl_interfaces/msg/ParameterType`` codes) and ``parameters`` (the parameter table:
    name, type code, unit, default, range, choices, whether it changes at runtime).
    """
    robot = RobotParams() if robot is None else robot
    lidar = LidarParams() if lidar is None else lidar
    return {
        "robot": {name: getattr(robot, name) for name in ROBOT_FIELDS},
        "lidar": {name: getattr(lidar, name) for name in LIDAR_FIELDS},
        "topics": {spec.name.strip("/"): {"name": spec.name, "type": spec.type,
                                          "direction": spec.direction,
                                          "rate_hz": spec.rate_hz}
                   for spec in ROBOT_TOPICS},
        "node": NODE_NAME,
        "services": {"reset": {"name": RESET_SERVICE, "type": "std_srvs/srv/Empty"},
                     **{role: {"name": f"{NODE_NAME}/{role}", "type": type_name}
                        for role, type_name in PARAMETER_SERVICES.items()}},
        "parameter_types": {"NOT_SET": PARAMETER_NOT_SET, "BOOL": PARAMETER_BOOL,
                            "INTEGER": PARAMETER_INTEGER, "DOUBLE": PARAMETER_DOUBLE,
                            "STRING": PARAMETER_STRING},
        "parameters": [{"name": spec.name, "type": spec.type_code, "unit": spec.unit,
                        "description": spec.description, "default": spec.default,
                        "minimum": spec.minimum, "maximum": spec.maximum,
                        "choices": list(spec.choices), "runtime": spec.runtime}
                       for spec in PARAMETERS if spec.embedded],
    }


def robot_json(robot: RobotParams | None = None, lidar: LidarParams | None = None) -> str:
    """``robot_description`` as the text of ``web-interface/robot.json`` (sorted, indented)."""
    return json.dumps(robot_description(robot, lidar), indent=2, sort_keys=True) + "\n"
