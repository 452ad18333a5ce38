"""A real robot's recording read into a ``physics.recorded_run.RecordedRun``.

What real robots record, read with rosbags (no ROS install needed): a rosbag2 folder or its
file, with sqlite3 (``.db3``, Humble's default) or MCAP storage; a ROS 1 ``.bag``; or a CSV
with the columns ``CSV_COLUMNS`` (a command row fills ``cmd_v``, ``cmd_omega``; a pose row
``x``, ``y``, ``yaw``; a row may fill both). From the bag, the command topic (Twist or
TwistStamped) and the pose topic: odometry (``nav_msgs/Odometry``), or ground truth when one
is named (motion capture: ``PoseStamped``, ``Odometry``, or a ``TFMessage``'s transform to a
child frame).

Times: ``receive`` stamps (the default) are when the recorder got each message, all on one
clock (the recorder's); ``header`` stamps are the senders' (the robot's clock for /odom); a
message without a header (a plain Twist) keeps its receive stamp. A clock that jumps backwards,
or commands and poses whose times never overlap (two unsynchronised clocks), are refused with
what was seen and the other choice of stamps.

Bounded: at most ``MAX_MESSAGES`` messages per topic and ``MAX_MESSAGE_BYTES`` per message are
read (rosbags reads lazily, one message at a time, and only the chosen topics are decoded);
a CSV of more than ``MAX_CSV_BYTES`` is refused before it is read.
"""

from __future__ import annotations

import csv
import math
import sqlite3
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from grading.recorded import yaw_of
from physics import ConfigError
from physics.recorded_run import RecordedRun

STAMPS = ("receive", "header")
"""Which time a message gets: when the recorder received it, or its header's stamp."""

CMD_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")
POSE_TYPES = ("nav_msgs/msg/Odometry",)
TRUTH_TYPES = ("geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage",
               "geometry_msgs/msg/PoseWithCovarianceStamped", "geometry_msgs/msg/TransformStamped")

CSV_COLUMNS = ("t_s", "cmd_v", "cmd_omega", "x", "y", "yaw")
"""A recording as CSV: time (s), commanded linear.x (m/s) and angular.z (rad/s), measured
x, y (m) and yaw (rad)."""

MAX_MESSAGES = 2_000_000
"""Most messages read from one topic: 27 hours at 20 Hz; more is refused (cut a window)."""

MAX_MESSAGE_BYTES = 1 << 20
"""Largest message read (1 MiB): a Twist is 48 bytes, an Odometry about 700, a TFMessage a
few kB; a larger one on these topics is a damaged or hostile file."""

MAX_CSV_BYTES = 512 << 20
"""Largest CSV read (512 MiB, some 8 million rows)."""

BAG_SUFFIXES = (".mcap", ".db3", ".bag")


@dataclass(frozen=True)
class Recording:
    """A recording read: the run and what was read to make it.

    Attributes:
        run: the commands and poses, in seconds from the first message read.
        info: the path, its kind, the topics and types used, the stamps and the counts.
    """

    run: RecordedRun
    info: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Topics:
    """Which topics to read.

    Attributes:
        cmd: the commands (Twist or TwistStamped).
        odom: the odometry (used when no ground truth is named).
        truth: a ground-truth pose topic, or None.
        truth_frame: with a TFMessage ground truth, the child frame that is the robot.
    """

    cmd: str = "/cmd_vel"
    odom: str = "/odom"
    truth: str | None = None
    truth_frame: str = "base_link"


def read_recording(path: Path, topics: Topics = Topics(), stamps: str = "receive",
                   start_s: float | None = None, end_s: float | None = None) -> Recording:
    """Read a bag or CSV, keeping the window ``start_s`` to ``end_s`` (s from its start).

    The command in force at the window's start (the last one before it) is kept.

    Raises:
        ConfigError: missing file or topics, an unknown type, a damaged file, a clock that
            jumps backwards, or nothing in the window; the message says what the file has.
    """
    if stamps not in STAMPS:
        raise ConfigError(f"--stamps must be one of {', '.join(STAMPS)}, got {stamps!r}")
    if not path.exists():
        raise ConfigError(f"{path}: no such recording (a rosbag2 folder, a .db3, .mcap or "
                          "ROS 1 .bag file, or a CSV)")
    if path.suffix.lower() == ".csv":
        commands, poses, info = _read_csv(path)
    else:
        commands, poses, info = _read_bag(path, topics, stamps)
    return _windowed(path, commands, poses, info, start_s, end_s)


Timed = list[tuple[int, tuple[float, ...]]]
"""(time ns, values) in the order read."""


def _bag_path(path: Path) -> Path:
    """The rosbag2 folder when ``path`` is a file of one with its metadata, else ``path``."""
    if path.is_file() and path.suffix in (".mcap", ".db3") and \
            (path.parent / "metadata.yaml").is_file():
        return path.parent
    return path


def _read_bag(path: Path, topics: Topics, stamps: str) -> tuple[Timed, Timed, dict[str, Any]]:
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    bag = _bag_path(path)
    pose_topic = topics.truth or topics.odom
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except (AnyReaderError, OSError, sqlite3.Error, struct.error, ValueError, KeyError,
            IndexError, EOFError) as error:
        raise ConfigError(f"{path}: cannot read this recording: damaged, truncated or not a "
                          f"bag ({_damaged(error)})") from None
    try:
        available = {c.topic: (c.msgtype, 0) for c in reader.connections}
        for connection in reader.connections:
            kind, count = available[connection.topic]
            available[connection.topic] = (kind, count + connection.msgcount)
        _check_topics(path, available, topics, pose_topic)
        cmd_conns = [c for c in reader.connections if c.topic == topics.cmd]
        pose_conns = [c for c in reader.connections if c.topic == pose_topic]
        _check_type(path, topics.cmd, cmd_conns[0].msgtype, CMD_TYPES, "--cmd-topic")
        _check_type(path, pose_topic, pose_conns[0].msgtype,
                    TRUTH_TYPES if topics.truth else POSE_TYPES,
                    "--truth-topic" if topics.truth else "--odom-topic")
        for topic in (topics.cmd, pose_topic):
            if available[topic][1] > MAX_MESSAGES:
                raise ConfigError(f"{path}: {topic} has {available[topic][1]} messages, more "
                                  f"than websim reads ({MAX_MESSAGES}); cut a part with "
                                  "ros2 bag convert or rosbags-convert")
        commands: Timed = []
        poses: Timed = []
        header_used = {topics.cmd: False, pose_topic: False}
        wanted = cmd_conns + pose_conns
        messages = reader.messages(connections=wanted)
        for connection, log_ns, raw in _guarded(path, messages):
            if len(raw) > MAX_MESSAGE_BYTES:
                raise ConfigError(f"{path}: a {connection.topic} message of {len(raw)} bytes "
                                  f"(more than {MAX_MESSAGE_BYTES}): the file is damaged")
            try:
                msg: Any = reader.deserialize(raw, connection.msgtype)
            except (ValueError, KeyError, IndexError, struct.error, AssertionError) as error:
                raise ConfigError(f"{path}: a {connection.topic} message at {log_ns} ns does "
                                  f"not decode as {connection.msgtype} ({error}): the file is "
                                  "damaged") from None
            if connection.topic == topics.cmd:
                stamp_ns, twist = _twist(msg, log_ns, stamps)
                header_used[topics.cmd] |= stamp_ns != log_ns or hasattr(msg, "header")
                commands.append((stamp_ns, (float(twist.linear.x), float(twist.angular.z))))
                _bounded(path, topics.cmd, commands)
            else:
                found = _pose(msg, log_ns, stamps, topics.truth_frame)
                if found is not None:
                    header_used[pose_topic] = stamps == "header"
                    poses.append(found)
                    _bounded(path, pose_topic, poses)
    finally:
        reader.close()
    sqlite = bag.suffix == ".db3" or (bag.is_dir() and any(bag.glob("*.db3")))
    kind = ("ROS 1 bag" if path.suffix == ".bag" else
            "rosbag2 (sqlite3)" if sqlite else "rosbag2 (MCAP)")
    info = {"path": str(path), "kind": kind, "stamps": stamps,
            "command_topic": [topics.cmd, cmd_conns[0].msgtype],
            "pose_topic": [pose_topic, pose_conns[0].msgtype],
            "pose_source": "ground truth" if topics.truth else "odometry",
            "command_stamps": "header" if stamps == "header" and header_used[topics.cmd]
            else "receive",
            "pose_stamps": stamps}
    if topics.truth and pose_conns[0].msgtype == "tf2_msgs/msg/TFMessage":
        info["truth_frame"] = topics.truth_frame
    return commands, poses, info


def _guarded(path: Path, messages: Iterator[Any]) -> Iterator[Any]:
    """The reader's messages; a damaged or truncated file's error as a ConfigError."""
    from rosbags.highlevel import AnyReaderError

    count = 0
    while True:
        try:
            item = next(messages)
        except StopIteration:
            return
        except (AnyReaderError, OSError, sqlite3.Error, struct.error, ValueError, KeyError,
                IndexError, EOFError, AssertionError) as error:
            raise ConfigError(f"{path}: the recording is damaged or truncated after {count} "
                              f"messages ({_damaged(error)}); a bag copied while it was "
                              "written? ros2 bag reindex may repair a rosbag2 folder") from None
        count += 1
        yield item


def _damaged(error: BaseException) -> str:
    text = str(error) or type(error).__name__
    return text if len(text) < 300 else text[:300] + "..."


def _check_topics(path: Path, available: dict[str, tuple[str, int]], topics: Topics,
                  pose_topic: str) -> None:
    def listing() -> str:
        if not available:
            return "it has no topics"
        return "it has " + ", ".join(f"{name} ({kind}, {count} messages)"
                                     for name, (kind, count) in sorted(available.items()))

    has_cmd = available.get(topics.cmd, ("", 0))[1] > 0
    has_pose = available.get(pose_topic, ("", 0))[1] > 0
    if has_cmd and not has_pose:
        what = "ground truth" if topics.truth else "odometry"
        flag = "--truth-topic" if topics.truth else "--odom-topic"
        raise ConfigError(f"{path}: commands but no {what}: {available[topics.cmd][1]} "
                          f"{topics.cmd} messages and no {pose_topic} messages ({listing()}); "
                          f"record it too (ros2 bag record /cmd_vel /odom /scan) or name "
                          f"the topic with {flag}")
    for topic, flag in ((topics.cmd, "--cmd-topic"), (pose_topic, "--truth-topic"
                                                      if topics.truth else "--odom-topic")):
        if topic not in available:
            raise ConfigError(f"{path}: no topic {topic} ({listing()}); name the right one "
                              f"with {flag}")
        if available[topic][1] == 0:
            raise ConfigError(f"{path}: {topic} has no messages ({listing()})")


def _check_type(path: Path, topic: str, msgtype: str, known: tuple[str, ...],
                flag: str) -> None:
    if msgtype not in known:
        raise ConfigError(f"{path}: {topic} is {msgtype}, which websim cannot read there "
                          f"(it reads {', '.join(known)}); name another topic with {flag}")


def _bounded(path: Path, topic: str, items: Timed) -> None:
    if len(items) > MAX_MESSAGES:
        raise ConfigError(f"{path}: {topic} has more than {MAX_MESSAGES} messages, more than "
                          "websim reads; cut a part with ros2 bag convert or rosbags-convert")


def _header_ns(msg: Any) -> int:
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _twist(msg: Any, log_ns: int, stamps: str) -> tuple[int, Any]:
    if hasattr(msg, "twist"):  # TwistStamped
        return (_header_ns(msg) if stamps == "header" else log_ns), msg.twist
    return log_ns, msg


def _pose(msg: Any, log_ns: int, stamps: str,
          child_frame: str) -> tuple[int, tuple[float, ...]] | None:
    """(time, (x, y, yaw)) of an odometry or ground-truth message; None if not the robot's."""
    if hasattr(msg, "transforms"):  # TFMessage: the transform to the robot's frame, if any
        for transform in msg.transforms:
            if transform.child_frame_id.lstrip("/") == child_frame.lstrip("/"):
                return _pose(transform, log_ns, stamps, child_frame)
        return None
    stamp_ns = _header_ns(msg) if stamps == "header" else log_ns
    if hasattr(msg, "transform"):  # TransformStamped
        where, orientation = msg.transform.translation, msg.transform.rotation
    else:
        pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
        where, orientation = pose.position, pose.orientation
    return stamp_ns, (float(where.x), float(where.y), yaw_of(orientation))


def _read_csv(path: Path) -> tuple[Timed, Timed, dict[str, Any]]:
    try:
        size = path.stat().st_size
        if size > MAX_CSV_BYTES:
            raise ConfigError(f"{path}: {size} bytes, more than websim reads from a CSV "
                              f"({MAX_CSV_BYTES}); cut a part")
        stream = path.open(encoding="utf-8", newline="")
    except OSError as error:
        raise ConfigError(f"{path}: cannot read: {error.strerror}") from None
    commands: Timed = []
    poses: Timed = []
    with stream:
        try:
            rows = csv.DictReader(stream)
            missing = [name for name in CSV_COLUMNS if name not in (rows.fieldnames or [])]
            if missing:
                raise ConfigError(f"{path}: no column {', '.join(missing)} (a recording CSV "
                                  f"has the columns {', '.join(CSV_COLUMNS)}; got "
                                  f"{', '.join(rows.fieldnames or []) or 'none'})")
            for line, row in enumerate(rows, start=2):
                values = {name: _csv_number(path, line, name, row.get(name))
                          for name in CSV_COLUMNS}
                t_s = values["t_s"]
                if t_s is None:
                    raise ConfigError(f"{path}:{line}: t_s is empty")
                stamp_ns = round(t_s * 1e9)
                if values["cmd_v"] is not None or values["cmd_omega"] is not None:
                    commands.append((stamp_ns, (values["cmd_v"] or 0.0,
                                                values["cmd_omega"] or 0.0)))
                    _bounded(path, "cmd_v", commands)
                pose = (values["x"], values["y"], values["yaw"])
                if any(value is not None for value in pose):
                    if any(value is None for value in pose):
                        raise ConfigError(f"{path}:{line}: a pose needs x, y and yaw")
                    poses.append((stamp_ns, tuple(float(v or 0.0) for v in pose)))
                    _bounded(path, "x", poses)
        except (csv.Error, UnicodeDecodeError) as error:
            raise ConfigError(f"{path}: not a readable CSV ({error})") from None
    if not commands and not poses:
        raise ConfigError(f"{path}: no rows (a recording CSV has the columns "
                          f"{', '.join(CSV_COLUMNS)})")
    if commands and not poses:
        raise ConfigError(f"{path}: commands but no poses: {len(commands)} rows with cmd_v, "
                          "cmd_omega and none with x, y, yaw")
    if not commands:
        raise ConfigError(f"{path}: no commands: no row fills cmd_v or cmd_omega")
    info = {"path": str(path), "kind": "CSV", "stamps": "t_s", "command_topic": ["cmd_v, "
            "cmd_omega", "CSV"], "pose_topic": ["x, y, yaw", "CSV"], "pose_source": "CSV",
            "command_stamps": "t_s", "pose_stamps": "t_s"}
    return commands, poses, info


def _csv_number(path: Path, line: int, name: str, text: str | None) -> float | None:
    if text is None or not text.strip():
        return None
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(f"{path}:{line}: {name} is not a number: {text!r}") from None
    if not math.isfinite(value):
        raise ConfigError(f"{path}:{line}: {name} is not a finite number: {text!r}")
    return value


def _check_clock(path: Path, what: str, items: Timed, stamps: str) -> None:
    """Refuse times that go backwards, saying where, by how much, and what to try."""
    times = np.array([stamp for stamp, _ in items], dtype=np.int64)
    back = np.flatnonzero(np.diff(times) < 0)
    if len(back) == 0:
        return
    index = int(back[0]) + 1
    jump_s = (times[index - 1] - times[index]) / 1e9
    other = ("--stamps receive (the recorder's clock)" if stamps == "header"
             else "--stamps header (the senders' clocks)")
    which = {"header": "header stamps (the sender's clock)",
             "receive": "receive stamps (the recorder's clock)", "t_s": "t_s"}[stamps]
    hint = "sort the CSV by t_s" if stamps == "t_s" else f"try {other}"
    raise ConfigError(f"{path}: the clock of {what} jumps back {jump_s:.6g} s at message "
                      f"{index + 1} of {len(times)} ({which}): a clock set while recording, "
                      f"or two clocks mixed; {hint}")


def _windowed(path: Path, commands: Timed, poses: Timed, info: dict[str, Any],
              start_s: float | None, end_s: float | None) -> Recording:
    stamps = info["stamps"]
    _check_clock(path, f"{info['command_topic'][0]} ({info['command_stamps']} stamps)",
                 commands, info["command_stamps"] if stamps != "t_s" else "t_s")
    _check_clock(path, f"{info['pose_topic'][0]} ({info['pose_stamps']} stamps)", poses,
                 info["pose_stamps"] if stamps != "t_s" else "t_s")
    origin = min(commands[0][0] if commands else poses[0][0], poses[0][0])
    command_t = np.array([(stamp - origin) / 1e9 for stamp, _ in commands])
    pose_t = np.array([(stamp - origin) / 1e9 for stamp, _ in poses])
    if command_t[0] > pose_t[-1] or pose_t[0] > command_t[-1]:
        raise ConfigError(
            f"{path}: the commands ({command_t[0]:.3f} to {command_t[-1]:.3f} s) and the poses "
            f"({pose_t[0]:.3f} to {pose_t[-1]:.3f} s) never overlap in time: their stamps "
            f"come from two clocks ({info['command_stamps']} and {info['pose_stamps']} "
            "stamps); try --stamps receive, the recorder's one clock")
    low = -math.inf if start_s is None else start_s
    high = math.inf if end_s is None else end_s
    if low >= high:
        raise ConfigError(f"--start {start_s} must be before --end {end_s}")
    in_window = (pose_t >= low) & (pose_t <= high)
    commanded = (command_t >= low) & (command_t <= high)
    span = "the recording's {} spans {:.3f} to {:.3f} s"
    if not np.any(in_window):
        raise ConfigError(f"{path}: no {info['pose_topic'][0]} messages in the window "
                          f"{_window(start_s, end_s)} ("
                          + span.format(info['pose_topic'][0], pose_t[0], pose_t[-1]) + ")")
    if not np.any(commanded):
        raise ConfigError(f"{path}: no {info['command_topic'][0]} messages in the window "
                          f"{_window(start_s, end_s)} ("
                          + span.format(info['command_topic'][0], command_t[0], command_t[-1])
                          + ")")
    keep_commands = command_t <= high
    yaws = np.unwrap(np.array([values[2] for _, values in poses])[in_window])
    xy = np.array([values[:2] for _, values in poses])[in_window]
    times, unique = np.unique(pose_t[in_window], return_index=True)
    run = RecordedRun(command_t[keep_commands],
                      np.array([values for _, values in commands]).reshape(-1, 2)[keep_commands],
                      times, np.column_stack([xy, yaws])[unique], source=str(path))
    info = {**info, "commands": int(commanded.sum()), "poses": int(in_window.sum()),
            "origin_ns": int(origin), "window_s": [None if start_s is None else start_s,
                                                   None if end_s is None else end_s]}
    return Recording(run, info)


def _window(start_s: float | None, end_s: float | None) -> str:
    return (f"{'the start' if start_s is None else f'{start_s:g} s'} to "
            f"{'the end' if end_s is None else f'{end_s:g} s'}")

