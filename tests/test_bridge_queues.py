"""The bridge's delivery to each client, driven in-process: throttles and queue lengths.

A hand-advanced monotonic clock (``bridge_rig.Clock``) stands in for time.
"""

from __future__ import annotations

import itertools

import pytest
from bridge_rig import Rig

from rosbridge.core.outbox import Outbox


@pytest.fixture
def rig() -> Rig:
    return Rig()


def test_throttle_rate_drops_messages_inside_the_window(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom", "throttle_rate": 200,
                      "queue_length": 100})
    received = 0
    for _ in range(40):
        rig.tick()
        rig.clock.now_s += 0.05
        received += len(rig.drain(client))
    assert received == 10, "20 Hz throttled to one per 200 ms"


def test_queue_length_keeps_the_newest_messages_for_a_slow_client(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom", "queue_length": 3})
    rig.robot.sim.command(0.1, 0.0)
    rig.tick(10)
    xs = [f["msg"]["pose"]["pose"]["position"]["x"] for f in rig.drain(client)]
    assert xs == pytest.approx([0.040, 0.045, 0.050])
    assert client.outbox.dropped == 7


def test_default_queue_length_0_sends_every_message_while_the_client_keeps_up(
        rig: Rig) -> None:
    """rosbridge with no throttle: queue_length 0 drops nothing (a burst arrives whole)."""
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom"})
    rig.tick(5)
    stamps = [f["msg"]["header"]["stamp"]["nanosec"] for f in rig.drain(client)]
    assert len(stamps) == 5 and stamps == sorted(stamps)
    assert client.outbox.dropped == 0


def test_default_queue_length_0_keeps_only_the_newest_while_the_client_is_behind(
        rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom"})
    rig.tick(3)
    client.outbox.behind = True  # what the connection sets when the socket backs up
    rig.tick(2)
    frames = rig.drain(client)
    assert len(frames) == 1 and client.outbox.dropped == 4
    client.outbox.behind = False
    rig.tick(4)
    assert len(rig.drain(client)) == 4


def test_throttle_never_sends_closer_than_the_rate_less_jitter(rig: Rig) -> None:
    client = rig.client()
    rig.send(client, {"op": "subscribe", "topic": "/odom", "throttle_rate": 200,
                      "queue_length": 100})
    sent_at = []
    lateness = [0.0, 0.004, 0.001, 0.0045, 0.002]  # ticks start late, never early
    for tick in range(60):
        rig.clock.now_s = 100.0 + 0.05 * tick + lateness[tick % len(lateness)]
        rig.tick()
        if rig.drain(client):
            sent_at.append(rig.clock.now_s)
    gaps = [b - a for a, b in itertools.pairwise(sent_at)]
    assert min(gaps) >= 0.195
    assert len(sent_at) == 15, "5 Hz over 3 s despite the jitter"


# ---- the byte budget drops the oldest topic frames, never the reader -------------------------

MEGABYTE = "x" * 1_000_000


def test_a_burst_beyond_the_byte_budget_keeps_the_newest_frames_and_never_overflows() -> None:
    """32 publishers bursting 1 MB each closed a subscriber that read at full speed: its
    outbox overflowed on what others sent. Now the oldest frames make room."""
    for queue_length in (0, 10):
        outbox = Outbox(max_bytes=4 << 20)
        for number in range(32):
            outbox.put_topic("/flood", f"{number:02d}{MEGABYTE}", queue_length)
        assert outbox.overflowed is None
        assert outbox.queued_bytes <= 4 << 20
        frames = outbox.take(1 << 30)
        assert [frame[:2] for frame in frames] == ["28", "29", "30", "31"], "the newest"
        assert outbox.dropped == 28


def test_the_oldest_frames_of_any_topic_make_room_and_replies_are_kept() -> None:
    outbox = Outbox(max_bytes=3_500_000)
    outbox.put_topic("/a", f"a1{MEGABYTE}", 0)
    outbox.put_reply('{"op": "service_response"}')
    outbox.put_topic("/b", f"b1{MEGABYTE}", 0)
    outbox.put_topic("/a", f"a2{MEGABYTE}", 0)
    outbox.put_topic("/b", f"b2{MEGABYTE}", 0)
    assert outbox.overflowed is None
    assert [frame[:2] for frame in outbox.take(1 << 30)] == ['{"', "b1", "a2", "b2"]


def test_replies_past_the_byte_budget_still_overflow() -> None:
    outbox = Outbox(max_bytes=2_500_000)
    outbox.put_topic("/a", f"a1{MEGABYTE}", 0)
    outbox.put_reply(f"r1{MEGABYTE}")
    outbox.put_reply(f"r2{MEGABYTE}")
    assert outbox.overflowed is None, "the topic frame made room"
    outbox.put_reply(f"r3{MEGABYTE}")
    assert outbox.overflowed is not None and "bytes of replies" in outbox.overflowed


def test_a_half_sent_fragmented_message_is_never_dropped() -> None:
    outbox = Outbox(max_bytes=2_500_000)
    fragments = tuple(f"f{index}{'y' * 499_998}" for index in range(4))
    outbox.put_topic("/big", fragments, 0)
    assert outbox.pop() == fragments[0]
    outbox.put_topic("/big", f"n1{MEGABYTE}", 0)
    outbox.put_topic("/other", f"o1{MEGABYTE}", 0)
    assert [frame[:2] for frame in outbox.take(1 << 30)] == ["f1", "f2", "f3", "o1"], \
        "the rest of the half-sent message first, then the newest that fits"
