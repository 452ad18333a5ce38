"""A sandbox per submission: a student's controller and its private simulator, isolated.

Student code is untrusted. ``SubmissionSandbox`` runs one submission's controller so that
it reaches its own simulator and nothing else, cannot read other submissions, the grader's
files or the instructor's tokens, cannot change the recording, the scenario or the score,
and cannot take the machine down; and says how the run ended (``ControllerResult``).

How it is built (bubblewrap, Debian's ``bubblewrap``; util-linux's ``nsenter``, ``setpriv``
and ``prlimit``; libseccomp through ``pyseccomp``; as root, or unprivileged where the kernel
lets users make user namespaces):

1. **The simulator** (``start_server``) runs under ``bwrap --dev-bind / / --unshare-net``:
   this machine's files as they are (it is the grader's code and writes the recording where
   the grader says), in a network namespace of its own whose only interface is a loopback,
   as root without capabilities. bwrap reports the namespace (``--info-fd``); the sandbox
   holds it by a file descriptor (and the process by a pidfd), so a reused pid cannot
   redirect it.
2. **The controller** (``run_controller``) is a second bwrap, started inside that network
   namespace by ``nsenter --net=/proc/self/fd/N`` (the descriptor held in 1): it reaches
   ``ws://127.0.0.1:9090``, its simulator, and no other address; two sandboxes use the same
   ports without meeting. This second bwrap gives it its own process, IPC and host-name
   namespaces (it sees none of the simulator's or the grader's processes, so it can neither
   signal nor trace them), and a file system built from nothing: the system read-only, the
   Python that runs websim read-only, the submission read-only at ``/submission`` and a
   copy of it, writable, as its home ``/home/student``, which like its private ``/tmp`` and
   ``/dev/shm`` is a tmpfs of bounded size (``mounts.py``). In it, ``setpriv`` becomes a
   user of this sandbox's own (``identity.py``; ids 60000-64999,
   one per live sandbox) with no capabilities, no supplementary groups and no new
   privileges (bwrap sets ``no_new_privs``: no setuid program can raise it back).
   Unprivileged (the grader not root), bubblewrap runs as the grader's user in a user
   namespace of its own (``--unshare-user``) in which none may be made
   (``--disable-userns``), and joins the simulator's user and network namespaces. In both,
   a system-call filter (``syscalls.py``, seccomp) refuses new namespaces, mounts, the
   kernel's facilities and exotic sockets.
3. **The limits** (``limits.py``) are set by ``prlimit`` inside the sandbox, before the
   submission is copied home, and inherited by all its processes: CPU time, address space,
   open files, file size and no core dumps per process, and processes and threads per user
   (RLIMIT_NPROC, which does not apply to root: hence the user of its own, whose count is the
   controller's alone; unprivileged, the kernel counts it per user namespace). Where the
   grader may make a cgroup (``cgroups.py``: v1 or v2, as root or delegated) the controller
   runs in one of its own, which bounds the memory of all its processes as the kernel counts
   it (socket buffers included), their number, and their CPU (one process's weight for them
   all, and a quota of ``cpus`` cores: a controller burning every core cannot starve a
   simulator); elsewhere it
   runs at a lower priority (``nice``). Its memory is sampled besides (``watch.py``,
   10 Hz: the cgroup's count, else its processes' resident memory, plus its network's socket
   queues) and over the limit ends the run, as does the wall-clock limit: the sandbox then
   kills bwrap, whose process namespace dies with it (every process in it, whatever session
   or group it made), then any process of that namespace still alive.
4. **Its output** (stdout and stderr together) is read to its end, the last
   ``output_tail_bytes`` kept and the rest counted.

``no_sandbox=True`` (``websim grade --no-sandbox``) runs the controller as the grader's user
with the same per-process limits but RLIMIT_NPROC, on the host's network (the simulator on
free ports), its processes those of its session; results say it ran without a sandbox.
Without bubblewrap, libseccomp, or (not root) user namespaces, ``SubmissionSandbox`` refuses
with the install hint. The submission is copied without following links, its ignored names
left out, and refused before copying when larger than half the home (``submission.py``).
"""

from websim.sandbox.identity import SandboxUnavailableError
from websim.sandbox.limits import SandboxLimits
from websim.sandbox.outcome import ControllerResult, ServerOutcome
from websim.sandbox.sandbox import (
    INSTALL_HINT,
    PRIVATE_HTTP_PORT,
    PRIVATE_WS_PORT,
    SimulatorStartError,
    SubmissionSandbox,
    find_tools,
)
from websim.sandbox.submission import SubmissionRefusedError

__all__ = [
    "INSTALL_HINT",
    "PRIVATE_HTTP_PORT",
    "PRIVATE_WS_PORT",
    "ControllerResult",
    "SandboxLimits",
    "SandboxUnavailableError",
    "ServerOutcome",
    "SimulatorStartError",
    "SubmissionRefusedError",
    "SubmissionSandbox",
    "find_tools",
]
