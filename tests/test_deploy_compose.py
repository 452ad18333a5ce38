"""docker-compose.yml's stack, checked without a Docker engine: ``docker-compose config``
accepts it, and its two services share one network, restart, and have health checks.
"""

from __future__ import annotations

import os
import subprocess

import pytest
import yaml
from deployment import (
    BRIDGE,
    BRIDGE_DIR,
    COMPOSE_FILE,
    DOCKER_COMPOSE,
    WEB,
    WEB_DIR,
    build_of,
    default_services,
)

from physics.params import PROJECT_DIR


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
    assert build_of(WEB) == (PROJECT_DIR, WEB_DIR / "Dockerfile")  # it runs websim.static_site
