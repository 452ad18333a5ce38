"""``websim serve --record``: a real server, real roslibpy clients, bags read back twice.

What a client received over the bridge is compared with what both readers (rosbags; mcap
with mcap-ros2-support) read from the bag, and the bag's ``metadata.yaml`` with what
``ros2 bag info`` prints. Class mode gives each robot a bag of its own; a full disk stops the
recording with one log line while the simulation goes on; SIGTERM and SIGINT both close every
bag properly.
"""

from __future__ import annotations

import itertools
import math
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import roslibpy
from bag_readers import Read, bag_info, close, read_with_mcap, read_with_rosbags

from ros_nodes.robot_interface import RECORDED_TOPICS

from server_process import ServerProcess, start_server, stop_process, wait_for

TYPES = {spec.name: spec.type for spec in RECORDED_TOPICS}
WATCHED = ("/odom", "/scan", "/tf", "/ground_truth", "/tf_static")


def twist(x: float, z: float = 0.0) -> dict[str, Any]:
    return {"linear": {"x": x, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": z}}


def header_ns(read_or_msg: Any, topic: str) -> int:
    msg = read_or_msg.message if isinstance(read_or_msg, Read) else read_or_msg
    header = msg["transforms"][0]["header"] if topic in ("/tf", "/tf_static") else msg["header"]
    return int(header["stamp"]["sec"]) * 10**9 + int(header["stamp"]["nanosec"])


def as_json(value: Any) -> Any:
    """A read message as rosbridge's JSON carries it (non-finite floats as null)."""
    if isinstance(value, dict):
        return {key: as_json(item) for key, item in value.items()}
    if isinstance(value, list):
        return [as_json(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def only_bag(directory: Path, prefix: str) -> Path:
    (bag,) = [path for path in directory.iterdir() if path.name.startswith(f"{prefix}_")]
    return bag


def both_readers(bag: Path) -> list[Read]:
    """The bag as rosbags reads it, after checking that mcap + mcap-ros2 read the same."""
    by_rosbags, by_mcap = read_with_rosbags(bag), read_with_mcap(bag)
    assert [(r.topic, r.type, r.log_time_ns) for r in by_rosbags] == \
        [(r.topic, r.type, r.log_time_ns) for r in by_mcap]
    for one, other in zip(by_rosbags, by_mcap, strict=True):
        close(one.message, other.message, where=one.topic)
    return by_rosbags


def check_bag_info(bag: Path, reads: list[Read]) -> dict[str, Any]:
    """``ros2 bag info``'s view (metadata.yaml) agrees with the messages the readers read."""
    info = bag_info(bag)
    counts = Counter(read.topic for read in reads)
    assert info["version"] == 9 and info["storage"] == "mcap"
    assert info["messages"] == len(reads)
    assert {name: (kind, count) for name, (kind, count, *_) in info["topics"].items()} == \
        {name: (TYPES[name], count) for name, count in counts.items()}
    assert info["start_ns"] == reads[0].log_time_ns
    assert info["duration_s"] == pytest.approx(
        (reads[-1].log_time_ns - reads[0].log_time_ns) / 1e9, abs=1e-9)
    qos = {name: (profiles[0]["reliability"], profiles[0]["durability"])
           for name, (*_, profiles) in info["topics"].items()}
    assert qos["/scan"] == ("best_effort", "volatile")
    assert qos["/tf_static"] == ("reliable", "transient_local")
    assert qos["/odom"] == qos["/tf"] == ("reliable", "volatile")
    return info


@pytest.fixture
def recorded_server(tmp_path: Path) -> Iterator[tuple[ServerProcess, Path]]:
    bags = tmp_path / "bags"
    server = start_server(["--world", "maze", "--record", str(bags)])
    yield server, bags
    server.stop()


def test_a_bag_holds_what_a_roslibpy_client_received_and_sent(
        recorded_server: tuple[ServerProcess, Path]) -> None:
    server, bags = recorded_server
    client = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
    client.run(timeout=10)
    received: dict[str, list[dict[str, Any]]] = {topic: [] for topic in WATCHED}
    listeners = []
    for topic in WATCHED:
        listener = roslibpy.Topic(client, topic, TYPES[topic])
        listener.subscribe(received[topic].append)
        listeners.append(listener)
    wait_for(lambda: len(received["/scan"]) >= 3 and received["/tf_static"], what="messages")
    cmd_vel = roslibpy.Topic(client, "/cmd_vel", "geometry_msgs/msg/Twist")
    sent = [twist(0.1 * (index + 1), 0.2) for index in range(5)]
    for command in sent:
        cmd_vel.publish(roslibpy.Message(command))
        time.sleep(0.2)
    wait_for(lambda: server.health()["recording"]["messages_written"] > 50,
             what="the writer to report messages written")
    health = server.health()["recording"]
    assert health["state"] == "recording" and health["messages_lost"] == 0
    for listener in listeners:
        listener.unsubscribe()
    client.close()
    assert server.stop() == 0
    output = "".join(server.output)
    bag = only_bag(bags, "robot")
    assert f"websim: recorded {bag}:" in output and ", closed" in output

    reads = both_readers(bag)
    info = check_bag_info(bag, reads)
    assert info["custom_data"]["world"] == "maze" and info["custom_data"]["robot"] == "robot"
    assert set(info["topics"]) == {spec.name for spec in RECORDED_TOPICS}
    by_stamp = {(read.topic, header_ns(read, read.topic)): read for read in reads
                if read.topic in WATCHED}
    for topic in ("/odom", "/scan", "/tf", "/ground_truth"):
        assert len(received[topic]) >= 3
        for msg in received[topic]:
            read = by_stamp[(topic, header_ns(msg, topic))]
            close(as_json(read.message), msg, 1e-5 if topic == "/scan" else 0.0, topic)
            # received by the bag after the robot stamped it, within a tick
            assert 0 <= read.log_time_ns - header_ns(msg, topic) < 50_000_000
    commands = [read.message for read in reads if read.topic == "/cmd_vel"]
    assert commands == sent
    (static,) = [read for read in reads if read.topic == "/tf_static"]
    assert static is reads[0]
    static_sent = received["/tf_static"][0]["transforms"][0]
    static_read = static.message["transforms"][0]
    assert static_read["child_frame_id"] == static_sent["child_frame_id"] == "laser"
    close(static_read["transform"], static_sent["transform"])
    odoms = [read for read in reads if read.topic == "/odom"]
    span_s = (odoms[-1].log_time_ns - odoms[0].log_time_ns) / 1e9
    assert len(odoms) == pytest.approx(span_s * 20 + 1, abs=3)  # every tick's /odom


def test_a_class_records_one_bag_per_robot_and_ctrl_c_closes_them(tmp_path: Path) -> None:
    bags = tmp_path / "bags"
    server = start_server(["--class", "2", "--open-drive", "--record", str(bags)])
    try:
        client = roslibpy.Ros(host=f"ws://127.0.0.1:{server.ws_port}/robots/robot01")
        client.run(timeout=10)
        odoms: list[dict[str, Any]] = []
        roslibpy.Topic(client, "/odom", TYPES["/odom"]).subscribe(odoms.append)
        wait_for(lambda: odoms, what="robot01's /odom")
        roslibpy.Topic(client, "/cmd_vel", "geometry_msgs/msg/Twist").publish(
            roslibpy.Message(twist(0.3)))
        wait_for(lambda: odoms[-1]["pose"]["pose"]["position"]["x"] > 0.15, what="driving")
        robots = server.health()["robots"]
        assert robots["robot01"]["recording"]["state"] == "recording"
        assert robots["robot02"]["recording"]["state"] == "recording"
        client.close()
    finally:
        code = stop_process(server.process, server.output, signal.SIGINT)
    assert code == 0, "".join(server.output)
    first, second = both_readers(only_bag(bags, "robot01")), \
        both_readers(only_bag(bags, "robot02"))
    check_bag_info(only_bag(bags, "robot01"), first)
    check_bag_info(only_bag(bags, "robot02"), second)
    assert [read.message for read in first if read.topic == "/cmd_vel"] == [twist(0.3)]
    assert not [read for read in second if read.topic == "/cmd_vel"]
    last_x = {name: [read for read in reads if read.topic == "/ground_truth"][-1]
              .message["pose"]["pose"]["position"]["x"]
              for name, reads in (("robot01", first), ("robot02", second))}
    assert last_x["robot01"] > last_x["robot02"] + 0.15
    assert bag_info(only_bag(bags, "robot02"))["custom_data"]["robot"] == "robot02"


def test_a_full_disk_stops_the_recording_with_one_line_and_the_robot_goes_on(
        tiny_disk: Path) -> None:
    server = start_server(["--world", "maze", "--record", str(tiny_disk)])
    try:
        client = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
        client.run(timeout=10)
        odoms: list[dict[str, Any]] = []
        roslibpy.Topic(client, "/odom", TYPES["/odom"]).subscribe(odoms.append)
        stopped = wait_for(lambda: server.health()["recording"]["state"] == "stopped",
                           timeout_s=30.0, what="the disk to fill up (a 5 s chunk)")
        assert stopped
        health = server.health()
        assert health["status"] == "ok"
        assert "No space left on device" in health["recording"]["reason"]
        before = len(odoms)
        ticks = health["ticks"]
        wait_for(lambda: len(odoms) >= before + 20, what="/odom after the disk filled up")
        assert server.health()["ticks"] > ticks
        client.close()
    finally:
        code = server.stop()
    output = "".join(server.output)
    assert code == 0, output
    lines = [line for line in output.splitlines() if "recording of robot stopped" in line]
    assert len(lines) == 1, output
    assert "No space left on device" in lines[0] and "the simulation goes on" in lines[0]


def test_a_record_folder_that_cannot_be_written_is_refused_with_the_reason(
        tmp_path: Path) -> None:
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    result = subprocess.run([sys.executable, "-m", "websim.cli", "serve", "--record",
                             str(not_a_folder / "bags")], capture_output=True, text=True,
                            timeout=60, check=False)
    assert result.returncode == 2
    assert f"--record {not_a_folder / 'bags'}: cannot make the folder" in result.stderr


def test_a_server_killed_with_sigkill_still_leaves_its_bag_complete(tmp_path: Path) -> None:
    """The writer process closes every bag when the server's pipe ends, however it ended."""
    bags = tmp_path / "bags"
    server = start_server(["--record", str(bags)])
    wait_for(lambda: server.health()["recording"]["messages_written"] > 20,
             what="messages written")
    server.process.kill()
    server.process.wait(timeout=10)
    bag = only_bag(bags, "robot")
    wait_for(lambda: (bag / "metadata.yaml").is_file(), what="the orphaned writer to close it")
    reads = both_readers(bag)
    check_bag_info(bag, reads)
    assert len(reads) > 20


def test_above_real_time_the_ticks_wait_for_the_writer_and_nothing_is_lost(
        tmp_path: Path) -> None:
    """At --speed max a recording is complete: every tick's /clock and /odom, in order."""
    bags = tmp_path / "bags"
    server = start_server(["--record", str(bags), "--speed", "max"])
    # usually 10-25 s here; the margin is for a loaded machine (the writer is a process of
    # its own and the ticks wait for it: a slow disk or a busy core slows both, loses nothing)
    wait_for(lambda: server.health()["recording"]["messages_written"] > 20_000,
             timeout_s=240, what="20,000 messages written")
    assert server.health()["recording"]["messages_lost"] == 0
    assert server.stop() == 0
    assert "lost" not in "".join(server.output)
    reads = read_with_rosbags(only_bag(bags, "robot"))
    clocks = [read.message["clock"] for read in reads if read.topic == "/clock"]
    ticks_ns = [clock["sec"] * 10**9 + clock["nanosec"] for clock in clocks]
    steps = {b - a for a, b in itertools.pairwise(ticks_ns)}
    assert steps == {50_000_000}  # no tick missing
    odoms = [read for read in reads if read.topic == "/odom"]
    assert len(odoms) == len(clocks) > 3000
