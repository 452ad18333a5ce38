"""websim's grader core: scenario files, metrics over a trajectory, a headless reference run.

Pure computation and file parsing, on ``physics`` (worlds, geometry, parameters); no server,
ROS or sockets. ``websim grade`` (later) runs a student's controller against a private
simulator, records the run and hands its trajectory to ``evaluate``; ``run_headless`` runs a
Python controller in-process, the reference for tests and for determinism.

Example::

    from grading import load_scenario, run_headless, evaluate
    scenario = load_scenario("heading_pid")          # examples/scenarios/heading_pid.yaml
    trajectory = run_headless(scenario, my_controller)
    result = evaluate(scenario, trajectory)
    result.score, result.passed, result.reason
"""

from grading.headless import Controller, Observation, run_headless
from grading.metrics import METRICS
from grading.results import MetricResult
from grading.scenario import (
    Scenario,
    Suite,
    controller_environment,
    load_scenario,
    load_suite,
)
from grading.scoring import ScenarioResult, evaluate, suite_total
from grading.trajectory import Sample, Trajectory

__all__ = [
    "METRICS",
    "Controller",
    "MetricResult",
    "Observation",
    "Sample",
    "Scenario",
    "ScenarioResult",
    "Suite",
    "Trajectory",
    "controller_environment",
    "evaluate",
    "load_scenario",
    "load_suite",
    "run_headless",
    "suite_total",
]
