"""``--record DIR``: one rosbag2 (MCAP storage) per robot per run, from the robot's tap.

A ``Recorder`` serves a whole server; ``record`` gives a robot its ``Recording``, which listens
on the robot's tap (``ros_nodes.tap``) and keeps every message of a recorded topic
(``robot_interface.RECORDED_TOPICS``: what clients sent it, what it published) with its
receive time from the robot's one clock (``Clock.stamp_s``: wall time, or sim time).

What this costs the tick: the tap's call and one append to the recording's bounded queue
(``MAX_QUEUED_MESSAGES``); a full queue drops the message and counts it (``lost``). Everything
else happens elsewhere: a feeder thread takes the queues every ``FLUSH_PERIOD_S`` and pipes
them, pickled in small batches, to a writer process (``ros_nodes.recording_writer``), which
serializes them to CDR and writes the bags. A process, not a thread: serializing is pure
Python, and a busy thread would take the interpreter lock from the ticks for up to its 5 ms
switch interval each time. What a recording still costs the server's process besides the
tap: the feeder's pickling (about 10 µs a message, in batches that hold the lock for well
under a millisecond) and the garbage collector's visits to messages kept until the feeder
takes them (measured at 40 robots: ``benchmarks/bench_recording.py``).

What clients add to a robot's bag is bounded per minute (``client_bytes_per_minute``, a
parameter of the ``Recorder`` and of each ``Recording``; ``--record-client-mb-per-min``):
the commands they send (``/cmd_vel``, whose ``TwistStamped`` header may carry a long frame
name; whatever crosses the tap but the robot's periodic topics). Beyond it their messages are
left out of the bag (counted, said once in the log and on the dashboard) while the robot's
own topics (its sensors, at their rates: the README's 0.9 MB per robot-minute) go on
recording. Before, a student's own traffic grew the bag at 3.2 MB/s until its cap stopped it.

A bag that cannot go on (a full disk, ``--record-max-mb``) stops alone, with one log line;
the simulation and the other recordings go on; the dashboard says so on the robot's card
(``Recording.notice``). ``close`` (at shutdown) writes what is queued
and closes every bag properly; if the server dies instead, the writer closes every bag when
its pipe ends. The writer is a ``spawn`` process: a script that starts a ``Recorder`` must
guard its main code with ``if __name__ == "__main__"`` (``websim``'s entry points do).

Bags are ``DIR/NAME_YYYYmmddTHHMMSSZ/`` (the robot's name, ``robot`` for a single robot, and
the UTC time it started), as rosbag2 lays a bag out: ``metadata.yaml`` and one ``.mcap``.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import json
import logging
import multiprocessing
import pickle
import threading
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from ros_nodes.bag_writer import ROS_DISTRO
from ros_nodes.recording_writer import serve
from ros_nodes.robot_description import robot_json
from ros_nodes.robot_interface import RECORDED_TOPICS
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.msgs.values import Message, stamp

log = logging.getLogger("websim.recording")

MAX_QUEUED_MESSAGES = 1000
"""Messages one recording keeps waiting for the writer (about 14 s of a robot's 70 per
second); beyond it new messages are dropped and counted, never waited for."""

FLUSH_PERIOD_S = 0.05
"""How often the feeder hands the queued messages to the writer process."""

BATCH_MESSAGES = 32
"""Most messages pickled and piped at once (each pickling holds the interpreter lock)."""

CLOSE_TIMEOUT_S = 30.0
"""How long ``close`` waits for the writer to close every bag."""

DEFAULT_MAX_MB = 1000.0
"""Largest bag (MB on disk) by default (``--record-max-mb``): then it is closed, complete."""

DEFAULT_CLIENT_MB_PER_MIN = 1.0
"""What clients may add to one robot's bag per minute of its clock, by default (MB; a
teleop page or a 50 Hz controller sends under 0.3): ``--record-client-mb-per-min``."""

OWN_TOPICS = frozenset(spec.name for spec in RECORDED_TOPICS
                       if spec.direction == "out" and spec.every_ticks > 0)
"""The robot's periodic topics: what it publishes whatever its clients do, never bounded."""

ROBOT_JSON_KEY = "robot_json"
"""The bag's ``custom_data`` entry holding the robot's ``robot.json`` (what ``websim replay``
serves the page)."""

SINGLE_ROBOT_NAME = "robot"
"""The name of a single robot's bag (``websim serve`` without ``--class``)."""


def stamp_ns(time_s: float) -> int:
    """A stamp in seconds as nanoseconds, exactly as ``values.stamp`` writes a header."""
    time_msg = stamp(time_s)
    return int(time_msg["sec"]) * 1_000_000_000 + int(time_msg["nanosec"])


@dataclass
class RecordingStats:
    """What one recording has done, for /healthz and the log at the end.

    Attributes:
        queued: messages taken from the tap into the queue.
        lost: messages dropped because the queue was full (the writer fell behind).
        written: messages in the bag (as the writer last reported).
        bytes: bytes of the bag on disk (as the writer last reported).
        state: ``"recording"``, ``"stopped"`` (its writing failed, or it reached its size
            limit) or ``"closed"``.
        reason: why it stopped; empty otherwise.
        summary: the writer's last word on the bag (``BagSummary`` as a dict), once stopped
            or closed.
        clients_left_out: messages of its clients left out: over their per-minute bound.
        clients_left_out_bytes: about what they would have added (bytes, as CDR).
    """

    queued: int = 0
    lost: int = 0
    written: int = 0
    bytes: int = 0
    state: str = "recording"
    reason: str = ""
    summary: dict[str, Any] = field(default_factory=dict)
    clients_left_out: int = 0
    clients_left_out_bytes: int = 0


def message_bytes(value: Any) -> int:
    """About what a message takes as CDR (bytes): 8 a number, 4 + the length a text or a list.

    Cheap and bounded by the message (a client's, already within the frame limit).
    """
    if isinstance(value, (str, bytes, bytearray)):
        return 4 + len(value)
    if isinstance(value, Mapping):
        return sum(message_bytes(item) for item in value.values())
    if isinstance(value, (list, tuple)):
        return 4 + sum(message_bytes(item) for item in value)
    return 8


class Recording:
    """One robot's bag, as the server sees it: a tap listener and a bounded queue.

    Args:
        rid: its id with the writer process.
        name: the robot's name.
        path: the bag's folder.
        robot: the robot recorded.
        max_queued: most messages waiting for the writer.
        client_bytes_per_minute: what its clients' messages may add to the bag per minute
            of the robot's clock (bytes, as CDR; a minute's worth at once at most); None: no
            bound.
    """

    def __init__(self, rid: int, name: str, path: Path, robot: VirtualRobot,
                 max_queued: int = MAX_QUEUED_MESSAGES,
                 client_bytes_per_minute: int | None = int(DEFAULT_CLIENT_MB_PER_MIN * 1e6)
                 ) -> None:
        self.rid = rid
        self.name = name
        self.path = path
        self.robot = robot
        self.stats = RecordingStats()
        self.queue: deque[tuple[int, int, str, str, Message]] = deque()
        self._max_queued = max_queued
        self._topics = frozenset(spec.name for spec in RECORDED_TOPICS)
        self._clock = robot.clock
        self.accepting = True
        """False once the recording stopped or closed: the tap's messages are ignored."""
        self.open_command: tuple[Any, ...] | None = None
        """What starts its bag in the writer process; None once sent."""
        self.client_bytes_per_minute = client_bytes_per_minute
        self._client_allowance = float(client_bytes_per_minute or 0)
        self._allowance_s = self._clock.stamp_s()
        self._said_s: float | None = None
        for spec, msg in robot.latched():  # the robot's own, however large its /map
            if spec.recorded:
                self._queue(spec.name, spec.type, msg, self._clock.stamp_s())
        robot.tap.add(self.on_message)

    def on_message(self, direction: str, topic: str, type_name: str, msg: Message,
                   sim_time_s: float) -> None:
        """The robot's tap: queue a recorded topic's message, stamped by the robot's clock.

        Runs in the tick: one append, or one count when the queue is full or when its
        clients are over their per-minute bound (what they send, or make the robot send).
        """
        if topic not in self._topics or not self.accepting:
            return
        now_s = self._clock.stamp_s()
        if topic in OWN_TOPICS or self._clients_may_add(msg, now_s):
            self._queue(topic, type_name, msg, now_s)

    def _queue(self, topic: str, type_name: str, msg: Message, now_s: float) -> None:
        if len(self.queue) >= self._max_queued:
            self.stats.lost += 1
            return
        self.queue.append((self.rid, stamp_ns(now_s), topic, type_name, msg))
        self.stats.queued += 1

    def _clients_may_add(self, msg: Message, now_s: float) -> bool:
        """Charge a message of the clients' to their allowance; whether it fits.

        The allowance refills at ``client_bytes_per_minute`` a minute of the robot's clock
        and holds a minute's worth at most. Leaving messages out is said in the log at most
        once a minute.
        """
        per_minute = self.client_bytes_per_minute
        if per_minute is None:
            return True
        size = message_bytes(msg)
        elapsed_s = max(0.0, now_s - self._allowance_s)
        self._allowance_s = now_s
        self._client_allowance = min(float(per_minute),
                                     self._client_allowance + elapsed_s * per_minute / 60.0)
        if size <= self._client_allowance:
            self._client_allowance -= size
            return True
        self.stats.clients_left_out += 1
        self.stats.clients_left_out_bytes += size
        if self._said_s is None or now_s - self._said_s >= 60.0:
            self._said_s = now_s
            log.warning("recording of %s: its clients' messages add more than %g MB a minute "
                        "to its bag: they are left out until they send less (%d so far); "
                        "the robot's own topics go on recording", self.name, per_minute / 1e6,
                        self.stats.clients_left_out)
        return False

    def notice(self) -> str | None:
        """What the dashboard says of this recording, if anything is wrong with it."""
        stats = self.stats
        if stats.state == "stopped":
            return f"recording stopped: {stats.reason}"
        if stats.clients_left_out:
            return (f"recording: {stats.clients_left_out} client messages left out (over "
                    f"{(self.client_bytes_per_minute or 0) / 1e6:g} MB a minute)")
        if stats.lost:
            return f"recording: {stats.lost} messages lost (the writer fell behind)"
        return None

    def detach(self) -> None:
        """Stop listening to the robot (from the thread that ticks it)."""
        self.accepting = False
        self.robot.tap.remove(self.on_message)

    def health(self) -> dict[str, Any]:
        """This recording's part of its robot's /healthz."""
        stats = self.stats
        report: dict[str, Any] = {"state": stats.state, "messages_written": stats.written,
                                  "bytes": stats.bytes, "messages_lost": stats.lost,
                                  "messages_waiting": len(self.queue)}
        if stats.reason:
            report["reason"] = stats.reason
        if stats.clients_left_out:
            report["client_messages_left_out"] = stats.clients_left_out
            report["client_bytes_left_out"] = stats.clients_left_out_bytes
        return report


class _Pickler(pickle.Pickler):
    """Pickles list and str subclasses as the plain values they are.

    A message's ``TypedSequence`` s and ``Base64Bytes``: the writer needs no class of the
    server's to read them.
    """

    def reducer_override(self, obj: Any) -> Any:
        if isinstance(obj, list):
            return list, (list(obj),)
        if isinstance(obj, str):
            return str, (str(obj),)
        return NotImplemented


def _pickled(item: Any) -> bytes:
    buffer = io.BytesIO()
    _Pickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(item)
    return buffer.getvalue()


class Recorder:
    """Every recording of one server, their feeder thread and their writer process.

    Args:
        directory: where the bags go (made if missing).
        max_bytes: a bag reaching this size on disk is closed (complete); None: no limit.
        max_queued: most messages one recording keeps waiting for the writer.
        custom_data: added to every bag's ``custom_data`` (strings).
        client_bytes_per_minute: what clients may add to each bag per minute
            (``Recording``); None: no bound (a graded run sets its own).
    """

    def __init__(self, directory: Path, *, max_bytes: int | None = int(DEFAULT_MAX_MB * 1e6),
                 max_queued: int = MAX_QUEUED_MESSAGES,
                 custom_data: dict[str, str] | None = None,
                 client_bytes_per_minute: int | None = int(DEFAULT_CLIENT_MB_PER_MIN * 1e6)
                 ) -> None:
        self.directory = directory
        self.max_bytes = max_bytes
        self.client_bytes_per_minute = client_bytes_per_minute
        self._max_queued = max_queued
        self._custom_data = dict(custom_data or {})
        self.recordings: list[Recording] = []
        self._stop = threading.Event()
        self._feeder: threading.Thread | None = None
        self._process: Any = None
        self._commands: Connection | None = None
        self._status: Connection | None = None
        self._closed = False

    def record(self, name: str, robot: VirtualRobot, custom_data: dict[str, str] | None = None,
               directory: Path | None = None) -> Recording:
        """Start recording ``robot`` as ``name`` (its bag is made when the writer runs).

        Args:
            name: the robot's name (the bag's folder starts with it).
            robot: the robot.
            custom_data: this bag's own ``custom_data`` (added to its world, mode...).
            directory: where its bag goes (default: the recorder's ``directory``).
        """
        started = datetime.now(timezone.utc)
        path = self._new_folder(directory or self.directory, name, started)
        recording = Recording(len(self.recordings), name, path, robot, self._max_queued,
                              self.client_bytes_per_minute)
        sim = robot.sim
        data = {**self._custom_data, "robot": name, "world": sim.world.name, "mode": sim.mode,
                "started_utc": started.isoformat(timespec="seconds"),
                "message_definitions": f"ROS 2 {ROS_DISTRO}",
                ROBOT_JSON_KEY: json.dumps(json.loads(robot_json(sim.params, sim.lidar.params)),
                                           separators=(",", ":"), sort_keys=True),
                **(custom_data or {})}
        recording.open_command = ("open", recording.rid, str(path), data, self.max_bytes)
        self.recordings.append(recording)
        return recording

    def _new_folder(self, directory: Path, name: str, started: datetime) -> Path:
        """``DIR/NAME_YYYYmmddTHHMMSSZ``, or with ``-2``, ``-3``... if that one is taken."""
        base = f"{name}_{started.strftime('%Y%m%dT%H%M%SZ')}"
        taken = {recording.path for recording in self.recordings}
        candidate, number = directory / base, 1
        while candidate in taken or candidate.exists():
            number += 1
            candidate = directory / f"{base}-{number}"
        return candidate

    def caught_up(self) -> bool:
        """Whether every recording's queue is at most half full.

        A ``Schedule`` pacer: above real time the ticks wait for the writer rather than drop
        messages (at most ``CLIENT_WAIT_S`` a tick).
        """
        limit = self._max_queued // 2
        return all(len(recording.queue) <= limit for recording in self.recordings
                   if recording.accepting)

    @property
    def running(self) -> bool:
        """Whether the writer process runs (``start`` was called and ``close`` was not)."""
        return self._feeder is not None and not self._closed

    def start(self) -> None:
        """Start the writer process and the feeder thread (once the server is up)."""
        if self._feeder is not None or self._closed:
            return
        context = multiprocessing.get_context("spawn")
        commands_out, commands_in = context.Pipe(duplex=False)
        status_out, status_in = context.Pipe(duplex=False)
        self._process = context.Process(target=serve, args=(commands_out, status_in),
                                        name="websim-recording-writer", daemon=False)
        self._process.start()
        commands_out.close()
        status_in.close()
        self._commands, self._status = commands_in, status_out
        self._feeder = threading.Thread(target=self._feed, name="websim-recording-feeder",
                                        daemon=True)
        self._feeder.start()
        # Before multiprocessing joins its children at exit (atexit runs the later first): a
        # process that ends without close() (an exception, a failed test) ends the writer's
        # pipe, so the writer closes the bags and exits instead of waiting for commands.
        atexit.register(self._abandon)

    def _abandon(self) -> None:
        """At exit without ``close``: stop feeding and end the pipe (the writer closes up)."""
        if self._closed or self._commands is None:
            return
        self._stop.set()
        if self._feeder is not None:
            self._feeder.join(timeout=2.0)
        with contextlib.suppress(OSError):
            self._commands.close()

    def _feed(self) -> None:
        """The feeder thread: hand the queues to the writer until ``close``."""
        while True:
            stopping = self._stop.wait(FLUSH_PERIOD_S)
            try:
                self._flush()
            except OSError as error:  # the writer process is gone
                self._writer_lost(error)
                return
            self._read_status()
            if stopping:
                return

    def _flush(self) -> None:
        """Pipe every queued message to the writer, in batches of ``BATCH_MESSAGES``.

        A batch takes several robots' messages: each pickling holds the interpreter lock
        (about 10 µs a message), and each call has its own cost too.
        """
        commands = self._commands
        assert commands is not None
        batch: list[tuple[int, int, str, str, Message]] = []
        for recording in list(self.recordings):
            if recording.open_command is not None:
                commands.send_bytes(_pickled(recording.open_command))
                recording.open_command = None
            queue = recording.queue
            while queue:
                batch.append(queue.popleft())
                if len(batch) >= BATCH_MESSAGES:
                    commands.send_bytes(_pickled(("messages", batch)))
                    batch = []
        if batch:
            commands.send_bytes(_pickled(("messages", batch)))

    def _read_status(self, timeout_s: float = 0.0) -> bool:
        """Take the writer's reports; False once its pipe has ended."""
        status = self._status
        assert status is not None
        try:
            while status.poll(timeout_s):
                self._on_status(pickle.loads(status.recv_bytes()))
        except (EOFError, OSError):
            return False
        return True

    def _on_status(self, item: tuple[Any, ...]) -> None:
        op = item[0]
        if op == "progress":
            for rid, (written, size) in item[1].items():
                stats = self.recordings[rid].stats
                stats.written, stats.bytes = written, size
            return
        recording = self.recordings[item[1]]
        recording.accepting = False
        recording.queue.clear()
        stats = recording.stats
        summary = item[-1]
        stats.summary, stats.written, stats.bytes = summary, summary["messages"], summary["bytes"]
        if op == "stopped":
            stats.state, stats.reason = "stopped", item[2]
            kept = f"{summary['messages']} messages in {recording.path}" if summary["complete"] \
                else (f"{recording.path} keeps the {summary['messages']} messages written "
                      "before (no metadata.yaml; its .mcap ends where writing failed)")
            log.error("recording of %s stopped: %s; %s; the simulation goes on",
                      recording.name, item[2], kept)
        elif op == "closed":
            stats.state = "closed"

    def _writer_lost(self, error: OSError) -> None:
        for recording in self.recordings:
            if recording.stats.state == "recording":
                recording.accepting = False
                recording.stats.state = "stopped"
                recording.stats.reason = f"the writer process ended ({error})"
        log.error("the recordings' writer process ended (%s): nothing more is recorded; the "
                  "simulation goes on", error)

    def close(self) -> list[Recording]:
        """Write what is queued, close every bag properly, stop the writer; the recordings.

        Call it where the robots tick (after the last tick): it detaches their taps. Logs a
        line per recording; idempotent.
        """
        if self._closed:
            return self.recordings
        self._closed = True
        for recording in self.recordings:
            recording.detach()
        if self._feeder is None:  # never started: nothing was written
            return self.recordings
        self._stop.set()
        self._feeder.join()
        commands = self._commands
        assert commands is not None
        try:
            for recording in self.recordings:
                if recording.stats.state == "recording":
                    commands.send_bytes(_pickled(("close", recording.rid)))
        except OSError as error:
            self._writer_lost(error)
        commands.close()
        while self._read_status(CLOSE_TIMEOUT_S) and any(
                recording.stats.state == "recording" for recording in self.recordings):
            pass
        self._process.join(CLOSE_TIMEOUT_S)
        if self._process.is_alive():
            log.error("the recordings' writer process did not finish in %g s; stopping it",
                      CLOSE_TIMEOUT_S)
            self._process.terminate()
            self._process.join()
        if self._status is not None:
            self._status.close()
        for recording in self.recordings:
            stats = recording.stats
            log.info("recording of %s: %s, %d messages, %d bytes, %d lost (queue full) in %s",
                     recording.name, stats.state, stats.written, stats.bytes, stats.lost,
                     recording.path)
            if stats.lost:
                log.warning("recording of %s lost %d messages: the writer fell behind (its "
                            "queue holds %d)", recording.name, stats.lost, self._max_queued)
        return self.recordings

    def summary_lines(self) -> list[str]:
        """What the recordings hold, for the terminal at shutdown (one line per bag)."""
        lines = []
        for recording in self.recordings:
            stats = recording.stats
            lost = f", {stats.lost} lost (queue full)" if stats.lost else ""
            why = f" ({stats.reason})" if stats.reason else ""
            duration_s = float(stats.summary.get("duration_s", 0.0))
            lines.append(f"{recording.path}: {stats.written} messages, {duration_s:.1f} s, "
                         f"{stats.bytes / 1e6:.1f} MB, {stats.state}{why}{lost}")
        return lines
