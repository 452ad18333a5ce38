"""Reading a recording back with two independent readers, and what ``ros2 bag info`` shows.

* rosbags' ``Reader`` (rosbag2 folders: ``metadata.yaml`` and the MCAP storage plugin) with
  its ROS 2 typestore's CDR deserializer;
* the ``mcap`` package's reader with ``mcap-ros2-support``'s decoder, which builds its
  decoders from the schemas in the file alone (the ``ros2msg`` text with its dependencies).

Both give ``Read`` records with plain values, so tests compare them with each other and with
what a rosbridge client received.
"""

from __future__ import annotations

import base64
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore


@dataclass(frozen=True)
class Read:
    """One message as a reader gave it: topic, type, log time (ns), its fields as dicts."""

    topic: str
    type: str
    log_time_ns: int
    message: dict[str, Any]


def plain(value: Any) -> Any:
    """A decoded message (rosbags' dataclasses, mcap-ros2's objects, numpy arrays) as dicts."""
    if dataclasses.is_dataclass(value):  # rosbags; ROS 2 names fields lower, constants UPPER
        return {field.name: plain(getattr(value, field.name))
                for field in dataclasses.fields(value)
                if not field.name.startswith("__") and not field.name.isupper()}
    if hasattr(value, "__slots__") and not isinstance(value, (str, bytes)):  # mcap-ros2
        names = [name for name in value.__slots__ if not name.startswith("_")]
        return {name: plain(getattr(value, name)) for name in names}
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if hasattr(value, "tolist"):
        return plain(value.tolist())
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    return value


def read_with_rosbags(bag: Path) -> list[Read]:
    """Every message of a rosbag2 folder, in log-time order, by rosbags."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(bag) as reader:
        return [Read(connection.topic, connection.msgtype, log_time,
                     plain(store.deserialize_cdr(raw, connection.msgtype)))
                for connection, log_time, raw in reader.messages()]


def read_with_mcap(bag: Path) -> list[Read]:
    """Every message of the bag's ``.mcap`` file, in log-time order, by mcap + mcap-ros2."""
    (path,) = bag.glob("*.mcap")
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        return [Read(channel.topic, schema.name, message.log_time, plain(decoded))
                for schema, channel, message, decoded
                in reader.iter_decoded_messages(log_time_order=True)]


def mcap_summary(bag: Path) -> Any:
    """The ``.mcap`` file's header, summary (schemas, channels, statistics) and metadata."""
    (path,) = bag.glob("*.mcap")
    with path.open("rb") as stream:
        reader = make_reader(stream)
        return (reader.get_header(), reader.get_summary(),
                {record.name: record.metadata for record in reader.iter_metadata()})


def bag_info(bag: Path) -> dict[str, Any]:
    """What ``ros2 bag info`` prints of a bag, from its ``metadata.yaml`` as rosbag2 reads it.

    Keys: ``version``, ``storage``, ``files``, ``messages``, ``duration_s``, ``start_ns``,
    ``ros_distro``, ``custom_data`` and ``topics``: name -> (type, count, serialization
    format, type hash, QoS profiles).
    """
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return {
        "version": info["version"],
        "storage": info["storage_identifier"],
        "files": info["relative_file_paths"],
        "file_entries": info["files"],
        "messages": info["message_count"],
        "duration_s": info["duration"]["nanoseconds"] / 1e9,
        "start_ns": info["starting_time"]["nanoseconds_since_epoch"],
        "ros_distro": info["ros_distro"],
        "custom_data": info["custom_data"],
        "topics": {item["topic_metadata"]["name"]: (
            item["topic_metadata"]["type"], item["message_count"],
            item["topic_metadata"]["serialization_format"],
            item["topic_metadata"]["type_description_hash"],
            item["topic_metadata"]["offered_qos_profiles"])
            for item in info["topics_with_message_count"]},
    }


def close(a: Any, b: Any, tolerance: float = 0.0, where: str = "") -> None:
    """Assert two plain values equal (floats within ``tolerance``; NaN equals NaN).

    A ``uint8[]`` as base64 text (rosbridge's form of it) equals the list of its bytes.
    """
    if isinstance(a, str) and isinstance(b, list):
        a = list(base64.b64decode(a))
    if isinstance(b, str) and isinstance(a, list):
        b = list(base64.b64decode(b))
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), f"{where}: {a} != {b}"
        for key in a:
            close(a[key], b[key], tolerance, f"{where}.{key}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{where}: length {len(a)} != {len(b)}"
        for index, (x, y) in enumerate(zip(a, b, strict=True)):
            close(x, y, tolerance, f"{where}[{index}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert (math.isnan(a) and math.isnan(b)) or a == b or \
            abs(a - b) <= tolerance, f"{where}: {a} != {b}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"
