"""The controller's system-call filter: what no controller needs, refused by the kernel.

A seccomp program (BPF) that bubblewrap loads just before the controller's first program
(``bwrap --seccomp FD``), built with libseccomp (``pyseccomp``, its Python interface through
ctypes; libseccomp itself is Debian's ``libseccomp2``, present wherever systemd is). A deny
list, as Flatpak's: everything a Python, Node or rclpy program does is allowed, and these
fail with an error (never a kill, so that a student sees the reason in the output):

- new namespaces and mounts (``unshare``, ``clone`` with a ``CLONE_NEW*`` flag, ``setns``,
  ``mount`` and the new mount API, ``pivot_root``, ``chroot``): a user namespace inside
  would give the controller every capability in it (bubblewrap's ``--disable-userns`` also
  forbids them; this holds should that ever fail). ``clone3`` answers ENOSYS, as on an old
  kernel, so that C libraries fall back to ``clone``, whose flags a filter can read;
- the kernel's own facilities (``bpf``, ``perf_event_open``, ``userfaultfd``, ``io_uring``,
  modules, ``kexec``, ``reboot``, swap, ``acct``, quotas, the kernel log, keyrings, the
  clock's setting, ``ptrace`` and reading other processes' memory, handles to files by
  number), and typing into a terminal (``TIOCSTI``, ``TIOCLINUX``);
- sockets other than local, IPv4, IPv6 and netlink (the interfaces' addresses, which DDS
  reads): no raw packets, no Bluetooth, no kernel crypto.

Other architectures' system calls (32-bit calls from a 64-bit program) kill the process:
libseccomp's default for a foreign architecture.
"""

from __future__ import annotations

import errno
import functools
import tempfile

from websim.sandbox.identity import SandboxUnavailableError

SECCOMP_HINT = "pip install pyseccomp, and libseccomp (apt-get install libseccomp2)"

REFUSED = (
    "unshare", "setns", "mount", "umount2", "pivot_root", "chroot", "mount_setattr",
    "move_mount", "open_tree", "fsopen", "fsconfig", "fsmount", "fspick",
    "bpf", "perf_event_open", "userfaultfd", "io_uring_setup", "io_uring_enter",
    "io_uring_register", "init_module", "finit_module", "delete_module", "kexec_load",
    "kexec_file_load", "reboot", "swapon", "swapoff", "acct", "quotactl", "quotactl_fd",
    "syslog", "add_key", "request_key", "keyctl", "settimeofday", "clock_settime",
    "clock_adjtime", "adjtimex", "ptrace", "process_vm_readv", "process_vm_writev",
    "name_to_handle_at", "open_by_handle_at", "lookup_dcookie", "uselib", "vhangup",
    "iopl", "ioperm", "sethostname", "setdomainname", "fanotify_init", "kcmp",
)
"""System calls that fail with EPERM (those this kernel's libseccomp does not know are
left out: they do not exist here)."""

CLONE_NEW_FLAGS = {
    "CLONE_NEWTIME": 0x00000080, "CLONE_NEWNS": 0x00020000, "CLONE_NEWCGROUP": 0x02000000,
    "CLONE_NEWUTS": 0x04000000, "CLONE_NEWIPC": 0x08000000, "CLONE_NEWUSER": 0x10000000,
    "CLONE_NEWPID": 0x20000000, "CLONE_NEWNET": 0x40000000,
}
"""``clone`` with any of these fails with EPERM (a process or thread without them runs)."""

ALLOWED_SOCKET_FAMILIES = {"AF_UNIX": 1, "AF_INET": 2, "AF_INET6": 10, "AF_NETLINK": 16}
"""The socket families a controller may open; any other fails with EAFNOSUPPORT."""

REFUSED_IOCTLS = {"TIOCSTI": 0x5412, "TIOCLINUX": 0x541C}


@functools.lru_cache(maxsize=1)
def seccomp_program() -> bytes:
    """The filter as a BPF program, for ``bwrap --seccomp`` (built once per process).

    Raises:
        SandboxUnavailableError: pyseccomp or libseccomp is missing (with the install hint).
    """
    try:
        import pyseccomp as seccomp
    except (ImportError, OSError) as error:  # OSError: the library libseccomp is missing
        raise SandboxUnavailableError(
            f"the sandbox's system-call filter needs libseccomp ({error}): {SECCOMP_HINT}; "
            "or grade without a sandbox (--no-sandbox; only for code you trust)") from None
    program = seccomp.SyscallFilter(seccomp.ALLOW)
    refuse = seccomp.ERRNO(errno.EPERM)
    for name in REFUSED:
        try:
            program.add_rule(refuse, name)
        except (ValueError, RuntimeError, OSError):
            continue  # a call this architecture does not have
    for flag in CLONE_NEW_FLAGS.values():
        program.add_rule(refuse, "clone", seccomp.Arg(0, seccomp.MASKED_EQ, flag, flag))
    program.add_rule(seccomp.ERRNO(errno.ENOSYS), "clone3")
    allowed = sorted(ALLOWED_SOCKET_FAMILIES.values())
    no_family = seccomp.ERRNO(errno.EAFNOSUPPORT)
    for family in range(allowed[-1]):
        if family not in allowed:
            program.add_rule(no_family, "socket", seccomp.Arg(0, seccomp.EQ, family))
    program.add_rule(no_family, "socket", seccomp.Arg(0, seccomp.GT, allowed[-1]))
    for request in REFUSED_IOCTLS.values():
        program.add_rule(refuse, "ioctl", seccomp.Arg(1, seccomp.MASKED_EQ, 0xFFFFFFFF,
                                                      request))
    with tempfile.TemporaryFile() as file:
        program.export_bpf(file)
        file.seek(0)
        return file.read()
