"""The ros2-web-bridge image's health check (ros2-bridge/healthcheck.py) against a real
``websim serve`` standing in for the bridge, and against nothing.
"""

from __future__ import annotations

import pytest
from deployment import (
    load_healthcheck,
)

from server_process import ServerProcess, free_port


def test_healthcheck_passes_on_a_live_bridge(server: ServerProcess) -> None:
    healthcheck = load_healthcheck()
    assert healthcheck.main(["--url", server.ws_url, "--admin-url", server.ws_url]) == 0


def test_healthcheck_fails_when_nothing_listens(capsys: pytest.CaptureFixture[str]) -> None:
    healthcheck = load_healthcheck()
    closed = f"ws://127.0.0.1:{free_port()}"
    assert healthcheck.main(["--url", closed, "--timeout", "2"]) == 1
    assert "unhealthy" in capsys.readouterr().out
