"""``websim serve``: the simulator in real time behind rosbridge, and the web interface.

The whole platform with one command and no ROS install: a rosbridge v2 WebSocket on
``--ws-port`` (9090) and the browser pages on ``--http-port`` (8080).
"""

from __future__ import annotations

import argparse
import asyncio
import errno
import gc
import importlib.util
import ipaddress
import logging
import math
import os
import re
import signal
import sys
from collections.abc import Callable, MutableMapping
from pathlib import Path
from typing import Protocol

from classroom.class_server import ClassServer
from classroom.nginx_config import parse_worker, worker_for, worker_ring
from classroom.registry import DEFAULT_IDLE_PAUSE_S, DEFAULT_MAX_ROBOTS
from classroom.state import DEFAULT_ENROLMENT_HOURS
from physics import TICK_PERIOD_S, ConfigError
from physics.shipped import shipped
from physics.world import LOCALIZATIONS
from ros_nodes.recording import DEFAULT_CLIENT_MB_PER_MIN, DEFAULT_MAX_MB, Recorder
from ros_nodes.robot_interface import NODE_NAME
from ros_nodes.sim_clock import SPEED_MAX
from rosbridge.core.limits import ClientLimits, OriginPolicy, TrustedProxies
from rosbridge.core.schema import NAME_TOKEN
from rosbridge.graph.names import RELAY_NODE_NAME
from rosbridge.transport.front import start_websocket
from websim.code_routes import code_routes
from websim.http_server import start_http
from websim.lan import lan_addresses, qr_lines
from websim.robot_server import SimServer
from websim.sites import Site, dashboard_url, public_host, url_name
from websim.submissions import SubmitLimits

WEB_DIR = shipped("websim", "web-interface")
"""The static frontend."""

log = logging.getLogger("websim.serve")

EVENT_LOOPS = ("uvloop", "asyncio")
"""The event loops ``websim serve`` runs on (``--event-loop``)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``websim serve`` (besides world, mode, params and seed)."""
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to bind (default 127.0.0.1; 0.0.0.0 serves a classroom)")
    parser.add_argument("--ws-port", type=int, default=9090,
                        help="rosbridge WebSocket port (default 9090)")
    parser.add_argument("--http-port", type=int, default=8080,
                        help="web interface port (default 8080)")
    parser.add_argument("--admin-token", default=None,
                        help="secret for admin rights (the instructor's, in a class): at least "
                             "20 characters of A-Z a-z 0-9 . _ ~ -, mixing three of lower "
                             "case, upper case, digits and symbols; a weaker one is refused "
                             "(websim token prints one). Default: a class keeps the one of "
                             "its state file (made at its first start); one robot, a random "
                             "one at each start; printed at start")
    defaults = ClientLimits()
    parser.add_argument("--max-rate", type=_positive(float), default=defaults.max_rate,
                        metavar="N",
                        help="messages/s one client may send before it is disconnected "
                             f"(close 1008; default {defaults.max_rate:g}; a message counts "
                             "once per started 16 KiB)")
    parser.add_argument("--max-frame-bytes", type=_positive(int),
                        default=defaults.max_frame_bytes, metavar="BYTES",
                        help="largest incoming WebSocket message; larger ones close the "
                             f"connection (1009; default {defaults.max_frame_bytes})")
    parser.add_argument("--max-queued-bytes", type=_positive(int),
                        default=defaults.max_queued_bytes, metavar="BYTES",
                        help="most bytes waiting to be sent to one client: beyond it its "
                             "oldest topic messages are dropped for the newest; replies beyond "
                             "it close it (1008; default "
                             f"{defaults.max_queued_bytes})")
    parser.add_argument("--max-clients", type=_positive(int), default=defaults.max_clients,
                        metavar="N",
                        help="WebSocket clients served at once; more are refused with HTTP "
                             f"503 (default {defaults.max_clients})")
    parser.add_argument("--max-connections-per-address", type=_positive(int),
                        default=defaults.address_max_connections, metavar="N",
                        help="WebSocket connections one client address may hold at once; "
                             "more are refused with HTTP 429 (default "
                             f"{defaults.address_max_connections}: a class of 40 behind one NAT "
                             "address, ~4 each; raise it for a larger class behind one address)")
    parser.add_argument("--max-rate-per-address", type=_positive(float),
                        default=defaults.address_max_rate, metavar="N",
                        help="messages/s all the connections of one client address may send "
                             "together; beyond it their frames wait (default "
                             f"{defaults.address_max_rate:g}; raise it with "
                             "--max-connections-per-address)")
    parser.add_argument("--handling-share-per-robot", type=_positive(float),
                        default=defaults.robot_handling_share, metavar="FRACTION",
                        help="fraction of a core the server spends on the input of all the "
                             "clients of one robot together, from every address; beyond it "
                             "their frames wait, so no robot's crowd slows the others "
                             f"(default {defaults.robot_handling_share:g})")
    parser.add_argument("--trusted-proxy", action="append", default=[], metavar="ADDR[/BITS]",
                        help="a reverse proxy (nginx) whose X-Real-IP / X-Forwarded-For name "
                             "the client, so per-address budgets apply to students, not to "
                             "the proxy; repeatable. Default: none (those headers are ignored)")
    parser.add_argument("--allow-origin", action="append", default=[], metavar="URL",
                        help="also accept browser pages from this origin (e.g. "
                             "http://robot.example:8080); repeatable; '*' accepts any page. "
                             "Default: the pages this server serves, pages from this machine "
                             "(localhost, any port) and clients without an Origin (roslibpy, "
                             "Node)")
    parser.add_argument("--class", dest="class_spec", metavar="ROSTER|N", default=None,
                        help="host a class: one independent robot per line of the roster "
                             "file (name[,world[,token]]), or N robots robot01..robotNN; robot "
                             "NAME is at ws://HOST:9090/robots/NAME and "
                             "http://HOST:8080/robots/NAME/")
    parser.add_argument("--open-class", action="store_true",
                        help="with --class: a new name enrols on its first connection, which "
                             "is handed that robot's token (its page keeps it); nobody else "
                             "can take the name afterwards")
    parser.add_argument("--arena", action="store_true",
                        help="with --class: every student's robot in the one --world, where "
                             "they see each other (LiDAR) and collide; a robot the world "
                             "file places (its robots: list) starts there, the others at the "
                             "nearest free place to its start; see docs/arena.md")
    parser.add_argument("--student-spawn", type=int, default=0, metavar="N",
                        help="with --arena: a student may spawn up to N robots of their own "
                             "into the arena (simulation_interfaces' SpawnEntity, turtlesim's "
                             "/spawn) and delete them (default 0: only the instructor spawns)")
    parser.add_argument("--open-drive", action="store_true",
                        help="with --class: any connection may drive and reset any robot "
                             "(default: only with the robot's token or the instructor's; "
                             "without one a connection may only watch)")
    parser.add_argument("--state", default=None, metavar="FILE",
                        help="with --class: the SQLite file keeping the class's secret, the "
                             "instructor's token, enrolments and each robot's parameters, "
                             "pause and pose across restarts (default: "
                             "ROSTER.websim-state.sqlite beside the roster; for --class N, "
                             "one per folder and port in ~/.local/share/websim/, started "
                             "anew when last saved more than 12 h ago; the banner says what "
                             "was restored and from where)")
    parser.add_argument("--fresh", action="store_true",
                        help="with --class: start the class over: new secret (new robot "
                             "tokens), new instructor's token (unless --admin-token), no "
                             "enrolments, every robot at its spawn pose")
    parser.add_argument("--enrolment-hours", type=_positive(float),
                        default=DEFAULT_ENROLMENT_HOURS, metavar="H",
                        help="with --open-class: a name nobody connected to for H hours is "
                             "forgotten at the next start, with its robot (default "
                             f"{DEFAULT_ENROLMENT_HOURS:g})")
    parser.add_argument("--max-robots", type=_positive(int), default=DEFAULT_MAX_ROBOTS,
                        metavar="N", help="most robots an open class holds (default "
                                          f"{DEFAULT_MAX_ROBOTS})")
    parser.add_argument("--idle-pause", type=_positive(float), default=DEFAULT_IDLE_PAUSE_S,
                        metavar="S", help="with --class: a robot nobody has been connected to "
                                          "for S seconds stops ticking, keeping its state "
                                          f"(default {DEFAULT_IDLE_PAUSE_S:g})")
    parser.add_argument("--links", default=None, metavar="FILE",
                        help="with --class: write FILE, a CSV to hand out (every robot's "
                             "page, admin page with its token, WebSocket URL and token; never "
                             "the instructor's token), and beside it FILE's name with "
                             ".instructor.txt, yours (the dashboard and the instructor's "
                             "token); both mode 0600")
    parser.add_argument("--worker", action="store_true",
                        help="with --class: one of several processes behind nginx (websim "
                             "nginx-config): a robot is made when first routed here")
    parser.add_argument("--worker-index", type=int, default=None, metavar="K",
                        help="with --worker and --workers: this worker is the K-th (0-based) "
                             "of websim nginx-config --workers; it makes only the robots nginx "
                             "routes to it, and refuses other names (404)")
    parser.add_argument("--workers", nargs="+", default=None, metavar="HOST:HTTP:WS",
                        help="with --worker-index: every worker, as given to websim "
                             "nginx-config --workers, in the same order")
    parser.add_argument("--public-ws-port", type=int, default=None, metavar="PORT",
                        help="the WebSocket port students reach (a proxy's) for the pages' "
                             "config.json and the links file (default --ws-port)")
    parser.add_argument("--public-http-port", type=int, default=None, metavar="PORT",
                        help="the page port students reach (a proxy's), for the links file "
                             "(default --http-port)")
    parser.add_argument("--localization", choices=LOCALIZATIONS, default=None,
                        help="who publishes map -> odom on /tf: 'perfect', websim, from the "
                             "ground truth; 'none', a localizer (AMCL, slam_toolbox), as on the "
                             "real robot (default: the world's 'localization', else none)")
    parser.add_argument("--public-host", type=_host_name, default=None, metavar="HOST",
                        help="the host name or address students reach (this machine's on "
                             "the network, or a proxy's), in every URL the banner and the "
                             "links files give (default: with --host 0.0.0.0, this machine's "
                             "address on the network; else --host)")
    parser.add_argument("--record", type=Path, default=None, metavar="DIR",
                        help="record every robot to a rosbag2 of its own (MCAP storage: ros2 "
                             "bag, Foxglove and Lichtblick open it) in DIR/NAME_<UTC time>/ "
                             "(NAME 'robot' for a single robot); see docs/recording.md")
    parser.add_argument("--record-max-mb", type=_positive(float), default=DEFAULT_MAX_MB,
                        metavar="MB",
                        help="with --record: a robot's bag reaching this size on disk is "
                             f"closed and recording it stops (default {DEFAULT_MAX_MB:g})")
    parser.add_argument("--record-client-mb-per-min", type=_positive(float),
                        default=DEFAULT_CLIENT_MB_PER_MIN, metavar="MB",
                        help="with --record: what a robot's clients (their /cmd_vel) may add "
                             "to its bag per minute; beyond it their messages are left out, "
                             "said in the log and on the dashboard, and the robot's own "
                             f"topics go on recording (default {DEFAULT_CLIENT_MB_PER_MIN:g})")
    parser.add_argument("--ros", action="store_true",
                        help="also run the virtual_robot node on the ROS 2 graph and relay "
                             "rosbridge topics to it (needs rclpy: pip install '.[ros]')")
    parser.add_argument("--event-loop", choices=EVENT_LOOPS, default="asyncio",
                        help="the event loop: asyncio (the standard library's, the default) "
                             "or uvloop, if installed (measured: 10 %% less CPU at 500 "
                             "clients, but ticks start later; benchmarks/bench_server.py)")
    submit = SubmitLimits()
    parser.add_argument("--grade-jobs", type=_not_negative, default=submit.jobs, metavar="N",
                        help="the Code panel's Submit: programs graded at once, each by "
                             "websim grade in its sandbox, at a lower CPU priority than the "
                             f"robots (default {submit.jobs}; 0 turns Submit off)")
    parser.add_argument("--grade-per-hour", type=_positive(int), default=submit.per_hour,
                        metavar="N", help="submissions one student may make in any hour "
                                          f"(default {submit.per_hour})")
    parser.add_argument("--web-dir", type=Path, default=WEB_DIR, help=argparse.SUPPRESS)
    parser.add_argument("--log-level", default="warning",
                        choices=["debug", "info", "warning", "error"],
                        help="logging level (default warning)")


def _positive(kind: type[float] | type[int]) -> Callable[[str], float]:
    """An argparse type: a number of ``kind`` greater than zero."""
    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from None
        if not (math.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(f"must be greater than 0, got '{text}'")
        return value
    return parse


HOST_NAME = re.compile(r"(?=.{1,253}$)[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?"
                       r"(?:\.[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*")
"""A DNS host name (RFC 1123 labels): what may stand as the host of a URL besides an IP."""


def _host_name(text: str) -> str:
    """An argparse type: a host name or an IP address, as it may stand in a URL."""
    try:
        return str(ipaddress.ip_address(text))
    except ValueError:
        if HOST_NAME.fullmatch(text):
            return text
    raise argparse.ArgumentTypeError(f"expected a host name or an IP address, got '{text}'")


def limits_from(args: argparse.Namespace) -> ClientLimits:
    """The client limits the options ask for."""
    return ClientLimits(max_rate=args.max_rate, max_frame_bytes=args.max_frame_bytes,
                        max_queued_bytes=args.max_queued_bytes, max_clients=args.max_clients,
                        address_max_connections=args.max_connections_per_address,
                        address_max_rate=args.max_rate_per_address,
                        robot_handling_share=args.handling_share_per_robot)


def _not_negative(text: str) -> int:
    """An argparse type: a whole number, 0 or more."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got '{text}'") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected 0 or more, got {value}")
    return value


def submit_limits(args: argparse.Namespace) -> SubmitLimits:
    """Submit's bounds as the options ask (``--grade-jobs``, ``--grade-per-hour``)."""
    return SubmitLimits(jobs=getattr(args, "grade_jobs", SubmitLimits.jobs),
                        per_hour=getattr(args, "grade_per_hour", SubmitLimits.per_hour))


def owned_names(args: argparse.Namespace) -> Callable[[str], bool] | None:
    """``--worker-index K --workers ...``: whether nginx routes a robot's name to this worker.

    Raises:
        ConfigError: one without the other, or K not one of the workers.
    """
    index, workers = getattr(args, "worker_index", None), getattr(args, "workers", None)
    if index is None and workers is None:
        return None
    if index is None or not workers:
        raise ConfigError("--worker-index and --workers go together")
    peers = [parse_worker(text) for text in workers]
    if not 0 <= index < len(peers):
        raise ConfigError(f"--worker-index {index}: there are {len(peers)} workers (0-based)")
    ring = worker_ring(peers)
    return lambda name: worker_for(name, ring) == index


def proxies_from(args: argparse.Namespace) -> TrustedProxies:
    """The trusted proxies the options name (``--trusted-proxy``).

    Raises:
        ConfigError: one is no address or network.
    """
    try:
        return TrustedProxies.parse(args.trusted_proxy)
    except ValueError as error:
        raise ConfigError(f"--trusted-proxy: {error}") from None


def origins_from(args: argparse.Namespace) -> OriginPolicy:
    """The origin policy the options ask for.

    Behind a proxy (``--public-http-port``) the pages students open are the proxy's, on its
    port, at the name they typed: a worker bound to 127.0.0.1 refused every page but this
    machine's own (a student's page at http://HOST:8080/robots/NAME/ got 403).
    """
    public_http_port = getattr(args, "public_http_port", None)
    return OriginPolicy.default(args.host, public_http_port or args.http_port,
                                args.allow_origin, proxied=public_http_port is not None)


async def serve_forever(args: argparse.Namespace, site: Site, token: str) -> int:
    """Run until SIGINT or SIGTERM; returns the exit code."""
    server = site.front
    server.proxies = proxies_from(args)
    if isinstance(server, ClassServer):
        server.owns = owned_names(args)
    server.refusals.install()
    robot = site.robot
    try:
        websocket = await start_websocket(server, args.host, args.ws_port)
    except OSError as error:
        return _port_error("WebSocket", args.host, args.ws_port, error)
    code = code_routes(site.classroom, server.is_admin_token, server.proxies,
                       submit_limits(args))
    try:
        http = await start_http(
            args.host, args.http_port, args.web_dir,
            server.health_for, site, server.limits, server.proxies, code)
    except OSError as error:
        websocket.close()
        return _port_error("HTTP", args.host, args.http_port, error)

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    ros: RosGraph | None = None
    if args.ros:
        try:
            ros = _start_ros(site, loop)
            site.ros = ros
        except RuntimeError as error:
            print(f"websim: error: {error}", file=sys.stderr)
            websocket.close()
            await http.close()
            return 1
    for signum in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(signum, stop.set)
    if site.recorder is not None:
        site.recorder.start()
        site.schedule().pacers.append(site.recorder.caught_up)  # lossless above real time
    tasks = [asyncio.create_task(server.run_ticks()), asyncio.create_task(code.queue.run())]
    if ros is not None:
        tasks.append(asyncio.create_task(_poll_graph(ros)))

    # what students and the instructor type, one host everywhere (the address students
    # reach: --public-host, else this machine's on the network); behind a proxy, its ports
    public = public_host(args)
    host = url_name(public)
    http_port = args.public_http_port or args.http_port
    ws_port = args.public_ws_port or args.ws_port
    single = site.classroom is None
    if single:
        print(f"websim: {site.headline}", flush=True)
        print(f"  page:      http://{host}:{http_port}/", flush=True)
        print(f"  websocket: ws://{host}:{ws_port}/", flush=True)
        if site.replay is None:
            print(f"  admin:     http://{host}:{http_port}/admin?token={token}", flush=True)
    else:
        print(f"websim: a class, {args.mode} mode", flush=True)
        print(f"  pages:     http://{host}:{http_port}/robots/NAME/", flush=True)
        print(f"  websocket: ws://{host}:{ws_port}/robots/NAME", flush=True)
        print(f"  admin:     http://{host}:{http_port}/robots/NAME/admin?token={token} "
              "(the instructor's token: every robot)", flush=True)
        print(f"  dashboard: {dashboard_url(public, http_port, token)}", flush=True)
        if args.public_http_port or args.public_ws_port:
            print(f"  (this process listens on {args.http_port} and {args.ws_port}; the "
                  "addresses above are the proxy's)", flush=True)
    speed = getattr(args, "speed", None)
    if speed is not None:
        pace = ("as fast as the host and the clients allow" if speed == SPEED_MAX
                else f"{speed:g}x real time")
        print(f"  clock:     sim time, {pace}: /clock and every stamp start at the wall time "
              f"of the start and move {TICK_PERIOD_S * 1000:g} ms per tick", flush=True)
    for line in site.banner:
        print(f"  {line}", flush=True)
    if ros is not None:
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        if robot is not None:
            print(f"  ROS 2:     node {NODE_NAME} and relay /{RELAY_NODE_NAME} on "
                  f"ROS_DOMAIN_ID {domain}", flush=True)
        else:
            print(f"  ROS 2:     node /NAME{NODE_NAME} per robot, topics under /NAME, "
                  f"frames NAME/odom, NAME/base_link, NAME/laser, on ROS_DOMAIN_ID {domain}",
                  flush=True)
            print("  ROS 2:     any node in this ROS domain can reach every robot's topics "
                  "(tokens guard only the WebSocket); discovery range "
                  f"{os.environ.get(DISCOVERY_RANGE, 'SUBNET')}", flush=True)
    if args.host in ("0.0.0.0", "::"):
        if single or getattr(args, "open_drive", False):
            print("  listening on every network interface: anyone who can reach this machine "
                  "can drive the robots; only a token can change their parameters", flush=True)
        else:
            print("  listening on every network interface: anyone who can reach this machine "
                  "can watch the robots; driving one needs its token ("
                  + ("the links file" if getattr(args, "links", None) else
                     "--links FILE writes every robot's; the dashboard's Token button shows "
                     "one") + ")", flush=True)
        _print_lan_urls(args, single, public, http_port)
    if not (args.web_dir / "node_modules" / "roslib").is_dir():
        print(f"websim: warning: the page's libraries are not installed in {args.web_dir}; "
              "run: npm ci --prefix web-interface", flush=True)
    print("websim: ready (Ctrl+C to stop)", flush=True)
    freeze_start_up_objects()

    await stop.wait()
    for task in tasks:
        task.cancel()
    if ros is not None:
        site.ros = None
        ros.stop()
    websocket.close()
    await websocket.wait_closed()
    await http.close()
    site.close()
    if site.recorder is not None:
        for line in site.recorder.summary_lines():
            print(f"websim: recorded {line}", flush=True)
    print("websim: stopped", flush=True)
    return 0


def _print_lan_urls(args: argparse.Namespace, single_robot: bool, host: str,
                    http_port: int) -> None:
    """Where students are sent (and, for one robot, a QR code of its page).

    Every URL above names one host; this says which other addresses the machine has, if
    any, so an instructor whose students are on another network can name that one
    (``--public-host``).
    """
    addresses = lan_addresses()
    if not addresses and not getattr(args, "public_host", None):
        print("  no network address found besides loopback: students on other machines "
              "cannot reach this one", flush=True)
        return
    others = [address for address in addresses if address != host]
    host = url_name(host)
    if others:
        print(f"  also at:   {', '.join(others)} (this machine's other addresses; "
              "--public-host ADDRESS names the one students reach in every URL)", flush=True)
    if single_robot:
        page = f"http://{host}:{http_port}/"
        print(f"  {page} as a QR code:", flush=True)
        for line in qr_lines(page):
            print(f"  {line}", flush=True)


def freeze_start_up_objects() -> None:
    """Exempt what start-up built from the garbage collector's full collections.

    The modules, message definitions (rosbags), worlds and robots live as long as the
    process; left in the collected generations, every full collection walks all of them:
    measured with 500 clients, 25-53 ms pauses, each a late tick (``gc.freeze``, Python's
    documented remedy for long-lived start-up state).
    """
    gc.collect()
    gc.freeze()


GRAPH_POLL_PERIOD_S = 0.5
"""How often subscriptions waiting for a topic to appear on the ROS graph look again."""


class RosGraph(Protocol):
    """rclpy running inside ``websim serve`` (``RosRuntime`` or ``ClassRosRuntime``)."""

    def poll(self) -> None:
        """Look again for graph topics that subscriptions wait for."""

    def stop(self) -> None:
        """Stop rclpy and destroy the nodes."""


def _start_ros(site: Site, loop: asyncio.AbstractEventLoop) -> RosGraph:
    """Start rclpy in-process (``--ros``); RuntimeError with the reason if it cannot.

    One robot: its node and the relay of its bridge to the graph. A class: a namespaced node
    per robot of the roster, whose LiDAR is then cast on every scan tick (a node listens to
    its robot: the robot builds all its messages).
    """
    try:
        from websim.ros_runtime import ClassRosRuntime, RosRuntime
    except ImportError as error:
        raise RuntimeError(f"--ros needs ROS 2's rclpy: {error} (pip install '.[ros]', "
                           "or source a ROS 2 installation)") from None
    runtime: RosRuntime | ClassRosRuntime
    if site.classroom is not None:
        localhost_only_discovery(os.environ)
    if site.robot is not None and isinstance(site.front, SimServer):
        runtime = RosRuntime(site.robot, site.front.bridge, loop, site.front.driver.writers,
                             site.ros_parameters, simulation=site.simulation,
                             read_only=site.graph_read_only)
    elif site.classroom is not None:
        hosts = site.class_hosts()
        unnamable = [name for name, _ in hosts if not NAME_TOKEN.fullmatch(name)]
        if unnamable:
            raise RuntimeError(f"--ros: robot names must also be ROS namespaces (a letter or _ "
                               f"first, no -): {', '.join(unnamable[:5])}")
        runtime = ClassRosRuntime([(name, host.robot) for name, host in hosts], loop,
                                  site.classroom.driver)
    else:
        raise RuntimeError("--ros: this site has neither a robot nor a class")
    runtime.start()
    return runtime


DISCOVERY_RANGE = "ROS_AUTOMATIC_DISCOVERY_RANGE"
"""ROS 2 (Iron and later): how far DDS discovery reaches."""


def localhost_only_discovery(environ: MutableMapping[str, str]) -> None:
    """A class's ROS graph stays on this machine unless the environment says otherwise.

    Any node in the ROS domain can publish a robot's ``/NAME/cmd_vel``: the robots' tokens
    guard the WebSocket only. Sets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (and, for
    Humble, ``ROS_LOCALHOST_ONLY=1``) when neither is set; export either to widen it.
    """
    if DISCOVERY_RANGE in environ or "ROS_LOCALHOST_ONLY" in environ:
        return
    environ[DISCOVERY_RANGE] = "LOCALHOST"
    if environ.get("ROS_DISTRO") == "humble":
        environ["ROS_LOCALHOST_ONLY"] = "1"


async def _poll_graph(ros: RosGraph) -> None:
    """Let subscriptions to topics nobody publishes yet start when a publisher appears."""
    while True:
        await asyncio.sleep(GRAPH_POLL_PERIOD_S)
        ros.poll()


def _port_error(what: str, host: str, port: int, error: OSError) -> int:
    if error.errno == errno.EADDRINUSE:
        reason = "is already in use (is another websim running?)"
    else:
        reason = f"cannot be opened: {error.strerror or error}"
    print(f"websim: error: {what} port {host}:{port} {reason}", file=sys.stderr)
    return 1


TOKEN_IN_TEXT = re.compile(r"(token=)[^&\s'\"#]+", re.IGNORECASE)
"""A token in a URL or query (``?token=...``, ``&token=...``) as any log line may quote it."""


class RedactTokens(logging.Filter):
    """Takes tokens out of every log line, at every level.

    ``websockets`` logs the request line ``GET /?token=...`` at debug: ``token=`` values and
    the known secrets are replaced before any handler writes the line.
    """

    def __init__(self, secrets: tuple[str, ...] = ()) -> None:
        super().__init__()
        self.secrets = tuple(secret for secret in secrets if secret)

    def filter(self, record: logging.LogRecord) -> bool:
        """Redact the record in place; always keep it."""
        text = record.getMessage()
        redacted = TOKEN_IN_TEXT.sub(r"\1<redacted>", text)
        for secret in self.secrets:
            redacted = redacted.replace(secret, "<redacted>")
        if redacted != text:
            record.msg, record.args = redacted, None
        return True


def redact_tokens(*secrets: str) -> None:
    """Install ``RedactTokens`` on every handler of the root logger."""
    for handler in logging.getLogger().handlers:
        handler.addFilter(RedactTokens(secrets))


def recorder_from(args: argparse.Namespace) -> Recorder | None:
    """The recorder ``--record DIR`` asks for (None without it).

    Raises:
        ConfigError: DIR cannot be made or written.
    """
    directory: Path | None = getattr(args, "record", None)
    if directory is None:
        return None
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ConfigError(f"--record {directory}: cannot make the folder: "
                          f"{error.strerror}") from None
    if not directory.is_dir() or not os.access(directory, os.W_OK | os.X_OK):
        raise ConfigError(f"--record {directory}: not a folder this user can write")
    return Recorder(directory, max_bytes=int(args.record_max_mb * 1e6),
                    client_bytes_per_minute=int(getattr(args, "record_client_mb_per_min",
                                                        DEFAULT_CLIENT_MB_PER_MIN) * 1e6))


def run(args: argparse.Namespace, site: Site, token: str) -> int:
    """Entry point of ``websim serve`` after the robots were built."""
    logging.basicConfig(level=args.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    redact_tokens(token)
    try:
        if args.event_loop == "uvloop":
            if importlib.util.find_spec("uvloop") is None:
                print("websim: error: --event-loop uvloop: uvloop is not installed "
                      "(pip install uvloop)", file=sys.stderr)
                return 2
            import uvloop

            exit_code: int = uvloop.run(serve_forever(args, site, token))
            return exit_code
        return asyncio.run(serve_forever(args, site, token))
    finally:
        if site.recorder is not None:  # every bag closed properly, however the server ended
            site.recorder.close()
