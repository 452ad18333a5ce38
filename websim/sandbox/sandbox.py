"""One submission's sandbox: its private simulator, its controller, and how the run ended."""

from __future__ import annotations

import contextlib
import functools
import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType

from websim.sandbox.cgroups import Cgroup, enter_then
from websim.sandbox.identity import SandboxUnavailableError, UidLease, account_files
from websim.sandbox.limits import SandboxLimits, prlimit_arguments
from websim.sandbox.mounts import (
    DEFAULT_PATH,
    HOME_DIR,
    RUNTIME_BIN,
    bwrap_options,
    command_in_home,
    controller_environment,
    runtime_commands,
)
from websim.sandbox.mounts import visible_paths as outermost_visible_paths
from websim.sandbox.outcome import ControllerResult, Observed, ServerOutcome
from websim.sandbox.submission import copy_submission
from websim.sandbox.syscalls import seccomp_program
from websim.sandbox.watch import SAMPLE_PERIOD_S, OutputTail, kill_all, socket_bytes, usage

INSTALL_HINT = "apt-get install bubblewrap"

READY_TEXT = "websim: ready"
"""What ``websim serve`` prints once it listens (``start_server``'s default)."""

PRIVATE_WS_PORT = 9090
PRIVATE_HTTP_PORT = 8080
"""The simulator's ports inside a sandbox: the same in every one (each has its own network),
and websim's defaults, so a controller written for ``websim serve`` finds them."""

SERVER_READY_TIMEOUT_S = 60.0
SERVER_STOP_TIMEOUT_S = 10.0
"""How long the simulator may take to start (a loaded machine, a cold import), and to stop
on SIGTERM (writing its recording's end) before it is killed."""

OUTPUT_DRAIN_S = 5.0
"""How long the last output may take to arrive once a process has ended."""

SERVER_OUTPUT_TAIL_BYTES = 64 * 1024

SANDBOXED_SERVER_DDS = {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4",
                        "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
"""The sandboxed simulator's DDS (``--ros``): over UDP only, discovering over its namespace's
network (its loopback: nothing else is there). Fast DDS would otherwise send to an rclpy
controller it takes for a neighbour through shared memory, which the two do not share
(each has a private ``/dev/shm``), and nothing would arrive; with discovery on LOCALHOST
(websim serve's default) it uses shared memory whatever FASTDDS_BUILTIN_TRANSPORTS says.
A controller's own settings do not matter: it talks to a simulator that speaks only UDP."""


class SimulatorStartError(RuntimeError):
    """The private simulator did not start (the grader's fault, not the submission's)."""


def find_tools(*, sandboxed: bool, bwrap: str | None = None) -> dict[str, str]:
    """The programs the sandbox runs, by name, as paths.

    Args:
        sandboxed: the sandbox is wanted (else only ``prlimit`` is).
        bwrap: bubblewrap's path (default: ``bwrap`` on ``PATH``).

    Raises:
        SandboxUnavailableError: one is missing, or this kernel lets no user namespace be
            made (the message says how to get it, or ``--no-sandbox``).
    """
    tools: dict[str, str] = {}
    if sandboxed:
        found = bwrap or shutil.which("bwrap")
        if found is None or not os.access(found, os.X_OK):
            raise SandboxUnavailableError(
                "bubblewrap (bwrap) is not installed, so submissions cannot be sandboxed: "
                f"install it ({INSTALL_HINT}), or grade without a sandbox (--no-sandbox; "
                "only for code you trust)")
        tools["bwrap"] = found
    names = ("prlimit", "nsenter", "nice") + (("setpriv",) if os.geteuid() == 0 else ())
    for name in names if sandboxed else ("prlimit",):
        found = shutil.which(name)
        if found is None:
            raise SandboxUnavailableError(
                f"{name} is not installed (it is part of util-linux and coreutils: apt-get "
                "install util-linux coreutils)")
        tools[name] = found
    if sandboxed:
        seccomp_program()  # raises with the hint when libseccomp is missing
        if os.geteuid() != 0:
            _check_user_namespaces(tools["bwrap"])
    return tools


USERNS_HINT = (
    "this kernel lets no unprivileged user make a user namespace, which the sandbox needs "
    "(bubblewrap runs as the sandbox's user, in a user namespace of its own). Allow them "
    "(Debian: sysctl kernel.unprivileged_userns_clone=1; Ubuntu 24.04: sysctl "
    "kernel.apparmor_restrict_unprivileged_userns=0, or an AppArmor profile for bwrap; "
    "everywhere: user.max_user_namespaces > 0), grade in a container or CI runner where "
    "they are allowed, or without a sandbox (--no-sandbox; only for code you trust). "
    "docs/assignments.md, \"Grading on your own machine\"")


@functools.lru_cache(maxsize=4)
def _check_user_namespaces(bwrap: str) -> None:
    """Raise unless bubblewrap can make its user namespace here (unprivileged)."""
    command = [bwrap, "--unshare-user", "--disable-userns", "--ro-bind", "/", "/", "--",
               "/bin/true"]
    probe = subprocess.run(command, stdin=subprocess.DEVNULL, capture_output=True,
                           timeout=60, check=False)
    if probe.returncode != 0:
        said = probe.stderr.decode("utf-8", errors="replace").strip()
        raise SandboxUnavailableError(f"{USERNS_HINT} (bwrap said: {said[-300:]})")


class SubmissionSandbox:
    """One submission's sandbox: a private simulator and the controller, isolated together.

    Use as a context manager; then ``start_server`` (the private ``websim serve``), then
    ``run_controller`` (which returns how it ended), then ``stop_server``. See the
    package's docstring for what it isolates and how.
    """

    def __init__(self, submission_dir: str | os.PathLike[str], *,
                 limits: SandboxLimits | None = None,
                 visible_paths: Sequence[str | os.PathLike[str]] = (),
                 hidden_paths: Sequence[str | os.PathLike[str]] = (),
                 no_sandbox: bool = False, bwrap: str | None = None,
                 node_path: Sequence[str | os.PathLike[str]] = ()) -> None:
        """Check that the sandbox can run here (nothing runs until ``__enter__``).

        Args:
            submission_dir: the student's folder; the controller gets a writable copy.
            limits: the controller's limits (default ``SandboxLimits()``).
            visible_paths: absolute paths the controller may read besides the system and
                the Python that runs websim (a ``node_modules`` the course provides).
            hidden_paths: the grader's private paths (the grade output, the submissions'
                folder, the scenarios): covered if they lie inside a visible path.
            no_sandbox: run the controller without isolation, as the grader's user on the
                grader's network (``--no-sandbox``; results say so).
            bwrap: bubblewrap's path (default: ``bwrap`` on ``PATH``).
            node_path: folders of Node modules the controller may ``require`` (roslib):
                made visible and its ``NODE_PATH``.

        Raises:
            SandboxUnavailableError: a tool is missing, or user namespaces are not allowed
                here (and not ``no_sandbox``).
            ValueError: the submission folder or a visible path does not exist.
        """
        self.submission_dir = Path(submission_dir).resolve()
        if not self.submission_dir.is_dir():
            raise ValueError(f"the submission is not a folder: {self.submission_dir}")
        self.limits = limits or SandboxLimits()
        self.sandboxed = not no_sandbox
        self._tools = find_tools(sandboxed=self.sandboxed, bwrap=bwrap)
        self._node_path = tuple(os.path.normpath(os.fspath(path)) for path in node_path)
        self._visible = outermost_visible_paths([*visible_paths, *self._node_path]) \
            if self.sandboxed else ()
        self._privileged = os.geteuid() == 0
        self._hidden = (*(os.fspath(path) for path in hidden_paths), str(self.submission_dir))
        self._workspace: Path | None = None
        self._lease: UidLease | None = None
        self._accounts: tuple[Path, Path] | None = None
        self._server: subprocess.Popen[bytes] | None = None
        self._server_output: OutputTail | None = None
        self._server_pidfd: int | None = None
        self._netns_fd: int | None = None
        self._userns_fd: int | None = None
        self._server_child: int | None = None
        """The simulator's process inside its network namespace (bwrap's child)."""
        self._uid: int | None = None
        self._cgroup: Cgroup | None = None
        self.copied_bytes = 0
        self.ws_port, self.http_port = PRIVATE_WS_PORT, PRIVATE_HTTP_PORT

    # --- lifetime ---------------------------------------------------------------------

    def __enter__(self) -> SubmissionSandbox:
        """Copy the submission and, in the sandbox, take a user for it.

        Raises:
            SubmissionRefusedError: the submission is larger than half the controller's home
                (``SandboxLimits.home_bytes``), or too many files, or too deep.
        """
        self._workspace = Path(tempfile.mkdtemp(prefix="websim-sandbox-"))
        try:
            self.copied_bytes = copy_submission(
                self.submission_dir, self.submission_copy, self.limits.home_bytes // 2,
                left_out=[Path(path) for path in self._hidden[:-1]])
            runtime_commands(self._workspace / "bin")
            if self.sandboxed:
                if self._privileged:
                    self._lease = UidLease()
                    self._uid = self._lease.uid
                    own_tree(self.submission_copy, self._uid)
                else:
                    self._uid = os.getuid()
                self._accounts = account_files(self._uid, HOME_DIR, self._workspace)
                self._cgroup = Cgroup.open(memory_bytes=self.limits.memory_bytes,
                                           processes=self.limits.processes,
                                           cpus=self.limits.cpus)
            else:
                self.ws_port = self.http_port = free_port()
                while self.http_port == self.ws_port:
                    self.http_port = free_port()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Stop the simulator, give the user back, delete the copy (idempotent)."""
        self.stop_server()
        if self._cgroup is not None:
            self._cgroup.remove()
            self._cgroup = None
        if self._lease is not None:
            self._lease.release()
            self._lease = None
        if self._workspace is not None:
            shutil.rmtree(self._workspace, ignore_errors=True)
            self._workspace = None

    @property
    def submission_copy(self) -> Path:
        """The copy of the submission on this machine.

        In the sandbox, its user's, read-only at ``/submission`` inside and copied to its
        home; without the sandbox, where the controller runs.
        """
        if self._workspace is None:
            raise RuntimeError("the sandbox is not open: use it in a with block")
        return self._workspace / "submission"

    @property
    def uid(self) -> int | None:
        """The user the controller runs as (None without the sandbox, or before it opens).

        As root, a user of its own (``UidLease``); otherwise the grader's own user, in a
        user namespace of the sandbox's own.
        """
        return self._uid

    @property
    def websim_url(self) -> str:
        """The simulator's WebSocket address, as the controller reaches it."""
        return f"ws://127.0.0.1:{self.ws_port}"

    @property
    def isolation(self) -> str:
        """One line: what isolates the controller (for reports)."""
        if not self.sandboxed:
            return ("none (--no-sandbox): the controller ran as the grader's user, with the "
                    "grader's files and network")
        network = ("its own network namespace, shared with its simulator"
                   if self._netns_fd is not None else "its own network namespace")
        user = (f"user {self.uid} of its own" if self._privileged
                else f"the grader's user {self.uid}, in a user namespace of its own")
        bounds = (f"memory, processes and CPU share bounded by its {self._cgroup.bounds}"
                  if self._cgroup is not None else
                  "memory sampled (resident memory and socket queues; no cgroup could be "
                  "made here), processes bounded by their resource limit")
        return (f"bubblewrap: {user}; no user namespace may be made in it; a system-call "
                f"filter (seccomp); {network} (loopback only); its own process, "
                "IPC and host-name namespaces; the system read-only; writable only its home "
                f"(a copy of the submission), /tmp and /dev/shm, each of bounded size; {bounds}")

    # --- the simulator ----------------------------------------------------------------

    def start_server(self, argv: Sequence[str], *, env: Mapping[str, str] | None = None,
                     ready: str = READY_TEXT,
                     timeout_s: float = SERVER_READY_TIMEOUT_S) -> None:
        """Start the private simulator and wait until it prints ``ready``.

        In the sandbox it runs in a network namespace of its own (bwrap ``--unshare-net``:
        only a loopback), with this machine's files as they are (it is the grader's code,
        writing the recording where the grader says) but a private ``/dev/shm``, as root
        without capabilities, its DDS set to reach the controller
        (``SANDBOXED_SERVER_DDS``); the controller joins that namespace. It should listen
        on ``ws_port`` and ``http_port``.

        Args:
            argv: its command (``python -m websim.cli serve --ws-port ...``).
            env: its environment (default: the grader's).
            ready: a text it prints once it listens.
            timeout_s: how long it may take.

        Raises:
            SimulatorStartError: it exited or did not print ``ready`` in time (with its output).
        """
        if self._workspace is None:
            raise RuntimeError("the sandbox is not open: use it in a with block")
        if self._server is not None:
            raise RuntimeError("this sandbox's simulator is already running")
        server_env = dict(os.environ if env is None else env)
        if self.sandboxed:
            server_env.pop("ROS_LOCALHOST_ONLY", None)
            server_env.update(SANDBOXED_SERVER_DDS)
            info_read, info_write = os.pipe()
            userns = [] if self._privileged else ["--unshare-user"]
            command = [self._tools["bwrap"], *userns, "--dev-bind", "/", "/", "--unshare-net",
                       "--tmpfs", "/dev/shm", "--die-with-parent", "--info-fd",
                       str(info_write), "--", *argv]
            try:
                self._server = subprocess.Popen(
                    command, pass_fds=(info_write,), stdin=subprocess.DEVNULL,
                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=server_env,
                    start_new_session=True)
            finally:
                os.close(info_write)
            self._server_output = self._read_server_output(ready)
            with os.fdopen(info_read, "rb") as info_file:
                info_text = info_file.read()  # bwrap closes it once the namespace exists
            if info_text:
                self._join_namespace(json.loads(info_text))
        else:
            self._server = subprocess.Popen(
                list(argv), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, env=server_env, start_new_session=True)
            self._server_output = self._read_server_output(ready)
        deadline = time.monotonic() + timeout_s
        output = self._server_output
        while not output.ready.wait(SAMPLE_PERIOD_S):
            exited = self._server.poll() is not None
            if exited or time.monotonic() > deadline:
                outcome = self.stop_server()
                why = (f"exited with code {outcome.exit_code}" if exited
                       else f"did not print {ready!r} within {timeout_s:g} s")
                raise SimulatorStartError(f"the simulator {why} ({' '.join(argv)}); its output "
                                      f"ended with:\n{outcome.output_tail}")

    def _read_server_output(self, ready: str) -> OutputTail:
        assert self._server is not None and self._server.stdout is not None
        return OutputTail(self._server.stdout, SERVER_OUTPUT_TAIL_BYTES, ready=ready,
                          name="websim-sandbox-server")

    def _join_namespace(self, info: Mapping[str, int]) -> None:
        """Hold the simulator's process and network namespace by file descriptors.

        Descriptors are immune to its pid being reused once it has gone.
        """
        pid = info["child-pid"]
        self._server_pidfd = os.pidfd_open(pid)
        netns_fd = os.open(f"/proc/{pid}/ns/net", os.O_RDONLY | os.O_CLOEXEC)
        if os.fstat(netns_fd).st_ino != info["net-namespace"]:
            os.close(netns_fd)  # the pid was reused before this opened it: not its namespace
            raise SimulatorStartError("the simulator's process ended before its network "
                                  "namespace could be joined")
        self._netns_fd = netns_fd
        self._server_child = pid
        if not self._privileged:  # its network namespace belongs to its user namespace
            self._userns_fd = os.open(f"/proc/{pid}/ns/user", os.O_RDONLY | os.O_CLOEXEC)

    def stop_server(self, *, timeout_s: float = SERVER_STOP_TIMEOUT_S,
                    ending: bool = False) -> ServerOutcome:
        """Stop the simulator (SIGTERM, then SIGKILL after ``timeout_s``); how it ended.

        ``ending``: the simulator is stopping on its own (its run is over, and it is writing
        its record and closing its recording): it gets ``timeout_s`` to exit before the
        SIGTERM, which would otherwise cut those writes short. Idempotent: without a
        simulator, an outcome with no exit code.
        """
        server, output = self._server, self._server_output
        if server is None or output is None:
            return ServerOutcome(None, "")
        if ending:
            with contextlib.suppress(subprocess.TimeoutExpired):
                server.wait(timeout_s)
        if server.poll() is None:
            try:
                if self._server_pidfd is not None:
                    signal.pidfd_send_signal(self._server_pidfd, signal.SIGTERM)
                else:
                    server.send_signal(signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                server.wait(timeout_s)
            except subprocess.TimeoutExpired:
                _kill_group(server.pid)
                server.wait()
        if not self.sandboxed:
            _kill_group(server.pid)  # what it left behind in its group
        output.join(OUTPUT_DRAIN_S)
        for fd in (self._server_pidfd, self._netns_fd, self._userns_fd):
            if fd is not None:
                os.close(fd)
        self._server = self._server_output = None
        self._server_pidfd = self._netns_fd = self._userns_fd = self._server_child = None
        return ServerOutcome(server.returncode,
                             output.tail.decode("utf-8", errors="replace"))

    # --- the controller ---------------------------------------------------------------

    def run_controller(self, command: Sequence[str], *,
                       env: Mapping[str, str] | None = None) -> ControllerResult:
        """Run the student's controller; how it ended.

        It runs until it exits, a limit stops it, or its simulator exits.

        Args:
            command: its command, run in its copy of the submission (``python3 main.py``).
            env: its variables (``WEBSIM_<NAME>``, a ROS domain...), over the few it gets
                (``mounts.controller_environment``); ``WEBSIM_URL`` defaults to
                ``websim_url``.
        """
        if self._workspace is None:
            raise RuntimeError("the sandbox is not open: use it in a with block")
        if not command:
            raise ValueError("the controller's command is empty")
        run_env = {"WEBSIM_URL": self.websim_url, **(env or {})}
        limits = self.limits
        home = HOME_DIR if self.sandboxed else str(self.submission_copy)
        runtime_bin = RUNTIME_BIN if self.sandboxed else str(self._workspace / "bin")
        full_env = controller_environment(run_env, home=home, visible=self._visible,
                                          sandboxed=self.sandboxed, runtime_bin=runtime_bin,
                                          node_path=self._node_path)
        prlimit = [self._tools["prlimit"],
                   *prlimit_arguments(limits, processes=self.sandboxed), "--"]
        pass_fds: list[int] = []
        info_read: int | None = None
        match: dict[str, int]
        if self.sandboxed:
            argv, info_read = self._sandboxed_argv(command, full_env, prlimit, pass_fds)
            popen_env, cwd = {"PATH": DEFAULT_PATH}, str(self._workspace)
            match = {"uid": self._uid} if self._privileged and self._uid is not None else {}
        else:
            argv, popen_env, cwd = [*prlimit, *command], full_env, str(self.submission_copy)
        started = time.monotonic()
        try:
            process = subprocess.Popen(
                argv, pass_fds=pass_fds, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, env=popen_env, cwd=cwd, start_new_session=True)
        finally:
            for fd in pass_fds:
                if fd not in (self._netns_fd, self._userns_fd):
                    os.close(fd)
        if info_read is not None:
            with os.fdopen(info_read, "rb") as info_file:
                info_text = info_file.read()  # bwrap closes it once its namespaces exist
            if info_text:
                match = {"pidns": int(json.loads(info_text)["pid-namespace"])}
        if not self.sandboxed:
            match = {"session": process.pid}
        assert process.stdout is not None
        output = OutputTail(process.stdout, limits.output_tail_bytes,
                            name="websim-sandbox-controller")
        try:
            observed = self._watch(process, output, match, started)
        except BaseException:  # interrupted (Ctrl+C): leave nothing running
            if process.returncode is None:
                self._stop_controller(process, match)
                process.wait()
            raise
        return ControllerResult.build(observed, sandboxed=self.sandboxed,
                                      isolation=self.isolation, command=tuple(command),
                                      limits=limits)

    def _sandboxed_argv(self, command: Sequence[str], env: Mapping[str, str],
                        prlimit: list[str], pass_fds: list[int]) -> tuple[list[str], int]:
        """The controller's command line in the sandbox, and bwrap's ``--info-fd`` to read.

        From the outside in: enter its cgroup; join its simulator's network namespace
        (``nsenter``; unprivileged, its user namespace too); without a cgroup's CPU share,
        lower its CPU priority (``nice``); bubblewrap, its options and its system-call
        filter by file descriptors; inside, as root, become its user (``setpriv``); the
        resource limits (``prlimit``: inside, so that unprivileged the process limit counts
        the processes of its user namespace only); the copy of the submission home; the
        command. Every descriptor opened goes into ``pass_fds``.
        """
        assert self._workspace is not None and self._accounts is not None
        assert self._uid is not None
        uid = self._uid
        options = bwrap_options(uid=uid, privileged=self._privileged, visible=self._visible,
                                hidden=self._hidden, submission_copy=self.submission_copy,
                                accounts=self._accounts, runtime_bin=self._workspace / "bin",
                                limits=self.limits, env=env,
                                own_network=self._netns_fd is None)
        seccomp_read, seccomp_write = os.pipe()
        pass_fds.append(seccomp_read)
        try:
            os.write(seccomp_write, seccomp_program())  # within a pipe's buffer
        finally:
            os.close(seccomp_write)
        info_read, info_write = os.pipe()
        pass_fds.append(info_write)
        options += ["--seccomp", str(seccomp_read), "--info-fd", str(info_write)]
        args_file = self._workspace / "bwrap-args"
        args_file.write_bytes(b"".join(option.encode() + b"\0" for option in options))
        args_fd = os.open(args_file, os.O_RDONLY | os.O_CLOEXEC)
        pass_fds.append(args_fd)
        inside = [*prlimit, *command_in_home(command)]
        if self._privileged:
            inside = [self._tools["setpriv"], f"--reuid={uid}", f"--regid={uid}",
                      "--clear-groups", "--inh-caps=-all", "--bounding-set=-all", "--",
                      *inside]
        argv = [self._tools["bwrap"], "--args", str(args_fd), "--", *inside]
        if self._cgroup is None or "cpu" not in self._cgroup.folders:
            argv = [self._tools["nice"], "-n", str(NICENESS), *argv]
        if self._netns_fd is not None:
            pass_fds.append(self._netns_fd)
            enter = [f"--net=/proc/self/fd/{self._netns_fd}"]
            if self._userns_fd is not None:
                pass_fds.append(self._userns_fd)
                enter = [f"--user=/proc/self/fd/{self._userns_fd}", "--preserve-credentials",
                         *enter]
            argv = [self._tools["nsenter"], *enter, "--", *argv]
        return enter_then(self._cgroup, argv), info_read

    def _watch(self, process: subprocess.Popen[bytes], output: OutputTail,
               match: Mapping[str, int], started: float) -> Observed:
        """Wait for the controller, sampling its processes; stop it if it must stop."""
        limits = self.limits
        deadline = started + limits.wall_time_s
        peak_tasks = peak_memory = 0
        stopped_by: str | None = None
        cgroup = self._cgroup
        while True:
            pid, status = os.waitpid(process.pid, os.WNOHANG)
            if pid:
                break
            tasks, memory = self._sample(match)
            peak_tasks, peak_memory = max(peak_tasks, tasks), max(peak_memory, memory)
            if memory > limits.memory_bytes or (cgroup is not None and cgroup.oom_kills()):
                stopped_by = "memory"
            elif time.monotonic() >= deadline:
                stopped_by = "wall_time"
            elif self._server is not None and self._server.poll() is not None:
                stopped_by = "server_exit"
            if stopped_by is not None:
                self._stop_controller(process, match)
                _, status = os.waitpid(process.pid, 0)
                break
            time.sleep(SAMPLE_PERIOD_S)
        ended = time.monotonic()
        process.returncode = os.waitstatus_to_exitcode(status)
        if cgroup is not None:
            peak_memory = max(peak_memory, cgroup.peak_memory_bytes())
        # What it left behind: its session's processes without the sandbox; in it, none
        # (its process namespace ended with it), unless the kernel is slow to say so.
        if match:
            kill_all(**match)
        output.join(OUTPUT_DRAIN_S)
        return Observed(
            exit_status=process.returncode, by_signal_code=self.sandboxed,
            stopped_by=stopped_by, wall_time_s=ended - started,
            peak_tasks=peak_tasks if self.sandboxed else None,
            peak_memory_bytes=peak_memory, output_tail=output.tail,
            output_bytes=output.total_bytes,
            oom_killed=cgroup is not None and cgroup.oom_kills() > 0)

    def _sample(self, match: Mapping[str, int]) -> tuple[int, int]:
        """The controller's processes and threads now, and its memory (bytes).

        With a cgroup, its counts (v2: socket buffers included; v1: TCP's buffers under
        their own count, added, and its network's UDP queues); no scan of ``/proc``. Else its
        processes' resident memory and its network namespace's TCP and UDP queues.
        """
        cgroup = self._cgroup
        if cgroup is not None:
            udp = 0
            if not cgroup.v2 and self._server_child is not None:
                udp = socket_bytes(self._server_child, ("udp", "udp6"))
            return cgroup.tasks(), cgroup.memory_bytes() + udp
        now = usage(**match) if match else None
        if now is None:
            return 0, 0
        sockets = 0
        if self.sandboxed:
            probe = now.pids[0] if now.pids else self._server_child
            sockets = socket_bytes(probe) if probe is not None else 0
        return now.tasks, now.rss_bytes + sockets

    def _stop_controller(self, process: subprocess.Popen[bytes],
                         match: Mapping[str, int]) -> None:
        """Kill every process of the controller, ``process`` not yet waited for.

        (Not waited for, its pid is still its own.) In the sandbox, killing bubblewrap ends
        its process namespace (``--die-with-parent``), whose end kills every process in it;
        its namespace's (and cgroup's) processes are then killed too, should any remain.
        Without it, its process group, then its session.
        """
        if self.sandboxed:
            with contextlib.suppress(ProcessLookupError):
                os.kill(process.pid, signal.SIGKILL)
            if self._cgroup is not None:
                for pid in self._cgroup.pids():
                    with contextlib.suppress(ProcessLookupError, PermissionError):
                        os.kill(pid, signal.SIGKILL)
        else:
            _kill_group(process.pid)
        if match:
            kill_all(**match)


NICENESS = 10
"""Without a cgroup's CPU share: the controller's processes' niceness (a tenth of an
ordinary process's CPU share each), so that it cannot starve its simulator."""


def _kill_group(pgid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, signal.SIGKILL)


def free_port() -> int:
    """A TCP port free on this machine's loopback now (for a simulator without sandbox)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def own_tree(root: Path, uid: int) -> None:
    """Give ``root`` and everything in it to ``uid`` (user and group), links not followed."""
    os.lchown(root, uid, uid)
    for folder, folders, files in os.walk(root):
        for name in (*folders, *files):
            os.lchown(os.path.join(folder, name), uid, uid)
