#!/usr/bin/env bash
# Generate and install tf2_msgs (TFMessage only) for the PyPI ROS 2 wheels, which lack it.
#
# The ROS 2 wheels on PyPI (pip install '.[ros]') carry geometry_msgs and the rosidl generators
# but no tf2_msgs, so /tf and /tf_static cannot be published. This builds the one message websim
# needs, tf2_msgs/msg/TFMessage ("geometry_msgs/TransformStamped[] transforms", the upstream
# definition, so its type hash matches a ROS install's), with scripts/build_ros_interface.sh
# (the wheels' own rosidl) into the Python environment's prefix. Needs cmake and a C/C++
# compiler (Debian: apt-get install cmake g++); takes about 10 s. Does nothing when tf2_msgs
# already imports (a ROS 2 installation, or an earlier run).
#
# Usage: bash scripts/build_tf2_msgs.sh        (PYTHON=... to pick the interpreter)
set -euo pipefail
python=${PYTHON:-python3}

if "$python" -c 'import tf2_msgs.msg' 2>/dev/null; then
    echo "tf2_msgs is already installed"
    exit 0
fi
bash "$(dirname "$0")/build_ros_interface.sh" tf2_msgs geometry_msgs msg/TFMessage.msg \
    'geometry_msgs/TransformStamped[] transforms'
"$python" -c 'from tf2_msgs.msg import TFMessage; TFMessage()'
