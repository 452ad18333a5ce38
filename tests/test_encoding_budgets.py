"""Issue 20, section 1: a message has a small bounded set of encodings; the asker pays.

In-process (a hosted robot on the test's clock, no sockets): fragment sizes are rounded to a
few powers of two; ``png``, ``cbor-raw`` and fragmented forms are ``Deferred`` (made when
the subscriber's frames are taken to be written, their time counted for that subscriber in
``Outbox.encode_s``), and a message keeps at most ``MAX_VARIANTS`` of them, bounded in
bytes, however many subscribers ask for however many sizes.
"""

from __future__ import annotations

import json

import pytest
from bridge_rig import Rig

from rosbridge.core.capabilities.topics import MAX_VARIANTS, VARIANT_BYTES_FACTOR, Encoded
from rosbridge.core.fragments import MIN_TOPIC_FRAGMENT_SIZE, topic_fragment_size
from rosbridge.core.outbox import Deferred, Outbox


@pytest.fixture
def rig() -> Rig:
    return Rig()


@pytest.mark.parametrize("asked, cut_by", [
    (None, None), (1, MIN_TOPIC_FRAGMENT_SIZE), (255, 256), (256, 256), (300, 256),
    (1023, 512), (1024, 1024), (2**31 - 1, 2**30),
])
def test_fragment_sizes_are_rounded_down_to_a_power_of_two_above_a_minimum(
        asked: int | None, cut_by: int | None) -> None:
    assert topic_fragment_size(asked) == cut_by


def test_every_fragment_size_a_client_can_ask_gives_a_dozen_forms_at_most() -> None:
    sizes = {topic_fragment_size(size) for size in range(1, 1 << 21)}
    assert len(sizes) <= 13


def test_costly_formats_are_made_when_written_not_on_the_tick(rig: Rig) -> None:
    watchers = []
    for compression, size in (("png", None), ("none", 512), ("cbor-raw", None)):
        watcher = rig.client()
        rig.send(watcher, {"op": "subscribe", "topic": "/scan", "compression": compression,
                           "fragment_size": size})
        watchers.append(watcher)
    plain = rig.client()
    rig.send(plain, {"op": "subscribe", "topic": "/scan"})
    rig.tick(2)
    for watcher in watchers:
        assert watcher.outbox.has_deferred(), "a costly format was made on the tick"
        assert watcher.outbox.encode_s == 0.0
        frames = watcher.outbox.take(1 << 30)
        assert frames and watcher.outbox.encode_s > 0.0  # made now, counted for this client
    assert not plain.outbox.has_deferred()
    assert json.loads(plain.outbox.take(1 << 30)[0])["topic"] == "/scan"


def test_a_message_keeps_a_bounded_set_of_forms_however_many_sizes_are_asked() -> None:
    encoded = Encoded("/scan", {"data": "x" * 20_000})
    json_chars = len(encoded.json)
    for size in range(1, 20_000, 37):
        for compression in ("none", "png"):
            entry = encoded.entry(compression, size)
            frames = entry.make() if isinstance(entry, Deferred) else entry
            assert frames
    assert len(encoded._variants) <= MAX_VARIANTS
    assert encoded.held_bytes <= (VARIANT_BYTES_FACTOR + 2) * json_chars


def test_fragments_still_reassemble_and_respect_the_asked_size(rig: Rig) -> None:
    watcher = rig.client()
    rig.send(watcher, {"op": "subscribe", "topic": "/scan", "fragment_size": 1000})
    rig.tick(2)
    fragments = [f for f in rig.drain(watcher) if f.get("op") == "fragment"]
    assert fragments and all(len(f["data"]) <= 1000 for f in fragments)
    first = [f for f in fragments if f["id"] == fragments[0]["id"]]
    assert len(first) == first[0]["total"]
    message = json.loads("".join(f["data"] for f in sorted(first, key=lambda f: f["num"])))
    assert message["topic"] == "/scan"


def test_a_deferred_frame_replaced_by_a_newer_one_is_never_made() -> None:
    made = []
    outbox = Outbox()
    outbox.behind = True  # a client behind keeps only the newest of a queue_length 0 topic
    for number in range(5):
        outbox.put_topic("/scan", Deferred(lambda n=number: made.append(n) or f"{n}", 10), 0)
    assert outbox.pop() == "4"
    assert made == [4]
