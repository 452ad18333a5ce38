"""The ``websim`` command: each subcommand is a function of parsed arguments -> exit code."""

from __future__ import annotations

import argparse
import importlib.metadata
import math
import sys
import time
from collections.abc import Callable, Sequence

from classroom import nginx_config
from classroom.registry import Student, check_name, strong_token, weak_token
from physics import (
    MODES,
    TICK_PERIOD_S,
    ConfigError,
    Simulation,
    WorldSim,
    load_params,
    load_world,
    raycast_kernel,
)
from physics.params import SHIPPED_PARAMS_FILE
from physics.simulation import SINGLE_ROBOT
from physics.world import WORLDS_DIR
from ros_nodes.robot_description import robot_json
from ros_nodes.sim_clock import MAX_SPEED, MIN_SPEED, SPEED_MAX, SimClock
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.clock import WALL_CLOCK, Clock, WallClock
from websim import compare_command, compare_real, fit_command, grade_command, map_command, sites
from websim import replay as replay_command
from websim import serve as serve_command

DEFAULT_WORLD = str(WORLDS_DIR / "empty.yaml")


def installed_version() -> str:
    """Websim's version, as installed (a wheel, or an editable install of a checkout)."""
    try:
        return importlib.metadata.version("websim")
    except importlib.metadata.PackageNotFoundError:
        return "(not installed: run from a checkout without pip install)"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``websim`` and its subcommands."""
    parser = argparse.ArgumentParser(
        prog="websim", description="Browser-based 2D differential-drive robot simulator.")
    parser.add_argument("--version", action="version", version=f"websim {installed_version()}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = commands.add_parser(
        "demo", help="drive the robot headless and print odometry (no server)",
        description="Drive a circle headless, faster than real time, printing odometry.")
    _add_sim_arguments(demo)
    demo.add_argument("--speed", type=parse_speed, default=SPEED_MAX, metavar="X|max",
                      help=f"times real time ({MIN_SPEED:g} to {MAX_SPEED:g}), or max: as fast "
                           "as the host allows (default max)")
    demo.add_argument("--seconds", type=float, default=5.0, help="simulated time (default 5)")
    demo.add_argument("--linear", type=float, default=0.3, help="linear.x in m/s (default 0.3)")
    demo.add_argument("--angular", type=float, default=0.5,
                      help="angular.z in rad/s (default 0.5)")
    demo.set_defaults(run=_run_demo)

    serve = commands.add_parser(
        "serve", help="run the simulator in real time behind rosbridge, with the web pages",
        description="Run the simulator in real time, speak the rosbridge v2 protocol on the "
                    "WebSocket port and serve the web interface on the HTTP port.")
    _add_sim_arguments(serve)
    serve.add_argument("--speed", type=parse_speed, default=None, metavar="X|max",
                       help="run on sim time at X times real time "
                            f"({MIN_SPEED:g} to {MAX_SPEED:g}), or max: as fast as the host "
                            "and the clients allow; stamps and /clock are then sim time, "
                            "starting at the wall time of the start (default: real time, "
                            "stamped with the wall clock)")
    serve_command.add_arguments(serve)
    serve.set_defaults(run=_run_serve)

    replay = commands.add_parser(
        "replay", help="play a recording (websim serve --record) back to the page",
        description="Serve a recording's topics on the rosbridge WebSocket as they were "
                    "recorded (or --speed times faster) and the robot's page, which shows "
                    "them: view and plots, no ROS install needed.")
    replay_command.add_arguments(replay)
    replay.set_defaults(run=_run_replay)

    compare = commands.add_parser(
        "compare", help="run a command file (or a real robot's recorded commands, --real) in "
                        "kinematic and dynamic mode and compare them",
        description="Drive a command file headless through both motion models with the same "
                    "seed; write trajectory.csv, summary.json and comparison.png to --out. "
                    "With --real RECORDING, replay a real robot's recorded commands and "
                    "measure both models against its trajectory (docs/validation.md).")
    _add_sim_arguments(compare, mode=False)
    compare_command.add_arguments(compare)
    compare_real.add_recording_arguments(compare)
    compare.set_defaults(run=_run_compare)

    fit = commands.add_parser(
        "fit", help="fit the robot's lag, speed scales and acceleration limits to a real "
                    "robot's recording; write a parameter file",
        description="Estimate the robot driver's command lag, linear and angular scale and "
                    "acceleration limits from a real robot's recording (fitted on its first "
                    "part, checked on the rest) and write a parameter file for websim serve "
                    "--params, compare and grade (docs/validation.md).")
    fit_command.add_arguments(fit)
    compare_real.add_recording_arguments(fit)
    fit.set_defaults(run=fit_command.run)

    proxy = commands.add_parser(
        "nginx-config", help="print an nginx.conf routing a class's robots to its workers "
                             "(and each worker's instructor view at /workers/K/)",
        description="Print an nginx configuration that routes /robots/NAME (pages and "
                    "WebSockets) to 'websim serve --class ROSTER --worker' processes with "
                    "hash $robot consistent: the same name always reaches the same worker.")
    nginx_config.add_arguments(proxy)
    proxy.set_defaults(run=nginx_config.run)

    grade = commands.add_parser(
        "grade", usage="websim grade SCENARIO_OR_SUITE [options] -- COMMAND...",
        help="grade a controller on a scenario or suite: a private simulator, a sandbox, a "
             "recording, a score (docs/grading.md)",
        description="Run the controller COMMAND (given after --) against a private simulator "
                    "set up by each scenario, in a sandbox, record the run and score it from "
                    "the recording's ground truth; report.json per run.")
    grade_command.add_arguments(grade)
    grade.set_defaults(run=grade_command.run)

    map_files = commands.add_parser(
        "map", help="write a world's occupancy map as nav2 map_server's NAME.yaml and NAME.pgm",
        description="Rasterise a world into the occupancy grid /map carries and write it as "
                    "the map_server pair NAME.yaml and NAME.pgm (NAME: the world file's name), "
                    "for map_server, AMCL or slam_toolbox on a real ROS 2 install.")
    map_command.add_arguments(map_files)
    map_files.set_defaults(run=map_command.run)

    token = commands.add_parser(
        "token", help="print a random token for --admin-token, or a roster with a token each",
        description="Print a random token of the kind --admin-token and a roster's token "
                    "field accept (192 bits, URL-safe, a mix of kinds of characters); with "
                    "--roster, a roster line NAME,,TOKEN for each name (a class spread over "
                    "workers gives its robots' tokens in the roster: every worker then agrees "
                    "on them).")
    token.add_argument("--roster", nargs="+", metavar="NAME", default=None,
                       help="robot names: print NAME,,TOKEN for each (a roster file)")
    token.set_defaults(run=_run_token)

    describe = commands.add_parser(
        "robot-json", help="print the robot.json the web page reads (limits, topics, params)",
        description="Print the robot description the web page reads: speed limits, footprint, "
                    "topic names and types, services and the parameter table. websim serve "
                    "serves it live; web-interface/robot.json is this output for the shipped "
                    "parameters (the Docker stack's nginx serves that file).")
    describe.add_argument("--params", default=str(SHIPPED_PARAMS_FILE),
                          help="robot parameter file (default: config/pi4b_params.yaml)")
    describe.set_defaults(run=_run_robot_json)
    return parser


def _add_sim_arguments(parser: argparse.ArgumentParser, *, mode: bool = True) -> None:
    parser.add_argument("--world", default=DEFAULT_WORLD,
                        help="world file, or a shipped world's name (default: empty)")
    if mode:
        parser.add_argument("--mode", choices=MODES, default="kinematic",
                            help="motion model (default: kinematic)")
    parser.add_argument("--params", default=str(SHIPPED_PARAMS_FILE),
                        help="robot parameter file (default: config/pi4b_params.yaml)")
    parser.add_argument("--seed", type=int, default=0, help="random seed for noise (default 0)")


def make_simulation(args: argparse.Namespace, name: str = SINGLE_ROBOT) -> Simulation:
    """Build the simulation the common arguments describe, its robot named ``name``.

    The world's ``noise`` section, if any, overrides the parameter file's sigmas.
    """
    platform = load_params(args.params)
    world = load_world(args.world)
    return Simulation(world, platform.robot, mode=args.mode, seed=args.seed,
                      lidar=world.lidar_over(platform.lidar),
                      noise=world.noise_over(platform.noise), name=name)


def parse_speed(text: str) -> float:
    """``--speed``, an argparse type: times real time, or ``max`` (``SPEED_MAX``).

    A finite number from ``MIN_SPEED`` to ``MAX_SPEED``, or ``max``: as fast as the host
    allows; anything else (0, negative, nan, inf, a word, 1e9) is refused with the range.
    """
    allowed = f"a number of times real time from {MIN_SPEED:g} to {MAX_SPEED:g}, or 'max'"
    if text.strip().lower() == "max":
        return SPEED_MAX
    try:
        speed = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {allowed}, got '{text}'") from None
    if not math.isfinite(speed):
        raise argparse.ArgumentTypeError(f"expected {allowed}, got '{text}' (as fast as the "
                                         "host allows is 'max')")
    if not MIN_SPEED <= speed <= MAX_SPEED:
        hint = " (as fast as the host allows is 'max')" if speed > MAX_SPEED else ""
        raise argparse.ArgumentTypeError(f"expected {allowed}, got '{text}'{hint}")
    return speed


def make_clock(speed: float | None, epoch_s: float | None = None) -> Clock:
    """A robot's clock: wall time (no ``--speed``), else sim time at ``speed``.

    Sim time starts at ``epoch_s`` (default: the wall time now) and follows its world's ticks.
    """
    return WallClock() if speed is None else SimClock(TICK_PERIOD_S, speed, epoch_s)


def _run_demo(args: argparse.Namespace) -> int:
    sim = make_simulation(args)
    sim.command(args.linear, args.angular)
    print("t_s     odom_x_m  odom_y_m  odom_theta_rad  v_mps   omega_rps", flush=True)
    ticks_per_print = max(1, round(0.5 / sim.dt_s))
    wall_period_s = sim.dt_s / args.speed  # 0 at max: no waiting
    started_s = WALL_CLOCK.monotonic_s()
    for tick in range(max(1, round(args.seconds / sim.dt_s))):
        delay_s = started_s + tick * wall_period_s - WALL_CLOCK.monotonic_s()
        if delay_s > 0:
            time.sleep(delay_s)
        sim.step()
        if sim.tick % ticks_per_print == 0:
            odom = sim.odometry()
            print(f"{sim.time_s:6.2f}  {odom.x:8.4f}  {odom.y:8.4f}  {odom.theta:14.4f}  "
                  f"{odom.v:6.3f}  {odom.omega:9.3f}", flush=True)
    return 0


def _run_compare(args: argparse.Namespace) -> int:
    if args.real is None:
        return compare_command.run(args)
    given = [flag for flag, value in (("--world", args.world != DEFAULT_WORLD),
                                      ("--controller", args.controller is not None))
             if value]
    if given:
        raise ConfigError(f"{given[0]} is for --commands: --real replays the recording's own "
                          "commands on an open floor")
    return compare_real.run(args)


def _run_token(args: argparse.Namespace) -> int:
    if args.roster is None:
        print(strong_token())
        return 0
    names = [check_name(name, "--roster") for name in args.roster]
    if len(set(names)) != len(names):
        repeated = sorted({name for name in names if names.count(name) > 1})
        raise ConfigError(f"--roster: {', '.join(repeated)} named twice")
    for name in names:
        print(f"{name},,{strong_token()}")
    return 0


def _run_robot_json(args: argparse.Namespace) -> int:
    platform = load_params(args.params)
    sys.stdout.write(robot_json(platform.robot, platform.lidar))
    return 0


def _run_serve(args: argparse.Namespace) -> int:
    weakness = None if args.admin_token is None else weak_token(args.admin_token)
    if weakness is not None:
        raise ConfigError(f"--admin-token is too weak: {weakness} (leave it out for a random "
                          "one, printed at start)")
    if getattr(args, "links", None) and (args.public_ws_port is None) != \
            (args.public_http_port is None):
        raise ConfigError("--links behind a proxy needs both --public-http-port and "
                          "--public-ws-port (the proxy's ports): with one, the links would mix "
                          "this process's port with the proxy's")
    limits, origins = serve_command.limits_from(args), serve_command.origins_from(args)
    clock = make_clock(args.speed)  # the server's: the single robot's, a class's intervals
    recorder = serve_command.recorder_from(args)
    if args.arena and args.class_spec is None:
        raise ConfigError("--arena puts a class's robots in one world: it needs --class")
    if args.student_spawn and not args.arena:
        raise ConfigError("--student-spawn is for an arena: it needs --class and --arena")
    if not 0 <= args.student_spawn <= MAX_STUDENT_SPAWN:
        raise ConfigError(f"--student-spawn: from 0 to {MAX_STUDENT_SPAWN}, got "
                          f"{args.student_spawn}")
    if args.class_spec is None:
        token = args.admin_token or strong_token()
        robot = VirtualRobot(make_simulation(args), clock, localization=args.localization)
        site = sites.single_robot(robot, token, limits, origins,
                                  args.public_ws_port or args.ws_port, recorder)
        return serve_command.run(args, site, token)
    make_robot = arena_robots(args, clock) if args.arena else class_robots(args, clock)

    platform = load_params(args.params)
    site = sites.classroom_site(args, make_robot, (platform.robot, platform.lidar),
                                args.admin_token, limits, origins, clock, recorder)
    return serve_command.run(args, site, site.admin_token)  # given, kept, or new


MAX_STUDENT_SPAWN = 20
"""Most robots one student may have spawned into an arena at once (``--student-spawn``)."""


def class_robots(args: argparse.Namespace, clock: Clock) -> Callable[[Student], VirtualRobot]:
    """``--class``: each student's robot in a world of its own (the roster's, or ``--world``).

    On sim time each world keeps its own time and pace (all from the server's start), but a
    class on the ROS graph has one ``/clock``: one clock, one pace for all.
    """
    epoch_s = clock.stamp_s()

    def robot_clock() -> Clock:
        return clock if args.speed is None or args.ros else make_clock(args.speed, epoch_s)

    def make_robot(student: Student) -> VirtualRobot:
        world = args.world if student.world is None else student.world
        return VirtualRobot(make_simulation(argparse.Namespace(**{**vars(args),
                                                                 "world": world}),
                                            student.name),
                            robot_clock(), localization=args.localization)

    return make_robot


def arena_robots(args: argparse.Namespace, clock: Clock) -> Callable[[Student], VirtualRobot]:
    """``--class --arena``: every student's robot spawned into the one ``--world``.

    A robot the world places (its ``robots`` list) starts where it says, with its parameters
    over the parameter file's; the others at the nearest free place to the world's start.
    Each robot's noise streams come from ``--seed`` and its name: the same seed, the same run.

    Raises:
        ConfigError: with ``--worker`` (one world cannot be split over processes).
    """
    if getattr(args, "worker", False):
        raise ConfigError("--arena puts every robot in one world: it cannot be split over "
                          "--worker processes")
    platform = load_params(args.params)
    world = load_world(args.world)
    arena = WorldSim(world, seed=args.seed, lidar=world.lidar_over(platform.lidar),
                     noise=world.noise_over(platform.noise))

    def make_robot(student: Student) -> VirtualRobot:
        if student.world is not None and student.world != args.world:
            raise ConfigError(f"robot '{student.name}': the roster gives it the world "
                              f"'{student.world}', but --arena puts every robot in --world")
        placed = world.placed(student.name)
        start = student.start or (None if placed is None else placed.start)
        arena.spawn(student.name, start,
                    platform.robot if placed is None else placed.params_over(platform.robot),
                    mode=args.mode)
        return VirtualRobot(Simulation.of(arena, student.name), clock,
                            localization=args.localization)

    return make_robot


def _run_replay(args: argparse.Namespace) -> int:
    recording = replay_command.Recording(args.recording)
    serve_args = build_parser().parse_args(["serve"])  # every other option at its default
    for name in ("host", "ws_port", "http_port", "log_level"):
        setattr(serve_args, name, getattr(args, name))
    token = strong_token()
    site = replay_command.replay_site(recording, args.speed, args.loop, token,
                                      serve_command.origins_from(serve_args), args.ws_port)
    try:
        return serve_command.run(serve_args, site, token)
    finally:
        recording.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``websim`` with ``argv`` (default: the process arguments); returns the exit code."""
    parser = build_parser()
    arguments = list(sys.argv[1:] if argv is None else argv)
    tail: list[str] | None = None
    if "--" in arguments:  # websim grade ... -- COMMAND: the controller's, never parsed
        split = arguments.index("--")
        arguments, tail = arguments[:split], arguments[split + 1:]
    args = parser.parse_args(arguments)
    if tail is not None:
        if not hasattr(args, "controller"):
            parser.error("'-- COMMAND' is for websim grade only")
        args.controller = tail
    if args.command is None:
        parser.print_help()
        return 0
    try:
        # WEBSIM_RAYCAST checked before anything runs: a grader's simulators would otherwise
        # each fail on it, and every submission would score 0
        raycast_kernel.kernel()
        return int(args.run(args))
    except ConfigError as error:
        print(f"websim: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
