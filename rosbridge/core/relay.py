"""One budget for every byte one client has relayed to others, and room at the receiver.

Publications, service requests and responses, action goals, feedback and results all go
from one client to others; each is charged, as the frame it arrived in, to its sender's
``Session.relay_budget`` (``ClientLimits.relay_bytes_per_s``, one second of burst). What
goes to a client as a reply (a request to a provider, a goal to a server, a response,
feedback or a result to the caller) is never dropped once queued, so it is refused at its
sender while the receiver's send queue is more than ``RECEIVER_ROOM_SHARE`` full: a flood
is refused at its sender, never by closing the receiver for send-queue overflow.
"""

from __future__ import annotations

from rosbridge.core.errors import BridgeError
from rosbridge.core.session import Session

RECEIVER_ROOM_SHARE = 0.5
"""A relayed reply is refused while its receiver's send queue holds more than this share of
its ``max_queued_bytes`` (half of 4 MiB): the other half is for its topics and its own
replies, so the receiver is not closed for what others sent it."""


def charge(sender: Session, what: str, receiver: Session | None = None) -> None:
    """Charge ``sender``'s relay budget with the frame it is handling, relayed to ``receiver``.

    Args:
        sender: the client whose frame is relayed (``frame_bytes``: its size).
        what: the op and name, for the reason.
        receiver: the client it goes to as a reply (None: topic subscribers, the graph).

    Raises:
        BridgeError: the receiver has no room, or the sender is over its budget; nothing
            was taken from the budget in the first case.
    """
    size = sender.frame_bytes
    if receiver is not None:
        waiting = receiver.outbox.queued_bytes
        room = int(receiver.limits.max_queued_bytes * RECEIVER_ROOM_SHARE)
        if waiting + size > room:
            raise BridgeError(f"{what}: its receiver has {waiting} bytes waiting to be sent "
                              f"(at most {room} for what others send it); dropped, try "
                              "again later")
    if not sender.relay_budget.take(size):
        raise BridgeError(f"{what}: more than {sender.limits.relay_bytes_per_s} bytes/s "
                          "relayed to other clients; dropped")
