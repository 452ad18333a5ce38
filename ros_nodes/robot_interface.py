"""The robot's ROS interface: topic names, types, rates and frames, kept in one place.

These match the real robot (course text 2.5.3 and 2.5.6): sim-to-real parity is the point.
"""

from __future__ import annotations

from dataclasses import dataclass

from physics import TICK_PERIOD_S


@dataclass(frozen=True)
class QosProfile:
    """The QoS a topic's publisher offers (the values rclpy's profiles have).

    Attributes:
        reliability: ``"reliable"`` or ``"best_effort"``.
        durability: ``"volatile"`` or ``"transient_local"`` (late subscribers get the last
            ``depth`` messages).
        depth: the history kept (keep last N).
    """

    reliability: str
    durability: str
    depth: int


QOS_PROFILES = {
    "reliable": QosProfile("reliable", "volatile", 10),
    "sensor_data": QosProfile("best_effort", "volatile", 5),
    "transient_local": QosProfile("reliable", "transient_local", 1),
}
"""``TopicSpec.qos`` -> what its publisher offers: ``reliable`` is ROS 2's default profile,
``sensor_data`` rclpy's ``qos_profile_sensor_data`` (as lidar drivers publish), and
``transient_local`` what tf2's static broadcaster offers. The rclpy node publishes with these
and a recording (``ros_nodes.recording``) writes them as the topic's ``offered_qos_profiles``."""


@dataclass(frozen=True)
class TopicSpec:
    """One topic of the virtual robot.

    Attributes:
        name: the topic name.
        type: the ROS 2 type, ``pkg/msg/Type``.
        direction: ``"in"`` (the robot subscribes) or ``"out"`` (the robot publishes).
        every_ticks: published every this many 50 ms ticks; 0 for latched topics, which are
            sent once to every new subscriber (transient local), and for event topics.
        qos: ``"reliable"``, ``"sensor_data"`` (best effort, like lidar drivers) or
            ``"transient_local"``.
        description: what it carries.
        event: published when something happens (a log line, a parameter change), not per
            tick and not latched.
        recorded: ``websim serve --record`` writes it to the robot's rosbag2 (what the robot
            publishes and what it accepts, as they cross its tap, ``ros_nodes.tap``).
    """

    name: str
    type: str
    direction: str
    every_ticks: int
    qos: str
    description: str
    event: bool = False
    recorded: bool = True

    @property
    def rate_hz(self) -> float:
        """Publishing rate (Hz); 0 for latched, event and input topics."""
        return 1.0 / (self.every_ticks * TICK_PERIOD_S) if self.every_ticks else 0.0

    @property
    def latched(self) -> bool:
        """True for topics sent once to every subscriber."""
        return self.direction == "out" and self.every_ticks == 0 and not self.event

    @property
    def qos_profile(self) -> QosProfile:
        """What its publisher offers (``QOS_PROFILES``)."""
        return QOS_PROFILES[self.qos]


CMD_VEL = TopicSpec("/cmd_vel", "geometry_msgs/msg/Twist", "in", 0, "reliable",
                    "velocity command: linear.x (m/s), angular.z (rad/s); the robot keeps the last")
CMD_VEL_STAMPED_TYPE = "geometry_msgs/msg/TwistStamped"
"""/cmd_vel's other type: the embedded bridge takes both, each client's messages of the type
it advertised; the rclpy node subscribes one of the two (its ``cmd_vel_stamped``)."""
ODOM = TopicSpec("/odom", "nav_msgs/msg/Odometry", "out", 1, "reliable",
                 "wheel odometry, frame odom, child base_link")
SCAN = TopicSpec("/scan", "sensor_msgs/msg/LaserScan", "out", 2, "sensor_data",
                 "360-beam LiDAR, frame laser")
TF = TopicSpec("/tf", "tf2_msgs/msg/TFMessage", "out", 1, "reliable",
               "odom -> base_link, then base_link -> left_wheel and right_wheel; also "
               "map -> odom with localization: perfect")
TF_STATIC = TopicSpec("/tf_static", "tf2_msgs/msg/TFMessage", "out", 0, "transient_local",
                      "base_link -> laser")
GROUND_TRUTH = TopicSpec("/ground_truth", "nav_msgs/msg/Odometry", "out", 1, "reliable",
                         "true pose, frame map (simulation only)")
WORLD = TopicSpec("/world", "visualization_msgs/msg/MarkerArray", "out", 0, "transient_local",
                  "the walls, frame map (simulation only)")
MAP = TopicSpec("/map", "nav_msgs/msg/OccupancyGrid", "out", 0, "transient_local",
                "the world's occupancy grid, frame map (as nav2's map_server publishes it)")
WORLD_ROBOTS = TopicSpec("/world_robots", "visualization_msgs/msg/MarkerArray", "out", 1,
                         "reliable", "every robot of the world (this one too) at this tick: "
                         "its footprint, a cylinder whose text is its name, frame map "
                         "(simulation only; an arena's other robots)", recorded=False)

JOINT_STATES = TopicSpec("/joint_states", "sensor_msgs/msg/JointState", "out",
                         ODOM.every_ticks, "reliable",
                         "the wheel joints: angle (rad) and speed (rad/s) from the encoders")
ROBOT_DESCRIPTION = TopicSpec("/robot_description", "std_msgs/msg/String", "out", 0,
                              "transient_local",
                              "the URDF, from the robot's parameters (again when they change)")

CLOCK = TopicSpec("/clock", "rosgraph_msgs/msg/Clock", "out", 1, "reliable",
                  "the time of the tick, what its messages are stamped with: wall time, or sim "
                  "time with --speed")

ROBOT_TOPICS = (CMD_VEL, ODOM, SCAN, TF, TF_STATIC, GROUND_TRUTH, WORLD, MAP, WORLD_ROBOTS,
                JOINT_STATES, ROBOT_DESCRIPTION, CLOCK)
"""Every topic of the virtual robot, in the README's order."""

PUBLISHED_TOPICS = tuple(spec for spec in ROBOT_TOPICS if spec.direction == "out")
"""Topics only the simulator may publish."""

RECORDED_TOPICS = tuple(spec for spec in ROBOT_TOPICS if spec.recorded)
"""What ``--record`` writes: every topic of the robot (a new one is recorded once it is in
``ROBOT_TOPICS`` and crosses the robot's tap), unless its spec says ``recorded=False``."""

ROBOTS_PREFIX = "/robots/"
"""Where a class's robots are: robot NAME at ``ws://HOST:9090/robots/NAME``, its page at
``http://HOST:8080/robots/NAME/`` (a single robot's server refuses these paths)."""

NODE_BASENAME = "virtual_robot"
"""The robot node's name, as on the real robot and in the Docker stack (what rclpy is given)."""

NODE_NAME = f"/{NODE_BASENAME}"
"""The robot node's fully qualified name (the root namespace)."""

RESERVED_NAMESPACES = (f"{NODE_NAME}/", "/rosapi/", "/websim/")
"""The namespaces of the simulator's own services (the robot node's, rosapi's, websim's):
clients may not offer services or actions in them."""

ROSOUT = TopicSpec("/rosout", "rcl_interfaces/msg/Log", "out", 0, "transient_local",
                   "the node's log lines (start, reset, parameter changes, refused commands)",
                   event=True)
PARAMETER_EVENTS = TopicSpec("/parameter_events", "rcl_interfaces/msg/ParameterEvent", "out", 0,
                             "reliable", "every parameter declared or changed, with its node",
                             event=True)
NODE_TOPICS = (ROSOUT, PARAMETER_EVENTS)
"""What every ROS 2 node publishes besides its own topics: rclpy does it for the virtual_robot
node on a graph; the embedded bridge publishes them for the simulator
(``ros_nodes.rosout``)."""

RESET_SERVICE = "/reset_simulation"
"""``std_srvs/srv/Empty``: back to spawn with odometry zeroed (as gazebo_ros offers it)."""

PARAMETER_SERVICES = {
    "get_parameters": "rcl_interfaces/srv/GetParameters",
    "set_parameters": "rcl_interfaces/srv/SetParameters",
    "list_parameters": "rcl_interfaces/srv/ListParameters",
    "describe_parameters": "rcl_interfaces/srv/DescribeParameters",
    "get_parameter_types": "rcl_interfaces/srv/GetParameterTypes",
}
"""The node's parameter services (``/virtual_robot/NAME``) and their types, as rclpy offers."""
