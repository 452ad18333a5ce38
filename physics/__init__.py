"""websim's simulation core: worlds of differential-drive robots and their LiDARs, on pymunk.

Pure computation: no ROS, network, threads or plotting. Units are SI (m, s, rad, kg, N).

``compare_modes`` is ``physics.compare.compare`` (kinematic vs dynamic on one command list);
it is not exported as ``compare``, which would hide the ``physics.compare`` module.
"""

from physics.compare import compare as compare_modes
from physics.compare import load_commands
from physics.lidar import Lidar
from physics.params import LidarParams, NoiseParams, PlatformParams, RobotParams, load_params
from physics.robot import MODES, MobileRobotPhysics
from physics.simulation import TICK_PERIOD_S, Simulation
from physics.snapshots import Command, LaserScan, Odometry, Pose2D, RobotState, WheelState
from physics.validation import ConfigError
from physics.world import World, load_world
from physics.world_sim import WorldSim

__all__ = [
    "MODES",
    "TICK_PERIOD_S",
    "Command",
    "ConfigError",
    "LaserScan",
    "Lidar",
    "LidarParams",
    "MobileRobotPhysics",
    "NoiseParams",
    "Odometry",
    "PlatformParams",
    "Pose2D",
    "RobotParams",
    "RobotState",
    "Simulation",
    "WheelState",
    "World",
    "WorldSim",
    "compare_modes",
    "load_commands",
    "load_params",
    "load_world",
]
