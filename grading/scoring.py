"""A run's score: its scenario's metrics measured on its trajectory, then weighted.

    scenario score = Σ w_m score_m / Σ w_m        over the metrics (weights >= 0, one > 0)
    suite total    = Σ W_s score_s / Σ W_s        over the scenarios

A scenario passes when every metric of weight > 0 passes; a metric of weight 0 (smoothness by
default) is reported and changes nothing.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from grading.metrics import METRICS
from grading.results import MetricResult
from grading.scenario import Scenario, Suite
from grading.trajectory import Trajectory


@dataclass(frozen=True)
class ScenarioResult:
    """One scenario's grade.

    Attributes:
        name: the scenario's name.
        score: the weighted mean of its metrics' scores, in [0, 1].
        passed: whether every metric of weight > 0 passed.
        reason: the first failing metric's reason, or "passed".
        metrics: each metric's result, in the scenario's order.
        weights: each metric's weight, in the same order.
    """

    name: str
    score: float
    passed: bool
    reason: str
    metrics: tuple[MetricResult, ...]
    weights: tuple[float, ...]

    def to_json(self) -> dict[str, Any]:
        """JSON-ready values for report.json."""
        return {"name": self.name, "score": self.score, "passed": self.passed,
                "reason": self.reason,
                "metrics": [dict(result.to_json(), weight=weight)
                            for result, weight in zip(self.metrics, self.weights, strict=True)]}


def evaluate(scenario: Scenario, trajectory: Trajectory) -> ScenarioResult:
    """Measure every metric of ``scenario`` on ``trajectory`` (ground truth) and weigh them."""
    results = []
    for spec in scenario.metrics:
        result = METRICS[spec.kind].measure(trajectory, spec.params, scenario.world)
        results.append(_renamed(result, spec.name))
    weights = tuple(spec.weight for spec in scenario.metrics)
    total = sum(weights)
    score = sum(w * r.score for w, r in zip(weights, results, strict=True)) / total
    failing = [r for w, r in zip(weights, results, strict=True) if w > 0.0 and not r.passed]
    reason = f"{failing[0].name}: {failing[0].reason}" if failing else "passed"
    return ScenarioResult(scenario.name, min(1.0, score), not failing, reason, tuple(results),
                          weights)


def suite_total(suite: Suite, results: Sequence[ScenarioResult]) -> float:
    """The suite's weighted total of its scenarios' scores, in [0, 1] (results in its order)."""
    weights = [entry.weight for entry in suite.entries]
    if len(results) != len(weights):
        raise ValueError(f"{len(results)} results for {len(weights)} scenarios")
    return min(1.0, sum(w * r.score for w, r in zip(weights, results, strict=True))
               / sum(weights))


def _renamed(result: MetricResult, name: str) -> MetricResult:
    return result if result.name == name else dataclasses.replace(result, name=name)
