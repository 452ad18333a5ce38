"""A class: one independent robot per student on one server, by name.

``Classroom`` is the one registry of tenants (STYLE 16): it creates a ``RobotHost`` (its
simulation, bridge and token) per roster entry, or on first connection in an open class,
and nothing of one robot is reachable from another's objects. All robots follow one tick
``Schedule``; a robot nobody has been connected to for the idle time stops ticking.

Roster files: one student a line, ``name`` or ``name,world`` or ``name,world,token``
(names ``[a-z0-9_-]{1,32}``; an empty world field means the server's ``--world``); ``#``
starts a comment.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import hashlib
import hmac
import logging
import re
import secrets
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from classroom.state import DEFAULT_ENROLMENT_HOURS, SAVE_INTERVAL_S, ClassState
from physics import TICK_PERIOD_S, ConfigError, load_world
from physics.snapshots import Pose2D
from physics.validation import read_text_file
from ros_nodes.recording import Recorder
from ros_nodes.robot_host import TOKEN_SERVICE, RobotHost
from ros_nodes.robot_services import require_admin
from ros_nodes.sensors import Sensor
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.clock import Clock, SimClock, WallClock
from rosbridge.core.limits import ClientLimits, LatchedBytes
from rosbridge.core.session import Session
from rosbridge.transport.schedule import Schedule

ROBOT_NAME = re.compile(r"[a-z0-9_-]{1,32}")
"""What a robot (student) name may be: it becomes a URL path segment and a ROS namespace."""

DEFAULT_MAX_ROBOTS = 200
"""Most robots an open class enrols (``--max-robots``)."""

DEFAULT_IDLE_PAUSE_S = 600.0
"""A robot nobody has been connected to for this long stops ticking (``--idle-pause``)."""

SPREAD = 0.8
"""Share of the tick period the robots' ticks are spread over (the last robot steps 40 ms
after the first at 20 Hz, leaving the rest of the period for the frames to go out)."""

SLOTS = 10
"""The spread's slots per period: robots are ticked in up to this many groups, one group every
``SPREAD / SLOTS`` of the period (4 ms at 20 Hz). A robot's frames go out after its group, not
after the whole class; and the event loop wakes ten times a tick, not once per robot."""

TOKEN_BYTES = 18
"""Bytes of a robot token (24 URL-safe characters)."""

MIN_TOKEN_CHARS = 20
"""The shortest token accepted (``--admin-token``, a roster's token field)."""

TOKEN_CHARS = re.compile(r"[A-Za-z0-9._~-]+")
"""What a token may be made of: URL-safe characters (it travels in ``?token=``)."""

TOKEN_CLASSES = (("lower-case letters", re.compile(r"[a-z]")),
                 ("upper-case letters", re.compile(r"[A-Z]")),
                 ("digits", re.compile(r"[0-9]")),
                 ("symbols (. _ ~ -)", re.compile(r"[._~-]")))
"""A token must mix at least three of these four classes of characters."""

log = logging.getLogger("websim.class")


@dataclass(frozen=True)
class Student:
    """One roster entry.

    Attributes:
        name: the robot's name (``[a-z0-9_-]{1,32}``): ``/robots/NAME``.
        world: a world for this robot (file or shipped name); None: the server's.
        token: the robot's own admin token; None: a random one is made.
    """

    name: str
    world: str | None = None
    token: str | None = None


def check_name(name: str, where: str = "robot name") -> str:
    """``name`` if it is a valid robot name; ConfigError otherwise."""
    if not ROBOT_NAME.fullmatch(name):
        raise ConfigError(f"{where}: '{name[:40]}' is not a robot name (1 to 32 of a-z, 0-9, "
                          "_ and -)")
    return name


def read_roster(path: str | Path) -> list[Student]:
    """The students of a roster file, in order.

    Raises:
        ConfigError: unreadable file, a bad or repeated name, too many fields; the message
            names the file and the line.
    """
    source = str(path)
    text = read_text_file(path, "roster")
    students: list[Student] = []
    seen: set[str] = set()
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = [field.strip() for field in line.split(",")]
        where = f"{source}:{number}"
        if len(fields) > 3:
            raise ConfigError(f"{where}: expected name[,world[,token]], got {len(fields)} "
                              "fields")
        name = check_name(fields[0], where)
        if name in seen:
            raise ConfigError(f"{where}: '{name}' is on the roster twice")
        seen.add(name)
        world = fields[1] if len(fields) > 1 and fields[1] else None
        if world is not None:  # a typo is the roster's error, with its line, not the server's
            try:
                load_world(world)
            except ConfigError as error:
                raise ConfigError(f"{where}: the world of '{name}': {error}") from None
        token = fields[2] if len(fields) > 2 and fields[2] else None
        if token is not None and (why := weak_token(token)) is not None:
            raise ConfigError(f"{where}: the token of '{name}' is too weak: {why}")
        students.append(Student(name, world, token))
    if not students:
        raise ConfigError(f"{source}: the roster names no student")
    return students


def derived_token(secret: str, name: str) -> str:
    """Robot ``name``'s token derived from the class's random ``secret`` (HMAC-SHA256).

    The secret is the class's own (``classroom.state``), never the instructor's token: a
    student's token says nothing of the secret, of the instructor's token or of other robots'
    tokens, and the same state file gives the same tokens after a restart.
    """
    digest = hmac.new(secret.encode(), f"websim robot {name}".encode(), hashlib.sha256)
    return base64.urlsafe_b64encode(digest.digest()[:TOKEN_BYTES]).decode()


def weak_token(token: str) -> str | None:
    """Why ``token`` is too weak to guard a robot or a class, or None if it is strong enough.

    Strong: at least ``MIN_TOKEN_CHARS`` characters, URL-safe only (A-Z a-z 0-9 . _ ~ -),
    mixing at least three of lower-case letters, upper-case letters, digits and symbols.
    """
    if len(token) < MIN_TOKEN_CHARS:
        return f"{len(token)} characters, at least {MIN_TOKEN_CHARS} are needed"
    if not TOKEN_CHARS.fullmatch(token):
        return "only A-Z, a-z, 0-9 and . _ ~ - may be used (it travels in URLs)"
    missing = [name for name, pattern in TOKEN_CLASSES if not pattern.search(token)]
    if len(missing) > 1:
        return (f"it must mix at least three of lower-case letters, upper-case letters, "
                f"digits and symbols (. _ ~ -); it has no {' and no '.join(missing)}")
    return None


def strong_token() -> str:
    """A random token ``weak_token`` accepts (192 bits)."""
    while True:
        token = secrets.token_urlsafe(24)
        if weak_token(token) is None:
            return token


def numbered_roster(count: int) -> list[Student]:
    """``robot01`` ... ``robotNN`` (at least two digits)."""
    if not 1 <= count <= DEFAULT_MAX_ROBOTS * 10:
        raise ConfigError(f"--class: between 1 and {DEFAULT_MAX_ROBOTS * 10} robots, "
                          f"got {count}")
    width = max(2, len(str(count)))
    return [Student(f"robot{index:0{width}d}") for index in range(1, count + 1)]


class Classroom:
    """Every robot of one server, by name.

    Args:
        roster: the students known at start.
        make_robot: builds a student's robot (its world, the server's parameters).
        schedule: the tick schedule all robots follow.
        open_class: enrol unknown names on their first connection.
        max_robots: most robots an open class holds.
        idle_pause_s: a robot nobody has been connected to for this long pauses.
        make_token: makes robot NAME's token when the roster gives none (default: derived
            from the class secret).
        lazy: create a robot on its first ``get`` rather than at start (a worker of a class
            spread over several processes hosts only the robots routed to it).
        clock: the class's clock (the one its robots are made with): its monotonic time
            places the groups' ticks within a period. Default: wall time.
        state: the class's state file: its secret, enrolments and robots' state, restored
            now and saved every ``SAVE_INTERVAL_S`` while ``run_ticks`` runs. None: a random
            secret, nothing kept.
        latched: the server's pool of clients' latched messages, each robot's within it
            (default: one of the default sizes).
        recorder: records every robot from its creation on (``--record``); None: none.
        on_robot: called with (name, host) of each robot once it is made (``websim serve``
            adds its simulation services: ``ros_nodes.simulation_services``).
        enrolment_hours: an open class's enrolment nobody connected to for this long is
            forgotten when the class starts (with its robot's state): its name enrols anew.
    """

    def __init__(self, roster: list[Student], make_robot: Callable[[Student], VirtualRobot],
                 schedule: Schedule | None = None, *, open_class: bool = False,
                 max_robots: int = DEFAULT_MAX_ROBOTS,
                 idle_pause_s: float | None = DEFAULT_IDLE_PAUSE_S,
                 make_token: Callable[[str], str] | None = None, lazy: bool = False,
                 clock: Clock | None = None, state: ClassState | None = None,
                 latched: LatchedBytes | None = None,
                 recorder: Recorder | None = None,
                 on_robot: Callable[[str, RobotHost], Any] | None = None,
                 enrolment_hours: float = DEFAULT_ENROLMENT_HOURS) -> None:
        self._recorder = recorder
        self._on_robot = on_robot
        self.clock: Clock = WallClock() if clock is None else clock
        """The class's one clock (its robots' too)."""
        self.schedule = schedule or Schedule(TICK_PERIOD_S, self.clock)
        self.open_class = open_class
        self.max_robots = max(max_robots, len(roster))
        self.state = state
        self.secret = state.secret if state is not None else secrets.token_urlsafe(32)
        """The random secret robot tokens derive from (kept in the state file)."""
        self._make_robot = make_robot
        self._latched = latched or LatchedBytes.for_server(ClientLimits())
        self._idle_pause_s = idle_pause_s
        self._make_token = make_token or (lambda name: derived_token(self.secret, name))
        self._hosts: dict[str, RobotHost] = {}
        self._tokens: dict[str, str] = {}
        roster_names = {student.name for student in roster}
        self.forgotten: list[str] = [] if state is None else state.forget_enrolments(
            enrolment_hours * 3600.0, keep=roster_names)
        """Enrolments forgotten at start: nobody had connected to them for the enrolment
        time."""
        self._saved: dict[str, dict[str, Any]] = {} if state is None else state.robots()
        self.unclaimed: set[str] = set()
        """Names enrolled in an open class whose token nobody has been handed yet."""
        self.students: dict[str, Student] = {student.name: student for student in roster}
        self._roster_names = frozenset(roster_names)
        enrolled = {} if state is None else state.enrolments()
        for name, claimed in enrolled.items():
            if name not in self.students and ROBOT_NAME.fullmatch(name):
                self.students[name] = Student(name)
                if not claimed:
                    self.unclaimed.add(name)
        for student in roster:
            if not lazy:
                self._enrol(student)
        for name in enrolled:
            if name in self.students and name not in self._hosts and (
                    not lazy or name in self._saved):
                self._enrol(self.students[name])
        if lazy:
            for name in list(self._saved):  # _enrol takes each robot's saved state out
                if name in self.students and name not in self._hosts:
                    self._enrol(self.students[name])

    def _enrol(self, student: Student) -> RobotHost:
        host = RobotHost(self._make_robot(student), self.schedule, self._idle_pause_s,
                         self._latched.for_robot())
        self._hosts[student.name] = host
        self.students[student.name] = student
        self.token(student.name)
        name = student.name

        def robot_token(args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
            require_admin(session, TOKEN_SERVICE)
            return {"token": self.token(name)}

        host.bridge.services.add(TOKEN_SERVICE, "websim/srv/RobotToken", robot_token)
        saved = self._saved.pop(name, None)
        if saved is not None:
            try:
                restore_robot(host, saved)
            except (ConfigError, KeyError, TypeError, ValueError) as error:
                log.error("robot %s: its saved state could not be restored (%s); it starts "
                          "at its spawn pose", name, error)
        if self._recorder is not None:
            host.recording = self._recorder.record(name, host.robot)
        if self._on_robot is not None:
            self._on_robot(name, host)
        return host

    def __iter__(self) -> Iterator[tuple[str, RobotHost]]:
        return iter(list(self._hosts.items()))

    def __len__(self) -> int:
        return len(self._hosts)

    def knows(self, name: str) -> bool:
        """Whether ``name`` is (or may become, in an open class) a robot here, creating none."""
        return name in self.students or (self.open_class and ROBOT_NAME.fullmatch(name)
                                         is not None)

    def get(self, name: str) -> RobotHost | None:
        """The robot ``name``, created now if it is not yet (lazily, or enrolling).

        A name an open class enrols now waits for its student (``claim``).

        None: no such robot (unknown, invalid, or the open class is full).
        """
        host = self._hosts.get(name)
        if host is not None or not self.knows(name):
            return host
        if name not in self.students:
            if len(self._hosts) >= self.max_robots:
                return None
            self.unclaimed.add(name)
            if self.state is not None:
                self.state.enrol(name)
        return self._enrol(self.students.get(name, Student(name)))

    def claim(self, name: str) -> bool:
        """Hand robot ``name`` to the connection asking; whether it was handed.

        True once, for the first connection to a name the open class enrolled; nobody else
        can take it afterwards.
        """
        if name not in self.unclaimed:
            return False
        self.unclaimed.discard(name)
        if self.state is not None:
            self.state.enrol(name, claimed=True)
        log.info("robot %s enrolled: its token was handed to its first connection", name)
        return True

    def token(self, name: str) -> str:
        """Robot ``name``'s own token (roster robots, created or not)."""
        if name not in self._tokens:
            student = self.students[name]
            self._tokens[name] = student.token or self._make_token(name)
        return self._tokens[name]

    def is_robot_token(self, name: str, presented: str | None) -> bool:
        """Constant-time check of a token presented for robot ``name``."""
        expected = self.token(name) if name in self.students else self._tokens.get(name)
        if not presented or expected is None:
            return False
        return hmac.compare_digest(presented.encode(), expected.encode())

    def save(self) -> None:
        """Save every robot's state in the state file (if any); never raises."""
        if self.state is None:
            return
        enrolled = [name for name, host in self
                    if host.bridge.sessions and name not in self._roster_names]
        try:
            self.state.save_robots({name: robot_state(host) for name, host in self},
                                   used=enrolled)
        except Exception as error:  # a full disk must not stop the class
            log.error("could not save the class's state in %s: %s", self.state.path, error)

    async def run_ticks(self) -> None:
        """Tick every robot on the one schedule, forever (each robot's faults stay its own).

        The robots' ticks are spread over ``SPREAD`` of the period in up to ``SLOTS``
        groups, each group at its own offset: a robot's frames go out right after its group's
        steps instead of waiting for every other robot's, so its latency does not grow with
        the class, and the work of a tick does not arrive on the event loop all at once.
        On sim time (``--speed``) every robot ticks at once instead: the tick's stamp is one
        time for all, and the next tick cannot begin before the last group has run.
        """
        saver = asyncio.create_task(self._save_every(SAVE_INTERVAL_S))
        try:
            await self.schedule.run(self._tick_all)
        finally:
            saver.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await saver
            self.save()

    async def _save_every(self, interval_s: float) -> None:
        while True:
            await asyncio.sleep(interval_s)
            self.save()

    def _tick_all(self, lateness_s: float) -> None:
        hosts = [host for _, host in self]
        if not hosts:
            return
        loop = asyncio.get_running_loop()
        now_s = self.clock.monotonic_s()
        if isinstance(self.clock, SimClock):
            self._tick_group(hosts, now_s, lateness_s)
            return
        slots = min(SLOTS, len(hosts))
        slot_s = SPREAD * self.schedule.period_s / slots
        groups = [hosts[index::slots] for index in range(slots)]
        self._tick_group(groups[0], now_s, lateness_s)
        for index, group in enumerate(groups[1:], start=1):
            # One loop turn later: a /cmd_vel that arrived with the timer is applied first
            # (its reader was woken by the same poll, and runs before what call_soon adds).
            loop.call_later(index * slot_s, loop.call_soon, self._tick_group, group,
                            now_s + index * slot_s, lateness_s)

    def _tick_group(self, hosts: list[RobotHost], due_s: float, lateness_s: float) -> None:
        """Advance a group's robots, prepare their costly readings together, deliver each's.

        A sensor with ``prepare_many`` (the LiDAR) due on several robots of the group has
        their readings computed at once (one ray intersection for a world); each robot's
        ``end_tick`` then finds its reading ready.

        Args:
            hosts: the group's robots.
            due_s: when the group was due (the class clock's monotonic s).
            lateness_s: how late the period's tick started (s).
        """
        late_s = lateness_s + max(0.0, self.clock.monotonic_s() - due_s)
        advanced = [host for host in hosts if host.begin_tick(late_s)]
        preparing: dict[Sensor, list[RobotHost]] = {}
        for host in advanced:
            for sensor in host.due(late_s):
                if sensor.prepare_many is not None:
                    preparing.setdefault(sensor, []).append(host)
        for sensor, group in preparing.items():
            if len(group) > 1 and sensor.prepare_many is not None:
                try:
                    sensor.prepare_many([host.robot.sim for host in group])
                except Exception as error:  # each robot then builds its own, in its boundary
                    for host in group:
                        host.faults.record(f"preparing the class's {sensor.topic.name} "
                                           "together", error)
        for host in advanced:
            host.end_tick(late_s)


def robot_state(host: RobotHost) -> dict[str, Any]:
    """What a restart restores of a robot.

    Its runtime parameters (mode, payload...), whether it is held (``/websim/pause``), its
    true pose and its odometry.
    """
    robot = host.robot
    parameters = robot.parameters
    truth, odometry = robot.sim.ground_truth(), robot.sim.odometry()
    return {
        "parameters": {name: parameters.get(name) for name in parameters.names()
                       if parameters.spec(name).runtime},
        "held": host.held,
        "pose": [truth.x, truth.y, truth.theta],
        "odometry": [odometry.x, odometry.y, odometry.theta],
    }


def restore_robot(host: RobotHost, saved: Mapping[str, Any]) -> None:
    """Put a robot back as ``robot_state`` saved it (ConfigError: a value no longer valid)."""
    robot = host.robot
    robot.parameters.set_many(dict(saved["parameters"]))
    robot.sim.place(Pose2D(*map(float, saved["pose"])), Pose2D(*map(float, saved["odometry"])))
    host.held = bool(saved["held"])
    host.stats.paused = host.stats.paused or host.held
