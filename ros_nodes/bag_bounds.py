"""A recording checked before it is read: nothing in a bag can make its reader exhaust memory.

An MCAP file is compressed in chunks, each declaring its size once decompressed; rosbags (the
reader ``websim replay`` plays with) decompresses a chunk whole, without an output bound, and
compares the sizes only afterwards: an 8 kB file of zstd-compressed zeros took the replay to
1.4 GB. ``check_bag`` walks every record of every MCAP file of a bag first, without trusting
it:

* every record's length is within ``BagLimits.record_bytes`` before it is read;
* every chunk declares at most ``BagLimits.chunk_bytes`` decompressed, and holds exactly
  that: it is decompressed with its output bounded by its declaration (zstd and lz4 both
  stop there), so a chunk that lies is refused after reading one byte past what it
  declared, never expanded;
* every chunk index (what the reader seeks by) names a chunk record that agrees with it,
  and the chunks a reader holds at once (those whose time ranges overlap: it merges their
  messages by time) declare at most ``BagLimits.open_chunk_bytes`` together;
* every YAML inside (the folder's ``metadata.yaml``, each channel's QoS profiles) goes
  through the project's bounded loader (``physics.validation.parse_yaml``);
* a bag compressed per file or per message (``ros2 bag record --compression-mode``, which
  rosbags would decompress whole) is refused with how to convert it.

The check reads the file once (and decompresses it once, a chunk at a time); the reader then
reads what was checked. A file changed between the two is the instructor's own doing.
"""

from __future__ import annotations

import struct
import sys
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any, BinaryIO

import lz4.frame

from physics import ConfigError
from physics.validation import load_yaml_file, parse_yaml, shown

if sys.version_info >= (3, 14):
    from compression import zstd
else:
    from backports import zstd

MAGIC = b"\x89MCAP0\r\n"
"""What starts and ends an MCAP file."""

_CHUNK, _CHUNK_INDEX, _CHANNEL, _FOOTER = 0x06, 0x08, 0x04, 0x02
"""The MCAP records the check reads (the specification's opcodes); it skips the others."""

_HEADER = struct.Struct("<BQ")
"""A record's opcode (uint8) and content length (uint64)."""

MAX_COMPRESSION_CHARS = 16
"""Longest compression name a chunk may give (``""``, ``zstd``, ``lz4``)."""


@dataclass(frozen=True)
class BagLimits:
    """What a bag may make its reader hold.

    Attributes:
        record_bytes: the largest record as stored (a chunk's compressed data, an
            attachment...).
        chunk_bytes: the largest chunk once decompressed (rosbag2 writes chunks of about
            1 MB, websim's of a few seconds: far below).
        open_chunk_bytes: what the chunks a reader holds at once declare together (chunks
            whose time ranges overlap).
    """

    record_bytes: int = 80 << 20
    chunk_bytes: int = 64 << 20
    open_chunk_bytes: int = 256 << 20


@dataclass(frozen=True)
class _Chunk:
    """A chunk record as the file declares it."""

    start_ns: int
    end_ns: int
    compression: str
    compressed_bytes: int
    uncompressed_bytes: int


def check_bag(path: Path, limits: BagLimits | None = None) -> None:
    """Check a bag (its folder, or an ``.mcap`` file) before a reader opens it.

    Raises:
        ConfigError: the bag is beyond a bound, or lies about its sizes (the message names
            the file and what is wrong); a file that cannot be read.
    """
    limits = limits or BagLimits()
    if path.is_dir():
        for file in _bag_files(path):
            if file.suffix == ".mcap":
                check_mcap(file, limits)
    elif path.suffix == ".mcap":
        check_mcap(path, limits)


def _bag_files(folder: Path) -> list[Path]:
    """The storage files a bag folder's ``metadata.yaml`` names (checked as it is read)."""
    metadata_path = folder / "metadata.yaml"
    if not metadata_path.is_file():
        return sorted(folder.glob("*.mcap"))
    document: Any = load_yaml_file(metadata_path, "recording metadata")
    info = document.get("rosbag2_bagfile_information") if isinstance(document, dict) else None
    if not isinstance(info, dict):
        raise ConfigError(f"{metadata_path}: not a rosbag2 metadata file (no "
                          "rosbag2_bagfile_information)")
    mode = str(info.get("compression_mode") or "none").lower()
    if mode not in ("", "none"):
        raise ConfigError(f"{metadata_path}: compressed per {mode} (compression_mode); "
                          "websim replay reads MCAP's own chunk compression only: convert it "
                          "first (ros2 bag convert, or ros2 bag decompress)")
    names = info.get("relative_file_paths") or []
    if not isinstance(names, list) or not all(isinstance(name, str) for name in names):
        raise ConfigError(f"{metadata_path}: relative_file_paths: expected a list of file "
                          f"names, got {shown(names)}")
    return [folder / PurePath(name).name for name in names]


def check_mcap(path: Path, limits: BagLimits | None = None) -> None:
    """Check every record of one MCAP file (see the module's text).

    Raises:
        ConfigError: beyond a bound, or a chunk that lies about its size.
    """
    limits = limits or BagLimits()
    try:
        with path.open("rb") as stream:
            _walk(stream, str(path), limits)
    except OSError as error:
        raise ConfigError(f"{path}: cannot read this recording: {error.strerror}") from None


def _walk(stream: BinaryIO, source: str, limits: BagLimits) -> None:
    if stream.read(len(MAGIC)) != MAGIC:
        return  # not MCAP: the reader says so
    chunks: dict[int, _Chunk] = {}
    indexes: list[tuple[int, _Chunk]] = []
    while True:
        offset = stream.tell()
        header = stream.read(_HEADER.size)
        if len(header) < _HEADER.size:
            break  # the end, or a truncated file: the reader says so
        opcode, length = _HEADER.unpack(header)
        where = f"{source}: the record at byte {offset}"
        if opcode == _FOOTER:
            break
        if length > limits.record_bytes:
            raise ConfigError(f"{where} is {length} bytes long, more than "
                              f"{limits.record_bytes} (websim replay's bound)")
        if opcode not in (_CHUNK, _CHUNK_INDEX, _CHANNEL):
            stream.seek(length, 1)
            continue
        content = stream.read(length)
        if len(content) < length:
            break  # truncated: the reader says so
        try:
            if opcode == _CHUNK:
                chunks[offset] = _check_chunk(content, where, limits)
            elif opcode == _CHUNK_INDEX:
                indexes.append(_chunk_index(content))
            else:
                _check_channel(content, where)
        except (struct.error, UnicodeDecodeError, IndexError) as error:
            raise ConfigError(f"{where} is malformed: {error}") from None
    _check_indexes(source, chunks, indexes, limits)


class _Fields:
    """Reads an MCAP record's fields (little-endian) from its content, in order."""

    def __init__(self, content: bytes) -> None:
        self._content = content
        self._at = 0

    def number(self, form: str) -> int:
        value: int = struct.unpack_from(f"<{form}", self._content, self._at)[0]
        self._at += struct.calcsize(form)
        return value

    def raw(self, size: int) -> bytes:
        if self._at + size > len(self._content):
            raise IndexError(f"a field of {size} bytes runs past the record's end")
        value = self._content[self._at:self._at + size]
        self._at += size
        return value

    def string(self, most: int | None = None) -> str:
        size = self.number("I")
        if most is not None and size > most:
            raise IndexError(f"a name of {size} bytes where at most {most} are expected")
        return self.raw(size).decode()

    def skip_sized(self, form: str) -> None:
        self.raw(self.number(form))


def _check_chunk(content: bytes, where: str, limits: BagLimits) -> _Chunk:
    """A chunk's declaration, once its data was found to hold exactly what it declares."""
    fields = _Fields(content)
    start_ns, end_ns, declared = fields.number("Q"), fields.number("Q"), fields.number("Q")
    fields.number("I")  # the CRC: the reader checks it
    compression = fields.string(MAX_COMPRESSION_CHARS)
    data = fields.raw(fields.number("Q"))
    if declared > limits.chunk_bytes:
        raise ConfigError(f"{where}: a chunk of {declared} bytes decompressed, more than "
                          f"{limits.chunk_bytes} (websim replay's bound)")
    size = _decompressed_size(data, compression, declared, where)
    if size != declared:
        raise ConfigError(f"{where}: a chunk that declares {declared} bytes decompressed "
                          + ("holds more (a decompression bomb?)" if size > declared
                             else f"holds {size}"))
    return _Chunk(start_ns, end_ns, compression, len(data), declared)


def _decompressed_size(data: bytes, compression: str, declared: int, where: str) -> int:
    """How many bytes ``data`` decompresses to, counting no further than ``declared`` + 1.

    Every frame is decompressed (zstd's and lz4's decompress take concatenated frames), each
    with its output bounded by what is left of the declaration.
    """
    if compression == "":
        return len(data)
    if compression not in ("zstd", "lz4"):
        raise ConfigError(f"{where}: chunk compression '{compression}' is not one websim "
                          "replay reads (zstd, lz4, none)")
    total, rest = 0, data
    try:
        while rest and total <= declared:
            room = declared + 1 - total
            part: Any = zstd.ZstdDecompressor() if compression == "zstd" else \
                lz4.frame.LZ4FrameDecompressor()
            total += len(part.decompress(rest, max_length=room))
            if not part.eof:
                if total <= declared:
                    raise ConfigError(f"{where}: a chunk whose compressed data ends inside "
                                      "a frame")
                break  # past its declaration: refused below, never decompressed further
            rest = part.unused_data
    except (zstd.ZstdError, RuntimeError) as error:
        raise ConfigError(f"{where}: a chunk that does not decompress ({error})") from None
    return total


def _chunk_index(content: bytes) -> tuple[int, _Chunk]:
    """A chunk index's chunk offset and what it says of the chunk."""
    fields = _Fields(content)
    start_ns, end_ns, offset = fields.number("Q"), fields.number("Q"), fields.number("Q")
    fields.number("Q")  # the chunk's record length
    fields.skip_sized("I")  # message index offsets
    fields.number("Q")  # message index length
    compression = fields.string(MAX_COMPRESSION_CHARS)
    compressed, uncompressed = fields.number("Q"), fields.number("Q")
    return offset, _Chunk(start_ns, end_ns, compression, compressed, uncompressed)


def _check_channel(content: bytes, where: str) -> None:
    """A channel's metadata map: its QoS profiles are YAML, read by the bounded loader."""
    fields = _Fields(content)
    fields.number("H")  # id
    fields.number("H")  # schema id
    fields.string()  # topic
    fields.string()  # message encoding
    metadata = _Fields(fields.raw(fields.number("I")))
    while True:
        try:
            key = metadata.string()
        except (struct.error, IndexError):
            return
        value = metadata.string()
        if key == "offered_qos_profiles":
            parse_yaml(value, f"{where}: offered_qos_profiles")


def _check_indexes(source: str, chunks: dict[int, _Chunk],
                   indexes: list[tuple[int, _Chunk]], limits: BagLimits) -> None:
    """Every chunk index agrees with its chunk; overlapping chunks stay within the bound."""
    for offset, index in indexes:
        chunk = chunks.get(offset)
        if chunk is None or (chunk.compression, chunk.compressed_bytes,
                             chunk.uncompressed_bytes) != (index.compression,
                                                           index.compressed_bytes,
                                                           index.uncompressed_bytes):
            raise ConfigError(f"{source}: a chunk index names no chunk like it at byte "
                              f"{offset}")
    events = sorted([(index.start_ns, 0, index.uncompressed_bytes) for _, index in indexes]
                    + [(index.end_ns, 1, -index.uncompressed_bytes) for _, index in indexes])
    held = 0
    for _, _, change in events:
        held += change
        if held > limits.open_chunk_bytes:
            raise ConfigError(f"{source}: chunks overlapping in time declare more than "
                              f"{limits.open_chunk_bytes} bytes together, which a reader "
                              "would hold at once (websim replay's bound)")

