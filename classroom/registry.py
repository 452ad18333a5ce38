"""A class: one independent robot per student on one server, by name.

``Classroom`` is the one registry of tenants (STYLE 16): it creates a ``RobotHost`` (its
simulation, bridge and token) per roster entry, or on first connection in an open class,
and nothing of one robot is reachable from another's objects: each student's robot lives in
a world of its own (``ros_nodes.world_host.WorldHost``). The class's one tick driver
(``heartbeat.driver.TickDriver``) ticks every world; a robot nobody has been connected to for
the idle time stops ticking.

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
from heartbeat.driver import TickDriver
from heartbeat.schedule import Schedule
from physics import ConfigError, load_world
from physics.snapshots import Pose2D
from physics.validation import read_text_file
from ros_nodes.recording import Recorder
from ros_nodes.robot_host import TOKEN_SERVICE, RobotHost
from ros_nodes.robot_services import require_admin
from ros_nodes.virtual_robot_core import VirtualRobot
from ros_nodes.world_host import WorldHost
from rosbridge.core.clock import Clock, WallClock
from rosbridge.core.limits import ClientLimits, LatchedBytes
from rosbridge.core.session import Session

ROBOT_NAME = re.compile(r"[a-z0-9_-]{1,32}")
"""What a robot (student) name may be: it becomes a URL path segment and a ROS namespace."""

DEFAULT_MAX_ROBOTS = 200
"""Most robots an open class enrols (``--max-robots``)."""

DEFAULT_IDLE_PAUSE_S = 600.0
"""A robot nobody has been connected to for this long stops ticking (``--idle-pause``)."""

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
        start: where it spawns in a shared world (a robot spawned while the arena runs);
            None: where the world places it.
    """

    name: str
    world: str | None = None
    token: str | None = None
    start: Pose2D | None = None


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
        make_robot: builds a student's robot (its world, the server's parameters): in a world
            of its own, or in the one world every robot shares (``--arena``): robots whose
            simulations are of one ``WorldSim`` are ticked as one world.
        driver: the tick driver of every robot (default: one of its own, on ``clock``).
        open_class: enrol unknown names on their first connection.
        max_robots: most robots an open class holds.
        idle_pause_s: a robot nobody has been connected to for this long pauses.
        make_token: makes robot NAME's token when the roster gives none (default: derived
            from the class secret).
        lazy: create a robot on its first ``get`` rather than at start (a worker of a class
            spread over several processes hosts only the robots routed to it).
        clock: the class's clock (its monotonic time: idle times, saves; its speed, if a
            ``SimClock``, the driver's when none is given). Default: wall time.
        state: the class's state file: its secret, enrolments and robots' state, restored
            now and saved every ``SAVE_INTERVAL_S`` while ``run_ticks`` runs. None: a random
            secret, nothing kept.
        latched: the server's pool of clients' latched messages, each robot's within it
            (default: one of the default sizes).
        recorder: records every robot from its creation on (``--record``); None: none.
        on_robot: called with (the class, name, host, its world's host) of each robot once
            it is made (``websim serve`` adds its simulation services:
            ``ros_nodes.simulation_services``).
        enrolment_hours: an open class's enrolment nobody connected to for this long is
            forgotten when the class starts (with its robot's state): its name enrols anew.
    """

    def __init__(self, roster: list[Student], make_robot: Callable[[Student], VirtualRobot],
                 driver: TickDriver | None = None, *, open_class: bool = False,
                 max_robots: int = DEFAULT_MAX_ROBOTS,
                 idle_pause_s: float | None = DEFAULT_IDLE_PAUSE_S,
                 make_token: Callable[[str], str] | None = None, lazy: bool = False,
                 clock: Clock | None = None, state: ClassState | None = None,
                 latched: LatchedBytes | None = None,
                 recorder: Recorder | None = None,
                 on_robot: Callable[[Classroom, str, RobotHost, WorldHost], Any] | None = None,
                 enrolment_hours: float = DEFAULT_ENROLMENT_HOURS) -> None:
        self._recorder = recorder
        self._on_robot = on_robot
        self.clock: Clock = WallClock() if clock is None else clock
        """The class's clock (wall time for intervals; its robots' stamps are their worlds')."""
        self.driver = driver or TickDriver.for_clock(self.clock)
        """The one tick driver of every robot of the class."""
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
        self._worlds: dict[str, WorldHost] = {}
        self._shared: dict[int, WorldHost] = {}
        """Each world's host, by its simulation: robots made in one world (``--arena``)
        share it."""
        self._spawned: dict[str, str | None] = {}
        """Robots spawned while the class runs (``spawn``), and who spawned each (None: the
        instructor)."""
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
        robot = self._make_robot(student)
        world = self._shared.get(id(robot.sim.world_sim))
        if world is None:  # a world of its own (or the first robot of a shared one)
            world = WorldHost(robot.sim.world_sim, self._idle_pause_s)
            self._shared[id(robot.sim.world_sim)] = world
        host = world.add(robot, self._latched.for_robot())
        if len(world) == 1:
            self.driver.add(world)
        self._hosts[student.name] = host
        self._worlds[student.name] = world
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
            self._on_robot(self, name, host, world)
        return host

    def __iter__(self) -> Iterator[tuple[str, RobotHost]]:
        return iter(list(self._hosts.items()))

    def __len__(self) -> int:
        return len(self._hosts)

    def spawn(self, name: str, pose: Pose2D, owner: str | None) -> None:
        """Add robot ``name`` at ``pose`` to the class (an arena's ``SpawnEntity``).

        It is a robot of the class as a student's is (``/robots/NAME``, a token derived from
        the class's secret, its state kept), spawned by ``owner`` (None: the instructor).

        Raises:
            ConfigError: an invalid or taken name, a full class, or no room at ``pose``.
        """
        check_name(name, "entity name")
        if name in self.students or name in self._hosts:
            raise ConfigError(f"entity name: '{name}' is a robot of this class already")
        if len(self._hosts) >= self.max_robots:
            raise ConfigError(f"the class is full ({self.max_robots} robots)")
        student = Student(name, start=pose)
        self.students[name] = student
        try:
            self._enrol(student)
        except BaseException:
            del self.students[name]
            raise
        self._spawned[name] = owner
        log.info("robot %s spawned%s", name, f" by {owner}" if owner else "")

    def delete(self, name: str) -> None:
        """Take robot ``name`` out of the class and its world (KeyError: no such robot).

        Its clients stay connected to a robot that no longer ticks until they leave.
        """
        host = self._hosts.pop(name)
        world = self._worlds.pop(name)
        world.remove(name)
        if not len(world):
            self.driver.remove(world)
            self._shared.pop(id(world.world), None)
        self.students.pop(name, None)
        self._tokens.pop(name, None)
        self._spawned.pop(name, None)
        self.unclaimed.discard(name)
        if host.recording is not None:
            host.recording.detach()  # its bag ends here
        log.info("robot %s deleted", name)

    def owner(self, name: str) -> str | None:
        """Who spawned robot ``name`` (None: the instructor, or a robot of the roster)."""
        return self._spawned.get(name)

    def spawned(self, name: str) -> bool:
        """Whether robot ``name`` was spawned while the class runs."""
        return name in self._spawned

    def world(self, name: str) -> WorldHost:
        """The world robot ``name`` lives in (KeyError: no robot of that name here yet)."""
        return self._worlds[name]

    def pace(self, name: str) -> Schedule:
        """The pace robot ``name``'s messages follow (KeyError: no such robot yet)."""
        return self.driver.pace(self._worlds[name])

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
        """Run the tick driver forever (each robot's faults stay its own), saving the state.

        The driver ticks every robot's world: at real time together, spread over the period
        (``heartbeat.driver``); above real time each world at its own pace.
        """
        saver = asyncio.create_task(self._save_every(SAVE_INTERVAL_S))
        try:
            await self.driver.run()
        finally:
            saver.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await saver
            self.save()

    async def _save_every(self, interval_s: float) -> None:
        while True:
            await asyncio.sleep(interval_s)
            self.save()


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
