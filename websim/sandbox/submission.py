"""A submission's files as the grader touches them: copied and read, never followed out.

A submission is the student's: any name in it may be a symbolic link (zip files and git keep
them), to another student's folder, the hidden suite or ``/etc/shadow``; a file may be a pipe
that never ends, or a gigabyte. So the grader:

- copies a submission (``copy_submission``) folder by folder without following a link (a link
  is copied as a link, which in the sandbox points at nothing of the grader's), leaving out
  what a student does not hand in (``IGNORED``: a checkout's ``.venv``, ``node_modules``,
  ``.git``; and the patterns of its ``.websimignore``), and refuses one larger than it may
  be, before copying, with its size;
- reads a file of it (``read_own_file``: its ``websim-submission.yaml``) only as a regular
  file of the folder itself, opened without following a link, and of bounded size.
"""

from __future__ import annotations

import contextlib
import fnmatch
import hashlib
import os
import shutil
import stat
from collections.abc import Iterator, Sequence
from pathlib import Path

from websim.sandbox.outcome import size_text

IGNORED = (".venv", "venv", ".git", ".hg", ".svn", "node_modules", "__pycache__",
           ".mypy_cache", ".pytest_cache", ".ruff_cache", ".tox", ".ipynb_checkpoints",
           "grade-out")
"""Names left out of a submission's copy wherever they are (a checkout's environment and
history, caches, ``websim grade``'s default output): the grader gives the controller its
Python with roslibpy and roslib for Node itself."""

IGNORE_FILE = ".websimignore"
"""A submission's own patterns to leave out, one a line (``#`` a comment): a name
(``*.bag``, ``data``) or a path from the submission's folder (``logs/*.csv``)."""

MAX_IGNORE_FILE_BYTES = 64 * 1024
MAX_ENTRIES = 20_000
MAX_DEPTH = 32
"""A submission holds at most this many files, folders and links, this deep."""


class SubmissionRefusedError(ValueError):
    """The submission cannot be graded as handed in (the student's, not the grader's fault)."""


@contextlib.contextmanager
def open_own_file(folder: Path, name: str, max_bytes: int) -> Iterator[int | None]:
    """``folder/name`` open, a regular file of the folder itself; None if absent.

    Yields its descriptor. Opened without following a link (``O_NOFOLLOW``, relative to
    the folder's descriptor) and without blocking (a pipe); closed on leaving.

    Raises:
        SubmissionRefusedError: it is a link, not a regular file, or larger than
            ``max_bytes``.
    """
    try:
        folder_fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except FileNotFoundError:
        yield None
        return
    try:
        fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC,
                     dir_fd=folder_fd)
    except FileNotFoundError:
        fd = None
    except OSError as error:
        if os.path.islink(os.path.join(folder, name)):
            raise SubmissionRefusedError(f"{name} is a symbolic link: hand in the file "
                                         "itself") from None
        raise SubmissionRefusedError(f"{name} cannot be read: {error.strerror}") from None
    finally:
        os.close(folder_fd)
    if fd is None:
        yield None
        return
    try:
        status = os.fstat(fd)
        if not stat.S_ISREG(status.st_mode):
            raise SubmissionRefusedError(f"{name} is not a regular file")
        if status.st_size > max_bytes:
            raise SubmissionRefusedError(f"{name} is {size_text(status.st_size)}, more than "
                                         f"the {size_text(max_bytes)} it may be")
        yield fd
    finally:
        os.close(fd)


def read_own_file(folder: Path, name: str, max_bytes: int) -> bytes | None:
    """The bytes of ``folder/name`` (``open_own_file``), at most ``max_bytes``; None if absent.

    Raises:
        SubmissionRefusedError: as ``open_own_file``.
    """
    with open_own_file(folder, name, max_bytes) as fd:
        if fd is None:
            return None
        data = os.read(fd, max_bytes + 1)
    if len(data) > max_bytes:
        raise SubmissionRefusedError(f"{name} is more than the {size_text(max_bytes)} it "
                                     "may be")
    return data


def ignore_patterns(folder: Path) -> tuple[str, ...]:
    """``IGNORED`` and the patterns of the submission's ``.websimignore``."""
    data = read_own_file(folder, IGNORE_FILE, MAX_IGNORE_FILE_BYTES) or b""
    own = [line.strip() for line in data.decode("utf-8", errors="replace").splitlines()]
    return (*IGNORED, *(line.rstrip("/") for line in own if line and not line.startswith("#")))


def _ignored(relative: str, name: str, patterns: Sequence[str]) -> bool:
    return any(fnmatch.fnmatchcase(relative if "/" in pattern else name, pattern.lstrip("/"))
               for pattern in patterns)


def plan_copy(source: Path, max_bytes: int, *, left_out: Sequence[Path] = ()
              ) -> tuple[list[tuple[str, int]], int]:
    """What ``copy_submission`` copies: (relative path, mode) in order, and their bytes.

    Links are not followed; devices, pipes and sockets are left out, as are the ignored
    names and ``left_out`` (the grader's output folder, should it lie in the submission).

    Raises:
        SubmissionRefusedError: it is larger than ``max_bytes``, holds more than ``MAX_ENTRIES``
            entries, or is deeper than ``MAX_DEPTH`` (the message says how large).
    """
    patterns = ignore_patterns(source)
    skipped = {os.path.realpath(path) for path in left_out}
    entries: list[tuple[str, int]] = []
    total = 0
    pending: list[tuple[str, int]] = [("", 0)]
    while pending:
        relative, depth = pending.pop()
        folder = source / relative if relative else source
        if depth > MAX_DEPTH:
            raise SubmissionRefusedError(f"the submission is more than {MAX_DEPTH} folders deep "
                                    f"({relative})")
        with os.scandir(folder) as listing:
            children = sorted(listing, key=lambda entry: entry.name)
        for child in children:
            path = f"{relative}/{child.name}" if relative else child.name
            if _ignored(path, child.name, patterns) or \
                    (os.path.realpath(child.path) in skipped and not child.is_symlink()):
                continue
            mode = child.stat(follow_symlinks=False).st_mode
            if stat.S_ISDIR(mode):
                pending.append((path, depth + 1))
            elif stat.S_ISREG(mode):
                total += child.stat(follow_symlinks=False).st_size
            elif not stat.S_ISLNK(mode):
                continue
            entries.append((path, mode))
            if len(entries) > MAX_ENTRIES:
                raise SubmissionRefusedError(f"the submission holds more than {MAX_ENTRIES} files "
                                        "and folders")
        if total > max_bytes:
            raise SubmissionRefusedError(
                f"the submission is more than {size_text(total)} (without "
                f"{', '.join(IGNORED[:6])}... and its {IGNORE_FILE}'s patterns), more than "
                f"the {size_text(max_bytes)} a submission may be: leave out what the "
                f"controller does not need (list it in {IGNORE_FILE})")
    entries.sort()
    return entries, total


def copy_submission(source: Path, target: Path, max_bytes: int, *,
                    left_out: Sequence[Path] = ()) -> int:
    """Copy a submission (``plan_copy``'s entries) to ``target``; its bytes.

    Links are copied as links, never followed: a link to another student's folder stays a
    link, to nothing in the sandbox.

    Raises:
        SubmissionRefusedError: as ``plan_copy``, before anything is copied.
    """
    entries, total = plan_copy(source, max_bytes, left_out=left_out)
    target.mkdir(mode=0o700)
    for relative, mode in entries:
        origin, copy = source / relative, target / relative
        if stat.S_ISDIR(mode):
            copy.mkdir(mode=0o700)
        elif stat.S_ISLNK(mode):
            os.symlink(os.readlink(origin), copy)
        else:
            fd = os.open(origin, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
            with os.fdopen(fd, "rb") as reading, open(copy, "wb") as writing:
                if not stat.S_ISREG(os.fstat(reading.fileno()).st_mode):
                    continue  # replaced since it was listed
                shutil.copyfileobj(reading, writing)
            copy.chmod(stat.S_IMODE(mode) & 0o755 | 0o600)
    return total


def submission_digest(source: Path, max_bytes: int) -> str:
    """SHA-256 of what ``copy_submission`` copies: each entry's path, kind and content.

    The same folder gives the same digest wherever it lies (a grade's receipt).

    Raises:
        SubmissionRefusedError: as ``plan_copy``.
    """
    entries, _ = plan_copy(source, max_bytes)
    digest = hashlib.sha256()
    for relative, mode in entries:
        origin = source / relative
        kind = "d" if stat.S_ISDIR(mode) else "l" if stat.S_ISLNK(mode) else "f"
        digest.update(f"{kind} {relative}\0".encode())
        if kind == "l":
            digest.update(os.readlink(origin).encode() + b"\0")
        elif kind == "f":
            fd = os.open(origin, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
            with os.fdopen(fd, "rb") as file:
                while chunk := file.read(1 << 20):
                    digest.update(chunk)
            digest.update(b"\0")
    return digest.hexdigest()
