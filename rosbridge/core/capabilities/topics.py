"""Topics: advertise, unadvertise, publish, subscribe, unsubscribe; throttles, queues, latching.

The one path for every message: a client's ``publish`` and an in-process endpoint's
(``publish``, e.g. the robot's /odom) both go through ``_deliver``, and in-process subscribers
(``subscribe_local``, e.g. the robot's /cmd_vel) get what clients publish, as another client
would. A topic carries one type, except where an in-process subscriber takes several
(``subscribe_local`` once per type, e.g. Twist and TwistStamped on /cmd_vel): there each
client's messages are of the type it advertised, each in-process subscriber gets those of its
type, and each client subscriber those of the type it named (none named: the first). Every
message is relayed in its canonical form (``definitions``: defaults filled, unknown fields
refused); a type websim cannot check (not among its definitions, nor with
``--ros`` importable) is refused at advertise, subscribe and publish, as rosbridge refuses a
type it cannot import.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass
from typing import Any

from rosbridge.core.clock import WALL_CLOCK, Clock
from rosbridge.core.context import BridgeContext
from rosbridge.core.encoding import cbor_raw_frame, png_frame, to_cbor, to_json
from rosbridge.core.errors import BridgeError, shorten
from rosbridge.core.faults import Faults
from rosbridge.core.fragments import fragment, topic_fragment_size
from rosbridge.core.outbox import Deferred, Frames
from rosbridge.core.session import Session, Subscription
from rosbridge.msgs import cdr, definitions
from rosbridge.msgs.values import normalize_type

log = logging.getLogger("websim.bridge")

THROTTLE_JITTER_S = 0.005
"""What a throttle tolerates: ``throttle_rate`` is the least time between two messages
(rosbridge's definition), less this. The robot's messages are timed at their tick's due time
(``publish_many``), so a 200 ms throttle on the 20 Hz /odom gives exactly every fourth however
late ticks run; this covers rounding, and clients' messages timed on arrival."""

CLOSING_LOOP_S = 1.0
"""A client that published within this long closes a loop (a teleop page, a PID node): in
every fan-out its frame is queued first and handed to the transport to be written at once
(``Flush.now``); in a tick (``publish_many``) that happens before the message is even queued
for the clients that only watch. With 500 watchers, queueing and writing for all of them
takes milliseconds; the driver's /odom does not wait for that (benchmarks/bench_server.py)."""

LocalSubscriber = Callable[[Any, Session], None]
"""An in-process subscriber: called with a client's (canonical) message and its publisher.
It raises one of ``Bridge.refusals`` to refuse the message; the reason goes back to the
publisher."""

Listener = Callable[[Any], None]
"""An in-process listener (``Topics.listen``): called with every message delivered on its
topic, whoever published it (canonical form)."""


MAX_VARIANTS = 4
"""Costly forms of one message (``png``, ``cbor-raw``, fragmented JSON, each per namespace
and fragment size) kept for reuse by every subscriber that asks for the same; a form past
it is made for each subscriber that asks, at that subscriber's cost."""

VARIANT_BYTES_FACTOR = 4
"""The costly forms one message keeps together hold at most this many times its JSON
text's length (plus its JSON and CBOR): a latched message holds at most about six times its
size, whatever its subscribers ask for."""


@dataclass
class _Latched:
    """A topic's latched message and whose it is.

    Attributes:
        encoded: the message, with its encodings.
        owner: the client that published it, None for an in-process endpoint's (the
            robot's, the ROS graph's): it goes when its owner leaves or unadvertises.
        size: what it counts in the robot's and the server's latched pools
            (``BridgeContext.latched``; 0 for in-process).
    """

    encoded: Encoded
    owner: Session | None
    size: int = 0


class Encoded:
    """One publish envelope, encoded at most once per format whatever the subscriber count.

    A format is a compression (``schema.COMPRESSIONS``), for the JSON ones (``none``,
    ``png``) a ``fragment_size`` (a longer text goes as its ``fragment`` frames; the size is
    ``fragments.topic_fragment_size``: a power of two, so a message has few forms), and a
    namespace that prefixes the topic's name in the envelope (``Session.namespace``).

    JSON and CBOR, cheap and shared, are made on the tick (``frame``); the costly forms
    (``png``, ``cbor-raw``, fragments) are ``Deferred``: made when the subscriber's frames
    are written, charged to it, and kept for the next subscriber that asks for the same
    (at most ``MAX_VARIANTS``, ``VARIANT_BYTES_FACTOR`` times the JSON text).

    Args:
        topic: the topic it is published on.
        msg: the message (canonical form).
        type_name: its type (``pkg/msg/Type``), known where it is published (the publisher's
            advertisement, the robot's own topic, the ROS graph's subscription): its
            ``cbor-raw`` form is serialized as it, and where a topic carries several types
            (/cmd_vel: Twist and TwistStamped) it goes to the subscribers of its type. None:
            not known, so it has no ``cbor-raw`` form.
        clock: what stamps its ``cbor-raw`` frame (``stamp_s``; default: wall time).
        faults: where a form that fails to be made is recorded (default: nowhere).
    """

    def __init__(self, topic: str, msg: Any, type_name: str | None = None,
                 clock: Clock = WALL_CLOCK, faults: Faults | None = None) -> None:
        self.topic = topic
        self.type_name = type_name
        self._clock = clock
        self._faults = faults
        self.envelope = {"op": "publish", "topic": topic, "msg": msg}
        self._json: str | None = None
        self._frames: dict[tuple[str, str], Frames] = {}
        self._variants: dict[tuple[str, int | None, str], Frames] = {}
        self._variant_bytes = 0
        self._deferred: dict[tuple[str, int | None, str], Deferred] = {}
        self._failed: dict[str, str] = {}
        """Formats this message cannot be written in, and why (each is tried once)."""
        self._reported: set[str] = set()

    def report_failure(self, compression: str) -> bool:
        """Whether a failure to write it as ``compression`` is to be recorded (once)."""
        if compression in self._reported:
            return False
        self._reported.add(compression)
        return True

    @property
    def json(self) -> str:
        """The envelope's JSON text (made once)."""
        if self._json is None:
            self._json = to_json(self.envelope)
        return self._json

    @property
    def held_bytes(self) -> int:
        """What its encodings hold (characters of text, bytes of binary frames)."""
        return (len(self._json or "") + sum(_size(frames) for frames in self._frames.values())
                + self._variant_bytes)

    def frame(self, compression: str, fragment_size: int | None = None,
              namespace: str = "") -> Frames:
        """The frames for subscribers that asked for ``compression`` and ``fragment_size``.

        ``fragment_size``: the client's; it is rounded (``topic_fragment_size``).
        ``namespace``: the prefix of the topic's name for the subscriber
        (``Session.namespace``). A message that cannot be serialized as ``cbor-raw`` (its
        type unknown or not one websim can serialize) gets an error ``status`` frame in its
        place, made again for each asker: it is never kept as the message's form. Made now,
        even a costly format (``entry`` defers those).

        Raises:
            ValueError: the message cannot be written in this format at all (JSON, CBOR).
        """
        entry = self.entry(compression, fragment_size, namespace)
        return entry.make() if isinstance(entry, Deferred) else entry

    def entry(self, compression: str, fragment_size: int | None = None,
              namespace: str = "") -> Frames | Deferred:
        """As ``frame``, but a costly format comes back ``Deferred``: made when written.

        Raises:
            ValueError: the message cannot be written in this format at all (JSON, CBOR).
        """
        if compression == "cbor":
            return self._cheap("cbor", namespace)
        size = topic_fragment_size(fragment_size)
        if compression == "none" and (size is None or len(self.json) <= size):
            return self._cheap("none", namespace)
        key = (compression, None if compression == "cbor-raw" else size, namespace)
        made = self._variants.get(key)
        if made is not None:
            return made
        deferred = self._deferred.get(key)
        if deferred is None:  # one for every subscriber of this form
            deferred = self._deferred[key] = Deferred(
                functools.partial(self._variant, key), len(self.json))
        return deferred

    def _cheap(self, compression: str, namespace: str) -> Frames:
        """JSON or CBOR, made once; raises (ValueError) if it cannot be, once and again."""
        key = (compression, namespace)
        frames = self._frames.get(key)
        if frames is not None:
            return frames
        failed = self._failed.get(compression)
        if failed is not None:
            raise ValueError(failed)  # recorded the first time, not again
        try:
            if namespace:  # the same message under the name the subscriber knows it by
                named = Encoded(namespace + self.topic, self.envelope["msg"], self.type_name,
                                self._clock)
                frames = named._cheap(compression, "")
            else:
                frames = to_cbor(self.envelope) if compression == "cbor" else self.json
        except (TypeError, ValueError) as error:
            self._failed[compression] = f"{type(error).__name__}: {error}"
            raise
        self._frames[key] = frames
        return frames

    def _variant(self, key: tuple[str, int | None, str]) -> Frames:
        """A costly form, made for the subscriber being written (kept if there is room).

        A ``cbor-raw`` form that cannot be made (``cdr.CdrError``: the type is unknown or
        not one websim serializes) is an error ``status`` for this subscriber, never kept:
        a refusal is not the message's form.
        """
        made = self._variants.get(key)
        if made is not None:
            return made
        compression, size, namespace = key
        try:
            frames = self._encode(compression, size, namespace)
        except cdr.CdrError as error:
            return to_json({"op": "status", "level": "error",
                            "msg": shorten(f"cbor-raw: a message on {namespace}{self.topic} "
                                           f"cannot be sent as CDR: {error}")})
        except Exception as error:  # one subscriber's format is not the others'
            if self._faults is not None and compression not in self._failed:
                self._faults.record(f"encoding {self.topic} as {compression}", error)
            self._failed[compression] = str(error)
            return to_json({"op": "status", "level": "error",
                            "msg": shorten(f"{compression}: a message on {self.topic} "
                                           f"cannot be sent so: {error}")})
        size_bytes = _size(frames)
        if len(self._variants) < MAX_VARIANTS and self._variant_bytes + size_bytes <= \
                VARIANT_BYTES_FACTOR * len(self.json):
            self._variants[key] = frames
            self._variant_bytes += size_bytes
        return frames

    def _encode(self, compression: str, fragment_size: int | None,
                namespace: str) -> Frames:
        """A costly form; raises ``cdr.CdrError`` if it is ``cbor-raw`` and cannot be made."""
        if namespace:  # the same message under the name the subscriber knows the topic by
            named = Encoded(namespace + self.topic, self.envelope["msg"], self.type_name,
                            self._clock)
            return named._encode(compression, fragment_size, "")
        if compression == "cbor":
            return to_cbor(self.envelope)
        if compression == "cbor-raw":
            return self._cbor_raw()
        text = png_frame(self.json) if compression == "png" else self.json
        if fragment_size is not None and len(text) > fragment_size:
            return fragment(text, fragment_size)
        return text

    def _cbor_raw(self) -> Frames:
        if self.type_name is None:
            raise cdr.CdrError("its type is not known")
        data = cdr.to_cdr(self.type_name, self.envelope["msg"])
        return cbor_raw_frame(self.topic, data, self._clock.stamp_s())


def _size(frames: Frames) -> int:
    return sum(map(len, frames)) if isinstance(frames, tuple) else len(frames)


class Topics:
    """The topic capability of one bridge.

    Args:
        context: what it shares with the bridge's other capabilities (sessions, clock,
            faults, refusals, the graph port).
    """

    OPS = ("advertise", "unadvertise", "publish", "subscribe", "unsubscribe")

    def __init__(self, context: BridgeContext) -> None:
        self._context = context
        self._types: dict[str, str] = {}
        self._owned: set[str] = set()
        self._subscribers: dict[str, set[Session]] = {}
        self._local: dict[str, dict[str, list[LocalSubscriber]]] = {}
        """Each topic's in-process subscribers, by the type they take (one or several)."""
        self._latched: dict[str, _Latched] = {}
        """Each latched topic's newest latched message (rosbridge gives it to every new
        subscriber), owned by its publisher: dropped when that client leaves or
        unadvertises the topic, as rosbridge drops a publisher's latched message with it."""
        self._subscribed_types: dict[str, str] = {}
        """Types named by subscriptions to topics of no other known type (rosbridge infers
        a publisher's type from them); dropped with the last subscriber."""
        self._latching: set[tuple[Session, str]] = set()
        """(client, topic) advertised with ``latch: true``: its every publish is latched."""
        self._published_s: dict[Session, float] = {}
        """When each client last published (monotonic s): the fan-out serves them first."""
        self._listeners: dict[str, list[Listener]] = {}
        """In-process listeners of every message on a topic (``listen``); a topic listened
        to counts as subscribed (``subscribed_topics``), so its publisher builds it."""
        definitions.load()  # now, not at the first publish (it takes ~0.1 s)

    def handlers(self) -> dict[str, Callable[[Session, dict[str, Any]], None]]:
        """This capability's ops."""
        return {"advertise": self._advertise, "unadvertise": self._unadvertise,
                "publish": self._publish, "subscribe": self._subscribe,
                "unsubscribe": self._unsubscribe}

    # ---- in-process endpoints ---------------------------------------------------------------

    def own(self, topic: str, type_name: str) -> None:
        """Declare ``topic`` published in-process (the robot's outputs): clients may not."""
        self._types[topic] = normalize_type(type_name)
        self._owned.add(topic)

    def disown(self, topic: str) -> None:
        """An in-process publisher gives ``topic`` up: clients may use it, its latched goes."""
        if topic not in self._owned:
            return
        self._owned.discard(topic)
        self._unlatch(topic)
        if topic not in self._local and not any(
                topic in other.advertised for other in self._context.sessions):
            self._types.pop(topic, None)

    def listen(self, topic: str, listener: Listener) -> None:
        """Give ``listener`` every message delivered on ``topic`` from now on, and its latched one.

        While anything listens, ``topic`` counts as subscribed (``subscribed_topics``): an
        in-process publisher that builds only what is subscribed builds it.
        """
        self._listeners.setdefault(topic, []).append(listener)
        latched = self._latched.get(topic)
        if latched is not None:
            self._hear(topic, listener, latched.encoded.envelope["msg"])

    def unlisten(self, topic: str, listener: Listener) -> None:
        """Stop giving ``listener`` the messages of ``topic``."""
        listeners = self._listeners.get(topic)
        if listeners is not None and listener in listeners:
            listeners.remove(listener)
            if not listeners:
                del self._listeners[topic]

    def _hear(self, topic: str, listener: Listener, msg: Any) -> None:
        try:
            listener(msg)
        except Exception as error:  # an in-process listener's bug is not the delivery's
            self._context.faults.record(f"listening to {topic}", error)

    def subscribe_local(self, topic: str, type_name: str, callback: LocalSubscriber) -> None:
        """Give ``callback`` every message clients publish on ``topic`` of ``type_name``.

        Called for a second type, the topic carries both: a client may advertise either
        (each client's messages are of the type it advertised); the first stays the topic's
        type (what a publish without advertise, rosapi and a typeless subscribe get).
        """
        normalized = normalize_type(type_name)
        self._types.setdefault(topic, normalized)
        self._local.setdefault(topic, {}).setdefault(normalized, []).append(callback)

    def publish(self, topic: str, msg: Any, latch: bool = False,
                type_name: str | None = None) -> None:
        """Queue an in-process message (the robot's, the ROS graph's) for ``topic``'s clients.

        ``type_name``: its type, as its publisher knows it (the ROS graph's subscription
        does); None: the type ``topic`` is known to carry here (the robot's own topics).
        """
        encoded = Encoded(topic, msg, type_name or self._type_of(topic), self._context.clock,
                          self._context.faults)
        if latch:
            self._latch(topic, _Latched(encoded, None))
        _run(self._deliver([encoded]))

    def _latch(self, topic: str, latched: _Latched) -> None:
        """Make ``latched`` ``topic``'s latched message, in place of any before it."""
        self._unlatch(topic)
        self._latched[topic] = latched
        self._context.latched.change(latched.size)

    def _unlatch(self, topic: str, owner: Session | None = None) -> None:
        """Drop ``topic``'s latched message (only if ``owner``'s, when one is given)."""
        latched = self._latched.get(topic)
        if latched is None or (owner is not None and latched.owner is not owner):
            return
        del self._latched[topic]
        self._context.latched.change(-latched.size)

    def latched_topics(self) -> dict[str, int]:
        """Each latched topic and the bytes it counts (in-process ones: 0)."""
        return {topic: latched.size for topic, latched in self._latched.items()}

    def publish_many(self, messages: list[tuple[str, Any]],
                     tick_s: float | None = None) -> Iterator[None]:
        """Queue several in-process messages (one tick's) for their clients, not latched.

        A generator, to be run to its end: it pauses once the clients closing a loop have
        all their messages of the tick queued (``BridgeContext.closing``), so that they can
        be written before the others' are queued. ``tick_s``: when the tick was due
        (monotonic s), the time throttles measure against, so a tick that runs late does not
        make a throttled client miss its message.
        """
        return self._deliver([Encoded(topic, msg, self._type_of(topic), self._context.clock,
                                      self._context.faults)
                              for topic, msg in messages], tick_s)

    def has_subscribers(self, topic: str) -> bool:
        """Whether any client subscribes to ``topic``."""
        return bool(self._subscribers.get(topic))

    def types(self) -> dict[str, str]:
        """Every topic known here and its type."""
        return dict(self._types)

    def subscribed_topics(self) -> Collection[str]:
        """Topics some client subscribes to or an in-process listener listens to.

        A live view while nothing listens: do not keep it.
        """
        if not self._listeners:
            return self._subscribers.keys()
        return self._subscribers.keys() | self._listeners.keys()

    def relayed_topics(self) -> list[str]:
        """Topics some client subscribes to that the simulator does not publish.

        What a ROS graph, once attached, is asked for (``GraphPort.attach``).
        """
        return [topic for topic in self._subscribers if topic not in self._owned]

    def owned(self) -> frozenset[str]:
        """Topics only in-process endpoints publish."""
        return frozenset(self._owned)

    def disconnect(self, session: Session) -> None:
        """Drop every subscription and advertisement of ``session``."""
        for topic in list(session.subscriptions):
            self._drop_subscription(session, topic)
        for topic in list(session.advertised):
            self._drop_advertisement(session, topic)
        for topic in [topic for topic, latched in self._latched.items()
                      if latched.owner is session]:  # latched without advertise, too
            self._unlatch(topic, session)
        self._published_s.pop(session, None)

    # ---- advertise ------------------------------------------------------------------------

    def _known_type(self, topic: str, type_name: str) -> str:
        """Check ``type_name`` against what ``topic`` is known to carry; return it normalised."""
        try:
            normalized = normalize_type(type_name)
        except ValueError as error:
            raise BridgeError(f"{topic}: {error}") from None
        known = self._types.get(topic)
        if known is not None and known != normalized and normalized not in self._local_types(topic):
            carried = " or ".join(dict.fromkeys((known, *self._local_types(topic))))
            raise BridgeError(f"{topic} carries {carried}, not {normalized}")
        return normalized

    def _local_types(self, topic: str) -> Collection[str]:
        """The types in-process subscribers take on ``topic`` (several: it carries them all)."""
        return self._local.get(topic, {}).keys()

    def _wants(self, subscription: Subscription, topic: str, encoded: Encoded) -> bool:
        """Whether a subscriber gets ``encoded``: on a topic of several types, only its own."""
        local = self._local.get(topic)
        if encoded.type_name is None or local is None or len(local) < 2:
            return True
        return (subscription.type_name or self._types.get(topic)) == encoded.type_name

    def _refuse_owned(self, topic: str) -> None:
        if topic in self._owned:
            raise BridgeError(f"{topic} is published by the simulator; clients cannot "
                              "publish it")

    def _advertise(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        self._refuse_owned(topic)
        type_name = self._known_type(topic, message["type"])
        try:
            definitions.check_type(type_name, graph=self._context.graph.attached)
        except self._context.refusals as error:
            raise BridgeError(f"advertise {topic}: {error}") from None
        self._types.setdefault(topic, type_name)
        held = session.advertised.get(topic)
        if held and type_name not in held.values():  # rosbridge: one type per publisher
            raise BridgeError(f"advertise {topic}: this client advertised it as "
                              f"{next(iter(held.values()))}; unadvertise that first")
        session.advertised.setdefault(topic, {})[message.get("id")] = type_name
        if message.get("latch"):
            self._latching.add((session, topic))
        self._context.graph.advertise(session, topic, type_name)

    def _unadvertise(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        ids = session.advertised.get(topic)
        if ids is None or message.get("id") not in ids:
            return  # rosbridge: an id that holds nothing releases nothing
        del ids[message.get("id")]
        if not ids:  # the last id held it (rosbridge counts per id)
            self._drop_advertisement(session, topic)

    def _drop_advertisement(self, session: Session, topic: str) -> None:
        if session.advertised.pop(topic, None) is None:
            return
        self._latching.discard((session, topic))
        self._unlatch(topic, session)  # its latched message goes with its publisher
        still_used = topic in self._owned or topic in self._local or any(
            topic in other.advertised for other in self._context.sessions)
        if not still_used:
            self._types.pop(topic, None)
            self._unlatch(topic)
        if not any(topic in other.advertised for other in self._context.sessions):
            self._context.graph.unadvertise(topic)

    # ---- publish --------------------------------------------------------------------------

    def _publish(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        self._refuse_owned(topic)
        ids = session.advertised.get(topic)
        type_name = next(iter(ids.values())) if ids else self._inferred_type(topic)
        if type_name is None:
            raise BridgeError(f"Cannot infer topic type for topic {topic} as it is not yet "
                              "advertised (advertise it with its type first)")
        msg = message["msg"]
        try:
            msg = definitions.canonical(type_name, msg, graph=self._context.graph.attached)
        except self._context.refusals as error:
            raise BridgeError(f"publish to {topic}: {error}") from None
        size = session.frame_bytes  # what arrived: known before anything is encoded
        latch = bool(message.get("latch")) or (session, topic) in self._latching
        if latch and size > session.limits.max_latched_bytes:
            raise BridgeError(f"publish to {topic}: a latched message may be at most "
                              f"{session.limits.max_latched_bytes} bytes, this one is {size}")
        if latch and (full := self._context.latched.refusal(
                size, self._latched_size(topic))) is not None:
            raise BridgeError(f"publish to {topic}: {full}; message dropped (publish it "
                              "without latch, or unadvertise a latched topic)")
        if not session.relay_budget.take(size):
            raise BridgeError(f"publish to {topic}: more than "
                              f"{session.limits.relay_bytes_per_s} bytes/s published; "
                              "message dropped")
        for callback in self._local.get(topic, {}).get(type_name, ()):
            try:
                callback(msg, session)
            except self._context.refusals as error:
                raise BridgeError(f"{topic}: {error}") from None
        self._published_s[session] = self._context.clock.monotonic_s()
        encoded = Encoded(topic, msg, type_name, self._context.clock, self._context.faults)
        if latch:
            self._latch(topic, _Latched(encoded, session, size))
        _run(self._deliver([encoded]))
        self._context.graph.publish(session, topic, type_name, msg)

    def _latched_size(self, topic: str) -> int:
        latched = self._latched.get(topic)
        return 0 if latched is None else latched.size

    def _inferred_type(self, topic: str) -> str | None:
        """A publish without advertise: the type ``topic`` is known to carry (rosbridge).

        Known from the simulator, another client's advertisement or subscription, or the
        ROS graph.
        """
        known = self._type_of(topic)
        if known is None:
            known = self._context.graph.topic_types().get(topic)
        return known

    def _type_of(self, topic: str) -> str | None:
        """The type ``topic`` is known to carry here (not asking the graph)."""
        return self._types.get(topic) or self._subscribed_types.get(topic)

    def _deliver(self, messages: list[Encoded], now_s: float | None = None) -> Iterator[None]:
        """Queue ``messages`` (one tick's, or one client's publish) for their subscribers.

        A generator: clients closing a loop get all of them queued first (and are noted in
        ``BridgeContext.closing``: written first, in one write); it pauses there if there are
        any, then queues them for the clients that only watch. ``now_s``: the time throttles
        measure against (default: the clock).
        """
        if self._listeners:
            for encoded in messages:
                for listener in tuple(self._listeners.get(encoded.topic, ())):
                    self._hear(encoded.topic, listener, encoded.envelope["msg"])
        now = self._context.clock.monotonic_s() if now_s is None else now_s
        audiences = [(encoded, subscribers) for encoded in messages
                     if (subscribers := self._subscribers.get(encoded.topic))]
        if not audiences:
            return
        closing_loops = self._closing_loops(now)
        for session in closing_loops:
            subscribed = False
            for encoded, subscribers in audiences:
                if session in subscribers:
                    subscribed = True
                    self._queue(session, encoded, now)
            if subscribed:
                self._context.closing[session] = None
        if self._context.closing:
            yield
        for encoded, subscribers in audiences:
            for session in subscribers:
                if session not in closing_loops:
                    self._queue(session, encoded, now)

    def _queue(self, session: Session, encoded: Encoded, now: float) -> None:
        """Queue ``encoded`` for ``session`` unless its throttle holds it back.

        A message that cannot be written in the client's format is recorded once (a fault)
        and skipped for the clients of that format only: one subscriber's failure never
        skips the others.
        """
        topic = encoded.topic
        subscription = session.subscriptions[topic]
        if not self._wants(subscription, topic, encoded):
            return
        throttle_ms = subscription.throttle_in_force_ms
        if throttle_ms > 0 and now - subscription.last_sent_s < \
                throttle_ms / 1000.0 - THROTTLE_JITTER_S:
            return
        subscription.last_sent_s = now
        try:
            frame = encoded.entry(subscription.compression, session.fragment_size,
                                  session.namespace)
        except (TypeError, ValueError) as error:  # a message no encoder can write
            if encoded.report_failure(subscription.compression):
                self._context.faults.record(f"encoding {topic}", error)
            return
        try:
            session.queue_topic(topic, frame, subscription.queue_in_force)
        except Exception as error:  # one client's fault is not the others'
            self._context.faults.record(f"delivering {topic}", error)

    def _closing_loops(self, now: float) -> dict[Session, None]:
        """The clients that published within ``CLOSING_LOOP_S``, in order."""
        if not self._published_s:
            return {}
        stale = [session for session, published_s in self._published_s.items()
                 if now - published_s > CLOSING_LOOP_S]
        for session in stale:
            del self._published_s[session]
        return dict.fromkeys(self._published_s)

    # ---- subscribe ------------------------------------------------------------------------

    def _subscribe(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        named_type = None
        if message.get("type"):
            try:
                named_type = self._known_type(topic, message["type"])
                definitions.check_type(named_type, graph=self._context.graph.attached)
            except self._context.refusals as error:
                raise BridgeError(f"subscribe {topic}: {error}") from None
        limits = session.limits
        throttle_ms = float(message.get("throttle_rate", 0))  # ranges: schema.OP_FIELDS
        queue_length = int(message.get("queue_length", 0))
        subscription = session.subscriptions.get(topic)
        if subscription is not None and named_type is not None \
                and subscription.type_name not in (None, named_type):
            raise BridgeError(f"subscribe {topic}: this client subscribed to it as "
                              f"{subscription.type_name}; unsubscribe that first")
        sub_id = message.get("id")
        if subscription is not None and sub_id not in subscription.throttle_ms \
                and len(subscription.throttle_ms) >= limits.max_ids_per_topic:
            raise BridgeError(f"subscribe {topic}: a client may hold at most "
                              f"{limits.max_ids_per_topic} subscribe ids on one topic")
        compression = message.get("compression", "none")
        if compression == "cbor-raw":
            self._check_cdr(topic)
        if subscription is None:
            subscription = session.subscriptions[topic] = Subscription(type_name=named_type)
        subscription.add(sub_id, throttle_ms, queue_length, compression)
        if named_type is not None and topic not in self._types:
            self._subscribed_types.setdefault(topic, named_type)
        self._subscribers.setdefault(topic, set()).add(session)
        if topic not in self._owned:  # the simulator's own topics come from here only
            self._context.graph.subscribe(session, topic,
                                          message.get("type") or self._types.get(topic))
        latched = self._latched.get(topic)
        if latched is not None and self._wants(subscription, topic, latched.encoded):
            _, length = subscription.effective()
            try:
                frames = latched.encoded.entry(subscription.compression,
                                               session.fragment_size, session.namespace)
            except (TypeError, ValueError) as error:
                raise BridgeError(f"subscribe {topic}: its latched message cannot be sent as "
                                  f"{subscription.compression}: {error}") from None
            session.queue_topic(topic, frames, length)

    def _check_cdr(self, topic: str) -> None:
        """Refuse ``cbor-raw`` on a topic whose known type cannot be serialized as CDR.

        Known here or, as a subscribe without a type to a graph-only topic needs, on the
        ROS graph (what rosapi lists).
        """
        type_name = self._inferred_type(topic)
        if type_name is not None and not cdr.serializable(type_name):
            raise BridgeError(f"subscribe {topic}: cbor-raw needs the message's CDR bytes, "
                              f"and {type_name} is not a type websim can serialize; "
                              "subscribe with compression 'cbor' or 'none'")

    def _unsubscribe(self, session: Session, message: dict[str, Any]) -> None:
        topic = message["topic"]
        subscription = session.subscriptions.get(topic)
        if subscription is None:
            return
        if "id" in message and message["id"] in subscription.throttle_ms \
                and subscription.remove(message["id"]):
            return
        self._drop_subscription(session, topic)

    def _drop_subscription(self, session: Session, topic: str) -> None:
        session.subscriptions.pop(topic, None)
        session.discard_topic(topic)
        subscribers = self._subscribers.get(topic)
        if subscribers is not None:
            subscribers.discard(session)
            if not subscribers:
                del self._subscribers[topic]
                self._subscribed_types.pop(topic, None)
                self._context.graph.unsubscribe(topic)


def _run(steps: Iterator[None]) -> None:
    """Run a delivery to its end (its pause only matters to a tick's)."""
    for _ in steps:
        pass
