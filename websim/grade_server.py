"""The private simulator of one graded run: ``websim serve`` set up by a scenario, in lock step.

``websim grade`` starts it (in the submission's sandbox, the controller in its network
namespace) as ``python -m websim.grade_server SUITE --scenario NAME --out DIR ...``. It is
``websim serve`` with one robot, built from the scenario (world, start, mode, payload, seed),
recording to ``DIR/recording`` (``--record``), with five things of its own:

- **the scenario's clock**: nothing ticks until the controller subscribes to its trigger
  topic (``/odom``, or what ``--step-on`` names), at most ``STARTUP_TIMEOUT_S``; then the
  run lasts ``duration_s`` of sim time, or until the robot comes within the scenario's
  ``end``, and the server stops itself;
- **its timed changes** (payload, mode) at the first tick at or after their time;
- **lock step** (``--mode deterministic``): on sim time at ``--speed max``, and after each
  tick at which the controller is due (``LockStep``) the next tick waits for its /cmd_vel,
  so the run depends only on the controller's answers and the seed; in ``wall-clock`` mode
  it runs at 1x and waits for nobody;
- **the ROS graph** (``--ros``, for an rclpy controller): ``websim serve --ros``'s nodes in
  this process (``websim.ros_runtime``); the controller's subscription to the trigger topic
  on the graph starts the run as a rosbridge client's does (``graph_subscribed``: once the
  robot's publisher has matched it, so the first message reaches it), and its
  /cmd_vel from the graph answers the lock step as a rosbridge client's does (the robot's
  tap sees both);
- **no changes from the controller**: ``/reset_simulation`` is refused; parameters and pause
  need the admin token, which only this process knows (the controller's environment does not
  hold it).

How it ended goes to ``DIR/run.json`` (``RunEnd``), which the grader reads with the bag.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json
import math
import os
import signal
import sys
from collections.abc import Callable, Collection, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from classroom.registry import strong_token
from grading import Scenario, load_suite
from grading.recorded import TRUTH_FILE, TruthLog
from physics import TICK_PERIOD_S, ConfigError, Simulation
from physics.params import NoiseParams
from ros_nodes.recording import Recorder
from ros_nodes.robot_interface import RESET_SERVICE
from ros_nodes.tap import IN, OUT
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.clock import MAX_SPEED, SPEED_MAX, SimClock
from rosbridge.core.limits import ClientLimits, OriginPolicy
from rosbridge.msgs.values import Message
from websim import serve as serve_command
from websim import sites

MODES = ("deterministic", "wall-clock")
"""How a graded run keeps time: in lock step with the controller on sim time, or at 1x."""

STEP_ON = {"odom": "/odom", "scan": "/scan", "rate": "/clock"}
"""``--step-on``: what the controller answers (deterministic mode waits for its command after
each): every ``/odom`` (20 Hz), every ``/scan`` (10 Hz), or the scenario's
``controller_rate_hz`` on ``/clock`` (a timer on sim time)."""

STARTUP_TIMEOUT_S = 60.0
"""How long (wall time) the controller may take to connect and subscribe before the run
starts; beyond it the run ends unstarted (an interpreter's start on a loaded machine takes a
few seconds)."""

STEP_TIMEOUT_S = 5.0
"""Deterministic mode: how long (wall time) a tick waits for the controller's command."""

MAX_MISSED_STEPS = 3
"""Deterministic mode: after this many commands not given in time the run ends: the controller
does not answer each observation, so the run could not be repeated exactly."""

RUN_FILE = "run.json"
RECORDING_DIR = "recording"

RECORDING_MAX_BYTES = 64 * 1024 * 1024
"""A graded run's bag is closed (complete) at this size: what a client publishes into it is
bounded per run (a 120 s run of the robot's own topics is a few MB); the score does not read
it (``grading.recorded.TruthLog``)."""

GRAPH_READ_ONLY = "a graded run's robot cannot be changed or reset (websim grade)"
"""``--ros``: why the robot's parameters and ``/reset_simulation`` on the graph are refused."""


@dataclass
class RunEnd:
    """How a graded run ended (``run.json``).

    Attributes:
        ended_by: ``duration`` (it ran its whole length), ``end_point`` (the robot reached
            the scenario's end), ``no_start`` (the controller never subscribed), ``no_answer``
            (deterministic: it stopped answering), or ``stopped`` (the grader stopped it,
            before its end: the controller had exited).
        reason: one line for the report.
        sim_time_s: sim time reached (s).
        ticks: ticks run.
        epoch_s: the stamp of sim time 0 (s): a message's time in the run is its stamp
            minus this.
        mode: ``deterministic`` or ``wall-clock``.
        step_on: what the controller was stepped on (deterministic).
        commands: /cmd_vel messages the robot accepted.
        steps_waited: ticks that waited for the controller's command (deterministic).
        missed_steps: of which it did not answer within ``STEP_TIMEOUT_S``.
        first_miss_s: sim time of the first missed step, or None.
    """

    ended_by: str
    reason: str
    sim_time_s: float
    ticks: int
    epoch_s: float
    mode: str
    step_on: str
    commands: int
    steps_waited: int
    missed_steps: int
    first_miss_s: float | None


GRAPH_TOPICS = ("/odom", "/scan", "/clock")
"""The trigger topics a controller on the graph may subscribe to (``STEP_ON``); one
subscribed is, in wall-clock mode, the controller being there (an rclpy node on sim time
subscribes ``/clock`` at its start)."""


class LockStep:
    """The run's pace and end: the schedule's gate and tick listener, the robot's tap.

    Before the first tick it waits for the controller to subscribe to the trigger topic (in
    wall-clock mode: to connect), at most ``startup_timeout_s``. Each
    time the robot publishes that topic (every ``every``-th time, for ``rate``) the controller
    is due; in deterministic mode the next tick waits until a /cmd_vel arrives after it, at
    most ``STEP_TIMEOUT_S``. Every tick it applies the scenario's timed changes and checks
    whether the run is over.
    """

    def __init__(self, scenario: Scenario, robot: VirtualRobot, clock: SimClock,
                 subscribed: Callable[[], Collection[str]], connected: Callable[[], bool], *,
                 mode: str, step_on: str, out: Path,
                 startup_timeout_s: float = STARTUP_TIMEOUT_S) -> None:
        self.scenario, self.robot, self.clock = scenario, robot, clock
        self.subscribed, self.connected = subscribed, connected
        self.startup_timeout_s = startup_timeout_s
        self.deterministic = mode == "deterministic"
        self.mode, self.step_on = mode, step_on
        self.trigger = STEP_ON[step_on]
        self.every = scenario.controller_period_ticks if step_on == "rate" else 1
        self.out = out
        self.epoch_s = clock.stamp_s()
        self.ticks_total = math.floor(scenario.duration_s / TICK_PERIOD_S + 1e-9)
        self.pending = list(scenario.changes)
        self.started = False
        self.finished: RunEnd | None = None
        self.awaiting = False
        self.answered = asyncio.Event()
        self.triggers = self.commands = self.steps_waited = self.missed = 0
        self.first_miss_s: float | None = None
        robot.tap.add(self.on_message)

    @property
    def sim_time_s(self) -> float:
        """Sim time since the start (s)."""
        return self.clock.ticks * TICK_PERIOD_S

    def on_message(self, direction: str, topic: str, type_name: str, msg: Message,
                   sim_time_s: float) -> None:
        """The tap: the controller is due after its trigger; its /cmd_vel answers."""
        if direction == OUT and topic == self.trigger:
            if self.triggers % self.every == 0:
                self.awaiting = True
                self.answered.clear()
            self.triggers += 1
        elif direction == IN and topic == "/cmd_vel":
            self.commands += 1
            if self.awaiting:
                self.awaiting = False
                self.answered.set()

    async def gate(self) -> None:
        """Hold the next tick: until the start, for the controller's command, or for good.

        For good once the run is over (the server is stopping).
        """
        if self.finished is not None:
            await asyncio.Event().wait()
        if not self.started:
            await self._wait_for_start()
            return
        if not (self.deterministic and self.awaiting):
            return
        self.steps_waited += 1
        try:
            await asyncio.wait_for(self.answered.wait(), STEP_TIMEOUT_S)
        except asyncio.TimeoutError:
            self.awaiting = False
            self.missed += 1
            if self.first_miss_s is None:
                self.first_miss_s = self.sim_time_s
            if self.missed >= MAX_MISSED_STEPS:
                self.finish("no_answer", (
                    f"the controller did not answer {self.trigger} within {STEP_TIMEOUT_S:g} s "
                    f"{self.missed} times (first at t = {self.first_miss_s:.2f} s of sim time): "
                    f"deterministic mode needs a /cmd_vel after each {self.trigger}"
                    + (f" (every {self.every} ticks)" if self.every > 1 else "")
                    + "; grade it with --mode wall-clock, or --step-on scan|rate if it answers "
                      "those"))
                await asyncio.Event().wait()

    async def _wait_for_start(self) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.startup_timeout_s
        wanted = f"subscribe to {self.trigger}" if self.deterministic else "connect"
        while not (self.trigger in self.subscribed() if self.deterministic
                   else self.connected()):
            if loop.time() >= deadline:
                self.finish("no_start", f"the controller did not {wanted} within "
                                        f"{self.startup_timeout_s:g} s: the run never started")
                await asyncio.Event().wait()
            await asyncio.sleep(0.01)
        self.started = True

    def after_tick(self) -> None:
        """The schedule's tick listener: the timed changes due, and the run's end."""
        now_s = self.sim_time_s
        sim = self.robot.sim
        while self.pending and self.pending[0].at_s <= now_s + 1e-9:
            change = self.pending.pop(0)
            if change.payload is not None:
                sim.set_payload(change.payload.mass_kg, change.payload.inertia_kg_m2)
            if change.mode is not None:
                sim.mode = change.mode
        if self.finished is not None:
            return
        end = self.scenario.end
        pose = sim.ground_truth()
        if end is not None and math.hypot(pose.x - end.x_m, pose.y - end.y_m) <= end.radius_m:
            self.finish("end_point", f"reached the end point at t = {now_s:.2f} s")
        elif self.clock.ticks >= self.ticks_total:
            self.finish("duration", f"ran its {self.scenario.duration_s:g} s")

    def finish(self, ended_by: str, reason: str) -> None:
        """Write ``run.json`` and stop the server (SIGTERM: the bag is closed properly)."""
        if self.finished is not None:
            return
        self.finished = self.run_end(ended_by, reason)
        self.write()
        os.kill(os.getpid(), signal.SIGTERM)

    def run_end(self, ended_by: str, reason: str) -> RunEnd:
        """How the run ended, as it stands."""
        return RunEnd(ended_by, reason, round(self.sim_time_s, 6), self.clock.ticks,
                      self.epoch_s, self.mode, self.step_on, self.commands,
                      self.steps_waited, self.missed, self.first_miss_s)

    def write(self) -> None:
        """Write ``run.json`` (atomically)."""
        end = self.finished or self.run_end("stopped", "stopped by the grader before its end")
        temporary = self.out / f".{RUN_FILE}.tmp"
        temporary.write_text(json.dumps(asdict(end), indent=2))
        temporary.replace(self.out / RUN_FILE)


def build_parser() -> argparse.ArgumentParser:
    """The arguments ``websim grade`` gives this server."""
    parser = argparse.ArgumentParser(prog="python -m websim.grade_server",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("suite", help="the scenario or suite file")
    parser.add_argument("--scenario", default=None, help="the suite's scenario to run")
    parser.add_argument("--out", type=Path, required=True, help="run.json and recording/")
    parser.add_argument("--mode", choices=MODES, default="deterministic")
    parser.add_argument("--step-on", choices=tuple(STEP_ON), default="odom")
    parser.add_argument("--startup-timeout", type=float, default=STARTUP_TIMEOUT_S)
    parser.add_argument("--ros", action="store_true",
                        help="start the ROS graph (websim serve --ros): an rclpy controller")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--ws-port", type=int, default=9090)
    parser.add_argument("--http-port", type=int, default=8080)
    return parser


def pick_scenario(suite_file: str, name: str | None) -> Scenario:
    """The scenario ``name`` of a suite file (its only one when None)."""
    suite = load_suite(suite_file)
    for entry in suite.entries:
        if name is None or entry.scenario.name == name:
            return entry.scenario
    known = ", ".join(entry.scenario.name for entry in suite.entries)
    raise ConfigError(f"{suite_file}: no scenario named '{name}' (it has: {known})")


def main(argv: Sequence[str] | None = None) -> int:
    """Run one graded run's simulator until the run ends; 0 when it ran."""
    args = build_parser().parse_args(argv)
    try:
        scenario = pick_scenario(args.suite, args.scenario)
    except ConfigError as error:
        print(f"websim grade server: error: {error}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    speed = SPEED_MAX if args.mode == "deterministic" else 1.0
    clock = SimClock(TICK_PERIOD_S, speed)
    simulation = Simulation(scenario.world, scenario.robot, mode=scenario.mode,
                            seed=scenario.seed,
                            noise=scenario.world.noise_over(NoiseParams()))
    robot = VirtualRobot(simulation, clock)
    token = strong_token()
    serve_args = serve_command_arguments(args)
    recorder = Recorder(args.out / RECORDING_DIR, max_bytes=RECORDING_MAX_BYTES)
    site = sites.single_robot(robot, token, grade_limits(args.mode), OriginPolicy.default(
        args.host, args.http_port, []), args.ws_port, recorder=recorder)
    site.graph_read_only = GRAPH_READ_ONLY
    host = site.front.host  # type: ignore[attr-defined]
    host.bridge.services.add(RESET_SERVICE, "std_srvs/srv/Empty", _refuse_reset)

    def subscribed() -> Collection[str]:
        return {*host.bridge.topics.subscribed_topics(), *graph_subscribed(site)}

    def connected() -> bool:
        return bool(host.bridge.sessions) or bool(graph_subscribed(site))

    lock_step = LockStep(scenario, robot, clock, subscribed, connected, mode=args.mode,
                         step_on=args.step_on, out=args.out,
                         startup_timeout_s=args.startup_timeout)
    truth = TruthLog(simulation, lambda: lock_step.sim_time_s, args.out / TRUTH_FILE,
                     lambda: lock_step.finished is not None)
    schedule = site.schedule()
    schedule.gates.append(lock_step.gate)
    schedule.tick_listeners.append(lock_step.after_tick)
    schedule.tick_listeners.append(truth.after_tick)
    try:
        return serve_command.run(serve_args, site, token)
    finally:
        if lock_step.finished is None:
            lock_step.write()
        truth.write(recording=[recording.health() for recording in recorder.recordings])


def graph_subscribed(site: sites.Site) -> set[str]:
    """Those of ``GRAPH_TOPICS`` the robot's node (``--ros``) has matched a subscriber for.

    None without ``--ros``, or before the graph has started.
    """
    ros = site.ros
    if ros is None:
        return set()
    return {topic for topic in GRAPH_TOPICS if ros.robot_node.subscription_count(topic) > 0}


def grade_limits(mode: str) -> ClientLimits:
    """The clients' bounds: ``websim serve``'s, but in deterministic mode its rates.

    The rate budgets are per second of wall time, and a deterministic run goes as fast as
    the controller answers: one /cmd_vel per 0.05 s tick at 10x real time is 200 messages a
    second, ``DEFAULT_MAX_RATE``. There the lock step is the bound (the controller sends its
    command and the next tick waits for it), so the rates are raised by ``MAX_SPEED``.
    """
    limits = ClientLimits()
    if mode != "deterministic":
        return limits
    return dataclasses.replace(
        limits, max_rate=limits.max_rate * MAX_SPEED,
        address_max_rate=limits.address_max_rate * MAX_SPEED,
        handling_share=1.0, address_handling_share=1.0, robot_handling_share=1.0)


def _refuse_reset(args: Any, session: Any) -> Any:
    raise ConfigError(f"{RESET_SERVICE}: a graded run cannot be reset (websim grade)")


def serve_command_arguments(args: argparse.Namespace) -> argparse.Namespace:
    """``websim serve``'s arguments for this server (its defaults, these ports)."""
    parser = argparse.ArgumentParser()
    serve_command.add_arguments(parser)
    return parser.parse_args(["--host", args.host, "--ws-port", str(args.ws_port),
                              "--http-port", str(args.http_port), "--log-level", "error",
                              *(["--ros"] if args.ros else [])])


if __name__ == "__main__":
    sys.exit(main())
