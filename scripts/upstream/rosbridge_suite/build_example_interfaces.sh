#!/usr/bin/env bash
# Generate and install example_interfaces (action/Fibonacci only) for the PyPI ROS 2 wheels.
#
# rosbridge_suite's action tests (advertise_action, advertise_action_feedback, send_action_goal)
# run an rclpy ActionClient or ActionServer of example_interfaces/action/Fibonacci; the PyPI
# wheels have no example_interfaces. This builds that one action with
# scripts/build_ros_interface.sh (the wheels' own rosidl) into the Python environment's prefix.
# Does nothing when it already imports. The definition is upstream's (ros2/example_interfaces,
# Fibonacci.action).
#
# Usage: bash scripts/upstream/rosbridge_suite/build_example_interfaces.sh   (PYTHON=...)
set -euo pipefail
python=${PYTHON:-python3}

if "$python" -c 'from example_interfaces.action import Fibonacci' 2>/dev/null; then
    echo "example_interfaces is already installed"
    exit 0
fi
bash "$(dirname "$0")/../../build_ros_interface.sh" example_interfaces action_msgs \
    action/Fibonacci.action \
    "$(printf '# Goal\nint32 order\n---\n# Result\nint32[] sequence\n---\n# Feedback\nint32[] sequence')"
"$python" -c 'from example_interfaces.action import Fibonacci; Fibonacci.Goal(order=3)'
