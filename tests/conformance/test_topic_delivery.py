"""rosbridge's topic semantics, driven by roslibpy and roslibjs against a real ``websim serve``.

* queue_length 0 with no throttle (both libraries' default) sends every message: a burst
  arrives complete and in order (rosbridge_server's own smoke test publishes ten at once);
* an advertisement is counted per ``advertise`` id: unadvertising one id leaves the others;
* a publish without advertise takes the type the topic is known to carry.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
import roslibpy

from server_process import ServerProcess, wait_for

NODE = shutil.which("node")
NODE_PROGRAMS = Path(__file__).parent / "node"
BURST = 100
"""Messages published at once: half of a client's one-second burst of the rate limit."""


def heard(ros: roslibpy.Ros, topic: str, **options: Any) -> list[Any]:
    """Subscribe with roslibpy (its defaults unless ``options``); the list messages go to."""
    messages: list[Any] = []
    listener = roslibpy.Topic(ros, topic, "std_msgs/msg/String", **options)
    listener.subscribe(lambda message: messages.append(message["data"]))
    ros.get_topics()  # a round trip: the subscribe before it is in force
    return messages


def test_queue_length_0_delivers_a_burst_complete_and_in_order_to_roslibpy(
        ros: roslibpy.Ros) -> None:
    messages = heard(ros, "/burst_py")
    talker = roslibpy.Topic(ros, "/burst_py", "std_msgs/msg/String")
    talker.advertise()
    for index in range(BURST):
        talker.publish(roslibpy.Message({"data": str(index)}))
    wait_for(lambda: len(messages) >= BURST, 10.0, f"{BURST} messages")
    time.sleep(0.2)
    assert messages == [str(index) for index in range(BURST)]


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_queue_length_0_delivers_a_burst_complete_and_in_order_to_roslibjs(
        server: ServerProcess, ros: roslibpy.Ros) -> None:
    assert NODE is not None
    subscriber = subprocess.Popen(
        [NODE, str(NODE_PROGRAMS / "burst_subscriber.js"), server.ws_url, "/burst_js",
         str(BURST), "1000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert subscriber.stderr is not None
        for line in subscriber.stderr:  # roslib may warn first
            if line.strip() == "subscribed":
                break
        talker = roslibpy.Topic(ros, "/burst_js", "std_msgs/msg/String")
        talker.advertise()
        for index in range(BURST):
            talker.publish(roslibpy.Message({"data": str(index)}))
        out, err = subscriber.communicate(timeout=30)
    finally:
        subscriber.kill()
    assert subscriber.returncode == 0, err
    assert json.loads(out) == [str(index) for index in range(BURST)]


def test_unadvertising_one_advertise_id_keeps_the_clients_other_ids(
        ros: roslibpy.Ros) -> None:
    messages = heard(ros, "/two_ids")
    first = roslibpy.Topic(ros, "/two_ids", "std_msgs/msg/String")
    second = roslibpy.Topic(ros, "/two_ids", "std_msgs/msg/String")
    first.advertise()
    second.advertise()
    first.unadvertise()
    second.publish(roslibpy.Message({"data": "still advertised"}))
    wait_for(lambda: messages, 5.0, "the message published under the second id")
    assert messages == ["still advertised"]


def test_a_publish_without_advertise_takes_the_topics_known_type(
        server: ServerProcess) -> None:
    """Raw frames: roslibpy and roslibjs always advertise first; rosbridge infers the type."""
    import websockets.sync.client as ws_client

    with ws_client.connect(server.ws_url) as listener, \
            ws_client.connect(server.ws_url) as advertiser, \
            ws_client.connect(server.ws_url) as publisher:
        listener.send(json.dumps({"op": "subscribe", "topic": "/inferred"}))
        advertiser.send(json.dumps({"op": "advertise", "topic": "/inferred",
                                    "type": "std_msgs/msg/String"}))
        publisher.send(json.dumps({"op": "set_level", "level": "error"}))
        publisher.send(json.dumps({"op": "publish", "topic": "/nobody_knows",
                                   "msg": {"data": "x"}}))
        refusal = json.loads(publisher.recv(timeout=5))
        assert refusal["op"] == "status" and "Cannot infer topic type" in refusal["msg"]
        time.sleep(0.1)  # the advertisement is in force
        publisher.send(json.dumps({"op": "publish", "topic": "/inferred", "msg": {}}))
        relayed = json.loads(listener.recv(timeout=5))
    assert relayed["topic"] == "/inferred"
    assert relayed["msg"] == {"data": ""}, "filled as the String it is known to be"


def test_an_advertise_with_latch_true_latches_every_publish(ros: roslibpy.Ros,
                                                            server: ServerProcess) -> None:
    talker = roslibpy.Topic(ros, "/latched_by_advertise", "std_msgs/msg/String", latch=True)
    talker.advertise()
    talker.publish(roslibpy.Message({"data": "kept"}))  # roslibpy sends latch on advertise
    ros.get_topics()
    late = roslibpy.Ros(host="127.0.0.1", port=server.ws_port)
    late.run(timeout=10)
    try:
        messages = heard(late, "/latched_by_advertise")
        wait_for(lambda: messages, 5.0, "the latched message")
    finally:
        late.close()
    assert messages == ["kept"]


def test_a_publish_without_advertise_takes_the_type_a_subscriber_named(
        server: ServerProcess) -> None:
    import websockets.sync.client as ws_client

    with ws_client.connect(server.ws_url) as listener, \
            ws_client.connect(server.ws_url) as publisher:
        listener.send(json.dumps({"op": "subscribe", "topic": "/typed_by_subscriber",
                                  "type": "std_msgs/String"}))
        time.sleep(0.1)
        publisher.send(json.dumps({"op": "publish", "topic": "/typed_by_subscriber",
                                   "msg": {"data": "inferred"}}))
        relayed = json.loads(listener.recv(timeout=5))
    assert relayed["msg"] == {"data": "inferred"}
