"""A run's ``report.html``: one self-contained page (no internet, no script) to read a grade.

The trajectory over the world (walls, discs, start, end or goal) as inline SVG, each metric's
time series (the true heading against its setpoint, the distance to the followed wall against
d*, the distance to the goal; the commands), the metrics' table, how the run ended and the
controller's output. Pure: a report (``report.json``'s dict), its scenario and trajectory in,
text out.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from grading.geometry import side_distance_m, world_shapes
from grading.results import figure
from grading.scenario import Scenario
from grading.trajectory import Trajectory, unwrapped_yaw

PLOT_W, PLOT_H = 760, 220
MAP_PX = 480
MARGIN = 40
PLOT_LEFT = 60
"""Left of the plotting area: the value axis's labels."""
LEGEND_W = 130
"""Right of the plotting area: the legend."""

Series = tuple[str, str, Sequence[float], Sequence[float]]
"""(label, colour, times s, values)."""


def report_html(scenario: Scenario, trajectory: Trajectory, report: Mapping[str, Any]) -> str:
    """The page for one run."""
    title = f"{scenario.name}: {report['score']:.4f} {'passed' if report['passed'] else 'failed'}"
    parts = [f"<h1>{html.escape(title)}</h1>",
             f"<p>{html.escape(str(report['reason']))}</p>",
             f"<p>{html.escape(scenario.description)} ({html.escape(str(report.get('mode')))} "
             f"mode, seed {scenario.seed})</p>",
             "<h2>Trajectory (ground truth, map frame)</h2>", trajectory_svg(scenario, trajectory),
             "<h2>Metrics</h2>"]
    completed = "score_if_completed" not in report and not report.get("invalid")
    if not completed:
        parts.append("<p>The run did not run its course, so it scores 0: what the metrics "
                     "would have found until it ended:</p>")
    parts.append(metrics_table(report.get("metrics", []), completed=completed))
    for name, unit, series in time_series(scenario, trajectory):
        parts += [f"<h3>{html.escape(name)}</h3>", plot_svg(series, unit)]
    run = report.get("run") or {}
    if run:
        parts.append(f"<h2>The run</h2><p>{html.escape(str(run.get('reason')))}: "
                     f"{figure(run.get('sim_time_s'), 's')} of sim time, "
                     f"{run.get('commands')} commands, {run.get('missed_steps')} missed "
                     "steps</p>")
    if report.get("recording_note"):
        parts.append(f"<p>{html.escape(str(report['recording_note']))}</p>")
    if report.get("recording"):
        parts.append(f"<p>Recording: <code>{html.escape(str(report['recording']))}</code> "
                     "(open the .mcap in Foxglove or Lichtblick, or <code>websim replay</code> "
                     "it)</p>")
    controller = report.get("controller") or {}
    if controller:
        parts += [f"<h2>The controller</h2><p>{html.escape(str(controller.get('reason')))}</p>",
                  f"<pre>{html.escape(str(controller.get('output_tail', '')))}</pre>"]
    return ("<!DOCTYPE html><html><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>"
            "body{font-family:sans-serif;margin:1.5em;max-width:60em}"
            "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:.2em .5em}"
            "pre{background:#f4f4f4;padding:.5em;max-height:30em;overflow:auto}"
            f"</style></head><body>{''.join(parts)}</body></html>")


def metrics_table(metrics: Sequence[Mapping[str, Any]], *, completed: bool = True) -> str:
    """The metrics as a table: name, value, threshold, pass, score, weight, reason.

    A run that did not run its course (``completed`` False: the controller crashed or
    stopped answering) has no passing row: its metrics say what they would have found,
    each "not judged".
    """
    rows = ["<tr><th>metric</th><th>value</th><th>threshold</th><th>pass</th><th>score</th>"
            "<th>weight</th><th>reason</th></tr>"]
    for metric in metrics:
        unit = metric.get("unit", "")
        shown = "—" if metric.get("value") is None else figure(metric["value"], unit)
        threshold = metric.get("threshold")
        verdict = ("yes" if metric.get("passed") else "no") if completed else "not judged"
        score = f"{metric.get('score', 0.0):.4f}" if completed else "—"
        rows.append(
            f"<tr><td>{html.escape(metric['name'])}</td><td>{html.escape(shown)}</td>"
            f"<td>{'—' if threshold is None else html.escape(figure(threshold, unit))}</td>"
            f"<td>{verdict}</td><td>{score}</td><td>{metric.get('weight', 1):g}</td>"
            f"<td>{html.escape(str(metric.get('reason', '')))}</td></tr>")
    return f"<table>{''.join(rows)}</table>"


def time_series(scenario: Scenario, trajectory: Trajectory
                ) -> list[tuple[str, str, list[Series]]]:
    """What each metric measures over time: (title, unit, series)."""
    times = [sample.t_s for sample in trajectory]
    plots: list[tuple[str, str, list[Series]]] = []
    kinds = {spec.kind: spec.params for spec in scenario.metrics}
    if "heading_step" in kinds:
        heading = unwrapped_yaw(trajectory)
        heading = heading - heading[0]
        setpoints = [float(scenario.parameters_at(t).get("setpoint_rad", 0.0)) for t in times]
        plots.append(("heading step: true heading and setpoint", "rad", [
            ("heading", "#1f77b4", times, list(heading)),
            ("setpoint", "#d62728", times, setpoints)]))
    if "wall_following" in kinds:
        params = kinds["wall_following"]
        shapes = world_shapes(scenario.world)
        distances = [min(side_distance_m(shapes, s.x_m, s.y_m, s.yaw_rad, params.side),
                         params.max_distance_m) for s in trajectory]
        plots.append((f"wall following: distance to the {params.side} wall and d*", "m", [
            ("d", "#1f77b4", times, distances),
            ("d*", "#d62728", times, [params.desired_distance_m] * len(times))]))
    if "go_to_goal" in kinds:
        params = kinds["go_to_goal"]
        plots.append(("go to goal: distance to the goal", "m", [
            ("distance", "#1f77b4", times,
             [math.hypot(s.x_m - params.goal_x_m, s.y_m - params.goal_y_m) for s in trajectory]),
            ("radius", "#d62728", times, [params.goal_radius_m] * len(times))]))
    plots.append(("commands in force", "m/s, rad/s", [
        ("linear m/s", "#2ca02c", times, [s.v_cmd_mps for s in trajectory]),
        ("angular rad/s", "#9467bd", times, [s.w_cmd_rps for s in trajectory])]))
    return plots


def nice_ticks(low: float, high: float, count: int = 5) -> list[float]:
    """About ``count`` round values (1, 2 or 5 times a power of ten apart) in [low, high]."""
    span = high - low
    if not span > 0.0 or not math.isfinite(span):
        return [low]
    raw = span / max(1, count - 1)
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1.0, 2.0, 5.0, 10.0) if m * power >= raw)
    first = math.ceil(low / step - 1e-9) * step
    ticks: list[float] = []
    value = first
    while value <= high + 1e-9 * step and len(ticks) < 4 * count:
        ticks.append(0.0 if abs(value) < step * 1e-9 else value)
        value += step
    return ticks


def plot_svg(series: Sequence[Series], unit: str) -> str:
    """Lines over time: axes with ticks and their values, and a legend beside the plot.

    The legend stands right of the plotting area, never over the lines.
    """
    finite = [v for _, _, _, values in series for v in values if math.isfinite(v)]
    t_max = max((max(times) for _, _, times, _ in series if times), default=1.0) or 1.0
    low, high = (min(finite), max(finite)) if finite else (0.0, 1.0)
    if high - low < 1e-9:
        low, high = low - 0.5, high + 0.5
    pad = 0.05 * (high - low)
    low, high = low - pad, high + pad
    left, top = PLOT_LEFT, MARGIN // 2
    width, height = PLOT_W - left - LEGEND_W, PLOT_H - top - MARGIN

    def x_of(t: float) -> float:
        return left + width * t / t_max

    def y_of(v: float) -> float:
        return top + height * (1 - (v - low) / (high - low))

    lines = [f'<rect x="{left}" y="{top}" width="{width}" height="{height}" fill="none" '
             'stroke="#999"/>']
    for value in nice_ticks(low, high):
        y = y_of(value)
        lines += [f'<line x1="{left - 4}" y1="{y:.1f}" x2="{left + width}" y2="{y:.1f}" '
                  'stroke="#eee"/>',
                  f'<text x="{left - 6}" y="{y + 4:.1f}" font-size="11" text-anchor="end">'
                  f"{value:.3g}</text>"]
    for t in nice_ticks(0.0, t_max, 8):
        x = x_of(t)
        lines += [f'<line x1="{x:.1f}" y1="{top + height}" x2="{x:.1f}" '
                  f'y2="{top + height + 4}" stroke="#999"/>',
                  f'<text x="{x:.1f}" y="{top + height + 16}" font-size="11" '
                  f'text-anchor="middle">{t:g}</text>']
    lines += [f'<text x="{left + width / 2:.0f}" y="{PLOT_H - 4}" font-size="11" '
              'text-anchor="middle">t (s, sim time)</text>',
              f'<text x="12" y="{top + height / 2:.0f}" font-size="11" text-anchor="middle" '
              f'transform="rotate(-90 12 {top + height / 2:.0f})">{html.escape(unit)}</text>']
    for index, (label, colour, times, values) in enumerate(series):
        points = " ".join(f"{x_of(t):.1f},{y_of(v):.1f}"
                          for t, v in zip(times, values, strict=True) if math.isfinite(v))
        lines.append(f'<polyline points="{points}" fill="none" stroke="{colour}" '
                     'stroke-width="1.5"/>')
        y = top + 10 + 16 * index
        lines += [f'<line x1="{left + width + 10}" y1="{y}" x2="{left + width + 26}" '
                  f'y2="{y}" stroke="{colour}" stroke-width="2"/>',
                  f'<text x="{left + width + 30}" y="{y + 4}" font-size="11">'
                  f"{html.escape(label)}</text>"]
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{PLOT_W}" height="{PLOT_H}">'
            f"{''.join(lines)}</svg>")


def trajectory_svg(scenario: Scenario, trajectory: Trajectory) -> str:
    """The world and the path, y up, at one scale."""
    world = scenario.world
    targets: list[tuple[float, float, float, str]] = []
    if scenario.end is not None:
        targets.append((scenario.end.x_m, scenario.end.y_m, scenario.end.radius_m, "end"))
    for spec in scenario.metrics:
        if spec.kind == "go_to_goal":
            targets.append((spec.params.goal_x_m, spec.params.goal_y_m,
                            spec.params.goal_radius_m, "goal"))
    xs = np.array([s.x_m for s in trajectory] + [x + d for x, _, r, _ in targets
                                                  for d in (-r, r)])
    ys = np.array([s.y_m for s in trajectory] + [y + d for _, y, r, _ in targets
                                                  for d in (-r, r)])
    min_x, min_y, max_x, max_y = world.bounds
    min_x, max_x = min(min_x, float(xs.min())) - 0.3, max(max_x, float(xs.max())) + 0.3
    min_y, max_y = min(min_y, float(ys.min())) - 0.3, max(max_y, float(ys.max())) + 0.3
    scale = MAP_PX / max(max_x - min_x, max_y - min_y)
    width, height = (max_x - min_x) * scale, (max_y - min_y) * scale

    def at(x: float, y: float) -> tuple[float, float]:
        return (x - min_x) * scale, (max_y - y) * scale

    shapes = []
    for wall in world.walls:
        (ax, ay), (bx, by) = at(wall.x1, wall.y1), at(wall.x2, wall.y2)
        shapes.append(f'<line x1="{ax:.1f}" y1="{ay:.1f}" x2="{bx:.1f}" y2="{by:.1f}" '
                      'stroke="#333" stroke-width="3"/>')
    for circle in world.circles:
        cx, cy = at(circle.x, circle.y)
        shapes.append(f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{circle.radius_m * scale:.1f}" '
                      'fill="#666"/>')
    path = " ".join(f"{px:.1f},{py:.1f}"
                    for px, py in (at(sample.x_m, sample.y_m) for sample in trajectory))
    shapes.append(f'<polyline points="{path}" fill="none" stroke="#1f77b4" stroke-width="2"/>')
    sx, sy = at(scenario.start.x, scenario.start.y)
    shapes.append(f'<circle cx="{sx:.1f}" cy="{sy:.1f}" r="5" fill="#2ca02c"><title>start'
                  '</title></circle>')
    for x, y, radius, label in targets:
        tx, ty = at(x, y)
        shapes.append(f'<circle cx="{tx:.1f}" cy="{ty:.1f}" r="{radius * scale:.1f}" '
                      f'fill="none" stroke="#d62728" stroke-dasharray="4"><title>{label}'
                      '</title></circle>')
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" '
            f'height="{height:.0f}">{"".join(shapes)}</svg>')
