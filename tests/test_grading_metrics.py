"""The grader's metrics on trajectories made by hand, against values worked out by hand."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence

import pytest

from grading.geometry import side_distance_m, world_shapes
from grading.metrics import (
    CollisionsParams,
    GoToGoalParams,
    HeadingStepParams,
    SmoothnessParams,
    WallFollowingParams,
    collisions,
    go_to_goal,
    heading_step,
    smoothness,
    wall_following,
)
from grading.shortest_path import shortest_path_m
from grading.trajectory import Sample, check_trajectory, circular_mean_rad
from physics import World, load_world
from physics.world import world_from_dict

STEP_RAD = math.pi / 2
RADIUS_M = 0.11


def track(t: Sequence[float], x: Sequence[float] | float = 0.0, y: Sequence[float] | float = 0.0,
          yaw: Sequence[float] | float = 0.0, v: Sequence[float] | float = 0.0,
          w: Sequence[float] | float = 0.0,
          collided: Sequence[bool] | None = None) -> list[Sample]:
    """Samples from columns; a number stands for a constant column."""
    def column(values: Sequence[float] | float) -> list[float]:
        return [float(values)] * len(t) if isinstance(values, (int, float)) else list(values)
    flags: list[bool | None] = [None] * len(t) if collided is None else list(collided)
    return [Sample(*row) for row in zip(t, column(x), column(y), column(yaw), column(v),
                                        column(w), flags, strict=True)]


def ticks(end_s: float, dt_s: float) -> list[float]:
    return [round(k * dt_s, 9) for k in range(round(end_s / dt_s) + 1)]


# --- heading step ---------------------------------------------------------------------------

def overshooting_step() -> list[Sample]:
    """Up to 1.1 x the step at 1 s, back down to the step at 2 s, then still; every 0.1 s."""
    t = ticks(5.0, 0.1)
    yaw = [1.1 * STEP_RAD * s if s <= 1.0 else
           1.1 * STEP_RAD - 0.1 * STEP_RAD * (s - 1.0) if s <= 2.0 else STEP_RAD for s in t]
    return track(t, yaw=yaw)


def test_a_step_with_ten_percent_overshoot_settles_at_the_first_sample_inside_for_good() -> None:
    # Inside the ±0.02 rad band on the way up at 0.9 s, out again; on the way down the
    # error is 0.1 S (2 - t): 0.0314 rad at 1.8 s, 0.0157 rad at 1.9 s.
    params = HeadingStepParams(setpoints=((0.0, STEP_RAD),), threshold=3.0,
                               tolerance_rad=0.02, max_overshoot=0.15)
    result = heading_step(overshooting_step(), params)
    assert result.value == pytest.approx(1.9)
    assert result.figures["overshoot"] == pytest.approx(0.1)
    assert result.figures["steady_state_error_rad"] == pytest.approx(0.0, abs=1e-12)
    assert result.passed and result.score == 1.0


def test_the_heading_score_is_the_product_of_the_ratios_beyond_each_limit() -> None:
    params = HeadingStepParams(setpoints=((0.0, STEP_RAD),), threshold=1.0,
                               tolerance_rad=0.02, max_overshoot=0.05)
    result = heading_step(overshooting_step(), params)
    # settling 1.9 s against 1 s: 1/1.9; overshoot 10 % against 5 %: 0.5; no error: 1
    assert result.score == pytest.approx(0.5 / 1.9)
    assert not result.passed
    assert "settling time 1.90 s > 1 s" in result.reason
    assert "overshoot 10.0% > 5%" in result.reason


def test_a_response_that_stops_short_never_settles_and_scores_zero() -> None:
    t = ticks(5.0, 0.1)
    yaw = [min(s, 1.0) * (STEP_RAD - 0.05) for s in t]
    params = HeadingStepParams(setpoints=((0.0, STEP_RAD),), tolerance_rad=0.02)
    result = heading_step(track(t, yaw=yaw), params)
    assert result.value is None and result.score == 0.0 and not result.passed
    assert result.figures["steady_state_error_rad"] == pytest.approx(0.05)
    assert "never settled within ±0.020 rad, error at the end +0.050 rad" in result.reason
    assert json.dumps(result.to_json(), allow_nan=False)  # None, never NaN or Infinity


def test_headings_are_relative_to_the_start_and_may_come_wrapped() -> None:
    # From 3.0 rad in the map frame, +0.5 rad over a second: through +pi, as a recording's
    # quaternion gives it (wrapped into (-pi, pi]).
    t = ticks(3.0, 0.1)
    yaw = [math.remainder(3.0 + 0.5 * min(s, 1.0), 2 * math.pi) for s in t]
    assert min(yaw) < 0.0 < max(yaw)
    params = HeadingStepParams(setpoints=((0.0, 0.5),), tolerance_rad=0.02)
    result = heading_step(track(t, yaw=yaw), params)
    assert result.value == pytest.approx(1.0)  # error 0.5 - 0.5 t: last outside at 0.9 s
    assert result.figures["overshoot"] == 0.0 and result.passed


def test_each_setpoint_change_is_a_step_of_its_own() -> None:
    t = ticks(6.0, 0.1)
    yaw = [STEP_RAD if 0.1 <= s < 3.2 else 0.0 for s in t]
    params = HeadingStepParams(setpoints=((0.0, STEP_RAD), (3.0, 0.0)), tolerance_rad=0.02)
    result = heading_step(track(t, yaw=yaw), params)
    first, second = result.figures["steps"]
    assert first["settling_time_s"] == pytest.approx(0.1)
    assert second["settling_time_s"] == pytest.approx(0.2)
    assert second["step_rad"] == pytest.approx(-STEP_RAD)
    assert result.value == pytest.approx(0.2) and result.passed


def test_turning_the_wrong_way_is_not_overshoot() -> None:
    t = ticks(3.0, 0.1)
    yaw = [-2.5 * s if s < 1.0 else -2.5 for s in t]  # away from +pi/2, past -pi
    params = HeadingStepParams(setpoints=((0.0, STEP_RAD),))
    result = heading_step(track(t, yaw=yaw), params)
    assert result.figures["overshoot"] == 0.0
    assert result.value is None and "never settled" in result.reason


def test_the_steady_state_error_is_a_circular_mean_across_the_wrap() -> None:
    # Turned the wrong way to the opposite heading (-pi/2 for +pi/2) and wobbling 0.07 rad
    # about it: the error is pi -+ 0.07, wrapped +3.0716 or -3.0716 rad. The last 0.5 s (six
    # samples) hold four of one and two of the other: their arithmetic mean is 1.0239 rad,
    # a third of the truth (a run that straddled the wrap evenly read 0 rad); the circular
    # mean is pi - atan(tan(0.07) / 3) = 3.11826 rad: nearly half a turn off.
    t = ticks(5.0, 0.1)
    near = [-STEP_RAD + 0.07] * len(t)
    near[0] = 0.0
    for k in range(1, 10):
        near[k] = -STEP_RAD * k / 10
    for k, sign in zip(range(45, 51), (1, -1, 1, -1, 1, 1), strict=True):
        near[k] = -STEP_RAD + sign * 0.07
    result = heading_step(track(t, yaw=near), HeadingStepParams(setpoints=((0.0, STEP_RAD),)))
    step = result.figures["steps"][0]
    assert step["final_error_rad"] == pytest.approx(math.pi - 0.07)
    assert step["steady_state_error_rad"] == pytest.approx(math.pi - math.atan(math.tan(0.07)
                                                                              / 3))
    assert step["steady_state_error_rad"] > 3.1 and not result.passed


def test_the_circular_mean_of_angles_close_together_is_their_mean() -> None:
    assert circular_mean_rad([0.1, 0.2, 0.3]) == pytest.approx(0.2, abs=1e-15)
    assert circular_mean_rad([3.0, -3.0]) == pytest.approx(math.pi)  # not 0
    assert circular_mean_rad([-0.01, 0.01, 0.03]) == pytest.approx(0.01, abs=1e-7)
    with pytest.raises(ValueError, match="no angles"):
        circular_mean_rad([])


# --- wall following ---------------------------------------------------------------------------

WALL_Y_M = 1.0


@pytest.fixture
def one_wall() -> World:
    return world_from_dict({"walls": [[-10.0, WALL_Y_M, 10.0, WALL_Y_M]]}, source="one wall")


def wall_params(side: str = "left", desired: float = 0.5, **overrides: float) -> \
        WallFollowingParams:
    values = {"end_x_m": 5.0, "end_y_m": 0.6, "end_radius_m": 1.0, "footprint_radius_m": RADIUS_M,
              "side": side, "desired_distance_m": desired, **overrides}
    return WallFollowingParams(**values)  # type: ignore[arg-type]


def along_the_wall(end_s: float = 10.0, y: float = 0.6) -> list[Sample]:
    """0.5 m/s along x, heading 0, y = 0.6: the wall 0.4 m to the left."""
    t = ticks(end_s, 0.1)
    return track(t, x=[0.5 * s for s in t], y=y, v=0.5)


def test_wall_following_loss_and_mit_score_at_a_known_distance(one_wall: World) -> None:
    result = wall_following(along_the_wall(), wall_params(), one_wall)
    assert result.value == pytest.approx(0.1)  # |0.4 - 0.5| at every sample
    assert result.score == pytest.approx(1.0 / (1.0 + (4.0 * 0.1) ** 2))  # 0.862
    assert result.passed
    assert result.figures["reached_end_s"] == pytest.approx(8.0)  # x = 4: 1 m from (5, 0.6)
    assert result.inputs["samples"] == 81  # the run ends at the end point


def test_the_followed_side_decides_which_wall_counts(one_wall: World) -> None:
    result = wall_following(along_the_wall(), wall_params(side="right"), one_wall)
    assert result.value == pytest.approx(3.5 - 0.5)  # no wall on the right: range_max
    exact = wall_following(along_the_wall(), wall_params(desired=0.4), one_wall)
    assert exact.value == pytest.approx(0.0, abs=1e-12) and exact.score == pytest.approx(1.0)


def test_touching_the_wall_fails_the_run_with_the_crash(one_wall: World) -> None:
    t = ticks(10.0, 0.1)
    y = [min(0.6 + 0.1 * s, WALL_Y_M - RADIUS_M) for s in t]  # reaches the wall at 2.9 s
    result = wall_following(track(t, x=[0.5 * s for s in t], y=y), wall_params(), one_wall)
    assert not result.passed and result.score == 0.0
    assert result.reason.startswith("crashed: walls[0] at t = 2.90 s")


def test_not_reaching_the_end_point_fails(one_wall: World) -> None:
    result = wall_following(along_the_wall(end_s=6.0), wall_params(), one_wall)
    assert not result.passed and result.score == 0.0
    assert "did not come within 1 m of the end point (5, 0.6) in 6.0 s (closest 2.00 m)" \
        in result.reason


def test_side_distance_clips_walls_and_discs_to_the_side() -> None:
    wall = world_shapes(world_from_dict({"walls": [[-1.0, 1.0, 1.0, 1.0]]}, source="wall"))
    # Facing the wall: it crosses the robot's axis, so it is on both sides, 1 m ahead.
    assert side_distance_m(wall, 0.0, 0.0, math.pi / 2, "left") == pytest.approx(1.0)
    assert side_distance_m(wall, 0.0, 0.0, math.pi / 2, "right") == pytest.approx(1.0)
    # Heading +x it is on the left only; past its end, its nearest point is its end.
    assert side_distance_m(wall, 0.0, 0.0, 0.0, "left") == pytest.approx(1.0)
    assert side_distance_m(wall, 0.0, 0.0, 0.0, "right") == math.inf
    assert side_distance_m(wall, 2.0, 0.0, 0.0, "left") == pytest.approx(math.sqrt(2.0))
    disc = world_shapes(world_from_dict({"circles": [{"center": [2.0, -0.3], "radius": 0.5}]},
                                        source="disc"))
    # Heading +x from the origin, the disc's centre is on the right: the nearest point there.
    assert side_distance_m(disc, 0.0, 0.0, 0.0, "right") == pytest.approx(
        math.hypot(2.0, 0.3) - 0.5)
    # On the left only its chord on the axis, x = 2 ± 0.4, is: 1.6 m ahead.
    assert side_distance_m(disc, 0.0, 0.0, 0.0, "left") == pytest.approx(1.6)
    assert side_distance_m(disc, 0.0, 1.0, 0.0, "left") == math.inf


# --- go to goal -------------------------------------------------------------------------------

OPEN = world_from_dict({"name": "open"}, source="open")


def goal_params(**overrides: object) -> GoToGoalParams:
    values = {"footprint_radius_m": RADIUS_M, "duration_s": 10.0, "goal_x_m": 2.0,
              "goal_y_m": 0.0, "goal_radius_m": 0.25, **overrides}
    return GoToGoalParams(**values)  # type: ignore[arg-type]


def straight_to_the_goal(collided: Sequence[bool] | None = None) -> list[Sample]:
    t = ticks(5.0, 0.05)
    return track(t, x=[0.5 * s for s in t], v=0.5, collided=collided)


def test_a_straight_path_to_the_goal_scores_by_time_alone() -> None:
    result = go_to_goal(straight_to_the_goal(), goal_params(), OPEN)
    figures = result.figures
    assert result.value == pytest.approx(3.5)  # 0.25 m short of (2, 0) at 0.5 m/s
    assert figures["reference_path_m"] == pytest.approx(2.0)
    assert figures["path_length_m"] == pytest.approx(1.75)
    assert figures["distance_term"] == pytest.approx(1.0)
    assert figures["path_term"] == pytest.approx(1.0)  # (2 - 0.25) / 1.75
    assert figures["time_term"] == pytest.approx(1.0 - 3.5 / 10.0)
    assert result.score == pytest.approx((1.0 + 1.0 + 0.5 * 0.65) / 2.5)  # 0.93
    assert result.passed


def test_a_robot_that_never_moves_gets_only_the_distance_element() -> None:
    result = go_to_goal(track(ticks(10.0, 0.05)), goal_params(), OPEN)
    miss = 2.0 - 0.25
    distance = 0.1 * (1.0 - miss / 2.0) + 0.9 * math.exp(-6.0 * miss / 2.0)
    assert result.value is None and not result.passed
    assert result.score == pytest.approx(distance / 2.5)  # 0.0069
    assert "did not come within 0.25 m of the goal (2, 0) (closest 2.00 m)" in result.reason


def test_a_contact_costs_the_penalty_time_and_the_pass() -> None:
    flags = [k == 20 for k in range(101)]  # touching at t = 1.0 s
    result = go_to_goal(straight_to_the_goal(flags), goal_params(), OPEN)
    assert result.figures["contacts"] == 1
    assert result.figures["effective_time_s"] == pytest.approx(3.5 + 10.0)
    assert result.figures["time_term"] == 0.0
    assert not result.passed and "1 contact with walls, first ? at t = 1.00 s" in result.reason


def test_the_shortest_path_goes_round_the_end_of_a_wall() -> None:
    world = world_from_dict({"walls": [[1.0, -1.0, 1.0, 1.0]]}, source="one wall")
    # Exact: tangents from (0, 0) and (2, 0) to the circle of radius r round (1, 1), and
    # the arc between them.
    tangent = math.sqrt(2.0 - RADIUS_M ** 2)
    arc = (1.5 * math.pi - 2.0 * math.acos(RADIUS_M / math.sqrt(2.0))) * RADIUS_M
    exact = 2.0 * tangent + arc  # 3.0098 m
    length = shortest_path_m(world, world_shapes(world), (0.0, 0.0), (2.0, 0.0), RADIUS_M)
    assert length is not None and exact <= length <= 1.025 * exact


def test_the_shortest_path_in_the_maze_is_found_and_a_walled_in_goal_has_none() -> None:
    maze = load_world("maze")
    length = shortest_path_m(maze, world_shapes(maze), (0.0, 0.0), (2.5, 2.5), RADIUS_M)
    assert length is not None and 7.0 < length < 7.6  # round three walls, not the 3.5 m line
    boxed = world_from_dict({"polylines": [{"points": [[1, -1], [3, -1], [3, 1], [1, 1]],
                                            "closed": True}]}, source="boxed")
    assert shortest_path_m(boxed, world_shapes(boxed), (0.0, 0.0), (2.0, 0.0), RADIUS_M) is None


# --- collisions and smoothness ----------------------------------------------------------------

def two_touches() -> list[Sample]:
    t = ticks(3.0, 0.1)
    y = [WALL_Y_M - RADIUS_M if 1.0 <= s < 1.5 else
         WALL_Y_M - RADIUS_M + 0.005 if 2.0 <= s < 2.2 else 0.5 for s in t]
    return track(t, y=y)


def test_contacts_are_counted_timed_and_named(one_wall: World) -> None:
    result = collisions(two_touches(), CollisionsParams(footprint_radius_m=RADIUS_M), one_wall)
    assert result.value == 2 and result.score == pytest.approx(1.0 / 3.0)
    assert not result.passed  # none allowed by default
    first, second = result.figures["listed"]
    assert (first["start_s"], first["end_s"], first["wall"]) == (1.0, 1.4, "walls[0]")
    assert (second["start_s"], second["end_s"]) == (2.0, 2.1)
    # 0.105 m from the wall overlaps the footprint; each touching sample counts its 0.1 s
    assert result.figures["time_in_contact_s"] == pytest.approx(0.7)
    assert result.inputs["contact_source"] == "geometry"
    allowed = collisions(two_touches(), CollisionsParams(footprint_radius_m=RADIUS_M,
                                                         threshold=2), one_wall)
    assert allowed.passed


def test_the_simulations_contact_flags_win_over_the_geometry(one_wall: World) -> None:
    flagged = [sample._replace(collided=False) for sample in two_touches()]
    result = collisions(flagged, CollisionsParams(footprint_radius_m=RADIUS_M), one_wall)
    assert result.value == 0 and result.passed
    assert result.inputs["contact_source"] == "simulation"


def test_smoothness_counts_full_range_swings_per_second() -> None:
    samples = track([0.0, 0.5, 1.0, 1.5, 2.0], v=[0.0, 0.5, 0.5, 0.0, 0.0],
                    w=[0.0, 0.0, 2.5, -2.5, 0.0])
    result = smoothness(samples, SmoothnessParams(max_linear_mps=0.5, max_angular_rps=2.5))
    assert result.figures["mean_abs_dv_mps_per_s"] == pytest.approx(1.0 / 2.0)
    assert result.figures["mean_abs_dw_rps_per_s"] == pytest.approx(10.0 / 2.0)
    assert result.value == pytest.approx(0.5 / 0.5 + 5.0 / 2.5)
    assert result.score == pytest.approx(1.0 / 3.0) and not result.passed


def test_a_trajectory_out_of_time_order_is_refused() -> None:
    with pytest.raises(ValueError, match=r"sample 2 at t = 0\.1 s does not follow t = 0\.2 s"):
        check_trajectory(track([0.0, 0.2, 0.1]))
