"""What ``websim serve`` runs: one robot, or a class of them, with the documents its pages read.

A ``Site`` joins the WebSocket front (``SimServer`` or ``ClassServer``) to what the page
server fills itself (``LiveDocuments``: ``robot.json``, a class robot's ``config.json``) and
to the URLs the banner prints. ``single_robot`` and ``classroom_site`` build them.
"""

from __future__ import annotations

import argparse
import csv
import functools
import io
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from classroom.class_server import ClassServer
from classroom.registry import (
    Classroom,
    Student,
    numbered_roster,
    read_roster,
    strong_token,
)
from classroom.state import (
    DEFAULT_ENROLMENT_HOURS,
    SAVE_INTERVAL_S,
    STALE_AFTER_S,
    ClassState,
    class_identity,
    default_state_path,
)
from heartbeat.driver import TickDriver
from heartbeat.schedule import Schedule
from physics import ConfigError, LidarParams, RobotParams
from ros_nodes.recording import SINGLE_ROBOT_NAME, Recorder
from ros_nodes.robot_description import robot_json
from ros_nodes.robot_host import TOKEN_SERVICE, RobotHost
from ros_nodes.robot_interface import ROBOTS_PREFIX
from ros_nodes.simulation_services import SimulationServices, add_simulation_services
from ros_nodes.simulator_control import OneRobotWorld, SharedWorld
from ros_nodes.virtual_robot_core import VirtualRobot
from ros_nodes.world_host import WorldHost
from rosbridge.core.clock import Clock
from rosbridge.core.limits import ClientLimits, LatchedBytes, OriginPolicy
from rosbridge.transport.front import WebSocketFront
from websim.lan import lan_addresses
from websim.robot_server import SimServer

REPLAY_SERVICE = "/websim/replay"
"""A replay's player controls (``websim.replay.ReplayHost.control``), named to its page in
``config.json``."""

REPLAY_SERVICE_TYPE = "websim/srv/Replay"
"""Its type, as the page names it."""


@dataclass
class Site:
    """A server's robots, as the WebSocket front, the page server and the banner see them.

    Attributes:
        front: the WebSocket front.
        banner: lines the banner prints after the URLs.
        robot: the single robot (None for a class).
        ws_port: the WebSocket port the pages are told (``config.json``): the server's
            own, or a proxy's (``--public-ws-port``).
        classroom: the class (None for a single robot).
        new_robot_json: ``robot.json`` of a class robot not created yet.
        recorder: the robots' recordings (``--record``), if any.
        headline: what the banner says the server runs (a robot's world and mode; a
            replay's recording), for one robot.
        description: ``robot.json`` of a robot without a simulation here (a replay's).
        ros: rclpy in the server (``--ros``: ``websim.ros_runtime.RosRuntime`` or
            ``ClassRosRuntime``) while it runs, else None.
        simulation: the single robot's simulation services (``simulation_interfaces``),
            which ``--ros`` also offers on the graph; None for a class.
        ros_parameters: overrides of the single robot's node parameters with ``--ros``
            (``websim grade``: a reliable ``/scan``).
        admin_token: the instructor's token (a class's: given, or kept in its state file);
            empty: the caller's.
        replay: a replay's player (``websim.replay.ReplayHost``), else None.
        arena: a class whose robots share one world (``--arena``): the dashboard also
            draws it as one map.
        graph_read_only: with ``--ros``, why nothing on the ROS graph may change the robot
            (its parameters, ``/reset_simulation``): a graded run's; None: the graph may.
    """

    front: WebSocketFront
    banner: list[str] = field(default_factory=list)
    robot: VirtualRobot | None = None
    ws_port: int = 9090
    classroom: Classroom | None = None
    new_robot_json: str | None = None
    recorder: Recorder | None = None
    headline: str = ""
    description: str | None = None
    ros: Any = None
    simulation: SimulationServices | None = None
    ros_parameters: dict[str, Any] = field(default_factory=dict)
    admin_token: str = ""
    replay: Any = None
    arena: bool = False
    graph_read_only: str | None = None

    def close(self) -> None:
        """Close the recordings, save a class's state and release its file (at shutdown)."""
        if self.recorder is not None:
            self.recorder.close()
        if self.classroom is not None and self.classroom.state is not None:
            self.classroom.save()
            self.classroom.state.close()

    def schedule(self) -> TickDriver | Schedule:
        """What ticks the robots: a class's or a robot's tick driver, or a replay's schedule.

        Its ``gates``, ``pacers`` and ``tick_listeners`` apply to every tick.
        """
        if self.classroom is not None:
            return self.classroom.driver
        if isinstance(self.front, SimServer):
            return self.front.driver
        destination = self.front.route("/")
        assert not isinstance(destination, str)
        pace = destination[0].pace
        assert isinstance(pace, Schedule)
        return pace

    def class_hosts(self) -> list[tuple[str, RobotHost]]:
        """The robots of a class, by name (none for a single robot)."""
        return [] if self.classroom is None else list(self.classroom)

    def has_robot(self, name: str) -> bool:
        """Whether ``/robots/NAME/`` is a robot's page (pages create no robot)."""
        return self.classroom is not None and self.classroom.knows(name)

    def why_no_robot(self, name: str, address: str = "") -> str:
        """Why ``/robots/NAME/`` is no robot's page, as the student is told.

        The names close to theirs (classmates') go to the instructor's log only, once per
        address a while (the front's refusal log).
        """
        if self.classroom is None:
            return "this server runs one robot, not a class: its page is /"
        if not isinstance(self.front, ClassServer):
            return f"no robot named '{name[:40]}' here"
        reason = self.front.why_unknown(name)
        self.front.refusals.note(address, "no such robot page", f"refused the page of "
                                 f"{ROBOTS_PREFIX}{name[:40]}/: {reason}"
                                 + self.front.log_hint(f"{ROBOTS_PREFIX}{name}"))
        return reason

    def root_notice(self) -> str | None:
        """What ``/`` of a class says instead of a robot's page; None for one robot.

        No robot is there: a student who left out ``/robots/NAME`` got a robot page that
        could never connect.
        """
        if self.classroom is None:
            return None
        return ("This server hosts a class: each student's robot has its own page, at "
                f"{ROBOTS_PREFIX}NAME/ (the instructor's dashboard is /class).")

    def document(self, robot: str | None, name: str, hostname: str) -> str | None:
        """The live ``robot.json`` of a robot, and a class robot's ``config.json``.

        A class robot not hosted here (yet) is described as a new robot would be: behind a
        proxy the page and the WebSocket of one robot may be served by different workers.
        """
        if name == "workers.json" and (robot is not None or self.classroom is None):
            return None  # a class's root only
        if robot is None:
            if self.classroom is None:  # one robot: its description, and where its bridge is
                if name == "robot.json":
                    if self.robot is None:
                        return self.description
                    return robot_json(self.robot.sim.params, self.robot.sim.lidar.params)
                url = f"ws://{url_name(hostname)}:{self.ws_port}/"
                single: dict[str, object] = {
                    "about": "this server's robot, filled by websim serve: the bridge of the "
                             "server that served the page", "ws": url, "adminWs": url}
                if self.robot is not None:  # its name in its world: its /world_robots marker
                    single["entity"] = self.robot.sim.name
                if self.replay is not None:  # the page is a player: no driving
                    single["replay"] = {"name": REPLAY_SERVICE, "type": REPLAY_SERVICE_TYPE}
                return json.dumps(single)
            if name == "robot.json":  # a class's root (the dashboard): a class robot's
                return self.new_robot_json
            if name == "workers.json":  # one process (behind nginx, nginx answers it)
                return json.dumps({"about": "this class is served by one websim serve "
                                            "process: its root view is at the WebSocket "
                                            "root", "workers": None})
            url = f"ws://{url_name(hostname)}:{self.ws_port}/"
            return json.dumps({"about": "the instructor's view of this class, filled by "
                                        "websim serve; robotsPath: where its robots' pages are; "
                                        "arena: whether they share one world",
                               "ws": url, "adminWs": url, "robotsPath": ROBOTS_PREFIX,
                               "arena": self.arena})
        if name == "robot.json":
            host = dict(self.class_hosts()).get(robot)
            if host is None:
                return self.new_robot_json
            return robot_json(host.robot.sim.params, host.robot.sim.lidar.params)
        url = f"ws://{url_name(hostname)}:{self.ws_port}{ROBOTS_PREFIX}{robot}"
        config: dict[str, object] = {"about": f"robot {robot} of this class, filled by websim "
                                              "serve", "ws": url, "adminWs": url,
                                     "robot": robot, "entity": robot}
        if self.classroom is not None and self.classroom.open_class:
            # the service that hands a newly enrolled robot's token to its first connection
            config["robotToken"] = {"name": TOKEN_SERVICE, "type": "websim/srv/RobotToken"}
        return json.dumps(config)


def single_robot(robot: VirtualRobot, token: str, limits: ClientLimits,
                 origins: OriginPolicy, ws_port: int = 9090,
                 recorder: Recorder | None = None, *,
                 simulation_services: bool = True) -> Site:
    """Today's websim: one robot at ``ws://HOST:9090/``.

    Args:
        robot: the robot to serve.
        token: the admin token.
        limits: the bounds every client lives within.
        origins: which web pages may connect.
        ws_port: where the pages are told its bridge is: the server's port, or a proxy's.
        recorder: records the robot (``--record``); None: nothing is recorded.
        simulation_services: offer ``simulation_interfaces`` and turtlesim's names (teleport,
            pause, step...); a graded run offers none (``websim.grade_server``: nothing a
            controller calls may change its run).
    """
    server = SimServer(robot, token, limits=limits, origins=origins)
    simulation = add_simulation_services(server.bridge, OneRobotWorld(
        server.world, robot.sim.name, server.driver)) if simulation_services else None
    site = Site(server, robot=robot, ws_port=ws_port, recorder=recorder,
                headline=f"world '{robot.sim.world.name}', {robot.sim.mode} mode",
                simulation=simulation)
    if recorder is not None:
        recording = recorder.record(SINGLE_ROBOT_NAME, robot)
        server.host.recording = recording
        site.banner.append(f"recording: {recording.path}/ (rosbag2, MCAP storage)")
    return site


def class_roster(spec: str) -> list[Student]:
    """``--class``: a roster file, or a number of robots (``robot01``...)."""
    if spec.isdigit():
        return numbered_roster(int(spec))
    return read_roster(spec)


def classroom_site(args: argparse.Namespace, make_robot: Callable[[Student], VirtualRobot],
                   new_robot_params: tuple[RobotParams, LidarParams], token: str | None,
                   limits: ClientLimits, origins: OriginPolicy,
                   clock: Clock | None = None, recorder: Recorder | None = None) -> Site:
    """A class: robot NAME at ``ws://HOST:9090/robots/NAME``, its page at ``/robots/NAME/``.

    Writes the links files when ``--links`` asks for them.

    Args:
        args: the options of ``websim serve``.
        make_robot: builds a student's robot (with ``clock``).
        new_robot_params: the robot and LiDAR a new robot gets (its ``robot.json``).
        token: the instructor's token (``--admin-token``); None: the one kept in the class's
            state file, else a new one, kept there (``Site.admin_token`` says which). Robots'
            tokens derive from the class's own secret, kept there too (``--state``,
            ``--fresh``).
        limits: the bounds every client lives within.
        origins: which web pages may connect.
        clock: the server's one clock, the robots' too. Default: wall time.
        recorder: records every robot (``--record``); None: nothing is recorded.

    Raises:
        ConfigError: a bad roster or world (the message names the file and line).
    """
    roster = class_roster(args.class_spec)
    named = getattr(args, "state", None)
    state_path = Path(named) if named else default_state_path(
        args.class_spec, args.ws_port if args.worker else None, ws_port=args.ws_port)
    anonymous = not named and args.class_spec.isdigit()  # nothing else tells two apart
    state = ClassState(state_path, class_identity(args.class_spec),
                       fresh=getattr(args, "fresh", False),
                       stale_after_s=STALE_AFTER_S if anonymous else None)
    try:
        token, token_kept = state.admin_token(token, strong_token)
        classroom = Classroom(roster, make_robot, open_class=args.open_class,
                              max_robots=args.max_robots, idle_pause_s=args.idle_pause,
                              lazy=args.worker, clock=clock, state=state,
                              latched=LatchedBytes.for_server(limits),
                              recorder=recorder,
                              on_robot=functools.partial(
                                  simulated, getattr(args, "arena", False),
                                  getattr(args, "student_spawn", 0)),
                              enrolment_hours=getattr(args, "enrolment_hours",
                                                      DEFAULT_ENROLMENT_HOURS))
    except BaseException:
        state.close()
        raise
    open_drive = getattr(args, "open_drive", False)
    site = Site(ClassServer(classroom, token, limits=limits, origins=origins,
                            open_drive=open_drive),
                ws_port=args.public_ws_port or args.ws_port, classroom=classroom,
                new_robot_json=robot_json(*new_robot_params), recorder=recorder,
                admin_token=token, arena=getattr(args, "arena", False))
    names = list(classroom.students)
    notes = [note for note, wanted in (("new names enrol (open class)", args.open_class),
                                       ("a worker: a robot is made when first routed here",
                                        args.worker)) if wanted]
    if open_drive:
        notes.append("anyone may drive any robot (--open-drive)")
    if getattr(args, "arena", False):
        notes.append("every robot in the one world (--arena)")
    first, last = (names[0], names[-1]) if names else ("none yet", "none yet")
    site.banner.append(f"class:     {len(names)} robots ({first} ... {last}), each at "
                       f"{ROBOTS_PREFIX}NAME/ on both ports" + "".join(f"; {n}" for n in notes))
    site.banner.extend(state_lines(state, classroom, token_kept, anonymous))
    if recorder is not None:
        site.banner.append(f"recording: {recorder.directory}/NAME_<UTC time>/ per robot "
                           "(rosbag2, MCAP storage)")
    if args.links is not None:
        host = public_host(args)
        handout, private = Path(args.links), instructor_links_path(Path(args.links))
        http_port = args.public_http_port or args.http_port
        write_links(handout, classroom, host, http_port, site.ws_port)
        write_instructor_links(private, host, http_port, site.ws_port, token)
        site.banner.append(f"links:     {handout} to hand out (each robot's page, WebSocket "
                           "and token; no instructor token)")
        site.banner.append(f"           {private} is yours (the dashboard and the "
                           "instructor's token): keep it to yourself")
    return site


def simulated(arena: bool, spawn_quota: int, classroom: Classroom, name: str,
              host: RobotHost, world: WorldHost) -> None:
    """A class robot's simulation services, over its world.

    ``simulation_interfaces`` and turtlesim's names (``ros_nodes.simulation_services``): over
    the robot's world of its own, or over the arena every robot shares (``--arena``), where
    the class spawns and deletes robots and a student may spawn ``spawn_quota`` of them.
    """
    control = SharedWorld(world, name, classroom.driver, classroom, spawn_quota) if arena \
        else OneRobotWorld(world, name, classroom.driver)
    add_simulation_services(host.bridge, control)


def state_lines(state: ClassState, classroom: Classroom, token_kept: bool,
                anonymous: bool) -> list[str]:
    """What the banner says of the class's state file: where, and what came back from it."""
    where = f"state:     {state.path}"
    if state.stale_s is not None:
        hours = state.stale_s / 3600.0
        lines = [f"{where}: last saved {hours:.0f} h ago, more than {STALE_AFTER_S / 3600:g} "
                 "h: started anew (another day's class; --state FILE restores a file "
                 "however old)"]
    elif state.saved_s is None:
        lines = [f"{where}: new (saved every {SAVE_INTERVAL_S:g} s; a restart restores it, "
                 "--fresh starts anew)"]
    else:
        ago_s = max(0.0, time.time() - state.saved_s)
        ago = f"{ago_s / 60:.0f} min" if ago_s < 5400 else f"{ago_s / 3600:.1f} h"
        restored = [f"{len(classroom)} robots as they were" if state.restored else
                    "no robot's state", "the same tokens"]
        if token_kept:
            restored.append("the instructor's token")
        if classroom.open_class:
            restored.append(f"{len(state.enrolments())} enrolments")
        lines = [f"{where}: restored, saved {ago} ago: {', '.join(restored)} "
                 "(--fresh starts anew)"]
        if anonymous:  # nothing tells two sections of --class N apart but this line
            lines.append("           the links of the class run from here then drive these "
                         "robots: another class or section? --fresh (new links), or its own "
                         "--state FILE")
    if classroom.forgotten:
        shown_names = ", ".join(classroom.forgotten[:5])
        more = f" and {len(classroom.forgotten) - 5} more" if len(classroom.forgotten) > 5 \
            else ""
        lines.append(f"           forgot {len(classroom.forgotten)} enrolments nobody used for "
                     f"the enrolment time ({shown_names}{more})")
    if anonymous and state.saved_s is None:
        lines.append("           (--class N keeps its state per folder and port; "
                     "--state FILE names one)")
    return lines


def public_host(args: argparse.Namespace) -> str:
    """The one host name or address every URL the server prints and writes names.

    ``--public-host``; else, bound to every interface, this machine's address on the
    network (``lan.lan_addresses``: what students' machines reach, where its name often does
    not resolve), ``localhost`` if it has none; bound to loopback, ``localhost``; else the
    address it is bound to.
    """
    given = getattr(args, "public_host", None)
    if given:
        return str(given)
    bind = args.host
    if bind in ("0.0.0.0", "::", ""):
        addresses = lan_addresses()
        return addresses[0] if addresses else "localhost"
    return "localhost" if bind in ("127.0.0.1", "::1", "localhost") else bind


def dashboard_url(host: str, http_port: int, admin_token: str) -> str:
    """The class's dashboard URL with the instructor's token.

    The page keeps the token for its tab and takes it out of the address bar.
    """
    return f"http://{url_name(host)}:{http_port}/class?token={admin_token}"


def instructor_links_path(handout: Path) -> Path:
    """The instructor's own links beside the handout: ``links.csv`` -> ``links.instructor.txt``."""
    return handout.with_name(f"{handout.stem}.instructor.txt")


def write_links(path: Path, classroom: Classroom, host: str, http_port: int,
                ws_port: int) -> None:
    """The students' handout: one row per robot (name, page, admin page, WebSocket, token).

    The page URL carries the robot's token in its fragment (``#token=``: never sent to a
    server; the page keeps it and takes it out of the address bar). No instructor's token,
    ever (``write_instructor_links`` writes those). CSV with LF line ends (a shell reading a
    token reads no carriage return); written atomically (a temporary file renamed over it) with mode
    0600; a symbolic link at ``path`` is refused, never written through.

    Raises:
        ConfigError: the file cannot be written, or ``path`` is a symbolic link.
    """
    name_in_url = url_name(host)
    text = io.StringIO(newline="")
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(["name", "page", "admin_page", "websocket", "token"])
    for name in classroom.students:
        token = classroom.token(name)
        page = f"http://{name_in_url}:{http_port}{ROBOTS_PREFIX}{name}/"
        writer.writerow([name, f"{page}#token={token}", f"{page}admin?token={token}",
                         f"ws://{name_in_url}:{ws_port}{ROBOTS_PREFIX}{name}", token])
    write_private(path, text.getvalue(), "--links")


def write_instructor_links(path: Path, host: str, http_port: int, ws_port: int,
                           admin_token: str) -> None:
    """The instructor's own links: the dashboard, the root WebSocket and the token.

    ``KEY=VALUE`` lines (a shell may ``source`` it), LF line ends, mode 0600, written as
    ``write_private`` writes.
    """
    lines = ["# websim: the instructor's links; keep this file to yourself (its token rules "
             "every robot)",
             f"dashboard={dashboard_url(host, http_port, admin_token)}",
             f"websocket=ws://{url_name(host)}:{ws_port}/",
             f"token={admin_token}"]
    write_private(path, "\n".join(lines) + "\n", "--links")


def write_private(path: Path, text: str, what: str) -> None:
    """Write ``text`` to ``path`` atomically, mode 0600, never through a symbolic link.

    Raises:
        ConfigError: ``path`` is a symbolic link, or the file cannot be written.
    """
    if path.is_symlink():
        raise ConfigError(f"{what} {path}: is a symbolic link; websim writes tokens only to "
                          "a file of its own (remove the link or name another file)")
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW,
                             0o600)
        with os.fdopen(descriptor, "w", encoding="utf-8", newline="") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise ConfigError(f"{what} {path}: cannot write: {error.strerror}") from None


def url_name(hostname: str) -> str:
    """A host name as it stands in a URL (IPv6 addresses in brackets)."""
    return f"[{hostname}]" if ":" in hostname else hostname
