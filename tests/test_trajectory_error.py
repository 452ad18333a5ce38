"""The measures of physics.trajectory_error on trajectories whose errors are known exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physics.trajectory_error import (
    absolute_pose_error,
    align_se2,
    lag_by_xcorr,
    moved,
    pairs_by_frames,
    pairs_by_path,
    relative_pose_error,
    speed_ratio,
    trajectory_errors,
)

DT_S = 0.05


def circle(count: int = 400, radius: float = 1.0) -> np.ndarray:
    angle = np.linspace(0.0, 1.5 * math.pi, count)
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle),
                            angle + math.pi / 2])


def test_a_rigidly_moved_path_has_its_offset_as_ape_and_none_once_aligned():
    reference = circle()
    estimate = moved(reference, (0.3, -0.2, 0.25))
    motion = align_se2(reference, estimate)
    # the inverse of x -> R(0.25) x + (0.3, -0.2)
    assert motion == pytest.approx((-0.3 * math.cos(0.25) + 0.2 * math.sin(0.25),
                                    0.3 * math.sin(0.25) + 0.2 * math.cos(0.25), -0.25))
    ape = absolute_pose_error(reference, estimate)
    assert ape["heading_rad"]["max"] == pytest.approx(0.25)
    assert ape["aligned"]["translation_m"]["max"] < 1e-12
    assert ape["aligned"]["heading_rad"]["max"] < 1e-12
    # a rigid motion changes no relative motion: RPE is zero either way
    rpe = relative_pose_error(reference, estimate, pairs_by_frames(len(reference), 20))
    assert rpe["translation_m"]["max"] < 1e-12 and rpe["heading_rad"]["max"] < 1e-12


def test_a_shifted_path_has_ape_of_the_shift():
    reference = circle()
    estimate = reference + np.array([0.3, 0.4, 0.0])
    ape = absolute_pose_error(reference, estimate)
    assert ape["translation_m"]["rmse"] == pytest.approx(0.5)
    assert ape["translation_m"]["max"] == pytest.approx(0.5)


def test_rpe_of_a_path_scaled_by_s_is_the_extra_distance_per_interval():
    straight = np.column_stack([np.arange(0, 10, DT_S), np.zeros(200), np.zeros(200)])
    longer = straight * [1.1, 0.0, 0.0]
    errors = trajectory_errors(straight, longer, DT_S)
    # over 1 s the reference moves 20 * 0.05 m = 1 m: the estimate 10 % more
    assert errors["rpe_1s"]["translation_m"]["rmse"] == pytest.approx(0.1)
    assert errors["rpe_1m"]["translation_m"]["rmse"] == pytest.approx(0.1)
    assert errors["final"]["position_m"] == pytest.approx(0.1 * straight[-1, 0])


def test_pairs_follow_evo_consecutive_pairs():
    assert pairs_by_frames(7, 3) == [(0, 3), (3, 6)]
    path = np.column_stack([np.arange(0, 3.01, 0.25), np.zeros(13), np.zeros(13)])
    # evo: a stretch ends where the path since the last end reaches 1 m; pairs join the ends
    assert pairs_by_path(path, 1.0) == [(4, 8), (8, 12)]


def test_the_lag_of_a_delayed_signal_is_found_between_samples():
    rng = np.random.default_rng(3)
    steps = np.repeat(rng.uniform(-0.3, 0.3, 40), 20)
    for lag_ticks in (0, 3, 7):
        delayed = np.concatenate([np.zeros(lag_ticks), steps[:len(steps) - lag_ticks]])
        assert lag_by_xcorr(steps, delayed, DT_S) == pytest.approx(lag_ticks * DT_S, abs=0.01)
    # a lag of 2.5 ticks: half of each change one tick, half the next
    half = 0.5 * (np.concatenate([np.zeros(2), steps[:-2]]) +
                  np.concatenate([np.zeros(3), steps[:-3]]))
    assert lag_by_xcorr(steps, half, DT_S) == pytest.approx(2.5 * DT_S, abs=0.01)
    assert lag_by_xcorr(np.zeros(50), steps[:50], DT_S) is None


def test_the_speed_ratio_counts_held_speeds_not_ramps():
    steps = np.repeat([0.0, 0.3, 0.0, -0.2, 0.1], 40)
    ramped = np.empty_like(steps)
    speed = 0.0
    for index, target in enumerate(steps * 0.8):
        speed += max(-0.03, min(0.03, target - speed))  # a ramp of 0.6 m/s^2
        ramped[index] = speed
    assert speed_ratio(steps, ramped, 0.0, DT_S) == pytest.approx(0.8, abs=1e-9)
    assert speed_ratio(np.zeros(100), ramped[:100], 0.0, DT_S) is None
