"""A recording an instructor opens cannot exhaust the machine (``ros_nodes.bag_bounds``).

The attacks are real MCAP files, built record by record as a hostile student would: a chunk
of zstd-compressed zeros that expands to gigabytes (declared honestly, or declared small), a
chunk index that disagrees with its chunk, chunks that all overlap in time, an alias bomb in
a channel's QoS profiles and in a bag folder's ``metadata.yaml``. ``websim replay`` runs in a
process of its own, which reports its peak memory.
"""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import lz4.frame
import pytest
from mcap.data_stream import RecordBuilder
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    MessageIndex,
    Schema,
)

from physics import ConfigError
from ros_nodes.bag_bounds import MAGIC, BagLimits, check_bag

if sys.version_info >= (3, 14):
    from compression import zstd
else:
    from backports import zstd

MAX_RSS_MB = 400
"""What refusing a bomb may cost the replay process (its imports take about 150 MB)."""

QOS = ("- history: 1\n  depth: 1\n  reliability: 1\n  durability: 2\n"
       "  deadline: {sec: 0, nsec: 0}\n  lifespan: {sec: 0, nsec: 0}\n  liveliness: 1\n"
       "  liveliness_lease_duration: {sec: 0, nsec: 0}\n"
       "  avoid_ros_namespace_conventions: false\n")
"""A channel's offered QoS profile as rosbag2 writes it (rosbags reads every field)."""


def zeros_zstd(megabytes: int) -> bytes:
    """One zstd frame of ``megabytes`` MiB of zeros, made a MiB at a time (a few kB)."""
    compressor = zstd.ZstdCompressor(level=19)
    block = bytes(1 << 20)
    parts = [compressor.compress(block) for _ in range(megabytes)]
    parts.append(compressor.flush())
    return b"".join(parts)


def one_message_chunk() -> bytes:
    """The records of a chunk holding one std_msgs/String on channel 1 (CDR)."""
    inner = RecordBuilder()
    payload = b"\x00\x01\x00\x00" + struct.pack("<I", 3) + b"hi\x00"
    Message(channel_id=1, sequence=0, log_time=1_000, publish_time=1_000,
            data=payload).write(inner)
    return inner.end()


def mcap_file(path: Path, chunks: list[Chunk], *, qos: str = QOS,
              index_override: dict[str, int] | None = None) -> Path:
    """A ros2-profile MCAP: a schema, a channel, ``chunks``, and a summary indexing them."""
    out = RecordBuilder()
    out.write(MAGIC)
    Header(profile="ros2", library="test").write(out)
    schema = Schema(id=1, name="std_msgs/msg/String", encoding="ros2msg", data=b"string data")
    channel = Channel(id=1, schema_id=1, topic="/chatter", message_encoding="cdr",
                      metadata={"offered_qos_profiles": qos})
    schema.write(out)
    channel.write(out)
    indexes = []
    for chunk in chunks:
        offset = out.count
        chunk.write(out)
        chunk_length = out.count - offset
        index_offset = out.count  # its message index: a reader then knows channel 1 is in it
        MessageIndex(channel_id=1, records=[(chunk.message_start_time, 0)]).write(out)
        fields = {"compressed_size": len(chunk.data),
                  "uncompressed_size": chunk.uncompressed_size, **(index_override or {})}
        indexes.append(ChunkIndex(
            message_start_time=chunk.message_start_time,
            message_end_time=chunk.message_end_time, chunk_start_offset=offset,
            chunk_length=chunk_length, message_index_offsets={1: index_offset},
            message_index_length=out.count - index_offset,
            compression=chunk.compression, **fields))
    DataEnd(data_section_crc=0).write(out)
    summary_start = out.count
    schema.write(out)
    channel.write(out)
    for index in indexes:
        index.write(out)
    Footer(summary_start=summary_start, summary_offset_start=0, summary_crc=0).write(out)
    out.write(MAGIC)
    path.write_bytes(out.end())
    return path


def chunk(data: bytes, compression: str, declared: int, start_ns: int = 1_000,
          end_ns: int = 1_000) -> Chunk:
    return Chunk(compression=compression, data=data, message_start_time=start_ns,
                 message_end_time=end_ns, uncompressed_crc=0, uncompressed_size=declared)


def replay_refuses(bag: Path, reason: str) -> None:
    """``websim replay BAG`` exits 2 with ``reason``, within ``MAX_RSS_MB`` of memory."""
    # VmHWM, not getrusage's ru_maxrss: Linux keeps ru_maxrss across exec, so a child of a
    # large pytest process (a whole suite's) would report the parent's peak
    script = ("import re, sys\n"
              "from pathlib import Path\n"
              "from websim.cli import main\n"
              f"code = main(['replay', {str(bag)!r}, '--ws-port', '0', '--http-port', '0'])\n"
              "status = Path('/proc/self/status').read_text()\n"
              "kb = int(re.search(r'VmHWM:\\s+(\\d+)', status).group(1))\n"
              "print('peak_rss_mb', kb >> 10)\n"
              "sys.exit(code)\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=120, check=False)
    assert result.returncode == 2, result.stdout + result.stderr
    assert reason in result.stderr, result.stderr
    peak_mb = int(result.stdout.split("peak_rss_mb")[1])
    assert peak_mb < MAX_RSS_MB, f"websim replay reached {peak_mb} MB refusing {bag.name}"


def test_a_small_mcap_whose_chunk_expands_to_gigabytes_is_refused(tmp_path: Path) -> None:
    frame = zeros_zstd(256)
    data = frame * 8  # 2 GiB of zeros, declared honestly
    bag = mcap_file(tmp_path / "bomb.mcap", [chunk(data, "zstd", 2 << 30)])
    assert bag.stat().st_size < 100_000
    replay_refuses(bag, "a chunk of 2147483648 bytes decompressed, more than")


def test_a_chunk_that_declares_less_than_it_holds_is_refused_unexpanded(
        tmp_path: Path) -> None:
    data = zeros_zstd(256) * 8  # 2 GiB, declared as 100 bytes
    bag = mcap_file(tmp_path / "liar.mcap", [chunk(data, "zstd", 100)])
    replay_refuses(bag, "a chunk that declares 100 bytes decompressed holds more")


def test_an_lz4_chunk_that_lies_is_refused_too(tmp_path: Path) -> None:
    data = lz4.frame.compress(bytes(8 << 20))
    bag = mcap_file(tmp_path / "liar_lz4.mcap", [chunk(data, "lz4", 64)])
    with pytest.raises(ConfigError, match="declares 64 bytes decompressed holds more"):
        check_bag(bag)


def test_a_chunk_index_that_disagrees_with_its_chunk_is_refused(tmp_path: Path) -> None:
    records = one_message_chunk()
    bag = mcap_file(tmp_path / "index.mcap", [chunk(records, "", len(records))],
                    index_override={"uncompressed_size": 1 << 40})
    with pytest.raises(ConfigError, match="a chunk index names no chunk like it"):
        check_bag(bag)


def test_chunks_overlapping_in_time_are_bounded_together(tmp_path: Path) -> None:
    """Each chunk within the bound; a reader merging them by time would hold them all."""
    records = one_message_chunk()
    padded = zstd.compress(records + bytes(1 << 20))
    chunks = [chunk(padded, "zstd", len(records) + (1 << 20), 1_000, 9_000) for _ in range(8)]
    bag = mcap_file(tmp_path / "overlap.mcap", chunks)
    limits = BagLimits(open_chunk_bytes=4 << 20)
    with pytest.raises(ConfigError, match="chunks overlapping in time declare more than"):
        check_bag(bag, limits)
    check_bag(bag)  # the default bound holds eight 1 MiB chunks


def test_an_alias_bomb_in_a_channels_qos_profiles_is_refused(tmp_path: Path) -> None:
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"a{n}: &a{n} [{', '.join([f'*a{n - 1}'] * 9)}]" for n in range(1, 9)]
    records = one_message_chunk()
    bag = mcap_file(tmp_path / "qos.mcap", [chunk(records, "", len(records))],
                    qos="\n".join(lines))
    replay_refuses(bag, "with its aliases expanded")


def test_an_alias_bomb_in_a_bag_folders_metadata_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "bag"
    folder.mkdir()
    records = one_message_chunk()
    mcap_file(folder / "bag_0.mcap", [chunk(records, "", len(records))])
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"a{n}: &a{n} [{', '.join([f'*a{n - 1}'] * 9)}]" for n in range(1, 9)]
    lines.append("rosbag2_bagfile_information: *a8")
    (folder / "metadata.yaml").write_text("\n".join(lines) + "\n")
    replay_refuses(folder, "with its aliases expanded")


def test_a_bag_compressed_per_file_is_refused_with_how_to_convert_it(tmp_path: Path) -> None:
    folder = tmp_path / "bag"
    folder.mkdir()
    (folder / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n"
        "  compression_mode: FILE\n  compression_format: zstd\n"
        "  relative_file_paths: [bag_0.mcap.zstd]\n")
    with pytest.raises(ConfigError, match=r"compressed per file .*ros2 bag"):
        check_bag(folder)


def test_an_honest_compressed_file_passes(tmp_path: Path) -> None:
    records = one_message_chunk()
    bag = mcap_file(tmp_path / "fine.mcap", [chunk(zstd.compress(records), "zstd",
                                                   len(records))])
    check_bag(bag)
