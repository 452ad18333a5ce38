"""The bridge's errors: an operation that cannot be carried out, with the reason sent back."""

from __future__ import annotations

MAX_REASON_CHARS = 300
"""Longest error reason logged or sent back; reasons quote input, which may be a megabyte."""


class BridgeError(Exception):
    """An operation that cannot be carried out; the message is the reason sent back."""


class ServiceError(BridgeError):
    """A service call failed; the reason goes back in ``service_response.values``."""


def shorten(reason: str) -> str:
    """``reason``, cut to ``MAX_REASON_CHARS`` with its full length noted."""
    if len(reason) <= MAX_REASON_CHARS:
        return reason
    return f"{reason[:MAX_REASON_CHARS]}... ({len(reason)} characters)"
