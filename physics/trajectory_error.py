"""How far a model's trajectory is from a measured one, as evo measures it, and why.

Poses are (x, y, yaw) rows in m and rad, the reference (the real robot) and the estimate (a
model) at the same times. The measures follow evo (the standard trajectory evaluation tool)
restricted to the plane:

* **APE** (absolute pose error): per pose, the distance between the two positions
  (evo's ``translation_part``) and the absolute heading difference (``rotation_angle``);
  reported as RMSE, mean and max. *Aligned*: first the estimate is moved by the rigid motion
  in the plane (an SE(2) transform, no scale) that brings its positions closest to the
  reference's in the least-squares sense (Umeyama's method, evo's ``--align``), which
  forgives a wrong start heading and keeps the shape of the error.
* **RPE** (relative pose error): over consecutive pairs of poses a fixed interval apart (1 s:
  evo's ``--delta`` in frames; 1 m of the reference's path: ``--delta_unit m``, pairs from
  the reference), the error of the estimate's relative motion against the reference's:
  E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j); its translation's length and its angle. Drift per second and
  per metre, whatever happened before.
* **Final pose error**: where each ended.

``speed_response`` says how the measured speeds follow the commanded ones: the lag
(cross-correlation's peak) and the ratio (least squares, with the lag taken out).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

RPE_SECONDS = 1.0
"""RPE's interval in time (s)."""

RPE_METRES = 1.0
"""RPE's interval along the reference's path (m)."""

MAX_XCORR_LAG_S = 2.0
"""Longest lag the cross-correlation looks for (s): the range of ``cmd_lag_s``."""

SETTLE_S = 0.5
"""A command held this long (after the lag) is steady: a ramp of the driver is over."""

MOVING_FRACTION = 0.05
"""A commanded speed counts as moving above this share of its largest value."""


def wrap(angles: FloatArray) -> FloatArray:
    """Angles in [-pi, pi) (rad)."""
    return (np.asarray(angles) + np.pi) % (2.0 * np.pi) - np.pi


def align_se2(reference: FloatArray, estimate: FloatArray) -> tuple[float, float, float]:
    """The rigid motion (dx, dy, dtheta) that best moves ``estimate`` onto ``reference``.

    Umeyama's least squares on the positions, without scale: the rotation from the SVD of
    their cross-covariance (its sign fixed so it is a rotation, never a reflection).
    """
    ref, est = reference[:, :2], estimate[:, :2]
    ref_mean, est_mean = ref.mean(axis=0), est.mean(axis=0)
    covariance = (ref - ref_mean).T @ (est - est_mean) / len(ref)
    u, _, vt = np.linalg.svd(covariance)
    sign = np.diag([1.0, 1.0 if np.linalg.det(u) * np.linalg.det(vt) >= 0 else -1.0])
    rotation = u @ sign @ vt
    theta = math.atan2(rotation[1, 0], rotation[0, 0])
    shift = ref_mean - rotation @ est_mean
    return float(shift[0]), float(shift[1]), theta


def moved(poses: FloatArray, motion: tuple[float, float, float]) -> FloatArray:
    """``poses`` moved by the rigid motion (dx, dy, dtheta) of the plane."""
    dx, dy, dtheta = motion
    cos, sin = math.cos(dtheta), math.sin(dtheta)
    x = cos * poses[:, 0] - sin * poses[:, 1] + dx
    y = sin * poses[:, 0] + cos * poses[:, 1] + dy
    return np.column_stack([x, y, poses[:, 2] + dtheta])


def _stats(errors: FloatArray) -> dict[str, float]:
    if len(errors) == 0:
        return {"rmse": math.nan, "mean": math.nan, "max": math.nan}
    return {"rmse": float(np.sqrt(np.mean(errors ** 2))), "mean": float(np.mean(errors)),
            "max": float(np.max(errors))}


def absolute_pose_error(reference: FloatArray, estimate: FloatArray) -> dict[str, Any]:
    """APE, without and with SE(2) alignment (m and rad; RMSE, mean, max).

    Returns:
        ``{"translation_m": stats, "heading_rad": stats, "aligned": {"translation_m",
        "heading_rad", "motion": [dx, dy, dtheta]}}``.
    """
    def errors(est: FloatArray) -> dict[str, Any]:
        translation = np.hypot(*(est[:, :2] - reference[:, :2]).T)
        heading = np.abs(wrap(est[:, 2] - reference[:, 2]))
        return {"translation_m": _stats(translation), "heading_rad": _stats(heading)}

    motion = align_se2(reference, estimate)
    return {**errors(estimate), "aligned": {**errors(moved(estimate, motion)),
                                            "motion": list(motion)}}


def pairs_by_frames(count: int, delta: int) -> list[tuple[int, int]]:
    """Consecutive pairs ``delta`` poses apart (evo's ``filter_pairs_by_index``)."""
    ids = list(range(0, count, max(1, delta)))
    return list(itertools.pairwise(ids))


def pairs_by_path(poses: FloatArray, delta_m: float) -> list[tuple[int, int]]:
    """Consecutive pairs each ``delta_m`` of path apart (evo's ``filter_pairs_by_path``).

    As evo: a pose ends a stretch once the path since the last one reaches ``delta_m``, and
    the pairs join the poses that end stretches (the first starts after the first stretch).
    """
    steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    ids = []
    path = 0.0
    for index, step in enumerate(steps.tolist(), start=1):
        path += step
        if path >= delta_m:
            ids.append(index)
            path = 0.0
    return list(itertools.pairwise(ids))


def _relative(poses: FloatArray, i: npt.NDArray[np.int_], j: npt.NDArray[np.int_]
              ) -> FloatArray:
    """P_i⁻¹ P_j for each pair: (dx, dy) in frame i and dtheta."""
    dx, dy = poses[j, 0] - poses[i, 0], poses[j, 1] - poses[i, 1]
    cos, sin = np.cos(poses[i, 2]), np.sin(poses[i, 2])
    return np.column_stack([cos * dx + sin * dy, -sin * dx + cos * dy,
                            poses[j, 2] - poses[i, 2]])


def relative_pose_error(reference: FloatArray, estimate: FloatArray,
                        pairs: Sequence[tuple[int, int]]) -> dict[str, Any]:
    """RPE over ``pairs``: translation (m) and heading (rad) stats, and the pair count."""
    if not pairs:
        return {"pairs": 0, "translation_m": _stats(np.array([])),
                "heading_rad": _stats(np.array([]))}
    i = np.array([pair[0] for pair in pairs])
    j = np.array([pair[1] for pair in pairs])
    ref, est = _relative(reference, i, j), _relative(estimate, i, j)
    # E = ref⁻¹ est, with ref and est both relative motions from the same pose
    cos, sin = np.cos(ref[:, 2]), np.sin(ref[:, 2])
    ex, ey = est[:, 0] - ref[:, 0], est[:, 1] - ref[:, 1]
    translation = np.hypot(cos * ex + sin * ey, -sin * ex + cos * ey)
    heading = np.abs(wrap(est[:, 2] - ref[:, 2]))
    return {"pairs": len(pairs), "translation_m": _stats(translation),
            "heading_rad": _stats(heading)}


def final_pose_error(reference: FloatArray, estimate: FloatArray) -> dict[str, float]:
    """How far apart the two ended: position (m) and heading (rad, signed, estimate - ref)."""
    return {"position_m": float(np.hypot(*(estimate[-1, :2] - reference[-1, :2]))),
            "heading_rad": float(wrap(estimate[-1, 2] - reference[-1, 2]))}


def trajectory_errors(reference: FloatArray, estimate: FloatArray,
                      dt_s: float) -> dict[str, Any]:
    """APE (both ways), RPE over ``RPE_SECONDS`` and ``RPE_METRES``, final pose error."""
    return {
        "ape": absolute_pose_error(reference, estimate),
        "rpe_1s": relative_pose_error(reference, estimate, pairs_by_frames(
            len(reference), round(RPE_SECONDS / dt_s))),
        "rpe_1m": relative_pose_error(reference, estimate,
                                      pairs_by_path(reference, RPE_METRES)),
        "final": final_pose_error(reference, estimate),
    }


def lag_by_xcorr(commanded: FloatArray, measured: FloatArray, dt_s: float,
                 max_lag_s: float = MAX_XCORR_LAG_S) -> float | None:
    """How long ``measured`` trails ``commanded`` (s): the cross-correlation's peak.

    Both are sampled every ``dt_s``; the peak between 0 and ``max_lag_s`` is refined between
    samples by a parabola through it and its neighbours. None if the command never changes.
    """
    cmd = commanded - commanded.mean()
    out = measured - measured.mean()
    if not np.any(cmd) or not np.any(out):
        return None
    most = min(len(cmd) - 1, round(max_lag_s / dt_s))
    scores = np.array([float(np.dot(cmd[:len(cmd) - lag], out[lag:])) / (len(cmd) - lag)
                       for lag in range(most + 1)])
    best = int(np.argmax(scores))
    shift = 0.0
    if 0 < best < most:
        left, centre, right = scores[best - 1], scores[best], scores[best + 1]
        curvature = left - 2.0 * centre + right
        if curvature < 0.0:
            shift = 0.5 * (left - right) / curvature
    return (best + shift) * dt_s


def speed_ratio(commanded: FloatArray, measured: FloatArray, lag_s: float | None,
                dt_s: float) -> float | None:
    """Measured per commanded speed in steady motion: the least-squares slope through 0.

    Counted only on ticks whose command had been the same for ``SETTLE_S`` (or twice the
    lag, if longer) and asks for motion above ``MOVING_FRACTION`` of the largest command:
    the ratio of speeds held, not of ramps or of the dead time. None if there are no such
    ticks.
    """
    settle = max(1, round(max(SETTLE_S, 2.0 * (lag_s or 0.0)) / dt_s))
    if len(commanded) <= settle:
        return None
    cmd, out = commanded, measured
    peak = float(np.max(np.abs(cmd)))
    changed = np.concatenate([[True], cmd[1:] != cmd[:-1]])
    since = np.arange(len(cmd)) - np.maximum.accumulate(np.where(changed, np.arange(len(cmd)),
                                                                 0))
    steady = (since >= settle) & (np.abs(cmd) > MOVING_FRACTION * peak)
    if peak == 0.0 or not np.any(steady):
        return None
    return float(np.dot(cmd[steady], out[steady]) / np.dot(cmd[steady], cmd[steady]))


def speed_response(commanded: FloatArray, measured: FloatArray,
                   dt_s: float) -> dict[str, dict[str, float | None]]:
    """Lag (s) and ratio of each speed, linear and angular, against the commanded one."""
    out: dict[str, dict[str, float | None]] = {}
    for column, name in ((0, "linear"), (1, "angular")):
        lag = lag_by_xcorr(commanded[:, column], measured[:, column], dt_s)
        out[name] = {"lag_s": lag,
                     "ratio": speed_ratio(commanded[:, column], measured[:, column], lag, dt_s)}
    return out
