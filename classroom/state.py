"""A class's state on disk: what a restart of the same command brings back.

One SQLite file (the standard library's ``sqlite3``, write-ahead log) per class server
(``websim serve --state FILE``; a worker of a class spread over several processes keeps its
own): the class secret the robots' tokens derive from, the instructor's token (unless
``--admin-token`` gives one, the same across restarts: an open dashboard keeps working), the
open class's enrolments (whether the student who enrolled a name has been handed its token,
and when a connection last used it: one nobody used for the enrolment time is forgotten at
the next start), and each robot's runtime parameters (mode, payload...), paused flag and
pose, saved every ``SAVE_INTERVAL_S`` and at shutdown. ``kill -9`` loses at most that
interval.

How the file is keyed (``default_state_path``; ``--state FILE`` names another): a roster's
class keeps it beside the roster; ``--class N`` in the user's data directory, in a file named
by N, the folder the command runs in and its WebSocket port, so two classes started from two
folders (or on two ports) never share a secret; and since nothing else tells two sections of
``--class N`` apart, such a default file older than ``STALE_AFTER_S`` is started anew, said so
at start (``--state FILE`` keeps it however old). The layout: a ``meta`` table of key/value
text (``schema``, ``class``, ``secret``, ``admin_token``, ``saved_s``), ``enrolments`` (name,
claimed, seen_s) and ``robots`` (name, JSON state from ``registry.robot_state``); a feature
that keeps more adds a table of its own (older websims ignore it) or a key of
``robot_state``.

Besides, each student's program as the Code panel saved it (a few recent versions per
language, ``save_code``) and their last submission with its reports (``save_submission``),
written when they change (tables ``code``, ``submissions`` and ``reports``).

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
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from physics import ConfigError

SCHEMA_VERSION = 2
"""The layout this code writes; a file of a newer one is refused (an older websim would lose
what it does not know). 2: enrolments have ``seen_s``; ``meta`` may hold ``admin_token`` and
``saved_s``. A file of schema 1 is brought up to 2 when opened."""

STALE_AFTER_S = 12 * 3600.0
"""A ``--class N`` default state file saved longer ago than this (s) is started anew: another
day's class, not a restart of this one."""

DEFAULT_ENROLMENT_HOURS = 12.0
"""An open class forgets a name nobody connected to for this long (``--enrolment-hours``)."""

SAVE_INTERVAL_S = 2.0
"""How often the robots' state is saved (s): what ``kill -9`` may lose at most."""

SECRET_BYTES = 32
"""Random bytes of a class secret."""

ROSTER_DIGEST_CHARS = 12
"""Hex digits of a roster path's SHA-256 in a worker's state file name (48 bits)."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS enrolments (
    name TEXT PRIMARY KEY, claimed INTEGER NOT NULL DEFAULT 0, seen_s REAL NOT NULL DEFAULT 0);
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


def default_state_path(class_spec: str, worker_port: int | None = None,
                       ws_port: int | None = None, folder: Path | None = None) -> Path:
    """Where ``--state`` is by default.

    Beside the roster (``ROSTER.websim-state.sqlite``), or, for ``--class N`` and for a
    worker (one file each, named by its WebSocket port), in the user's data directory
    (``$XDG_DATA_HOME/websim``, else ``~/.local/share/websim``). A worker's file is named by
    its roster's name and a digest of the roster's absolute path too: two rosters of one name
    in two folders are two classes (``class_identity``), never one file. ``--class N``'s is
    named by N and a digest of the folder it runs in (``folder``, default the current one)
    and its WebSocket port: two classes of N robots started from two folders never meet.
    """
    data = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "websim"
    if class_spec.isdigit():
        stem = f"class-{int(class_spec)}"
        if worker_port:
            return data / f"{stem}-worker-{worker_port}.sqlite"
        where = f"{(folder or Path.cwd()).resolve()}\n{ws_port or ''}"
        digest = hashlib.sha256(where.encode()).hexdigest()[:ROSTER_DIGEST_CHARS]
        return data / f"{stem}-{digest}.sqlite"
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
        stale_after_s: start over too if the file was last saved longer ago than this
            (``stale_s`` then says how long); None: however old (a file the instructor
            named, a roster's).
        now_s: the time it is opened (wall time, s since the epoch; default now).

    Raises:
        ConfigError: another class's file, a newer schema, locked by another server,
            corrupt or unreadable; the message says which and what to do.
    """

    def __init__(self, path: Path, identity: str, *, fresh: bool = False,
                 stale_after_s: float | None = None, now_s: float | None = None) -> None:
        self.path = path
        self.stale_s: float | None = None
        """How long ago a file started anew for its age was last saved (s), else None."""
        now_s = time.time() if now_s is None else now_s
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
            if not fresh and stale_after_s is not None:
                saved = self._meta_value("saved_s")
                if saved is not None and now_s - float(saved) > stale_after_s:
                    fresh, self.stale_s = True, now_s - float(saved)
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
            elif int(meta.get("schema", "0")) == 1:
                self._upgrade_from_1(now_s)
                meta["schema"] = str(SCHEMA_VERSION)
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
        saved = meta.get("saved_s")
        self.saved_s: float | None = float(saved) if saved is not None else None
        """When the robots were last saved (wall time, s since the epoch), None: never."""

    def _meta_value(self, key: str) -> str | None:
        try:
            row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        except sqlite3.OperationalError:  # a new file: no table yet
            return None
        return None if row is None else str(row[0])

    def _upgrade_from_1(self, now_s: float) -> None:
        """Schema 1 to 2: enrolments get ``seen_s`` (now: each is kept one enrolment time)."""
        columns = {row[1] for row in self._db.execute("PRAGMA table_info(enrolments)")}
        if "seen_s" not in columns:
            self._db.execute("ALTER TABLE enrolments ADD COLUMN seen_s REAL NOT NULL "
                             "DEFAULT 0")
        self._db.execute("UPDATE enrolments SET seen_s = ?", (now_s,))
        self._db.execute("UPDATE meta SET value = ? WHERE key = 'schema'",
                         (str(SCHEMA_VERSION),))

    def admin_token(self, given: str | None, make: Callable[[], str]) -> tuple[str, bool]:
        """The instructor's token: ``given``, else the one kept here, else a new one (kept).

        Returns:
            The token, and whether it was restored from the file.
        """
        kept = self._meta_value("admin_token")
        if given is not None:
            token, restored = given, False
        elif kept is not None:
            return kept, True
        else:
            token, restored = make(), False
        if token != kept:
            self._db.execute("INSERT INTO meta VALUES ('admin_token', ?) ON CONFLICT(key) DO "
                             "UPDATE SET value = excluded.value", (token,))
        return token, restored

    def enrolments(self) -> dict[str, bool]:
        """The open class's enrolled names, and whether each one's token was handed out."""
        return {name: bool(claimed) for name, claimed in
                self._db.execute("SELECT name, claimed FROM enrolments ORDER BY rowid")}

    def enrol(self, name: str, claimed: bool = False, now_s: float | None = None) -> None:
        """Note ``name`` enrolled (``claimed``: its token has been handed to its student)."""
        seen_s = time.time() if now_s is None else now_s
        self._db.execute("INSERT INTO enrolments VALUES (?, ?, ?) ON CONFLICT(name) DO UPDATE "
                         "SET claimed = excluded.claimed, seen_s = excluded.seen_s",
                         (name, int(claimed), seen_s))

    def forget_enrolments(self, unused_for_s: float, keep: Iterable[str] = (),
                          now_s: float | None = None) -> list[str]:
        """Forget the enrolments nobody used for ``unused_for_s``, with their robots' state.

        Args:
            unused_for_s: how long an enrolment may go unused (s).
            keep: names kept whatever their age (a roster's).
            now_s: the time it is (wall time; default now).

        Returns:
            The names forgotten, in enrolment order.
        """
        before_s = (time.time() if now_s is None else now_s) - unused_for_s
        kept = set(keep)
        names = [name for (name,) in self._db.execute(
            "SELECT name FROM enrolments WHERE seen_s < ? ORDER BY rowid", (before_s,))
            if name not in kept]
        with self._db:
            self._db.execute("BEGIN")
            self._db.executemany("DELETE FROM enrolments WHERE name = ?",
                                 [(name,) for name in names])
            self._db.executemany("DELETE FROM robots WHERE name = ?",
                                 [(name,) for name in names])
        return names

    def robots(self) -> dict[str, dict[str, Any]]:
        """Each robot's saved state, by name."""
        return {name: json.loads(text)
                for name, text in self._db.execute("SELECT name, state FROM robots")}

    def save_robots(self, states: Mapping[str, Mapping[str, Any]],
                    used: Iterable[str] = (), now_s: float | None = None) -> None:
        """Save these robots' states, at once (one transaction).

        Args:
            states: each robot's state, by name.
            used: the enrolled names a connection uses now (their enrolments are kept).
            now_s: the time of the save (wall time; default now).
        """
        now_s = time.time() if now_s is None else now_s
        with self._db:
            self._db.execute("BEGIN")
            self._db.executemany("INSERT INTO robots VALUES (?, ?) ON CONFLICT(name) DO "
                                 "UPDATE SET state = excluded.state",
                                 [(name, json.dumps(state)) for name, state in states.items()])
            self._db.executemany("UPDATE enrolments SET seen_s = ? WHERE name = ?",
                                 [(now_s, name) for name in used])
            self._db.execute("INSERT INTO meta VALUES ('saved_s', ?) ON CONFLICT(key) DO "
                             "UPDATE SET value = excluded.value", (repr(now_s),))
        self.saved_s = now_s

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
