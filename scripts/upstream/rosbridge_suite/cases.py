"""What one upstream test is here: its upstream id, our wire-level body, or why it cannot run.

A ``Case`` names one upstream test (``file::Class::test``) and either a body, an async
function of a ``Context``, or the reason it does not apply, per mode: ``plain`` (``websim
serve``; where upstream's test uses a ROS node, a second rosbridge client plays that node)
and ``ros`` (``websim serve --ros``; an rclpy node of this process plays it, as upstream's).
The bodies are our own code, written from reading upstream's tests; none is copied.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from wire_client import Trace, TracedClient

MODES = ("plain", "ros")


@dataclass
class Context:
    """What a test body gets: its mode, the bridge URL, its trace, its clients and ROS node."""

    mode: str
    url: str
    trace: Trace
    ros: Any = None
    node: Any = None
    clients: list[TracedClient] = field(default_factory=list)

    @property
    def on_graph(self) -> bool:
        """Whether an rclpy node plays upstream's node (``--ros``) rather than a peer client."""
        return self.mode == "ros"

    async def client(self, name: str) -> TracedClient:
        """Open one more traced client to the bridge (closed after the test)."""
        opened = await TracedClient.connect(self.url, name, self.trace)
        self.clients.append(opened)
        return opened

    def note(self, text: str) -> None:
        """Put a remark in the trace (what the test is about to check)."""
        self.trace.add("runner", "--", text)


Body = Callable[[Context], Awaitable[None]]


@dataclass(frozen=True)
class Case:
    """One upstream test: a body, and the modes where it does not apply with the reason."""

    suite: str
    test_id: str
    body: Body | None
    not_applicable: Mapping[str, str] = field(default_factory=dict)
    note: str = ""

    def reason_not_applicable(self, mode: str) -> str | None:
        """Why this test does not run in ``mode``, or None when it runs."""
        return self.not_applicable.get(mode) or self.not_applicable.get("both")


def expect(condition: bool, message: str) -> None:
    """AssertionError with ``message`` unless ``condition`` (assert statements may be stripped)."""
    if not condition:
        raise AssertionError(message)


def expect_equal(actual: Any, expected: Any, what: str) -> None:
    """AssertionError showing both values unless they are equal."""
    if actual != expected:
        raise AssertionError(f"{what}: expected {expected!r}, got {actual!r}")
