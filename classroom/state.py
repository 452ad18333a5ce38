"""A class's state on disk: what a restart of the same command brings back.

One SQLite file (the standard library's ``sqlite3``, write-ahead log) per class server
(``websim serve --state FILE``; a worker of a class spread over several processes keeps its
own): the class secret the robots' tokens derive from, the open class's enrolments (and
whether the student who enrolled a name has been handed its token), and each robot's runtime
parameters (mode, payload...), paused flag and pose, saved every ``SAVE_INTERVAL_S`` and at
shutdown. ``kill -9`` loses at most that interval. Besides, each student's program as the Code
panel saved it (a few recent versions per language, ``save_code``) and their last submission
with its reports (``save_submission``), written when they change.

The file is held for the server's life (``locking_mode=EXCLUSIVE``): a second server on the
same file is refused. A file of another class, of a newer schema, locked or corrupt is
refused with the reason (``ConfigError``), never overwritten: ``--fresh`` starts over.
"""

from __future__ import annotations

import hashlib
import json
import os
import secrets
import sqlite3
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from physics import ConfigError

SCHEMA_VERSION = 1
"""The layout this code writes; a file of a newer one is refused (an older websim would lose
what it does not know)."""

SAVE_INTERVAL_S = 2.0
"""How often the robots' state is saved (s): what ``kill -9`` may lose at most."""

SECRET_BYTES = 32
"""Random bytes of a class secret."""

ROSTER_DIGEST_CHARS = 12
"""Hex digits of a roster path's SHA-256 in a worker's state file name (48 bits)."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS enrolments (
    name TEXT PRIMARY KEY, claimed INTEGER NOT NULL DEFAULT 0);
CREATE TABLE IF NOT EXISTS robots (name TEXT PRIMARY KEY, state TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS code (
    name TEXT NOT NULL, version INTEGER NOT NULL, language TEXT NOT NULL,
    saved_at REAL NOT NULL, reason TEXT NOT NULL, text TEXT NOT NULL,
    PRIMARY KEY (name, version));
CREATE TABLE IF NOT EXISTS submissions (name TEXT PRIMARY KEY, submission TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS reports (
    name TEXT NOT NULL, scenario TEXT NOT NULL, html TEXT NOT NULL,
    PRIMARY KEY (name, scenario));
"""

TABLES = ("meta", "enrolments", "robots", "code", "submissions", "reports")

AUTOSAVE = "autosave"
"""A save the page makes by itself while the student types: it replaces the newest version
if that was one too, so typing does not push the versions a student asked for out."""


def default_state_path(class_spec: str, worker_port: int | None = None) -> Path:
    """Where ``--state`` is by default.

    Beside the roster (``ROSTER.websim-state.sqlite``), or, for ``--class N`` and for a
    worker (one file each, named by its WebSocket port), in the user's data directory
    (``$XDG_DATA_HOME/websim``, else ``~/.local/share/websim``). A worker's file is named by
    its roster's name and a digest of the roster's absolute path too: two rosters of one name
    in two folders are two classes (``class_identity``), never one file.
    """
    data = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "websim"
    if class_spec.isdigit():
        stem = f"class-{int(class_spec)}"
        return data / (f"{stem}-worker-{worker_port}.sqlite" if worker_port else
                       f"{stem}.sqlite")
    roster = Path(class_spec).resolve()
    if worker_port:
        digest = hashlib.sha256(str(roster).encode()).hexdigest()[:ROSTER_DIGEST_CHARS]
        return data / f"{roster.stem}-{digest}-worker-{worker_port}.sqlite"
    return roster.with_name(f"{roster.name}.websim-state.sqlite")


def class_identity(class_spec: str) -> str:
    """What names a class in its state file: its roster's absolute path, or its size."""
    if class_spec.isdigit():
        return f"robots:{int(class_spec)}"
    return f"roster:{Path(class_spec).resolve()}"


class ClassState:
    """A class's state file, held open (and locked) while the server runs.

    Args:
        path: the file (created, with its directory, mode 0600, if missing).
        identity: the class (``class_identity``); a file of another class is refused.
        fresh: start over: the file's content is dropped (new secret, new tokens).

    Raises:
        ConfigError: another class's file, a newer schema, locked by another server,
            corrupt or unreadable; the message says which and what to do.
    """

    def __init__(self, path: Path, identity: str, *, fresh: bool = False) -> None:
        self.path = path
        where = f"--state {path}"
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            if not path.exists():
                os.close(os.open(path, os.O_CREAT | os.O_WRONLY | os.O_NOFOLLOW, 0o600))
            self._db = sqlite3.connect(path, timeout=0.5, isolation_level=None)
        except (OSError, sqlite3.Error) as error:
            raise ConfigError(f"{where}: cannot open the class's state file: "
                              f"{getattr(error, 'strerror', None) or error}") from None
        try:
            self._db.execute("PRAGMA locking_mode=EXCLUSIVE")
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.execute("BEGIN IMMEDIATE")  # takes the lock, kept until close
            check = self._db.execute("PRAGMA quick_check").fetchone()
            if check is None or check[0] != "ok":
                raise sqlite3.DatabaseError(f"integrity check: {check[0] if check else '?'}")
            if fresh:
                for table in TABLES:
                    self._db.execute(f"DROP TABLE IF EXISTS {table}")
            for statement in filter(str.strip, _SCHEMA.split(";")):
                self._db.execute(statement)
            meta = dict(self._db.execute("SELECT key, value FROM meta").fetchall())
            if not meta:
                meta = {"schema": str(SCHEMA_VERSION), "class": identity,
                        "secret": secrets.token_urlsafe(SECRET_BYTES)}
                self._db.executemany("INSERT INTO meta VALUES (?, ?)", meta.items())
            self._db.execute("COMMIT")
        except sqlite3.OperationalError as error:
            self._db.close()
            if "locked" in str(error):
                raise ConfigError(f"{where}: another websim serve is using this class's "
                                  "state file (stop it first, or give this server its own "
                                  "--state FILE)") from None
            raise ConfigError(f"{where}: cannot read the class's state file: {error} "
                              "(--fresh starts the class over)") from None
        except sqlite3.DatabaseError as error:
            self._db.close()
            raise ConfigError(f"{where}: the class's state file is corrupt ({error}); move "
                              "it away to keep it, or start over with --fresh") from None
        schema = int(meta.get("schema", "0"))
        if schema > SCHEMA_VERSION:
            self._db.close()
            raise ConfigError(f"{where}: written by a newer websim (schema {schema}, this one "
                              f"reads {SCHEMA_VERSION}); upgrade websim, or start over with "
                              "--fresh")
        if meta.get("class") != identity:
            self._db.close()
            raise ConfigError(f"{where}: this file holds another class "
                              f"({meta.get('class')}, not {identity}); give --state another "
                              "file, or start over with --fresh")
        self.secret: str = meta["secret"]
        """The random secret the robots' tokens derive from (never the instructor's)."""
        self.restored = bool(self._db.execute("SELECT 1 FROM robots LIMIT 1").fetchone())
        """Whether robots' state was found (a restart, not a first start)."""

    def enrolments(self) -> dict[str, bool]:
        """The open class's enrolled names, and whether each one's token was handed out."""
        return {name: bool(claimed) for name, claimed in
                self._db.execute("SELECT name, claimed FROM enrolments ORDER BY rowid")}

    def enrol(self, name: str, claimed: bool = False) -> None:
        """Note ``name`` enrolled (``claimed``: its token has been handed to its student)."""
        self._db.execute("INSERT INTO enrolments VALUES (?, ?) ON CONFLICT(name) DO UPDATE "
                         "SET claimed = excluded.claimed", (name, int(claimed)))

    def robots(self) -> dict[str, dict[str, Any]]:
        """Each robot's saved state, by name."""
        return {name: json.loads(text)
                for name, text in self._db.execute("SELECT name, state FROM robots")}

    def save_robots(self, states: Mapping[str, Mapping[str, Any]]) -> None:
        """Save these robots' states, at once (one transaction)."""
        with self._db:
            self._db.execute("BEGIN")
            self._db.executemany("INSERT INTO robots VALUES (?, ?) ON CONFLICT(name) DO "
                                 "UPDATE SET state = excluded.state",
                                 [(name, json.dumps(state)) for name, state in states.items()])

    def code_versions(self, name: str) -> list[dict[str, Any]]:
        """A student's saved programs, the newest first.

        Each: version, language, saved_at (s since the epoch), reason (``autosave``, ``run``,
        ``submit``...) and text.
        """
        rows = self._db.execute("SELECT version, language, saved_at, reason, text FROM code "
                                "WHERE name = ? ORDER BY version DESC", (name,))
        return [{"version": version, "language": language, "saved_at": saved_at,
                 "reason": reason, "text": text}
                for version, language, saved_at, reason, text in rows]

    def save_code(self, name: str, language: str, text: str, reason: str, saved_at: float,
                  keep: int) -> int:
        """Save a student's program; its version number.

        The same text as the newest version of its language only updates that version's time;
        an autosave replaces a newest version that was an autosave; anything else is a new
        version. Of each language the ``keep`` newest versions stay.
        """
        with self._db:
            self._db.execute("BEGIN")
            newest = self._db.execute(
                "SELECT version, reason, text FROM code WHERE name = ? AND language = ? "
                "ORDER BY version DESC LIMIT 1", (name, language)).fetchone()
            if newest is not None and (newest[2] == text or (
                    reason == AUTOSAVE and newest[1] == AUTOSAVE)):
                version = int(newest[0])
                kept_reason = newest[1] if newest[2] == text and reason == AUTOSAVE else reason
                self._db.execute("UPDATE code SET saved_at = ?, reason = ?, text = ? WHERE "
                                 "name = ? AND version = ?",
                                 (saved_at, kept_reason, text, name, version))
                return version
            last = self._db.execute("SELECT MAX(version) FROM code WHERE name = ?",
                                    (name,)).fetchone()[0]
            version = int(last or 0) + 1
            self._db.execute("INSERT INTO code VALUES (?, ?, ?, ?, ?, ?)",
                             (name, version, language, saved_at, reason, text))
            self._db.execute("DELETE FROM code WHERE name = ? AND language = ? AND version "
                             "NOT IN (SELECT version FROM code WHERE name = ? AND language = ? "
                             "ORDER BY version DESC LIMIT ?)",
                             (name, language, name, language, keep))
            return version

    def newest_code(self) -> dict[str, dict[str, Any]]:
        """Every student's newest saved program (of any language), by name."""
        rows = self._db.execute(
            "SELECT name, version, language, saved_at, reason, text FROM code c WHERE version "
            "= (SELECT MAX(version) FROM code WHERE name = c.name) ORDER BY name")
        return {name: {"version": version, "language": language, "saved_at": saved_at,
                       "reason": reason, "text": text}
                for name, version, language, saved_at, reason, text in rows}

    def submission(self, name: str) -> dict[str, Any] | None:
        """A student's last submission (as ``save_submission`` kept it), or None."""
        row = self._db.execute("SELECT submission FROM submissions WHERE name = ?",
                               (name,)).fetchone()
        return None if row is None else dict(json.loads(row[0]))

    def submissions(self) -> dict[str, dict[str, Any]]:
        """Every student's last submission, by name."""
        return {name: json.loads(text) for name, text in
                self._db.execute("SELECT name, submission FROM submissions ORDER BY name")}

    def save_submission(self, name: str, submission: Mapping[str, Any],
                        reports: Mapping[str, str] | None = None) -> None:
        """Keep a student's last submission.

        With ``reports`` (scenario: report.html), those replace the previous submission's.
        """
        with self._db:
            self._db.execute("BEGIN")
            self._db.execute("INSERT INTO submissions VALUES (?, ?) ON CONFLICT(name) DO "
                             "UPDATE SET submission = excluded.submission",
                             (name, json.dumps(submission)))
            if reports is not None:
                self._db.execute("DELETE FROM reports WHERE name = ?", (name,))
                self._db.executemany("INSERT INTO reports VALUES (?, ?, ?)",
                                     [(name, scenario, html)
                                      for scenario, html in reports.items()])

    def report(self, name: str, scenario: str) -> str | None:
        """The report.html of a student's last submission for ``scenario``, or None."""
        row = self._db.execute("SELECT html FROM reports WHERE name = ? AND scenario = ?",
                               (name, scenario)).fetchone()
        return None if row is None else str(row[0])

    def close(self) -> None:
        """Checkpoint and release the file."""
        try:
            self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        finally:
            self._db.close()
