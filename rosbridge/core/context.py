"""What the capabilities of one bridge share: its clients, clock, faults, refusals, graph port.

Each capability (``capabilities.topics``, ``.services``, ``.actions``) is built over one
``BridgeContext`` and never over the ``Bridge``: none reaches another through it. What one
capability must know of another's state it is given explicitly (an argument, a narrow
callable), so the bridge is the only module that knows them all.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rosbridge.core.clock import Clock
from rosbridge.core.faults import Faults
from rosbridge.core.graph_port import GraphPort
from rosbridge.core.limits import LatchedBytes
from rosbridge.core.session import Ready, Session


@dataclass
class BridgeContext:
    """The state of one bridge that every capability may use.

    Attributes:
        clock: the bridge's clock: its ``monotonic_s`` times throttles, timeouts and loops
            closing; its ``stamp_s`` stamps ``cbor-raw`` frames.
        faults: where unexpected exceptions are recorded.
        refusals: what an in-process handler raises to refuse with a reason (not a fault).
        graph: the port to a ROS 2 graph (does nothing until one is attached).
        latched: the bytes of clients' latched messages this bridge holds, within its
            server's (``LatchedBytes``).
        sessions: the connected clients.
        ready: the clients whose outboxes got frames since the bridge last handed them to
            the transport (each ``Session.ready`` is this set once connected).
        closing: those of them closing a loop (``capabilities.topics.CLOSING_LOOP_S``), to
            be written first.
    """

    clock: Clock
    faults: Faults
    refusals: tuple[type[Exception], ...]
    graph: GraphPort
    latched: LatchedBytes
    sessions: set[Session] = field(default_factory=set)
    ready: Ready = field(default_factory=dict)
    closing: Ready = field(default_factory=dict)
