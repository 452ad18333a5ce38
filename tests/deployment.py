"""The Docker Compose deployment's files, read for the tests/test_deploy_*.py checks.

docker-compose.yml, the Dockerfiles, ros2-bridge/'s rosbridge parameters and launch file, and
web-interface/nginx.conf, parsed as Docker, rosbridge and nginx read them; where the tools
(docker-compose, nginx, openssl) are. No Docker engine is needed, and no image is built.
"""

from __future__ import annotations

import fnmatch
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import Any

import yaml

from classroom.nginx_config import Worker, foreground_command, in_directory, nginx_config
from physics.params import PROJECT_DIR

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


def stage(path: Path, name: str) -> list[tuple[str, str]]:
    """The instructions of build stage ``name`` (``FROM ... AS name``) of a Dockerfile."""
    found: list[tuple[str, str]] = []
    inside = False
    for keyword, args in dockerfile(path):
        if keyword == "FROM":
            inside = args.endswith(f" AS {name}")
        elif inside:
            found.append((keyword, args))
    assert found, f"{path}: no stage {name}"
    return found


SITE_INCLUDES = "/etc/nginx/websim/"
"""Where the web image's nginx reads the include files its site stage writes."""


def docker_site(directory: Path) -> tuple[Path, Path]:
    """What web-interface/Dockerfile's ``site`` stage makes, made here: (site, includes).

    Its COPY instructions from the build context are replayed into ``directory``, the vendor
    stage's node_modules are this checkout's (``npm ci``), and its RUN runs as it is, on
    this Python without its site-packages (``-S``: the stage's python image has only the
    standard library); then the files the last stage adds to the web root (robot.json).
    """
    build = directory / "build"
    run = None
    for keyword, args in stage(WEB_DIR / "Dockerfile", "site"):
        if keyword == "COPY" and args.startswith("--from=vendor "):
            target = build / args.split()[-1]
            shutil.copytree(WEB_DIR / "node_modules", target, symlinks=True)
        elif keyword == "COPY":
            *sources, destination = args.split()
            for source in sources:
                for path in sorted(PROJECT_DIR.glob(source.rstrip("/"))):
                    target = build / destination
                    if destination.endswith("/"):
                        target = target / path.name if len(sources) > 1 or \
                            not source.endswith("/") else target
                    target.parent.mkdir(parents=True, exist_ok=True)
                    if path.is_dir():
                        shutil.copytree(path, target, dirs_exist_ok=True)
                    else:
                        shutil.copyfile(path, target)
        elif keyword == "RUN":
            run = args
    assert run is not None and run.startswith("python -m websim.static_site "), run
    out = run.replace("--out /site", f"--out {directory / 'site'}").replace(
        "--nginx /nginx", f"--nginx {directory / 'nginx'}")
    subprocess.run([sys.executable, "-S", *out.split()[1:]], cwd=build, check=True,
                   capture_output=True, text=True, timeout=120)
    site = directory / "site"
    in_root = False
    for keyword, args in dockerfile(WEB_DIR / "Dockerfile"):  # the web root's own files
        if keyword == "WORKDIR":
            in_root = args == "/usr/share/nginx/html"
        elif keyword == "COPY" and in_root and not args.startswith("--from="):
            *sources, _ = args.split()
            for source in sources:
                shutil.copyfile(PROJECT_DIR / source, site / Path(source).name)
    return site, directory / "nginx"


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


@contextmanager
def running_nginx(directory: Path, workers: list[Worker], http_port: int,
                  ws_port: int) -> Iterator[None]:
    """The real nginx, configured by ``websim nginx-config`` for ``workers``, in front of
    them on ``http_port`` and ``ws_port`` of 127.0.0.1, until the block ends; it answers
    ``/healthz`` when the block starts."""
    from server_process import wait_for

    assert NGINX is not None
    conf = nginx_config(workers, f"127.0.0.1:{http_port}", f"127.0.0.1:{ws_port}")
    path = directory / "nginx.conf"
    path.write_text(in_directory(conf, directory))
    process = subprocess.Popen(foreground_command(str(NGINX), path, directory),
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def answers() -> bool:
        if process.poll() is not None:
            raise AssertionError((directory / "error.log").read_text())
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{http_port}/healthz", timeout=2):
                return True
        except OSError:
            return False

    try:
        wait_for(answers, 10.0, "nginx to answer")
        yield
    finally:
        process.terminate()
        process.wait(timeout=10)
