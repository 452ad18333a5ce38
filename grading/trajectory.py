"""A run's trajectory: the robot's true pose and the command in force, sample by sample.

What every metric reads. It is ground truth (the ``map`` frame, as ``/ground_truth``), never
the student's odometry, so a controller is scored on what the robot did, not on what it
believed. ``grading.headless.run_headless`` makes one from a simulation; a recording gives the
same samples from its ``/ground_truth`` and ``/cmd_vel``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


class Sample(NamedTuple):
    """The robot at one instant.

    Attributes:
        t_s: time since the run started (s, sim time).
        x_m: true position x in the map frame (m).
        y_m: true position y in the map frame (m).
        yaw_rad: true heading in the map frame (rad); wrapped or not, metrics unwrap it.
        v_cmd_mps: the linear command in force (``/cmd_vel`` linear.x, m/s, after clamping).
        w_cmd_rps: the angular command in force (``/cmd_vel`` angular.z, rad/s).
        collided: the simulation's contact flag for the tick that ended here (the footprint
            touched a wall), or None when the source does not carry it (then contacts are
            found from the pose and the world's geometry).
    """

    t_s: float
    x_m: float
    y_m: float
    yaw_rad: float
    v_cmd_mps: float
    w_cmd_rps: float
    collided: bool | None = None


Trajectory = Sequence[Sample]
"""Samples in time order (strictly increasing ``t_s``)."""


def check_trajectory(trajectory: Trajectory) -> None:
    """Raise ValueError unless the samples are non-empty, finite and in time order."""
    if not trajectory:
        raise ValueError("the trajectory is empty")
    previous = -math.inf
    for index, sample in enumerate(trajectory):
        if not all(math.isfinite(value) for value in sample[:6]):
            raise ValueError(f"sample {index} is not finite: {sample}")
        if sample.t_s <= previous:
            raise ValueError(f"sample {index} at t = {sample.t_s} s does not follow "
                             f"t = {previous} s")
        previous = sample.t_s


def times(trajectory: Trajectory) -> FloatArray:
    """Each sample's time (s)."""
    return np.array([sample.t_s for sample in trajectory], dtype=np.float64)


def positions(trajectory: Trajectory) -> FloatArray:
    """Each sample's (x, y) in the map frame (m), shape (n, 2)."""
    return np.array([(sample.x_m, sample.y_m) for sample in trajectory],
                    dtype=np.float64).reshape(-1, 2)


def unwrapped_yaw(trajectory: Trajectory) -> FloatArray:
    """Each sample's heading (rad), unwrapped so that full turns accumulate.

    Consecutive samples are taken to be less than half a turn apart (at 20 Hz that allows
    62.8 rad/s; the robot turns at most 2.5).
    """
    return np.unwrap(np.array([sample.yaw_rad for sample in trajectory], dtype=np.float64))


def circular_mean_rad(angles_rad: npt.ArrayLike) -> float:
    """The mean direction of angles (rad, in (-pi, pi]): atan2(mean sin, mean cos).

    Every average of angles in the metrics is this one: the arithmetic mean of headings or
    heading errors that straddle the ±pi wrap cancels out (3.07 and -3.07 rad average 0,
    though both are nearly half a turn off), the circular mean does not (it is ±pi there).
    Where the angles are close together it is their arithmetic mean, to within the cube of
    their spread.

    Raises:
        ValueError: no angles.
    """
    values = np.asarray(angles_rad, dtype=np.float64)
    if values.size == 0:
        raise ValueError("the circular mean of no angles")
    return float(np.arctan2(np.mean(np.sin(values)), np.mean(np.cos(values))))


def path_length_m(trajectory: Trajectory) -> float:
    """Length of the polyline through the samples' positions (m)."""
    steps = np.diff(positions(trajectory), axis=0)
    return float(np.sum(np.hypot(steps[:, 0], steps[:, 1])))


def until(trajectory: Trajectory, end_s: float) -> Trajectory:
    """The samples up to and including time ``end_s`` (s)."""
    return [sample for sample in trajectory if sample.t_s <= end_s]


def first_within(trajectory: Trajectory, x_m: float, y_m: float,
                 radius_m: float) -> float | None:
    """Time of the first sample whose position is within ``radius_m`` of (x, y), or None."""
    for sample in trajectory:
        if math.hypot(sample.x_m - x_m, sample.y_m - y_m) <= radius_m:
            return sample.t_s
    return None
