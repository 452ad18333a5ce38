"""The ROS 2 graph side of the upstream tests (``--ros`` mode): rclpy in a background thread.

Upstream's launch tests give each test an rclpy node that owns the publishers, subscribers,
service servers, clients and action servers the bridge talks to. Here one rclpy ``Context``
per run spins a ``MultiThreadedExecutor`` in a thread; each test gets its own node, destroyed
after it. The asyncio test bodies wait on rclpy futures by polling (``until``), which needs no
bridge between the two event models.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import threading
import time
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node


async def until(condition: Callable[[], Any], timeout_s: float, what: str) -> Any:
    """Poll ``condition`` every 20 ms until truthy; AssertionError naming ``what`` on timeout."""
    deadline = time.monotonic() + timeout_s
    while True:
        result = condition()
        if result:
            return result
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")
        await asyncio.sleep(0.02)


class RosSide:
    """One rclpy context and executor thread for a whole run; ``node()`` per test."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = MultiThreadedExecutor(num_threads=4, context=self.context)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        with contextlib.suppress(Exception):
            self.executor.spin()

    def node(self, name: str) -> Node:
        """A new node on the executor."""
        node = Node(name, context=self.context)
        self.executor.add_node(node)
        return node

    def drop(self, node: Node) -> None:
        """Remove and destroy a test's node."""
        self.executor.remove_node(node)
        node.destroy_node()

    def shutdown(self) -> None:
        """Stop the executor and the context."""
        self.executor.shutdown(timeout_sec=2)
        rclpy.shutdown(context=self.context)
        self._thread.join(timeout=5)


def message_class(type_name: str) -> Any:
    """The rclpy class of ``pkg/Type`` or ``pkg/msg/Type`` (ImportError if not installed)."""
    package, _, name = type_name.replace("/msg/", "/").partition("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def default_dict(message: Any) -> Any:
    """A message instance as rosbridge JSON: nested dicts, lists, numbers, strings.

    Enough for default-valued messages (``test_assorted_msgs``): byte arrays become base64
    strings as rosbridge writes them, other sequences lists.
    """
    import base64

    if hasattr(message, "get_fields_and_field_types"):
        return {name: default_dict(getattr(message, name))
                for name in message.get_fields_and_field_types()}
    if isinstance(message, (bytes, bytearray)):
        return base64.b64encode(bytes(message)).decode()
    if hasattr(message, "tolist"):
        return message.tolist()
    if isinstance(message, (list, tuple)) or type(message).__name__ == "array":
        return [default_dict(item) for item in message]
    return message
