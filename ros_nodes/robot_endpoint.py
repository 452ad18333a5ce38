"""The robot attached to its bridge like a client of the hub: one path in, one path out.

The robot subscribes /cmd_vel (``Topics.subscribe_local``: it gets what clients publish, in
canonical form, as any subscriber would) as both ``geometry_msgs/Twist`` and
``TwistStamped`` (what Jazzy-era nav2 publishes): each client's commands are of the type
it advertised, and the latest command of either drives the robot. It publishes its topics
(``Topics.publish``), which it owns: clients may not publish them. Its services (parameters,
reset, rosapi) are added to the bridge's service capability.
"""

from __future__ import annotations

from typing import Any

from physics import ConfigError
from ros_nodes.robot_interface import CMD_VEL, CMD_VEL_STAMPED_TYPE, PUBLISHED_TOPICS
from ros_nodes.robot_services import add_robot_services
from ros_nodes.virtual_robot_core import Publication, VirtualRobot
from rosbridge.core.bridge import Bridge
from rosbridge.core.session import Session


class RobotEndpoint:
    """One robot's connection to its bridge.

    Args:
        bridge: the bridge of this robot.
        robot: the robot.

    Attributes:
        last_driver: the address of the client whose /cmd_vel the robot took last (None: none
            yet).
        last_drive_s: when it did (the robot's ``clock.monotonic_s``), None before.
        log: the robot node's /rosout and /parameter_events.
    """

    def __init__(self, bridge: Bridge, robot: VirtualRobot) -> None:
        self.bridge = bridge
        self.robot = robot
        self.last_driver: str | None = None
        self.last_drive_s: float | None = None
        for spec in PUBLISHED_TOPICS:
            bridge.topics.own(spec.name, spec.type)
        bridge.topics.subscribe_local(CMD_VEL.name, CMD_VEL.type, self._on_cmd_vel)
        bridge.topics.subscribe_local(CMD_VEL.name, CMD_VEL_STAMPED_TYPE,
                                      self._on_cmd_vel_stamped)
        self.log = add_robot_services(bridge, robot)
        for spec, msg in robot.latched():
            bridge.publish(spec.name, msg, latch=True)
        robot.latched_listeners.append(self._republish)

    def _republish(self, publication: Publication) -> None:
        """A latched message changed (the URDF): latch the new one for every subscriber."""
        spec, msg = publication
        self.bridge.publish(spec.name, msg, latch=True)

    def _on_cmd_vel(self, msg: Any, publisher: Session) -> None:
        self._drive(msg, publisher, stamped=False)

    def _on_cmd_vel_stamped(self, msg: Any, publisher: Session) -> None:
        self._drive(msg, publisher, stamped=True)

    def _drive(self, msg: Any, publisher: Session, stamped: bool) -> None:
        try:
            self.robot.on_cmd_vel(msg, stamped=stamped)
        except ConfigError as error:  # the reason also goes back to the publisher
            self.log.warning(f"/cmd_vel refused: {error}")
            raise
        self.last_driver = publisher.peer
        self.last_drive_s = self.robot.clock.monotonic_s()
