"""The private simulator of one graded run: ``websim serve`` set up by a scenario, in lock step.

``websim grade`` starts it (in the submission's sandbox, the controller in its network
namespace) as ``python -m websim.grade_server SUITE --scenario NAME --out DIR ...``. It is
``websim serve`` with one robot, built from the scenario (world, start, mode, payload, seed),
recording to ``DIR/recording`` (``--record``), with five things of its own:

- **the scenario's clock**: sim time from 0 (``/clock`` starts at 0, as Gazebo's does);
  nothing ticks until the controller is ready (``LockStep``: subscribed to what it is stepped
  on, ``--step-on auto`` by default), at most ``STARTUP_TIMEOUT_S``; then the run lasts
  ``duration_s`` of sim time, or until the robot comes within the scenario's ``end``, and
  the server stops itself;
- **its timed changes** (payload, mode) at the first tick at or after their time, and its
  LiDAR (``Scenario.lidar``: the scan's angles a world or a scenario sets);
- **lock step** (``--mode deterministic``): on sim time at ``--speed max``, and after each
  tick the next waits for the controller (``LockStep``): for its /cmd_vel after each message
  of what it answers (rosbridge), or until its node's executor has handled each of the
  tick's messages (``--ros``: ``websim.grade_graph``), so the run depends only on the
  controller's answers and the seed; in ``wall-clock`` mode it runs at 1x and waits for
  nobody;
- **the ROS graph** (``--ros``, for an rclpy controller): ``websim serve --ros``'s nodes in
  this process (``websim.ros_runtime``), ``/scan`` offered reliable
  (``GRADE_NODE_PARAMETERS``); the controller's node spinning with its subscriptions matched
  starts the run, its /cmd_vel from the graph reaches the robot's tap as a rosbridge
  client's does, and a subscription the robot cannot serve is named (incompatible QoS);
- **no changes from the controller**: ``/reset_simulation`` is refused; parameters and pause
  need the admin token, which only this process knows (the controller's environment does not
  hold it); the simulation services (``simulation_interfaces`` and turtlesim's teleports,
  resets, pause and steps) are not offered.

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
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from classroom.registry import strong_token
from grading import Scenario, load_suite
from grading.recorded import TRUTH_FILE, TruthLog
from physics import TICK_PERIOD_S, ConfigError, RobotParams, Simulation, load_params
from physics.params import NoiseParams
from ros_nodes.recording import Recorder
from ros_nodes.robot_interface import CLOCK, PUBLISHED_TOPICS, RESET_SERVICE, SCAN
from ros_nodes.sim_clock import MAX_SPEED, SPEED_MAX, SimClock
from ros_nodes.tap import IN, OUT
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.limits import ClientLimits, OriginPolicy
from rosbridge.msgs.values import Message
from websim import serve as serve_command
from websim import sites

MODES = ("deterministic", "wall-clock")
"""How a graded run keeps time: in lock step with the controller on sim time, or at 1x."""

STEP_ON: dict[str, str | None] = {"auto": None, "odom": "/odom", "scan": "/scan",
                                  "rate": "/clock"}
"""``--step-on``: when deterministic mode waits for the controller. ``auto`` (the default):
an rclpy controller (``--ros``) every tick, until its executor has handled the tick
(``websim.grade_graph``: a timer node answers when its timer says); a rosbridge controller
after each message of what it subscribes to (``AUTO_TOPICS``: every tick for ``/odom`` and
its kind, every ``/scan``, or ``controller_rate_hz`` of ``/clock``). Or by hand: after each
``/odom`` (20 Hz), each ``/scan`` (10 Hz), or the scenario's ``controller_rate_hz`` on
``/clock``, waiting for a ``/cmd_vel`` after each."""

TICK_TOPICS = tuple(spec.name for spec in PUBLISHED_TOPICS
                    if spec.every_ticks == 1 and spec is not CLOCK)
"""The robot's topics published at every tick (``/odom``, ``/tf``, ``/ground_truth``...):
a controller that answers one of them answers at every tick, as one on ``/odom`` does."""

AUTO_TOPICS = (*TICK_TOPICS, SCAN.name, CLOCK.name)
"""What ``--step-on auto`` looks for among a rosbridge controller's subscriptions."""

STARTUP_TIMEOUT_S = 60.0
"""How long (wall time) the controller may take to connect and subscribe before the run
starts; beyond it the run ends unstarted (an interpreter's start on a loaded machine takes a
few seconds)."""

SETTLE_S = 0.25
"""``--step-on auto``: once a rosbridge controller subscribed to a topic it may step on, the
run starts when its subscriptions have not changed for this long (wall time, s): roslibpy and
roslibjs send a controller's subscriptions one after the other, within milliseconds."""

STEP_TIMEOUT_S = 5.0
"""Deterministic mode: how long (wall time) a tick waits for the controller's command."""

MAX_MISSED_STEPS = 3
"""Deterministic mode: after this many commands not given in time the run ends: the controller
does not answer each observation, so the run could not be repeated exactly."""

PROBE_AT_STEP = 20
"""Deterministic mode: at this step (one second of sim time at 20 Hz) the next tick is held
for ``PROBE_S`` of wall time, while the controller is sent nothing new."""

PROBE_S = 0.3
"""How long the probe holds the run (wall time, s)."""

WALL_PACED_COMMANDS = 2
"""Commands a controller publishes during the probe, having been sent nothing new, that show
it is paced by the wall clock (a ``time.sleep`` loop, a steady timer), not by what it is sent:
a controller tied to its messages publishes nothing then, or its one late second answer."""

RUN_FILE = "run.json"
RECORDING_DIR = "recording"

GRADE_NODE_PARAMETERS = {"scan_reliability": "reliable"}
"""The robot node's parameters in a graded run (``--ros``): ``/scan`` reliable, which both a
best-effort subscriber (sensor data, as rplidar's examples) and a RELIABLE one (the Neato
driver's, many a course's) receive."""

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
            minus this (0: in a graded run ``/clock`` starts at 0, as Gazebo's does).
        mode: ``deterministic`` or ``wall-clock``.
        step_on: what deterministic mode waited for: ``odom``, ``scan``, ``rate`` (a
            ``/cmd_vel`` after each), or ``handshake`` (an rclpy controller's executor, every
            tick); in wall-clock mode, ``--step-on`` as given.
        commands: /cmd_vel messages the robot accepted.
        steps_waited: ticks that waited for the controller (deterministic).
        missed_steps: of which it did not answer within ``STEP_TIMEOUT_S``.
        first_miss_s: sim time of the first missed step, or None.
        subscribed: the robot's topics the controller subscribed to at the start.
        incompatible_qos: its subscriptions the robot could not serve, one line each.
        last_command_s: sim time of the tick at which the last /cmd_vel arrived, or None.
        probe_commands: commands published during the probe (deterministic; None if the
            run ended before it).
        wall_paced: those show a controller paced by the wall clock, not by what it is sent:
            deterministic mode cannot repeat its run (``--mode wall-clock``).
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
    subscribed: list[str] = field(default_factory=list)
    incompatible_qos: list[str] = field(default_factory=list)
    last_command_s: float | None = None
    probe_commands: int | None = None
    wall_paced: bool = False


GRAPH_TOPICS = ("/odom", "/scan", "/clock")
"""The trigger topics a controller on the graph may subscribe to (``STEP_ON``); one
subscribed is, in wall-clock mode, the controller being there (an rclpy node on sim time
subscribes ``/clock`` at its start)."""


class LockStep:
    """The run's pace and end: the schedule's gate and tick listener, the robot's tap.

    Before the first tick it waits for the controller (at most ``startup_timeout_s``): in
    wall-clock mode to connect; in deterministic mode to subscribe to its trigger topic, or
    with ``auto`` to settle its subscriptions (rosbridge) or to spin its node with every
    subscription matched (``graph``). Then, in deterministic mode, each tick waits before
    the next: with a trigger, for a /cmd_vel after each time the robot published it (every
    ``every``-th time, for ``rate``), at most ``STEP_TIMEOUT_S``; with a graph, for the
    controller's executor to have handled the tick (``ControllerGraph.deliver``). Once,
    at ``PROBE_AT_STEP``, it holds the run to see whether the controller publishes unasked.
    Every tick it applies the scenario's timed changes and checks whether the run is over.

    Args:
        graph: ``--ros`` with ``--step-on auto``: returns the controller's graph
            (``websim.grade_graph.ControllerGraph``) once the ROS graph runs, else None.
    """

    def __init__(self, scenario: Scenario, robot: VirtualRobot, clock: SimClock,
                 subscribed: Callable[[], Collection[str]], connected: Callable[[], bool], *,
                 mode: str, step_on: str, out: Path,
                 startup_timeout_s: float = STARTUP_TIMEOUT_S,
                 graph: Callable[[], Any] | None = None) -> None:
        self.scenario, self.robot, self.clock = scenario, robot, clock
        self.subscribed, self.connected = subscribed, connected
        self.startup_timeout_s = startup_timeout_s
        self.deterministic = mode == "deterministic"
        self.mode, self.step_on = mode, step_on
        self.trigger = STEP_ON[step_on]
        self.every = scenario.controller_period_ticks if step_on == "rate" else 1
        self.graph_factory = graph if self.deterministic and step_on == "auto" else None
        self.graph: Any = None
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
        self.subscribed_at_start: list[str] = []
        self.incompatible_qos: list[str] = []
        self.scan_fallback = False
        """auto: it subscribes /scan and a per-tick topic: stepped on every tick until it
        leaves a tick without /scan unanswered, then on /scan."""
        self.last_command_tick: int | None = None
        self.probe_commands: int | None = None
        self._tick_topics: set[str] = set()
        self._last_tick_topics: set[str] = set()
        robot.tap.add(self.on_message)

    @property
    def sim_time_s(self) -> float:
        """Sim time since the start (s)."""
        return self.clock.ticks * TICK_PERIOD_S

    @property
    def stepped_on(self) -> str:
        """What the run is stepped on, as ``run.json`` says it."""
        if self.graph is not None:
            return "handshake"
        names = {topic: name for name, topic in STEP_ON.items() if topic is not None}
        return names.get(self.trigger or "", self.step_on)

    def on_message(self, direction: str, topic: str, type_name: str, msg: Message,
                   sim_time_s: float) -> None:
        """The tap: the controller is due after its trigger; its /cmd_vel answers."""
        if direction == OUT:
            self._tick_topics.add(topic)
            if topic == self.trigger:
                if self.triggers % self.every == 0:
                    self.awaiting = True
                    self.answered.clear()
                self.triggers += 1
        elif direction == IN and topic == "/cmd_vel":
            self.commands += 1
            self.last_command_tick = self.clock.ticks
            if self.awaiting:
                self.awaiting = False
                self.answered.set()

    async def gate(self) -> None:
        """Hold the next tick: until the start, for the controller, or for good.

        For good once the run is over (the server is stopping).
        """
        if self.finished is not None:
            await asyncio.Event().wait()
        if not self.started:
            await self._wait_for_start()
            return
        if not self.deterministic:
            return
        if self.graph is not None:
            await self._wait_for_handshake()
        elif self.awaiting:
            await self._wait_for_answer()
        else:
            return
        if self.steps_waited == PROBE_AT_STEP and self.probe_commands is None:
            before = self.commands
            await asyncio.sleep(PROBE_S)
            self.probe_commands = self.commands - before

    async def _wait_for_answer(self) -> None:
        self.steps_waited += 1
        try:
            await asyncio.wait_for(self.answered.wait(), STEP_TIMEOUT_S)
        except asyncio.TimeoutError:
            self.awaiting = False
            if self.scan_fallback and SCAN.name not in self._last_tick_topics:
                # it left a tick without /scan unanswered: it answers /scan (not counted)
                self.trigger, self.scan_fallback = SCAN.name, False
                self.steps_waited -= 1
                return
            await self._missed(
                f"the controller did not answer {self.trigger} within {STEP_TIMEOUT_S:g} s",
                f"deterministic mode needs a /cmd_vel after each {self.trigger}"
                + (f" (every {self.every} ticks)" if self.every > 1 else "")
                + "; grade it with --mode wall-clock"
                + "".join(f", or --step-on {name} if it answers each {topic}"
                          for name, topic in STEP_ON.items()
                          if topic is not None and topic != self.trigger))

    async def _wait_for_handshake(self) -> None:
        self.steps_waited += 1
        if not await self.graph.deliver(STEP_TIMEOUT_S):
            await self._missed(
                f"the controller's node ({', '.join(self.graph.active)}) did not answer the "
                f"simulator's handshake within {STEP_TIMEOUT_S:g} s",
                "its executor stopped spinning (a callback that blocks: input(), "
                "time.sleep, a loop); grade it with --mode wall-clock if it paces itself")

    async def _missed(self, what: str, advice: str) -> None:
        self.missed += 1
        if self.first_miss_s is None:
            self.first_miss_s = self.sim_time_s
        if self.missed >= MAX_MISSED_STEPS:
            self.finish("no_answer", f"{what} {self.missed} times (first at t = "
                                     f"{self.first_miss_s:.2f} s of sim time): {advice}")
            await asyncio.Event().wait()

    async def _wait_for_start(self) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.startup_timeout_s
        if not self.deterministic:
            await self._until(self.connected, deadline, "connect")
        elif self.graph_factory is not None:
            await self._wait_for_graph(deadline)
        elif self.trigger is not None:
            trigger = self.trigger
            await self._until(lambda: trigger in self.subscribed(), deadline,
                              f"subscribe to {trigger}")
        else:
            await self._wait_for_subscriptions(deadline)
        if self.graph is None:
            self.subscribed_at_start = sorted(set(self.subscribed()) & set(AUTO_TOPICS))
        self.started = True

    async def _until(self, condition: Callable[[], bool], deadline: float, wanted: str) -> None:
        loop = asyncio.get_running_loop()
        while not condition():
            if loop.time() >= deadline:
                await self._no_start(f"the controller did not {wanted} within "
                                     f"{self.startup_timeout_s:g} s")
            await asyncio.sleep(0.01)

    async def _no_start(self, reason: str) -> None:
        self.finish("no_start", f"{reason}: the run never started")
        await asyncio.Event().wait()

    async def _wait_for_subscriptions(self, deadline: float) -> None:
        """``auto``, rosbridge: its subscriptions, settled, choose the trigger."""
        loop = asyncio.get_running_loop()
        wanted = " or ".join(("/odom", SCAN.name, CLOCK.name))
        await self._until(lambda: bool(set(self.subscribed()) & set(AUTO_TOPICS)), deadline,
                          f"subscribe to {wanted} (or another topic published every tick)")
        seen, since = set(self.subscribed()), loop.time()
        while loop.time() - since < SETTLE_S:
            await asyncio.sleep(0.01)
            now = set(self.subscribed())
            if now != seen:
                seen, since = now, loop.time()
        if seen & set(TICK_TOPICS):
            self.trigger, self.scan_fallback = "/odom", SCAN.name in seen
        elif SCAN.name in seen:
            self.trigger = SCAN.name
        else:
            self.trigger, self.every = CLOCK.name, self.scenario.controller_period_ticks

    async def _wait_for_graph(self, deadline: float) -> None:
        """``auto``, rclpy: its nodes spin and the robot has matched what they subscribe."""
        loop = asyncio.get_running_loop()
        assert self.graph_factory is not None
        graph, state = None, "no node of the controller appeared on the run's ROS graph"
        while True:
            graph = graph or self.graph_factory()
            if graph is not None and graph.ready():
                served, refused = graph.subscriptions()
                state = (f"its node {', '.join(graph.active)} subscribes to none of the "
                         f"robot's topics (not even /clock: is use_sim_time set?)"
                         + "".join(f"; {line}" for line in refused))
                if served:
                    state = f"the robot did not match its subscriptions ({', '.join(served)})"
                if served and graph.matched(served) and \
                        await graph.round_trip(STEP_TIMEOUT_S) and \
                        graph.subscriptions() == (served, refused) and graph.matched(served):
                    self.graph = graph
                    graph.served = set(served)
                    self.subscribed_at_start = sorted(served)
                    self.incompatible_qos = refused
                    return
            elif graph is not None and graph.active:
                state = (f"its node {', '.join(graph.active)} does not answer on the graph "
                         "(its parameter services)")
            if loop.time() >= deadline:
                await self._no_start(f"the controller was not ready within "
                                     f"{self.startup_timeout_s:g} s: {state}")
            await asyncio.sleep(0.01)

    def after_tick(self) -> None:
        """The schedule's tick listener: the timed changes due, and the run's end."""
        self._last_tick_topics, self._tick_topics = self._tick_topics, set()
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
        last_s = None if self.last_command_tick is None else \
            round(self.last_command_tick * TICK_PERIOD_S, 6)
        return RunEnd(ended_by, reason, round(self.sim_time_s, 6), self.clock.ticks,
                      self.epoch_s, self.mode, self.stepped_on, self.commands,
                      self.steps_waited, self.missed, self.first_miss_s,
                      self.subscribed_at_start, self.incompatible_qos, last_s,
                      self.probe_commands,
                      self.probe_commands is not None
                      and self.probe_commands >= WALL_PACED_COMMANDS)

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
    parser.add_argument("--step-on", choices=tuple(STEP_ON), default="auto")
    parser.add_argument("--startup-timeout", type=float, default=STARTUP_TIMEOUT_S)
    parser.add_argument("--params", default=None,
                        help="grade on the robot of this parameter file (websim fit's)")
    parser.add_argument("--ros", action="store_true",
                        help="start the ROS graph (websim serve --ros): an rclpy controller")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--ws-port", type=int, default=9090)
    parser.add_argument("--http-port", type=int, default=8080)
    return parser


def on_robot(scenario: Scenario, params_file: str | None) -> Scenario:
    """``scenario`` graded on the robot of a parameter file (``--params``; None: its own).

    The file's robot section replaces the shipped robot; a payload the scenario sets (its
    mass and inertia differ from the shipped robot's) is kept.

    Raises:
        ConfigError: the file is not a valid parameter file.
    """
    if params_file is None:
        return scenario
    robot = load_params(params_file).robot
    shipped = RobotParams()
    if (scenario.robot.mass_kg, scenario.robot.inertia_kg_m2) != \
            (shipped.mass_kg, shipped.inertia_kg_m2):
        robot = dataclasses.replace(robot, mass_kg=scenario.robot.mass_kg,
                                    inertia_kg_m2=scenario.robot.inertia_kg_m2)
    return dataclasses.replace(scenario, robot=robot)


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
        scenario = on_robot(pick_scenario(args.suite, args.scenario), args.params)
    except ConfigError as error:
        print(f"websim grade server: error: {error}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    speed = SPEED_MAX if args.mode == "deterministic" else 1.0
    clock = SimClock(TICK_PERIOD_S, speed, epoch_s=0.0)  # /clock starts at 0, as Gazebo's
    simulation = Simulation(scenario.world, scenario.robot, mode=scenario.mode,
                            seed=scenario.seed, lidar=scenario.lidar,
                            noise=scenario.world.noise_over(NoiseParams()))
    robot = VirtualRobot(simulation, clock)
    token = strong_token()
    serve_args = serve_command_arguments(args)
    recorder = Recorder(args.out / RECORDING_DIR, max_bytes=RECORDING_MAX_BYTES)
    site = sites.single_robot(robot, token, grade_limits(args.mode), OriginPolicy.default(
        args.host, args.http_port, []), args.ws_port, recorder=recorder,
        simulation_services=False)  # no teleport, pause or step for the graded controller
    site.ros_parameters.update(GRADE_NODE_PARAMETERS)
    site.graph_read_only = GRAPH_READ_ONLY
    host = site.front.host  # type: ignore[attr-defined]
    host.bridge.services.add(RESET_SERVICE, "std_srvs/srv/Empty", _refuse_reset)

    def subscribed() -> Collection[str]:
        return {*host.bridge.topics.subscribed_topics(), *graph_subscribed(site)}

    def connected() -> bool:
        return bool(host.bridge.sessions) or bool(graph_subscribed(site))

    graphs: list[Any] = []

    def controller_graph() -> Any:
        """The controller's side of the ROS graph, once it runs (``--ros``)."""
        if not graphs and site.ros is not None:
            from websim.grade_graph import ControllerGraph
            node = site.ros.robot_node
            graph = ControllerGraph(node, node.robot_publishers(), asyncio.get_running_loop())
            node.publish_hook = graph.hold  # lock step hands the ticks' messages over
            graphs.append(graph)
        return graphs[0] if graphs else None

    lock_step = LockStep(scenario, robot, clock, subscribed, connected, mode=args.mode,
                         step_on=args.step_on, out=args.out,
                         startup_timeout_s=args.startup_timeout,
                         graph=controller_graph if args.ros else None)
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
