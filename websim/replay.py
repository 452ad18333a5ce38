"""``websim replay FILE.mcap|DIR``: a recording played back as its robot's topics, to the page.

An instructor sees what a student's robot did without a ROS install: the recording's
messages (``--record``'s bags, or any rosbag2 with the robot's topics) are published on the
embedded bridge at the pace they were recorded, or ``--speed`` times faster, and the robot's
page (``http://HOST:8080/``) draws them as it draws a live robot: the view (walls, pose,
trail, scan) and the plots. Topics recorded as transient local (``/tf_static``, ``/world``)
are latched, as on the robot, so a page opened midway gets them. The bridge owns every
recorded topic: a page's teleop is refused (nothing drives a recording), and the robot's
services are absent (the page falls back on ``robot.json``'s limits). ``robot.json`` is the
recorded robot's (``custom_data`` of the bag), else the shipped robot's. The recording's
time runs while a client is connected: it starts when the first page opens and waits while
nobody watches. At the end the last picture stays; ``--loop`` starts over.

It is a player: the service ``/websim/replay`` (``websim/srv/Replay``: ``{command: play |
pause | seek | speed | status, position_s, speed}``, answered with the player's status) plays,
pauses, seeks and sets the speed, for every client at once (what a projector shows: serve it
on 127.0.0.1, the default, or to a room that may touch it); the page knows a replay by its
``config.json`` (``replay``) and shows these controls instead of driving.

Messages are read and decoded as they fall due (rosbags' reader and the bridge's typestore),
never all at once: an hour's bag plays in the memory of a few messages.
"""

from __future__ import annotations

import argparse
import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError

from heartbeat.schedule import Schedule
from physics import TICK_PERIOD_S, ConfigError
from physics.validation import shown
from ros_nodes.bag_bounds import check_bag
from ros_nodes.recording import ROBOT_JSON_KEY
from ros_nodes.robot_description import robot_json
from ros_nodes.robot_interface import RESERVED_NAMESPACES
from rosbridge.core.bridge import Bridge
from rosbridge.core.clock import Clock, WallClock
from rosbridge.core.errors import ServiceError
from rosbridge.core.faults import Faults
from rosbridge.core.limits import OriginPolicy
from rosbridge.core.session import Session
from rosbridge.msgs import cdr, definitions
from rosbridge.msgs.checks import MessageError
from rosbridge.msgs.values import Message
from rosbridge.transport.front import Destination, WebSocketFront
from websim.sites import REPLAY_SERVICE, REPLAY_SERVICE_TYPE, Site

log = logging.getLogger("websim.replay")

REPLAY_COMMANDS = ("play", "pause", "seek", "speed", "status")
"""What the player's service does."""

MIN_REPLAY_SPEED, MAX_REPLAY_SPEED = 0.05, 100.0
"""The speeds a replay plays at (times as recorded)."""

@dataclass(frozen=True)
class Played:
    """One message of a recording: its log time (ns), topic, type, and canonical dict."""

    log_time_ns: int
    topic: str
    type: str
    msg: Message


def plain(value: Any) -> Any:
    """A deserialized message (rosbags' classes, numpy arrays) as dicts and lists."""
    if hasattr(value, "__dataclass_fields__"):
        return {name: plain(getattr(value, name)) for name in value.__dataclass_fields__
                if not name.startswith("__") and not name.isupper()}  # constants are UPPER
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, list):
        return [plain(item) for item in value]
    return value


class Recording:
    """A rosbag2 to play: its topics, its time span, its messages in log-time order.

    Args:
        path: the bag's folder (``metadata.yaml`` and its files) or an ``.mcap`` file.

    Raises:
        ConfigError: no such bag, one that cannot be read, or one beyond the bounds of
            ``ros_nodes.bag_bounds`` (its chunks, its YAML): the reason says why.
    """

    def __init__(self, path: Path) -> None:
        if path.suffix == ".mcap" and (path.parent / "metadata.yaml").is_file():
            path = path.parent  # the folder's metadata knows its files
        if not path.exists():
            raise ConfigError(f"{path}: no such recording (a --record bag's folder or its "
                              ".mcap file)")
        self.path = path
        check_bag(path)  # nothing in it can make the reader exhaust memory
        try:
            self._reader = Reader(path)
            self._reader.open()
        except (ReaderError, OSError) as error:
            raise ConfigError(f"{path}: cannot read this recording: {error}") from None
        store = cdr.typestore()
        unknown = sorted({c.msgtype for c in self._reader.connections
                          if c.msgtype not in store.fielddefs})
        if unknown:
            log.warning("%s: skipping topics of types websim does not know: %s", path,
                        ", ".join(unknown))
        self.connections = [c for c in self._reader.connections
                            if c.msgtype in store.fielddefs]
        self.topics = {c.topic: c.msgtype for c in self.connections}
        """Each topic played and its type."""
        self.latched = frozenset(
            c.topic for c in self.connections
            if any(qos.durability == QosDurability.TRANSIENT_LOCAL
                   for qos in getattr(c.ext, "offered_qos_profiles", ())))
        """Topics recorded as transient local: latched on the bridge."""
        self.start_ns = self._reader.start_time
        self.duration_s = max(0, self._reader.end_time - self._reader.start_time) / 1e9
        self.message_count = self._reader.message_count
        metadata = getattr(self._reader.storage, "metadata", None)
        custom: dict[str, str] = getattr(metadata, "custom", None) or {}
        self.robot_json: str = custom.get(ROBOT_JSON_KEY) or robot_json()
        """The recorded robot's ``robot.json`` (the shipped robot's if the bag lacks it)."""
        self.name = custom.get("robot") or path.stem

    def messages(self, start_ns: int | None = None) -> Iterator[Played]:
        """Every message in log-time order (from ``start_ns`` on), decoded as it is reached.

        One that does not decode (a corrupt record) is skipped with a warning.
        """
        yield from self._decoded(self.connections, start_ns, None)

    def latched_before(self, stop_ns: int) -> list[Played]:
        """The last message of each latched topic recorded before ``stop_ns``.

        What a page that seeks there must hold (``/world``, ``/tf_static``, ``/map``).
        """
        latched = [c for c in self.connections if c.topic in self.latched]
        if not latched:
            return []
        last: dict[str, Played] = {}
        for played in self._decoded(latched, None, stop_ns):
            last[played.topic] = played
        return list(last.values())

    def _decoded(self, connections: list[Any], start_ns: int | None,
                 stop_ns: int | None) -> Iterator[Played]:
        store = cdr.typestore()
        for connection, log_time_ns, raw in self._reader.messages(connections, start=start_ns,
                                                                  stop=stop_ns):
            try:
                msg = definitions.canonical(
                    connection.msgtype,
                    plain(store.deserialize_cdr(raw, connection.msgtype)))
            except (MessageError, ValueError, KeyError, IndexError) as error:
                log.warning("%s: a %s message at %d ns does not decode: %s", self.path,
                            connection.topic, log_time_ns, error)
                continue
            yield Played(log_time_ns, connection.topic, connection.msgtype, msg)

    def close(self) -> None:
        """Close the bag's files."""
        self._reader.close()


class ReplayHost:
    """A recording's bridge and the ticks that publish what falls due.

    Its own ``Schedule``: a replay has no world to tick.

    Args:
        recording: the recording to play.
        speed: times real time (1: as recorded).
        loop: start over at the end (else the last picture stays).
        clock: the clock of the pace, the bridge's throttles and timeouts.
    """

    def __init__(self, recording: Recording, speed: float = 1.0, loop: bool = False,
                 clock: Clock | None = None) -> None:
        if not (math.isfinite(speed) and MIN_REPLAY_SPEED <= speed <= MAX_REPLAY_SPEED):
            raise ConfigError(f"--speed must be a number from {MIN_REPLAY_SPEED:g} to "
                              f"{MAX_REPLAY_SPEED:g}, got {speed}")
        self.recording = recording
        self.speed = speed
        self.loop = loop
        self.clock: Clock = clock or WallClock()
        self.faults = Faults()
        self.bridge = Bridge(clock=self.clock, faults=self.faults,
                             reserved_namespaces=RESERVED_NAMESPACES)
        for topic, type_name in recording.topics.items():
            self.bridge.topics.own(topic, type_name)  # a recording is not driven
        self.bridge.services.add(REPLAY_SERVICE, REPLAY_SERVICE_TYPE, self.control)
        self.playing = True
        """Whether the recording's time runs (while a client is connected)."""
        self.schedule = Schedule(TICK_PERIOD_S, clock=self.clock)
        self.played = 0
        """Messages published so far (this pass)."""
        self.passes = 0
        """Times the recording was played to its end."""
        self._messages: Iterator[Played] = iter(())
        self._next: Played | None = None
        self._position_s = 0.0
        self._last_tick_s = self.clock.monotonic_s()
        self._at_end = False
        self._restart()

    def _restart(self) -> None:
        self._messages = self.recording.messages()
        self._next = next(self._messages, None)
        self._position_s = 0.0
        self._at_end = False
        self.played = 0

    def seek(self, position_s: float) -> None:
        """Go to ``position_s`` (s from the recording's start, within it).

        The latched topics' messages recorded before it are published again first (a page
        that seeks before they were played still gets the walls and the laser's mount).
        """
        position_s = min(max(0.0, position_s), self.recording.duration_s)
        start_ns = self.recording.start_ns + round(position_s * 1e9)
        writers = self.schedule.writers
        for played in self.recording.latched_before(start_ns):
            writers.write(self.bridge.publish(played.topic, played.msg, latch=True))
        self._messages = self.recording.messages(start_ns)
        self._next = next(self._messages, None)
        self._position_s = position_s
        self._at_end = False

    def control(self, args: Any, session: Session) -> dict[str, Any]:
        """``/websim/replay``: play, pause, seek, set the speed, or say the status.

        Raises:
            ServiceError: an unknown command or a value out of its range (the reason says).
        """
        args = args if isinstance(args, dict) else {}
        command = args.get("command", "status")
        if command not in REPLAY_COMMANDS:
            raise ServiceError(f"{REPLAY_SERVICE}: command must be one of "
                               f"{', '.join(REPLAY_COMMANDS)}, got {shown(command)}")
        if command == "play":
            if self.finished:
                self._restart()
            self.playing = True
        elif command == "pause":
            self.playing = False
        elif command == "seek":
            position_s = args.get("position_s")
            if isinstance(position_s, bool) or not isinstance(position_s, (int, float)) or \
                    not 0.0 <= position_s <= self.recording.duration_s:
                raise ServiceError(f"{REPLAY_SERVICE}: position_s must be a number from 0 to "
                                   f"{self.recording.duration_s:g} (s), got {shown(position_s)}")
            self.seek(float(position_s))
        elif command == "speed":
            speed = args.get("speed")
            if isinstance(speed, bool) or not isinstance(speed, (int, float)) or \
                    not MIN_REPLAY_SPEED <= speed <= MAX_REPLAY_SPEED:
                raise ServiceError(f"{REPLAY_SERVICE}: speed must be a number from "
                                   f"{MIN_REPLAY_SPEED:g} to {MAX_REPLAY_SPEED:g}, got "
                                   f"{shown(speed)}")
            self.speed = float(speed)
        return self.status()

    def status(self) -> dict[str, Any]:
        """The player's state: playing, position and duration (s), speed, at its end, loop."""
        return {"playing": self.playing and not self.finished,
                "position_s": round(self.position_s, 3),
                "duration_s": round(self.recording.duration_s, 3), "speed": self.speed,
                "finished": self.finished, "loop": self.loop}

    @property
    def position_s(self) -> float:
        """Where the playback is in the recording (s from its start)."""
        return min(self._position_s, self.recording.duration_s)

    @property
    def finished(self) -> bool:
        """Whether every message was published (and no loop starts over)."""
        return self._next is None

    async def run_ticks(self) -> None:
        """Play, one tick every 50 ms, forever."""
        await self.schedule.run(self.tick)

    def tick(self, lateness_s: float = 0.0) -> None:
        """Publish every message whose time has come; never raises.

        The recording's time runs while a client is connected (``speed`` times the clock's):
        it starts with the first page or client, and waits while nobody watches.
        """
        now_s = self.clock.monotonic_s()
        elapsed_s, self._last_tick_s = now_s - self._last_tick_s, now_s
        if not self.bridge.sessions or not self.playing:
            self.bridge.services.expire()
            self.schedule.writers.write(self.bridge.take_flush())
            return
        self._position_s += elapsed_s * self.speed
        due_ns = self.recording.start_ns + self._position_s * 1e9
        batch: list[tuple[str, Message]] = []
        writers = self.schedule.writers
        try:
            while self._next is not None and self._next.log_time_ns <= due_ns:
                played = self._next
                if played.topic in self.recording.latched:
                    writers.write(self.bridge.publish(played.topic, played.msg, latch=True))
                else:
                    batch.append((played.topic, played.msg))
                self.played += 1
                self._next = next(self._messages, None)
            for flush in self.bridge.publish_many(batch, now_s - lateness_s):
                writers.write(flush)
            self.bridge.services.expire()
            writers.write(self.bridge.take_flush())
        except Exception as error:  # the replay's boundary: record, go on
            self.faults.record("replaying the recording", error)
        if self._next is None and not self._at_end:
            self._at_end = True
            self.passes += 1
            log.info("replay of %s reached its end (%d messages)", self.recording.path,
                     self.played)
            if self.loop:
                self._restart()

    def health(self) -> dict[str, Any]:
        """The replay's /healthz."""
        sessions = self.bridge.sessions
        report: dict[str, Any] = {
            "status": "degraded" if self.faults.degraded else "ok",
            "replay": str(self.recording.name),
            "position_s": round(self.position_s, 3),
            "duration_s": round(self.recording.duration_s, 3),
            "speed": self.speed,
            "playing": self.playing,
            "finished": self.finished,
            "passes": self.passes,
            "ticks": self.schedule.ticks_due(),
            "clients": len(sessions),
        }
        report.update(self.faults.report())
        return report


class ReplayServer(WebSocketFront):
    """The WebSocket front of a replay: the recording's robot at every path.

    Args:
        host: the replay.
        admin_token: the secret of admin rights (nothing of a replay needs them).
        origins: which web pages may connect.
    """

    def __init__(self, host: ReplayHost, admin_token: str,
                 origins: OriginPolicy | None = None) -> None:
        super().__init__(admin_token, origins=origins, clock=host.clock)
        self.host = host

    def route(self, path: str) -> tuple[Destination, str | None] | str:
        """The one recording, whatever the path."""
        return Destination(self.host.bridge, self.host.schedule), None

    async def run_ticks(self) -> None:
        """Play the recording."""
        await self.host.run_ticks()

    def health(self, full: bool = True) -> dict[str, Any]:
        """The replay's position, clients and faults."""
        return {**self.host.health(), "uptime_s": self._uptime_s()}


def replay_site(recording: Recording, speed: float, loop: bool, token: str,
                origins: OriginPolicy, ws_port: int) -> Site:
    """What ``websim serve``'s loop runs for a replay: its front, page documents, banner."""
    host = ReplayHost(recording, speed, loop)
    site = Site(ReplayServer(host, token, origins), ws_port=ws_port, replay=host,
                headline=f"replaying {recording.path} ({recording.duration_s:.1f} s, "
                         f"{recording.message_count} messages) at {speed:g}x"
                         + (", in a loop" if loop else ""),
                description=recording.robot_json)
    site.banner.append(f"topics:    {', '.join(sorted(recording.topics))} (a recording is "
                       "not driven: publishing on them is refused)")
    site.banner.append("player:    the page plays, pauses, seeks and sets the speed (for every "
                       f"viewer at once: {REPLAY_SERVICE})")
    return site


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``websim replay``."""
    parser.add_argument("recording", type=Path, metavar="FILE.mcap|DIR",
                        help="a bag of websim serve --record (its folder or its .mcap file)")
    parser.add_argument("--speed", type=float, default=1.0, metavar="X",
                        help="play X times faster than recorded, from "
                             f"{MIN_REPLAY_SPEED:g} to {MAX_REPLAY_SPEED:g} (default 1; the "
                             "page's player changes it)")
    parser.add_argument("--loop", action="store_true", help="start over at the end")
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to bind (default 127.0.0.1)")
    parser.add_argument("--ws-port", type=int, default=9090,
                        help="rosbridge WebSocket port (default 9090)")
    parser.add_argument("--http-port", type=int, default=8080,
                        help="web interface port (default 8080)")
    parser.add_argument("--log-level", default="warning",
                        choices=["debug", "info", "warning", "error"],
                        help="logging level (default warning)")
