"""A real robot's run as data, put on the simulation's tick grid, and replayed through a model.

``RecordedRun`` holds what a recording says (``websim.real_recording`` reads it from a bag or
a CSV): the commands the robot was sent and the poses it measured, each with its time.
``on_grid`` puts it on the simulation's ticks: from the first pose, every ``dt_s``; each tick
gets the command in force as the robot's tick takes it (the last one that arrived before the
tick's end: websim's own robot applies a command that arrives during a tick to that whole
tick) and the measured pose interpolated at the tick's time. ``replay`` drives a
``Simulation`` (no walls, starting at rest at the first measured pose) tick by tick with
those commands, exactly as ``websim serve``'s robot would have been driven.

Times are seconds from the recording's start; poses (x, y, yaw) in the frame of the measured
poses (``odom``, or the motion capture's), m and rad, yaw unwrapped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from physics.kinematics import clamp_command
from physics.params import NoiseParams, RobotParams
from physics.simulation import TICK_PERIOD_S, Simulation
from physics.snapshots import Pose2D
from physics.validation import ConfigError
from physics.world import World

FloatArray = npt.NDArray[np.float64]

STAMP_TOLERANCE_S = 1e-6
"""A command stamped this close to a tick's end arrived after it (stamps in ns, rounded)."""

MAX_GAP_TICKS = 4
"""Measured poses further apart than this many ticks leave the ticks between them unmeasured
(a dropped odometry stream is not interpolated across)."""


@dataclass(frozen=True)
class RecordedRun:
    """What a recording says a robot was told and did.

    Attributes:
        command_times_s: when each command arrived (s, non-decreasing).
        commands: (n, 2) linear.x (m/s) and angular.z (rad/s) of each command.
        pose_times_s: when each pose was measured (s, increasing).
        poses: (m, 3) x, y (m) and yaw (rad, unwrapped) of each measured pose.
        source: where it came from, for titles and errors.
    """

    command_times_s: FloatArray
    commands: FloatArray
    pose_times_s: FloatArray
    poses: FloatArray
    source: str = "<recording>"

    @property
    def span_s(self) -> tuple[float, float]:
        """First and last measured pose times (s)."""
        return float(self.pose_times_s[0]), float(self.pose_times_s[-1])


@dataclass(frozen=True)
class GridRun:
    """A recording on the simulation's ticks.

    Attributes:
        t_s: (N + 1,) tick times from the first measured pose, every ``dt_s`` (s).
        commands: (N, 2) the command in force during each tick (t_s[k] to t_s[k + 1]) as
            the robot received it, or a stop once it was older than the command timeout.
        poses: (N + 1, 3) the measured pose at each tick (interpolated; unwrapped yaw).
        measured: (N + 1,) whether a measured pose lies within ``MAX_GAP_TICKS`` each side.
        command_age_s: (N,) how old the command in force was at each tick's start (s; inf
            before the first command).
        dt_s: the tick (s).
        start_s: the recording time of t_s = 0 (s).
        source: where the run came from.
    """

    t_s: FloatArray
    commands: FloatArray
    poses: FloatArray
    measured: npt.NDArray[np.bool_]
    command_age_s: FloatArray
    dt_s: float
    start_s: float
    source: str

    @property
    def ticks(self) -> int:
        """Number of ticks N (steps between the N + 1 times)."""
        return len(self.commands)

    def speeds(self) -> FloatArray:
        """(N, 2) measured forward speed and yaw rate over each tick (m/s, rad/s).

        Forward speed is the tick's displacement along the heading at its start, which for
        Eq. 1-3 is the speed itself, to rounding.
        """
        return tick_speeds(self.poses, self.dt_s)

    def speeds_measured(self) -> npt.NDArray[np.bool_]:
        """(N,) whether both ends of each tick were measured."""
        return self.measured[:-1] & self.measured[1:]


def tick_speeds(poses: FloatArray, dt_s: float) -> FloatArray:
    """(N, 2) forward speed and yaw rate over each step between N + 1 poses (m/s, rad/s)."""
    steps = np.diff(poses, axis=0)
    heading = poses[:-1, 2]
    forward = steps[:, 0] * np.cos(heading) + steps[:, 1] * np.sin(heading)
    return np.column_stack([forward / dt_s, steps[:, 2] / dt_s])


def on_grid(run: RecordedRun, dt_s: float = TICK_PERIOD_S, cmd_timeout_s: float = 0.0,
            start_s: float | None = None, end_s: float | None = None) -> GridRun:
    """Put ``run`` on ticks of ``dt_s`` from its first pose at or after ``start_s``.

    Args:
        run: the recording.
        dt_s: the simulation's tick (s).
        cmd_timeout_s: a command older than this at a tick's start is replaced by a stop, as
            a driver's watchdog (and ``websim serve``'s ``cmd_vel_timeout_s``) does; 0: never.
        start_s: the window's start (s of recording time; default: the first pose).
        end_s: the window's end (default: the last pose).

    Raises:
        ConfigError: fewer than two ticks of measured poses in the window.
    """
    inside = np.ones(len(run.pose_times_s), dtype=bool)
    if start_s is not None:
        inside &= run.pose_times_s >= start_s - STAMP_TOLERANCE_S
    if end_s is not None:
        inside &= run.pose_times_s <= end_s + STAMP_TOLERANCE_S
    times, poses = run.pose_times_s[inside], run.poses[inside]
    if len(times) < 2 or times[-1] - times[0] < dt_s - STAMP_TOLERANCE_S:
        raise ConfigError(f"{run.source}: {len(times)} measured poses in the window, less "
                          f"than one tick ({dt_s:g} s) of motion to compare")
    first = float(times[0])
    count = math.floor((float(times[-1]) - first) / dt_s + STAMP_TOLERANCE_S)
    grid: FloatArray = first + dt_s * np.arange(count + 1, dtype=np.float64)
    grid_poses = np.column_stack([np.interp(grid, times, poses[:, i]) for i in range(3)])
    after = np.clip(np.searchsorted(times, grid - STAMP_TOLERANCE_S), 0, len(times) - 1)
    before = np.clip(after - 1, 0, len(times) - 1)
    exact = np.abs(times[after] - grid) <= STAMP_TOLERANCE_S
    gap = times[after] - times[before]
    measured = exact | (gap <= MAX_GAP_TICKS * dt_s + STAMP_TOLERANCE_S)
    commands, age = _commands_per_tick(run, grid, cmd_timeout_s)
    return GridRun(grid - first, commands, grid_poses, measured, age, dt_s, first, run.source)


def _commands_per_tick(run: RecordedRun, grid: FloatArray,
                       cmd_timeout_s: float) -> tuple[FloatArray, FloatArray]:
    """The command in force during each tick, and its age at the tick's start.

    The command in force is the last that arrived before the tick's end.
    """
    ends = grid[1:]
    arrived = np.searchsorted(run.command_times_s, ends - STAMP_TOLERANCE_S) - 1
    commands = np.zeros((len(ends), 2))
    has = arrived >= 0
    commands[has] = run.commands[arrived[has]]
    age = np.full(len(ends), np.inf)
    age[has] = np.maximum(grid[:-1][has] - run.command_times_s[arrived[has]], 0.0)
    if cmd_timeout_s > 0.0:
        commands[age >= cmd_timeout_s - STAMP_TOLERANCE_S] = 0.0
    return commands, age


OPEN_WORLD_NAME = "open floor"


def open_world(start: Pose2D) -> World:
    """A world with nothing in it, the robot at ``start``: a replay meets no wall."""
    return World(OPEN_WORLD_NAME, start, (), (), "<replay>")


def replay(grid: GridRun, mode: str, params: RobotParams | None = None, *, seed: int = 0,
           noise: NoiseParams | None = None) -> tuple[FloatArray, FloatArray]:
    """Drive a model with the recording's commands from its first pose, at rest.

    Returns:
        (N + 1, 3) the model's true pose at each tick (unwrapped yaw), and (N, 2) the
        commands it was given, clamped to the robot's limits as the robot clamps them.
    """
    x, y, yaw = (float(value) for value in grid.poses[0])
    sim = Simulation(open_world(Pose2D(x, y, yaw)), params, mode=mode, seed=seed,
                     noise=noise, dt_s=grid.dt_s)
    poses = np.empty((grid.ticks + 1, 3))
    given = np.empty((grid.ticks, 2))
    poses[0] = (x, y, yaw)
    for index, (linear, angular) in enumerate(grid.commands.tolist()):
        given[index] = sim.command(linear, angular)
        sim.step()
        truth = sim.ground_truth()
        poses[index + 1] = (truth.x, truth.y, truth.theta)
    return poses, given


def clamped(commands: FloatArray, params: RobotParams) -> FloatArray:
    """``commands`` clamped to the robot's limits, as ``Simulation.command`` clamps them."""
    return np.array([clamp_command(v, w, params.max_linear_mps, params.max_angular_rps)
                     for v, w in commands.tolist()]).reshape(-1, 2)
