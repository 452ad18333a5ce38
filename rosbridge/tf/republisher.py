"""tf2_web_republisher, served in-process on a bridge: what every ros3djs object waits for.

A browser cannot listen to ``/tf`` the way tf2 does (every transform of the tree at its own
rate), so ROS's web viewers ask tf2_web_republisher for the few frames they draw, each as
its pose in one fixed frame, sent at a chosen rate and only when it moved by more than a
threshold. This module answers both of its ROS 2 interfaces over a ``Bridge``, from a
``TfBuffer`` of the bridge's own ``/tf`` and ``/tf_static``:

* the service ``/republish_tfs`` (``tf2_web_republisher/srv/RepublishTFs``: the type
  roslib 1.4.1's ``ROSLIB.TFClient`` names, with ``Ros({groovyCompatibility: false})``),
  answering a topic ``/tf_repub_N`` on which the frames come as
  ``tf2_web_republisher/msg/TFArray`` while it has subscribers; it goes once it has had none
  for the request's ``timeout`` (2 s when 0, roslib's default);
* the action ``/tf2_web_republisher`` (``tf2_web_republisher_interfaces/action/TFSubscription``,
  the ROS 2 package roslib 2.x's ``ROS2TFClient`` names), whose feedback carries the frames
  until the goal is cancelled.

Each frame of a request is sent (stamped now, ``header.frame_id`` the target frame,
``child_frame_id`` the source frame) when it is first known, and then at most ``rate``
times a second (Hz; at most as often as ``step`` is called: the robot's tick, 20 Hz) when it
moved more than ``trans_thres`` (m) or turned more than ``angular_thres`` (rad, the angle of
the rotation between the orientation last sent and the current one); a threshold of 0 sends
it at every step, as tf2_web_republisher does. Frames unknown to the tree are left out until
they appear. A service's frames are all sent again when its topic gains a subscriber after
having none.

Everything a client can make it hold is bounded (``RepublisherLimits``): republications per
client and per bridge, frames per request, the rate and the timeout (refused outside their
ranges, with the reason); a client's republications go when it leaves. The bridge's share
belongs to its owner: clients that may only watch (``Session.may_drive`` false: a class
robot's visitors without its token) hold together at most what the owner's reserve leaves,
so however many watch, the robot's own page and code get theirs. The buffer listens to
``/tf`` and ``/tf_static`` only while some republication exists (so a robot that builds only
what is subscribed builds ``/tf`` then), and is emptied when the last one goes.

This module knows no robot: the owner of the bridge (``ros_nodes.robot_host``) makes one and
calls ``step`` once per tick.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rosbridge.core.bridge import Bridge
from rosbridge.core.capabilities.actions import Cancel, GoalSender
from rosbridge.core.errors import BridgeError, ServiceError
from rosbridge.core.schema import GoalStatus
from rosbridge.core.session import Session
from rosbridge.msgs import definitions
from rosbridge.msgs.values import stamp
from rosbridge.tf.buffer import (
    MAX_FRAME_CHARS,
    TfBuffer,
    Transform,
    TransformLookupError,
    clean_frame,
    transform_stamped,
)

REPUBLISH_SERVICE = "/republish_tfs"
"""The service variant's name (tf2_web_republisher's, roslib's ``repubServiceName``)."""

REPUBLISH_SERVICE_TYPE = "tf2_web_republisher/srv/RepublishTFs"
"""The service variant's type, as roslib 1.4.1's ``TFClient`` names it."""

TF_ARRAY_TYPE = "tf2_web_republisher/msg/TFArray"
"""The type of a service republication's topic, as roslib 1.4.1's ``TFClient`` subscribes it."""

ACTION = "/tf2_web_republisher"
"""The action variant's name (roslib's ``serverName``)."""

ACTION_TYPE = "tf2_web_republisher_interfaces/action/TFSubscription"
"""The action variant's type: the ROS 2 package's, as roslib 2.x's ``ROS2TFClient`` names it."""

TOPIC_PREFIX = "/tf_repub_"
"""A service republication's topic is this and a number (tf2_web_republisher's names)."""

TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
"""What the buffer listens to."""

DEFAULT_TIMEOUT_S = 2.0
"""A service republication's timeout when the request gives 0 (roslib's ``topicTimeout``)."""

RATE_JITTER_S = 0.005
"""What the rate tolerates: a step this early still sends (steps come on ticks, whose times
are rounded; a 10 Hz request on 20 Hz ticks is sent at every other tick)."""


@dataclass(frozen=True)
class RepublisherLimits:
    """What clients may make one republisher hold.

    Attributes:
        per_client: republications (service topics and action goals) one client may hold;
            a service request beyond it replaces that client's oldest republication without
            subscribers (a ros3djs page asks again at every new frame and drops the old
            topic), or is refused if all have some.
        per_bridge: republications of all clients together.
        owner_reserve: of ``per_bridge``, what only clients that may drive the robot (its
            owner, the instructor) may hold: watchers hold the rest at most, together.
        frames: source frames in one request.
        max_rate_hz: the highest rate a request may ask for (Hz); it is sent at most at
            every ``step`` anyway.
        max_timeout_s: the longest timeout a service request may ask for (s).
    """

    per_client: int = 8
    per_bridge: int = 64
    owner_reserve: int = 16
    frames: int = 32
    max_rate_hz: float = 100.0
    max_timeout_s: float = 60.0


@dataclass
class _Frame:
    """One source frame of a republication: what was last sent of it."""

    name: str
    sent: Transform | None = None
    resend: bool = True
    """Send it at the next step whatever the thresholds say (first known, a new subscriber)."""


@dataclass(eq=False)
class _Republication:
    """One request's frames, thresholds and rate, and where they go.

    Attributes:
        owner: the client that asked for it.
        target: the fixed frame.
        frames: the source frames.
        angular_thres_rad: least turn that is sent (rad).
        trans_thres_m: least move that is sent (m).
        period_s: least time between two sends (s).
        next_s: when it may send next (monotonic s).
        topic: its topic (the service variant), or None.
        sender: its goal's sender (the action variant), or None.
        timeout_s: how long its topic may have no subscriber (service variant).
        idle_since_s: since when its topic has had no subscriber (None: it has one).
    """

    owner: Session
    target: str
    frames: list[_Frame]
    angular_thres_rad: float
    trans_thres_m: float
    period_s: float
    next_s: float
    topic: str | None = None
    sender: GoalSender | None = None
    timeout_s: float = DEFAULT_TIMEOUT_S
    idle_since_s: float | None = None

    @property
    def always(self) -> bool:
        """A threshold of 0: every frame is sent at every step (tf2_web_republisher's rule)."""
        return self.angular_thres_rad == 0.0 or self.trans_thres_m == 0.0


@dataclass
class _Request:
    """A request's fields, checked."""

    target: str
    frames: list[str]
    angular_thres_rad: float
    trans_thres_m: float
    period_s: float
    timeout_s: float = DEFAULT_TIMEOUT_S


class TfRepublisher:
    """tf2_web_republisher's service and action on one bridge (see the module text).

    Args:
        bridge: the bridge it serves on; it adds its service and action there.
        limits: what clients may make it hold.

    Attributes:
        buffer: the transforms of ``/tf`` and ``/tf_static`` (while it listens).
    """

    def __init__(self, bridge: Bridge, limits: RepublisherLimits | None = None) -> None:
        self._bridge = bridge
        self._limits = limits or RepublisherLimits()
        self.buffer = TfBuffer()
        self._republications: list[_Republication] = []
        self._numbers = 0
        self._listening = False
        bridge.services.add(REPUBLISH_SERVICE, REPUBLISH_SERVICE_TYPE, self._request)
        bridge.actions.add(ACTION, ACTION_TYPE, self._goal)
        bridge.on_disconnect(self._forget)

    # ---- what clients hold --------------------------------------------------------------

    def held(self, session: Session | None = None) -> int:
        """Republications held by ``session`` (None: by every client)."""
        return sum(session is None or rep.owner is session for rep in self._republications)

    def _request(self, args: Mapping[str, Any], session: Session) -> Mapping[str, Any]:
        """``/republish_tfs``: a topic on which the frames will come."""
        request = self._check(f"{REPUBLISH_SERVICE_TYPE}_Request", args, REPUBLISH_SERVICE,
                              ServiceError)
        self._make_room(session, ServiceError, REPUBLISH_SERVICE)
        topic = self._new_topic()
        now = self._bridge.clock.monotonic_s()
        self._add(_Republication(session, request.target, _frames(request.frames),
                                 request.angular_thres_rad, request.trans_thres_m,
                                 request.period_s, now, topic=topic,
                                 timeout_s=request.timeout_s, idle_since_s=now))
        self._bridge.topics.own(topic, TF_ARRAY_TYPE)
        return {"topic_name": topic}

    def _goal(self, args: Any, sender: GoalSender, session: Session) -> Cancel:
        """A ``/tf2_web_republisher`` goal: its feedback carries the frames until cancelled."""
        request = self._check(f"{ACTION_TYPE}_Goal", args, ACTION, BridgeError)
        self._make_room(session, BridgeError, ACTION)
        rep = _Republication(session, request.target, _frames(request.frames),
                             request.angular_thres_rad, request.trans_thres_m,
                             request.period_s, self._bridge.clock.monotonic_s(),
                             sender=sender)
        self._add(rep)

        def cancel() -> None:
            if rep in self._republications:
                self._remove(rep)
                sender.goal_result({}, GoalStatus.CANCELED, True)

        return cancel

    def _check(self, type_name: str, args: Any, name: str,
               error: type[BridgeError]) -> _Request:
        """A request's fields in canonical form and within their ranges.

        Raises:
            error: a field is missing its type or out of its range; the reason names it.
        """
        limits = self._limits
        try:
            fields = definitions.canonical(type_name, {} if args in ([], None) else args)
        except ValueError as wrong:  # MessageError
            raise error(f"{name}: {wrong}") from None
        frames = list(dict.fromkeys(clean_frame(frame) for frame in fields["source_frames"]))
        target = clean_frame(fields["target_frame"])
        rate_hz, angular, trans = fields["rate"], fields["angular_thres"], fields["trans_thres"]
        problems = []
        if len(frames) > limits.frames:
            problems.append(f"source_frames: at most {limits.frames} frames, got {len(frames)}")
        if not target:
            problems.append("target_frame: empty (name the fixed frame, e.g. odom)")
        if any(len(frame) > MAX_FRAME_CHARS for frame in [*frames, target]):
            problems.append(f"frame names are at most {MAX_FRAME_CHARS} characters")
        if not (math.isfinite(rate_hz) and 0.0 < rate_hz <= limits.max_rate_hz):
            problems.append(f"rate: must be more than 0 and at most {limits.max_rate_hz:g} Hz,"
                            f" got {rate_hz:g}")
        for field_name, value in (("angular_thres", angular), ("trans_thres", trans)):
            if not (math.isfinite(value) and value >= 0.0):
                problems.append(f"{field_name}: must be 0 or more, got {value:g}")
        timeout_s = DEFAULT_TIMEOUT_S
        if "timeout" in fields:
            duration = fields["timeout"]
            timeout_s = duration["sec"] + duration["nanosec"] / 1e9
            if not 0.0 <= timeout_s <= limits.max_timeout_s:
                problems.append(f"timeout: must be 0 (the default, {DEFAULT_TIMEOUT_S:g} s) "
                                f"to {limits.max_timeout_s:g} s, got {timeout_s:g}")
            timeout_s = timeout_s or DEFAULT_TIMEOUT_S
        if problems:
            raise error(f"{name}: {'; '.join(problems)}")
        return _Request(target, frames, float(angular), float(trans), 1.0 / rate_hz,
                        timeout_s)

    def _make_room(self, session: Session, error: type[BridgeError], name: str) -> None:
        """Make room for one more republication of ``session``, or refuse it."""
        limits = self._limits
        if self.held(session) >= limits.per_client:
            topics, now = self._bridge.topics, self._bridge.clock.monotonic_s()
            idle = [rep for rep in self._republications if rep.owner is session
                    and rep.topic is not None and not topics.has_subscribers(rep.topic)]
            if not idle:
                raise error(f"{name}: a client may hold at most {limits.per_client} TF "
                            "republications (cancel a goal, or unsubscribe a topic)")
            self._remove(min(idle, key=lambda rep: now if rep.idle_since_s is None
                             else rep.idle_since_s))
        if self.held() >= limits.per_bridge:
            raise error(f"{name}: this robot's TF republisher serves {limits.per_bridge} "
                        "republications already; try again later")
        watchers_share = limits.per_bridge - limits.owner_reserve
        if not session.may_drive and sum(not rep.owner.may_drive for rep in
                                         self._republications) >= watchers_share:
            raise error(f"{name}: this robot's watchers hold {watchers_share} TF "
                        f"republications already; the other {limits.owner_reserve} are kept "
                        "for its owner (connect with the robot's token to use them)")

    def _new_topic(self) -> str:
        """The next ``/tf_repub_N`` no one else uses."""
        known = self._bridge.topic_types()
        while True:
            topic = f"{TOPIC_PREFIX}{self._numbers}"
            self._numbers += 1
            if topic not in known:
                return topic

    def _add(self, rep: _Republication) -> None:
        self._republications.append(rep)
        if not self._listening:
            self._listening = True
            topics = self._bridge.topics
            topics.listen(TF_TOPIC, self.buffer.add)
            topics.listen(TF_STATIC_TOPIC, self.buffer.add)

    def _remove(self, rep: _Republication) -> None:
        self._republications.remove(rep)
        if rep.topic is not None:
            self._bridge.topics.disown(rep.topic)
        if not self._republications and self._listening:
            self._listening = False
            topics = self._bridge.topics
            topics.unlisten(TF_TOPIC, self.buffer.add)
            topics.unlisten(TF_STATIC_TOPIC, self.buffer.add)
            self.buffer.clear()

    def _forget(self, session: Session) -> None:
        """A client left: its republications go (its goals were cancelled already)."""
        for rep in [rep for rep in self._republications if rep.owner is session]:
            self._remove(rep)

    # ---- sending ------------------------------------------------------------------------

    def step(self, now_s: float | None = None) -> None:
        """Send what is due: each republication's moved frames, at its rate.

        ``now_s``: the time of the step (monotonic s; default the clock's): the robot's tick's
        due time, so that a late tick does not make a 10 Hz request miss its turn.
        """
        if not self._republications:
            return
        clock = self._bridge.clock
        now = clock.monotonic_s() if now_s is None else now_s
        stamped = stamp(clock.stamp_s())
        poses: dict[tuple[str, str], Transform | None] = {}
        for rep in list(self._republications):
            if rep.topic is not None and not self._has_audience(rep, now):
                continue
            if now < rep.next_s - RATE_JITTER_S:
                continue
            rep.next_s += rep.period_s
            if rep.next_s <= now:
                rep.next_s = now + rep.period_s
            moved = [transform_stamped(rep.target, frame.name, pose, stamped)
                     for frame, pose in self._moved(rep, poses)]
            if not moved:
                continue
            if rep.sender is not None:
                rep.sender.goal_feedback({"transforms": moved})
            elif rep.topic is not None:
                self._bridge.topics.publish(rep.topic, {"transforms": moved})

    def _has_audience(self, rep: _Republication, now: float) -> bool:
        """Whether a service republication's topic has a subscriber (it goes after timeout)."""
        assert rep.topic is not None
        if self._bridge.topics.has_subscribers(rep.topic):
            rep.idle_since_s = None
            return True
        if rep.idle_since_s is None:
            rep.idle_since_s = now
            for frame in rep.frames:  # whoever subscribes next gets every frame
                frame.resend = True
        elif now - rep.idle_since_s >= rep.timeout_s:
            self._remove(rep)
        return False

    def _moved(self, rep: _Republication,
               poses: dict[tuple[str, str], Transform | None]) -> list[tuple[_Frame, Transform]]:
        """The frames of ``rep`` to send now, with their poses; notes them as sent."""
        moved = []
        for frame in rep.frames:
            key = (rep.target, frame.name)
            if key not in poses:
                try:
                    poses[key] = self.buffer.lookup(rep.target, frame.name)
                except TransformLookupError:
                    poses[key] = None
            pose = poses[key]
            if pose is None:
                continue
            sent = frame.sent
            if frame.resend or rep.always or sent is None or \
                    sent.distance_m(pose) > rep.trans_thres_m or \
                    sent.angle_rad(pose) > rep.angular_thres_rad:
                frame.sent, frame.resend = pose, False
                moved.append((frame, pose))
        return moved


def _frames(names: list[str]) -> list[_Frame]:
    return [_Frame(name) for name in names]

