"""Issue 20, section 8: text no encoder can write is refused at the boundary; faults pass.

A string escaping a lone UTF-16 surrogate (``"\\ud800"``) decodes in Python but no UTF-8,
CBOR or CDR encoder can write it: it is refused where the frame is parsed, with the reason.
A message one format cannot write skips only that format's subscribers, and ``degraded``
clears once no fault was caught for ``DEGRADED_FOR_S``.
"""

from __future__ import annotations

import json

import pytest
from bridge_rig import Rig, topics_of

from rosbridge.core.encoding import parse_json
from rosbridge.core.faults import DEGRADED_FOR_S, Faults
from rosbridge.msgs.values import typed_sequence

LONE = '{"op": "publish", "topic": "/t", "msg": {"data": "a\\ud800b"}, "latch": true}'


@pytest.fixture
def rig() -> Rig:
    return Rig()


def test_a_lone_surrogate_is_refused_when_parsed_and_a_pair_is_not() -> None:
    with pytest.raises(ValueError, match="lone UTF-16 surrogate"):
        parse_json(LONE)
    with pytest.raises(ValueError, match="lone UTF-16 surrogate"):
        parse_json(b'{"a": {"\\uDFFF": 1}}')  # keys too, bytes too
    assert parse_json('{"a": "\\ud83d\\ude00"}') == {"a": "\U0001F600"}


def test_a_latched_lone_surrogate_is_refused_and_a_cbor_subscriber_still_gets_the_topic(
        rig: Rig) -> None:
    cbor, plain, talker = rig.client(), rig.client(), rig.client()
    for watcher, compression in ((cbor, "cbor"), (plain, "none")):
        rig.send(watcher, {"op": "subscribe", "topic": "/t", "type": "std_msgs/String",
                           "compression": compression})
    rig.send(talker, {"op": "set_level", "level": "error"})
    rig.send(talker, LONE)
    statuses = rig.drain(talker)
    assert statuses and "lone UTF-16 surrogate" in statuses[0]["msg"]
    rig.send(talker, {"op": "publish", "topic": "/t", "msg": {"data": "ok"}})
    assert topics_of(rig.drain(cbor)) == topics_of(rig.drain(plain)) == ["/t"]
    assert not rig.bridge.faults.degraded


def test_a_message_cbor_cannot_write_skips_only_the_cbor_subscribers(rig: Rig) -> None:
    watchers = {}
    for number, compression in enumerate(("cbor", "none", "cbor", "none")):
        watchers[number] = rig.client()
        rig.send(watchers[number], {"op": "subscribe", "topic": "/bytes",
                                    "compression": compression})
    rig.bridge.publish("/bytes", {"data": typed_sequence("uint8", [1, 300])})
    got = {number: rig.drain(session) for number, session in watchers.items()}
    assert got[0] == got[2] == []
    assert [m["msg"]["data"] for m in got[1]] == [m["msg"]["data"] for m in got[3]] == \
        [[1, 300]]
    assert rig.bridge.faults.total == 1  # recorded once, not per subscriber
    assert json.dumps(rig.bridge.faults.report())


def test_degraded_clears_once_no_fault_was_caught_for_a_while() -> None:
    now = [100.0]
    faults = Faults(clock=lambda: now[0])
    assert not faults.degraded
    faults.record("encoding /t", ValueError("x"))
    assert faults.degraded
    now[0] += DEGRADED_FOR_S - 1
    assert faults.degraded
    now[0] += 2
    assert not faults.degraded
    assert faults.total == 1 and faults.report()["faults_total"] == 1
