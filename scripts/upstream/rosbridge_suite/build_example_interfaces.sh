#!/usr/bin/env bash
# Generate and install example_interfaces (action/Fibonacci only) for the PyPI ROS 2 wheels.
#
# rosbridge_suite's action tests (advertise_action, advertise_action_feedback, send_action_goal)
# run an rclpy ActionClient or ActionServer of example_interfaces/action/Fibonacci; the PyPI
# wheels have no example_interfaces. This builds that one action with the rosidl generators,
# the way scripts/build_tf2_msgs.sh builds tf2_msgs (which must have run first: it installs the
# build-time half of rosidl), into the Python environment's prefix. Does nothing when it
# already imports. The definition is upstream's (ros2/example_interfaces, Fibonacci.action).
#
# Usage: bash scripts/upstream/rosbridge_suite/build_example_interfaces.sh   (PYTHON=...)
set -euo pipefail
python=${PYTHON:-python3}

if "$python" -c 'from example_interfaces.action import Fibonacci' 2>/dev/null; then
    echo "example_interfaces is already installed"
    exit 0
fi
"$python" -c 'import rclpy, action_msgs.msg' 2>/dev/null || {
    echo "build_example_interfaces: install the ROS 2 wheels first: pip install '.[ros]'" >&2
    exit 1
}
prefix=$("$python" -c 'import sysconfig; print(sysconfig.get_paths()["data"])')
python_dir=$("$python" -c 'import os, sysconfig; p = sysconfig.get_paths()
print(os.path.relpath(p["purelib"], p["data"]))')
executable=$("$python" -c 'import sys; print(sys.executable)')
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
pkg="$work/example_interfaces"
mkdir -p "$pkg/action"
printf '# Goal\nint32 order\n---\n# Result\nint32[] sequence\n---\n# Feedback\nint32[] sequence\n' \
    > "$pkg/action/Fibonacci.action"
cat > "$pkg/package.xml" <<'XML'
<?xml version="1.0"?>
<package format="3">
  <name>example_interfaces</name>
  <version>0.0.0</version>
  <description>example_interfaces/action/Fibonacci only, generated for websim's upstream test runner</description>
  <maintainer email="websim@example.invalid">websim</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>action_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
XML
cat > "$pkg/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(example_interfaces)
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
find_package(action_msgs REQUIRED)
rosidl_generate_interfaces(${PROJECT_NAME} "action/Fibonacci.action" DEPENDENCIES action_msgs)
get_property(imported DIRECTORY PROPERTY IMPORTED_TARGETS)
foreach(target IN LISTS imported)
  get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
  if(dirs)
    list(FILTER dirs EXCLUDE REGEX "^/opt/python/")
    set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${dirs}")
  endif()
endforeach()
ament_package()
CMAKE
export AMENT_PREFIX_PATH="$prefix${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
if ! { cmake -S "$pkg" -B "$work/build" -DCMAKE_BUILD_TYPE=Release \
           -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_INSTALL_PREFIX="$prefix" \
           -DPython3_EXECUTABLE="$executable" -DPYTHON_INSTALL_DIR="$python_dir" \
           -DBUILD_TESTING=OFF \
       && cmake --build "$work/build" -j 2 \
       && cmake --install "$work/build"; } > "$work/build.log" 2>&1; then
    tail -40 "$work/build.log" >&2
    echo "build_example_interfaces: the build failed (log above)" >&2
    exit 1
fi
"$python" -c 'from example_interfaces.action import Fibonacci; Fibonacci.Goal(order=3)'
echo "example_interfaces installed into $prefix"
