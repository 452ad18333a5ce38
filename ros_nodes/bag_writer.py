"""One rosbag2 of one robot, in MCAP storage: what ``ros2 bag``, Foxglove and Lichtblick open.

Written with rosbags' ``Writer`` and its MCAP storage plugin (no ROS install): a folder with
``metadata.yaml`` (rosbag2 version 9: files, custom_data, each topic's
``type_description_hash`` and ``offered_qos_profiles``) and one ``.mcap`` file (profile
``ros2``; message encoding ``cdr``; schemas ``ros2msg`` with the definition of every type they
depend on; each channel's ``offered_qos_profiles``; the ``rosbag2`` metadata record). Messages
are the robot's dicts in canonical form, serialized by the bridge's own CDR serializer
(``rosbridge.msgs.cdr``); definitions and type hashes come from the same typestore.

Chunks (zstd-compressed) are written every 5 s of messages (``CHUNK_SPAN_NS``), not only
once 1 MiB is held as rosbags does, so a writer that dies loses little.

rosbags 0.11 leaves out two things rosbag2's MCAP plugin writes, filled in here:

* the channel metadata ``topic_type_hash`` (rosbag2 Jazzy and later read a topic's type hash
  from it when they open the ``.mcap`` without its ``metadata.yaml``);
* the ROS distribution: rosbags writes ``ros_distro: rosbags`` in ``metadata.yaml`` and in
  the ``rosbag2`` record; here it is the distribution whose message definitions the bag
  holds (``ROS_DISTRO``: those of the typestore, ``rosbridge.msgs.definitions.TYPESTORE``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import os
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import Any, Final, Literal, cast

import yaml
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.storage_mcap import Channel, McapWriter, write_channel, write_string

from physics.validation import load_yaml_file, parse_yaml, plain_data
from ros_nodes.robot_interface import QOS_PROFILES, RECORDED_TOPICS, QosProfile
from rosbridge.msgs import cdr, definitions

ROSBAG2_VERSION: Final[Literal[9]] = 9
"""The ``metadata.yaml`` version written (rosbag2 Jazzy and later)."""

ROS_DISTRO = definitions.TYPESTORE.value.removeprefix("ros2_")
"""The distribution whose message definitions the bags hold (the bridge's typestore)."""

TYPE_HASH_KEY = "topic_type_hash"
"""The channel metadata key under which rosbag2's MCAP plugin keeps a topic's type hash."""

CHUNK_SPAN_NS = 5_000_000_000
"""A chunk is written once it spans this much log time (5 s), or 1 MiB (rosbags' size):
a writer that dies loses at most that much, and a full disk shows within it."""

INFINITE = QosTime(9_223_372_036, 854_775_807)
"""A QoS duration left at its default (no deadline, lifespan or lease), as rosbag2 records it
from a publisher's offer."""

QOS_POLICIES = {
    "reliable": QosReliability.RELIABLE, "best_effort": QosReliability.BEST_EFFORT,
    "volatile": QosDurability.VOLATILE, "transient_local": QosDurability.TRANSIENT_LOCAL,
}
"""``QosProfile`` policy names -> rosbags' enums."""

_TOPIC_QOS = {spec.name: spec.qos_profile for spec in RECORDED_TOPICS}


def offered_qos(profile: QosProfile) -> Qos:
    """A topic's ``offered_qos_profiles`` entry: what its publisher offers."""
    return Qos(QosHistory.KEEP_LAST, profile.depth,
               cast(QosReliability, QOS_POLICIES[profile.reliability]),
               cast(QosDurability, QOS_POLICIES[profile.durability]),
               INFINITE, INFINITE, QosLiveliness.AUTOMATIC, INFINITE, False)


class _McapStorage(McapWriter):
    """rosbags' MCAP storage, with the channel's type hash and the bag's ROS distribution.

    Attributes:
        messages_in_file: messages in the chunks written to the file so far.
    """

    messages_in_file = 0

    def close_chunk(self) -> None:
        """Write the pending chunk; count its messages once it is written."""
        pending = sum(len(messages) for messages in self.chunk.msgs.values())
        super().close_chunk()
        self.messages_in_file += pending

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        """A channel with ``offered_qos_profiles`` and ``topic_type_hash``, as rosbag2's."""
        metadata = BytesIO()
        for key, value in (("offered_qos_profiles", offered_qos_profiles),
                           (TYPE_HASH_KEY, connection.digest)):
            write_string(metadata, key)
            write_string(metadata, value)
        ext = cast(ConnectionExtRosbag2, connection.ext)
        self.channels.append(Channel(connection.id, connection.msgtype, connection.topic,
                                     ext.serialization_format, metadata.getvalue()))
        self.channel_stats[connection.id] = 0
        write_channel(self.chunk.bio, self.channels[-1], self.schemas)

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        """Append a message; write the chunk to the file once it spans ``CHUNK_SPAN_NS``."""
        super().write(connection, timestamp, data)
        chunk = self.chunk
        if chunk.bio.tell() and chunk.message_end_time - chunk.message_start_time >= \
                CHUNK_SPAN_NS:
            self.close_chunk()
            self.bio.flush()

    def close(self, version: int, metadata: str) -> None:
        """Close with the ``rosbag2`` record's ``ros_distro`` set to ``ROS_DISTRO``."""
        record = plain_data(parse_yaml(metadata, "the bag's rosbag2 metadata record"))
        record["ros_distro"] = ROS_DISTRO
        super().close(version, yaml.safe_dump(record, sort_keys=False).strip())


class _Writer(Writer):
    STORAGE_PLUGINS = {  # noqa: RUF012  (rosbags declares it a plain class attribute)
        **Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: _McapStorage}

    def close(self) -> None:
        """Close the storage and write ``metadata.yaml`` with ``ros_distro`` set."""
        super().close()
        text = plain_data(load_yaml_file(self.metapath, "recording metadata"))
        text["rosbag2_bagfile_information"]["ros_distro"] = ROS_DISTRO
        temporary = self.metapath.with_suffix(".yaml.tmp")
        temporary.write_text(yaml.safe_dump(text, sort_keys=False), encoding="utf-8")
        os.replace(temporary, self.metapath)


@dataclass(frozen=True)
class BagSummary:
    """What a bag holds once closed (or stopped).

    Attributes:
        path: its folder.
        messages: messages written.
        bytes: its size on disk (the ``.mcap`` file and ``metadata.yaml``).
        duration_s: from its first message's log time to its last (s).
        topics: messages per topic.
        complete: closed properly (summary, footer and ``metadata.yaml`` written); False
            when writing failed (a full disk): the ``.mcap`` then ends where it failed.
    """

    path: str
    messages: int
    bytes: int
    duration_s: float
    topics: dict[str, int]
    complete: bool


class BagWriter:
    """One rosbag2 folder, written message by message (not thread-safe: one writer each).

    Args:
        path: the bag's folder; it must not exist (rosbags never overwrites a bag).
        custom_data: ``metadata.yaml``'s ``custom_data`` (strings).
        compress: zstd-compress the MCAP chunks (every MCAP reader reads them; rosbag2's own
            ``zstd_fast`` preset does the same).

    Raises:
        OSError: the folder cannot be made (exists, no permission, full disk).
    """

    def __init__(self, path: Path, custom_data: Mapping[str, str] | None = None,
                 compress: bool = True) -> None:
        self.path = path
        self._writer = _Writer(path, version=ROSBAG2_VERSION, storage_plugin=StoragePlugin.MCAP)
        if compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        for key, value in (custom_data or {}).items():
            self._writer.set_custom_data(key, value)
        try:
            self._writer.open()
        except WriterError:  # rosbags never overwrites a bag
            raise FileExistsError(errno.EEXIST, "the bag's folder exists already",
                                  str(path)) from None
        self._connections: dict[tuple[str, str], Connection] = {}
        self._counts: Counter[str] = Counter()
        self.complete = False

    @property
    def messages(self) -> int:
        """Messages written so far."""
        return sum(self._counts.values())

    @property
    def bytes_on_disk(self) -> int:
        """Bytes written to the ``.mcap`` file so far (chunks are written 1 MiB at a time)."""
        storage = self._writer.storage
        return 0 if storage is None else int(cast(McapWriter, storage).bio.tell())

    def write(self, topic: str, type_name: str, log_time_ns: int, msg: Any) -> None:
        """Append one message, received at ``log_time_ns`` (ns since the epoch).

        Raises:
            CdrError: the message does not fit its type (it is not written).
            OSError: writing failed (a full disk); the bag cannot go on.
        """
        data = cdr.to_cdr(type_name, msg)
        connection = self._connections.get((topic, type_name))
        if connection is None:
            profile = _TOPIC_QOS.get(topic, QOS_PROFILES["reliable"])
            connection = self._writer.add_connection(
                topic, type_name, typestore=cdr.typestore(),
                offered_qos_profiles=[offered_qos(profile)])
            self._connections[(topic, type_name)] = connection
        self._writer.write(connection, log_time_ns, data)
        self._counts[topic] += 1

    def close(self) -> BagSummary:
        """Write the MCAP summary and ``metadata.yaml``; what the bag holds.

        Raises:
            OSError: writing failed (a full disk); ``abort`` then.
        """
        self._writer.close()
        self.complete = True
        return self.summary()

    def abort(self) -> BagSummary:
        """Give up on the bag (writing failed): close its file as it is; what it holds.

        Its summary counts the messages of the chunks written before (what a reader of the
        file up to where it ends finds, at best).
        """
        storage = self._writer.storage
        in_file = cast(_McapStorage, storage).messages_in_file if storage is not None else 0
        with contextlib.suppress(OSError):  # the file is closed even if its flush fails
            self._writer.abort()
        summary = self.summary()
        return dataclasses.replace(summary, messages=min(summary.messages, in_file))

    def summary(self) -> BagSummary:
        """What the bag holds now."""
        writer = self._writer
        size = sum(item.stat().st_size for item in self.path.iterdir() if item.is_file()) \
            if self.path.is_dir() else 0
        span_ns = max(0, writer.max_timestamp - writer.min_timestamp) if self.messages else 0
        return BagSummary(str(self.path), self.messages, size, span_ns / 1e9,
                          dict(self._counts), self.complete)
