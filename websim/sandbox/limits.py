"""What a submission's controller may use: the limits of one run and how they are applied.

Applied with ``prlimit`` (util-linux) in front of the sandbox, so every process of the
controller inherits them; each is a kernel resource limit except ``memory_bytes`` for all
the processes together and ``wall_time_s``, which the sandbox watches (``watch.py``), and the
tmpfs sizes (``/tmp``, ``/dev/shm``, the home), which bubblewrap sets.
"""

from __future__ import annotations

from dataclasses import dataclass

KIB = 1024
MIB = 1024 * KIB
GIB = 1024 * MIB

CPU_KILL_GRACE_S = 5
"""Past ``cpu_time_s`` a process gets SIGXCPU; this much later, the kernel's SIGKILL (a
controller may catch SIGXCPU, not SIGKILL)."""

MAX_WALL_TIME_S = 24 * 3600.0
"""A run's wall-clock limit is at most a day: a typo (``wall_time_s=36000000``) is refused."""


@dataclass(frozen=True)
class SandboxLimits:
    """The limits of one controller run (defaults fit a 120 s scenario on a 2-core machine).

    Attributes:
        wall_time_s: wall-clock time from start to the end of the run, s; past it the whole
            sandbox is killed (every process of the controller, whatever session or group
            it made for itself).
        cpu_time_s: CPU time of each process, s (RLIMIT_CPU: SIGXCPU at this, SIGKILL
            ``CPU_KILL_GRACE_S`` later).
        memory_bytes: memory, bytes: the address space of each process (RLIMIT_AS: an
            allocation beyond it fails, Python raises MemoryError) and the resident memory of
            all of them together, sampled ``watch.SAMPLE_PERIOD_S`` apart (past it the sandbox
            is killed).
        processes: processes and threads of the controller together (RLIMIT_NPROC, which
            counts both, per user: each sandbox runs as a user of its own). Not enforced
            without the sandbox (it would count the grader's user's processes).
        open_files: open files and sockets per process (RLIMIT_NOFILE).
        file_size_bytes: the largest file a process may write, bytes (RLIMIT_FSIZE).
        tmp_bytes: the size of each of the sandbox's private ``/tmp`` and ``/dev/shm``
            (tmpfs, in memory), bytes.
        home_bytes: the size of the controller's home (tmpfs, in memory): its copy of the
            submission and all it writes there, bytes.
        output_tail_bytes: how much of the controller's output (stdout and stderr together)
            is kept: the last this many bytes; the rest is counted and dropped.
        cpus: the CPU time its processes may have together, in cores (a cgroup's quota,
            where one can be made; all of them weigh as one process besides,
            ``cgroups.CPU_SHARES_V1``).
    """

    wall_time_s: float = 600.0
    cpu_time_s: int = 600
    memory_bytes: int = 4 * GIB
    processes: int = 128
    open_files: int = 1024
    file_size_bytes: int = 256 * MIB
    tmp_bytes: int = 64 * MIB
    home_bytes: int = 256 * MIB
    output_tail_bytes: int = 64 * KIB
    cpus: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.wall_time_s <= MAX_WALL_TIME_S:
            raise ValueError(f"wall_time_s must be in (0, {MAX_WALL_TIME_S:.0f}] s, "
                             f"got {self.wall_time_s!r}")
        for name in ("cpu_time_s", "memory_bytes", "processes", "open_files",
                     "file_size_bytes", "tmp_bytes", "home_bytes", "output_tail_bytes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a whole number of at least 1, got {value!r}")
        if not 0.01 <= self.cpus <= 1024:
            raise ValueError(f"cpus must be in [0.01, 1024] cores, got {self.cpus!r}")
        if self.open_files < 16:
            raise ValueError(f"open_files must be at least 16 (stdin, stdout, stderr and the "
                             f"interpreter's own), got {self.open_files}")


def prlimit_arguments(limits: SandboxLimits, *, processes: bool) -> list[str]:
    """The options of ``prlimit`` that apply ``limits``' kernel resource limits.

    Args:
        limits: the run's limits.
        processes: apply RLIMIT_NPROC (only for a sandbox's own user: for the grader's user
            it would count every process that user runs).
    """
    options = [
        f"--cpu={limits.cpu_time_s}:{limits.cpu_time_s + CPU_KILL_GRACE_S}",
        f"--as={limits.memory_bytes}",
        f"--nofile={limits.open_files}",
        f"--fsize={limits.file_size_bytes}",
        "--core=0",
    ]
    if processes:
        options.append(f"--nproc={limits.processes}")
    return options
