"""ROS message values, definitions, checks and conversions: no protocol, no robot."""
