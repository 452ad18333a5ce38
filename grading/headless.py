"""A scenario run in this process with a Python controller: no server, no sockets, no clock.

The reference the graded runs are held to, and what tests grade controllers with. The
simulation is built as ``websim serve`` builds it (the shipped robot with the scenario's
payload, the shipped LiDAR, the shipped noise with the world's own sigmas in its place) and
advances one physics tick (0.05 s) at a time; every ``controller_period_ticks``
ticks, starting at t = 0, the controller is called with what the robot publishes at that
moment (odometry, the true pose, a LiDAR scan, the parameters in force) and its command is
applied from that tick on, as a ``/cmd_vel`` that arrives at once. Timed changes apply at the
first tick at or after their time, before the controller is called. The run stops at
``duration_s`` or, with an ``end``, at the first sample within its radius.

Every step is a pure function of the scenario, the seed and the controller's answers, so
the same controller gives the same trajectory to the last bit, run after run.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

from grading.scenario import ParameterValue, Scenario
from grading.trajectory import Sample
from physics.params import NoiseParams
from physics.simulation import Simulation
from physics.snapshots import Command, LaserScan, Odometry
from physics.validation import ConfigError


@dataclass(frozen=True)
class Observation:
    """What a controller sees when it is called.

    Attributes:
        time_s: sim time since the start (s), as the messages' stamps say.
        odometry: ``/odom``: wheel odometry in the odom frame (zero at the start).
        ground_truth: ``/ground_truth``: the true pose and speeds in the map frame.
        scan: ``/scan``: the LiDAR scan at this instant.
        parameters: the scenario's parameters in force (what ``WEBSIM_<NAME>`` told it,
            with the changes made so far).
    """

    time_s: float
    odometry: Odometry
    ground_truth: Odometry
    scan: LaserScan
    parameters: Mapping[str, ParameterValue]


class Controller(Protocol):
    """A controller: an observation in, a command out.

    Returns (linear m/s, angular rad/s), as a ``/cmd_vel`` Twist's linear.x and angular.z;
    None keeps the command in force. Values beyond the robot's limits are clamped.
    """

    def __call__(self, observation: Observation) -> tuple[float, float] | None:
        """One control step."""


def run_headless(scenario: Scenario,
                 controller: Controller | Callable[[Observation],
                                                    tuple[float, float] | None]
                 ) -> list[Sample]:
    """Run ``scenario`` with ``controller`` and return its trajectory (ground truth).

    The first sample is the start (t = 0, no command yet); then one sample per tick, with
    the command in force during that tick and the simulation's contact flag.

    Raises:
        physics.ConfigError: the controller answered with a value that is not a number
            (the message says which, and when).
    """
    simulation = Simulation(scenario.world, scenario.robot, mode=scenario.mode,
                            seed=scenario.seed, lidar=scenario.lidar,
                            noise=scenario.world.noise_over(NoiseParams()))
    period = scenario.controller_period_ticks
    ticks = math.floor(scenario.duration_s / simulation.dt_s + 1e-9)
    pending = list(scenario.changes)
    parameters = dict(scenario.parameters)
    start = simulation.ground_truth()
    trajectory = [Sample(0.0, start.x, start.y, start.theta, 0.0, 0.0, False)]
    for tick in range(ticks):
        now_s = simulation.time_s
        while pending and pending[0].at_s <= now_s + 1e-9:
            change = pending.pop(0)
            if change.payload is not None:
                simulation.set_payload(change.payload.mass_kg, change.payload.inertia_kg_m2)
            if change.mode is not None:
                simulation.mode = change.mode
            parameters.update(change.parameters)
        if tick % period == 0:
            observation = Observation(now_s, simulation.odometry(), simulation.ground_truth(),
                                      simulation.scan(), dict(parameters))
            answer = controller(observation)
            if answer is not None:
                try:
                    linear, angular = answer
                    simulation.command(linear, angular)
                except (TypeError, ValueError) as error:
                    raise ConfigError(f"the controller's answer at t = {now_s:.2f} s: {error} "
                                      f"(expected (linear_mps, angular_rps) or None)") from None
        command: Command = simulation.last_command
        simulation.step()
        pose = simulation.ground_truth()
        trajectory.append(Sample(simulation.time_s, pose.x, pose.y, pose.theta,
                                 command.linear_mps, command.angular_rps,
                                 simulation.state().collided))
        end = scenario.end
        if end is not None and math.hypot(pose.x - end.x_m, pose.y - end.y_m) <= end.radius_m:
            break
    return trajectory
