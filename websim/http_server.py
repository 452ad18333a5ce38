"""The web interface over HTTP, on the event loop that runs the simulation (aiohttp).

``websim serve`` serves the pages, the files they load, ``/healthz`` and the live
``/robot.json``; the Docker stack serves the same files with nginx. Only an allow-list is
published (``open_published``): the pages, ``css/``, ``js/`` and the built folders of the three
libraries the pages load, never a listing, a dotfile, the Dockerfile, nginx.conf, the
entrypoint scripts or package.json, and never a file a symlink leads to outside that list.

Connections are bounded by construction, for a classroom on one process's file descriptors:

* a connection with no request in progress (idle keep-alive, or a request whose headers have
  not all arrived: a half-open or slowloris client) is closed ``IDLE_TIMEOUT_S`` after it
  connected or got its last response; a request still being answered (a client that stops
  reading) is cut after ``REQUEST_TIMEOUT_S``;
* at most ``connection_cap()`` connections are open, a quarter of the process's open-file
  limit (the rest is for WebSockets and files); a connection beyond it evicts the one idle
  the longest, so a thousand stalled sockets cannot lock out a browser;
* one client address holds at most ``address_cap`` of them (twice its WebSocket connections,
  ``ClientLimits.address_max_connections``: a class of 40 behind one NAT address loading the
  page at once); beyond it its own longest-idle one goes, or, all of its own answering (a
  client that asks for files and stops reading), the newcomer is refused: one address cannot
  hold every slot. A trusted proxy (``--trusted-proxy``) is not capped;
* the listen backlog (``LISTEN_BACKLOG``) holds a whole class loading the page at once.

Files are read into memory on first use and again when they change (the allow-list bounds
what can be cached), gzipped once when that pays, and answered with an ETag, so a classroom
reloading after every update costs a 304 per file.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import gzip
import html
import json
import logging
import os
import stat
import threading
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol
from urllib.parse import urlsplit

from aiohttp import web
from aiohttp.abc import AbstractAccessLogger

from ros_nodes.robot_interface import ROBOTS_PREFIX
from rosbridge.core.limits import ClientLimits, TrustedProxies, budget_key
from websim.import_map import with_import_map
from websim.page_policy import (
    SECURITY_HEADERS,
    WORKER_POLICIES,
    page_policy,
)
from websim.web_files import CONTENT_TYPES, PYODIDE_FILES, published

log = logging.getLogger("websim.http")

PAGE_ROUTES = {"/": "index.html", "/admin": "admin.html", "/class": "class.html",
               "/submissions": "submissions.html"}
"""Clean URLs the course uses, mapped to files of the web folder."""

COMPRESSIBLE = frozenset({".html", ".js", ".mjs", ".css", ".json", ".map", ".svg", ".py",
                          ".wasm"})

GZIP_MIN_BYTES = 1024
"""Smaller files are sent as they are: the gzip header and a round of inflating cost more."""

GZIP_LEVEL = 5
"""zlib level: the largest file (uPlot, 145 kB) in ~3 ms on the loop, within 2 % of level 9's
size; once per file and change."""


LIVE_DOCUMENTS = ("/robot.json", "/config.json", "/workers.json")
"""Documents the server may fill itself (``LiveDocuments``) instead of serving the file."""

CACHE_CONTROL = "no-cache"
"""Every answer is revalidated: a classroom reloads after every update (ETags make it a 304)."""

LOOP_GZIP_MAX_BYTES = 1 << 20
"""A larger file is gzipped on a thread, not on the event loop (Pyodide's 9.6 MB interpreter
takes ~0.5 s: every robot's tick would wait); it is sent as it is until that is done."""

LISTEN_BACKLOG = 1024
"""Connections the kernel queues before they are accepted: 40 browsers opening 6 each at
once fit, where the old backlog of 5 made them wait seconds for SYN retries. The kernel caps
it at net.core.somaxconn (4096 on current Linux)."""

IDLE_TIMEOUT_S = 10.0
"""A connection without a request in progress is closed this long after it connected or got
its last response: an idle keep-alive connection (a page has loaded all it needs by then), or
a request whose headers have not arrived (half-open, slowloris). Apache's default keep-alive
is 5 s, nginx's header timeout 60 s."""

REQUEST_TIMEOUT_S = 30.0
"""A request still being answered this long after its headers arrived is cut: the largest
file takes ~3 s at 50 kB/s, so only a client that stopped reading is this slow."""

SHUTDOWN_TIMEOUT_S = 2.0
"""At shutdown, requests in progress get this long to finish before their connections close."""

FD_SHARE_FOR_HTTP = 4
"""HTTP connections may use 1/this of the process's open-file limit; WebSockets and files
the rest."""

MIN_CONNECTION_CAP = 16

UNLIMITED_FILES = 1 << 16
"""The open-file limit assumed where there is none (Windows, or RLIM_INFINITY)."""


def openpublished(web_dir: str, url_path: str) -> tuple[int, str] | None:
    """Open the published file a URL path names; None when there is none (then: 404).

    The URL must name an allow-listed file of a published type, and so must the real path of
    the file opened (after every symlink, and read from the open file, so that swapping a
    symlink between a check and the open cannot lead out of the web folder).

    Args:
        web_dir: the web folder, with every symlink resolved (``os.path.realpath``).
        url_path: the request's path, percent-decoded, starting with ``/``.

    Returns:
        A file descriptor the caller closes, and the file's real path relative to
        ``web_dir`` (``/``-separated).
    """
    relative = PAGE_ROUTES.get(url_path, url_path.removeprefix("/"))
    if not published(relative):
        return None
    candidate = os.path.join(web_dir, relative)
    try:  # O_NONBLOCK: a FIFO planted in the folder opens instead of blocking the loop
        fd = os.open(candidate, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError:  # missing, unreadable, a symlink loop
        return None
    try:
        real = _real_path(fd, candidate)
        inside = real.startswith(web_dir + os.sep)
        real_relative = real[len(web_dir) + 1:].replace(os.sep, "/")
        if inside and published(real_relative) and stat.S_ISREG(os.fstat(fd).st_mode):
            return fd, real_relative
    except OSError:
        pass
    os.close(fd)
    return None


def _real_path(fd: int, opened_as: str) -> str:
    """The real path of an open file: Linux tells it from the descriptor itself."""
    try:
        return os.readlink(f"/proc/self/fd/{fd}")
    except OSError:  # no /proc (macOS): resolve the name, as the open just did
        return os.path.realpath(opened_as)


def raise_open_file_limit() -> int:
    """Raise the soft RLIMIT_NOFILE to the hard limit (common practice for servers).

    Returns:
        The soft limit in effect afterwards (a large number where there is no such limit).
    """
    try:
        import resource
    except ImportError:  # Windows: no such limit to raise
        return UNLIMITED_FILES
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != soft:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
        except (ValueError, OSError) as error:  # e.g. macOS: unlimited hard, capped soft
            log.debug("open-file limit stays %d (hard %d): %s", soft, hard, error)
        else:
            log.debug("open-file limit raised from %d to %d", soft, hard)
            soft = hard
    return soft if soft != resource.RLIM_INFINITY else UNLIMITED_FILES


def connection_cap(open_file_limit: int) -> int:
    """The most HTTP connections open at once, for a process allowed this many files."""
    return max(MIN_CONNECTION_CAP, open_file_limit // FD_SHARE_FOR_HTTP)


def address_connection_cap(limits: ClientLimits) -> int:
    """The most HTTP connections one client address holds at once (twice its WebSockets)."""
    return 2 * limits.address_max_connections


@dataclass
class _Connection:
    transport: asyncio.Transport
    address: str | None
    busy: bool = False
    timer: asyncio.TimerHandle | None = None


class ConnectionTable:
    """The open HTTP connections, the one active longest ago first.

    Each has a timer: ``IDLE_TIMEOUT_S`` while no request is in progress, ``REQUEST_TIMEOUT_S``
    while one is; when it fires the connection is aborted. Beyond ``cap`` connections, the one
    idle longest is aborted to make room (never one answering a request); when every one is
    answering, the newcomer is refused. Likewise per client address beyond ``address_cap``,
    among that address's own connections only.

    Args:
        cap: connections open at once.
        address_cap: connections of one client address (IPv6: its /64) open at once.
        uncapped: the addresses ``address_cap`` does not apply to (trusted proxies).
    """

    def __init__(self, cap: int, address_cap: int | None = None,
                 uncapped: Callable[[str], bool] = lambda address: False) -> None:
        self.cap = cap
        self.address_cap = address_cap or cap
        self._uncapped = uncapped
        self._open: OrderedDict[object, _Connection] = OrderedDict()
        self._per_address: dict[str, int] = {}

    def __len__(self) -> int:
        return len(self._open)

    def opened(self, key: object, transport: asyncio.Transport) -> None:
        """A connection was accepted: make room for it and start its idle timer."""
        address = _address_of(transport)
        if address is not None and self._uncapped(address):
            address = None
        if address is not None and self._per_address.get(address, 0) >= self.address_cap \
                and not self._make_room(transport, lambda c: c.address == address,
                                        f"{self.address_cap} connections of {address}"):
            return
        if len(self._open) >= self.cap and not self._make_room(
                transport, lambda c: True, f"{self.cap} connections"):
            return
        self._open[key] = connection = _Connection(transport, address)
        if address is not None:
            self._per_address[address] = self._per_address.get(address, 0) + 1
        self._arm(key, connection, IDLE_TIMEOUT_S)

    def _make_room(self, newcomer: asyncio.Transport, among: Callable[[_Connection], bool],
                   what: str) -> bool:
        """Abort the longest-idle ``among`` those open; none idle: refuse ``newcomer`` (False)."""
        idle = next((k for k, conn in self._open.items() if among(conn) and not conn.busy),
                    None)
        if idle is None:
            log.debug("HTTP connection refused: %s, all answering", what)
            newcomer.abort()
            return False
        self._abort(idle)
        return True

    def closed(self, key: object) -> None:
        """A connection ended, however."""
        connection = self._open.pop(key, None)
        if connection is not None:
            self._forget(connection)

    def begin(self, key: object) -> None:
        """A request's headers arrived: it is answering now."""
        connection = self._open.get(key)
        if connection is not None:
            connection.busy = True
            self._open.move_to_end(key)
            self._arm(key, connection, REQUEST_TIMEOUT_S)

    def end(self, key: object) -> None:
        """The answer is sent: idle again."""
        connection = self._open.get(key)
        if connection is not None:
            connection.busy = False
            self._open.move_to_end(key)
            self._arm(key, connection, IDLE_TIMEOUT_S)

    def _arm(self, key: object, connection: _Connection, delay_s: float) -> None:
        if connection.timer is not None:
            connection.timer.cancel()
        connection.timer = asyncio.get_running_loop().call_later(delay_s, self._abort, key)

    def _abort(self, key: object) -> None:
        connection = self._open.pop(key, None)
        if connection is not None:
            self._forget(connection)
            connection.transport.abort()

    def _forget(self, connection: _Connection) -> None:
        if connection.timer is not None:
            connection.timer.cancel()
        if connection.address is not None:
            left = self._per_address.get(connection.address, 1) - 1
            if left > 0:
                self._per_address[connection.address] = left
            else:
                self._per_address.pop(connection.address, None)


def _address_of(transport: asyncio.Transport) -> str | None:
    """Whose budget a connection spends: its peer's address (IPv6: its /64), or None."""
    peer = transport.get_extra_info("peername")
    if isinstance(peer, tuple) and peer:
        return budget_key(str(peer[0]))
    return None


class _TrackedServer(web.Server):
    """aiohttp's low-level server, reporting its connections to a ``ConnectionTable``."""

    def __init__(self, handler: Callable[[web.BaseRequest], Awaitable[web.StreamResponse]],
                 connections: ConnectionTable, **kwargs: Any) -> None:
        super().__init__(handler, **kwargs)
        self.tracked = connections

    def connection_made(self, handler: web.RequestHandler,
                        transport: asyncio.Transport) -> None:
        super().connection_made(handler, transport)
        self.tracked.opened(handler, transport)

    def connection_lost(self, handler: web.RequestHandler,
                        exc: BaseException | None = None) -> None:
        self.tracked.closed(handler)
        super().connection_lost(handler, exc)


class _AccessLogger(AbstractAccessLogger):
    """One debug line per request; the path without its query (it may carry the token)."""

    def log(self, request: web.BaseRequest, response: web.StreamResponse,
            time: float) -> None:
        self.logger.debug('%s "%s %s" %d %.1f ms', request.remote, request.method,
                          request.path, response.status, time * 1e3)

    @property
    def enabled(self) -> bool:
        """Whether lines would be logged (aiohttp skips timing the request otherwise)."""
        return self.logger.isEnabledFor(logging.DEBUG)


class _ClientFaultLogger(logging.Logger):
    """aiohttp's protocol logger, which logs at debug what it would log as errors.

    What it reports (malformed requests, clients gone away) is the client's doing, so it goes
    where the access log goes: a client cannot fill the log. Our own handler's failures are
    logged as errors by ``HttpServer`` itself.
    """

    def exception(self, msg: object, *args: object, **kwargs: Any) -> None:
        kwargs.setdefault("exc_info", True)
        self.debug(msg, *args, **kwargs)


@dataclass(frozen=True)
class _Asset:
    """A published file in memory: ``key`` tells whether the file changed since."""

    key: tuple[int, int, int]  # inode, mtime (ns), size
    body: bytes
    gzipped: bytes | None
    content_type: str
    etag: str
    policy: str | None = None  # its own Content-Security-Policy, if not the pages'


class HttpServer:
    """The web interface's HTTP server; ``start_http`` starts one, ``close()`` stops it."""

    def __init__(self, web_dir: Path, health: Callable[[str | None], dict[str, Any]],
                 live: LiveDocuments, connections: ConnectionTable,
                 code: CodeRoutes | None = None) -> None:
        self._web_dir = os.path.realpath(web_dir)
        self._health = health
        self._live = live
        self._code = code
        self._assets: dict[str, _Asset] = {}  # by real path in the web folder
        self.connections = connections
        protocol_log = _ClientFaultLogger("websim.http.protocol")
        protocol_log.parent = log
        self._server = _TrackedServer(
            self._handle, self.connections, keepalive_timeout=IDLE_TIMEOUT_S,
            access_log_class=_AccessLogger, access_log=log, logger=protocol_log)
        self._listener: asyncio.Server | None = None

    async def listen(self, host: str, port: int) -> None:
        """Bind and accept; raises OSError (a port in use, say)."""
        loop = asyncio.get_running_loop()
        self._listener = await loop.create_server(self._server, host or None, port,
                                                  backlog=LISTEN_BACKLOG, reuse_address=True)

    async def close(self) -> None:
        """Stop accepting, let requests in progress finish (briefly), close every connection."""
        if self._listener is not None:
            self._listener.close()
        for connection in self._server.connections:
            connection.close()  # idle ones (and half-open) go now, busy ones after their answer
        await self._server.shutdown(SHUTDOWN_TIMEOUT_S)
        if self._listener is not None:
            await self._listener.wait_closed()
            self._listener = None

    async def _handle(self, request: web.BaseRequest) -> web.StreamResponse:
        """Answer one request, the whole response sent within the connection's request timer."""
        connection = request.protocol
        self.connections.begin(connection)
        try:
            try:
                if self._code is not None and self._code.handles(request.path):
                    response = await self._code.respond(request)
                else:
                    response = self._respond(request)
            except Exception:
                log.exception("HTTP %s %s failed", request.method, request.path)
                response = web.Response(status=500, text="500: Internal Server Error")
            response.headers.setdefault("Cache-Control", CACHE_CONTROL)
            for name, value in SECURITY_HEADERS.items():  # unless the answer set its own
                response.headers.setdefault(name, value)
            response.headers["Server"] = "websim"  # not aiohttp's and Python's versions
            await response.prepare(request)
            await response.write_eof()
            return response
        finally:
            self.connections.end(connection)

    def _respond(self, request: web.BaseRequest) -> web.Response:
        if request.method not in ("GET", "HEAD"):
            return web.Response(status=405, text="405: Method Not Allowed",
                                headers={"Allow": "GET, HEAD"})
        path = request.path
        if path == "/healthz":  # public: status and counts; the admin token: names too
            report = self._health(request.query.get("token"))
            return web.Response(text=json.dumps(report), content_type="application/json",
                                headers={"Cache-Control": "no-store"})
        robot: str | None = None
        if path in ("/", "/index.html") and (landing := self._live.root_notice()) is not None:
            return notice_page("A class", landing, 200)
        if path == ROBOTS_PREFIX.rstrip("/"):  # /robots: the name left out
            path = ROBOTS_PREFIX
        if path.startswith(ROBOTS_PREFIX):  # a class's robot: its page, with its documents
            robot, slash, rest = path[len(ROBOTS_PREFIX):].partition("/")
            if not self._live.has_robot(robot):
                return not_a_robot_page(self._live.why_no_robot(robot, request.remote or ""))
            if not slash:  # the page's relative URLs need the trailing slash
                return web.Response(status=308, headers={"Location": f"{ROBOTS_PREFIX}{robot}/"})
            path = f"/{rest}"
        if path in LIVE_DOCUMENTS:
            hostname = urlsplit(f"//{request.host}").hostname or "localhost"
            text = self._live.document(robot, path[1:], hostname)
            if text is not None:
                return web.Response(text=text, content_type="application/json")
        asset = self._asset(path)
        if asset is None:
            return web.Response(status=404, text="404: Not Found")
        gzipped = asset.gzipped is not None and "gzip" in request.headers.get(
            "Accept-Encoding", "")
        etag = f'"{asset.etag}-gz"' if gzipped else f'"{asset.etag}"'
        headers = {"ETag": etag, "Content-Type": asset.content_type}
        if asset.policy is not None:
            headers["Content-Security-Policy"] = asset.policy
        if asset.gzipped is not None:
            headers["Vary"] = "Accept-Encoding"
        if etag in _etags(request.headers.get("If-None-Match", "")):
            return web.Response(status=304, headers=headers)
        if gzipped:
            headers["Content-Encoding"] = "gzip"
        return web.Response(body=asset.gzipped if gzipped else asset.body, headers=headers)

    def warm(self, relatives: tuple[str, ...]) -> threading.Thread:
        """Read and gzip these files on a thread now: their first request finds them ready.

        Pyodide's runtime: the first student to open the Code panel gets it gzipped too.
        """
        def read_all() -> None:
            for relative in relatives:
                self._asset(f"/{relative}", gzip_here=True)

        thread = threading.Thread(target=read_all, daemon=True, name="warm files")
        thread.start()
        return thread

    def _asset(self, url_path: str, gzip_here: bool = False) -> _Asset | None:
        """The published file ``url_path`` names, reread when changed (inode, mtime, size).

        ``gzip_here``: compress a large file on the calling thread (not the event loop's).
        """
        opened = openpublished(self._web_dir, url_path)
        if opened is None:
            return None
        fd, relative = opened
        try:
            with open(fd, "rb") as file:
                info = os.fstat(fd)
                key = (info.st_ino, info.st_mtime_ns, info.st_size)
                cached = self._assets.get(relative)
                if cached is not None and cached.key == key:
                    return cached
                body = file.read()
        except OSError:
            return None
        suffix = os.path.splitext(relative)[1]
        policy = WORKER_POLICIES.get(relative)
        if suffix == ".html":
            body, script = with_import_map(body, Path(self._web_dir))
            if script is not None:
                policy = page_policy(script)
        gzipped = None
        compress = suffix in COMPRESSIBLE and len(body) >= GZIP_MIN_BYTES
        if compress and (gzip_here or len(body) <= LOOP_GZIP_MAX_BYTES):
            gzipped = _gzipped(body)
        asset = _Asset(key, body, gzipped, CONTENT_TYPES[suffix],
                       f"{info.st_mtime_ns:x}-{info.st_size:x}", policy)
        self._assets[relative] = asset
        if compress and gzipped is None and len(body) > LOOP_GZIP_MAX_BYTES:
            threading.Thread(target=self._gzip_later, args=(relative, asset), daemon=True,
                             name=f"gzip {relative}").start()
        return asset

    def _gzip_later(self, relative: str, asset: _Asset) -> None:
        """Gzip a large file on this thread; cached unless the file changed meanwhile."""
        gzipped = _gzipped(asset.body)
        if gzipped is not None and self._assets.get(relative) is asset:
            self._assets[relative] = dataclasses.replace(asset, gzipped=gzipped)


def _gzipped(body: bytes) -> bytes | None:
    """``body`` gzipped, or None when that is no smaller."""
    packed = gzip.compress(body, compresslevel=GZIP_LEVEL, mtime=0)
    return packed if len(packed) < len(body) else None


def not_a_robot_page(reason: str) -> web.Response:
    """404 for a robot page that does not exist, styled as the pages are: what is wrong.

    Never the names close to the one asked (classmates'): the instructor's log has them.
    """
    return notice_page("No such robot", reason, 404)


def notice_page(title: str, reason: str, status: int) -> web.Response:
    """A page that says one thing (``reason``) under ``title``, styled as the pages are."""
    body = ('<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            '<meta name="referrer" content="no-referrer">'
            f'<title>{html.escape(title)} - websim</title>'
            '<link rel="icon" href="/favicon.svg" type="image/svg+xml">'
            '<link rel="stylesheet" href="/css/style.css"></head>'
            '<body><main class="layout"><section class="card not-found">'
            f'<h1>{html.escape(title)}</h1><p id="reason">{html.escape(reason, quote=False)}</p>'
            '<p>A robot\'s page is <code>/robots/NAME/</code> on this server; your '
            'instructor\'s links name yours (ask them if yours is not there).</p>'
            "</section></main></body></html>")
    return web.Response(status=status, text=body, content_type="text/html")


def _etags(header: str) -> list[str]:
    """The entity tags of an If-None-Match header, weak ones compared as strong."""
    return [tag.strip().removeprefix("W/") for tag in header.split(",")]


class CodeRoutes(Protocol):
    """The Code panel's routes: saving, submitting and the instructor's view of them."""

    def handles(self, path: str) -> bool:
        """Whether ``path`` is one of its routes (any method)."""

    async def respond(self, request: web.BaseRequest) -> web.Response:
        """The answer to a request for one of its routes."""


class LiveDocuments(Protocol):
    """The documents the server fills itself, and which robots (``/robots/NAME/``) exist."""

    def has_robot(self, name: str) -> bool:
        """Whether ``/robots/NAME/`` is a robot's page (False on a single-robot server)."""

    def why_no_robot(self, name: str, address: str = "") -> str:
        """Why ``/robots/NAME/`` is no robot's page, as the student (at ``address``) is told."""

    def root_notice(self) -> str | None:
        """What ``/`` says instead of a robot's page (a class's root), or None: the page."""

    def document(self, robot: str | None, name: str, hostname: str) -> str | None:
        """The text of ``name`` (``robot.json``, ``config.json``) for ``robot``.

        ``robot`` None is the server's own; ``hostname`` is what the browser asked for.
        None: serve the file instead.
        """


async def start_http(host: str, port: int, directory: Path,
                     health: Callable[[str | None], dict[str, Any]],
                     live: LiveDocuments, limits: ClientLimits | None = None,
                     proxies: TrustedProxies | None = None,
                     code: CodeRoutes | None = None) -> HttpServer:
    """Serve the web interface on ``host:port`` on the running event loop.

    Raises the process's soft open-file limit to the hard one first, and sizes the
    connection cap from it.

    Args:
        host: address to bind ("" or "0.0.0.0" for every interface).
        port: TCP port.
        directory: the web folder (``web-interface/``).
        health: the ``/healthz`` document for the token presented (``?token=``; None:
            none), called on the loop per request.
        live: the live ``robot.json`` and ``config.json`` and the robots of a class,
            likewise.
        limits: the client limits (``address_max_connections`` sizes each address's share
            of connections; default: the defaults).
        proxies: the trusted proxies, whose connections are not capped per address.
        code: the Code panel's routes (saving, submitting); None: none.

    Raises:
        OSError: the port cannot be bound (in use, say).
    """
    cap = connection_cap(raise_open_file_limit())
    address_cap = address_connection_cap(limits or ClientLimits())
    trusted = proxies or TrustedProxies()
    server = HttpServer(directory, health, live,
                        ConnectionTable(cap, address_cap, trusted.trusts), code)
    log.debug("HTTP connections capped at %d, %d per address", cap, address_cap)
    try:
        await server.listen(host, port)
    except OSError:
        with contextlib.suppress(Exception):
            await server.close()
        raise
    if code is not None:
        server.warm(PYODIDE_FILES)
    return server
