"""Files an instructor opens cannot exhaust the machine: every YAML goes through one bounded
loader (size, nesting, aliases, expansion), and no error message is built from a whole value.

Each attack is a file as a hostile student would hand it over (an alias bomb of a few hundred
bytes, ten thousand nested brackets, a recursive alias, a megabyte of one value), read by the
command that reads it; the memory it costs is measured with ``tracemalloc``.
"""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from classroom.registry import read_roster
from grading.scenario import load_scenario
from physics import ConfigError, load_params, load_world
from physics.compare import load_commands
from physics.validation import (
    MAX_YAML_DEPTH,
    MAX_YAML_FILE_BYTES,
    parse_yaml,
    shown,
)
from websim.cli import main

MAX_PEAK_BYTES = 30 << 20
"""What refusing one of these files may cost at most (the bombs stood for gigabytes)."""

MAX_FILE_PEAK_BYTES = 150 << 20
"""What parsing a YAML file of the largest size accepted costs (PyYAML's nodes and marks:
about 80 MB for a megabyte of text), bounded by ``MAX_YAML_FILE_BYTES``."""


def alias_bomb(levels: int = 9, key: str = "walls") -> str:
    """A "billion laughs": each level a list of nine aliases of the last (9**levels items)."""
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for level in range(1, levels):
        items = ", ".join([f"*a{level - 1}"] * 9)
        lines.append(f"a{level}: &a{level} [{items}]")
    lines.append(f"{key}: *a{levels - 1}")
    return "\n".join(lines) + "\n"


def merge_bomb(levels: int = 30) -> str:
    """Merge keys (``<<``) doubling a mapping's entries at every level."""
    lines = ["m0: &m0 {k0: 1, k1: 2}"]
    for level in range(1, levels):
        lines.append(f"m{level}: &m{level} {{<<: [*m{level - 1}, *m{level - 1}]}}")
    return "\n".join(lines) + "\n"


def refused_cheaply(read: Callable[[], Any], expected: str,
                    max_peak_bytes: int = MAX_PEAK_BYTES) -> str:
    """Run ``read``; it must raise ConfigError matching ``expected`` within the bounds."""
    tracemalloc.start()
    started = time.perf_counter()
    try:
        with pytest.raises(ConfigError, match=expected) as caught:
            read()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < max_peak_bytes, f"refusing cost {peak / 1e6:.0f} MB"
    assert time.perf_counter() - started < 30.0
    message = str(caught.value)
    assert len(message) < 600, f"an error of {len(message)} characters"
    return message


def test_the_597_byte_world_alias_bomb_is_refused_before_it_expands(tmp_path: Path) -> None:
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(alias_bomb())
    assert bomb.stat().st_size < 700
    message = refused_cheaply(lambda: load_world(bomb), "with its aliases expanded")
    assert message.startswith(f"{bomb}:")


def test_websim_map_and_serve_refuse_the_bomb_with_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(alias_bomb())
    tracemalloc.start()
    try:
        assert main(["map", str(bomb), "--out", str(tmp_path / "out")]) == 2
        assert main(["serve", "--world", str(bomb), "--ws-port", "0", "--http-port", "0"]) == 2
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < MAX_PEAK_BYTES
    err = capsys.readouterr().err
    assert err.count("with its aliases expanded (an alias bomb?)") == 2
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_merge_key_bomb_is_refused(tmp_path: Path) -> None:
    bomb = tmp_path / "params.yaml"
    bomb.write_text(merge_bomb())
    refused_cheaply(lambda: load_params(bomb), "with its aliases expanded")


def test_ten_thousand_nested_brackets_are_refused_at_the_depth_bound(tmp_path: Path) -> None:
    deep = tmp_path / "deep.yaml"
    deep.write_text("walls: " + "[" * 10_000 + "]" * 10_000 + "\n")
    refused_cheaply(lambda: load_world(deep), f"nested more than {MAX_YAML_DEPTH} levels")


def test_aliases_cannot_stack_depth_beyond_the_bound() -> None:
    """Each anchor is shallow; expanded, the aliases nest far deeper than any file may."""
    lines = ["l0: &l0 [[[[[[[[1]]]]]]]]"]
    for level in range(1, 20):
        lines.append(f"l{level}: &l{level} [[[[[[[[*l{level - 1}]]]]]]]]")
    refused_cheaply(lambda: parse_yaml("\n".join(lines), "stack.yaml"),
                    "levels deep \\(aliases expanded\\)")


def test_a_recursive_alias_is_refused(tmp_path: Path) -> None:
    loop = tmp_path / "loop.yaml"
    loop.write_text("walls: &w [[0, 0, 1, 1], *w]\n")
    refused_cheaply(lambda: load_world(loop), "recursive structure")


def test_a_scenario_bomb_is_refused(tmp_path: Path) -> None:
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(alias_bomb(key="metrics"))
    refused_cheaply(lambda: load_scenario(scenario), "with its aliases expanded")


def test_a_command_file_bomb_is_refused(tmp_path: Path) -> None:
    commands = tmp_path / "commands.yaml"
    commands.write_text(alias_bomb(key="segments"))
    refused_cheaply(lambda: load_commands(commands), "with its aliases expanded")


@pytest.mark.parametrize("reader", [load_world, load_params, load_commands, read_roster],
                         ids=["world", "params", "commands", "roster"])
def test_a_file_of_endless_bytes_is_refused_after_the_size_bound(
        reader: Callable[[Path], Any]) -> None:
    refused_cheaply(lambda: reader(Path("/dev/zero")), f"longer than {MAX_YAML_FILE_BYTES}")


def test_a_megabyte_value_in_an_error_is_cut_before_it_is_built(tmp_path: Path) -> None:
    """The value is within every bound, and wrong: the error shows its start only."""
    world = tmp_path / "long.yaml"
    world.write_text("name: [" + ", ".join(["12345678"] * 25_000) + "]\n")
    message = refused_cheaply(lambda: load_world(world), "name: expected text, got",
                              MAX_FILE_PEAK_BYTES)
    assert "12345678, 12345678" in message and "..." in message


def test_an_aliased_value_in_an_error_is_cut_too(tmp_path: Path) -> None:
    """Within the expansion bound, a wrong value that holds one list a hundred times."""
    world = tmp_path / "aliased.yaml"
    world.write_text("start: &x [" + ", ".join(["7"] * 1000) + "]\n"
                     "name: [" + ", ".join(["*x"] * 100) + "]\n")
    message = refused_cheaply(lambda: load_world(world), "name: expected text, got")
    assert "[[7, 7, 7, 7, 7, 7, ...]" in message


def test_shown_cuts_every_kind_of_value() -> None:
    huge_list = list(range(1_000_000))
    assert len(shown(huge_list)) < 200
    assert len(shown("x" * 10_000_000)) < 200
    assert shown(10**5000) == "an integer of about 5001 digits"
    nested: Any = [1]
    for _ in range(10_000):
        nested = [nested]
    assert len(shown(nested)) < 200
    parsed = parse_yaml("a: [1, 2]\nb: {c: 3}\n", "small.yaml")
    assert shown(parsed) == "{'a': [1, 2], 'b': {'c': 3}}"


def test_anchors_that_save_typing_still_work(tmp_path: Path) -> None:
    world = tmp_path / "anchored.yaml"
    world.write_text("boxes:\n"
                     "  - &box {center: [1, 1], size: [0.5, 0.5]}\n"
                     "  - {<<: *box, center: [2, 2]}\n"
                     "  - {<<: *box, center: [-2, 2]}\n")
    assert len(load_world(world).walls) == 12


def test_a_key_given_twice_in_a_world_is_refused_with_both_lines(tmp_path: Path) -> None:
    world = tmp_path / "twice.yaml"
    world.write_text("walls: [[0, 0, 1, 0]]\nstart: [0, 1, 0]\nwalls: [[0, 2, 1, 2]]\n")
    with pytest.raises(ConfigError, match=r"twice.yaml:3: key 'walls' given twice \(first at "
                                          r"line 1\)"):
        load_world(world)
