"""One robot served: its bridge, its endpoint, its health, and its part of each tick.

A ``RobotHost`` owns everything of one robot and nothing of another, so a server may run
many. It does not tick on its own: its world's host (``ros_nodes.world_host``) steps the world
and asks each robot's host for its part of the tick, and the one tick driver
(``heartbeat.driver``) runs every world's ticks. The host is the robot's fault boundary: an
exception while building, encoding or delivering one of its messages is recorded (``Faults``:
logged once with the cause, counted, ``/healthz`` says ``degraded``) and the ticks go on; a
robot whose state went non-finite is reset to its spawn pose. When the server cannot keep up
(a tick starts half a period late), that tick's /scan is shed first; /odom and /tf keep their
rate. Above real time (``--speed`` over 1) no tick is late (the driver waits instead), so
nothing is shed.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections import deque
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from physics import ConfigError
from ros_nodes.recording import Recording
from ros_nodes.robot_endpoint import RobotEndpoint
from ros_nodes.robot_interface import (
    RESERVED_NAMESPACES,
    RESET_SERVICE,
    ROBOT_TOPICS,
)
from ros_nodes.robot_services import require_admin
from ros_nodes.sensors import Sensor
from ros_nodes.simulation_services import WATCHABLE_SERVICES
from ros_nodes.virtual_robot_core import Publication, VirtualRobot
from rosbridge.core.access import DriveRules
from rosbridge.core.bridge import Bridge
from rosbridge.core.errors import ServiceError
from rosbridge.core.faults import Faults
from rosbridge.core.limits import LatchedBytes
from rosbridge.core.session import Flush, Session
from rosbridge.tf.republisher import ACTION as TF_REPUBLISHER_ACTION
from rosbridge.tf.republisher import REPUBLISH_SERVICE, TfRepublisher

Write = Callable[[Flush], None]
"""Has a flush written (the tick driver's connections): the loop closers at once."""

log = logging.getLogger("websim.robot")

SHED_SCANS_AFTER_S = 0.025
"""A tick that starts this late (half a period: the host cannot keep up with the clients)
publishes no sheddable sensor's message (/scan): the biggest message goes first, /odom and
/tf keep their rate."""

STATUS_SERVICE = "/websim/status"
"""Admin only: a robot's clients and their addresses, its last driver, collisions, mode,
payload and whether it is paused (``RobotHost.status`` and the clients' addresses; the
instructor's dashboard asks the class's root for every robot's ``status`` at once)."""

PAUSE_SERVICE = "/websim/pause"
"""Admin only: ``{paused: true}`` holds the robot, ``{paused: false}`` lets it run."""

TOKEN_SERVICE = "/websim/token"
"""``websim/srv/RobotToken`` ``{}`` -> ``{token}``: a class robot's own token, for a client that
holds it already or the instructor's token (an open class hands it to the student who
enrolled the name: the page keeps it)."""

DRIVE_RULES = DriveRules(
    topics=frozenset(spec.name for spec in ROBOT_TOPICS if spec.direction == "in"),
    services=frozenset({RESET_SERVICE}),
    watch_services=(*RESERVED_NAMESPACES, RESET_SERVICE, REPUBLISH_SERVICE,
                    *WATCHABLE_SERVICES),
    watch_actions=frozenset({TF_REPUBLISHER_ACTION}),
    hint=": connect to ws://HOST:9090/robots/NAME?token=TOKEN with the robot's token (the "
         "links file, or the page the student enrolled it with)")
"""What a class robot's client needs its token for: driving it (the topics it subscribes),
resetting it, offering services or actions on it, calling services it does not offer (a
classmate's code's, the ROS graph's). Watching includes the TF republisher (its service and
action only read the robot's TF tree: ros3djs pages need them). Changing its parameters and
pausing it need admin rights (``require_admin``: the robot's token or the instructor's) in any
case."""


RECENT_TICKS = 1200
"""Ticks whose lateness and delivery /healthz's percentiles cover (a minute at 20 Hz)."""


@dataclass
class TickStats:
    """What one robot's ticks have done, for /healthz and benchmarks.

    Attributes:
        ticks: ticks run since start (paused ones not counted).
        lateness_s: how late each recent tick started after its deadline (s).
        scans_shed: messages of sheddable sensors (``Sensor.sheddable``: the LiDAR's /scan)
            not built because their tick was late.
        scans_cast: messages of sheddable sensors built (only on ticks where a client
            subscribes to their topic, or a ROS graph or a tap listens).
        resets: times the robot was reset because a fault left it in a non-finite state.
        paused: whether the robot is paused now (nobody connected for the idle time).
        delivery_s: how long after its step began each recent tick's /odom and /tf were
            handed to its clients (s): the robots stepped before it and its world's step in
            the tick, and in a world of one robot its scan (they go out together).
    """

    ticks: int = 0
    lateness_s: deque[float] = field(default_factory=lambda: deque(maxlen=RECENT_TICKS))
    scans_shed: int = 0
    scans_cast: int = 0
    resets: int = 0
    paused: bool = False
    delivery_s: deque[float] = field(default_factory=lambda: deque(maxlen=RECENT_TICKS))

    def jitter_p99_ms(self) -> float:
        """99th percentile of recent tick lateness (ms)."""
        return p99_ms(self.lateness_s)

    def delivery_p99_ms(self) -> float:
        """99th percentile of recent ticks' delivery after their step began (ms)."""
        return p99_ms(self.delivery_s)


def p99_ms(samples_s: Collection[float]) -> float:
    """The 99th percentile of ``samples_s`` (s) in ms; 0 if there are none.

    The sorted samples' element at 99 % of their count, found among the largest few
    (``heapq.nlargest``: a public /healthz of a class reads two per robot, and sorting them
    all cost 155 µs a robot).
    """
    count = len(samples_s)
    if not count:
        return 0.0
    index = min(count - 1, int(0.99 * count))
    return 1000.0 * heapq.nlargest(count - index, samples_s)[-1]


class RobotHost:
    """A robot and its bridge.

    Args:
        robot: the virtual robot to serve.
        idle_pause_s: stop ticking (keeping the state) once nobody has been connected for
            this long; the next connection resumes it. None: never pause.
        latched: the pool its clients' latched messages are counted in (its own, within its
            server's: ``LatchedBytes.for_robot``; default: one of the default size).

    The robot's clock (``robot.clock``) is the host's: its monotonic time (wall time) measures
    the idle time, the bridge's throttles and timeouts and the last command's age.
    """

    def __init__(self, robot: VirtualRobot, idle_pause_s: float | None = None,
                 latched: LatchedBytes | None = None) -> None:
        self.robot = robot
        self.faults = Faults()
        clock = robot.clock
        self.bridge = Bridge(clock=clock, faults=self.faults, refusals=(ConfigError,),
                             reserved_namespaces=RESERVED_NAMESPACES,
                             drive_rules=DRIVE_RULES, latched=latched)
        self.endpoint = RobotEndpoint(self.bridge, robot)
        self.tf_republisher = TfRepublisher(self.bridge)
        """tf2_web_republisher's service and action, from the robot's /tf and /tf_static."""
        self.stats = TickStats()
        self.held = False
        """Paused by an admin (``/websim/pause``), whoever is connected."""
        self.recording: Recording | None = None
        """Its rosbag2 recording (``--record``), if any: /healthz reports it."""
        self._idle_pause_s = idle_pause_s
        self._clock = clock
        self._last_client_s = clock.monotonic_s()
        self._step_began_s = self._last_client_s
        self.bridge.services.add(STATUS_SERVICE, "websim/srv/RobotStatus", self._status)
        self.bridge.services.add(PAUSE_SERVICE, "websim/srv/Pause", self._pause)
        sim = robot.sim
        self.endpoint.log.info(f"world '{sim.world.name}', {sim.mode} mode")

    def _idle(self) -> bool:
        """Whether the robot should pause: nobody connected for ``idle_pause_s``."""
        if self.bridge.sessions:
            self._last_client_s = self._clock.monotonic_s()
            return False
        return self._idle_pause_s is not None and \
            self._clock.monotonic_s() - self._last_client_s >= self._idle_pause_s

    def pausing(self) -> bool:
        """Whether the robot sits this tick out: held by an admin, or idle (``stats.paused``)."""
        idle = self._idle()  # first: it notes when clients were last here
        self.stats.paused = self.held or idle
        return self.stats.paused

    def before_step(self, lateness_s: float) -> bool:
        """Its part before its world steps (its command's watchdog); whether it may step.

        Never raises: a fault is recorded and the robot reset to its spawn pose.
        """
        self.stats.ticks += 1
        self.stats.lateness_s.append(lateness_s)
        self._step_began_s = self._clock.monotonic_s()
        try:
            self.robot.before_step()
        except Exception as error:  # the robot's boundary: record, recover, go on
            self.faults.record("stepping the robot", error)
            self.recover("its step failed")
            return False
        return True

    def after_step(self) -> bool:
        """Its part after its world stepped; whether it ended in a finite state.

        Never raises: a state gone non-finite is recorded and the robot reset to its spawn.
        """
        try:
            self.robot.after_step()
            truth = self.robot.sim.ground_truth()
            if not all(math.isfinite(value) for value in truth):
                raise FloatingPointError(f"non-finite state {tuple(truth)}")
        except Exception as error:  # the robot's boundary: record, recover, go on
            self.faults.record("stepping the robot", error)
            self.recover("its state went non-finite" if isinstance(error, FloatingPointError)
                         else "its step failed")
            return False
        return True

    def reads_scan(self, lateness_s: float = 0.0) -> bool:
        """Whether a message ``end_tick`` builds reads the LiDAR's scan.

        The tick's scan pass casts it with every other robot's.
        """
        return any(sensor.reads_scan for sensor in self.due(lateness_s))

    def due(self, lateness_s: float = 0.0) -> list[Sensor]:
        """The sensors whose messages ``end_tick`` will build (wanted, and not shed)."""
        shed = lateness_s > SHED_SCANS_AFTER_S
        return [sensor for sensor in self.robot.due(self._wanted())
                if not (shed and sensor.sheddable)]

    def wants(self, topic: str) -> bool:
        """Whether a client of the robot subscribes to ``topic`` (a ROS graph: to all)."""
        wanted = self._wanted()
        return wanted is None or topic in wanted

    def end_tick(self, write: Write, lateness_s: float = 0.0,
                 shared: Sequence[Publication] = (), scans: bool | None = None) -> None:
        """Build and deliver the messages of the tick just stepped; never raises.

        ``write`` has each flush written: the clients closing a loop first, before the
        watchers' frames are even queued. ``shared``: messages of the robot's world, built
        once for all its robots (``/world_robots``), delivered to its clients that want them
        (the world's, not the robot's: its tap does not carry them). ``scans``: only the
        messages that read the LiDAR's scan (True), only the others (False), or all (None):
        a crowded world sends every robot's /odom and /tf before its scan pass.

        Only messages some client subscribes to are built (for a ROS graph: all). A tick that
        starts half a period late builds no sheddable sensor's message (/scan): it is shed,
        /odom and /tf keep their rate.
        """
        wanted = self._wanted()
        shed = lateness_s > SHED_SCANS_AFTER_S
        due = self.robot.due(wanted, scans)
        if scans and not due:
            return  # no scan of its this tick: the other part delivered everything
        sheddable = sum(sensor.sheddable for sensor in due)
        if shed:
            self.stats.scans_shed += sheddable
        try:
            publications = self.robot.messages(due, shed)
        except Exception as error:  # the robot's boundary: record, recover, go on
            self.faults.record("stepping the robot", error)
            self.recover("building its messages failed")
            publications = []
        else:
            self.stats.scans_cast += 0 if shed else sheddable
        messages = [(spec.name, msg) for spec, msg in publications]
        messages += [(spec.name, msg) for spec, msg in shared
                     if wanted is None or spec.name in wanted]
        # Throttles count from when the tick was due, not from when this robot's turn came:
        # a late tick is no shorter gap, nor is a robot late in a crowded world's order.
        due_s = self._step_began_s - lateness_s
        try:
            for flush in self.bridge.publish_many(messages, due_s):
                write(flush)
        except Exception as error:  # the robot's boundary: record, go on
            self.faults.record(f"delivering {', '.join(name for name, _ in messages)}", error)
        if scans:
            return  # the tick's other part republished and expired
        self.stats.delivery_s.append(self._clock.monotonic_s() - self._step_began_s)
        try:
            self.tf_republisher.step(due_s)
        except Exception as error:  # the robot's boundary: record, go on
            self.faults.record("republishing TF", error)
        try:
            self.bridge.services.expire()
            write(self.bridge.take_flush())
        except Exception as error:
            self.faults.record("expiring service calls", error)

    def _wanted(self) -> Collection[str] | None:
        """The topics the robot's clients subscribe to (None: all, for a ROS graph)."""
        if self.bridge.graph.attached:
            return None
        return self.bridge.topics.subscribed_topics()

    def recover(self, why: str) -> None:
        """Put the robot back at spawn (a finite state) after a fault."""
        self.stats.resets += 1
        log.error("robot reset to its spawn pose: %s", why)
        self.endpoint.log.error(f"reset to the spawn pose: {why}")
        try:
            self.robot.reset()
        except Exception as error:
            self.faults.record("resetting the robot", error)

    def status(self) -> dict[str, Any]:
        """What the instructor's dashboard shows of this robot, a fixed set of fields.

        ``client_count`` and ``admin_count`` (clients with the robot's or the instructor's
        token), of which ``owner_count`` (the robot's own token: its student's page and code)
        and ``instructor_count`` (the instructor's token: the dashboard itself is one),
        ``recording`` (what is wrong with its recording, if anything: ``Recording.notice``;
        None), ``last_driver`` (the address of the client whose /cmd_vel the robot took last)
        and ``last_drive_age_s`` (how long ago, s, by the robot's clock), ``collisions``,
        ``mode``, ``mass_kg``, ``inertia_kg_m2``, ``paused`` (not ticking: held or idle),
        ``held`` (by the instructor), ``speed_mps``. Each field a number, a string or None:
        a class's statuses together stay small (``InstructorView``'s class status).
        """
        params = self.robot.sim.params
        drive_s = self.endpoint.last_drive_s
        sessions = self.bridge.sessions
        return {
            "client_count": len(sessions),
            "admin_count": sum(1 for session in sessions if session.is_admin),
            "owner_count": sum(1 for session in sessions
                               if session.is_admin and not session.instructor),
            "instructor_count": sum(1 for session in sessions if session.instructor),
            "recording": None if self.recording is None else self.recording.notice(),
            "last_driver": self.endpoint.last_driver,
            "last_drive_age_s": None if drive_s is None
            else round(self._clock.monotonic_s() - drive_s, 3),
            "collisions": self.robot.collisions,
            "mode": self.robot.sim.mode,
            "mass_kg": params.mass_kg,
            "inertia_kg_m2": params.inertia_kg_m2,
            "paused": self.stats.paused,
            "held": self.held,
            "speed_mps": self.robot.sim.ground_truth().v,
        }

    def _status(self, args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        """``/websim/status``: ``status()`` and each client's address and rights."""
        require_admin(session, STATUS_SERVICE)
        return {
            "clients": [{"address": other.peer, "admin": other.is_admin}
                        for other in sorted(self.bridge.sessions, key=lambda s: s.peer)],
            **self.status(),
        }

    def _pause(self, args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        """``/websim/pause`` ``{paused: bool}``: hold the robot (or let it run again)."""
        require_admin(session, PAUSE_SERVICE)
        paused = args.get("paused")
        if not isinstance(paused, bool):
            raise ServiceError(f"{PAUSE_SERVICE}: args must be {{paused: true or false}}")
        self.held = paused
        self.stats.paused = paused or self._idle()
        return {"paused": self.held}

    def health(self, pace: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """This robot's part of /healthz.

        ``pace``: its tick driver's report of its pace (``ticks_due``, ``tick_resyncs``,
        ``speed``, ``clients_released``), in their place.
        """
        sessions = self.bridge.sessions
        pace = pace or {}
        report: dict[str, Any] = {
            "status": "degraded" if self.faults.degraded else "ok",
            "ticks": self.stats.ticks,
            "ticks_due": pace.get("ticks_due", self.stats.ticks),
            "paused": self.stats.paused,
            "tick_jitter_p99_ms": round(self.stats.jitter_p99_ms(), 3),
            "tick_delivery_p99_ms": round(self.stats.delivery_p99_ms(), 3),
            "tick_resyncs": pace.get("tick_resyncs", 0),
            "scans_shed": self.stats.scans_shed,
            "scans_cast": self.stats.scans_cast,
            "robot_resets": self.stats.resets,
            "clients": len(sessions),
            "queued_frames": sum(len(session.outbox) for session in sessions),
            "queued_bytes": sum(session.outbox.queued_bytes for session in sessions),
            "frames_dropped": sum(session.outbox.dropped for session in sessions),
            "frames_sent": sum(session.outbox.sent for session in sessions),
            "sim_time_s": round(self.robot.sim.time_s, 3),
            "speed": pace.get("speed", 1.0),
            "clients_released": pace.get("clients_released", 0),
            "mode": self.robot.sim.mode,
            "world": self.robot.sim.world.name,
            "last_driver": self.endpoint.last_driver,
        }
        if self.recording is not None:
            report["recording"] = self.recording.health()
        report.update(self.faults.report())
        return report
