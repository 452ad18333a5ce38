"""How a controller's run ended, and which limit it reached: the result the grader reports.

Pure: built from what the sandbox observed (exit status, who stopped it, the sampled peaks,
the output's tail), so the reasons are tested without running anything.
"""

from __future__ import annotations

import re
import signal
from dataclasses import dataclass

from websim.sandbox.limits import KIB, MIB, SandboxLimits

ENDINGS = ("exit", "signal", "wall_time", "memory", "server_exit")
"""How a run ends: the controller exited (``exit``) or was killed by a signal it did not
get from the sandbox (``signal``: a crash, or the kernel for a limit); or the sandbox stopped
it: past the wall-clock limit (``wall_time``), its processes' resident memory together over
the memory limit (``memory``), or its simulator ended the run (``server_exit``)."""

LIMITS = ("wall_time", "cpu_time", "memory", "processes", "open_files", "file_size", "disk",
          "output")
"""The limits a result may name as reached (``ControllerResult.limits_hit``)."""

_SIGNS_IN_OUTPUT = {
    # What a program prints when an allocation, a fork, an open or a write fails for a limit:
    # Python, glibc, C++, Node, bash. Read in the output's tail only, so "if known".
    "memory": re.compile(
        rb"MemoryError|Cannot allocate memory|std::bad_alloc|out of memory|"
        rb"Fatal process out of memory|Allocation failed"),
    "processes": re.compile(
        rb"fork: retry|fork: Resource temporarily unavailable|can't start new thread|"
        rb"BlockingIOError: \[Errno 11\]|spawn \S* ?EAGAIN|pthread_create.*(EAGAIN|"
        rb"Resource temporarily unavailable)"),
    "open_files": re.compile(rb"Too many open files|EMFILE"),
    "file_size": re.compile(rb"File too large|EFBIG"),
    "disk": re.compile(rb"No space left on device|ENOSPC"),
}


@dataclass(frozen=True)
class Observed:
    """What the sandbox saw of one run (the input of ``ControllerResult.build``).

    Attributes:
        exit_status: the controller's status as the sandbox's first process reports it: a
            code 0-255 (bubblewrap reports a death by signal N as 128 + N), or a negative
            signal number without the sandbox (as ``subprocess`` gives it); None if unknown.
        by_signal_code: codes above 128 mean a signal (true in the sandbox, where bubblewrap
            turns signal N into 128 + N).
        stopped_by: why the sandbox stopped it (``wall_time``, ``memory``, ``server_exit``),
            or None if it ended by itself.
        wall_time_s: from start to end, s.
        peak_tasks: the most processes and threads seen at once (None if not sampled).
        peak_memory_bytes: the most memory seen at once, all processes together (as its
            cgroup counts it, socket buffers included; else their resident memory and their
            sockets' queues).
        output_tail: the last bytes of the output.
        output_bytes: all the bytes of output, kept or not.
        oom_killed: the kernel killed one of its processes for its cgroup's memory limit.
    """

    exit_status: int | None
    by_signal_code: bool
    stopped_by: str | None
    wall_time_s: float
    peak_tasks: int | None
    peak_memory_bytes: int | None
    output_tail: bytes
    output_bytes: int
    oom_killed: bool = False


@dataclass(frozen=True)
class ControllerResult:
    """How one controller run ended (every field goes to the run's report).

    Attributes:
        sandboxed: it ran in the sandbox (False: ``no_sandbox``, ``--no-sandbox``).
        isolation: one line: what isolated it, or that nothing did.
        command: the command as given.
        ended_by: one of ``ENDINGS``.
        exit_code: its exit code, or None when a signal ended it.
        signal: the signal that ended it (``SIGKILL``), or None.
        limits_hit: the ``LIMITS`` it reached, as far as known (from the signal, the sampled
            peaks, or what it printed: a ``MemoryError``, a failed fork).
        wall_time_s: from start to end, s.
        peak_tasks: the most processes and threads it had at once (sampled; None without
            the sandbox).
        peak_memory_bytes: the most resident memory its processes held at once (sampled).
        output_tail: the end of its output (stdout and stderr together), as text.
        output_bytes: how many bytes it printed in all.
        limits: the limits it ran under.
        oom_killed: the kernel killed one of its processes at its cgroup's memory limit.
    """

    sandboxed: bool
    isolation: str
    command: tuple[str, ...]
    ended_by: str
    exit_code: int | None
    signal: str | None
    limits_hit: tuple[str, ...]
    wall_time_s: float
    peak_tasks: int | None
    peak_memory_bytes: int | None
    output_tail: str
    output_bytes: int
    limits: SandboxLimits
    oom_killed: bool = False

    @property
    def output_truncated(self) -> bool:
        """More was printed than ``output_tail`` holds."""
        return self.output_bytes > self.limits.output_tail_bytes

    @property
    def reason(self) -> str:
        """One line: how it ended, and which limits it reached."""
        limits = self.limits
        if self.ended_by == "wall_time":
            ending = f"stopped at the wall-clock limit ({limits.wall_time_s:g} s)"
        elif self.ended_by == "memory" and self.oom_killed:
            ending = (f"stopped: its processes needed more than the memory limit "
                      f"({size_text(limits.memory_bytes)}) together, and the kernel killed "
                      "one")
        elif self.ended_by == "memory":
            ending = (f"stopped: its processes held {size_text(self.peak_memory_bytes or 0)} "
                      f"together, over the memory limit ({size_text(limits.memory_bytes)})")
        elif self.ended_by == "server_exit":
            ending = "stopped when its simulator's run ended"
        elif self.signal is not None:
            ending = f"killed by {self.signal}"
        else:
            ending = f"exited with code {self.exit_code}"
        details = [_limit_detail(name, self) for name in self.limits_hit
                   if not (name == "wall_time" and self.ended_by == "wall_time")]
        line = ending if not details else f"{ending}; reached {', '.join(details)}"
        return line if self.sandboxed else f"{line} (ran without a sandbox)"

    @classmethod
    def build(cls, observed: Observed, *, sandboxed: bool, isolation: str,
              command: tuple[str, ...], limits: SandboxLimits) -> ControllerResult:
        """The result of one run from what the sandbox observed."""
        status = observed.exit_status
        signum: int | None = None
        if status is not None and status < 0:
            signum = -status
        elif status is not None and observed.by_signal_code and status > 128:
            signum = status - 128
        signal_name = _signal_name(signum) if signum is not None else None
        if observed.stopped_by is not None:
            ended_by = observed.stopped_by
        elif observed.oom_killed and signal_name == "SIGKILL":
            ended_by = "memory"  # the kernel killed it at its cgroup's memory limit
        else:
            ended_by = "signal" if signum is not None else "exit"
        exit_code = None if signum is not None else status
        hit = _limits_hit(observed, signal_name, ended_by, limits, sandboxed)
        return cls(
            sandboxed=sandboxed, isolation=isolation, command=command, ended_by=ended_by,
            exit_code=exit_code, signal=signal_name, limits_hit=hit,
            wall_time_s=round(observed.wall_time_s, 3),
            peak_tasks=observed.peak_tasks, peak_memory_bytes=observed.peak_memory_bytes,
            output_tail=observed.output_tail.decode("utf-8", errors="replace"),
            output_bytes=observed.output_bytes, limits=limits,
            oom_killed=observed.oom_killed)


@dataclass(frozen=True)
class ServerOutcome:
    """How the private simulator ended.

    Attributes:
        exit_code: its exit code (negative: the signal that ended it, without the sandbox;
            128 + N for signal N in it); None if it never started.
        output_tail: the end of its output, as text.
    """

    exit_code: int | None
    output_tail: str


def _limits_hit(observed: Observed, signal_name: str | None, ended_by: str,
                limits: SandboxLimits, sandboxed: bool) -> tuple[str, ...]:
    tail = observed.output_tail
    hit: set[str] = set()
    if ended_by in ("wall_time", "memory"):
        hit.add(ended_by)
    if observed.oom_killed:
        hit.add("memory")
    if signal_name == "SIGXCPU":  # (one that catches it gets SIGKILL: a kill of unknown cause)
        hit.add("cpu_time")
    if signal_name == "SIGXFSZ":
        hit.add("file_size")
    if sandboxed and observed.peak_tasks is not None and observed.peak_tasks >= limits.processes:
        hit.add("processes")
    for name, pattern in _SIGNS_IN_OUTPUT.items():
        if pattern.search(tail):
            hit.add(name)
    if observed.output_bytes > limits.output_tail_bytes:
        hit.add("output")
    return tuple(name for name in LIMITS if name in hit)


def _limit_detail(name: str, result: ControllerResult) -> str:
    limits = result.limits
    if name == "cpu_time":
        return f"the CPU-time limit ({limits.cpu_time_s} s per process)"
    if name == "memory":
        return f"the memory limit ({size_text(limits.memory_bytes)})"
    if name == "processes":
        if result.sandboxed:
            return f"the process limit ({limits.processes} processes and threads)"
        return "a process limit (the grader's user's)"
    if name == "open_files":
        return f"the open-file limit ({limits.open_files})"
    if name == "file_size":
        return f"the file-size limit ({size_text(limits.file_size_bytes)})"
    if name == "disk":
        return (f"the disk limit ({size_text(limits.home_bytes)} for its home, "
                f"{size_text(limits.tmp_bytes)} for /tmp)")
    if name == "output":
        return (f"the output limit (the last {size_text(limits.output_tail_bytes)} of "
                f"{size_text(result.output_bytes)} kept)")
    return f"the wall-clock limit ({limits.wall_time_s:g} s)"


def _signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def size_text(count: int) -> str:
    """Bytes as a person reads them: 512 B, 64 KiB, 1.5 GiB."""
    if count < KIB:
        return f"{count} B"
    if count < MIB:
        return f"{count / KIB:.4g} KiB"
    if count < 1024 * MIB:
        return f"{count / MIB:.4g} MiB"
    return f"{count / (1024 * MIB):.4g} GiB"
