"""``websim serve``'s HTTP side as a process: what it publishes, and how it holds up.

Real ``websim serve`` processes and real sockets: the allow-list (pages, their files, the
libraries' builds; nothing else, through no symlink or encoded ``..``), ``/robot.json`` and
``/healthz`` answered live, keep-alive, revalidation and gzip, a class loading the page at
once, and a thousand stalled connections next to a browser. ``ConnectionTable``'s eviction
order is checked in-process.
"""

from __future__ import annotations

import asyncio
import gzip
import http.client
import json
import os
import re
import resource
import select
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urljoin, urlsplit

import pytest
from websockets.asyncio.client import connect

from websim.http_server import IDLE_TIMEOUT_S, ConnectionTable, connection_cap
from websim.import_map import with_import_map
from websim.serve import WEB_DIR

from server_process import ADMIN_TOKEN, ServerProcess, free_port, start_server, wait_for

LIBRARIES = WEB_DIR / "node_modules" / "roslib" / "build" / "roslib.min.js"
needs_libraries = pytest.mark.skipif(not LIBRARIES.exists(),
                                     reason="web-interface/node_modules not installed (npm ci)")

REFERENCE = re.compile(
    r"""(?:src|href)="([^"#?]+)"|(?:from|import)\s*\(?\s*['"](\.{1,2}/[^'"]+)['"]""")
"""What a page or module loads: src/href attributes, ES module imports (static and dynamic)."""

FETCHED_BY_SCRIPTS = ("/config.json", "/robot.json")
"""Loaded with fetch() by the pages' modules, not named in a way REFERENCE finds."""

EXPECTED_TYPES = {".html": "text/html", ".js": "text/javascript", ".mjs": "text/javascript",
                  ".css": "text/css", ".json": "application/json", ".svg": "image/svg+xml",
                  ".py": "text/x-python", ".wasm": "application/wasm",
                  ".zip": "application/zip"}


def request(server: ServerProcess, path: str, method: str = "GET",
            headers: dict[str, str] | None = None) -> tuple[int, http.client.HTTPMessage, bytes]:
    """One request with the path sent exactly as given (no normalisation): status, headers,
    body."""
    connection = http.client.HTTPConnection("127.0.0.1", server.http_port, timeout=10)
    try:
        connection.request(method, path, headers=headers or {})
        response = connection.getresponse()
        return response.status, response.headers, response.read()
    finally:
        connection.close()


def crawl(server: ServerProcess, start: tuple[str, ...] = ("/", "/admin")) -> set[str]:
    """Every path the pages load, found the way a browser finds them (pages, then what they
    and their modules reference), plus what their scripts fetch."""
    seen: set[str] = set()
    pending = [*start, *FETCHED_BY_SCRIPTS]
    while pending:
        path = pending.pop()
        if path in seen:
            continue
        seen.add(path)
        status, headers, body = request(server, path)
        assert status == 200, f"{path}: {status}"
        if headers["Content-Type"].startswith(("text/html", "text/javascript")):
            for groups in REFERENCE.findall(body.decode()):
                url = urlsplit(urljoin(f"http://host{path}", next(filter(None, groups))))
                if url.netloc == "host":
                    pending.append(url.path)
    return seen


def served_page() -> bytes:
    """index.html as the server answers it: its import map written in."""
    return with_import_map((WEB_DIR / "index.html").read_bytes(), WEB_DIR)[0]


def file_of(path: str) -> Path:
    return WEB_DIR / {"/": "index.html", "/admin": "admin.html"}.get(path, path.lstrip("/"))


@needs_libraries
def test_every_file_the_pages_load_is_served_with_its_type_and_no_cache(
        server: ServerProcess) -> None:
    loaded = crawl(server)
    assert {"/node_modules/roslib/build/roslib.min.js", "/node_modules/nipplejs/dist/index.js",
            "/node_modules/uplot/dist/uPlot.esm.js", "/node_modules/uplot/dist/uPlot.min.css",
            "/favicon.svg", "/css/style.css", "/js/main.js", "/js/admin.js"} <= loaded
    for path in sorted(loaded - {"/robot.json", "/config.json"}):  # those two: filled live
        status, headers, body = request(server, path)
        expected = file_of(path).read_bytes()
        if file_of(path).suffix == ".html":  # the page as served: its import map written in
            expected = with_import_map(expected, WEB_DIR)[0]
        assert (status, body) == (200, expected), path
        suffix = file_of(path).suffix
        assert headers["Content-Type"].startswith(EXPECTED_TYPES[suffix]), path
        assert headers["Cache-Control"] == "no-cache", path


def test_admin_page_is_served_under_both_names(server: ServerProcess) -> None:
    admin = (WEB_DIR / "admin.html").read_bytes()
    assert request(server, "/admin")[2] == request(server, "/admin.html")[2] == admin
    assert request(server, f"/admin?token={ADMIN_TOKEN}")[2] == admin


def test_robot_json_is_the_live_robot_description(server: ServerProcess) -> None:
    status, headers, body = request(server, "/robot.json")
    assert status == 200 and headers["Content-Type"].startswith("application/json")
    described = json.loads(body)
    assert {"robot", "topics", "parameters"} <= described.keys()
    assert described["topics"]["odom"]["name"] == "/odom"

    async def set_mass(mass_kg: float) -> dict:
        async with connect(server.admin_ws_url) as websocket:
            await websocket.send(json.dumps({
                "op": "call_service", "id": "m", "service": "/virtual_robot/set_parameters",
                "args": {"parameters": [{"name": "mass_kg",
                                         "value": {"type": 3, "double_value": mass_kg}}]}}))
            async with asyncio.timeout(5):
                while True:
                    reply = json.loads(await websocket.recv())
                    if reply.get("op") == "service_response":
                        return dict(reply)

    mass_kg = described["robot"]["mass_kg"] + 0.25
    assert asyncio.run(set_mass(mass_kg))["result"] is True
    assert json.loads(request(server, "/robot.json")[2])["robot"]["mass_kg"] == mass_kg, \
        "robot.json describes the robot as it is now, not the file"
    asyncio.run(set_mass(described["robot"]["mass_kg"]))


def test_healthz_is_computed_for_each_request(server: ServerProcess) -> None:
    status, headers, body = request(server, "/healthz")
    assert status == 200 and headers["Content-Type"].startswith("application/json")
    assert headers["Cache-Control"] == "no-store"
    first = json.loads(body)
    assert first["status"] == "ok"
    wait_for(lambda: server.health()["ticks"] > first["ticks"], what="ticks in /healthz")


@pytest.mark.parametrize("path", [
    "/css/", "/css", "/js/", "/node_modules/", "/node_modules/roslib/",
    "/node_modules/roslib/build/", "/node_modules/roslib/package.json",
    "/node_modules/roslib/src/RosLib.js", "/node_modules/ws/index.js",
    "/node_modules/uplot/dist/uPlot.d.ts", "/node_modules/.package-lock.json",
    "/Dockerfile", "/nginx.conf", "/docker-entrypoint.d/",
    "/docker-entrypoint.d/40-websim-admin-htpasswd.sh", "/package.json",
    "/package-lock.json", "/.dockerignore", "/config.docker.json", "/admin/",
    "/../pyproject.toml", "/js/../../pyproject.toml", "/%2e%2e/pyproject.toml",
    "/js/%2e%2e/%2e%2e/pyproject.toml", "/js/..%2f..%2fpyproject.toml",
    "/%2e%2e%2f%2e%2e%2fpyproject.toml", "/js%5c..%5c..%5cpyproject.toml",
    "//etc/passwd", "/js/main.js%00.html", "/..%2fREADME.md",
])
def test_nothing_else_is_published(server: ServerProcess, path: str) -> None:
    status, _, body = request(server, path)
    assert status == 404, path
    assert b"[project]" not in body and b"root:" not in body


def test_a_symlink_out_of_the_web_folder_is_not_followed(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.js").write_text("secret")
    (outside / "style.css").write_text("secret")
    web = tmp_path / "web"
    web.mkdir()
    shutil.copy(WEB_DIR / "index.html", web / "index.html")
    (web / "js").mkdir()
    (web / "js" / "main.js").write_text("// main")
    (web / "js" / "alias.js").symlink_to("main.js")  # inside, to a published file: fine
    (web / "js" / "escape.js").symlink_to(outside / "secret.js")
    (web / "js" / "config.js").symlink_to(Path("..") / "Dockerfile")  # inside, not published
    (web / "Dockerfile").write_text("FROM secret")
    (web / "css").symlink_to(outside, target_is_directory=True)
    (web / "page.html").symlink_to(outside / "secret.js")
    running = start_server(["--web-dir", str(web)])
    try:
        assert request(running, "/")[0] == 200
        assert request(running, "/js/alias.js")[2] == b"// main"
        for path in ("/js/escape.js", "/js/config.js", "/css/style.css", "/page.html",
                     "/css/secret.js"):
            status, _, body = request(running, path)
            assert status == 404 and b"secret" not in body, path
    finally:
        running.stop()


def test_keep_alive_serves_two_requests_on_one_connection(server: ServerProcess) -> None:
    connection = http.client.HTTPConnection("127.0.0.1", server.http_port, timeout=10)
    try:
        connection.request("GET", "/")
        first = connection.getresponse()
        first.read()
        assert first.status == 200 and first.getheader("Connection", "").lower() != "close"
        opened = connection.sock
        connection.request("GET", "/config.json")
        second = connection.getresponse()
        assert second.status == 200
        config = json.loads(second.read())  # filled by the server: its own bridge
        assert config["ws"] == config["adminWs"] == f"ws://127.0.0.1:{server.ws_port}/"
        assert connection.sock is opened, "the second request reused the connection"
    finally:
        connection.close()


def test_unchanged_files_revalidate_and_text_is_gzipped(server: ServerProcess) -> None:
    script = WEB_DIR / "js" / "connection.js"
    status, headers, _ = request(server, "/js/connection.js")
    assert status == 200 and headers["ETag"]
    assert request(server, "/js/connection.js",
                   headers={"If-None-Match": headers["ETag"]})[0] == 304
    status, headers, body = request(server, "/js/connection.js",
                                    headers={"Accept-Encoding": "gzip, deflate"})
    assert status == 200 and headers["Content-Encoding"] == "gzip"
    assert "Accept-Encoding" in headers["Vary"]
    assert gzip.decompress(body) == script.read_bytes()


def test_only_get_and_head_are_answered(server: ServerProcess) -> None:
    status, headers, body = request(server, "/", method="HEAD")
    assert status == 200 and body == b""
    assert int(headers["Content-Length"]) == len(served_page())
    status, headers, _ = request(server, "/", method="POST")
    assert status == 405 and headers["Allow"] == "GET, HEAD"


def test_forty_simultaneous_page_loads_all_succeed(server: ServerProcess) -> None:
    page = served_page()
    start = threading.Barrier(40)
    results: list[tuple[int, bytes] | BaseException] = []

    def load() -> None:
        try:
            start.wait(timeout=10)
            status, _, body = request(server, "/")
            results.append((status, body))
        except BaseException as error:
            results.append(error)

    threads = [threading.Thread(target=load) for _ in range(40)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=30)
    assert results == [(200, page)] * 40


def closed_by_server(sock: socket.socket, timeout_s: float) -> bool:
    """Whether the server closes ``sock`` within ``timeout_s`` (EOF or reset)."""
    poller = select.poll()  # not select(): descriptors beyond 1024 are likely here
    poller.register(sock, select.POLLIN)
    if not poller.poll(timeout_s * 1e3):
        return False
    try:
        return sock.recv(1) == b""
    except ConnectionError:
        return True


@pytest.mark.slow
def test_a_request_whose_headers_never_arrive_is_closed(server: ServerProcess) -> None:
    with socket.create_connection(("127.0.0.1", server.http_port)) as stalled, \
            socket.create_connection(("127.0.0.1", server.http_port)) as idle:
        stalled.sendall(b"GET /index.html HT")
        assert closed_by_server(stalled, IDLE_TIMEOUT_S + 5)
        assert closed_by_server(idle, 5), "an idle connection too"


@pytest.fixture
def own_fd_headroom() -> Iterator[None]:
    """This process needs more than 1000 sockets at once."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and hard < 1200:
        pytest.skip(f"this process may open only {hard} files")
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    yield
    resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


def test_a_thousand_half_open_connections_do_not_lock_out_a_browser(
        own_fd_headroom: None) -> None:
    limited = start_server(open_files=1024)
    stalled: list[socket.socket] = []
    try:
        for _ in range(1000):
            sock = socket.create_connection(("127.0.0.1", limited.http_port), timeout=10)
            sock.sendall(b"GET /index.ht")
            stalled.append(sock)
        status, _, body = request(limited, "/")
        assert (status, body) == (200, served_page())
        held = sum(not closed_by_server(sock, 0) for sock in stalled)
        assert 0 < held <= connection_cap(1024), "the oldest stalled ones made room"
        assert limited.health()["status"] == "ok"

        async def websocket_opens() -> bool:
            async with connect(limited.ws_url, open_timeout=10) as websocket:
                await websocket.send(json.dumps({"op": "set_level", "level": "none"}))
                return True
        assert asyncio.run(websocket_opens()), "new WebSockets still open"
    finally:
        for sock in stalled:
            sock.close()
        assert limited.stop() == 0
    assert "Traceback" not in "".join(limited.output)


class Transport:
    """What the table asks of an asyncio transport: its peer, and abort."""

    def __init__(self, peer: str = "127.0.0.1") -> None:
        self.aborted = False
        self.peer = peer

    def abort(self) -> None:
        self.aborted = True

    def get_extra_info(self, name: str) -> object:
        return (self.peer, 40000) if name == "peername" else None


def test_connection_table_evicts_the_longest_idle_and_never_a_busy_one() -> None:
    async def scenario() -> list[bool]:
        table = ConnectionTable(cap=2)
        a, b, c, d = (Transport() for _ in range(4))
        table.opened("a", a)
        table.opened("b", b)
        table.begin("a")      # a is answering a request
        table.opened("c", c)  # evicts b, the idle one
        table.begin("c")
        table.opened("d", d)  # both answering: d is refused
        table.end("a")
        return [a.aborted, b.aborted, c.aborted, d.aborted, len(table) == 2]

    assert asyncio.run(scenario()) == [False, True, False, True, True]


def test_one_address_holds_its_share_of_connections_and_evicts_only_its_own() -> None:
    """Beyond ``address_cap``, an address's newcomer evicts that address's longest-idle
    connection, never another address's; all of its own answering, the newcomer is
    refused; a trusted proxy is not capped."""
    async def scenario() -> None:
        table = ConnectionTable(cap=100, address_cap=2,
                                uncapped=lambda address: address == "10.0.0.9")
        healthy = Transport("127.0.0.1")
        table.opened("healthy", healthy)
        mine = [Transport("127.0.0.2") for _ in range(4)]
        table.opened("m0", mine[0])
        table.opened("m1", mine[1])
        table.opened("m2", mine[2])  # evicts m0, its own longest idle
        assert [t.aborted for t in mine[:3]] == [True, False, False]
        table.begin("m1")
        table.begin("m2")
        table.opened("m3", mine[3])  # all of its own answering: refused
        assert mine[3].aborted and not healthy.aborted and len(table) == 3
        proxy = [Transport("10.0.0.9") for _ in range(5)]
        for number, transport in enumerate(proxy):
            table.opened(f"p{number}", transport)
        assert not any(t.aborted for t in proxy) and len(table) == 8
        table.end("m1")
        table.closed("m1")
        table.opened("m4", Transport("127.0.0.2"))  # room again
        assert len(table) == 8

    asyncio.run(scenario())


def test_a_real_server_keeps_one_addresses_idle_sockets_to_its_share() -> None:
    """Idle sockets from 127.0.0.2 beyond its share (twice --max-connections-per-address)
    evict its own oldest; a keep-alive connection of 127.0.0.1 opened first still answers."""
    running = start_server(["--max-connections-per-address", "5"])
    try:
        with socket.create_connection(("127.0.0.1", running.http_port)) as kept:
            attacker = []
            for _ in range(16):
                sock = socket.socket()
                sock.bind(("127.0.0.2", 0))
                sock.connect(("127.0.0.1", running.http_port))
                attacker.append(sock)
            time.sleep(0.5)
            closed = 0
            for sock in attacker:
                sock.settimeout(0.2)
                try:
                    closed += sock.recv(1) == b""
                except ConnectionResetError:
                    closed += 1
                except TimeoutError:
                    pass
            assert closed == 16 - 10, closed
            kept.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
            assert kept.recv(12) == b"HTTP/1.1 200"
            for sock in attacker:
                sock.close()
    finally:
        assert running.stop() == 0


def test_http_port_in_use_is_a_one_line_error() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run(
            [sys.executable, "-m", "websim.cli", "serve", "--ws-port", str(free_port()),
             "--http-port", str(port)], capture_output=True, text=True, timeout=30,
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert result.returncode == 1
    assert result.stderr.strip().splitlines() == [
        f"websim: error: HTTP port 127.0.0.1:{port} is already in use "
        "(is another websim running?)"]


def test_sigterm_stops_cleanly_with_connections_open() -> None:
    running = start_server()
    with socket.create_connection(("127.0.0.1", running.http_port)) as stalled, \
            socket.create_connection(("127.0.0.1", running.http_port)) as kept:
        stalled.sendall(b"GET / HTTP/1.1\r\nHost: x")
        kept.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        assert kept.recv(12) == b"HTTP/1.1 200"
        assert running.stop(timeout_s=10) == 0
    output = "".join(running.output)
    assert "websim: stopped" in output and "Traceback" not in output
