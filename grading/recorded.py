"""A graded run's trajectory read back from its recording (rosbag2, MCAP storage).

The samples are the recording's ``/ground_truth`` (the true pose in the ``map`` frame, one per
tick), each with the ``/cmd_vel`` in force during the tick that ended there: the last command
the robot accepted before that tick's time (a command stamped at tick N's time arrived after
tick N's messages and drove tick N + 1), clamped to the robot's limits as the robot clamps it.
The recording carries no contact flag, so the metrics find contacts from the geometry
(``grading.geometry``; the docs say both find the same first contact). Times are sim time
since the start: a message's stamp minus the run's ``epoch_s`` (``run.json``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from grading.scenario import Scenario
from grading.trajectory import Sample

GROUND_TRUTH = "/ground_truth"
CMD_VEL = "/cmd_vel"


def bag_folder(recording_dir: Path) -> Path:
    """The one bag a graded run's ``recording/`` folder holds.

    Raises:
        FileNotFoundError: it holds none, or its bag has no ``metadata.yaml`` (not closed).
    """
    bags = sorted(path for path in recording_dir.glob("*") if path.is_dir())
    if not bags:
        raise FileNotFoundError(f"{recording_dir}: no recording")
    if not (bags[-1] / "metadata.yaml").is_file():
        raise FileNotFoundError(f"{bags[-1]}: the recording was not closed (no metadata.yaml)")
    return bags[-1]


def yaw_of(orientation: object) -> float:
    """The yaw (rad) of a quaternion message about z."""
    x, y, z, w = (float(getattr(orientation, name)) for name in "xyzw")
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def trajectory_from_bag(bag: Path, scenario: Scenario, epoch_s: float) -> list[Sample]:
    """The run's trajectory: the start, then each tick's true pose and command in force.

    Cut as ``grading.run_headless`` cuts a run: at ``duration_s``, or at the first sample
    within the scenario's ``end``.

    Args:
        bag: the bag's folder.
        scenario: the run's scenario (its start pose, duration, end and the robot's limits).
        epoch_s: the stamp of sim time 0 (s).
    """
    store = get_typestore(Stores.ROS2_HUMBLE)
    poses: list[tuple[float, float, float, float]] = []
    commands: list[tuple[float, float, float]] = []
    robot = scenario.robot
    with Reader(bag) as reader:
        wanted = [c for c in reader.connections if c.topic in (GROUND_TRUTH, CMD_VEL)]
        # (no connection given means every one: a run that never ticked has neither topic)
        for connection, time_ns, raw in reader.messages(connections=wanted) if wanted else ():
            msg: Any = store.deserialize_cdr(raw, connection.msgtype)
            t_s = time_ns / 1e9 - epoch_s
            if connection.topic == GROUND_TRUTH:
                pose = msg.pose.pose
                poses.append((t_s, float(pose.position.x), float(pose.position.y),
                              yaw_of(pose.orientation)))
            else:
                twist = msg.twist if hasattr(msg, "twist") else msg
                commands.append((
                    t_s,
                    _clamp(float(twist.linear.x), robot.max_linear_mps),
                    _clamp(float(twist.angular.z), robot.max_angular_rps)))
    start = scenario.start
    samples = [Sample(0.0, start.x, start.y, start.theta, 0.0, 0.0, None)]
    commands.sort()
    index, v_mps, w_rps = 0, 0.0, 0.0
    end = scenario.end
    for t_s, x_m, y_m, yaw in sorted(poses):
        t_s = round(t_s, 6)
        if t_s <= samples[-1].t_s or t_s > scenario.duration_s + 1e-6:
            continue
        while index < len(commands) and commands[index][0] < t_s - 1e-6:
            _, v_mps, w_rps = commands[index]
            index += 1
        samples.append(Sample(t_s, x_m, y_m, yaw, v_mps, w_rps, None))
        if end is not None and math.hypot(x_m - end.x_m, y_m - end.y_m) <= end.radius_m:
            break
    return samples


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))
