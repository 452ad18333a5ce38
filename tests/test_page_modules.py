"""The web interface's pure frontend modules (PID, message conversions, connection, teleop,
who else drives, the class dashboard's) under Node's own test runner (``tests/web/*.test.mjs``).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

NODE_TESTS = sorted((Path(__file__).parent / "web").glob("*.test.mjs"))
NODE = shutil.which("node")


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_frontend_modules_pass_their_node_unit_tests() -> None:
    assert NODE is not None and NODE_TESTS
    result = subprocess.run([NODE, "--test", *map(str, NODE_TESTS)], capture_output=True,
                            text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "# fail 0" in result.stdout
