"""The compose file's "class" profile: two ``websim serve --class --worker`` containers
behind an nginx. ``docker-compose --profile class config`` accepts it, its ports stay off the
stack's, each worker's command is a ``websim serve`` its own parser accepts,
web-interface/nginx-class.conf is exactly what ``websim nginx-config`` prints for the workers
the compose file declares, and the real nginx accepts that file (``nginx -t``).
"""

from __future__ import annotations

import ipaddress
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml
from deployment import (
    BRIDGE,
    CLASS_CONF_TARGET,
    CLASS_NGINX,
    CLASS_NGINX_CONF,
    CLASS_PROFILE,
    COMPOSE_FILE,
    DOCKER_COMPOSE,
    NGINX,
    WEB,
    WEB_DIR,
    class_workers,
    compose,
    compose_env,
    option,
    worker_script,
)

from classroom.nginx_config import foreground_command, in_directory
from physics.params import PROJECT_DIR
from websim import cli


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
            assert set(services[name]["networks"]) == set(services[BRIDGE]["networks"]), name
            assert services[name]["restart"] == "unless-stopped", name
        for index, worker in enumerate(workers):
            body = services[worker]
            assert body["build"] == services[BRIDGE]["build"], "the ros2-web-bridge image"
            assert body["environment"] == {"CLASS_ADMIN_TOKEN": token,
                                           "WORKER_INDEX": str(index)}
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
        subnet = result_subnet(yaml.safe_load(result.stdout))
        assert ipaddress.ip_address(nginx_address(services)) in subnet, "nginx's fixed address"
        stack = {port["published"] for name in (BRIDGE, WEB) for port in services[name]["ports"]}
        assert stack == {8080, 9090}, "the stack's ports are as they were"
        assert not stack & {host for host, _ in published}, "the class collides with the stack"


def result_subnet(config: dict[str, Any]) -> ipaddress.IPv4Network:
    """The class network's fixed subnet."""
    (network,) = config["networks"].values()
    (pool,) = network["ipam"]["config"]
    return ipaddress.IPv4Network(pool["subnet"])


def nginx_address(services: dict[str, Any]) -> str:
    """The class nginx's fixed address in its network."""
    (network,) = services[CLASS_NGINX]["networks"].values()
    return str(network["ipv4_address"])


def test_a_class_worker_runs_websim_serve_on_its_ports_and_refuses_without_a_token() -> None:
    """Each worker's ``sh -c`` script run here for real, with ``exec websim`` replaced by a
    printf of its arguments, which websim's own parser then reads: its ports, which worker it
    is (the same list and order as nginx's), and nginx as its only trusted proxy."""
    http, ws = class_ports()
    workers = class_workers()
    services = compose()["services"]
    for index, worker in enumerate(workers):
        script = worker_script(worker)
        assert "exec websim serve " in script
        refused = subprocess.run(["sh", "-c", script], env=compose_env(), capture_output=True,
                                 text=True, timeout=10, check=False)
        assert refused.returncode != 0 and refused.stdout == ""
        assert "set CLASS_ADMIN_TOKEN, the instructor's token" in refused.stderr
        unplaced = subprocess.run(["sh", "-c", script], env=compose_env(CLASS_ADMIN_TOKEN="t"),
                                  capture_output=True, text=True, timeout=10, check=False)
        assert unplaced.returncode != 0 and "set WORKER_INDEX" in unplaced.stderr
        printing = script.replace("exec websim", "exec printf '%s\\n' websim")
        environment = services[worker]["environment"]
        printed = subprocess.run(["sh", "-c", printing],
                                 env=compose_env(CLASS_ADMIN_TOKEN="two words",
                                                 WORKER_INDEX=environment["WORKER_INDEX"]),
                                 capture_output=True, text=True, timeout=10, check=True)
        argv = printed.stdout.splitlines()
        assert argv[:2] == ["websim", "serve"]
        args = cli.build_parser().parse_args(argv[1:])
        assert (args.class_spec, args.worker, args.host) == ("/class/roster.txt", True, "0.0.0.0")
        assert (args.http_port, args.ws_port, args.admin_token) == (int(http), int(ws),
                                                                     "two words")
        assert args.public_ws_port is None, "its own WebSocket port is the public one"
        assert args.worker_index == index
        assert args.workers == [f"{name}:{http}:{ws}" for name in workers]
        assert args.trusted_proxy == [nginx_address(services)]
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
