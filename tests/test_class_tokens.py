"""Tokens that cannot be guessed, leaked or derived (issue 20, section 5).

Robot tokens derive from the class's own random secret (never the instructor's token); a weak
``--admin-token`` is refused with the reason; no log line carries a token at any level; the
links file is written atomically, mode 0600, never through a symbolic link.
"""

from __future__ import annotations

import argparse
import asyncio
import csv
import logging
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest
import websockets

from classroom.registry import (
    Classroom,
    Student,
    derived_token,
    read_roster,
    strong_token,
    weak_token,
)
from physics import ConfigError, Simulation, load_world
from ros_nodes.virtual_robot_core import VirtualRobot
from websim import cli
from websim.lan import lan_addresses
from websim.serve import RedactTokens
from websim.sites import instructor_links_path, write_links

from server_process import ADMIN_TOKEN, start_server


@pytest.mark.parametrize(("token", "reason"), [
    ("TEACHER", "7 characters, at least 20 are needed"),
    ("two words and more than twenty", "only A-Z, a-z, 0-9 and . _ ~ - may be used"),
    ("alllowercaseletters-only", "it has no upper-case letters and no digits"),
    ("0123456789012345678901", "mix at least three"),
])
def test_weak_tokens_are_refused_with_the_reason(token: str, reason: str) -> None:
    why = weak_token(token)
    assert why is not None and reason in why


def test_strong_tokens_pass_and_generated_ones_are_strong() -> None:
    assert weak_token(ADMIN_TOKEN) is None
    assert weak_token("Correct-Horse-Battery-9") is None
    generated = {strong_token() for _ in range(50)}
    assert len(generated) == 50
    assert all(weak_token(token) is None and len(token) == 32 for token in generated)


def test_serve_refuses_a_weak_admin_token(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["serve", "--admin-token", "TEACHER"]) == 2
    error = capsys.readouterr().err
    assert "--admin-token is too weak: 7 characters, at least 20 are needed" in error


def test_a_weak_roster_token_is_refused_with_its_line(tmp_path: Path) -> None:
    roster = tmp_path / "roster.txt"
    roster.write_text("alice\nbob,,secret\n")
    with pytest.raises(ConfigError, match=r"roster.txt:2: the token of 'bob' is too weak"):
        read_roster(roster)


def make_robot(student: Student) -> VirtualRobot:
    return VirtualRobot(Simulation(load_world("empty")))


def test_robot_tokens_come_from_the_class_secret_not_the_instructors_token() -> None:
    one = Classroom([Student("alice"), Student("bob")], make_robot, idle_pause_s=None)
    two = Classroom([Student("alice")], make_robot, idle_pause_s=None)
    assert one.token("alice") == derived_token(one.secret, "alice")
    assert one.token("alice") != two.token("alice"), "each class has its own secret"
    assert one.token("alice") != derived_token(ADMIN_TOKEN, "alice")
    assert len(one.secret) >= 43  # 32 random bytes


def test_the_links_file_is_private_atomic_and_never_written_through_a_link(
        tmp_path: Path) -> None:
    classroom = Classroom([Student("alice")], make_robot, idle_pause_s=None)
    links = tmp_path / "links.csv"
    links.write_text("old\n")
    links.chmod(0o644)
    write_links(links, classroom, "class.example", 8080, 9090)
    assert stat.S_IMODE(links.stat().st_mode) == 0o600
    row = next(csv.DictReader(links.open()))
    token = classroom.token("alice")
    assert row["page"] == f"http://class.example:8080/robots/alice/#token={token}"
    assert row["admin_page"] == f"http://class.example:8080/robots/alice/admin?token={token}"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["links.csv"]  # no temp left

    target = tmp_path / "elsewhere.txt"
    target.write_text("not yours\n")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    with pytest.raises(ConfigError, match="is a symbolic link"):
        write_links(link, classroom, "class.example", 8080, 9090)
    assert target.read_text() == "not yours\n"


def test_the_links_name_the_host_students_reach(tmp_path: Path) -> None:
    """Behind nginx a worker binds 127.0.0.1, and its links said localhost, which no student's
    machine reaches: --public-host names the proxy's host (the README's recipe gives it)."""
    links = tmp_path / "links.csv"
    server = start_server(["--class", "2", "--links", str(links), "--public-host",
                           "class.example", "--public-http-port", "8080",
                           "--public-ws-port", "9090"])
    try:
        rows = list(csv.DictReader(links.open()))
    finally:
        server.stop()
    assert rows[0]["page"].startswith("http://class.example:8080/robots/robot01/#token=")
    assert rows[0]["websocket"] == "ws://class.example:9090/robots/robot01"
    private = instructor_links_path(links).read_text()
    assert "dashboard=http://class.example:8080/class?token=" in private
    assert "dashboard: http://class.example:8080/class?token=" in "".join(server.output)
    for bad in ("http://class.example", "class example", "a..example"):
        result = subprocess.run([sys.executable, "-m", "websim.cli", "serve", "--class", "2",
                                 "--public-host", bad], capture_output=True, text=True,
                                check=False, timeout=60)
        assert result.returncode == 2, bad
        assert f"expected a host name or an IP address, got '{bad}'" in result.stderr


def test_the_redaction_filter_takes_tokens_out_of_any_record() -> None:
    record = logging.LogRecord("websockets.server", logging.DEBUG, __file__, 1,
                               "< GET %s HTTP/1.1", ("/robots/alice?token=Abc-123_x",), None)
    RedactTokens(("Instructor-Secret-2026",)).filter(record)
    assert record.getMessage() == "< GET /robots/alice?token=<redacted> HTTP/1.1"
    other = logging.LogRecord("x", logging.INFO, __file__, 1, "key %s", ("Instructor-Secret-2026",),
                              None)
    RedactTokens(("Instructor-Secret-2026",)).filter(other)
    assert other.getMessage() == "key <redacted>"


def test_no_log_line_carries_a_token_even_at_debug(tmp_path: Path) -> None:
    links = tmp_path / "links.csv"
    server = start_server(["--class", "2", "--links", str(links), "--log-level", "debug"])
    try:
        token = {row["name"]: row["token"] for row in csv.DictReader(links.open())}["robot01"]

        async def visit() -> None:
            for url in (f"ws://127.0.0.1:{server.ws_port}/robots/robot01?token={token}",
                        f"ws://127.0.0.1:{server.ws_port}/?token={ADMIN_TOKEN}",
                        f"ws://127.0.0.1:{server.ws_port}/robots/robot02?token=Wrong-Token-123"):
                topic = "/robot01/odom" if "/robots/" not in url else "/odom"
                async with websockets.connect(url) as ws:
                    await ws.send(f'{{"op": "subscribe", "topic": "{topic}"}}')
                    await asyncio.wait_for(ws.recv(), 5)

        asyncio.run(visit())
    finally:
        server.stop()
    logged = "".join(server.output)
    assert "GET /robots/robot01?token=<redacted>" in logged, "debug logs the request line"
    for secret in (token, "Wrong-Token-123"):
        assert secret not in logged
    # the banner prints the instructor's admin link once, on stdout; no log line has it
    assert not [line for line in logged.splitlines()
                if ADMIN_TOKEN in line and (" DEBUG " in line or " INFO " in line
                                            or " WARNING " in line)]
    assert stat.S_IMODE(os.stat(links).st_mode) == 0o600


def test_the_parser_documents_the_token_rule() -> None:
    parser = cli.build_parser()
    serve = next(action for action in parser._subparsers._group_actions  # type: ignore[union-attr]
                 if isinstance(action, argparse._SubParsersAction)).choices["serve"]
    help_text = serve.format_help()
    assert "at least 20 characters" in help_text and "--open-drive" in help_text


def test_the_handout_holds_no_instructor_token_and_both_files_are_private_lf_text(
        tmp_path: Path) -> None:
    """The handout went to students with the instructor's token in its last row; its CRLF
    line ends put a carriage return at the end of every token a shell read from it."""
    links = tmp_path / "links.csv"
    server = start_server(["--class", "3", "--links", str(links)])
    try:
        handout, private = links.read_bytes(), instructor_links_path(links).read_bytes()
    finally:
        server.stop()
    assert ADMIN_TOKEN.encode() not in handout
    assert b"\r" not in handout and b"\r" not in private
    assert handout.endswith(b"\n") and private.endswith(b"\n")
    rows = list(csv.DictReader(handout.decode().splitlines()))
    assert [row["name"] for row in rows] == ["robot01", "robot02", "robot03"]
    assert all(row["token"] and row["token"] in row["page"] for row in rows)
    assert private.decode().splitlines()[1:] == [
        f"dashboard=http://localhost:{server.http_port}/class?token={ADMIN_TOKEN}",
        f"websocket=ws://localhost:{server.ws_port}/", f"token={ADMIN_TOKEN}"]
    for path in (links, instructor_links_path(links)):
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
    token = subprocess.run(["sh", "-c", f". '{instructor_links_path(links)}' && "
                                        "printf %s \"$token\""],
                           capture_output=True, text=True, check=True).stdout
    assert token == ADMIN_TOKEN, "a shell reads the token as it is"
    output = "".join(server.output)
    assert f"links:     {links} to hand out" in output
    assert f"{instructor_links_path(links)} is yours" in output


def test_a_class_on_every_interface_names_the_address_students_reach_everywhere(
        tmp_path: Path) -> None:
    """Its links named the machine's host name ('vm'), which students' machines usually
    cannot resolve, and the banner named three hosts."""
    addresses = lan_addresses()
    if not addresses:
        pytest.skip("this machine has no network address besides loopback")
    links = tmp_path / "links.csv"
    server = start_server(["--class", "2", "--host", "0.0.0.0", "--links", str(links)])
    try:
        rows = list(csv.DictReader(links.open()))
    finally:
        server.stop()
    host = addresses[0]
    assert rows[0]["page"].startswith(f"http://{host}:{server.http_port}/robots/robot01/")
    assert rows[0]["websocket"] == f"ws://{host}:{server.ws_port}/robots/robot01"
    assert f"dashboard=http://{host}:{server.http_port}/class?token=" in \
        instructor_links_path(links).read_text()
    urls = [word for word in "".join(server.output).split() if "://" in word]
    assert len(urls) >= 4 and all(f"://{host}:" in url for url in urls), urls
