"""websim's ROS-facing layer: messages, the virtual robot, its hosts, sim time, nodes."""
