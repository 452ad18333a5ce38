"""A graded run's trajectory: from the simulation itself (``TruthLog``), or its recording.

What the score reads is the simulation's own record (``TruthLog``): the grade server takes
the true pose, the command in force and the contact flag from the simulation after every
tick, into memory it alone holds (one sample per tick, no queue a client could fill), and
writes ``truth.json`` when the run ends; ``trajectory_from_truth`` reads it back and refuses a
record with a gap (``IncompleteRecordError``: the run is then invalid, never scored from
gaps). The recording (rosbag2, MCAP storage) is for people and tools; its queue may drop
messages when a client floods it, so the score never depends on it.

From the recording (``trajectory_from_bag``: a second reading, which the tests hold equal to
the first for a fair controller), the samples are its ``/ground_truth`` (the true pose in the
``map`` frame, one per tick), each with the ``/cmd_vel`` in force during the tick that ended
there: the last command the robot accepted before that tick's time (a command stamped at
tick N's time arrived after tick N's messages and drove tick N + 1), clamped to the robot's
limits as the robot clamps it. The recording carries no contact flag, so the metrics find
contacts from the geometry (``grading.geometry``; the docs say both find the same first
contact). Times are sim time
since the start: a message's stamp minus the run's ``epoch_s`` (``run.json``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from grading.scenario import Scenario
from grading.trajectory import Sample
from physics.simulation import Simulation

GROUND_TRUTH = "/ground_truth"
CMD_VEL = "/cmd_vel"

TRUTH_FILE = "truth.json"
TRUTH_COLUMNS = ("tick", "t_s", "x_m", "y_m", "yaw_rad", "v_cmd_mps", "w_cmd_rps", "collided")


class IncompleteRecordError(ValueError):
    """The run's record of the truth has a gap or is missing: the run cannot be scored."""


class TruthLog:
    """The simulation's own record of a run, one sample per tick (the grade server's).

    Args:
        simulation: the run's simulation (never reset during a graded run).
        sim_time_s: the run's time since its start (s), as its messages are stamped.
        path: where the record is written: as soon as the run has ended (``ended``), before
            the server's shutdown (which a grader may cut short), and again at its end.
        ended: whether the run has ended (checked after each tick).
    """

    def __init__(self, simulation: Simulation, sim_time_s: Callable[[], float], path: Path,
                 ended: Callable[[], bool]) -> None:
        self._simulation = simulation
        self._sim_time_s = sim_time_s
        self._start_tick = simulation.tick
        self._path, self._ended = path, ended
        self._written = False
        self.rows: list[tuple[int, float, float, float, float, float, float, bool]] = []

    def after_tick(self) -> None:
        """The schedule's tick listener: the tick's true pose, command and contact.

        A tick in which the robot did not move (the simulation's tick count unchanged) adds
        nothing. The tick that ends the run writes the record.
        """
        sim = self._simulation
        tick = sim.tick - self._start_tick
        if tick > (self.rows[-1][0] if self.rows else 0):
            pose, command = sim.ground_truth(), sim.last_command
            self.rows.append((tick, round(self._sim_time_s(), 9), pose.x, pose.y, pose.theta,
                              command.linear_mps, command.angular_rps, sim.state().collided))
        if not self._written and self._ended():
            self._written = True
            self.write()

    def write(self, **notes: Any) -> None:
        """Write the record (atomically: a reader sees all of it or none), and ``notes``.

        ``notes``: what else the report should say (the recording's health: its messages
        lost, its size limit reached).
        """
        path = self._path
        temporary = path.with_name(f".{path.name}.tmp")
        temporary.write_text(json.dumps({"columns": TRUTH_COLUMNS, "rows": self.rows,
                                         "notes": notes}))
        temporary.replace(path)


def trajectory_from_truth(path: Path, scenario: Scenario
                          ) -> tuple[list[Sample], dict[str, Any]]:
    """The run's trajectory from ``truth.json`` (the start, then each tick's), and its notes.

    Cut as ``grading.run_headless`` cuts a run: at ``duration_s``, or at the first sample
    within the scenario's ``end``.

    Raises:
        IncompleteRecordError: the file is missing, unreadable, or a tick is missing from it
            (the message says which).
    """
    try:
        document = json.loads(path.read_text())
        rows, notes = document["rows"], dict(document.get("notes") or {})
        if list(document["columns"]) != list(TRUTH_COLUMNS):
            raise ValueError(f"columns {document['columns']}")
    except FileNotFoundError:
        raise IncompleteRecordError("the simulator wrote no record of the run's ground truth "
                                    "(it did not end cleanly)") from None
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise IncompleteRecordError(f"the record of the run's ground truth cannot be read: "
                                    f"{error}") from None
    start = scenario.start
    samples = [Sample(0.0, start.x, start.y, start.theta, 0.0, 0.0, False)]
    end = scenario.end
    for expected, row in enumerate(rows, start=1):
        tick, t_s, x_m, y_m, yaw, v_mps, w_rps, collided = row
        if tick != expected:
            raise IncompleteRecordError(f"the record of the run's ground truth has no tick "
                                        f"{expected} (the next is {tick}): not scored from gaps")
        if t_s > scenario.duration_s + 1e-6:
            break
        samples.append(Sample(float(t_s), float(x_m), float(y_m), float(yaw), float(v_mps),
                              float(w_rps), bool(collided)))
        if end is not None and math.hypot(x_m - end.x_m, y_m - end.y_m) <= end.radius_m:
            break
    return samples, notes


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
