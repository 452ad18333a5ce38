"""The recordings' writer process: serializes the robots' messages and writes their bags.

``websim serve --record`` runs this in a process of its own (``ros_nodes.recording`` starts
it), so that serializing and writing, pure Python and disk, never take the server's
interpreter lock from its ticks. It reads commands from one pipe and reports on another, both
pickled tuples:

* in: ``("open", id, folder, custom_data, max_bytes)``, ``("messages", [(id, log_time_ns,
  topic, type, message), ...])``, ``("close", id)``; the pipe's end closes every bag;
* out: ``("progress", {id: (messages, bytes)})`` about once a second, ``("stopped", id,
  reason, summary)`` when a bag cannot go on (a full disk, its size limit), ``("closed", id,
  summary)``.

A bag whose writing fails stops alone; the other bags and the process go on. SIGINT and
SIGTERM are ignored: the server closes the pipe when it stops (or dies), and every bag is
then closed properly.
"""

from __future__ import annotations

import contextlib
import dataclasses
import pickle
import signal
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from ros_nodes.bag_writer import BagSummary, BagWriter
from rosbridge.msgs.cdr import CdrError

PROGRESS_PERIOD_S = 1.0
"""How often the process reports what each bag holds."""


class BagSet:
    """The open bags, by recording id, and what the server is told about them.

    Args:
        report: sends one status tuple to the server.
    """

    def __init__(self, report: Any) -> None:
        self._report = report
        self._bags: dict[int, BagWriter] = {}
        self._limits: dict[int, int | None] = {}
        self._unwritable: dict[int, int] = {}
        self._last_progress_s = time.monotonic()

    def open(self, rid: int, folder: str, custom_data: dict[str, str],
             max_bytes: int | None) -> None:
        """Start a bag (a folder that cannot be made stops it at once)."""
        try:
            self._bags[rid] = BagWriter(Path(folder), custom_data)
        except OSError as error:
            self._report(("stopped", rid, f"cannot start the bag: {_reason(error)}",
                          dataclasses.asdict(BagSummary(folder, 0, 0, 0.0, {}, False))))
            return
        self._limits[rid] = max_bytes

    def write(self, batch: list[tuple[int, int, str, str, Any]]) -> None:
        """Append each message to its bag (those of stopped bags are dropped)."""
        for rid, log_time_ns, topic, type_name, msg in batch:
            bag = self._bags.get(rid)
            if bag is None:
                continue
            try:
                bag.write(topic, type_name, log_time_ns, msg)
            except CdrError:
                self._unwritable[rid] = self._unwritable.get(rid, 0) + 1
                continue
            except OSError as error:
                self._stop(rid, _reason(error), failed=True)
                continue
            except Exception as error:  # a bag's fault stays its own: the others go on
                self._stop(rid, f"{type(error).__name__}: {error}", failed=True)
                continue
            limit = self._limits[rid]
            if limit is not None and bag.bytes_on_disk >= limit:
                self._stop(rid, f"it reached its size limit ({limit / 1e6:g} MB, "
                                "--record-max-mb)", failed=False)
        now_s = time.monotonic()
        if now_s - self._last_progress_s >= PROGRESS_PERIOD_S:
            self._last_progress_s = now_s
            self._report(("progress", {rid: (bag.messages, bag.bytes_on_disk)
                                       for rid, bag in self._bags.items()}))

    def close(self, rid: int) -> None:
        """Close one bag properly (its summary and ``metadata.yaml``)."""
        bag = self._bags.pop(rid, None)
        if bag is None:
            return
        try:
            summary = bag.close()
        except OSError as error:
            self._report(("stopped", rid, _reason(error), self._summary(rid, bag.abort())))
            return
        self._report(("closed", rid, self._summary(rid, summary)))

    def close_all(self) -> None:
        """Close every bag still open."""
        for rid in list(self._bags):
            self.close(rid)

    def _stop(self, rid: int, reason: str, *, failed: bool) -> None:
        """Stop one bag: abort it after a write failed, else close it properly."""
        bag = self._bags.pop(rid)
        if failed:
            summary = bag.abort()
        else:
            try:
                summary = bag.close()
            except OSError as error:
                reason = f"{reason}; then {_reason(error)}"
                summary = bag.abort()
        self._report(("stopped", rid, reason, self._summary(rid, summary)))

    def _summary(self, rid: int, summary: BagSummary) -> dict[str, Any]:
        report = dataclasses.asdict(summary)
        report["unserializable"] = self._unwritable.pop(rid, 0)
        return report


def _reason(error: OSError) -> str:
    """An OSError as a few words (``No space left on device``).

    Without paths: /healthz shows it, and the log line names the bag.
    """
    return str(error.strerror or error)


def serve(commands: Connection, status: Connection) -> None:
    """The process's body: handle commands until the server closes the pipe."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)

    def report(item: tuple[Any, ...]) -> None:
        with contextlib.suppress(OSError):  # the server is gone: the bags are still closed
            status.send_bytes(pickle.dumps(item))

    bags = BagSet(report)
    try:
        while True:
            try:
                command = pickle.loads(commands.recv_bytes())
            except (EOFError, OSError):
                break
            op = command[0]
            if op == "messages":
                bags.write(command[1])
            elif op == "open":
                bags.open(*command[1:])
            elif op == "close":
                bags.close(command[1])
    finally:
        bags.close_all()
        status.close()
