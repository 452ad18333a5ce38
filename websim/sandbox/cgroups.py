"""A control group per sandbox, where this machine lets the grader make one.

What a cgroup bounds that resource limits cannot: the memory of all the controller's
processes together *as the kernel counts it*, socket buffers included (cgroup v2 counts every
socket's; v1 counts the kernel memory of local sockets with the rest, and TCP's buffers
under ``memory.kmem.tcp.limit_in_bytes``, which this sets), its processes together
(``pids.max``), and its share of the CPU (``cpu.shares`` / ``cpu.weight``: one ordinary
process's, however many it starts, and a quota of ``cpus`` cores), so that a controller
burning every core cannot starve its own or a classmate's simulator.

Made in the grader's own cgroup of each controller (``/proc/self/cgroup``), on v1 (a mount per
controller, as here) or v2 (one mount; the controllers enabled in the grader's
``cgroup.subtree_control``). Where none can be made (not root, a v2 tree not delegated) the
sandbox runs without (``Cgroup.open`` returns None) and its report says so; the resource
limits and the sampled memory still hold.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import time
from dataclasses import dataclass
from pathlib import Path

CONTROLLERS = ("memory", "pids", "cpu")

CPU_SHARES_V1 = 1024
CPU_WEIGHT_V2 = 100
"""The controller's CPU weight: all its processes together weigh as one ordinary process
(1024 in v1, 100 in v2) against its simulator, the grader or another run's simulator,
however many it forks. Not lower: in deterministic mode the run goes as fast as the
controller answers, and a busy machine would starve a fair controller (measured: a weight of
an eighth made the six-scenario suite 1.5-3x slower on a loaded machine)."""

CPU_PERIOD_US = 100_000

TCP_SHARE = 4
"""cgroup v1: TCP's socket buffers may hold a quarter of the memory limit (v1 counts them
apart from the rest, and nothing at all unless this limit is set)."""

REMOVE_WAIT_S = 5.0


def _mounts() -> dict[str, Path]:
    """Where each cgroup controller is mounted (``""`` for the v2 hierarchy)."""
    found: dict[str, Path] = {}
    with contextlib.suppress(OSError), open("/proc/self/mountinfo") as mountinfo:
        for line in mountinfo:
            fields = line.split()
            separator = fields.index("-")
            kind, options = fields[separator + 1], fields[separator + 3].split(",")
            point = Path(fields[4])
            if kind == "cgroup2":
                found.setdefault("", point)
            elif kind == "cgroup":
                for name in CONTROLLERS:
                    if name in options:
                        found.setdefault(name, point)
    return found


def _own_paths() -> dict[str, str]:
    """This process's cgroup per v1 controller, and ``""`` for v2."""
    paths: dict[str, str] = {}
    with contextlib.suppress(OSError), open("/proc/self/cgroup") as cgroup:
        for line in cgroup:
            _, names, path = line.rstrip("\n").split(":", 2)
            for name in names.split(",") if names else [""]:
                paths[name] = path
    return paths


@dataclass
class Cgroup:
    """One sandbox's cgroup: a folder per controller (v1) or one folder (v2).

    Attributes:
        folders: the controller's folder for each of ``CONTROLLERS`` this machine bounds.
        v2: the unified hierarchy (one folder for all).
    """

    folders: dict[str, Path]
    v2: bool

    @classmethod
    def open(cls, *, memory_bytes: int, processes: int, cpus: float) -> Cgroup | None:
        """Make a cgroup with these limits, or None where this machine lets none be made.

        Args:
            memory_bytes: the memory of all its processes together (and TCP's buffers: a
                ``TCP_SHARE``-th of it, v1).
            processes: processes and threads together.
            cpus: its CPU time as cores' worth (a quota), besides its weight.
        """
        mounts, own = _mounts(), _own_paths()
        name = f"websim-sandbox-{os.getpid()}-{secrets.token_hex(4)}"
        v1 = {controller: mounts[controller] / own[controller].lstrip("/") / name
              for controller in CONTROLLERS if controller in mounts and controller in own}
        made: Cgroup | None = None
        try:
            if "memory" in v1:
                for folder in v1.values():
                    folder.mkdir()
                made = cls(v1, v2=False)
            elif "" in mounts and "" in own:
                parent = mounts[""] / own[""].lstrip("/")
                enabled = (parent / "cgroup.subtree_control").read_text().split()
                if "memory" not in enabled:
                    return None
                folder = parent / name
                folder.mkdir()
                made = cls({controller: folder for controller in CONTROLLERS
                            if controller in enabled}, v2=True)
            else:
                return None
            made._limit(memory_bytes, processes, cpus)
        except OSError:
            if made is not None:
                made.remove()
            return None
        return made

    def _limit(self, memory_bytes: int, processes: int, cpus: float) -> None:
        quota_us = max(1000, int(cpus * CPU_PERIOD_US))
        if self.v2:
            self._write("memory", "memory.max", memory_bytes)
            self._write("memory", "memory.swap.max", 0, optional=True)
            self._write("pids", "pids.max", processes, optional=True)
            self._write("cpu", "cpu.weight", CPU_WEIGHT_V2, optional=True)
            self._write("cpu", "cpu.max", f"{quota_us} {CPU_PERIOD_US}", optional=True)
            return
        self._write("memory", "memory.limit_in_bytes", memory_bytes)
        self._write("memory", "memory.memsw.limit_in_bytes", memory_bytes, optional=True)
        self._write("memory", "memory.kmem.tcp.limit_in_bytes", memory_bytes // TCP_SHARE,
                    optional=True)
        self._write("pids", "pids.max", processes, optional=True)
        self._write("cpu", "cpu.shares", CPU_SHARES_V1, optional=True)
        self._write("cpu", "cpu.cfs_period_us", CPU_PERIOD_US, optional=True)
        self._write("cpu", "cpu.cfs_quota_us", quota_us, optional=True)

    def _write(self, controller: str, file: str, value: object, *,
               optional: bool = False) -> None:
        folder = self.folders.get(controller)
        if folder is None:
            return
        try:
            (folder / file).write_text(f"{value}\n")
        except OSError:
            if not optional:
                raise

    def _read(self, controller: str, file: str) -> str:
        folder = self.folders.get(controller)
        if folder is None:
            return ""
        try:
            return (folder / file).read_text()
        except OSError:
            return ""

    @property
    def procs_files(self) -> list[str]:
        """The ``cgroup.procs`` a process writes its pid to, to enter this cgroup."""
        return sorted({str(folder / "cgroup.procs") for folder in self.folders.values()})

    @property
    def bounds(self) -> str:
        """What it bounds, for the report (one phrase)."""
        kind = "v2" if self.v2 else "v1"
        return f"cgroup {kind} ({', '.join(sorted(self.folders))})"

    def memory_bytes(self) -> int:
        """Its memory as the kernel counts it now (socket buffers included), bytes."""
        if self.v2:
            return _number(self._read("memory", "memory.current"))
        return (_number(self._read("memory", "memory.usage_in_bytes"))
                + _number(self._read("memory", "memory.kmem.tcp.usage_in_bytes")))

    def peak_memory_bytes(self) -> int:
        """The most memory it has held (the kernel's own peak: no sample misses it)."""
        if self.v2:
            return _number(self._read("memory", "memory.peak"))
        return (_number(self._read("memory", "memory.max_usage_in_bytes"))
                + _number(self._read("memory", "memory.kmem.tcp.max_usage_in_bytes")))

    def tasks(self) -> int:
        """Its processes and threads now (0 without the pids controller)."""
        return _number(self._read("pids", "pids.current"))

    def oom_kills(self) -> int:
        """Processes the kernel killed for its memory limit."""
        text = self._read("memory", "memory.events" if self.v2 else "memory.oom_control")
        for line in text.splitlines():
            key, _, value = line.partition(" ")
            if key == "oom_kill":
                return _number(value)
        return 0

    def pids(self) -> list[int]:
        """The processes in it."""
        text = self._read("memory" if "memory" in self.folders else "pids", "cgroup.procs")
        return [int(pid) for pid in text.split()]

    def remove(self) -> None:
        """Remove its folders (once its processes have gone; idempotent)."""
        deadline = time.monotonic() + REMOVE_WAIT_S
        for folder in set(self.folders.values()):
            while folder.exists():
                try:
                    folder.rmdir()
                except OSError:
                    if time.monotonic() > deadline:
                        break
                    time.sleep(0.02)
        self.folders = {}


def _number(text: str) -> int:
    try:
        return int(text.split()[0])
    except (IndexError, ValueError):
        return 0


ENTER_CGROUP = 'while [ "$1" != -- ]; do echo $$ > "$1" || exit 125; shift; done; shift; ' \
               'exec "$@"'
"""``/bin/sh -c ENTER_CGROUP sh PROCS_FILE... -- COMMAND...``: enter the cgroup, become the
command (so that everything it starts is in the cgroup from its first instruction)."""


def enter_then(cgroup: Cgroup | None, command: list[str]) -> list[str]:
    """``command``, preceded by entering ``cgroup`` (unchanged without one)."""
    if cgroup is None:
        return command
    return ["/bin/sh", "-c", ENTER_CGROUP, "sh", *cgroup.procs_files, "--", *command]
