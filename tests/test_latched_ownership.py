"""Issue 20, section 2: latched messages belong to their publishers, and are bounded.

A client's latched message goes when that client leaves or unadvertises the topic (as
rosbridge drops it with the publisher), whether it advertised or only published with
``latch: true``; the robot's own latched topics stay. What clients latch on one robot is
bounded in bytes (``ClientLimits.robot_latched_bytes``), and what clients latch on all the
robots of a server too (``server_latched_bytes``), each with a refusal that says so.
"""

from __future__ import annotations

from typing import Any

import pytest
from bridge_rig import Rig, topics_of

from rosbridge.core.limits import ClientLimits, LatchedBytes
from rosbridge.core.session import Session


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
    assert rig.bridge.latched.held_bytes == 0


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
    assert rig.bridge.latched.held_bytes <= ClientLimits().robot_latched_bytes
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
    assert rig.bridge.latched.held_bytes == 0


def latch(rig: Rig, talker: Session, topic: str, size: int) -> list[dict[str, Any]]:
    """``talker`` publishes a latched String of ``size`` characters; the statuses it got."""
    talker.relay_budget.charge(-size)  # this test is about latching, not the relay rate
    rig.send(talker, {"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    rig.send(talker, {"op": "publish", "topic": topic, "msg": {"data": "x" * size},
                      "latch": True})
    return rig.drain(talker)


def test_latched_bytes_of_all_the_robots_of_a_server_are_bounded_together() -> None:
    size = 10_000
    server = LatchedBytes(3 * size + 2_000, robot_limit_bytes=2 * size + 1_000)
    one, two = Rig(latched=server.for_robot()), Rig(latched=server.for_robot())
    first, second = one.client(), two.client()
    for rig, talker in ((one, first), (two, second)):
        rig.send(talker, {"op": "set_level", "level": "error"})
    assert latch(one, first, "/a", size) == latch(one, first, "/b", size) == []
    assert latch(two, second, "/c", size) == []
    refused = latch(two, second, "/d", size)
    assert refused and "this server's latched messages hold" in str(refused[0]["msg"])
    assert server.held_bytes == one.bridge.latched.held_bytes + two.bridge.latched.held_bytes
    one.bridge.disconnect(first)  # its latched messages go, and free the server's pool
    assert one.bridge.latched.held_bytes == 0
    assert latch(two, second, "/d", size) == []
    refused = latch(two, second, "/e", size)
    assert refused and "this robot's latched messages hold" in str(refused[0]["msg"])
