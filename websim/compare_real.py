"""``websim compare --real RECORDING``: a real robot's recorded commands through both models.

Reads the recording (``websim.real_recording``: rosbag2 .db3 or .mcap, ROS 1 .bag, CSV),
replays its commands with their real timing through the kinematic and the dynamic model
(``physics.real_comparison``) and writes, to ``--out``: ``trajectory.csv`` (one row per tick:
the command, the real robot, each model; ``REAL_COLUMNS``), ``summary.json`` (the errors,
the speed responses, the causes and the sentences), ``comparison.png`` (with matplotlib;
``--format``) and ``report.html`` (self-contained, inline SVG). Prints a short table.

The options that say how to read a recording (topics, stamps, window, command timeout) are
shared with ``websim fit`` (``add_recording_arguments``, ``grid_from``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from physics import ConfigError, load_params
from physics.real_comparison import MODELS, REAL_COLUMNS, RealComparison, compare_real
from physics.recorded_run import GridRun, on_grid
from ros_nodes.parameters import CMD_VEL_TIMEOUT_OFF_S
from websim.compare_command import (
    FIGURE_DPI,
    opened,
    plots_hint,
    robot_with_overrides,
    write_table,
)
from websim.real_recording import STAMPS, Recording, Topics, read_recording
from websim.validation_report import comparison_page

MODEL_COLOURS = {"real": "black", "kinematic": "tab:blue", "dynamic": "tab:orange"}
"""Line colour of the real robot and each model, in the figure and the report."""


def add_recording_arguments(parser: argparse.ArgumentParser) -> None:
    """How to read a real robot's recording: topics, stamps, window, command timeout."""
    group = parser.add_argument_group("reading a real robot's recording")
    group.add_argument("--cmd-topic", default="/cmd_vel",
                       help="the commands: geometry_msgs Twist or TwistStamped (default "
                            "/cmd_vel)")
    group.add_argument("--odom-topic", default="/odom",
                       help="the measured poses: nav_msgs/Odometry (default /odom)")
    group.add_argument("--truth-topic", default=None,
                       help="ground truth to use instead of odometry (motion capture): "
                            "PoseStamped, Odometry or TFMessage")
    group.add_argument("--truth-frame", default="base_link",
                       help="with a TFMessage ground truth: the robot's child frame "
                            "(default base_link)")
    group.add_argument("--stamps", choices=STAMPS, default="receive",
                       help="message times: receive (when the recorder got each message, one "
                            "clock; default) or header (the senders' stamps; a Twist without "
                            "a header keeps its receive time)")
    group.add_argument("--start", type=float, default=None, metavar="S",
                       help="window start, s from the recording's first message read")
    group.add_argument("--end", type=float, default=None, metavar="S",
                       help="window end, s from the recording's first message read")
    group.add_argument("--cmd-timeout", type=float, default=CMD_VEL_TIMEOUT_OFF_S, metavar="S",
                       help="the robot driver's command timeout: a command older than this "
                            "is a stop (default 0: none, as the course robot's "
                            "cmd_vel_timeout_s)")


def read_from(args: argparse.Namespace) -> Recording:
    """The recording the arguments name, read as they say."""
    topics = Topics(args.cmd_topic, args.odom_topic, args.truth_topic, args.truth_frame)
    for name in ("start", "end", "cmd_timeout"):
        value = getattr(args, name)
        if value is not None and (not math.isfinite(value) or value < 0):
            raise ConfigError(f"--{name.replace('_', '-')}: expected a number of seconds >= 0, "
                              f"got {value}")
    return read_recording(Path(args.real), topics, args.stamps, args.start, args.end)


def grid_from(args: argparse.Namespace, recording: Recording) -> GridRun:
    """The recording on the simulation's ticks, with the arguments' window and timeout."""
    return on_grid(recording.run, cmd_timeout_s=args.cmd_timeout, start_s=args.start,
                   end_s=args.end)


def run(args: argparse.Namespace) -> int:
    """``websim compare --real``: read, replay, write the files, print the table."""
    recording = read_from(args)
    platform = load_params(args.params)
    robot = robot_with_overrides(platform.robot, args.overrides)
    grid = grid_from(args, recording)
    out: Path = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ConfigError(f"{out}: cannot create output directory: {error.strerror}") from None
    result = compare_real(grid, robot, seed=args.seed, noise=platform.noise)
    summary = {"recording": recording.info, "params": str(args.params),
               "overrides": list(args.overrides), "cmd_timeout_s": args.cmd_timeout,
               **result.summary}
    written = [write_rows(result, out / "trajectory.csv"),
               write_json(summary, out / "summary.json")]
    title = f"{Path(args.real).name}: the real robot against both models"
    written.append(write_text(comparison_page(title, summary, result), out / "report.html"))
    figure_path = out / f"comparison.{args.figure_format}"
    try:
        written.append(write_figure(result, figure_path, title))
    except ImportError:
        print(f"websim: {figure_path.name} skipped, matplotlib is not installed: {plots_hint()}",
              file=sys.stderr)
    print(f"wrote {', '.join(str(path) for path in written)}")
    print(summary_table(summary))
    for line in summary["explanation"]:
        print(line)
    return 0


def _number(value: Any, scale: float = 1.0, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{value * scale:.{digits}f}"


def summary_table(summary: dict[str, Any]) -> str:
    """The short table ``websim compare --real`` prints: each measure per model."""
    rows: list[tuple[str, list[str]]] = []

    def measure(label: str, path: tuple[str, ...], scale: float = 1.0) -> None:
        values = []
        for mode in MODELS:
            value: Any = summary[mode]
            for key in path:
                value = value[key]
            values.append(_number(value, scale))
        rows.append((label, values))

    measure("APE translation RMSE (m)", ("ape", "translation_m", "rmse"))
    measure("APE translation max (m)", ("ape", "translation_m", "max"))
    measure("APE heading RMSE (deg)", ("ape", "heading_rad", "rmse"), math.degrees(1.0))
    measure("APE aligned translation RMSE (m)", ("ape", "aligned", "translation_m", "rmse"))
    measure("APE aligned heading RMSE (deg)", ("ape", "aligned", "heading_rad", "rmse"),
            math.degrees(1.0))
    measure("RPE 1 s translation RMSE (m)", ("rpe_1s", "translation_m", "rmse"))
    measure("RPE 1 m translation RMSE (m)", ("rpe_1m", "translation_m", "rmse"))
    measure("final position error (m)", ("final", "position_m"))
    measure("final heading error (deg)", ("final", "heading_rad"), math.degrees(1.0))
    for speed in ("linear", "angular"):
        rows.append((f"{speed} speed ratio (real "
                     f"{_number(summary['real']['speeds'][speed]['ratio'], digits=3)})",
                     [_number(summary[mode]["speeds"][speed]["ratio"], digits=3)
                      for mode in MODELS]))
        rows.append((f"{speed} lag s (real "
                     f"{_number(summary['real']['speeds'][speed]['lag_s'], digits=3)})",
                     [_number(summary[mode]["speeds"][speed]["lag_s"], digits=3)
                      for mode in MODELS]))
    width = max(len(label) for label, _ in rows)
    lines = [f"{'':{width}}  {MODELS[0]:>10}  {MODELS[1]:>10}"]
    lines += [f"{label:{width}}  {values[0]:>10}  {values[1]:>10}" for label, values in rows]
    return "\n".join(lines)


def write_rows(result: RealComparison, path: Path) -> Path:
    """``trajectory.csv``: one row per tick (``REAL_COLUMNS``)."""
    return write_table(path, REAL_COLUMNS, result.rows)


def write_json(summary: dict[str, Any], path: Path) -> Path:
    """``summary.json``, indented; NaN (a measure with nothing to measure) as null."""
    with opened(path) as stream:
        json.dump(_finite(summary), stream, indent=2)
        stream.write("\n")
    return path


def _finite(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_text(text: str, path: Path) -> Path:
    """Write ``text`` (the report page) to ``path``."""
    with opened(path) as stream:
        stream.write(text)
    return path


def write_figure(result: RealComparison, path: Path, title: str = "") -> Path:
    """Paths in the plane; heading, v and ω over time: the real robot and both models.

    Raises:
        ImportError: matplotlib is not installed.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(12, 9.75), dpi=FIGURE_DPI, layout="constrained")
    FigureCanvasAgg(figure)
    if title:
        figure.suptitle(title, fontsize=10)
    grid = figure.add_gridspec(3, 2, width_ratios=(1.0, 1.25))
    plane = figure.add_subplot(grid[:, 0])
    heading = figure.add_subplot(grid[0, 1])
    linear = figure.add_subplot(grid[1, 1], sharex=heading)
    angular = figure.add_subplot(grid[2, 1], sharex=heading)
    rows = result.rows
    t = [row.t_s for row in rows]
    for name in ("real", *MODELS):
        colour = MODEL_COLOURS[name]
        label = "real robot" if name == "real" else f"{name} model"
        xs = [getattr(row, f"{name}_x") for row in rows]
        ys = [getattr(row, f"{name}_y") for row in rows]
        plane.plot(xs, ys, color=colour, linewidth=2 if name == "real" else 1.6, label=label)
        plane.plot(xs[-1], ys[-1], marker="o", color=colour)
        heading.plot(t, [math.degrees(getattr(row, f"{name}_yaw")) for row in rows],
                     color=colour, linewidth=1.5, label=label)
        for axes, column in ((linear, "v"), (angular, "omega")):
            axes.plot(t, [getattr(row, f"{name}_{column}") for row in rows], color=colour,
                      linewidth=1.5, label=label)
    plane.plot(rows[0].real_x, rows[0].real_y, marker="s", color="black", label="start")
    for axes, column in ((linear, "cmd_v"), (angular, "cmd_omega")):
        axes.step(t, [getattr(row, column) for row in rows], where="pre", color="0.45",
                  linestyle="--", linewidth=1.1, label="commanded")
    plane.set_aspect("equal", adjustable="datalim")
    plane.set(xlabel="x (m)", ylabel="y (m)", title="Paths in the plane (from the real start)")
    heading.set(ylabel="yaw (°)", title="Heading, speeds: the real robot and both models")
    linear.set_ylabel("v (m/s)")
    angular.set(ylabel="ω (rad/s)", xlabel="t (s)")
    for axes in (plane, heading, linear, angular):
        axes.grid(alpha=0.3)
        axes.legend(loc="best", fontsize=8)
    figure.savefig(path, format=path.suffix.lstrip(".") or "png", dpi=FIGURE_DPI)
    return path
