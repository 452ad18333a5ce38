#!/usr/bin/env bash
# Generate and install simulation_interfaces and turtlesim's services for the PyPI ROS 2 wheels.
#
# `websim serve --ros` offers ROS 2's simulation_interfaces services (/spawn_entity,
# /get_entities, ..., the /simulate_steps action) and turtlesim's names (/spawn, /kill,
# /NAME/teleport_absolute, ...) on the ROS graph; neither package is on PyPI. This builds both
# with scripts/build_ros_interface.sh (the wheels' own rosidl) from the definitions websim
# ships (rosbridge/msgs/interfaces/: simulation_interfaces as Humble 1.4 to Kilted 1.6 define
# it, turtlesim's four services), so their type hashes match a ROS install's (for
# simulation_interfaces, tests/test_simulation_interfaces_hashes.py holds them to upstream's
# 1.6.1, built with the same rosidl: tests/type_hashes/). Needs cmake and
# a C/C++ compiler (Debian: apt-get install cmake g++); about a minute. Does nothing for a
# package that already imports (a ROS 2 installation, or an earlier run).
#
# Usage: bash scripts/build_simulation_interfaces.sh        (PYTHON=... to pick the interpreter)
set -euo pipefail
python=${PYTHON:-python3}
here=$(dirname "$0")
interfaces="$here/../rosbridge/msgs/interfaces"

if "$python" -c 'from simulation_interfaces.srv import SpawnEntity' 2>/dev/null; then
    echo "simulation_interfaces is already installed"
else
    bash "$here/build_ros_interface.sh" simulation_interfaces \
        "builtin_interfaces geometry_msgs std_msgs action_msgs" \
        --dir "$interfaces/simulation_interfaces"
    "$python" -c 'from simulation_interfaces.action import SimulateSteps; SimulateSteps.Goal()'
fi
if "$python" -c 'from turtlesim.srv import TeleportAbsolute' 2>/dev/null; then
    echo "turtlesim is already installed"
else
    bash "$here/build_ros_interface.sh" turtlesim builtin_interfaces --dir "$interfaces/turtlesim"
    "$python" -c 'from turtlesim.srv import Spawn; Spawn.Request(name="t")'
fi
