"""The robot model: a URDF generated from the robot's parameters (``/robot_description``).

What rviz2, Foxglove, Lichtblick and ros3djs draw: ``base_link`` (the chassis, its collision
cylinder the footprint circle the simulation collides with, its mass and yaw inertia), two
continuous wheel joints at +-wheelbase/2 (radius ``wheel_radius_m``, axle +y, so a positive
angle rolls forward; limits from the speed and traction limits) and the laser fixed at its
mount (``LidarParams.mount_*``: the same origin as ``/tf_static``'s base_link -> laser).

Frames follow the planar model (and the real robot: course text 2.5.3.2): base_link lies on
the ground plane between the wheels (odom -> base_link has z = 0), and the laser frame too,
since the scan is the plane z = 0 (where ``/world`` draws the walls). There is no
``base_footprint``: base_link already is on the ground, and the real robot's frames are
odom, base_link and laser only. Heights that the planar model does not have (the chassis',
the laser's) are drawing sizes, named below.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from physics import LidarParams, RobotParams
from ros_nodes.robot_messages import BASE_FRAME, LASER_FRAME

ROBOT_NAME = "virtual_robot"
"""The ``<robot name>``: the robot node's name."""

LEFT_WHEEL_LINK = "left_wheel"
RIGHT_WHEEL_LINK = "right_wheel"
LEFT_WHEEL_JOINT = "left_wheel_joint"
RIGHT_WHEEL_JOINT = "right_wheel_joint"
LASER_JOINT = "laser_joint"

WHEEL_JOINTS = (LEFT_WHEEL_JOINT, RIGHT_WHEEL_JOINT)
"""The joints ``/joint_states`` reports, in its order (left, right)."""

WHEEL_LINKS = (LEFT_WHEEL_LINK, RIGHT_WHEEL_LINK)
"""The wheels' links (TF frames), in the order of ``WHEEL_JOINTS``."""

WHEEL_AXIS = (0.0, 1.0, 0.0)
"""The wheel joints' axis in their frame: the axle, +y of base_link."""

CHASSIS_HEIGHT_M = 0.05
"""Drawing only: the chassis cylinder's height, from the axles up (the planar model has none)."""

WHEEL_WIDTH_M = 0.025
"""Drawing only: the wheels' width (m)."""

LASER_RADIUS_M = 0.035
"""Drawing only: the LiDAR puck's radius (RPLIDAR A1-like, m)."""

LASER_HEIGHT_M = 0.03
"""Drawing only: the LiDAR puck's height (m); drawn on the chassis, its frame on the scan
plane (z = 0)."""

CHASSIS_RGBA = (0.25, 0.45, 0.85, 1.0)
WHEEL_RGBA = (0.1, 0.1, 0.1, 1.0)
LASER_RGBA = (0.9, 0.3, 0.2, 1.0)


def wheel_origin_m(robot: RobotParams, joint: str) -> tuple[float, float, float]:
    """Where a wheel joint is in base_link (m): on the axle, at +-wheelbase/2, axle height.

    The one definition of the wheels' place, used by the URDF and by the wheels' transforms
    on ``/tf`` (``ros_nodes.sensors``).

    Raises:
        KeyError: ``joint`` is not one of ``WHEEL_JOINTS``.
    """
    side = {LEFT_WHEEL_JOINT: 1.0, RIGHT_WHEEL_JOINT: -1.0}[joint]
    return 0.0, side * robot.half_wheelbase_m, robot.wheel_radius_m


def robot_urdf(robot: RobotParams, lidar: LidarParams) -> str:
    """The URDF of a robot with these parameters (text, ``<?xml ...?>`` first).

    Every number comes from the parameters except the drawing sizes above. The inertial's
    roll and pitch moments, which the planar model never uses, are those of a thin disc of
    the same yaw inertia (izz / 2), so that URDF parsers that require all six accept it.
    """
    root = ET.Element("robot", name=ROBOT_NAME)
    for name, rgba in (("chassis", CHASSIS_RGBA), ("wheel", WHEEL_RGBA),
                       ("laser", LASER_RGBA)):
        ET.SubElement(ET.SubElement(root, "material", name=name), "color", rgba=_numbers(rgba))

    chassis_z = robot.wheel_radius_m + CHASSIS_HEIGHT_M / 2.0
    base = ET.SubElement(root, "link", name=BASE_FRAME)
    _shape(base, "visual", (0.0, 0.0, chassis_z), (0.0, 0.0, 0.0),
           robot.footprint_radius_m, CHASSIS_HEIGHT_M, "chassis")
    _shape(base, "collision", (0.0, 0.0, chassis_z), (0.0, 0.0, 0.0),
           robot.footprint_radius_m, CHASSIS_HEIGHT_M)
    inertial = ET.SubElement(base, "inertial")
    _origin(inertial, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    ET.SubElement(inertial, "mass", value=_number(robot.mass_kg))
    izz = robot.inertia_kg_m2
    ET.SubElement(inertial, "inertia", ixx=_number(izz / 2.0), ixy="0.0", ixz="0.0",
                  iyy=_number(izz / 2.0), iyz="0.0", izz=_number(izz))

    upright_to_axle = (-1.5707963267948966, 0.0, 0.0)  # the cylinder's z onto the axle, y
    for joint, link in zip(WHEEL_JOINTS, WHEEL_LINKS, strict=True):
        wheel = ET.SubElement(root, "link", name=link)
        _shape(wheel, "visual", (0.0, 0.0, 0.0), upright_to_axle, robot.wheel_radius_m,
               WHEEL_WIDTH_M, "wheel")
        _shape(wheel, "collision", (0.0, 0.0, 0.0), upright_to_axle, robot.wheel_radius_m,
               WHEEL_WIDTH_M)
        element = ET.SubElement(root, "joint", name=joint, type="continuous")
        ET.SubElement(element, "parent", link=BASE_FRAME)
        ET.SubElement(element, "child", link=link)
        _origin(element, wheel_origin_m(robot, joint), (0.0, 0.0, 0.0))
        ET.SubElement(element, "axis", xyz=_numbers(WHEEL_AXIS))
        ET.SubElement(element, "limit",
                      effort=_number(robot.max_wheel_force_n * robot.wheel_radius_m),
                      velocity=_number(robot.max_wheel_speed_rad_s))

    laser = ET.SubElement(root, "link", name=LASER_FRAME)
    puck_z = robot.wheel_radius_m + CHASSIS_HEIGHT_M + LASER_HEIGHT_M / 2.0
    _shape(laser, "visual", (0.0, 0.0, puck_z), (0.0, 0.0, 0.0), LASER_RADIUS_M,
           LASER_HEIGHT_M, "laser")
    element = ET.SubElement(root, "joint", name=LASER_JOINT, type="fixed")
    ET.SubElement(element, "parent", link=BASE_FRAME)
    ET.SubElement(element, "child", link=LASER_FRAME)
    _origin(element, (lidar.mount_x_m, lidar.mount_y_m, 0.0), (0.0, 0.0, lidar.mount_yaw_rad))

    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _shape(link: ET.Element, kind: str, xyz: tuple[float, float, float],
           rpy: tuple[float, float, float], radius_m: float, length_m: float,
           material: str | None = None) -> None:
    """A ``<visual>`` or ``<collision>`` cylinder of ``link``."""
    element = ET.SubElement(link, kind)
    _origin(element, xyz, rpy)
    geometry = ET.SubElement(element, "geometry")
    ET.SubElement(geometry, "cylinder", radius=_number(radius_m), length=_number(length_m))
    if material is not None:
        ET.SubElement(element, "material", name=material)


def _origin(parent: ET.Element, xyz: tuple[float, float, float],
            rpy: tuple[float, float, float]) -> None:
    ET.SubElement(parent, "origin", xyz=_numbers(xyz), rpy=_numbers(rpy))


def _number(value: float) -> str:
    """A float as the shortest text that reads back to it exactly."""
    return repr(float(value))


def _numbers(values: tuple[float, ...]) -> str:
    return " ".join(_number(value) for value in values)
