"""The Docker Compose deployment, checked without a Docker engine.

* ``docker-compose config`` accepts docker-compose.yml, and the compose file, the Dockerfiles,
  nginx.conf, the rosbridge globs and the launch file agree with each other (ports, names,
  health checks, build contexts that hold every COPY source).
* The real nginx binary runs web-interface/nginx.conf in front of a real ``websim serve``
  standing in for the ros2-web-bridge container: only the upstream address, the listen port
  and file paths are changed, plus temp paths in the test's directory. roslibpy reads /odom
  through /rosbridge; /admin and its WebSocket need the password that the image's entrypoint
  script writes, and nobody gets in when no password is set.
* The "class" profile (two ``websim serve --class --worker`` containers behind an nginx):
  ``docker-compose --profile class config`` accepts it, its ports stay off the stack's,
  web-interface/nginx-class.conf is exactly what ``websim nginx-config`` prints for the
  workers the compose file declares, and the real nginx accepts that file (``nginx -t``).

No image is built here: the Dockerfiles' RUN steps (apt, pip, npm) are not exercised.
"""

from __future__ import annotations

import base64
import fnmatch
import gzip
import importlib.util
import json
import os
import re
import shutil
import subprocess
import urllib.error
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
import roslibpy
import yaml
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from classroom.nginx_config import foreground_command, in_directory
from physics.params import PROJECT_DIR
from ros_nodes.parameters import RobotParameters
from ros_nodes.robot_interface import ROBOT_TOPICS
from websim import cli

from server_process import ServerProcess, free_port, wait_for

COMPOSE_FILE = PROJECT_DIR / "docker-compose.yml"
BRIDGE_DIR = PROJECT_DIR / "ros2-bridge"
WEB_DIR = PROJECT_DIR / "web-interface"
NGINX_CONF = WEB_DIR / "nginx.conf"
HTPASSWD_SCRIPT = WEB_DIR / "docker-entrypoint.d" / "40-websim-admin-htpasswd.sh"
PARAMS_FILE = BRIDGE_DIR / "rosbridge_params.yaml"
LAUNCH_FILE = BRIDGE_DIR / "websim.launch.py"

BRIDGE = "ros2-web-bridge"
WEB = "web-interface"
CLASS_PROFILE = "class"
CLASS_NGINX = "class-nginx"
CLASS_NGINX_CONF = WEB_DIR / "nginx-class.conf"
CLASS_CONF_TARGET = "/etc/nginx/nginx.conf"
STUDENT_BRIDGE = "/rosbridge_websocket"
ADMIN_BRIDGE = "/admin/rosbridge_websocket"
ROSAPI = "/rosapi_node"

ADMIN_USER = "teacher"
ADMIN_PASSWORD = "correct horse: battery staple"
"""Spaces and a colon: the password must survive the script and basic auth unchanged."""

DOCKER_COMPOSE = shutil.which("docker-compose")
NGINX = shutil.which("nginx") or next(
    (path for path in ("/usr/sbin/nginx",) if os.access(path, os.X_OK)), None)
OPENSSL = shutil.which("openssl")


# --- parsing helpers --------------------------------------------------------------------------

def load_yaml(path: Path) -> Any:
    return yaml.safe_load(path.read_text())


def compose() -> dict[str, Any]:
    return dict(load_yaml(COMPOSE_FILE))


def default_services(services: dict[str, Any] | None = None) -> dict[str, Any]:
    """The services ``docker-compose up`` starts: those in no profile."""
    services = compose()["services"] if services is None else services
    return {name: body for name, body in services.items() if not body.get("profiles")}


def class_workers(services: dict[str, Any] | None = None) -> list[str]:
    """The class profile's worker services, class-worker-1, class-worker-2, ... in order."""
    services = compose()["services"] if services is None else services
    found = [name for name in services if re.fullmatch(r"class-worker-\d+", name)]
    return sorted(found, key=lambda name: int(name.rpartition("-")[2]))


def worker_script(service: str) -> str:
    """A class worker's ``sh -c`` script, as its container runs it (compose's ``$$`` is $)."""
    command = compose()["services"][service]["command"]
    assert command[:2] == ["sh", "-c"], command
    return str(command[2]).replace("$$", "$")


def option(script: str, name: str) -> str:
    """The value after ``--name`` in a command line."""
    found = re.search(rf"--{name} (\S+)", script)
    assert found, f"no --{name} in {script!r}"
    return found[1]


def compose_env(**values: str) -> dict[str, str]:
    """This process's environment without compose's variables, plus ``values``."""
    env = {key: value for key, value in os.environ.items()
           if not key.startswith(("ADMIN_", "CLASS_", "ROS_DISTRO"))}
    return {**env, **values}


def dockerfile(path: Path) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of a Dockerfile: continuations joined, comments dropped."""
    instructions: list[tuple[str, str]] = []
    pending = ""
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        keyword, _, arguments = (pending + line).partition(" ")
        instructions.append((keyword.upper(), " ".join(arguments.split())))
        pending = ""
    assert not pending, f"{path}: dangling line continuation"
    return instructions


def build_of(service: str) -> tuple[Path, Path]:
    """(build context, Dockerfile) of a compose service."""
    build = compose()["services"][service]["build"]
    if isinstance(build, str):
        build = {"context": build}
    context = (PROJECT_DIR / build["context"]).resolve()
    return context, context / build.get("dockerfile", "Dockerfile")


def parse_glob(value: str) -> list[str]:
    """A glob parameter as rosbridge and rosapi parse it: "[a, b]" -> ["a", "b"]."""
    assert value.startswith("[") and value.endswith("]"), value
    return [item.strip().strip("'") for item in value[1:-1].split(",")
            if item.strip().strip("'")]


def node_params() -> dict[str, dict[str, Any]]:
    """ros__parameters per fully qualified node name."""
    return {"/" + name.lstrip("/"): body["ros__parameters"]
            for name, body in load_yaml(PARAMS_FILE).items()}


def allowed(globs: list[str], name: str) -> bool:
    return any(fnmatch.fnmatch(name, pattern) for pattern in globs)


def student_services() -> list[str]:
    """The students' service globs, with the /rosapi/* rosbridge always adds."""
    return [*parse_glob(node_params()[STUDENT_BRIDGE]["services_glob"]), "/rosapi/*"]


def nginx_upstreams() -> dict[str, tuple[str, int]]:
    """nginx's `set $NAME HOST:PORT;` upstream variables."""
    found = re.findall(r"set \$(\w+) ([\w.-]+):(\d+);", NGINX_CONF.read_text())
    return {name: (host, int(port)) for name, host, port in found}


def load_healthcheck() -> ModuleType:
    spec = importlib.util.spec_from_file_location("healthcheck", BRIDGE_DIR / "healthcheck.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# --- docker-compose.yml and the Dockerfiles ---------------------------------------------------

@pytest.mark.skipif(DOCKER_COMPOSE is None, reason="docker-compose not installed")
def test_docker_compose_config_accepts_the_file() -> None:
    env = {**os.environ, "ROS_DISTRO": "jazzy"}
    for name in ("ADMIN_USER", "ADMIN_PASSWORD", "ADMIN_HTPASSWD"):
        env.pop(name, None)
    assert DOCKER_COMPOSE is not None
    result = subprocess.run([DOCKER_COMPOSE, "-f", str(COMPOSE_FILE), "config"], env=env,
                            capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    assert "WARNING" not in result.stderr, result.stderr
    resolved = yaml.safe_load(result.stdout)
    services = default_services(resolved["services"])  # docker-compose 1.x lists the rest too
    assert set(services) == {BRIDGE, WEB}
    assert services[BRIDGE]["build"]["args"]["ROS_DISTRO"] == "jazzy"
    published = {(port["published"], port["target"])
                 for service in services.values() for port in service["ports"]}
    assert published == {(9090, 9090), (8080, 80)}
    # Unset credentials stay empty: the entrypoint script then closes /admin.
    assert services[WEB]["environment"]["ADMIN_PASSWORD"] == ""


def test_compose_has_both_services_on_one_network_with_restart_and_healthchecks() -> None:
    services = default_services()
    assert set(services) == {BRIDGE, WEB}
    assert services[BRIDGE]["ports"] == ["9090:9090"]
    assert services[WEB]["ports"] == ["8080:80"]
    for name, service in services.items():
        assert service["restart"] == "unless-stopped", name
        assert service["healthcheck"]["test"][0] == "CMD", name
        assert len(service["networks"]) == 1, name
        assert "platform" not in service, name
    assert services[BRIDGE]["networks"] == services[WEB]["networks"]
    assert build_of(BRIDGE) == (PROJECT_DIR, BRIDGE_DIR / "Dockerfile")
    assert build_of(WEB) == (WEB_DIR, WEB_DIR / "Dockerfile")


# --- the class profile: workers behind nginx -------------------------------------------------

def class_ports() -> tuple[str, str]:
    """(page port, WebSocket port) every class worker listens on, and nginx in front too."""
    scripts = [worker_script(name) for name in class_workers()]
    ports = {(option(script, "http-port"), option(script, "ws-port")) for script in scripts}
    assert len(ports) == 1, f"the workers listen on different ports: {ports}"
    return ports.pop()


@pytest.mark.skipif(DOCKER_COMPOSE is None, reason="docker-compose not installed")
def test_docker_compose_config_accepts_the_class_profile_beside_the_stack() -> None:
    assert DOCKER_COMPOSE is not None
    for token in ("", "s3cret"):  # unset, it is accepted all the same (see the worker's test)
        env = compose_env(**({"CLASS_ADMIN_TOKEN": token} if token else {}))
        result = subprocess.run([DOCKER_COMPOSE, "-f", str(COMPOSE_FILE), "--profile",
                                 CLASS_PROFILE, "config"], env=env, capture_output=True,
                                text=True, timeout=60, check=False)
        assert result.returncode == 0, result.stderr
        assert "WARNING" not in result.stderr, result.stderr
        services = yaml.safe_load(result.stdout)["services"]
        workers = class_workers(services)
        assert workers == ["class-worker-1", "class-worker-2"]
        assert set(services) == {BRIDGE, WEB, CLASS_NGINX, *workers}
        for name in (CLASS_NGINX, *workers):
            assert services[name]["profiles"] == [CLASS_PROFILE], name
            assert services[name]["networks"] == services[BRIDGE]["networks"], name
            assert services[name]["restart"] == "unless-stopped", name
        for worker in workers:
            body = services[worker]
            assert body["build"] == services[BRIDGE]["build"], "the ros2-web-bridge image"
            assert body["environment"]["CLASS_ADMIN_TOKEN"] == token
            assert "ports" not in body, "reached through the class's nginx only"
            assert set(body["volumes"]) == {f"{PROJECT_DIR / 'class'}:/class:ro",
                                            f"{WEB_DIR}:/opt/websim/web-interface:ro"}
        nginx = services[CLASS_NGINX]
        assert nginx["build"] == services[WEB]["build"], "the web-interface image"
        assert nginx["volumes"] == [f"{CLASS_NGINX_CONF}:{CLASS_CONF_TARGET}:ro"]
        assert set(nginx["depends_on"]) == set(workers)
        published = {(port["published"], port["target"]) for port in nginx["ports"]}
        http, ws = class_ports()
        assert published == {(int(http), int(http)), (int(ws), int(ws))}
        stack = {port["published"] for name in (BRIDGE, WEB) for port in services[name]["ports"]}
        assert stack == {8080, 9090}, "the stack's ports are as they were"
        assert not stack & {host for host, _ in published}, "the class collides with the stack"


def test_a_class_worker_runs_websim_serve_on_its_ports_and_refuses_without_a_token() -> None:
    """Each worker's ``sh -c`` script run here for real, with ``exec websim`` replaced by a
    printf of its arguments, which websim's own parser then reads."""
    http, ws = class_ports()
    for worker in class_workers():
        script = worker_script(worker)
        assert "exec websim serve " in script
        refused = subprocess.run(["sh", "-c", script], env=compose_env(), capture_output=True,
                                 text=True, timeout=10, check=False)
        assert refused.returncode != 0 and refused.stdout == ""
        assert "set CLASS_ADMIN_TOKEN, the instructor's token" in refused.stderr
        printing = script.replace("exec websim", "exec printf '%s\\n' websim")
        printed = subprocess.run(["sh", "-c", printing],
                                 env=compose_env(CLASS_ADMIN_TOKEN="two words"),
                                 capture_output=True, text=True, timeout=10, check=True)
        argv = printed.stdout.splitlines()
        assert argv[:2] == ["websim", "serve"]
        args = cli.build_parser().parse_args(argv[1:])
        assert (args.class_spec, args.worker, args.host) == ("/class/roster.txt", True, "0.0.0.0")
        assert (args.http_port, args.ws_port, args.admin_token) == (int(http), int(ws),
                                                                     "two words")
        assert args.public_ws_port is None, "its own WebSocket port is the public one"
        healthcheck = compose()["services"][worker]["healthcheck"]["test"]
        assert f"http://127.0.0.1:{http}/healthz" in " ".join(healthcheck)
    nginx_check = compose()["services"][CLASS_NGINX]["healthcheck"]["test"]
    assert nginx_check[-1] == f"http://127.0.0.1:{http}/workers.json"


def test_the_class_nginx_conf_is_what_websim_nginx_config_prints(
        capsys: pytest.CaptureFixture[str]) -> None:
    """For the workers docker-compose.yml declares: a worker added there without the conf
    regenerated (the header's command) fails here."""
    http, ws = class_ports()
    workers = [f"{name}:{http}:{ws}" for name in class_workers()]
    assert cli.main(["nginx-config", "--workers", *workers, "--listen-http", http,
                     "--listen-ws", ws]) == 0
    assert capsys.readouterr().out == CLASS_NGINX_CONF.read_text()
    header = COMPOSE_FILE.read_text()
    assert f"--listen-http {http} --listen-ws {ws} > web-interface/{CLASS_NGINX_CONF.name}" \
        in header


@pytest.mark.skipif(NGINX is None, reason="nginx not installed")
def test_the_real_nginx_accepts_the_class_conf(tmp_path: Path) -> None:
    """``nginx -t`` on web-interface/nginx-class.conf: a check of syntax and directives, not a
    run (tests/test_scale_out.py runs ``websim nginx-config``'s output in front of real
    workers). nginx resolves upstream hosts while it tests, and the compose service names
    resolve only in Docker's network, so they become 127.0.0.1 (nothing need listen there:
    ``nginx -t`` connects to nothing and binds nothing). The error log, pid and temp paths go
    to the test's directory; nothing else changes."""
    assert NGINX is not None
    conf = CLASS_NGINX_CONF.read_text()
    for worker in class_workers():
        assert f"server {worker}:" in conf and f"http://{worker}:" in conf, worker
        conf = conf.replace(f"{worker}:", "127.0.0.1:")
    path = tmp_path / "nginx.conf"
    path.write_text(in_directory(conf, tmp_path))
    result = subprocess.run(foreground_command(NGINX, path, tmp_path, test=True),
                            capture_output=True, text=True, timeout=30, check=False)
    assert result.returncode == 0, result.stderr
    assert "test is successful" in result.stderr


def test_nothing_is_tied_to_amd64() -> None:
    """The Pi 4B is arm64: no platform pins, no architecture-specific downloads."""
    texts = {"docker-compose.yml": yaml.safe_dump(compose())}
    for service in (BRIDGE, WEB):
        _, path = build_of(service)
        texts[str(path)] = "\n".join(" ".join(pair) for pair in dockerfile(path))
    for name, text in texts.items():
        for marker in ("platform", "amd64", "x86_64", "x86-64"):
            assert marker not in text.lower(), f"{name} mentions {marker}"


def test_bridge_dockerfile_uses_the_distro_argument_everywhere() -> None:
    instructions = dockerfile(BRIDGE_DIR / "Dockerfile")
    assert instructions[0] == ("ARG", "ROS_DISTRO=humble")
    froms = [args for keyword, args in instructions if keyword == "FROM"]
    assert froms == ["ros:${ROS_DISTRO}-ros-base"]
    runs = " ".join(args for keyword, args in instructions if keyword == "RUN")
    assert "ros-${ROS_DISTRO}-rosbridge-server" in runs
    assert not re.search(r"ros-(humble|jazzy|iron|rolling)-", runs), "a distro spelled out"
    cmd = json.loads(dict(instructions)["CMD"])
    assert cmd[:2] == ["ros2", "launch"]
    assert Path(cmd[2]).name == LAUNCH_FILE.name


def test_web_dockerfile_builds_vendor_files_with_npm_ci_and_serves_with_nginx() -> None:
    instructions = dockerfile(WEB_DIR / "Dockerfile")
    froms = [args for keyword, args in instructions if keyword == "FROM"]
    assert len(froms) == 2
    assert froms[0].startswith("node:") and froms[0].endswith(" AS vendor")
    assert froms[1].startswith("nginx:")
    runs = [args for keyword, args in instructions if keyword == "RUN"]
    assert any(run.startswith("npm ci") for run in runs)
    copies = [args for keyword, args in instructions if keyword == "COPY"]
    assert "nginx.conf /etc/nginx/nginx.conf" in copies
    assert f"docker-entrypoint.d/{HTPASSWD_SCRIPT.name} /docker-entrypoint.d/" in copies
    assert any(copy.startswith("--from=vendor ") and "node_modules" in copy for copy in copies)


@pytest.mark.parametrize("service", [BRIDGE, WEB])
def test_every_copy_source_exists_in_the_build_context(service: str) -> None:
    context, path = build_of(service)
    for keyword, args in dockerfile(path):
        if keyword != "COPY" or args.startswith("--from="):
            continue
        *sources, _destination = [word for word in args.split() if not word.startswith("--")]
        for source in sources:
            assert list(context.glob(source.rstrip("/"))), f"{path}: COPY {source}: no such file"


def published_sources() -> list[str]:
    """What web-interface/Dockerfile copies from the build context into nginx's web root."""
    sources: list[str] = []
    in_root = False
    for keyword, args in dockerfile(WEB_DIR / "Dockerfile"):
        if keyword == "WORKDIR":
            in_root = args == "/usr/share/nginx/html"
        elif keyword == "COPY" and in_root and not args.startswith("--from="):
            sources += args.split()[:-1]
    return sources


def page_references() -> set[str]:
    """Web-root paths the pages and their modules load (src, href, import ... from)."""
    references: set[str] = set()
    for page in WEB_DIR.glob("*.html"):
        for url in re.findall(r'(?:src|href)="([^"#?]*)', page.read_text()):
            if not re.match(r"[a-z]+:|/|$", url):
                references.add(url.removeprefix("./"))
    for module in (WEB_DIR / "js").glob("*.js"):
        for url in re.findall(r"""from ['"](\.{1,2}/[^'"]+)['"]""", module.read_text()):
            references.add(str((module.parent / url).resolve().relative_to(WEB_DIR)))
    return references


def test_everything_the_pages_load_is_in_the_image() -> None:
    routes = {"", "admin"}  # nginx locations, not files
    sources = published_sources()
    missing = []
    for path in sorted(page_references() - routes):
        if path.startswith("node_modules/"):  # the vendor stage's npm ci
            installed = (WEB_DIR / "node_modules").exists()
            published = not installed or (WEB_DIR / path).is_file()
        else:
            published = (WEB_DIR / path).is_file() and any(
                fnmatch.fnmatch(path, source) or path.startswith(source.rstrip("/") + "/")
                for source in sources)
        if not published:
            missing.append(path)
    assert not missing, f"loaded by the pages but not in the image: {missing}"


def test_docker_pages_send_the_admin_page_to_the_password_protected_bridge() -> None:
    config = json.loads((WEB_DIR / "config.docker.json").read_text())
    assert config["adminWs"] == "/admin/rosbridge" and config["ws"] is None
    dockerfile = (WEB_DIR / "Dockerfile").read_text()
    assert "COPY config.docker.json config.json" in dockerfile
    nginx = (WEB_DIR / "nginx.conf").read_text()
    assert "location ^~ /admin" in nginx and "location = /admin/rosbridge" in nginx


@pytest.mark.parametrize("service", [BRIDGE, WEB])
def test_compose_healthcheck_is_the_images_healthcheck(service: str) -> None:
    """The image carries its HEALTHCHECK (docker run); compose repeats it (docker-compose ps)."""
    _, path = build_of(service)
    line = dict(dockerfile(path))["HEALTHCHECK"]
    options, _, command = line.partition(" CMD ")
    in_image = dict(option.removeprefix("--").split("=") for option in options.split())
    in_compose = compose()["services"][service]["healthcheck"]
    assert in_compose["test"] == ["CMD", *json.loads(command)]
    for key in ("interval", "timeout", "start-period", "retries"):
        assert str(in_compose[key.replace("-", "_")]) == in_image[key], key


def test_launch_file_starts_the_robot_and_the_nodes_the_params_file_configures() -> None:
    source = LAUNCH_FILE.read_text()
    compile(source, str(LAUNCH_FILE), "exec")
    assert '["websim-robot"]' in source
    nodes = re.findall(r'Node\(package="(\w+)", executable="(\w+)",\s*name="(\w+)"'
                       r'(?:, namespace="(\w+)")?', source)
    qualified = {f"/{namespace}/{name}" if namespace else f"/{name}"
                 for _, _, name, namespace in nodes}
    assert qualified == set(node_params()) == {STUDENT_BRIDGE, ADMIN_BRIDGE, ROSAPI}
    assert source.count("on_exit=Shutdown(") == 4


def test_the_robot_console_script_the_launch_file_runs_is_declared() -> None:
    pyproject = (PROJECT_DIR / "pyproject.toml").read_text()
    assert re.search(r'^websim-robot = "', pyproject, re.MULTILINE), \
        "pyproject.toml [project.scripts] has no websim-robot"


# --- what each rosbridge lets through ---------------------------------------------------------

def test_globs_are_nonempty_lists() -> None:
    """An empty list means "everything" to the Humble release of rosbridge."""
    for node, params in node_params().items():
        for key, value in params.items():
            if key.endswith("_glob"):
                assert parse_glob(value), f"{node} {key} is empty"


def test_students_reach_the_robots_topics_and_nothing_else() -> None:
    robot_topics = {spec.name for spec in ROBOT_TOPICS}
    for node in (STUDENT_BRIDGE, ADMIN_BRIDGE, ROSAPI):
        globs = parse_glob(node_params()[node]["topics_glob"])
        assert {name for name in robot_topics if allowed(globs, name)} == robot_topics
        for other in ("/rosout", "/parameter_events", "/client_count", "/odom_fake"):
            assert not allowed(globs, other), (node, other)


def test_students_may_reset_and_read_parameters_but_not_change_them() -> None:
    globs = student_services()
    for name in ("/reset_simulation", "/virtual_robot/get_parameters",
                 "/virtual_robot/list_parameters", "/virtual_robot/describe_parameters",
                 "/virtual_robot/get_parameter_types", "/rosapi/topics"):
        assert allowed(globs, name), name
    for name in ("/virtual_robot/set_parameters", "/virtual_robot/set_parameters_atomically",
                 "/rosbridge_websocket/set_parameters", f"{ADMIN_BRIDGE}/set_parameters",
                 f"{ROSAPI}/set_parameters", "virtual_robot/set_parameters"):
        assert not allowed(globs, name), name


def test_rosapis_own_parameter_services_are_outside_the_always_open_rosapi_glob() -> None:
    assert not ROSAPI.startswith("/rosapi/")
    assert not allowed(student_services(), f"{ROSAPI}/set_parameters")


def test_admin_bridge_may_change_parameters_on_its_own_unpublished_port() -> None:
    params = node_params()
    admin = params[ADMIN_BRIDGE]
    assert allowed(parse_glob(admin["services_glob"]), "/virtual_robot/set_parameters")
    assert admin["port"] != params[STUDENT_BRIDGE]["port"]
    published = [int(port.split(":")[1]) for port in compose()["services"][BRIDGE]["ports"]]
    assert published == [params[STUDENT_BRIDGE]["port"]]


def test_rosapi_gives_nobody_any_parameter() -> None:
    globs = parse_glob(node_params()[ROSAPI]["params_glob"])
    for name in [*RobotParameters.names(), "use_sim_time", "port", "params_glob"]:
        assert not allowed(globs, name), name


def test_nginx_and_the_healthcheck_use_the_bridges_ports() -> None:
    params = node_params()
    student, admin = params[STUDENT_BRIDGE]["port"], params[ADMIN_BRIDGE]["port"]
    assert nginx_upstreams() == {"rosbridge": (BRIDGE, student),
                                 "rosbridge_admin": (BRIDGE, admin)}
    healthcheck = load_healthcheck()
    defaults = healthcheck.STUDENT_URL, healthcheck.ADMIN_URL
    assert defaults == (f"ws://127.0.0.1:{student}", f"ws://127.0.0.1:{admin}")


# --- the bridge healthcheck against a real server ---------------------------------------------

def test_healthcheck_passes_on_a_live_bridge(server: ServerProcess) -> None:
    healthcheck = load_healthcheck()
    assert healthcheck.main(["--url", server.ws_url, "--admin-url", server.ws_url]) == 0


def test_healthcheck_fails_when_nothing_listens(capsys: pytest.CaptureFixture[str]) -> None:
    healthcheck = load_healthcheck()
    closed = f"ws://127.0.0.1:{free_port()}"
    assert healthcheck.main(["--url", closed, "--timeout", "2"]) == 1
    assert "unhealthy" in capsys.readouterr().out


# --- the real nginx in front of a real websim serve -------------------------------------------

@dataclass
class Nginx:
    """A running nginx with the deployment's config; ``url`` is its http://127.0.0.1:PORT."""

    url: str
    htpasswd: Path
    process: subprocess.Popen[bytes]

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


def deployment_conf(server: ServerProcess, directory: Path, port: int, htpasswd: Path) -> str:
    """nginx.conf with the test's addresses and paths; everything else unchanged."""
    conf = NGINX_CONF.read_text()
    replacements = {
        "listen 80;": f"listen 127.0.0.1:{port};",
        f"{BRIDGE}:": "127.0.0.1:",
        ":9090;": f":{server.ws_port};",
        ":9091;": f":{server.ws_port};",
        "/usr/share/nginx/html": str(WEB_DIR),
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
    directory = tmp_path_factory.mktemp("nginx")
    htpasswd = directory / "htpasswd"
    write_htpasswd(htpasswd, ADMIN_USER=ADMIN_USER, ADMIN_PASSWORD=ADMIN_PASSWORD)
    port = free_port()
    conf = directory / "nginx.conf"
    conf.write_text(deployment_conf(server, directory, port, htpasswd))
    log = (directory / "stderr.log").open("wb")
    process = subprocess.Popen(foreground_command(NGINX, conf, directory),
                               stdout=log, stderr=subprocess.STDOUT)
    running = Nginx(f"http://127.0.0.1:{port}", htpasswd, process)

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
    page = WEB_DIR / "index.html"
    if page.exists():
        response = get(f"{nginx.url}/")
        assert response.headers["Content-Type"].startswith("text/html")
    else:  # the frontend is not there yet: any static file proves the static serving
        page = WEB_DIR / "package.json"
        response = get(f"{nginx.url}/package.json")
    assert response.status == 200
    assert response.body == page.read_bytes()
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
    assert page.body == (WEB_DIR / "admin.html").read_bytes()
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
