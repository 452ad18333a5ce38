"""Recordings (``--record``): a robot's tap into a rosbag2 that every ROS tool opens.

Robots on the test rig (a manual clock, real bridge sessions), a real ``Recorder`` with its
real writer process; every bag is read back by two independent readers (rosbags; mcap with
mcap-ros2-support, ``bag_readers``) and compared with what crossed the robot's tap.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import sys
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from bag_readers import Read, bag_info, close, mcap_summary, read_with_mcap, read_with_rosbags
from robot_rig import RobotRig, robot_rig

from ros_nodes.bag_writer import CHUNK_SPAN_NS, ROS_DISTRO
from ros_nodes.recording import Recorder, stamp_ns
from ros_nodes.robot_interface import QOS_PROFILES, RECORDED_TOPICS, ROBOT_TOPICS
from rosbridge.core.outbox import Outbox
from rosbridge.core.session import Session
from rosbridge.msgs import cdr

TWIST = {"linear": {"x": 0.25, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.5}}

TYPES = {spec.name: spec.type for spec in RECORDED_TOPICS}


def tapped(rig: RobotRig) -> list[tuple[int, str, str, dict[str, Any]]]:
    """Every recorded message crossing the robot's tap from now on, with the clock's stamp."""
    heard: list[tuple[int, str, str, dict[str, Any]]] = []

    def listen(direction: str, topic: str, type_name: str, msg: dict[str, Any],
               sim_time_s: float) -> None:
        if topic in TYPES:
            heard.append((stamp_ns(rig.clock.stamp_s()), topic, type_name, msg))

    rig.robot.tap.add(listen)
    return heard


def drive(rig: RobotRig, ticks: int) -> None:
    """A client publishes /cmd_vel through the bridge, then the robot ticks ``ticks`` times."""
    client = rig.client("driver")
    rig.send(client, {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"})
    for index in range(ticks):
        if index % 10 == 0:
            twist = {**TWIST, "linear": {**TWIST["linear"], "x": 0.01 * index}}
            rig.send(client, {"op": "publish", "topic": "/cmd_vel", "msg": twist})
        rig.tick()


def as_recorded(type_name: str, msg: dict[str, Any]) -> Any:
    """A message as CDR carries it (float32 fields rounded), by deserializing its CDR."""
    from bag_readers import plain

    store = cdr.typestore()
    return plain(store.deserialize_cdr(cdr.to_cdr(type_name, msg), type_name))


@pytest.fixture
def recorder(tmp_path: Path) -> Iterator[Recorder]:
    recorder = Recorder(tmp_path / "bags")
    yield recorder
    recorder.close()


def test_a_bag_holds_every_message_that_crossed_the_tap_as_both_readers_read_it(
        recorder: Recorder) -> None:
    rig = robot_rig("maze", seed=3)
    heard = tapped(rig)
    latched_at_ns = stamp_ns(rig.clock.stamp_s())
    recording = recorder.record("alice", rig.robot)
    recorder.start()
    drive(rig, 60)
    recorder.close()

    assert recording.stats.state == "closed"
    by_rosbags, by_mcap = read_with_rosbags(recording.path), read_with_mcap(recording.path)
    assert [(r.topic, r.type, r.log_time_ns) for r in by_rosbags] == \
        [(r.topic, r.type, r.log_time_ns) for r in by_mcap]
    for one, other in zip(by_rosbags, by_mcap, strict=True):
        close(one.message, other.message, where=one.topic)

    # first the latched messages, as the recording started; then exactly what crossed the tap
    latched = [spec.name for spec, _ in rig.robot.latched() if spec.recorded]
    assert {"/tf_static", "/world"} <= set(latched)
    assert [(r.topic, r.log_time_ns) for r in by_rosbags[:len(latched)]] == \
        [(name, latched_at_ns) for name in latched]
    rest = by_rosbags[len(latched):]
    assert [(r.log_time_ns, r.topic, r.type) for r in rest] == \
        [(time_ns, topic, type_name) for time_ns, topic, type_name, _ in heard]
    for read, (_, _, type_name, msg) in zip(rest, heard, strict=True):
        close(read.message, as_recorded(type_name, msg), where=read.topic)
    counts = Counter(r.topic for r in rest)
    assert {topic: counts[topic] for topic in ("/cmd_vel", "/odom", "/tf", "/ground_truth",
                                               "/scan")} == \
        {"/cmd_vel": 6, "/odom": 60, "/tf": 60, "/ground_truth": 60, "/scan": 30}
    # stamped by the robot's one clock: a message's log time is its header's stamp
    for read in rest:
        stamp = read.message["transforms"][0]["header"]["stamp"] if read.topic == "/tf" \
            else read.message["clock"] if read.topic == "/clock" \
            else read.message.get("header", {}).get("stamp")
        if stamp is not None:
            assert stamp["sec"] * 10**9 + stamp["nanosec"] == read.log_time_ns, read.topic
    commands = [r.message["linear"]["x"] for r in rest if r.topic == "/cmd_vel"]
    assert commands == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])


def test_metadata_yaml_says_what_ros2_bag_info_prints(recorder: Recorder) -> None:
    rig = robot_rig("empty")
    recording = recorder.record("robot", rig.robot, {"course": "module 2"})
    recorder.start()
    drive(rig, 41)
    recorder.close()
    reads = read_with_rosbags(recording.path)
    info = bag_info(recording.path)

    assert info["version"] == 9 and info["storage"] == "mcap"
    assert info["files"] == [f"{recording.path.name}.mcap"]
    assert info["messages"] == len(reads) == recording.stats.written
    first, last = reads[0].log_time_ns, reads[-1].log_time_ns
    assert info["start_ns"] == first
    assert info["duration_s"] == pytest.approx((last - first) / 1e9, abs=1e-9)
    assert info["duration_s"] == pytest.approx(2.0, abs=1e-6)  # 41 ticks, 40 periods
    (entry,) = info["file_entries"]
    assert entry["message_count"] == len(reads)
    assert entry["starting_time"]["nanoseconds_since_epoch"] == first
    assert entry["duration"]["nanoseconds"] == last - first
    assert info["ros_distro"] == ROS_DISTRO == "humble"
    assert info["custom_data"]["robot"] == "robot"
    assert info["custom_data"]["world"] == rig.robot.sim.world.name
    assert info["custom_data"]["course"] == "module 2"

    counts = Counter(read.topic for read in reads)
    assert {name: (kind, count) for name, (kind, count, *_) in info["topics"].items()} == \
        {name: (TYPES[name], counts[name]) for name in counts}
    store = cdr.typestore()
    specs = {spec.name: spec for spec in ROBOT_TOPICS}
    for name, (kind, _, serialization, type_hash, qos) in info["topics"].items():
        assert serialization == "cdr"
        assert type_hash == store.hash_rihs01(kind) and type_hash.startswith("RIHS01_")
        offered = QOS_PROFILES[specs[name].qos]
        (profile,) = qos
        assert (profile["history"], profile["depth"], profile["reliability"],
                profile["durability"], profile["liveliness"]) == \
            ("keep_last", offered.depth, offered.reliability, offered.durability, "automatic")
    assert info["topics"]["/scan"][4][0]["reliability"] == "best_effort"
    assert info["topics"]["/tf_static"][4][0]["durability"] == "transient_local"
    assert info["topics"]["/odom"][4][0]["reliability"] == "reliable"


def installed_type_description(kind: str) -> Path | None:
    """rosidl's ``share/PKG/msg/TYPE.json`` of an installed ROS 2 package (the PyPI wheels
    put it under the environment's prefix; a ROS install under AMENT_PREFIX_PATH)."""
    package, _, name = kind.split("/")
    prefixes = [sys.prefix, *os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)]
    for prefix in filter(None, prefixes):
        path = Path(prefix) / "share" / package / "msg" / f"{name}.json"
        if path.is_file():
            return path
    return None


def test_the_type_hashes_are_those_of_the_installed_ros_packages(recorder: Recorder) -> None:
    """rosidl generates every type's hash into share/PKG/msg/TYPE.json: ours must agree."""
    rig = robot_rig("empty")
    recording = recorder.record("robot", rig.robot)
    recorder.start()
    drive(rig, 3)
    recorder.close()
    topics = bag_info(recording.path)["topics"]
    found = {kind: installed_type_description(kind) for kind, *_ in topics.values()}
    if not any(found.values()):
        pytest.skip("no ROS 2 message package installed (pip install '.[ros]')")
    for kind, _, _, type_hash, _ in topics.values():
        path = found[kind]
        if path is not None:
            hashes = json.loads(path.read_text())["type_hashes"]
            assert type_hash == next(item["hash_string"] for item in hashes
                                     if item["type_name"] == kind), kind
    assert sum(path is not None for path in found.values()) >= 4  # Twist, Odometry, ...


def test_the_mcap_file_is_what_the_ros2_profile_and_rosbag2_need(recorder: Recorder) -> None:
    rig = robot_rig("empty")
    recording = recorder.record("robot", rig.robot)
    recorder.start()
    drive(rig, 10)
    recorder.close()
    header, summary, metadata = mcap_summary(recording.path)
    assert header.profile == "ros2"
    assert summary.statistics.message_count == recording.stats.written
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "cdr"
        assert schema.encoding == "ros2msg" and schema.name == TYPES[channel.topic]
        assert set(channel.metadata) == {"offered_qos_profiles", "topic_type_hash"}
        assert yaml.safe_load(channel.metadata["offered_qos_profiles"])[0]["depth"] >= 1
        assert channel.metadata["topic_type_hash"] == cdr.typestore().hash_rihs01(schema.name)
    odometry = next(schema for schema in summary.schemas.values()
                    if schema.name == "nav_msgs/msg/Odometry").data.decode()
    for dependency in ("std_msgs/Header", "builtin_interfaces/Time",
                       "geometry_msgs/PoseWithCovariance", "geometry_msgs/Quaternion",
                       "geometry_msgs/Vector3"):
        assert f"MSG: {dependency}\n" in odometry
    serialized = yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])
    on_disk = yaml.safe_load((recording.path / "metadata.yaml").read_text())
    assert serialized["ros_distro"] == ROS_DISTRO
    assert serialized["version"] == 9
    assert serialized["topics_with_message_count"] == \
        on_disk["rosbag2_bagfile_information"]["topics_with_message_count"]


def test_rclpy_deserializes_every_recorded_message(recorder: Recorder) -> None:
    """ROS 2's own CDR (rclpy's typesupport) reads the bytes the bag holds."""
    serialization = pytest.importorskip("rclpy.serialization",
                                        reason="rclpy is not installed (pip install '.[ros]')")
    from rosbridge.msgs.rclpy_conversion import MessageConversionError, message_class, to_dict

    rig = robot_rig("maze")
    recording = recorder.record("robot", rig.robot)
    recorder.start()
    drive(rig, 6)
    recorder.close()
    from rosbags.rosbag2 import Reader

    checked: Counter[str] = Counter()
    by_rosbags = iter(read_with_rosbags(recording.path))
    with Reader(recording.path) as reader:
        for connection, _, raw in reader.messages():
            read = next(by_rosbags)
            try:
                cls = message_class(connection.msgtype)
            except MessageConversionError:
                continue  # tf2_msgs is not on PyPI: its class may be missing
            decoded = to_dict(serialization.deserialize_message(bytes(raw), cls))
            close(json.loads(json.dumps(decoded, default=list)),
                  json.loads(json.dumps(read.message, default=list)), where=read.topic)
            checked[connection.topic] += 1
    assert {"/odom", "/scan", "/cmd_vel", "/ground_truth", "/world"} <= set(checked)


def test_a_full_queue_drops_and_counts_messages_and_never_waits(tmp_path: Path) -> None:
    recorder = Recorder(tmp_path, max_queued=10)
    rig = robot_rig("empty")
    heard = tapped(rig)
    latched = sum(spec.recorded for spec, _ in rig.robot.latched())
    recording = recorder.record("robot", rig.robot)  # the writer is not running yet
    rig.tick(20)
    assert len(recording.queue) == 10
    assert recording.stats.queued == 10
    assert recording.stats.lost == latched + len(heard) - 10
    assert rig.robot.sim.tick == 20  # every tick ran
    health = recording.health()
    assert health["messages_lost"] == recording.stats.lost
    assert health["messages_waiting"] == 10
    recorder.start()
    recorder.close()
    reads = read_with_rosbags(recording.path)
    assert len(reads) == 10 and reads[0].topic == "/tf_static"


def test_a_bag_at_its_size_limit_is_closed_complete_and_the_robot_goes_on(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    recorder = Recorder(tmp_path, max_bytes=20_000)
    rig = robot_rig("maze")
    recording = recorder.record("robot", rig.robot)
    recorder.start()
    for _ in range(30):  # 30 s: six chunks of 5 s, paced as the schedule paces the ticks
        rig.tick(20)   # (a loaded machine's feeder would otherwise fall behind, and the
        wait_until(recorder.caught_up, recorder)  # queue drop what would fill the bag)
    wait_until(lambda: recording.stats.state != "recording", recorder)
    rig.tick(20)
    recorder.close()
    assert rig.robot.sim.tick == 620
    assert recording.stats.state == "stopped"
    assert "size limit" in recording.stats.reason
    assert recording.stats.summary["complete"] is True
    reads = read_with_rosbags(recording.path)  # its metadata.yaml and summary were written
    assert len(reads) == bag_info(recording.path)["messages"] == recording.stats.written
    assert recording.stats.written < recording.stats.queued
    assert [record.getMessage() for record in caplog.records
            if "recording of robot stopped" in record.getMessage()] != []


def wait_until(condition: Any, recorder: Recorder, timeout_s: float = 20.0) -> None:
    """Let the feeder hand the queues over until ``condition()`` holds."""
    import time

    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out waiting for the recording"
        time.sleep(0.05)


def test_a_full_disk_stops_that_recording_alone_with_one_log_line(
        tmp_path: Path, tiny_disk: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="websim.recording")
    recorder = Recorder(tmp_path / "bags", max_queued=10_000)
    full_rig, other_rig = robot_rig("maze"), robot_rig("maze", seed=1)
    heard = tapped(other_rig)
    latched = sum(spec.recorded for spec, _ in other_rig.robot.latched())
    on_full = recorder.record("alice", full_rig.robot, directory=tiny_disk)
    other = recorder.record("bob", other_rig.robot)
    recorder.start()
    for _ in range(400):  # 20 s of both robots: four chunks of 5 s each (some 20 KB each)
        full_rig.tick()
        other_rig.tick()
    wait_until(lambda: on_full.stats.state == "stopped", recorder)
    other_rig.tick(20)
    recorder.close()

    assert "No space left on device" in on_full.stats.reason
    assert on_full.stats.summary["complete"] is False
    stopped = [record for record in caplog.records
               if record.levelno == logging.ERROR and "recording of" in record.getMessage()]
    assert len(stopped) == 1
    assert "recording of alice stopped: No space left on device" in stopped[0].getMessage()
    assert "the simulation goes on" in stopped[0].getMessage()
    assert full_rig.robot.sim.tick == 400  # its robot never waited
    assert other.stats.state == "closed"
    reads = read_with_rosbags(other.path)
    assert len(reads) == bag_info(other.path)["messages"] == latched + len(heard)
    assert max(r.log_time_ns for r in reads) - min(r.log_time_ns for r in reads) > \
        3 * CHUNK_SPAN_NS


def test_bags_are_named_after_the_robot_and_the_utc_time_and_never_overwritten(
        recorder: Recorder) -> None:
    rig = robot_rig("empty")
    first = recorder.record("alice", rig.robot)
    second = recorder.record("alice", robot_rig("empty").robot)
    assert first.path.parent == second.path.parent == recorder.directory
    assert first.path.name.startswith("alice_") and first.path.name.endswith("Z")
    assert second.path != first.path
    recorder.start()
    recorder.close()
    assert (first.path / "metadata.yaml").is_file() and (second.path / "metadata.yaml").is_file()


def test_a_recorder_that_never_started_writes_nothing(tmp_path: Path) -> None:
    recorder = Recorder(tmp_path / "bags")
    rig = robot_rig("empty")
    recording = recorder.record("robot", rig.robot)
    rig.tick(5)
    recorder.close()
    assert not (tmp_path / "bags").exists()
    assert recording.on_message not in rig.robot.tap  # detached: the robot builds no more


def test_float32_fields_are_recorded_as_the_message_holds_them(recorder: Recorder) -> None:
    """LaserScan ranges are float32 on the wire: the bag holds each reading, inf included."""
    rig = robot_rig("empty")
    heard = tapped(rig)
    recording = recorder.record("robot", rig.robot)
    recorder.start()
    rig.tick(2)
    recorder.close()
    scan = next(msg for _, topic, _, msg in heard if topic == "/scan")
    read: Read = next(r for r in read_with_mcap(recording.path) if r.topic == "/scan")
    assert read.message["ranges"] == np.asarray(scan["ranges"], dtype=np.float32).tolist()


def test_rosbag2s_own_reader_and_ros2_bag_info_read_it(recorder: Recorder) -> None:
    """rosbag2_py and the ros2 CLI come with a ROS 2 install (Jazzy or later), not from PyPI."""
    rosbag2_py = pytest.importorskip(
        "rosbag2_py", reason="rosbag2_py is not on PyPI: it needs a ROS 2 install (Jazzy+)")
    rig = robot_rig("empty")
    recording = recorder.record("robot", rig.robot)
    recorder.start()
    drive(rig, 20)
    recorder.close()
    reader = rosbag2_py.SequentialReader()
    reader.open(rosbag2_py.StorageOptions(uri=str(recording.path), storage_id="mcap"),
                rosbag2_py.ConverterOptions("", ""))
    topics = {topic.name: topic.type for topic in reader.get_all_topics_and_types()}
    assert topics == {read.topic: read.type for read in read_with_rosbags(recording.path)}
    count = 0
    while reader.has_next():
        reader.read_next()
        count += 1
    assert count == recording.stats.written
    if shutil.which("ros2"):
        info = subprocess.run(["ros2", "bag", "info", str(recording.path)],
                              capture_output=True, text=True, timeout=60, check=True).stdout
        assert f"Messages:          {count}" in info


EXITS_WITHOUT_CLOSE = """
import sys
sys.path.insert(0, sys.argv[2])
from robot_rig import robot_rig
from ros_nodes.recording import Recorder
rig = robot_rig("maze")
from pathlib import Path
recorder = Recorder(Path(sys.argv[1]))
recorder.record("alice", rig.robot)
recorder.start()
for _ in range(20):
    rig.tick()
raise SystemExit("a failure before close()")
"""


def test_a_process_that_ends_without_close_still_exits_and_closes_its_bags(
        tmp_path: Path) -> None:
    """An exception before ``close`` (a server's crash, a failed test) must not leave the
    interpreter waiting at exit for a writer that waits for commands: the pipe ends, the
    writer closes the bag, and the process exits."""
    tests_dir = Path(__file__).resolve().parent
    ended = subprocess.run([sys.executable, "-c", EXITS_WITHOUT_CLOSE, str(tmp_path),
                            str(tests_dir)], capture_output=True, text=True, timeout=60,
                           check=False)
    assert ended.returncode == 1 and "a failure before close()" in ended.stderr
    (bag,) = [path for path in tmp_path.iterdir() if path.is_dir()]
    assert (bag / "metadata.yaml").is_file(), list(bag.iterdir())
    assert len(read_with_rosbags(bag)) >= 20


def test_what_a_student_sends_is_bounded_per_minute_and_the_robots_own_topics_go_on(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A student's own /cmd_vel (TwistStamped, a 10 kB frame name, at every tick) grew their
    robot's bag at 3.2 MB/s until its cap stopped it. Now their messages are bounded per
    minute of the robot's clock; every message of the robot's own topics is recorded."""
    per_minute = 200_000
    recorder = Recorder(tmp_path / "bags", max_queued=100_000,
                        client_bytes_per_minute=per_minute)
    rig = robot_rig("empty")
    recording = recorder.record("alice", rig.robot)
    recorder.start()
    client = Session("alice's code", False, Outbox(), clock=rig.clock)  # its budgets on it
    rig.bridge.connect(client)
    rig.send(client, {"op": "advertise", "topic": "/cmd_vel",
                      "type": "geometry_msgs/TwistStamped"})
    stamped = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "x" * 10_000},
               "twist": TWIST}
    minutes = 2
    for _ in range(minutes * 60):  # a second of ticks at a time, the writer keeping up
        for _ in range(20):
            rig.send(client, {"op": "publish", "topic": "/cmd_vel", "msg": stamped})
            rig.tick()
        wait_until(recorder.caught_up, recorder)
    notice = recording.notice()
    recorder.close()

    reads = read_with_rosbags(recording.path)
    counts = Counter(read.topic for read in reads)
    assert counts["/odom"] == counts["/ground_truth"] == minutes * 60 * 20, "all of its own"
    commands = [read for read in reads if read.topic == "/cmd_vel"]
    sent = minutes * 60 * 20
    assert len(commands) > 0 and recording.stats.clients_left_out == sent - len(commands)
    added = len(commands) * len(stamped["header"]["frame_id"])
    assert added <= per_minute * (minutes + 1), "a minute's burst, then the rate"
    assert added >= per_minute * minutes * 0.8
    assert notice is not None and "client messages left out (over 0.2 MB a minute)" in notice
    warnings = [record.getMessage() for record in caplog.records
                if "its clients' messages add more than" in record.getMessage()]
    assert len(warnings) <= 1 + minutes, "said once per stretch, not per message"
    assert warnings and "the robot's own topics go on recording" in warnings[0]


def test_a_graded_run_may_set_no_bound_on_its_clients(tmp_path: Path) -> None:
    recorder = Recorder(tmp_path / "bags", client_bytes_per_minute=None)
    rig = robot_rig("empty")
    recording = recorder.record("run", rig.robot)
    assert recording.client_bytes_per_minute is None
    recorder.start()
    drive(rig, 40)
    recorder.close()
    assert recording.stats.clients_left_out == 0
    assert Counter(read.topic for read in read_with_rosbags(recording.path))["/cmd_vel"] == 4
