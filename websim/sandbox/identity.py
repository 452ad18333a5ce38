"""A user of its own for each sandbox: who the controller runs as.

A controller runs as an unprivileged user that no other sandbox and no account uses at the
same time, so that the kernel's per-user limit on processes (RLIMIT_NPROC) counts its
processes alone, its processes can neither signal nor trace anyone else's (nor be counted
with them), and the files it may write are its copy of the submission, which that user owns.
"""

from __future__ import annotations

import fcntl
import os
import pwd
import tempfile
from pathlib import Path

from websim.sandbox.watch import usage

FIRST_UID = 60000
UID_COUNT = 5000
"""The users sandboxes run as: 60000-64999, the range Debian's policy keeps for users its
packages allocate globally (few systems use it; one that an account uses is skipped), and
within the 65536 user ids that a rootless container maps."""

USER_NAME = "student"
"""The user's name inside the sandbox (its ``/etc/passwd`` entry: some programs look it up)."""

LEASES_DIR = Path(tempfile.gettempdir()) / "websim-sandbox-uids"
"""One lock file per user id; a sandbox holds its user's lock (``flock``) while it lives, so
two graders on one machine never share a user."""


class SandboxUnavailableError(RuntimeError):
    """The sandbox cannot run here (what is missing, and how to get it, in the message)."""


class UidLease:
    """One sandbox user id, held until ``release``: a free id, its lock held."""

    def __init__(self, leases_dir: Path = LEASES_DIR) -> None:
        """Take the first id that no account, no other lease and no process uses.

        Raises:
            SandboxUnavailableError: every id of the range is in use.
        """
        leases_dir.mkdir(mode=0o700, exist_ok=True)
        owner = leases_dir.stat()
        if owner.st_uid != os.geteuid() or owner.st_mode & 0o022:
            raise SandboxUnavailableError(
                f"{leases_dir} is not this user's own folder (owner {owner.st_uid}, mode "
                f"{owner.st_mode & 0o777:o}): remove it, the sandbox recreates it")
        accounts = {entry.pw_uid for entry in pwd.getpwall()}
        for uid in range(FIRST_UID, FIRST_UID + UID_COUNT):
            if uid in accounts:
                continue
            fd = os.open(leases_dir / f"{uid}.lock", os.O_CREAT | os.O_RDWR | os.O_CLOEXEC,
                         0o600)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                continue
            if usage(uid=uid).pids:  # a process of an earlier grader that outlived it
                os.close(fd)
                continue
            self.uid = uid
            self._fd: int | None = fd
            return
        raise SandboxUnavailableError(
            f"all {UID_COUNT} sandbox users ({FIRST_UID}-{FIRST_UID + UID_COUNT - 1}) are in "
            "use: too many sandboxes at once")

    def release(self) -> None:
        """Let another sandbox take this id (idempotent)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def account_files(uid: int, home: str, into: Path) -> tuple[Path, Path]:
    """This machine's ``/etc/passwd`` and ``/etc/group`` with the sandbox user added.

    Returns the two files' paths (in ``into``), to be bound over the originals.
    """
    passwd, group = into / "passwd", into / "group"
    passwd.write_text(_lines_of("/etc/passwd")
                      + f"{USER_NAME}:x:{uid}:{uid}:websim submission:{home}:/bin/sh\n")
    group.write_text(_lines_of("/etc/group") + f"{USER_NAME}:x:{uid}:\n")
    for path in (passwd, group):
        path.chmod(0o644)  # whatever the grader's umask: every program reads them
    return passwd, group


def _lines_of(path: str) -> str:
    """A file's text ending in a newline (empty if it is missing or empty)."""
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        return ""
    return text if not text or text.endswith("\n") else text + "\n"
