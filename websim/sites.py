"""What ``websim serve`` runs: one robot, or a class of them, with the documents its pages read.

A ``Site`` joins the WebSocket front (``SimServer`` or ``ClassServer``) to what the page
server fills itself (``LiveDocuments``: ``robot.json``, a class robot's ``config.json``) and
to the URLs the banner prints. ``single_robot`` and ``classroom_site`` build them.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from classroom.class_server import ClassServer, closest_names
from classroom.registry import (
    Classroom,
    Student,
    numbered_roster,
    read_roster,
)
from classroom.state import ClassState, class_identity, default_state_path
from physics import ConfigError, LidarParams, RobotParams
from ros_nodes.recording import SINGLE_ROBOT_NAME, Recorder
from ros_nodes.robot_description import robot_json
from ros_nodes.robot_host import TOKEN_SERVICE, RobotHost
from ros_nodes.robot_interface import ROBOTS_PREFIX
from ros_nodes.robot_server import SimServer
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.clock import Clock
from rosbridge.core.limits import ClientLimits, LatchedBytes, OriginPolicy
from rosbridge.transport.front import WebSocketFront
from rosbridge.transport.schedule import Schedule


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
    graph_read_only: str | None = None

    def close(self) -> None:
        """Close the recordings, save a class's state and release its file (at shutdown)."""
        if self.recorder is not None:
            self.recorder.close()
        if self.classroom is not None and self.classroom.state is not None:
            self.classroom.save()
            self.classroom.state.close()

    def schedule(self) -> Schedule:
        """The tick schedule the robots follow (a class's, or the single robot's host's)."""
        if self.classroom is not None:
            return self.classroom.schedule
        destination = self.front.route("/")
        assert not isinstance(destination, str)
        return destination[0].schedule

    def class_hosts(self) -> list[tuple[str, RobotHost]]:
        """The robots of a class, by name (none for a single robot)."""
        return [] if self.classroom is None else list(self.classroom)

    def has_robot(self, name: str) -> bool:
        """Whether ``/robots/NAME/`` is a robot's page (pages create no robot)."""
        return self.classroom is not None and self.classroom.knows(name)

    def why_no_robot(self, name: str) -> tuple[str, list[str]]:
        """Why ``/robots/NAME/`` is no robot's page, and the names it may have meant."""
        if self.classroom is None:
            return "this server runs one robot, not a class: its page is /", []
        known = list(self.classroom.students) + [hosted for hosted, _ in self.classroom]
        reason = self.front.why_unknown(name) if isinstance(self.front, ClassServer) else \
            f"no robot named '{name[:40]}' here"
        return reason, closest_names(name, known)

    def document(self, robot: str | None, name: str, hostname: str) -> str | None:
        """The live ``robot.json`` of a robot, and a class robot's ``config.json``.

        A class robot not hosted here (yet) is described as a new robot would be: behind a
        proxy the page and the WebSocket of one robot may be served by different workers.
        """
        if robot is None:
            if self.classroom is None:  # one robot: its description, and where its bridge is
                if name == "robot.json":
                    if self.robot is None:
                        return self.description
                    return robot_json(self.robot.sim.params, self.robot.sim.lidar.params)
                url = f"ws://{_url_name(hostname)}:{self.ws_port}/"
                return json.dumps({"about": "this server's robot, filled by websim serve: "
                                            "the bridge of the server that served the page",
                                   "ws": url, "adminWs": url})
            if name == "robot.json":  # a class's root (the dashboard): a class robot's
                return self.new_robot_json
            url = f"ws://{_url_name(hostname)}:{self.ws_port}/"
            return json.dumps({"about": "the instructor's view of this class, filled by "
                                        "websim serve; robotsPath: where its robots' pages are",
                               "ws": url, "adminWs": url, "robotsPath": ROBOTS_PREFIX})
        if name == "robot.json":
            host = dict(self.class_hosts()).get(robot)
            if host is None:
                return self.new_robot_json
            return robot_json(host.robot.sim.params, host.robot.sim.lidar.params)
        url = f"ws://{_url_name(hostname)}:{self.ws_port}{ROBOTS_PREFIX}{robot}"
        config: dict[str, object] = {"about": f"robot {robot} of this class, filled by websim "
                                              "serve", "ws": url, "adminWs": url,
                                     "robot": robot}
        if self.classroom is not None and self.classroom.open_class:
            # the service that hands a newly enrolled robot's token to its first connection
            config["robotToken"] = {"name": TOKEN_SERVICE, "type": "websim/srv/RobotToken"}
        return json.dumps(config)


def single_robot(robot: VirtualRobot, token: str, limits: ClientLimits,
                 origins: OriginPolicy, ws_port: int = 9090,
                 recorder: Recorder | None = None) -> Site:
    """Today's websim: one robot at ``ws://HOST:9090/``.

    Args:
        robot: the robot to serve.
        token: the admin token.
        limits: the bounds every client lives within.
        origins: which web pages may connect.
        ws_port: where the pages are told its bridge is: the server's port, or a proxy's.
        recorder: records the robot (``--record``); None: nothing is recorded.
    """
    server = SimServer(robot, token, limits=limits, origins=origins)
    site = Site(server, robot=robot, ws_port=ws_port, recorder=recorder,
                headline=f"world '{robot.sim.world.name}', {robot.sim.mode} mode")
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
                   new_robot_params: tuple[RobotParams, LidarParams], token: str,
                   limits: ClientLimits, origins: OriginPolicy,
                   clock: Clock | None = None, recorder: Recorder | None = None) -> Site:
    """A class: robot NAME at ``ws://HOST:9090/robots/NAME``, its page at ``/robots/NAME/``.

    Writes the links file when ``--links`` asks for one.

    Args:
        args: the options of ``websim serve``.
        make_robot: builds a student's robot (with ``clock``).
        new_robot_params: the robot and LiDAR a new robot gets (its ``robot.json``).
        token: the instructor's token (robots' tokens derive from the class's own secret,
            kept in its state file: ``--state``, ``--fresh``).
        limits: the bounds every client lives within.
        origins: which web pages may connect.
        clock: the server's one clock, the robots' too. Default: wall time.
        recorder: records every robot (``--record``); None: nothing is recorded.

    Raises:
        ConfigError: a bad roster or world (the message names the file and line).
    """
    roster = class_roster(args.class_spec)
    state_path = Path(args.state) if getattr(args, "state", None) else default_state_path(
        args.class_spec, args.ws_port if args.worker else None)
    state = ClassState(state_path, class_identity(args.class_spec),
                       fresh=getattr(args, "fresh", False))
    try:
        classroom = Classroom(roster, make_robot, open_class=args.open_class,
                              max_robots=args.max_robots, idle_pause_s=args.idle_pause,
                              lazy=args.worker, clock=clock, state=state,
                              latched=LatchedBytes.for_server(limits),
                              recorder=recorder)
    except BaseException:
        state.close()
        raise
    open_drive = getattr(args, "open_drive", False)
    site = Site(ClassServer(classroom, token, limits=limits, origins=origins,
                            open_drive=open_drive),
                ws_port=args.public_ws_port or args.ws_port, classroom=classroom,
                new_robot_json=robot_json(*new_robot_params), recorder=recorder)
    names = list(classroom.students)
    notes = [note for note, wanted in (("new names enrol (open class)", args.open_class),
                                       ("a worker: a robot is made when first routed here",
                                        args.worker)) if wanted]
    if open_drive:
        notes.append("anyone may drive any robot (--open-drive)")
    first, last = (names[0], names[-1]) if names else ("none yet", "none yet")
    site.banner.append(f"class:     {len(names)} robots ({first} ... {last}), each at "
                       f"{ROBOTS_PREFIX}NAME/ on both ports" + "".join(f"; {n}" for n in notes))
    site.banner.append(f"state:     {state.path} ("
                       + ("restored: robots as they were, same tokens" if state.restored
                          else "new: saved every few seconds; --fresh starts over") + ")")
    if recorder is not None:
        site.banner.append(f"recording: {recorder.directory}/NAME_<UTC time>/ per robot "
                           "(rosbag2, MCAP storage)")
    if args.links is not None:
        host = getattr(args, "public_host", None) or public_host(args.host)
        write_links(Path(args.links), classroom, host,
                    args.public_http_port or args.http_port, site.ws_port, token)
        site.banner.append(f"links:     {args.links} (name, page, admin page with the robot's "
                           "token, WebSocket, token; last, #instructor: the dashboard), at "
                           f"{_url_name(host)} (--public-host: the name or address students "
                           "reach)")
    return site


def public_host(bind: str) -> str:
    """The host name students use: the machine's name when bound to every interface."""
    if bind in ("0.0.0.0", "::", ""):
        return socket.gethostname()
    return "localhost" if bind == "127.0.0.1" else bind


def dashboard_url(host: str, http_port: int, admin_token: str) -> str:
    """The class's dashboard URL with the instructor's token.

    The page keeps the token for its tab and takes it out of the address bar.
    """
    return f"http://{_url_name(host)}:{http_port}/class?token={admin_token}"


INSTRUCTOR_ROW = "#instructor"
"""The links file's last row: the dashboard with the instructor's token (not a robot name:
a ``#`` is never one)."""


def write_links(path: Path, classroom: Classroom, host: str, http_port: int,
                ws_port: int, admin_token: str | None = None) -> None:
    """The instructor's hand-out: one row per robot (name, page, admin page, WebSocket, token).

    The page URL carries the robot's token in its fragment (``#token=``: never sent to a
    server; the page keeps it and takes it out of the address bar). With ``admin_token``, a
    last row ``#instructor`` holds the dashboard's URL with it (keep that row to yourself).
    Written atomically (a temporary file renamed over it) with mode 0600; a symbolic link at
    ``path`` is refused, never written through.

    Raises:
        ConfigError: the file cannot be written, or ``path`` is a symbolic link.
    """
    name_in_url = _url_name(host)
    text = io.StringIO(newline="")
    writer = csv.writer(text)
    writer.writerow(["name", "page", "admin_page", "websocket", "token"])
    for name in classroom.students:
        token = classroom.token(name)
        page = f"http://{name_in_url}:{http_port}{ROBOTS_PREFIX}{name}/"
        writer.writerow([name, f"{page}#token={token}", f"{page}admin?token={token}",
                         f"ws://{name_in_url}:{ws_port}{ROBOTS_PREFIX}{name}", token])
    if admin_token is not None:
        writer.writerow([INSTRUCTOR_ROW, dashboard_url(host, http_port, admin_token), "",
                         f"ws://{name_in_url}:{ws_port}/", admin_token])
    write_private(path, text.getvalue(), "--links")


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


def _url_name(hostname: str) -> str:
    """A host name as it stands in a URL (IPv6 addresses in brackets)."""
    return f"[{hostname}]" if ":" in hostname else hostname
