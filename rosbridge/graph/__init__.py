"""The rclpy side of ``--ros``: the bridge's topics, services and actions on a ROS 2 graph."""
