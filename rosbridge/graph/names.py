"""The bridge's names on a ROS 2 graph, importable without rclpy."""

from __future__ import annotations

RELAY_NODE_NAME = "rosbridge_websocket"
"""The relay node's name, as rosbridge_server's (``/rosbridge_websocket`` on the graph)."""
