"""Faults caught at a robot's boundary: logged once, counted, and reported by /healthz.

Nothing a client sends may stop a robot's tick loop. Where an unexpected exception is caught
(stepping the robot, encoding or delivering a message, handling a client's operation), it is
recorded here: the first of each kind is logged with its traceback, later ones are counted,
and ``/healthz`` says ``degraded`` with the reasons while faults keep coming: once none was
caught for ``DEGRADED_FOR_S``, it says ``ok`` again (the counts stay).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field

from rosbridge.core.clock import WALL_CLOCK

log = logging.getLogger("websim.faults")

DEGRADED_FOR_S = 60.0
"""How long after its last fault a robot is reported ``degraded``: a cause that has stopped
(a client that sent something unencodable and left) does not mark it until restart."""

MAX_KINDS = 32
"""Distinct fault kinds remembered (where, exception type); later kinds are only counted."""


@dataclass
class Faults:
    """The faults of one robot (its bridge, its tick loop).

    Attributes:
        counts: per kind (``"where: ExceptionType"``), how often it happened.
        last_reason: the most recent fault, with its cause.
        total: every fault caught.
        last_s: when the last one was (monotonic s; -inf: never).
        clock: monotonic time (s): a ``Clock``'s ``monotonic_s`` (default: wall time).
    """

    counts: dict[str, int] = field(default_factory=dict)
    last_reason: str | None = None
    total: int = 0
    last_s: float = -math.inf
    clock: Callable[[], float] = WALL_CLOCK.monotonic_s

    def record(self, where: str, error: BaseException) -> None:
        """Count a fault caught at ``where``; log it with its traceback the first time."""
        kind = f"{where}: {type(error).__name__}"
        reason = f"{kind}: {str(error)[:200]}"
        self.total += 1
        self.last_reason = reason
        self.last_s = self.clock()
        if kind in self.counts:
            self.counts[kind] += 1
            return
        if len(self.counts) < MAX_KINDS:
            self.counts[kind] = 1
        log.error("fault caught (the loop goes on): %s", reason, exc_info=error)

    @property
    def degraded(self) -> bool:
        """Whether a fault was caught within the last ``DEGRADED_FOR_S``."""
        return self.total > 0 and self.clock() - self.last_s < DEGRADED_FOR_S

    def report(self) -> dict[str, object]:
        """For /healthz: the counts per kind and the last reason."""
        return {"faults": dict(self.counts), "faults_total": self.total,
                "last_fault": self.last_reason}
