"""Validation of values read from YAML files and set at runtime.

Every error names where the bad value came from (file and entry) and the value itself, so a
student can fix a world or parameter file without reading a traceback. A file read with
``load_yaml_file`` also remembers the line of every entry, so its errors can say
``file:LINE: entry: ...`` (``located``), the way compilers do.

Every YAML the project reads (worlds, parameters, command files, scenarios, suites,
submissions, recordings' metadata) goes through ``load_yaml_file`` or ``parse_yaml``, which
bound what a file can make the process hold before anything is built from it: its size
(``MAX_YAML_FILE_BYTES``), its nesting (``MAX_YAML_DEPTH``), its aliases
(``MAX_YAML_ALIASES``) and what it holds with every alias expanded (``MAX_YAML_EXPANSION``
times its size: a 600-byte "billion laughs" would otherwise stand for gigabytes). And an
error shows a value through ``shown``, which cuts it while it is written: a ``repr`` of a
large value is itself the bomb.
"""

from __future__ import annotations

import difflib
import math
import reprlib
from collections.abc import Callable, Hashable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import yaml

MAX_YAML_FILE_BYTES = 1 << 20
"""Longest YAML file ``load_yaml_file`` reads (1 MiB): a scenario or a submission's file is a
page of text, and one that is not is refused before it is parsed."""

MAX_YAML_DEPTH = 64
"""Deepest nesting of mappings and lists a YAML document may have (aliases expanded): a world
is four levels deep, a scenario six; a deeper one is refused while it is parsed, before
Python's own recursion limit would end the process's patience with a traceback."""

MAX_YAML_ALIASES = 10_000
"""Most aliases (``*name``) one YAML document may use."""

MAX_YAML_EXPANSION = 4
"""What a document may hold with every alias expanded, in times its text's length (each
value counts its characters, each mapping and list one): anchors that save typing pass, an
alias bomb (each level doubling the last) is refused before it is built."""

YAML_EXPANSION_FLOOR = 256 << 10
"""What any document may hold with its aliases expanded, however short (characters)."""

SHOWN_CHARS = 80
"""Most characters of a value an error message shows (``shown``)."""


class _Shown(reprlib.Repr):
    """``reprlib``'s cut ``repr``, for every mapping, list and string (subclasses too).

    ``reprlib`` dispatches on a type's name and falls back on the full ``repr`` of anything
    else (a ``LinedDict``, a message's ``TypedSequence``): that would build the whole text
    first. Integers beyond 40 digits are described, not written (Python refuses to write
    more than 4300 digits anyway).
    """

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel = 3
        self.maxdict = self.maxlist = self.maxtuple = self.maxset = 6
        self.maxstring = self.maxother = SHOWN_CHARS
        self.maxlong = 40

    def repr1(self, x: Any, level: int) -> str:
        if isinstance(x, bool) or x is None or isinstance(x, float):
            return repr(x)
        if isinstance(x, int):
            if x.bit_length() > 128:
                return f"an integer of {integer_digits(x)} digits"
            return repr(x)
        if isinstance(x, str):
            return self.repr_str(str(x[:self.maxstring + 1]), level)
        if isinstance(x, (bytes, bytearray)):
            return repr(bytes(x[:self.maxstring])) + ("..." if len(x) > self.maxstring else "")
        if isinstance(x, Mapping):
            return self.repr_dict(x, level)  # type: ignore[arg-type]
        if isinstance(x, list):
            return self.repr_list(x, level)
        if isinstance(x, tuple):
            return self.repr_tuple(x, level)
        if isinstance(x, (set, frozenset)):
            return self.repr_set(set(x), level)
        return self.repr_instance(x, level)


_SHOWN = _Shown()


def integer_digits(value: int) -> str:
    """How many decimal digits ``value`` has, without writing it past Python's 4300 digits."""
    try:
        return str(len(str(abs(value))))
    except ValueError:  # more than sys.get_int_max_str_digits()
        return f"about {int(abs(value).bit_length() * math.log10(2)) + 1}"


def shown(value: Any) -> str:
    """``repr(value)`` cut to about ``SHOWN_CHARS`` characters, never built whole.

    What every error message shows of a value read from a file or a client: a huge value
    (an aliased structure, a megabyte of text) costs no more to show than a small one.
    """
    text = _SHOWN.repr(value)
    return text if len(text) <= 2 * SHOWN_CHARS else f"{text[:2 * SHOWN_CHARS]}..."


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
        raise fail(where, f"expected a mapping, got {type_name(value)} {shown(value)}")
    return value


def as_finite_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is a finite real number (bools are refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise fail(where, f"expected a number, got {type_name(value)} {shown(value)}")
    try:
        number = float(value)
    except OverflowError:  # an integer beyond float range, e.g. 10**400 from JSON
        raise fail(where, f"expected a finite number, got an integer of "
                          f"{integer_digits(int(value))} digits") from None
    if not math.isfinite(number):
        raise fail(where, f"expected a finite number, got {shown(value)}")
    return number


def as_float_in_range(where: str, value: Any, minimum: float, maximum: float) -> float:
    """Return ``value`` as a float if it is finite and within [minimum, maximum]."""
    number = as_finite_float(where, value)
    if not minimum <= number <= maximum:
        raise fail(where, f"must be between {minimum:g} and {maximum:g}, got {shown(value)}")
    return number


def as_positive_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is finite and > 0."""
    number = as_finite_float(where, value)
    if number <= 0.0:
        raise fail(where, f"must be > 0, got {shown(value)}")
    return number


def as_non_negative_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is finite and >= 0."""
    number = as_finite_float(where, value)
    if number < 0.0:
        raise fail(where, f"must be >= 0, got {shown(value)}")
    return number


def as_number_list(where: str, value: Any, length: int) -> list[float]:
    """Return ``value`` as ``length`` finite floats, e.g. a ``[x1, y1, x2, y2]`` wall."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise fail(where, f"expected a list of {length} numbers, got {shown(value)}")
    return [as_finite_float(f"{where}[{i}]", item) for i, item in enumerate(value)]


def plain_data(value: Any) -> Any:
    """A parsed document with its ``LinedDict`` and ``LinedList`` as plain dicts and lists.

    What ``yaml.safe_dump`` writes back (it refuses their subclasses).
    """
    if isinstance(value, dict):
        return {key: plain_data(item) for key, item in value.items()}
    if isinstance(value, list):
        return [plain_data(item) for item in value]
    return value


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
                   max_bytes: int = MAX_YAML_FILE_BYTES, *, source: str | None = None) -> Any:
    """Read a YAML file whose mappings and lists remember their lines (``LinedDict``).

    Bounded (``parse_yaml``): its size, nesting, aliases and what it holds with the aliases
    expanded.

    Args:
        path: the file.
        what: what the file is, for the errors (``"scenario"``).
        max_bytes: longest file read; a longer one is refused unread.
        source: what the errors call the file (default: ``path``; a shipped file's name).

    Raises:
        ConfigError: the file is unreadable, too long, not valid YAML (with the line), holds
            a key twice (both lines named), or is nested, aliased or expanded beyond the
            bounds (with the line).
    """
    source = str(path) if source is None else source
    return parse_yaml(read_text_file(path, what, max_bytes, source=source), source)


def read_text_file(path: str | Path, what: str, max_bytes: int = MAX_YAML_FILE_BYTES, *,
                   source: str | None = None) -> str:
    """A UTF-8 text file's text, read only if it is at most ``max_bytes`` long.

    What every file an instructor or a student hands websim is read with (YAML, rosters,
    command files): ``/dev/zero`` or a gigabyte is refused after ``max_bytes`` + 1 bytes.

    Raises:
        ConfigError: unreadable, too long, or not UTF-8 (the message names the file).
    """
    source = str(path) if source is None else source
    try:
        with open(path, "rb") as stream:
            data = stream.read(max_bytes + 1)
    except OSError as error:
        raise ConfigError(f"{source}: cannot read {what} file: {error.strerror}") from None
    if len(data) > max_bytes:
        raise ConfigError(f"{source}: {what} file longer than {max_bytes} bytes")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ConfigError(f"{source}: {what} file is not UTF-8 text ({error.reason} at "
                          f"byte {error.start})") from None


def parse_yaml(text: str, source: str, max_chars: int = MAX_YAML_FILE_BYTES) -> Any:
    """Parse YAML text (a file's, or one held in another file) within the bounds.

    Mappings and lists remember their lines (``LinedDict``, ``LinedList``); a key given
    twice is refused. The document may nest ``MAX_YAML_DEPTH`` levels, use
    ``MAX_YAML_ALIASES`` aliases and hold, aliases expanded, ``MAX_YAML_EXPANSION`` times its
    length (or ``YAML_EXPANSION_FLOOR``, whichever is more); an alias may not refer to what
    holds it. Each bound is checked before anything is built from the document.

    Args:
        text: the YAML.
        source: where it comes from, for the errors (a file's name).
        max_chars: longest text parsed; a longer one is refused unparsed.

    Raises:
        ConfigError: too long, not valid YAML, or beyond a bound; with the line.
    """
    if len(text) > max_chars:
        raise ConfigError(f"{source}: longer than {max_chars} characters")
    loader = _LinedLoader(text, source,
                          MAX_YAML_EXPANSION * max(len(text), YAML_EXPANSION_FLOOR))
    try:
        return loader.get_single_data()
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = error.problem or error.context or "invalid"
        raise ConfigError(f"{source}{line}: not valid YAML: {problem}") from None
    except yaml.YAMLError as error:
        raise ConfigError(f"{source}: not valid YAML: {shown(str(error))}") from None
    finally:
        loader.dispose()


class _LinedLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` building ``LinedDict`` and ``LinedList``, refusing duplicate keys.

    It also bounds the document (``parse_yaml``): the nesting and the aliases while it is
    composed, what the aliases expand to once it is, before any value is built.
    """

    def __init__(self, text: str, source: str, max_expanded: int) -> None:
        super().__init__(text)
        self.source = source
        self._max_expanded = max_expanded
        self._depth = 0
        self._aliases = 0

    def _refuse(self, mark: Any, problem: str) -> ConfigError:
        line = f":{mark.line + 1}" if mark is not None else ""
        return ConfigError(f"{self.source}{line}: {problem}")

    def _next_mark(self) -> Any:
        return self.peek_event().start_mark  # type: ignore[no-untyped-call]

    def compose_node(self, parent: Any, index: Any) -> Any:
        """Compose one node, counting aliases and nesting as it goes."""
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_YAML_ALIASES:
                raise self._refuse(self._next_mark(),
                                   f"more than {MAX_YAML_ALIASES} aliases (*name)")
            return super().compose_node(parent, index)
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise self._refuse(self._next_mark(),
                                   f"nested more than {MAX_YAML_DEPTH} levels deep")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def get_single_data(self) -> Any:
        """The document, once its expansion was measured (``_expanded``)."""
        node = self.get_single_node()
        if node is None:
            return None
        self._expanded(node, 1, {}, set())
        return self.construct_document(node)

    def _expanded(self, node: yaml.Node, depth: int, known: dict[int, tuple[int, int]],
                  open_nodes: set[int]) -> int:
        """What ``node`` holds with every alias expanded (characters and nodes).

        Each node is measured once (``known``: its weight and height), however many aliases
        name it, so this costs what the text does. Refuses a document deeper than
        ``MAX_YAML_DEPTH`` or heavier than the bound, and an alias inside what it names.
        """
        key = id(node)
        if key in known:
            weight, height = known[key]
            if depth + height > MAX_YAML_DEPTH:
                raise self._refuse(node.start_mark, f"nested more than {MAX_YAML_DEPTH} "
                                                    "levels deep (aliases expanded)")
            return weight
        if key in open_nodes:
            raise self._refuse(node.start_mark, "an alias refers to a mapping or list that "
                                                "holds it (a recursive structure)")
        if isinstance(node, yaml.ScalarNode):
            known[key] = (1 + len(node.value), 0)
            return 1 + len(node.value)
        children: list[yaml.Node] = list(node.value) if isinstance(node, yaml.SequenceNode) \
            else [child for pair in node.value for child in pair]
        open_nodes.add(key)
        weight, height = 1, 0
        for child in children:
            weight += self._expanded(child, depth + 1, known, open_nodes)
            height = max(height, known[id(child)][1] + 1)
            if weight > self._max_expanded:
                raise self._refuse(node.start_mark, "holds more than "
                                   f"{self._max_expanded} characters with its aliases "
                                   "expanded (an alias bomb?)")
        open_nodes.discard(key)
        known[key] = (weight, height)
        return weight


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
            raise ConfigError(f"{loader.source}:{line}: key {shown(key)} given twice (first "
                              f"at line {first_lines[key]})")
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
