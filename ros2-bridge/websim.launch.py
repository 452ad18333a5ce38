"""The ROS side of the Docker deployment: the virtual robot and its two rosbridge servers.

``ros2 launch /opt/websim/ros2-bridge/websim.launch.py`` (the image's command) starts

* ``virtual_robot`` (``websim-robot``): the simulation, publishing /odom, /scan, /tf...;
* ``rosbridge_websocket`` on 9090 for students, limited by the globs in rosbridge_params.yaml;
* ``/admin/rosbridge_websocket`` on 9091 for the admin page (set_parameters), reached only
  through nginx's authenticated /admin/rosbridge;
* one ``rosapi_node``, which both bridges use (two would offer the same /rosapi/* services).

If any of them exits, the whole launch stops, so the container exits and Docker's restart
policy brings the stack back as one piece.
"""

from pathlib import Path

from launch import LaunchDescription
from launch.actions import ExecuteProcess, Shutdown
from launch_ros.actions import Node

PARAMS_FILE = str(Path(__file__).with_name("rosbridge_params.yaml"))
"""Port and globs of each rosbridge, and rosapi's globs."""


def generate_launch_description() -> LaunchDescription:
    """The four processes of the ros2-web-bridge container."""
    return LaunchDescription([
        ExecuteProcess(cmd=["websim-robot"], name="virtual_robot", output="screen",
                       on_exit=Shutdown(reason="virtual_robot exited")),
        Node(package="rosbridge_server", executable="rosbridge_websocket",
             name="rosbridge_websocket", parameters=[PARAMS_FILE], output="screen",
             on_exit=Shutdown(reason="rosbridge_websocket exited")),
        Node(package="rosbridge_server", executable="rosbridge_websocket",
             name="rosbridge_websocket", namespace="admin", parameters=[PARAMS_FILE],
             output="screen", on_exit=Shutdown(reason="admin rosbridge_websocket exited")),
        # Not named "rosapi": a node's own parameter services are /NODE/set_parameters, and
        # rosbridge opens /rosapi/* to every client.
        Node(package="rosapi", executable="rosapi_node", name="rosapi_node",
             parameters=[PARAMS_FILE], output="screen",
             on_exit=Shutdown(reason="rosapi exited")),
    ])
