"""The Dockerfiles and the compose file agree with each other and with the repository: no
amd64 pins, the ROS distribution an argument, build contexts that hold every COPY source and
everything the pages load, health checks repeated in compose, and a launch file that starts the
robot and the nodes the rosbridge parameters configure.

No image is built here: the Dockerfiles' RUN steps (apt, pip, npm) are not exercised, but the
web image's site stage is replayed (its COPYs, and its standard-library RUN).
"""

from __future__ import annotations

import ast
import json
import re
import sys
from pathlib import Path

import pytest
import tomllib
import yaml
from deployment import (
    ADMIN_BRIDGE,
    BRIDGE,
    BRIDGE_DIR,
    HTPASSWD_SCRIPT,
    LAUNCH_FILE,
    ROSAPI,
    SITE_INCLUDES,
    STUDENT_BRIDGE,
    WEB,
    WEB_DIR,
    build_of,
    compose,
    docker_site,
    dockerfile,
    node_params,
    stage,
)

from physics.params import PROJECT_DIR
from websim.static_site import INCLUDES


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
    assert len(froms) == 3
    assert froms[0].startswith("node:") and froms[0].endswith(" AS vendor")
    assert froms[1].startswith("python:") and froms[1].endswith(" AS site")
    assert froms[2].startswith("nginx:")
    runs = [args for keyword, args in instructions if keyword == "RUN"]
    assert any(run.startswith("npm ci") for run in runs)
    site_runs = [args for keyword, args in stage(WEB_DIR / "Dockerfile", "site")
                 if keyword == "RUN"]
    assert site_runs == ["python -m websim.static_site --web web --out /site --nginx /nginx"]
    copies = [args for keyword, args in instructions if keyword == "COPY"]
    assert "web-interface/nginx.conf /etc/nginx/nginx.conf" in copies
    assert f"web-interface/docker-entrypoint.d/{HTPASSWD_SCRIPT.name} /docker-entrypoint.d/" \
        in copies
    assert any(copy.startswith("--from=vendor ") and "node_modules" in copy for copy in copies)
    assert f"--from=site /nginx/ {SITE_INCLUDES}" in copies
    assert "--from=site /site/ ./" in copies


def test_the_site_stage_needs_only_the_standard_library() -> None:
    """The python image of the site stage has no websim dependencies: the modules it copies
    import only the standard library and each other."""
    copied = [word for keyword, args in stage(WEB_DIR / "Dockerfile", "site")
              if keyword == "COPY" and not args.startswith("--from=")
              for word in args.split()[:-1] if word.startswith("websim/")]
    assert "websim/static_site.py" in copied
    names = {Path(path).stem for path in copied}
    for path in copied:
        tree = ast.parse((PROJECT_DIR / path).read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                module = node.module
            elif isinstance(node, ast.Import):
                module = node.names[0].name
            else:
                continue
            top, _, rest = module.partition(".")
            if top == "websim":
                assert rest in names, f"{path} imports {module}, which the stage lacks"
            else:
                assert top in sys.stdlib_module_names, f"{path} imports {module}"


@pytest.mark.parametrize("service", [BRIDGE, WEB])
def test_every_copy_source_exists_in_the_build_context(service: str) -> None:
    context, path = build_of(service)
    checked = []
    for keyword, args in dockerfile(path):
        if keyword != "COPY" or args.startswith("--from="):
            continue
        *sources, _destination = [word for word in args.split() if not word.startswith("--")]
        for source in sources:
            assert list(context.glob(source.rstrip("/"))), f"{path}: COPY {source}: no such file"
            checked.append(source)
    assert checked, f"{path}: no COPY from the build context found: nothing was checked"


def test_the_bridge_image_carries_every_python_package_of_the_project() -> None:
    """``pip install -e .`` in the image needs every package pyproject.toml names (a folder
    the image lacks installs and then fails to import)."""
    project = tomllib.loads((PROJECT_DIR / "pyproject.toml").read_text(encoding="utf-8"))
    packages = [pattern.rstrip("*") for pattern in
                project["tool"]["setuptools"]["packages"]["find"]["include"]]
    copied = {args.split()[0].rstrip("/") for keyword, args in
              dockerfile(PROJECT_DIR / "ros2-bridge" / "Dockerfile") if keyword == "COPY"}
    assert packages and set(packages) <= copied, sorted(set(packages) - copied)


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


@pytest.mark.skipif(not (WEB_DIR / "node_modules").is_dir(),
                    reason="web-interface/node_modules missing: npm ci --prefix web-interface")
def test_everything_the_pages_load_is_in_the_image(tmp_path: Path) -> None:
    """The site stage run here (its COPYs and its RUN): every file a page or module loads
    is in the site, the pages carry the editor's import map, and every file the map names
    is there too."""
    site, includes = docker_site(tmp_path)
    routes = {"", "admin"}  # nginx locations, not files
    loaded = sorted(page_references() - routes)
    assert {"js/main.js", "js/admin.js", "css/style.css", "js/code-editor.js"} <= set(loaded), \
        f"the pages' own files are missing from what they were found to load: {loaded}"
    # a clean URL (/class) is its page: nginx.conf's try_files $uri.html
    missing = [path for path in loaded
               if not (site / path).is_file() and not (site / f"{path}.html").is_file()]
    assert not missing, f"loaded by the pages but not in the image: {missing}"
    page = (site / "index.html").read_text(encoding="utf-8")
    assert "websim:importmap" not in page
    mapped = json.loads(re.search(r'<script type="importmap">(.*?)</script>', page,
                                  re.S).group(1))["imports"]
    assert "@codemirror/view" in mapped
    assert all((site / target).is_file() for target in mapped.values()), mapped
    assert (site / "python" / "websim_worker.py").is_file()  # the Code panel's Python side
    assert json.loads((site / "config.json").read_text()) == \
        json.loads((WEB_DIR / "config.docker.json").read_text())
    assert sorted(path.name for path in includes.iterdir()) == sorted(INCLUDES)


def test_docker_pages_send_the_admin_page_to_the_password_protected_bridge() -> None:
    config = json.loads((WEB_DIR / "config.docker.json").read_text())
    assert config["adminWs"] == "/admin/rosbridge" and config["ws"] is None
    dockerfile = (WEB_DIR / "Dockerfile").read_text()
    assert "COPY web-interface/config.docker.json web/config.json" in dockerfile
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
