"""Fixtures of the conformance tests: a roslibpy client of the module's ``websim serve``.

The server itself is the root conftest's ``server`` (one per test module); the ``--ros``
server and its client are ``ros_fixtures``' ``ros_server`` and ``ros_client``.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import roslibpy

from server_process import ServerProcess


@pytest.fixture
def ros(server: ServerProcess) -> Iterator[roslibpy.Ros]:
    """roslibpy connected to ``server``, closed after the test."""
    client = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
    client.run(timeout=10)
    yield client
    client.close()
