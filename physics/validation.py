"""Validation of values read from YAML files and set at runtime.

Every error names where the bad value came from (file and entry) and the value itself, so a
student can fix a world or parameter file without reading a traceback. A file read with
``load_yaml_file`` also remembers the line of every entry, so its errors can say
``file:LINE: entry: ...`` (``located``), the way compilers do.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Hashable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import yaml

MAX_YAML_FILE_BYTES = 1 << 20
"""Longest YAML file ``load_yaml_file`` reads (1 MiB): a scenario or a submission's file is a
page of text, and one that is not is refused before it is parsed."""


class ConfigError(ValueError):
    """A world or parameter file, or a runtime setting, holds an invalid value."""


def fail(where: str, message: str) -> ConfigError:
    """Build a ConfigError whose message starts with the place of the error.

    Args:
        where: the file and entry, e.g. ``"worlds/maze.yaml: walls[3]"``.
        message: what is wrong with it.
    """
    return ConfigError(f"{where}: {message}")


def check_keys(where: str, mapping: Mapping[str, Any], allowed: Iterable[str], *,
               key_where: Callable[[Any], str] | None = None) -> None:
    """Reject keys that are not in ``allowed``, with a "did you mean" hint.

    Args:
        where: the file and entry of the mapping, for the error.
        mapping: the mapping read from the file.
        allowed: the keys it may hold.
        key_where: where a given key is, e.g. with its line (``located``); else ``where``.
    """
    allowed_list = list(allowed)
    for key in mapping:
        if key not in allowed_list:
            known = ", ".join(allowed_list)
            place = where if key_where is None else key_where(key)
            raise fail(place, f"unknown key '{key}'{did_you_mean(key, allowed_list)} "
                              f"(known keys: {known})")


def did_you_mean(word: Any, choices: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` with the closest of ``choices`` to ``word``, or ``""``."""
    close = difflib.get_close_matches(str(word), list(choices), n=1)
    return f"; did you mean '{close[0]}'?" if close else ""


def type_name(value: Any) -> str:
    """The name of ``value``'s type as a file's author knows it (``list``, not ``LinedList``)."""
    if isinstance(value, LinedDict):
        return "dict"
    if isinstance(value, LinedList):
        return "list"
    return type(value).__name__


def as_mapping(where: str, value: Any) -> Mapping[str, Any]:
    """Return ``value`` if it is a mapping with string keys, else raise."""
    if not isinstance(value, Mapping):
        raise fail(where, f"expected a mapping, got {type_name(value)} {value!r}")
    return value


def as_finite_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is a finite real number (bools are refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise fail(where, f"expected a number, got {type_name(value)} {value!r}")
    try:
        number = float(value)
    except OverflowError:  # an integer beyond float range, e.g. 10**400 from JSON
        raise fail(where, f"expected a finite number, got an integer of "
                          f"{len(str(abs(value)))} digits") from None
    if not math.isfinite(number):
        raise fail(where, f"expected a finite number, got {value!r}")
    return number


def as_float_in_range(where: str, value: Any, minimum: float, maximum: float) -> float:
    """Return ``value`` as a float if it is finite and within [minimum, maximum]."""
    number = as_finite_float(where, value)
    if not minimum <= number <= maximum:
        raise fail(where, f"must be between {minimum:g} and {maximum:g}, got {value!r}")
    return number


def as_positive_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is finite and > 0."""
    number = as_finite_float(where, value)
    if number <= 0.0:
        raise fail(where, f"must be > 0, got {value!r}")
    return number


def as_non_negative_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is finite and >= 0."""
    number = as_finite_float(where, value)
    if number < 0.0:
        raise fail(where, f"must be >= 0, got {value!r}")
    return number


def as_number_list(where: str, value: Any, length: int) -> list[float]:
    """Return ``value`` as ``length`` finite floats, e.g. a ``[x1, y1, x2, y2]`` wall."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise fail(where, f"expected a list of {length} numbers, got {value!r}")
    return [as_finite_float(f"{where}[{i}]", item) for i, item in enumerate(value)]


class LinedDict(dict[Any, Any]):
    """A YAML mapping that remembers its line and the line of each of its keys (1-based).

    A plain ``dict`` otherwise, so every check above takes it as it is.
    """

    line: int | None = None
    key_lines: dict[Any, int]

    def __init__(self) -> None:
        super().__init__()
        self.key_lines = {}


class LinedList(list[Any]):
    """A YAML list that remembers its line and the line of each of its items (1-based)."""

    line: int | None = None
    item_lines: list[int]

    def __init__(self) -> None:
        super().__init__()
        self.item_lines = []


def line_of(container: Any, key: Any = None) -> int | None:
    """The line of ``key`` in a ``LinedDict`` or of item ``key`` in a ``LinedList``.

    Without ``key`` (or with a key it does not hold), the container's own line; None for
    anything not read by ``load_yaml_file``.
    """
    if isinstance(container, LinedDict) and key in container.key_lines:
        return container.key_lines[key]
    if isinstance(container, LinedList) and isinstance(key, int) \
            and 0 <= key < len(container.item_lines):
        return container.item_lines[key]
    if isinstance(container, (LinedDict, LinedList)):
        return container.line
    return None


def located(source: str, container: Any, key: Any, entry: str) -> str:
    """The ``where`` of an entry: ``"file:LINE: entry"``, or ``"file: entry"`` with no line.

    Args:
        source: the file's name as the user gave it.
        container: the mapping or list (from ``load_yaml_file``) that holds the entry.
        key: the entry's key in it (a list index for a list), None for the container itself.
        entry: the entry's path in the file, e.g. ``"metrics[1].threshold"``.
    """
    line = line_of(container, key)
    return f"{source}: {entry}" if line is None else f"{source}:{line}: {entry}"


def load_yaml_file(path: str | Path, what: str,
                   max_bytes: int = MAX_YAML_FILE_BYTES) -> Any:
    """Read a YAML file whose mappings and lists remember their lines (``LinedDict``).

    Args:
        path: the file.
        what: what the file is, for the errors (``"scenario"``).
        max_bytes: longest file read; a longer one is refused unread.

    Raises:
        ConfigError: the file is unreadable, too long, not valid YAML (with the line), or
            holds a key twice (both lines named).
    """
    source = str(path)
    try:
        with open(path, "rb") as stream:
            data = stream.read(max_bytes + 1)
    except OSError as error:
        raise ConfigError(f"{source}: cannot read {what} file: {error.strerror}") from None
    if len(data) > max_bytes:
        raise ConfigError(f"{source}: {what} file longer than {max_bytes} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ConfigError(f"{source}: {what} file is not UTF-8 text ({error.reason} at "
                          f"byte {error.start})") from None
    loader = _LinedLoader(text, source)
    try:
        return loader.get_single_data()
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = error.problem or error.context or "invalid"
        raise ConfigError(f"{source}{line}: not valid YAML: {problem}") from None
    except yaml.YAMLError as error:
        raise ConfigError(f"{source}: not valid YAML: {error}") from None
    finally:
        loader.dispose()


class _LinedLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` building ``LinedDict`` and ``LinedList``, refusing duplicate keys."""

    def __init__(self, text: str, source: str) -> None:
        super().__init__(text)
        self.source = source


def _construct_lined_map(loader: _LinedLoader, node: yaml.MappingNode) -> Iterator[LinedDict]:
    data = LinedDict()
    data.line = node.start_mark.line + 1
    yield data
    first_lines: dict[Any, int] = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=True)
        line = key_node.start_mark.line + 1
        if isinstance(key, Hashable) and key in first_lines:
            raise ConfigError(f"{loader.source}:{line}: key '{key}' given twice (first at line "
                              f"{first_lines[key]})")
        if isinstance(key, Hashable):
            first_lines[key] = line
    data.update(loader.construct_mapping(node, deep=False))
    for key_node, _ in node.value:  # merged (<<) entries first, then the mapping's own
        key = loader.construct_object(key_node, deep=True)
        if isinstance(key, Hashable):
            data.key_lines[key] = key_node.start_mark.line + 1


def _construct_lined_list(loader: _LinedLoader, node: yaml.SequenceNode) -> Iterator[LinedList]:
    data = LinedList()
    data.line = node.start_mark.line + 1
    yield data
    data.extend(loader.construct_sequence(node, deep=False))
    data.item_lines = [item.start_mark.line + 1 for item in node.value]


_LinedLoader.add_constructor("tag:yaml.org,2002:map", _construct_lined_map)
_LinedLoader.add_constructor("tag:yaml.org,2002:seq", _construct_lined_list)
