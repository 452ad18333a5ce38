"""The motor driver between ``/cmd_vel`` and the wheels: scale, ramp, then lag.

A real robot does not do what it was told at once and exactly: the driver's idea of the wheel
radius and wheelbase may be off (a scale factor), it ramps the speeds up and down (an
acceleration limit, as ros2_control's diff_drive_controller does), and the command crosses
Wi-Fi and the driver's loop before the wheels answer (a dead time). Each tick the simulation
passes the command in force through ``drive``, and the wheels get what comes out, in both
motion models::

    scaled   = (linear_scale * command.linear, angular_scale * command.angular)
    ramped   = scaled, moved from the last tick's ramped value by at most the limit * dt
    output   = the ramped value of cmd_lag_s ago (between two ticks' values: the share of the
               tick each was in force, so a lag of 0.12 s on 50 ms ticks is exact for the
               distance driven, and the response moves smoothly with the lag)

A dead time commutes with the gain and the ramp, so the order is a choice of arithmetic; this
one makes every output a continuous function of the lag, which the fit needs
(``physics.command_fit``). The shipped parameters (no lag, scales of 1, no limits) make
``drive`` return the command itself: the course robot's model, and every figure made before
this stage existed.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

from physics.params import RobotParams
from physics.snapshots import Command

STOP = Command(0.0, 0.0)


class DriveState(NamedTuple):
    """What the driver remembers between ticks.

    Attributes:
        recent: the ramped commands of the last ticks, newest first, as many as the lag
            reaches back.
        before: the ramped command in force before the oldest of ``recent`` (a stop at rest).
        ramped: the ramp's value last tick (m/s, rad/s).
    """

    recent: tuple[Command, ...]
    before: Command
    ramped: Command


AT_REST = DriveState((), STOP, STOP)
"""The driver of a robot standing still that has had no command yet."""


def drive(state: DriveState, command: Command, params: RobotParams,
          dt_s: float) -> tuple[DriveState, Command]:
    """One tick of the driver: the command in force now in, the wheels' command out.

    Args:
        state: the driver's memory after the last tick (``AT_REST`` at first).
        command: the (clamped) command in force for this tick.
        params: the robot; its scales, acceleration limits and ``cmd_lag_s``.
        dt_s: the tick's length (s).

    Returns:
        The driver's memory for the next tick, and what the wheels get this tick.
    """
    linear, angular = command
    if params.linear_scale != 1.0:
        linear *= params.linear_scale
    if params.angular_scale != 1.0:
        angular *= params.angular_scale
    last = state.ramped
    if params.linear_accel_limit_mps2 > 0.0:
        linear = _ramp(last.linear_mps, linear, params.linear_accel_limit_mps2 * dt_s)
    if params.angular_accel_limit_rps2 > 0.0:
        angular = _ramp(last.angular_rps, angular, params.angular_accel_limit_rps2 * dt_s)
    ramped = command if (linear, angular) == tuple(command) else Command(linear, angular)
    lag_ticks = round(params.cmd_lag_s / dt_s, 9)  # 0.1 / 0.05 is 2 ticks, not 1.999...
    whole = math.floor(lag_ticks)
    keep = whole + 2 if params.cmd_lag_s > 0.0 else 1
    history = (ramped, *state.recent)
    recent, dropped = history[:keep], history[keep:]
    before = dropped[0] if dropped else state.before
    output = ramped
    if params.cmd_lag_s > 0.0:
        share = lag_ticks - whole  # of this tick, still under the value one tick older
        newer = recent[whole] if whole < len(recent) else before
        older = recent[whole + 1] if whole + 1 < len(recent) else before
        output = Command((1.0 - share) * newer.linear_mps + share * older.linear_mps,
                         (1.0 - share) * newer.angular_rps + share * older.angular_rps)
    return DriveState(recent, before, ramped), output


def drive_sequence(commands: Iterable[Command], params: RobotParams,
                   dt_s: float) -> list[Command]:
    """``drive`` over a whole run from rest: the wheels' command for each tick's command."""
    state = AT_REST
    out = []
    for command in commands:
        state, output = drive(state, command, params, dt_s)
        out.append(output)
    return out


def passes_through(params: RobotParams) -> bool:
    """Whether ``drive`` gives every command unchanged (the shipped robot's driver)."""
    return (params.cmd_lag_s == 0.0 and params.linear_scale == 1.0
            and params.angular_scale == 1.0 and params.linear_accel_limit_mps2 == 0.0
            and params.angular_accel_limit_rps2 == 0.0)


def _ramp(last: float, target: float, max_step: float) -> float:
    """``target``, or ``last`` moved towards it by at most ``max_step``."""
    return last + max(-max_step, min(max_step, target - last))
