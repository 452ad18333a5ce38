"""Issue 20, section 2: latched messages belong to their publishers, and are bounded.

A client's latched message goes when that client leaves or unadvertises the topic (as
rosbridge drops it with the publisher), whether it advertised or only published with
``latch: true``; the robot's own latched topics stay. What clients latch on one robot is
bounded in bytes (``MAX_LATCHED_BYTES_PER_ROBOT``), with a refusal that says so.
"""

from __future__ import annotations

import pytest
from bridge_rig import Rig, topics_of

from rosbridge.core.capabilities.topics import MAX_LATCHED_BYTES_PER_ROBOT
from rosbridge.core.limits import ClientLimits


@pytest.fixture
def rig() -> Rig:
    return Rig()


def late_subscriber_gets(rig: Rig, topic: str) -> list[str]:
    late = rig.client()
    rig.send(late, {"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    return topics_of(rig.drain(late))


def test_a_latched_publish_without_advertise_goes_with_its_publisher(rig: Rig) -> None:
    watcher = rig.client()
    rig.send(watcher, {"op": "subscribe", "topic": "/note", "type": "std_msgs/String"})
    talker = rig.client()
    rig.send(talker, {"op": "publish", "topic": "/note", "msg": {"data": "x"}, "latch": True})
    assert late_subscriber_gets(rig, "/note") == ["/note"]
    rig.bridge.disconnect(talker)
    assert late_subscriber_gets(rig, "/note") == []
    assert rig.bridge.topics.latched_bytes == 0


def test_unadvertising_drops_the_publishers_latched_message(rig: Rig) -> None:
    talker = rig.client()
    rig.send(talker, {"op": "advertise", "topic": "/goal", "type": "std_msgs/String",
                      "latch": True})
    rig.send(talker, {"op": "publish", "topic": "/goal", "msg": {"data": "x"}})
    assert late_subscriber_gets(rig, "/goal") == ["/goal"]
    rig.send(talker, {"op": "unadvertise", "topic": "/goal"})
    assert late_subscriber_gets(rig, "/goal") == []


def test_a_later_publishers_latched_message_is_not_dropped_by_the_first_leaving(
        rig: Rig) -> None:
    first, second = rig.client(), rig.client()
    for talker in (first, second):
        rig.send(talker, {"op": "advertise", "topic": "/goal", "type": "std_msgs/String",
                          "latch": True})
        rig.send(talker, {"op": "publish", "topic": "/goal", "msg": {"data": "x"}})
    rig.bridge.disconnect(first)
    assert late_subscriber_gets(rig, "/goal") == ["/goal"]


def test_the_robots_own_latched_topics_stay_when_clients_leave(rig: Rig) -> None:
    rig.tick()
    client = rig.client()
    rig.bridge.disconnect(client)
    late = rig.client()
    rig.send(late, {"op": "subscribe", "topic": "/tf_static"})
    assert topics_of(rig.drain(late)) == ["/tf_static"]


def test_latched_bytes_per_robot_are_bounded_with_a_clear_refusal(rig: Rig) -> None:
    talker = rig.client()
    rig.send(talker, {"op": "set_level", "level": "error"})
    size = ClientLimits().max_latched_bytes - 200
    accepted = 0
    for number in range(24):  # 1.5 times the bound, within 32 advertised topics
        talker.relay_budget.charge(-size)  # this test is about latching, not the relay rate
        rig.send(talker, {"op": "advertise", "topic": f"/big{number}",
                          "type": "std_msgs/String"})
        rig.send(talker, {"op": "publish", "topic": f"/big{number}",
                          "msg": {"data": "x" * size}, "latch": True})
        if not rig.drain(talker):
            accepted += 1
    assert rig.bridge.topics.latched_bytes <= MAX_LATCHED_BYTES_PER_ROBOT
    assert 14 <= accepted < 24
    talker.relay_budget.charge(-size)
    rig.send(talker, {"op": "publish", "topic": "/big0", "msg": {"data": "y" * size},
                      "latch": True})  # replacing one's own latched message is fine
    assert rig.drain(talker) == []
    other = rig.client()
    rig.send(other, {"op": "set_level", "level": "error"})
    rig.send(other, {"op": "advertise", "topic": "/one_more", "type": "std_msgs/String"})
    rig.send(other, {"op": "publish", "topic": "/one_more", "msg": {"data": "x" * size},
                     "latch": True})
    statuses = rig.drain(other)
    assert statuses and "this robot's latched messages hold" in statuses[0]["msg"]
    rig.bridge.disconnect(talker)
    assert rig.bridge.topics.latched_bytes == 0
