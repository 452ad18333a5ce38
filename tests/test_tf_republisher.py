"""tf2_web_republisher on the robot's bridge (``rosbridge.tf.republisher``), driven tick by tick.

The robot's own ``/tf`` (odom -> base_link, from its odometry) and ``/tf_static`` (base_link ->
laser, at the LiDAR's mount) are the tree; what the republisher sends is checked against the
odometry and the mount composed by hand, at the rate and thresholds the request asked for.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import pytest
from robot_rig import RobotRig, robot_rig

from physics import LidarParams
from rosbridge.core.outbox import Outbox
from rosbridge.core.schema import GoalStatus
from rosbridge.core.session import Session
from rosbridge.tf.republisher import (
    ACTION,
    ACTION_TYPE,
    DEFAULT_TIMEOUT_S,
    REPUBLISH_SERVICE,
    RepublisherLimits,
)

MOUNT = replace(LidarParams(), mount_x_m=0.1, mount_y_m=0.05, mount_yaw_rad=math.pi / 2)
"""A laser 10 cm ahead, 5 cm left, turned 90 degrees: the composition shows in every number."""


def request(frames: list[str], target: str = "odom", rate: float = 20.0,
            angular: float = 0.0, trans: float = 0.0, timeout_s: float = 0.0) -> Any:
    """``RepublishTFs`` args as roslib 1.4.1's TFClient writes them (a ROS 1 Duration)."""
    return {"source_frames": frames, "target_frame": target, "angular_thres": angular,
            "trans_thres": trans, "rate": rate,
            "timeout": {"secs": int(timeout_s), "nsecs": round(timeout_s % 1 * 1e9)}}


def drive(rig: RobotRig, client: Session, v: float, w: float) -> None:
    rig.send(client, {"op": "publish", "topic": "/cmd_vel",
                      "msg": {"linear": {"x": v, "y": 0.0, "z": 0.0},
                              "angular": {"x": 0.0, "y": 0.0, "z": w}}})


def arrays(rig: RobotRig, client: Session, topic: str) -> list[list[Any]]:
    """The transforms of each message ``client`` got on ``topic`` since last asked."""
    return [frame["msg"]["transforms"] for frame in rig.drain(client)
            if frame.get("op") == "publish" and frame["topic"] == topic]


def pose_of(transform: Any) -> tuple[float, float, float]:
    """(x, y, yaw) of a planar TransformStamped."""
    t, r = transform["transform"]["translation"], transform["transform"]["rotation"]
    assert t["z"] == pytest.approx(0.0) and r["x"] == pytest.approx(0.0) == r["y"]
    return t["x"], t["y"], 2.0 * math.atan2(r["z"], r["w"])


def expected(rig: RobotRig, frame: str) -> tuple[float, float, float]:
    """``frame`` 's pose in odom, worked out from the odometry and the mount."""
    odom = rig.robot.sim.odometry()
    if frame == "base_link":
        return odom.x, odom.y, odom.theta
    c, s = math.cos(odom.theta), math.sin(odom.theta)
    return (odom.x + c * MOUNT.mount_x_m - s * MOUNT.mount_y_m,
            odom.y + s * MOUNT.mount_x_m + c * MOUNT.mount_y_m, odom.theta + MOUNT.mount_yaw_rad)


def assert_same_pose(got: tuple[float, float, float], want: tuple[float, float, float]) -> None:
    assert got[:2] == pytest.approx(want[:2], abs=1e-9)
    assert math.remainder(got[2] - want[2], 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


@pytest.fixture
def rig() -> RobotRig:
    return robot_rig(lidar=MOUNT)


@pytest.fixture
def driver(rig: RobotRig) -> Session:
    client = rig.client("driver")
    rig.send(client, {"op": "advertise", "topic": "/cmd_vel", "type": "geometry_msgs/Twist"})
    return client


def test_the_service_answers_a_topic_that_carries_the_frames_in_the_fixed_frame(
        rig: RobotRig, driver: Session) -> None:
    page = rig.client("page")
    reply = rig.call(page, REPUBLISH_SERVICE, request(["base_link", "/laser", "odom"], rate=10))
    topic = reply["values"]["topic_name"]
    assert reply["result"] and topic == "/tf_repub_0"
    assert rig.call(page, "/rosapi/topic_type", {"topic": topic})["values"]["type"] == \
        "tf2_web_republisher/msg/TFArray"
    rig.tick(4)
    assert arrays(rig, page, topic) == []  # nothing while nobody subscribes
    rig.send(page, {"op": "subscribe", "topic": topic, "type": "tf2_web_republisher/TFArray"})
    drive(rig, driver, 0.2, 0.5)
    sent_at = []
    for tick in range(8):
        rig.tick()
        for transforms in arrays(rig, page, topic):  # thresholds 0: every frame, every time
            sent_at.append(tick)
            assert [t["child_frame_id"] for t in transforms] == ["base_link", "laser", "odom"]
            assert {t["header"]["frame_id"] for t in transforms} == {"odom"}
            for transform in transforms[:2]:
                assert_same_pose(pose_of(transform), expected(rig, transform["child_frame_id"]))
            assert_same_pose(pose_of(transforms[2]), (0.0, 0.0, 0.0))
    assert sent_at == [0, 2, 4, 6]  # 10 Hz on 20 Hz ticks
    assert rig.robot.sim.odometry().theta > 0.15  # it did turn: the yaws were not all zero


def test_a_frame_is_sent_again_only_once_it_moved_or_turned_past_its_threshold(
        rig: RobotRig, driver: Session) -> None:
    page = rig.client("page")
    trans_thres_m, angular_thres_rad = 0.045, 0.12
    topic = rig.call(page, REPUBLISH_SERVICE, request(
        ["base_link", "odom"], angular=angular_thres_rad, trans=trans_thres_m))["values"][
        "topic_name"]
    rig.send(page, {"op": "subscribe", "topic": topic})
    sent: list[tuple[float, float, float]] = []
    odom_frames = 0
    for v, w in ((0.2, 0.0), (0.0, 1.0)):  # 1 cm per tick, then 0.05 rad per tick
        drive(rig, driver, v, w)
        for _ in range(20):
            rig.tick()
            now = expected(rig, "base_link")
            for transforms in arrays(rig, page, topic):
                for transform in transforms:
                    if transform["child_frame_id"] == "odom":
                        odom_frames += 1
                        continue
                    assert_same_pose(pose_of(transform), now)
                    if sent:  # sent because it moved or turned past a threshold
                        last = sent[-1]
                        assert math.dist(now[:2], last[:2]) > trans_thres_m or \
                            abs(math.remainder(now[2] - last[2], 2 * math.pi)) > \
                            angular_thres_rad
                    sent.append(now)
                break
            else:  # not sent: it stayed within both thresholds of what was sent last
                last = sent[-1]
                assert math.dist(now[:2], last[:2]) <= trans_thres_m + 1e-12
                assert abs(math.remainder(now[2] - last[2], 2 * math.pi)) <= \
                    angular_thres_rad + 1e-12
    assert odom_frames == 1  # odom in odom never moves: sent once
    # x 1, 6, 11, 16 cm (steps of 5 cm > 4.5 cm; 20 cm at the end is 4 cm on), then yaw 0.15,
    # 0.30, ... 0.90 rad (steps of 0.15 rad > 0.12 rad; 1 rad at the end is 0.10 on)
    assert len(sent) == 10


def test_a_topic_nobody_subscribes_goes_after_its_timeout(rig: RobotRig) -> None:
    page = rig.client("page")
    republisher = rig.host.tf_republisher
    topic = rig.call(page, REPUBLISH_SERVICE, request(["base_link"], timeout_s=0.5))[
        "values"]["topic_name"]
    assert "/tf" in rig.bridge.topics.subscribed_topics()  # the robot builds /tf for it
    rig.send(page, {"op": "subscribe", "topic": topic})
    rig.tick(20)  # subscribed: it stays, however long
    assert republisher.held(page) == 1
    rig.send(page, {"op": "unsubscribe", "topic": topic})
    rig.tick(10)  # 0.45 s without a subscriber
    assert republisher.held(page) == 1
    rig.tick(2)
    assert republisher.held(page) == 0
    assert "/tf" not in rig.bridge.topics.subscribed_topics()  # and nobody listens any more
    assert not republisher.buffer.frames()
    rig.send(page, {"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    assert rig.bridge.topic_types()[topic] == "std_msgs/msg/String"  # the name is free again


def test_a_timeout_of_zero_is_the_default(rig: RobotRig) -> None:
    page = rig.client("page")
    rig.call(page, REPUBLISH_SERVICE, request(["base_link"], timeout_s=0.0))
    rig.tick(round(DEFAULT_TIMEOUT_S / 0.05) - 2)
    assert rig.host.tf_republisher.held() == 1
    rig.tick(3)
    assert rig.host.tf_republisher.held() == 0


def test_a_clients_republications_are_bounded_oldest_unsubscribed_replaced_first(
        rig: RobotRig) -> None:
    limits = RepublisherLimits()
    page = rig.client("page")
    topics = [rig.call(page, REPUBLISH_SERVICE, request(["base_link"]))["values"]["topic_name"]
              for _ in range(limits.per_client)]
    for topic in topics[1:]:
        rig.send(page, {"op": "subscribe", "topic": topic})
    newest = rig.call(page, REPUBLISH_SERVICE, request(["base_link"]))["values"]["topic_name"]
    assert newest not in topics
    assert topics[0] not in rig.bridge.topic_types()  # the one nobody subscribed went
    assert rig.host.tf_republisher.held(page) == limits.per_client
    rig.send(page, {"op": "subscribe", "topic": newest})
    refused = rig.call(page, REPUBLISH_SERVICE, request(["base_link"]))
    assert not refused["result"]
    assert f"at most {limits.per_client} TF republications" in refused["values"]


def test_the_bridge_serves_a_bounded_number_of_republications(rig: RobotRig) -> None:
    limits = RepublisherLimits()
    pages = [rig.client(f"page{n}") for n in range(limits.per_bridge // limits.per_client)]
    for page in pages:
        for _ in range(limits.per_client):
            assert rig.call(page, REPUBLISH_SERVICE, request(["base_link"]))["result"]
    refused = rig.call(rig.client("late"), REPUBLISH_SERVICE, request(["base_link"]))
    assert not refused["result"] and "serves 64 republications already" in refused["values"]


def test_watchers_of_a_robot_never_take_its_owners_share(rig: RobotRig) -> None:
    """Tokenless watchers of a classmate's robot took all 64 republications: its owner's
    page was refused. Watchers together hold at most what the owner's reserve leaves."""
    limits = RepublisherLimits()
    watchers = [Session(f"watcher{n}", False, Outbox(), may_drive=False)
                for n in range(limits.per_bridge // limits.per_client)]
    granted = 0
    for watcher in watchers:
        rig.bridge.connect(watcher)
        for _ in range(limits.per_client):
            reply = rig.call(watcher, REPUBLISH_SERVICE, request(["base_link"]))
            granted += reply["result"]
    assert granted == limits.per_bridge - limits.owner_reserve
    assert "are kept for its owner" in reply["values"]
    owner = rig.client("owner")  # may drive: its token (a single robot: everyone)
    for _ in range(limits.per_client):
        assert rig.call(owner, REPUBLISH_SERVICE, request(["base_link"]))["result"]
    instructor = rig.client("instructor", admin=True)
    for _ in range(limits.owner_reserve - limits.per_client):
        assert rig.call(instructor, REPUBLISH_SERVICE, request(["base_link"]))["result"]
    assert rig.host.tf_republisher.held() == limits.per_bridge
    rig.bridge.disconnect(watchers[0])  # a watcher's leaving frees a watcher's slots
    newcomer = Session("watcher-late", False, Outbox(), may_drive=False)
    rig.bridge.connect(newcomer)
    assert rig.call(newcomer, REPUBLISH_SERVICE, request(["base_link"]))["result"]


@pytest.mark.parametrize(("changes", "reason"), [
    ({"rate": 0.0}, "rate: must be more than 0 and at most 100 Hz, got 0"),
    ({"rate": 1000.0}, "rate: must be more than 0 and at most 100 Hz, got 1000"),
    ({"angular_thres": -0.1}, "angular_thres: must be 0 or more"),
    ({"trans_thres": math.inf}, "trans_thres: must be 0 or more"),
    ({"source_frames": [f"f{n}" for n in range(33)]}, "source_frames: at most 32 frames"),
    ({"target_frame": "/"}, "target_frame: empty"),
    ({"timeout": {"sec": 61, "nanosec": 0}}, "timeout: must be 0 (the default, 2 s) to 60 s"),
    ({"rate": "fast"}, "rate: expected a number"),
    ({"frames": ["odom"]}, "has no field 'frames'"),
])
def test_requests_out_of_range_are_refused_with_the_field(
        rig: RobotRig, changes: dict[str, Any], reason: str) -> None:
    page = rig.client("page")
    reply = rig.call(page, REPUBLISH_SERVICE, {**request(["base_link"]), **changes})
    assert not reply["result"]
    assert reason in reply["values"]
    assert rig.host.tf_republisher.held() == 0


def send_goal(rig: RobotRig, client: Session, goal_id: str, frames: list[str],
              action_type: str = "tf2_web_republisher_interfaces/TFSubscription") -> None:
    args = {key: value for key, value in request(frames).items() if key != "timeout"}
    rig.send(client, {"op": "send_action_goal", "action": ACTION, "action_type": action_type,
                      "args": args, "id": goal_id, "feedback": True})


def test_the_action_sends_the_frames_as_feedback_until_cancelled(
        rig: RobotRig, driver: Session) -> None:
    page = rig.client("page")
    send_goal(rig, page, "goal-1", ["base_link", "laser"])
    drive(rig, driver, 0.3, -0.4)
    for _ in range(3):
        rig.tick()
        [feedback] = [f for f in rig.drain(page) if f["op"] == "action_feedback"]
        assert feedback["id"] == "goal-1" and feedback["action"] == ACTION
        base_link, laser = feedback["values"]["transforms"]
        assert_same_pose(pose_of(base_link), expected(rig, "base_link"))
        assert_same_pose(pose_of(laser), expected(rig, "laser"))
    rig.send(page, {"op": "cancel_action_goal", "action": ACTION, "id": "goal-1"})
    [result] = rig.drain(page)
    assert (result["op"], result["id"], result["status"], result["result"]) == \
        ("action_result", "goal-1", GoalStatus.CANCELED, True)
    rig.tick(3)
    assert rig.drain(page) == [] and rig.host.tf_republisher.held() == 0


def test_a_goal_of_another_type_is_refused(rig: RobotRig) -> None:
    page = rig.client("page")
    send_goal(rig, page, "goal-1", ["base_link"], "tf2_web_republisher/TFSubscription")
    [result] = rig.drain(page)
    assert result["op"] == "action_result" and not result["result"]
    assert f"is of type {ACTION_TYPE}" in result["values"]


def test_a_client_that_leaves_frees_what_it_held(rig: RobotRig) -> None:
    page, other = rig.client("page"), rig.client("other")
    for _ in range(3):
        rig.call(page, REPUBLISH_SERVICE, request(["base_link"]))
    send_goal(rig, page, "goal-1", ["laser"])
    send_goal(rig, other, "goal-2", ["laser"])
    assert rig.host.tf_republisher.held(page) == 4
    rig.bridge.disconnect(page)
    assert rig.host.tf_republisher.held() == 1  # the other client's goal
    rig.bridge.disconnect(other)
    assert rig.host.tf_republisher.held() == 0
    assert "/tf" not in rig.bridge.topics.subscribed_topics()


def test_a_class_watcher_may_use_the_republisher_but_not_drive() -> None:
    rig = robot_rig()
    watcher = Session("watcher", False, may_drive=False)
    rig.bridge.connect(watcher)
    assert rig.call(watcher, REPUBLISH_SERVICE, request(["base_link"]))["result"]
    send_goal(rig, watcher, "goal-1", ["base_link"])
    rig.tick()
    assert [f["op"] for f in rig.drain(watcher)] == ["action_feedback"]
    rig.send(watcher, {"op": "send_action_goal", "action": "/fibonacci", "id": "goal-2",
                       "action_type": "example_interfaces/Fibonacci", "args": {"order": 3}})
    [result] = rig.drain(watcher)
    assert not result["result"] and "needs its token" in result["values"]


def test_rosapi_lists_the_republishers_action_and_service(rig: RobotRig) -> None:
    client = rig.client()
    assert ACTION in rig.call(client, "/rosapi/action_servers")["values"]["action_servers"]
    assert rig.call(client, "/rosapi/action_type", {"action": ACTION})["values"]["type"] == \
        ACTION_TYPE
    assert rig.call(client, "/rosapi/service_type", {"service": REPUBLISH_SERVICE})[
        "values"]["type"] == "tf2_web_republisher/srv/RepublishTFs"
    goal = rig.call(client, "/rosapi/action_goal_details", {"type": ACTION_TYPE})
    assert goal["values"]["typedefs"][0]["fieldnames"] == [
        "source_frames", "target_frame", "angular_thres", "trans_thres", "rate"]
