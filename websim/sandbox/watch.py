"""Watching a controller from outside: its output's tail, its processes, their memory.

The processes of a sandboxed controller are those of its process namespace (each sandbox
has its own, which none of its processes can leave); without the sandbox, those of the
session it was started in (a program that leaves its session escapes this count, which is
one reason the sandbox exists). What its sockets hold in the kernel is read from its
network namespace's ``/proc/PID/net`` tables (``socket_bytes``).
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from dataclasses import dataclass
from typing import IO

SAMPLE_PERIOD_S = 0.1
"""How often a running controller's processes and memory are sampled: the memory limit of
all of them together is checked this often (each one's address space is the kernel's)."""

READ_CHUNK_BYTES = 65536

STOP_WAIT_S = 5.0
"""How long killing a controller's processes may take before the sandbox gives up saying
so (SIGKILL is not ignorable; this covers a loaded machine)."""


class OutputTail:
    """Reads a pipe to its end in a thread, keeping its last bytes and counting all of them.

    A program that prints without end costs a read per 64 KiB and never more memory than
    ``limit_bytes`` (and the window ``ready`` needs).
    """

    def __init__(self, stream: IO[bytes], limit_bytes: int, *, ready: str | None = None,
                 name: str = "output") -> None:
        """Start reading ``stream``.

        Args:
            stream: the pipe's reading end (closed when it ends).
            limit_bytes: how many of the last bytes to keep.
            ready: a text whose appearance in the output sets ``ready`` (None: never).
            name: the thread's name.
        """
        self._stream = stream
        self._limit_bytes = limit_bytes
        self._ready_text = None if ready is None else ready.encode()
        self._kept = bytearray()
        self._total_bytes = 0
        self._lock = threading.Lock()
        self.ready = threading.Event()
        self._thread = threading.Thread(target=self._read, name=name, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        fd = self._stream.fileno()
        window = b""
        try:
            while chunk := os.read(fd, READ_CHUNK_BYTES):
                with self._lock:
                    self._total_bytes += len(chunk)
                    self._kept += chunk
                    if len(self._kept) > self._limit_bytes:
                        del self._kept[:len(self._kept) - self._limit_bytes]
                if self._ready_text is not None and not self.ready.is_set():
                    window += chunk
                    if self._ready_text in window:
                        self.ready.set()
                    window = window[-len(self._ready_text):]
        except OSError:
            pass  # the pipe went away with its process
        finally:
            self._stream.close()

    @property
    def tail(self) -> bytes:
        """The last ``limit_bytes`` bytes read so far."""
        with self._lock:
            return bytes(self._kept)

    @property
    def total_bytes(self) -> int:
        """Every byte read so far, kept or not."""
        with self._lock:
            return self._total_bytes

    @property
    def finished(self) -> bool:
        """The pipe ended (every writer closed it)."""
        return not self._thread.is_alive()

    def join(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the pipe's end; True if it ended."""
        self._thread.join(timeout_s)
        return not self._thread.is_alive()


@dataclass(frozen=True)
class Usage:
    """A controller's processes at one moment.

    Attributes:
        pids: its processes (in this machine's process namespace).
        tasks: its processes and threads (what RLIMIT_NPROC counts).
        rss_bytes: their resident memory together, bytes (shared pages counted once per
            process: an over-estimate, never an under-estimate).
    """

    pids: tuple[int, ...]
    tasks: int
    rss_bytes: int


def usage(*, uid: int | None = None, session: int | None = None,
          pidns: int | None = None) -> Usage:
    """The processes of a user (``uid``), a session or a process namespace (its inode).

    Read from each ``/proc/PID/status`` (not the owner of ``/proc/PID``, which a process
    can turn to root with ``prctl(PR_SET_DUMPABLE, 0)``) and ``/proc/PID/ns/pid``.
    """
    pids: list[int] = []
    tasks = rss_kib = 0
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/status", "rb") as status:
                fields = _status_fields(status.read())
        except OSError:
            continue  # gone since the listing
        if fields.get(b"State") == ZOMBIE:
            continue  # dead, waiting for its parent: holds no memory and no process slot
        if uid is not None and fields.get(b"Uid", -1) != uid:
            continue
        if session is not None and fields.get(b"NSsid", -1) != session:
            continue
        if pidns is not None and _pid_namespace(entry.name) != pidns:
            continue
        pids.append(int(entry.name))
        tasks += fields.get(b"Threads", 1)
        rss_kib += fields.get(b"VmRSS", 0)
    return Usage(tuple(pids), tasks, rss_kib * 1024)


def _pid_namespace(pid: str) -> int | None:
    """The inode of a process's pid namespace (None once it has gone)."""
    try:
        return os.stat(f"/proc/{pid}/ns/pid").st_ino
    except OSError:
        return None


SOCKET_TABLES = ("tcp", "tcp6", "udp", "udp6")


def socket_bytes(pid: int, tables: tuple[str, ...] = SOCKET_TABLES) -> int:
    """The bytes queued in the sockets of ``pid``'s network namespace (sent and received).

    From ``/proc/PID/net/TABLE`` (``tcp``, ``udp`` and their ``6``): each socket's
    ``tx_queue`` and ``rx_queue`` (what the kernel holds for it). 0 once the process has
    gone.
    """
    total = 0
    for table in tables:
        try:
            with open(f"/proc/{pid}/net/{table}", "rb") as file:
                lines = file.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) > 4:
                sent, _, received = fields[4].partition(b":")
                with contextlib.suppress(ValueError):
                    total += int(sent, 16) + int(received, 16)
    return total


ZOMBIE = -1
"""``State`` of a process that has ended but is not yet waited for."""


def _status_fields(text: bytes) -> dict[bytes, int]:
    """The fields of ``/proc/PID/status`` this module reads.

    The first number of each (the real user of ``Uid``; the session in this namespace of
    ``NSsid``); ``State`` as 0 or ``ZOMBIE``.
    """
    fields: dict[bytes, int] = {}
    for line in text.splitlines():
        key, _, rest = line.partition(b":")
        if key == b"State":
            fields[key] = ZOMBIE if rest.strip().startswith(b"Z") else 0
        elif key in (b"Uid", b"NSsid", b"Threads", b"VmRSS"):
            numbers = rest.split()
            if numbers:
                fields[key] = int(numbers[0])
    return fields


def kill_all(*, uid: int | None = None, session: int | None = None,
             pidns: int | None = None) -> bool:
    """SIGKILL every process of ``uid`` (or ``session``, or ``pidns``) until none is left.

    A process may fork while its siblings die, so this repeats until a scan finds none, up
    to ``STOP_WAIT_S``. Returns True when none is left.
    """
    deadline = time.monotonic() + STOP_WAIT_S
    while True:
        pids = usage(uid=uid, session=session, pidns=pidns).pids
        if not pids:
            return True
        if time.monotonic() > deadline:
            return False
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(0.01)
