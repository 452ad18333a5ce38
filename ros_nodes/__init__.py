"""websim's ROS-facing layer: message shapes, the virtual robot, the rosbridge server, nodes."""
