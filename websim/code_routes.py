"""The Code panel's HTTP routes: assignments, saving, submitting, the instructor's view.

Under a robot's page (``/robots/NAME/code/...``; ``/code/...`` on a single robot), so the page
reaches them with relative URLs:

* ``GET code/starters.json``: the assignments (``websim.code_starters``), the examples, and
  what this server offers (saving, submitting, per language, and the limits);
* ``GET code/saved``, ``POST code/saved`` ``{language, text, reason}``: the student's saved
  programs (a class robot, with the robot's token or the instructor's; kept in the class
  state, ``classroom.state``: a few versions per language, surviving a restart);
* ``POST code/submit`` ``{language, text, assignment}``, ``GET code/submission``: Submit
  (``websim.submissions``) and its progress: queue position, then the score per scenario;
  ``GET code/report/SCENARIO``: that scenario's report.html;

and for the instructor (the instructor's token), ``GET /class/submissions.json`` (every
student's saved program and last submission) and ``GET /class/code.zip`` (every student's
newest program as a folder for ``websim grade --submissions``, with its
``websim-submission.yaml``).

A token travels in an ``Authorization: Bearer`` header, never in the URL. Bodies are read up
to a bound (a program's limit and a little), refused beyond it with 413 before the rest is
read. A single robot keeps no program on the server (its page keeps it in the browser) and
counts submissions per client address.
"""

from __future__ import annotations

import io
import json
import logging
import re
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any

from aiohttp import web

from classroom.registry import ROBOT_NAME, Classroom
from classroom.state import ClassState
from ros_nodes.robot_interface import ROBOTS_PREFIX
from rosbridge.core.limits import TrustedProxies, budget_key
from websim.code_starters import assignments, examples
from websim.node_roslib import roslib_modules
from websim.submissions import (
    LANGUAGES,
    RefusedError,
    Submission,
    SubmissionQueue,
    SubmitLimits,
    write_submission,
)

log = logging.getLogger("websim.code")

KEEP_VERSIONS = 5
"""Saved versions kept per student and language."""

SAVE_REASONS = ("autosave", "run", "submit", "save")

BODY_SLACK_BYTES = 4096
"""A request body may exceed the program's limit by this much (its JSON around it)."""

ROUTE = re.compile(r"(?:/robots/(?P<robot>[^/]+))?/code/(?P<what>starters\.json|saved|submit|"
                   r"submission|report/(?P<scenario>[^/]+))")
CLASS_ROUTES = ("/class/submissions.json", "/class/code.zip")

REPORT_POLICY = ("default-src 'none'; style-src 'unsafe-inline'; img-src data:; sandbox; "
                 "frame-ancestors 'self'")
"""A report.html (it quotes the program's output): no script, an origin of its own."""


class CodeRoutes:
    """The routes, for one server (``websim.http_server.CodeRoutes``).

    Args:
        queue: Submit's queue.
        classroom: the class (None: a single robot).
        is_admin_token: the instructor's (admin) token check.
        proxies: trusted proxies (a single robot's submissions count per client address).
    """

    def __init__(self, queue: SubmissionQueue, classroom: Classroom | None,
                 is_admin_token: Any, proxies: TrustedProxies | None = None) -> None:
        self.queue = queue
        self.classroom = classroom
        self.is_admin_token = is_admin_token
        self.proxies = proxies or TrustedProxies()
        self._assignments = assignments()
        self._examples = examples()
        queue.assignments = {a["name"] for a in self._assignments}
        queue.on_done = self._keep

    @property
    def limits(self) -> SubmitLimits:
        """Submit's bounds (and the program's size limit, which saving shares)."""
        return self.queue.limits

    @property
    def state(self) -> ClassState | None:
        """The class's state file (None: a single robot, or a class without one)."""
        return None if self.classroom is None else self.classroom.state

    def handles(self, path: str) -> bool:
        """Whether ``path`` is a Code route."""
        return path in CLASS_ROUTES or ROUTE.fullmatch(path) is not None

    async def respond(self, request: web.BaseRequest) -> web.Response:
        """Answer a Code route; errors as ``{"reason": ...}`` with their status."""
        try:
            if request.path in CLASS_ROUTES:
                return await self._instructor(request)
            match = ROUTE.fullmatch(request.path)
            assert match is not None
            return await self._robot(request, match["robot"], match["what"], match["scenario"])
        except RefusedError as refused:
            return _json({"reason": refused.reason}, refused.status)

    # --- a robot's routes ------------------------------------------------------------------

    async def _robot(self, request: web.BaseRequest, robot: str | None, what: str,
                     scenario: str | None) -> web.Response:
        if robot is not None and (self.classroom is None or not ROBOT_NAME.fullmatch(robot)
                                  or not self.classroom.knows(robot)):
            raise RefusedError(404, f"no robot '{robot[:40]}' here")
        if robot is None and self.classroom is not None:
            raise RefusedError(404, f"a class's programs are under {ROBOTS_PREFIX}NAME/code/")
        if what == "starters.json":
            _method(request, "GET")
            return _json(self._starters(robot))
        if what == "saved":
            _method(request, "GET", "POST")
            name = self._student(request, robot)
            if request.method == "GET":
                return _json({"versions": self._versions(name)})
            return _json(await self._save(request, name))
        if what == "submit":
            _method(request, "POST")
            key = self._student(request, robot) if robot is not None else self._address(request)
            body = await _body(request, self.limits.code_bytes + BODY_SLACK_BYTES)
            language, text = _program(body, self.limits)
            self.queue.submit(key, language, text, _text(body, "assignment"))
            if robot is not None and self.state is not None:
                self._save_version(key, language, text, "submit")
            return _json(self._status(key), 202)
        _method(request, "GET")
        key = self._student(request, robot) if robot is not None else self._address(request)
        if what == "submission":
            return _json(self._status(key))
        return self._report(key, str(scenario))

    def _starters(self, robot: str | None) -> dict[str, Any]:
        return {"assignments": self._assignments, "examples": self._examples,
                "saving": robot is not None and self.state is not None,
                "submitting": self.queue.availability(),
                "limits": {"code_bytes": self.limits.code_bytes,
                           "per_hour": self.limits.per_hour,
                           "versions": KEEP_VERSIONS}}

    def _student(self, request: web.BaseRequest, robot: str | None) -> str:
        """The robot whose token (or the instructor's) the request carries; 401/403 else."""
        if robot is None:
            raise RefusedError(404, "this server keeps no programs (a single robot: the page "
                                    "keeps yours in this browser)")
        token = _bearer(request)
        if not token:
            raise RefusedError(401, "this needs your robot's token (the link from your "
                                    "instructor gives it to your page)")
        assert self.classroom is not None
        if not (self.classroom.is_robot_token(robot, token) or self.is_admin_token(token)):
            raise RefusedError(403, f"that is not robot {robot}'s token")
        return robot

    def _address(self, request: web.BaseRequest) -> str:
        peer = request.remote or "unknown"
        client = self.proxies.client(peer, request.headers.get("X-Real-IP"),
                                     request.headers.get("X-Forwarded-For"))
        return f"address:{budget_key(client)}"

    def _versions(self, name: str) -> list[dict[str, Any]]:
        return [] if self.state is None else self.state.code_versions(name)

    async def _save(self, request: web.BaseRequest, name: str) -> dict[str, Any]:
        if self.state is None:
            raise RefusedError(404, "this class keeps no state file, so no programs")
        body = await _body(request, self.limits.code_bytes + BODY_SLACK_BYTES)
        language, text = _program(body, self.limits)
        reason = body.get("reason", "save")
        if reason not in SAVE_REASONS:
            raise RefusedError(400, f"reason: expected one of {', '.join(SAVE_REASONS)}")
        saved_at = time.time()
        version = self._save_version(name, language, text, reason, saved_at)
        return {"version": version, "saved_at": saved_at}

    def _save_version(self, name: str, language: str, text: str, reason: str,
                      saved_at: float | None = None) -> int:
        assert self.state is not None
        return self.state.save_code(name, language, text, reason, saved_at or time.time(),
                                    KEEP_VERSIONS)

    def _status(self, key: str) -> dict[str, Any]:
        submission = self.queue.latest(key)
        if submission is not None:
            return {**submission.summary(), "position": self.queue.position(submission)}
        kept = self.state.submission(key) if self.state is not None else None
        return {**kept, "position": 0} if kept else {"state": "none"}

    def _report(self, key: str, scenario: str) -> web.Response:
        submission = self.queue.latest(key)
        html = None
        if submission is not None and submission.state == "done":
            html = submission.reports.get(scenario)
        elif self.state is not None:
            html = self.state.report(key, scenario)
        if html is None:
            raise RefusedError(404, f"no report of '{scenario[:60]}'")
        return web.Response(text=html, content_type="text/html",
                            headers={"Content-Security-Policy": REPORT_POLICY,
                                     "Cache-Control": "no-store"})

    def _keep(self, submission: Submission) -> None:
        """A finished submission of a class robot: into the class state."""
        if self.state is None or self.classroom is None or submission.key.startswith(
                "address:"):
            return
        self.state.save_submission(submission.key, submission.summary(),
                                   submission.reports if submission.state == "done" else {})

    # --- the instructor's ------------------------------------------------------------------

    async def _instructor(self, request: web.BaseRequest) -> web.Response:
        _method(request, "GET")
        if not self.is_admin_token(_bearer(request)):
            raise RefusedError(403, "this needs the instructor's token")
        if self.classroom is None or self.state is None:
            raise RefusedError(404, "this server runs no class")
        if request.path.endswith(".zip"):
            return web.Response(body=self._export(), content_type="application/zip", headers={
                "Content-Disposition": 'attachment; filename="websim-submissions.zip"',
                "Cache-Control": "no-store"})
        return _json(self._overview())

    def _overview(self) -> dict[str, Any]:
        assert self.classroom is not None and self.state is not None
        newest = self.state.newest_code()
        kept = self.state.submissions()
        # the class's students, not the robots spawned into an arena (unless one saved code)
        roster = {name for name in self.classroom.students if not self.classroom.spawned(name)}
        names = sorted(roster | set(newest) | set(kept))
        students = []
        for name in names:
            code = newest.get(name)
            live = self.queue.latest(name)
            submission = ({**live.summary(), "position": self.queue.position(live)}
                          if live is not None else kept.get(name))
            students.append({
                "name": name,
                "saved": None if code is None else {
                    "language": code["language"], "saved_at": code["saved_at"],
                    "version": code["version"], "bytes": len(code["text"].encode("utf-8")),
                    "text": code["text"]},
                "submission": submission})
        return {"students": students, "submitting": self.queue.availability(),
                "assignments": [a["name"] for a in self._assignments]}

    def _export(self) -> bytes:
        """Every student's newest program, zipped, a folder each for --submissions.

        ``NAME/controller.EXT`` and ``NAME/websim-submission.yaml`` (a JavaScript one with
        roslib in ``NAME/node_modules``).
        """
        assert self.state is not None
        modules = None  # JavaScript folders get roslib where the server has its Node package
        if self.queue.grader.language_unavailable("javascript") is None:
            modules = self.queue.grader.roslib_modules
        buffer = io.BytesIO()
        with tempfile.TemporaryDirectory(prefix="websim-export-") as folder, \
                zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
            root = Path(folder)
            for name, code in self.state.newest_code().items():
                if not ROBOT_NAME.fullmatch(name) or code["language"] not in LANGUAGES:
                    continue
                write_submission(root / name, code["language"], code["text"], modules)
            for path in sorted(root.rglob("*")):
                if path.is_file():
                    archive.write(path, path.relative_to(root).as_posix())
        return buffer.getvalue()


def _json(document: Any, status: int = 200) -> web.Response:
    return web.Response(text=json.dumps(document), status=status,
                        content_type="application/json", headers={"Cache-Control": "no-store"})


def _method(request: web.BaseRequest, *allowed: str) -> None:
    if request.method not in allowed:
        raise RefusedError(405, f"{request.method}: this takes {' or '.join(allowed)}")


def _bearer(request: web.BaseRequest) -> str:
    scheme, _, token = request.headers.get("Authorization", "").partition(" ")
    return token.strip() if scheme.lower() == "bearer" else ""


async def _body(request: web.BaseRequest, limit: int) -> dict[str, Any]:
    """The request's JSON object, read up to ``limit`` bytes (413 beyond, unread)."""
    too_large = RefusedError(413, f"the request is larger than {limit} bytes")
    if request.content_length is not None and request.content_length > limit:
        raise too_large
    data = bytearray()
    while chunk := await request.content.read(limit + 1 - len(data)):
        data += chunk
        if len(data) > limit:
            raise too_large
    try:
        body = json.loads(data)
    except (ValueError, UnicodeDecodeError):
        raise RefusedError(400, "expected a JSON object") from None
    if not isinstance(body, dict):
        raise RefusedError(400, "expected a JSON object")
    return body


def _text(body: dict[str, Any], key: str) -> str:
    value = body.get(key)
    if not isinstance(value, str):
        raise RefusedError(400, f"{key}: expected text")
    return value


def _program(body: dict[str, Any], limits: SubmitLimits) -> tuple[str, str]:
    """The (language, text) of a body, checked."""
    language, text = _text(body, "language"), _text(body, "text")
    if language not in LANGUAGES:
        raise RefusedError(400, f"language: expected one of {', '.join(LANGUAGES)}")
    if len(text.encode("utf-8")) > limits.code_bytes:
        raise RefusedError(413, f"the program is larger than {limits.code_bytes} bytes")
    return language, text


def code_routes(classroom: Classroom | None, is_admin_token: Any, proxies: TrustedProxies,
                limits: SubmitLimits) -> CodeRoutes:
    """The Code routes of a ``websim serve``: Submit graded by ``websim grade`` in its sandbox.

    JavaScript with roslib for Node where this websim has it (``websim.node_roslib``: a
    checkout's after ``npm ci``, or the wheel's).
    """
    from websim.submissions import Grader
    grader = Grader(roslib_modules())
    return CodeRoutes(SubmissionQueue(limits, grader, set()), classroom, is_admin_token,
                      proxies)
