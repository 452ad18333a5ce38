"""The suite's own rig: a server a test's body starts never outlives the test."""

from __future__ import annotations

from server_process import STARTED_BY_TESTS, start_server, stop_leftovers


def test_a_server_left_running_by_a_test_is_stopped_after_it() -> None:
    server = start_server([])
    assert server in STARTED_BY_TESTS  # started in the test's body: tracked
    assert stop_leftovers() == 1  # what the autouse fixture does after every test
    assert server.process.poll() is not None
    assert stop_leftovers() == 0


def test_a_stopped_server_is_not_stopped_again() -> None:
    server = start_server([])
    assert server.stop() == 0
    assert stop_leftovers() == 0
