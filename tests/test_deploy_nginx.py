"""The real nginx binary runs web-interface/nginx.conf in front of a real ``websim serve``
standing in for the ros2-web-bridge container: only the upstream address, the listen port and
file paths are changed, plus temp paths in the test's directory. It serves the site the
image's site stage writes (replayed here: ``deployment.docker_site``). roslibpy reads /odom
through /rosbridge; /admin and its WebSocket need the password that the image's entrypoint
script writes, and nobody gets in when no password is set; the pages carry the headers
``websim serve`` sends, and the Code panel runs a student's Python in headless Chromium.
"""

from __future__ import annotations

import base64
import gzip
import json
import os
import re
import subprocess
import urllib.error
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import roslibpy
from code_page import (
    CODEMIRROR,
    LOAD_TIMEOUT_S,
    PYODIDE,
    code_context,
    open_code,
    run_program,
    set_language,
    type_program,
    wait_output,
)
from deployment import (
    BRIDGE,
    HTPASSWD_SCRIPT,
    NGINX,
    NGINX_CONF,
    OPENSSL,
    SITE_INCLUDES,
    WEB_DIR,
    docker_site,
)
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from classroom.nginx_config import foreground_command, in_directory
from websim.import_map import script_hash
from websim.page_policy import WORKER_POLICIES, page_policy

from chromium import skip_reason
from server_process import ServerProcess, free_port, wait_for

BROWSER_SKIP = skip_reason([CODEMIRROR, PYODIDE])

ADMIN_USER = "teacher"
ADMIN_PASSWORD = "correct horse: battery staple"
"""Spaces and a colon: the password must survive the script and basic auth unchanged."""


@dataclass
class Nginx:
    """A running nginx with the deployment's config; ``url`` is its http://127.0.0.1:PORT."""

    url: str
    htpasswd: Path
    process: subprocess.Popen[bytes]
    site: Path
    """The web root: what the image's site stage wrote."""

    @property
    def ws_url(self) -> str:
        return self.url.replace("http://", "ws://", 1)


@dataclass
class Response:
    status: int
    headers: Any
    body: bytes


def get(url: str, headers: dict[str, str] | None = None) -> Response:
    request = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(request, timeout=5) as response:
            return Response(response.status, response.headers, response.read())
    except urllib.error.HTTPError as error:
        return Response(error.code, error.headers, error.read())


def basic_auth(user: str, password: str) -> dict[str, str]:
    token = base64.b64encode(f"{user}:{password}".encode()).decode()
    return {"Authorization": f"Basic {token}"}


def deployment_conf(server: ServerProcess, directory: Path, port: int, htpasswd: Path,
                    site: Path, includes: Path) -> str:
    """nginx.conf with the test's addresses and paths; everything else unchanged."""
    conf = NGINX_CONF.read_text()
    replacements = {
        "listen 80;": f"listen 127.0.0.1:{port};",
        f"{BRIDGE}:": "127.0.0.1:",
        ":9090;": f":{server.ws_port};",
        ":9091;": f":{server.ws_port};",
        "/usr/share/nginx/html": str(site),
        SITE_INCLUDES: f"{includes}/",
        "/etc/nginx/.htpasswd": str(htpasswd),
        "/var/log/nginx/": f"{directory}/",
    }
    for old, new in replacements.items():
        assert old in conf, f"nginx.conf no longer contains {old!r}"
        conf = conf.replace(old, new)
    return in_directory(conf, directory)


def write_htpasswd(path: Path, **env: str) -> subprocess.CompletedProcess[str]:
    """Run the image's entrypoint script with ``env`` as its only configuration."""
    group = subprocess.run(["id", "-gn"], capture_output=True, text=True, check=True)
    clean = {key: value for key, value in os.environ.items()
             if not key.startswith(("ADMIN_", "HTPASSWD_"))}
    return subprocess.run(["sh", str(HTPASSWD_SCRIPT)], capture_output=True, text=True,
                          check=True, timeout=30,
                          env={**clean, "HTPASSWD_FILE": str(path),
                               "HTPASSWD_GROUP": group.stdout.strip(), **env})


@pytest.fixture(scope="module")
def nginx(server: ServerProcess, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Nginx]:
    if NGINX is None:
        pytest.skip("nginx not installed")
    if OPENSSL is None:
        pytest.skip("openssl not installed")
    if not (WEB_DIR / "node_modules").is_dir():
        pytest.skip("web-interface/node_modules missing (npm ci --prefix web-interface): "
                    "the image's vendor stage")
    directory = tmp_path_factory.mktemp("nginx")
    site, includes = docker_site(directory / "image")
    htpasswd = directory / "htpasswd"
    write_htpasswd(htpasswd, ADMIN_USER=ADMIN_USER, ADMIN_PASSWORD=ADMIN_PASSWORD)
    port = free_port()
    conf = directory / "nginx.conf"
    conf.write_text(deployment_conf(server, directory, port, htpasswd, site, includes))
    log = (directory / "stderr.log").open("wb")
    process = subprocess.Popen(foreground_command(NGINX, conf, directory),
                               stdout=log, stderr=subprocess.STDOUT)
    running = Nginx(f"http://127.0.0.1:{port}", htpasswd, process, site)

    def healthy() -> bool:
        if process.poll() is not None:
            raise AssertionError(f"nginx exited with {process.returncode}:\n"
                                 f"{(directory / 'stderr.log').read_text()}")
        try:
            return get(f"{running.url}/healthz").status == 200
        except OSError:
            return False

    try:
        wait_for(healthy, timeout_s=10.0, what="nginx to answer /healthz")
        yield running
    finally:
        process.terminate()
        process.wait(timeout=10)
        log.close()


@pytest.fixture(scope="module")
def ros(nginx: Nginx) -> Iterator[roslibpy.Ros]:
    """One roslibpy client through nginx's /rosbridge: its Twisted reactor cannot restart."""
    client = roslibpy.Ros(host=f"{nginx.ws_url}/rosbridge")
    client.run(timeout=10)
    yield client
    client.close()


def test_nginx_serves_the_page(nginx: Nginx) -> None:
    response = get(f"{nginx.url}/")
    assert response.headers["Content-Type"].startswith("text/html")
    assert response.status == 200
    assert response.body == (nginx.site / "index.html").read_bytes()
    assert response.headers["Cache-Control"] == "no-cache"


def test_nginx_healthz(nginx: Nginx) -> None:
    response = get(f"{nginx.url}/healthz")
    assert response.status == 200
    assert json.loads(response.body) == {"status": "ok"}


def test_roslibpy_reads_odom_through_the_rosbridge_path(ros: roslibpy.Ros) -> None:
    odoms: list[dict[str, Any]] = []
    listener = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry")
    listener.subscribe(odoms.append)
    wait_for(lambda: len(odoms) >= 3, what="3 /odom messages through nginx")
    listener.unsubscribe()
    assert odoms[0]["header"]["frame_id"] == "odom"
    assert odoms[0]["child_frame_id"] == "base_link"


def test_our_javascript_is_gzipped_and_revalidated(nginx: Nginx) -> None:
    scripts = sorted((WEB_DIR / "js").glob("*.js"), key=lambda path: path.stat().st_size)
    assert scripts, "web-interface/js has no scripts"
    script = scripts[-1]
    response = get(f"{nginx.url}/js/{script.name}", {"Accept-Encoding": "gzip"})
    assert response.status == 200
    assert response.headers["Content-Encoding"] == "gzip"
    assert gzip.decompress(response.body) == script.read_bytes()
    assert response.headers["Cache-Control"] == "no-cache"
    assert "javascript" in response.headers["Content-Type"]


def test_vendor_libraries_are_gzipped_and_cached_long(nginx: Nginx) -> None:
    roslib = WEB_DIR / "node_modules" / "roslib" / "build" / "roslib.min.js"
    if not roslib.exists():
        pytest.skip("web-interface/node_modules not installed (npm ci)")
    response = get(f"{nginx.url}/node_modules/roslib/build/roslib.min.js",
                   {"Accept-Encoding": "gzip"})
    assert response.status == 200
    assert response.headers["Content-Encoding"] == "gzip"
    assert gzip.decompress(response.body) == roslib.read_bytes()
    max_age = re.search(r"max-age=(\d+)", response.headers["Cache-Control"])
    assert max_age and int(max_age[1]) >= 7 * 24 * 3600


def test_admin_page_needs_the_password(nginx: Nginx) -> None:
    for path in ("/admin", "/admin.html", "/admin/rosbridge"):
        refused = get(f"{nginx.url}{path}")
        assert refused.status == 401, path
        assert refused.headers["WWW-Authenticate"].startswith("Basic "), path
        wrong = get(f"{nginx.url}{path}", basic_auth(ADMIN_USER, ADMIN_PASSWORD + "x"))
        assert wrong.status == 401, path
    page = get(f"{nginx.url}/admin", basic_auth(ADMIN_USER, ADMIN_PASSWORD))
    assert page.status == 200
    assert page.body == (nginx.site / "admin.html").read_bytes()
    assert page.headers["Content-Type"].startswith("text/html")
    assert page.headers["Cache-Control"] == "no-cache"


def test_admin_websocket_needs_the_password(nginx: Nginx) -> None:
    url = f"{nginx.ws_url}/admin/rosbridge"
    with pytest.raises(InvalidStatus) as refused:
        connect(url, open_timeout=5)
    assert refused.value.response.status_code == 401
    with connect(url, open_timeout=5,
                 additional_headers=basic_auth(ADMIN_USER, ADMIN_PASSWORD)) as websocket:
        websocket.send(json.dumps({"op": "call_service", "id": "mass",
                                   "service": "/virtual_robot/get_parameters",
                                   "args": {"names": ["mass_kg"]}}))
        answer = json.loads(websocket.recv(timeout=5))
    assert answer["result"] is True
    assert answer["values"]["values"][0]["double_value"] > 0


def test_admin_is_closed_without_credentials_and_opens_with_htpasswd_lines(
        nginx: Nginx) -> None:
    """nginx reads the password file on every request, so rewriting it takes effect at once."""
    own = basic_auth(ADMIN_USER, ADMIN_PASSWORD)
    try:
        closed = write_htpasswd(nginx.htpasswd)
        assert nginx.htpasswd.read_text() == ""
        assert "ADMIN_PASSWORD" in closed.stderr
        assert get(f"{nginx.url}/admin", own).status == 401

        line = subprocess.run([OPENSSL or "openssl", "passwd", "-apr1", "-stdin"],
                              input="other secret", capture_output=True, text=True,
                              check=True).stdout.strip()
        write_htpasswd(nginx.htpasswd, ADMIN_HTPASSWD=f"other:{line}", ADMIN_USER="ignored",
                       ADMIN_PASSWORD="ignored")
        assert get(f"{nginx.url}/admin/rosbridge", own).status == 401
        assert get(f"{nginx.url}/admin/rosbridge",
                   basic_auth("other", "other secret")).status != 401
    finally:
        write_htpasswd(nginx.htpasswd, ADMIN_USER=ADMIN_USER, ADMIN_PASSWORD=ADMIN_PASSWORD)
    assert get(f"{nginx.url}/admin/rosbridge", own).status != 401


ISOLATION = {"Cross-Origin-Opener-Policy": "same-origin",
             "Cross-Origin-Embedder-Policy": "require-corp",
             "Cross-Origin-Resource-Policy": "same-origin"}


def header_values(response: Response, name: str) -> list[str]:
    return list(response.headers.get_all(name) or [])


def test_the_pages_carry_the_import_map_and_the_policy_that_admits_it(nginx: Nginx) -> None:
    """As ``websim serve`` sends them: the editor's import map in the robot's page, admitted
    by its hash and nothing else inline (the pages without a map get the same policy: it
    admits that one script only), cross-origin isolated, framed by nobody."""
    page = get(f"{nginx.url}/")
    script = re.search(rb'<script type="importmap">(.*?)</script>', page.body, re.S)
    assert script is not None
    policy = page_policy(script_hash(script[1].decode()))
    for path in ("/", "/class", "/submissions"):
        response = get(f"{nginx.url}{path}")
        assert response.status == 200, path
        assert header_values(response, "Content-Security-Policy") == [policy], path
        for name, value in {**ISOLATION, "X-Frame-Options": "DENY",
                            "Referrer-Policy": "no-referrer"}.items():
            assert header_values(response, name) == [value], (path, name)


def test_every_file_the_pages_load_is_isolated_too(nginx: Nginx) -> None:
    for path in ("/js/main.js", "/css/style.css", "/node_modules/pyodide/pyodide.mjs",
                 "/node_modules/@codemirror/view/dist/index.js", "/python/websim_worker.py"):
        response = get(f"{nginx.url}{path}")
        assert response.status == 200, path
        for name, value in ISOLATION.items():
            assert header_values(response, name) == [value], (path, name)
        assert header_values(response, "X-Content-Type-Options") == ["nosniff"], path
    assert get(f"{nginx.url}/node_modules/pyodide/package.json").status == 404  # allow-list


@pytest.mark.parametrize("worker", sorted(WORKER_POLICIES))
def test_each_code_worker_is_served_with_its_own_policy_alone(nginx: Nginx, worker: str) -> None:
    """A worker follows the policy it is served with: Pyodide's needs eval and WebAssembly,
    which the page's policy refuses; two policies would both apply."""
    response = get(f"{nginx.url}/{worker}")
    assert response.status == 200
    assert response.body == (WEB_DIR / worker).read_bytes()
    assert header_values(response, "Content-Security-Policy") == [WORKER_POLICIES[worker]]
    assert response.headers["Cache-Control"] == "no-cache"
    for name, value in ISOLATION.items():
        assert header_values(response, name) == [value], name


@pytest.mark.browser
@pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")
def test_the_code_panel_runs_a_students_python_through_the_images_nginx(
        nginx: Nginx, browser: Any) -> None:
    """The Docker stack's page in headless Chromium, under the headers nginx sends (no
    bypass), every other host refused: the Code panel's editor loads by the import map, the
    page is cross-origin isolated, and a program typed there reads the robot's /odom through
    nginx's /rosbridge."""
    url = f"{nginx.url}/?ws={nginx.ws_url}/rosbridge"
    with code_context(browser, nginx.url, nginx.ws_url) as context:
        page = context.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        open_code(page, url)
        assert page.evaluate("() => crossOriginIsolated") is True
        set_language(page, "python")
        type_program(page, ODOM_PROGRAM)
        run_program(page)
        wait_output(page, "odom frame odom", timeout_s=LOAD_TIMEOUT_S)
        assert errors == []


ODOM_PROGRAM = """import os
import time

import roslibpy

ros = roslibpy.Ros(host=os.environ["WEBSIM_URL"])
ros.run()
seen = []
roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(seen.append)
while not seen:
    time.sleep(0.05)
print("odom frame", seen[0]["header"]["frame_id"])
ros.close()
"""
