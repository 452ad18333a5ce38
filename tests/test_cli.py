"""The ``websim`` command, called in-process through ``main(argv)``."""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
from pathlib import Path

import pytest

from classroom.registry import read_roster, weak_token
from websim.cli import main


def test_help_lists_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as caught:
        main(["--help"])
    assert caught.value.code == 0
    assert "demo" in capsys.readouterr().out


def test_demo_prints_odometry_of_the_commanded_motion(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--seconds", "2", "--linear", "0.2", "--angular", "0"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[1:]]
    assert [float(row[0]) for row in rows] == [0.5, 1.0, 1.5, 2.0]
    assert float(rows[-1][1]) == pytest.approx(0.4, abs=1e-4)


def test_bad_world_is_a_one_line_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--world", "nowhere"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("websim: error: nowhere: cannot read world file")
    assert len(err.strip().splitlines()) == 1


def test_console_script_is_installed() -> None:
    result = subprocess.run([sys.executable, "-m", "websim.cli", "--help"],
                            capture_output=True, text=True, check=False)
    assert result.returncode == 0 and "usage: websim" in result.stdout


def test_version_says_which_websim_is_installed(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"websim {importlib.metadata.version('websim')}"


def test_links_behind_a_proxy_need_both_public_ports(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    links = tmp_path / "links.csv"
    code = main(["serve", "--class", "2", "--worker", "--public-ws-port", "9090",
                 "--links", str(links), "--state", str(tmp_path / "s.sqlite")])
    assert code == 2
    assert "needs both --public-http-port and --public-ws-port" in capsys.readouterr().err
    assert not links.exists()


def test_token_prints_tokens_the_rule_accepts_and_a_roster_with_one_each(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The README's scale-out recipe makes the instructor's token and the roster with it (a
    plain secrets.token_urlsafe(18) lacks a third kind of character in 0.7 % of draws, which
    the server refuses: a roster of 40 so made failed one time in four)."""
    assert main(["token"]) == 0
    token = capsys.readouterr().out.strip()
    assert weak_token(token) is None and "\n" not in token
    names = [f"student{i}" for i in range(200)]
    assert main(["token", "--roster", *names]) == 0
    roster = tmp_path / "roster.txt"
    roster.write_text(capsys.readouterr().out)
    students = read_roster(roster)
    assert [student.name for student in students] == names
    assert {student.world for student in students} == {None}
    tokens = [student.token for student in students]
    assert len(set(tokens)) == 200 and token not in tokens
    assert [weak_token(each or "") for each in tokens] == [None] * 200
    assert main(["token", "--roster", "alice", "Bad.Name"]) == 2
    assert "--roster: 'Bad.Name' is not a robot name" in capsys.readouterr().err
    assert main(["token", "--roster", "alice", "bob", "alice"]) == 2
    assert "--roster: alice named twice" in capsys.readouterr().err
