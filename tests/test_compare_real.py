"""``websim compare --real`` and ``websim fit`` on real recordings of ``websim serve --record``.

The recordings are made by a real server (``tests/recorded_runs.py``: sim time, a roslibpy
client driving a program of steps), once with the shipped robot and once with a perturbed
driver (lag, scales, ramps); the other formats are the same bag converted by rosbags
(sqlite3, ROS 1) and written as CSV; the bad ones are made from it (cut, retyped, restamped).
"""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from rosbags.convert import convert
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from physics import load_params
from physics.recorded_run import RecordedRun, on_grid
from websim.cli import main
from websim.real_recording import read_recording

from recorded_runs import EXCITING_PROGRAM, record_program

PERTURBED = {"cmd_lag_s": 0.15, "linear_scale": 0.9, "angular_scale": 1.1,
             "linear_accel_limit_mps2": 1.0, "angular_accel_limit_rps2": 4.0}
STORE = get_typestore(Stores.ROS2_HUMBLE)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("recordings")
    params = root / "perturbed.yaml"
    params.write_text("robot:\n" + "".join(f"  {k}: {v}\n" for k, v in PERTURBED.items()))
    (root / "known").mkdir()
    (root / "perturbed").mkdir()
    return {"known": record_program(root / "known", EXCITING_PROGRAM),
            "perturbed": record_program(root / "perturbed", EXCITING_PROGRAM, params)}


def run_cli(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main([str(arg) for arg in args])
    out, err = capsys.readouterr()
    return code, out, err


def compare(capsys: pytest.CaptureFixture[str], recording: Path, out: Path,
            *extra: object) -> dict:
    code, printed, err = run_cli(capsys, "compare", "--real", recording, "--out", out, *extra)
    assert code == 0, err
    assert "APE translation RMSE (m)" in printed
    return json.loads((out / "summary.json").read_text())


def test_websim_serves_own_recording_replays_with_zero_error_in_kinematic_mode(
        recordings, tmp_path, capsys):
    summary = compare(capsys, recordings["known"], tmp_path / "out")
    kinematic = summary["kinematic"]
    assert kinematic["ape"]["translation_m"]["max"] < 1e-9
    assert kinematic["ape"]["heading_rad"]["max"] < 1e-9
    assert kinematic["rpe_1s"]["translation_m"]["max"] < 1e-9
    assert kinematic["final"]["position_m"] < 1e-9
    assert kinematic["rpe_1s"]["pairs"] > 20 and kinematic["rpe_1m"]["pairs"] >= 2
    # the traction-limited dynamic model is a different model: it does not match
    assert summary["dynamic"]["ape"]["translation_m"]["rmse"] > 1e-3
    assert summary["real"]["speeds"]["linear"]["ratio"] == pytest.approx(1.0, abs=1e-9)
    assert "reproduces the real trajectory to rounding" in " ".join(summary["explanation"])
    assert summary["recording"]["kind"] == "rosbag2 (MCAP)"
    rows = list(csv.DictReader((tmp_path / "out" / "trajectory.csv").open()))
    assert len(rows) == summary["ticks"] + 1
    assert max(abs(float(r["real_x"]) - float(r["kinematic_x"])) for r in rows) < 1e-9
    page = (tmp_path / "out" / "report.html").read_text()
    assert page.count("<svg") == 4 and "<script" not in page and "http://" not in \
        page.replace("http://www.w3.org/2000/svg", "")
    assert (tmp_path / "out" / "comparison.png").stat().st_size > 10_000


def test_the_gap_of_a_perturbed_robot_is_measured_and_explained(recordings, tmp_path,
                                                                  capsys):
    summary = compare(capsys, recordings["perturbed"], tmp_path / "out")
    assert summary["kinematic"]["ape"]["translation_m"]["rmse"] > 0.05
    real = summary["real"]["speeds"]
    assert real["linear"]["ratio"] == pytest.approx(0.9, rel=0.02)
    assert real["angular"]["ratio"] == pytest.approx(1.1, rel=0.02)
    assert real["linear"]["lag_s"] > 0.15  # the dead time and half the ramp
    named = {cause["parameter"] for cause in summary["causes"] if cause["share"] > 0.05}
    assert named == {"linear_scale", "angular_scale", "cmd_lag_s"}
    text = " ".join(summary["explanation"])
    assert "drove 0.90 m per commanded metre" in text and "turned 1.10 rad" in text


def test_fit_finds_the_perturbed_driver_within_10_percent_and_closes_the_gap(
        recordings, tmp_path, capsys):
    fitted = tmp_path / "fitted.yaml"
    code, printed, err = run_cli(capsys, "fit", recordings["perturbed"], "--out", fitted)
    assert code == 0, err
    robot = load_params(fitted).robot
    for name, truth in PERTURBED.items():
        assert getattr(robot, name) == pytest.approx(truth, rel=0.1), name
    assert "held-out part" in printed and "implausible" not in printed
    assert fitted.read_text().startswith("# Written by websim fit")
    # the parameter file closes the gap: compare --params with it replays to rounding
    summary = compare(capsys, recordings["perturbed"], tmp_path / "after", "--params", fitted)
    assert summary["kinematic"]["ape"]["translation_m"]["max"] < 1e-6
    # and fitting websim's own robot finds the shipped driver
    code, printed, err = run_cli(capsys, "fit", recordings["known"], "--out", fitted)
    assert code == 0, err
    robot = load_params(fitted).robot
    assert robot.cmd_lag_s == pytest.approx(0.0, abs=0.005)
    assert (robot.linear_scale, robot.angular_scale) == pytest.approx((1.0, 1.0), abs=1e-3)
    assert robot.linear_accel_limit_mps2 in (0.0,) or robot.linear_accel_limit_mps2 > 100


def test_a_fit_with_implausible_values_says_why(tmp_path, capsys):
    times = np.arange(0, 20, 0.05)
    commands = np.where((times % 4) < 2, 0.3, 0.0)
    poses = np.column_stack([np.concatenate([[0.0], np.cumsum(0.4 * commands[:-1] * 0.05)]),
                             np.zeros_like(times), np.zeros_like(times)])
    path = tmp_path / "slipping.csv"
    write_csv(path, RecordedRun(times, np.column_stack([commands, 0 * commands]), times,
                                poses))
    code, printed, err = run_cli(capsys, "fit", path, "--out", tmp_path / "fit.yaml")
    assert code == 0, err
    assert "implausible: linear_scale = 0.4" in printed and "wheel slip" in printed


def write_csv(path: Path, run: RecordedRun) -> None:
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["t_s", "cmd_v", "cmd_omega", "x", "y", "yaw"])
        for t, (v, w) in zip(run.command_times_s, run.commands, strict=True):
            writer.writerow([repr(float(t)), repr(float(v)), repr(float(w)), "", "", ""])
        for t, (x, y, yaw) in zip(run.pose_times_s, run.poses, strict=True):
            writer.writerow([repr(float(t)), "", "", repr(float(x)), repr(float(y)),
                             repr(float(yaw))])


def bag_as_csv(bag: Path, path: Path) -> Path:
    """The bag's /cmd_vel and /odom as a recording CSV, read with rosbags (not websim)."""
    rows = []
    with AnyReader([bag], default_typestore=STORE) as reader:
        wanted = [c for c in reader.connections if c.topic in ("/cmd_vel", "/odom")]
        origin = None
        for connection, time_ns, raw in reader.messages(connections=wanted):
            origin = time_ns if origin is None else origin
            msg = reader.deserialize(raw, connection.msgtype)
            t = f"{(time_ns - origin) // 10**9}.{(time_ns - origin) % 10**9:09d}"
            if connection.topic == "/cmd_vel":
                rows.append([t, repr(msg.linear.x), repr(msg.angular.z), "", "", ""])
            else:
                q = msg.pose.pose.orientation
                yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2))
                rows.append([t, "", "", repr(msg.pose.pose.position.x),
                             repr(msg.pose.pose.position.y), repr(yaw)])
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["t_s", "cmd_v", "cmd_omega", "x", "y", "yaw"])
        writer.writerows(rows)
    return path


def converted(bag: Path, destination: Path, storage: str,
              topics: tuple[str, ...] = ("/cmd_vel", "/odom")) -> Path:
    convert([bag], destination, storage, 9, None, "file", None, None, [], list(topics), [], [])
    return destination


def numbers(value: object, prefix: str = "") -> dict[str, float]:
    if isinstance(value, dict):
        out: dict[str, float] = {}
        for key, item in value.items():
            out.update(numbers(item, f"{prefix}.{key}"))
        return out
    if isinstance(value, list):
        return {f"{prefix}[{i}]": v for i, v in enumerate(value)
                if isinstance(v, float)}
    return {prefix: value} if isinstance(value, float) else {}


def test_the_same_run_as_db3_mcap_ros1_bag_and_csv_gives_the_same_figures(
        recordings, tmp_path, capsys):
    bag = recordings["perturbed"]
    mcap_file = next(bag.glob("*.mcap"))
    forms = {
        "mcap folder": bag,
        "mcap file": mcap_file,
        "db3 folder": converted(bag, tmp_path / "as_db3", "sqlite3"),
        "ROS 1 bag": converted(bag, tmp_path / "as_ros1.bag", "sqlite3"),
        "CSV": bag_as_csv(bag, tmp_path / "as.csv"),
    }
    db3 = next((tmp_path / "as_db3").glob("*.db3"))
    forms["lone db3 file"] = Path(shutil.copy(db3, tmp_path / "lone.db3"))
    figures = {}
    for name, path in forms.items():
        summary = compare(capsys, path, tmp_path / name.replace(" ", "_"))
        figures[name] = {key: value for key, value in numbers(summary).items()
                         if not key.startswith(".recording")}
    kinds = {name: json.loads((tmp_path / name.replace(" ", "_") / "summary.json")
                              .read_text())["recording"]["kind"] for name in forms}
    assert kinds["ROS 1 bag"] == "ROS 1 bag" and kinds["db3 folder"] == "rosbag2 (sqlite3)"
    assert kinds["CSV"] == "CSV" and kinds["lone db3 file"] == "rosbag2 (sqlite3)"
    reference = figures["mcap folder"]
    assert len(reference) > 60
    for name, values in figures.items():
        assert values.keys() == reference.keys(), name
        for key, value in values.items():
            assert value == pytest.approx(reference[key], rel=1e-9, abs=1e-12), (name, key)


# --- bad input: each a clear error, exit code 2, never a traceback --------------------------

def refused(capsys: pytest.CaptureFixture[str], tmp_path: Path, recording: Path,
            *extra: object, command: str = "compare") -> str:
    if command == "compare":
        args = ["compare", "--real", recording, "--out", tmp_path / "refused", *extra]
    else:
        args = ["fit", recording, "--out", tmp_path / "refused.yaml", *extra]
    code, _, err = run_cli(capsys, *args)
    assert code == 2, err
    assert err.startswith("websim: error: ") and "Traceback" not in err
    return err


def test_a_missing_topic_is_named_with_what_the_recording_has(recordings, tmp_path, capsys):
    err = refused(capsys, tmp_path, recordings["known"], "--cmd-topic", "/teleop/cmd_vel")
    assert "no topic /teleop/cmd_vel" in err and "--cmd-topic" in err
    assert "/odom (nav_msgs/msg/Odometry, " in err and "/cmd_vel (geometry_msgs/msg/Twist, 18" \
        in err
    err = refused(capsys, tmp_path, recordings["known"], "--truth-topic", "/mocap/pose")
    assert "no /mocap/pose messages" in err and "commands but no ground truth" in err


def test_commands_but_no_odometry(recordings, tmp_path, capsys):
    only_commands = converted(recordings["known"], tmp_path / "cmd_only", "mcap",
                              ("/cmd_vel", "/scan"))
    err = refused(capsys, tmp_path, only_commands)
    assert "commands but no odometry: 18 /cmd_vel messages and no /odom" in err
    assert "ros2 bag record /cmd_vel /odom /scan" in err


def test_no_messages_in_the_window(recordings, tmp_path, capsys):
    err = refused(capsys, tmp_path, recordings["known"], "--start", "500")
    assert "no /odom messages in the window 500 s to the end" in err
    assert "spans 0.000 to" in err
    # a window between the program's first two commands (when the first arrives after the
    # recording's start depends on the machine's load: the window is read from the bag)
    first, second = read_recording(recordings["known"]).run.command_times_s[:2]
    start_s = round(first + 0.25 * (second - first), 3)
    end_s = round(first + 0.75 * (second - first), 3)
    err = refused(capsys, tmp_path, recordings["known"], "--start", start_s, "--end", end_s)
    assert f"no /cmd_vel messages in the window {start_s:g} s to {end_s:g} s" in err


def restamped(bag: Path, destination: Path, *, back_at: int | None = None,
              cmd_type: str | None = None, odom_offset_s: float = 0.0) -> Path:
    """The bag's /cmd_vel and /odom rewritten: an odometry clock that jumps back at message
    ``back_at``, a /cmd_vel of another type, or odometry stamps from a clock far away."""
    with AnyReader([bag], default_typestore=STORE) as reader, \
            Writer(destination, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        count = 0
        wanted = [c for c in reader.connections if c.topic in ("/cmd_vel", "/odom")]
        for connection, time_ns, raw in reader.messages(connections=wanted):
            msg = reader.deserialize(raw, connection.msgtype)
            msgtype = connection.msgtype
            if connection.topic == "/cmd_vel" and cmd_type is not None:
                msgtype = cmd_type
                msg = STORE.types[cmd_type](data="forward")
            if connection.topic == "/odom":
                count += 1
                shift_ns = int(odom_offset_s * 1e9)
                if back_at is not None and count >= back_at:
                    shift_ns -= 3 * 10**9
                stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec + shift_ns
                msg.header.stamp = STORE.types["builtin_interfaces/msg/Time"](
                    sec=stamp // 10**9, nanosec=stamp % 10**9)
            if connection.topic not in connections:
                connections[connection.topic] = writer.add_connection(
                    connection.topic, msgtype, typestore=STORE)
            writer.write(connections[connection.topic], time_ns,
                         STORE.serialize_cdr(msg, msgtype))
    return destination


def test_a_clock_that_jumps_backwards_says_which_stamps_and_offers_the_others(
        recordings, tmp_path, capsys):
    bag = restamped(recordings["known"], tmp_path / "jumps", back_at=100)
    err = refused(capsys, tmp_path, bag, "--stamps", "header")
    assert "the clock of /odom (header stamps) jumps back 2.95 s at message 100" in err
    assert "header stamps (the sender's clock)" in err and "try --stamps receive" in err
    summary = compare(capsys, bag, tmp_path / "receive", "--stamps", "receive")
    assert summary["kinematic"]["ape"]["translation_m"]["max"] < 1e-9
    far = restamped(recordings["known"], tmp_path / "far", odom_offset_s=-3600.0)
    err = refused(capsys, tmp_path, far, "--stamps", "header")
    assert "never overlap in time" in err and "try --stamps receive" in err


def test_an_unknown_message_type_on_the_chosen_topic(recordings, tmp_path, capsys):
    bag = restamped(recordings["known"], tmp_path / "strings", cmd_type="std_msgs/msg/String")
    err = refused(capsys, tmp_path, bag)
    assert "/cmd_vel is std_msgs/msg/String, which websim cannot read there" in err
    assert "geometry_msgs/msg/TwistStamped" in err
    err = refused(capsys, tmp_path, recordings["known"], "--odom-topic", "/scan")
    assert "/scan is sensor_msgs/msg/LaserScan" in err


@pytest.mark.parametrize("form", ["mcap", "db3", "ros1"])
def test_a_truncated_file(recordings, tmp_path, capsys, form):
    bag = recordings["known"]
    if form == "mcap":
        whole = next(bag.glob("*.mcap"))
    elif form == "db3":
        whole = next(converted(bag, tmp_path / "db3", "sqlite3").glob("*.db3"))
    else:
        whole = converted(bag, tmp_path / "whole.bag", "sqlite3")
    data = whole.read_bytes()
    # (sqlite ignores a last page cut short that it does not need: all is read, rightly)
    ends = (len(data) // 3, len(data) * 9 // 10) + (() if form == "db3" else (len(data) - 100,))
    for keep in ends:
        cut = tmp_path / f"cut_{keep}{whole.suffix}"
        cut.write_bytes(data[:keep])
        err = refused(capsys, tmp_path, cut)
        assert "damaged" in err or "truncated" in err, err
    refused(capsys, tmp_path, tmp_path / "nothing.mcap")


def test_bad_csv_files(tmp_path, capsys):
    cases = {
        "t_s,v,omega\n0,0.1,0\n": "no column cmd_v, cmd_omega, x, y, yaw",
        "t_s,cmd_v,cmd_omega,x,y,yaw\n0,0.1,0,,,\n": "commands but no poses",
        "t_s,cmd_v,cmd_omega,x,y,yaw\n0,0.1,0,0,0,0\n1,0.1,0,0.1,0,0\n0.5,,,0.2,0,0\n":
            "jumps back 0.5 s",
        "t_s,cmd_v,cmd_omega,x,y,yaw\n0,fast,0,0,0,0\n": "cmd_v is not a number",
        "t_s,cmd_v,cmd_omega,x,y,yaw\n0,nan,0,0,0,0\n": "not a finite number",
    }
    for index, (text, message) in enumerate(cases.items()):
        path = tmp_path / f"bad{index}.csv"
        path.write_text(text)
        assert message in refused(capsys, tmp_path, path)


def test_options_that_belong_to_command_files_are_refused_with_real(recordings, tmp_path,
                                                                    capsys):
    err = refused(capsys, tmp_path, recordings["known"], "--controller", "pid")
    assert "--controller is for --commands" in err
    err = refused(capsys, tmp_path, recordings["known"], "--world", "maze")
    assert "--world is for --commands" in err
    err = refused(capsys, tmp_path, recordings["known"], "--fit-share", "1.5", command="fit")
    assert "--fit-share" in err


def test_a_command_timeout_stops_the_replayed_robot():
    run = RecordedRun(np.array([0.0]), np.array([[0.2, 0.0]]), np.arange(0, 2.01, 0.05),
                      np.zeros((41, 3)))
    grid = on_grid(run, cmd_timeout_s=0.5)
    assert list(grid.commands[:10, 0]) == [0.2] * 10 and not grid.commands[10:, 0].any()
    assert not on_grid(run).commands[:, 0].tolist().count(0.0)
