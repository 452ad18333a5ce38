"""What a sandboxed controller sees: its file system and its environment, as bwrap options.

An allow-list, not a deny-list: the sandbox's root is an empty tmpfs into which only the
system's programs and libraries (``SYSTEM_PATHS``, read-only), the Python installation that
runs websim (read-only: the controller's ``roslibpy`` and ``rclpy``), the paths the grader
names (read-only) and the submission (read-only) are bound, and the controller runs in a
writable copy of it in a home of bounded size. Everything else of
the machine (other submissions, the grader's scenarios and output, the recording, tokens,
``/root``, ``/home``, ``/work``, ``/run``, ``/var``, ``/sys``) is absent, not hidden; a
private path that lies inside a path made visible (the grade folder inside a checkout whose
``node_modules`` is shown, say) is covered with an empty, unreadable tmpfs.
"""

from __future__ import annotations

import os
import shlex
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from websim.sandbox.identity import USER_NAME
from websim.sandbox.limits import SandboxLimits

SUBMISSION_DIR = "/submission"
"""The submission as handed in, inside the sandbox (read-only)."""

HOME_DIR = "/home/student"
"""The controller's home and working folder: a copy of the submission, writable, in a tmpfs
of ``SandboxLimits.home_bytes`` (so that what it writes is bounded in all, not only per
file; the machine's disk is never at its mercy)."""

COPY_AND_RUN = 'cp -a "$0" /home/student && cd /home/student && exec "$@"'
"""Run as the sandbox's user before its command (``/bin/sh -c COPY_AND_RUN SUBMISSION_DIR
COMMAND...``): copy the submission home, then become the command. A submission larger than
the home fails here, saying "No space left on device"."""

HOSTNAME = "websim-sandbox"

SYSTEM_PATHS = ("/usr", "/bin", "/sbin", "/lib", "/lib32", "/lib64", "/libx32", "/etc",
                "/opt/ros")
"""The system, read-only (each if it exists; a symbolic link, as merged-/usr makes /bin, is
recreated as one). ``/opt/ros``: a ROS 2 installed from its packages. ``/etc`` has no
secret a user may read (``/etc/shadow`` is root's); its passwd and group gain the sandbox's
user."""

DEFAULT_PATH = "/usr/local/bin:/usr/bin:/bin"

PASSED_ENV = ("ROS_DISTRO", "ROS_VERSION", "ROS_PYTHON_VERSION", "ROS_DOMAIN_ID",
              "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY",
              "RMW_IMPLEMENTATION")
"""The grader's environment variables a controller gets as they are: what ``rclpy`` needs
to find its middleware (a scenario's own values, the run loop's ``ROS_DOMAIN_ID`` and
``use_sim_time``, come in the run's ``env`` and win)."""

PASSED_PATH_LISTS = ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH", "COLCON_PREFIX_PATH",
                     "LD_LIBRARY_PATH", "PYTHONPATH")
"""Path lists a sourced ROS 2 sets; a controller gets the entries it can see (an entry in the
grader's checkout, say, is dropped)."""


def python_paths() -> tuple[str, ...]:
    """The folders of the Python that runs websim: its environment and its installation."""
    prefixes = {sys.prefix, sys.exec_prefix, sys.base_prefix, sys.base_exec_prefix}
    return tuple(sorted({os.path.realpath(prefix) for prefix in prefixes}))


def is_within(path: str, roots: Iterable[str]) -> bool:
    """``path`` is one of ``roots`` or inside one (paths absolute and normalised)."""
    return any(path == root or path.startswith(root.rstrip("/") + "/") for root in roots)


def visible_paths(extra: Sequence[str | os.PathLike[str]]) -> tuple[str, ...]:
    """The paths bound read-only beside the system: Python's and ``extra``, outermost only.

    Raises:
        ValueError: a path of ``extra`` is relative, missing, or the whole file system.
    """
    paths = list(python_paths())
    for given in extra:
        if not os.path.isabs(os.fspath(given)):
            raise ValueError(f"a visible path must be absolute, got {os.fspath(given)!r}")
        path = os.path.normpath(os.fspath(given))
        if path == "/":
            raise ValueError("the whole file system cannot be made visible in the sandbox")
        if not os.path.exists(path):
            raise ValueError(f"a visible path does not exist: {path}")
        paths.append(path)
    outermost: list[str] = []
    for path in sorted(set(paths), key=lambda each: (each.count("/"), each)):
        if not is_within(path, (*SYSTEM_PATHS, *outermost)):
            outermost.append(path)
    return tuple(outermost)


def bwrap_options(*, uid: int, privileged: bool, visible: Sequence[str],
                  hidden: Sequence[str], submission_copy: Path, accounts: tuple[Path, Path],
                  runtime_bin: Path, limits: SandboxLimits, env: Mapping[str, str],
                  own_network: bool) -> list[str]:
    """Bubblewrap's options for a controller (all but the command; given through ``--args``).

    Two ways, one result. As root (``privileged``), bubblewrap runs as root, so that it may
    bind what only root may read (a Python under ``/root``, pyenv's), and keeps the two
    capabilities ``setpriv`` needs to become ``uid`` (which drops them). Otherwise it runs
    as the grader's user, unprivileged, in a user namespace of its own (``--unshare-user``,
    ``uid`` its only user) in which none may be made (``--disable-userns``). In both the
    system-call filter (``syscalls``) refuses new namespaces.

    Args:
        uid: the sandbox's user (and group), inside and out.
        privileged: bubblewrap runs as root (the grader is root).
        visible: the paths bound read-only beside the system (``visible_paths``).
        hidden: private paths of the grader; any that lies in a visible path is covered.
        submission_copy: the copy of the submission its user owns, bound read-only on
            ``SUBMISSION_DIR`` (``COPY_AND_RUN`` copies it to ``HOME_DIR``).
        accounts: the passwd and group files with the sandbox's user (``account_files``).
        runtime_bin: the folder of ``python3`` and ``python`` (``runtime_commands``), bound
            on ``RUNTIME_BIN``.
        limits: the sizes of ``/tmp``, ``/dev/shm`` and the home.
        env: the controller's whole environment.
        own_network: make a network namespace of its own (True when no simulator shares one
            with it).
    """
    if privileged:  # setpriv needs these two to become the sandbox's user; it drops them
        options = ["--cap-add", "CAP_SETUID", "--cap-add", "CAP_SETGID"]
    else:
        options = ["--unshare-user", "--disable-userns", "--uid", str(uid), "--gid", str(uid)]
    options += ["--unshare-pid", "--unshare-ipc", "--unshare-uts", "--hostname", HOSTNAME,
                "--unshare-cgroup-try", "--die-with-parent", "--new-session", "--clearenv"]
    if own_network:
        options.append("--unshare-net")
    for name, value in env.items():
        options += ["--setenv", name, value]
    for path in SYSTEM_PATHS:
        if os.path.islink(path):
            options += ["--symlink", os.readlink(path), path]
        elif os.path.isdir(path):
            options += ["--ro-bind", path, path]
    size = str(limits.tmp_bytes)
    options += ["--proc", "/proc", "--dev", "/dev",
                "--perms", "1777", "--size", size, "--tmpfs", "/tmp",
                "--perms", "1777", "--size", size, "--tmpfs", "/dev/shm",
                "--perms", "1777", "--size", str(limits.home_bytes), "--tmpfs",
                os.path.dirname(HOME_DIR)]
    bound: list[str] = list(SYSTEM_PATHS)  # binds: what is in them exists
    folders = {"/tmp", "/dev", "/dev/shm", "/home"}  # folders that exist (bwrap's are 0700)
    for path in (*visible, RUNTIME_BIN):
        source = os.path.realpath(path) if path != RUNTIME_BIN else str(runtime_bin)
        for target in dict.fromkeys((path, source) if path != RUNTIME_BIN else (path,)):
            for parent in map(str, reversed(Path(target).parents[:-1])):  # outermost first
                if parent not in folders and not is_within(parent, bound):
                    options += ["--perms", "0755", "--dir", parent]
                    folders.add(parent)
            options += ["--ro-bind", source, target]
            bound.append(target)
    for path in sorted({os.path.realpath(each) for each in hidden}):
        if is_within(path, (*visible, *SYSTEM_PATHS)) and os.path.exists(path):
            if os.path.isdir(path):
                options += ["--perms", "0000", "--size", "4096", "--tmpfs", path]
            else:
                options += ["--ro-bind", "/dev/null", path]
    passwd, group = accounts
    options += ["--ro-bind", str(passwd), "/etc/passwd", "--ro-bind", str(group), "/etc/group",
                "--ro-bind", str(submission_copy), SUBMISSION_DIR,
                "--chdir", os.path.dirname(HOME_DIR)]
    return options


RUNTIME_BIN = "/websim/bin"
"""Inside the sandbox: ``python3`` and ``python``, the Python that runs websim (first on the
controller's ``PATH``): the runtime the docs promise, roslibpy included, however websim was
installed (a venv, pipx), not whichever ``python3`` the system has."""

RUNTIME_COMMANDS = ("python3", "python")


def runtime_commands(folder: Path, python: str = sys.executable) -> Path:
    """Write ``folder``'s ``python3`` and ``python``: each runs ``python`` (websim's).

    A script, not a link: a venv's Python finds its packages from the path it was started
    by (its ``pyvenv.cfg`` beside it), which a link elsewhere would lose.
    """
    folder.mkdir(parents=True, exist_ok=True)
    folder.chmod(0o755)  # whatever the grader's umask: the sandbox's user runs them
    for name in RUNTIME_COMMANDS:
        script = folder / name
        script.write_text(f"#!/bin/sh\nexec {shlex.quote(python)} \"$@\"\n")
        script.chmod(0o755)
    return folder


def command_in_home(command: Sequence[str]) -> list[str]:
    """``command``, preceded by the copy of the submission into its home (``COPY_AND_RUN``)."""
    return ["/bin/sh", "-c", COPY_AND_RUN, SUBMISSION_DIR, *command]


def controller_environment(run_env: Mapping[str, str], *, home: str, visible: Sequence[str],
                           sandboxed: bool, runtime_bin: str | None = None,
                           node_path: Sequence[str] = (),
                           grader_env: Mapping[str, str] = os.environ) -> dict[str, str]:
    """A controller's whole environment: nothing of the grader's but what it needs.

    ``PATH`` (``runtime_bin`` first: websim's Python as ``python3``; then its entries the
    controller can see), ``NODE_PATH`` (``node_path``: roslib for Node), ``HOME`` (its copy
    of the submission),
    ``TMPDIR``, ``LANG``, unbuffered Python output (so its last
    lines reach the report when it is stopped), the user's name, ROS 2's variables
    (``PASSED_ENV``, ``PASSED_PATH_LISTS``), then ``run_env`` (``WEBSIM_URL``,
    ``WEBSIM_<NAME>``...), which wins.

    Raises:
        ValueError: a name of ``run_env`` is empty or holds ``=``, or a value holds NUL.
    """
    seen = (*SYSTEM_PATHS, *visible)

    def visible_entries(value: str) -> str:
        if not sandboxed:
            return value
        return ":".join(entry for entry in value.split(":")
                        if entry and os.path.isabs(entry)
                        and is_within(os.path.normpath(entry), seen))

    path = visible_entries(grader_env.get("PATH", "")) or DEFAULT_PATH
    env = {
        "PATH": path if runtime_bin is None else f"{runtime_bin}:{path}",
        "HOME": home,
        "TMPDIR": "/tmp" if sandboxed else grader_env.get("TMPDIR", "/tmp"),
        "LANG": "C.UTF-8",
        "PYTHONUNBUFFERED": "1",
        "USER": USER_NAME if sandboxed else grader_env.get("USER", USER_NAME),
        "LOGNAME": USER_NAME if sandboxed else grader_env.get("LOGNAME", USER_NAME),
    }
    if node_path:
        env["NODE_PATH"] = ":".join(node_path)
    for name in PASSED_ENV:
        if name in grader_env:
            env[name] = grader_env[name]
    for name in PASSED_PATH_LISTS:
        entries = visible_entries(grader_env.get(name, ""))
        if entries:
            env[name] = entries
    for name, value in run_env.items():
        if not name or "=" in name or "\0" in name or "\0" in value:
            raise ValueError(f"invalid environment variable for the controller: {name!r}")
        env[name] = value
    return env
