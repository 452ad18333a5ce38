"""``report.html`` of ``websim compare --real``: one self-contained page, as ``websim grade``'s.

No internet, no script: the sentences that say where the gap comes from, the measures'
table, the paths in the plane and the heading and speeds over time as inline SVG (the time
plots are ``grading.report_page.plot_svg``, the grade report's). Pure: a summary and a
comparison in, text out.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from typing import Any

from grading.report_page import MAP_PX, Series, plot_svg
from physics.real_comparison import MODELS, RealComparison

COLOURS = {"real": "#000000", "kinematic": "#1f77b4", "dynamic": "#ff7f0e",
           "commanded": "#7f7f7f"}

MAX_PLOTTED_ROWS = 2000
"""Most ticks drawn per line (about 100 kB of SVG per plot)."""

STYLE = ("body{font-family:sans-serif;margin:1.5em;max-width:60em}"
         "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:.2em .5em}"
         "td.n{text-align:right;font-variant-numeric:tabular-nums}")


def _value(value: Any, scale: float = 1.0, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{value * scale:.{digits}f}"


MEASURES: tuple[tuple[str, tuple[str, ...], float], ...] = (
    ("APE translation RMSE (m)", ("ape", "translation_m", "rmse"), 1.0),
    ("APE translation max (m)", ("ape", "translation_m", "max"), 1.0),
    ("APE heading RMSE (°)", ("ape", "heading_rad", "rmse"), math.degrees(1.0)),
    ("APE, SE(2)-aligned: translation RMSE (m)", ("ape", "aligned", "translation_m", "rmse"),
     1.0),
    ("APE, SE(2)-aligned: heading RMSE (°)", ("ape", "aligned", "heading_rad", "rmse"),
     math.degrees(1.0)),
    ("RPE over 1 s: translation RMSE (m)", ("rpe_1s", "translation_m", "rmse"), 1.0),
    ("RPE over 1 s: heading RMSE (°)", ("rpe_1s", "heading_rad", "rmse"), math.degrees(1.0)),
    ("RPE over 1 m: translation RMSE (m)", ("rpe_1m", "translation_m", "rmse"), 1.0),
    ("final position error (m)", ("final", "position_m"), 1.0),
    ("final heading error (°)", ("final", "heading_rad"), math.degrees(1.0)),
)
"""The table's rows: label, where in a model's summary, factor to the unit shown."""


def measures_table(summary: dict[str, Any]) -> str:
    """Each measure for each model, then the speed ratios and lags with the real robot's."""
    head = "".join(f"<th>{mode} model</th>" for mode in MODELS)
    rows = [f"<tr><th>measure</th>{head}<th>real robot</th></tr>"]
    for label, path, scale in MEASURES:
        cells = []
        for mode in MODELS:
            value: Any = summary[mode]
            for key in path:
                value = value[key]
            cells.append(f'<td class="n">{_value(value, scale)}</td>')
        rows.append(f"<tr><td>{html.escape(label)}</td>{''.join(cells)}<td></td></tr>")
    for speed in ("linear", "angular"):
        for key, label in (("ratio", "speed per commanded"), ("lag_s", "lag (s)")):
            shown = "".join(f'<td class="n">{_value(summary[mode]["speeds"][speed][key], 1, 3)}'
                            "</td>" for mode in MODELS)
            real = _value(summary["real"]["speeds"][speed][key], 1, 3)
            rows.append(f"<tr><td>{speed} {label}</td>{shown}<td class=\"n\">{real}</td></tr>")
    return f"<table>{''.join(rows)}</table>"


def paths_svg(paths: Sequence[tuple[str, str, Sequence[float], Sequence[float]]]) -> str:
    """Paths (label, colour, xs, ys) in the plane at one scale, y up, with a legend."""
    xs = [x for _, _, path_x, _ in paths for x in path_x]
    ys = [y for _, _, _, path_y in paths for y in path_y]
    margin = 0.2
    min_x, max_x = min(xs) - margin, max(xs) + margin
    min_y, max_y = min(ys) - margin, max(ys) + margin
    scale = MAP_PX / max(max_x - min_x, max_y - min_y)
    width, height = (max_x - min_x) * scale, (max_y - min_y) * scale
    shapes = []
    for index, (label, colour, path_x, path_y) in enumerate(paths):
        points = " ".join(f"{(x - min_x) * scale:.1f},{(max_y - y) * scale:.1f}"
                          for x, y in zip(path_x, path_y, strict=True))
        shapes.append(f'<polyline points="{points}" fill="none" stroke="{colour}" '
                      f'stroke-width="{2.5 if index == 0 else 1.5}"/>')
        shapes.append(f'<text x="8" y="{16 + 14 * index}" font-size="12" fill="{colour}">'
                      f"{html.escape(label)}</text>")
    start_x, start_y = (paths[0][2][0] - min_x) * scale, (max_y - paths[0][3][0]) * scale
    shapes.append(f'<circle cx="{start_x:.1f}" cy="{start_y:.1f}" r="5" fill="#2ca02c">'
                  "<title>start</title></circle>")
    shapes.append(f'<text x="8" y="{height - 8:.0f}" font-size="11">{max_x - min_x:.2f} × '
                  f"{max_y - min_y:.2f} m</text>")
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" '
            f'height="{height:.0f}">{"".join(shapes)}</svg>')


def comparison_page(title: str, summary: dict[str, Any], result: RealComparison) -> str:
    """The whole page of a ``websim compare --real`` run.

    The plots show at most ``MAX_PLOTTED_ROWS`` ticks (every k-th): a long run stays a page
    a browser opens at once.
    """
    step = max(1, math.ceil(len(result.rows) / MAX_PLOTTED_ROWS))
    rows = result.rows[::step]
    t = [row.t_s for row in rows]
    recording = summary.get("recording", {})
    source = (f"{recording.get('kind', '')} {recording.get('path', '')}: commands "
              f"{' '.join(recording.get('command_topic', []))}, poses "
              f"{' '.join(recording.get('pose_topic', []))} ({recording.get('pose_source')}), "
              f"{recording.get('stamps')} stamps; {summary['duration_s']:.1f} s, "
              f"{summary['ticks']} ticks of {summary['dt_s']:g} s")
    names = ("real", *MODELS)
    labels = {"real": "real robot", **{mode: f"{mode} model" for mode in MODELS}}

    def series(column: str, scale: float = 1.0, commanded: str | None = None) -> list[Series]:
        out: list[Series] = [(labels[name], COLOURS[name], t,
                              [getattr(row, f"{name}_{column}") * scale for row in rows])
                             for name in names]
        if commanded is not None:
            out.append(("commanded", COLOURS["commanded"], t,
                        [getattr(row, commanded) for row in rows]))
        return out

    parts = [f"<h1>{html.escape(title)}</h1>", f"<p>{html.escape(source)}</p>",
             "<h2>Where the gap comes from</h2>",
             "".join(f"<p>{html.escape(line)}</p>" for line in summary["explanation"]),
             "<h2>Measures</h2>", measures_table(summary),
             "<p>APE: the distance between the real and the modelled pose at the same time; "
             "aligned: after the rigid motion that best overlays the paths. RPE: the error of "
             "the motion over each second (or metre) alone, whatever happened before.</p>",
             "<h2>Paths in the plane</h2>",
             paths_svg([(labels[name], COLOURS[name],
                         [getattr(row, f"{name}_x") for row in rows],
                         [getattr(row, f"{name}_y") for row in rows]) for name in names]),
             "<h3>Heading</h3>", plot_svg(series("yaw", math.degrees(1.0)), "°"),
             "<h3>Forward speed</h3>", plot_svg(series("v", commanded="cmd_v"), "m/s"),
             "<h3>Yaw rate</h3>", plot_svg(series("omega", commanded="cmd_omega"), "rad/s")]
    return ("<!DOCTYPE html><html><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style></head>"
            f"<body>{''.join(parts)}</body></html>")
