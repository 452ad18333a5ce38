"""One clock per robot: it stamps the messages and times the host (idle, last command's age)."""

from __future__ import annotations

from robot_rig import robot_rig

from rosbridge.core.clock import ManualClock

TWIST = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


def test_the_clock_stamps_the_messages_and_ages_the_last_command() -> None:
    rig = robot_rig(clock=ManualClock(10.0, epoch_s=1_700_000_000.0))
    admin = rig.client(admin=True)
    rig.send(admin, {"op": "subscribe", "topic": "/odom"})
    rig.send(admin, {"op": "publish", "topic": "/cmd_vel", "msg": TWIST})
    rig.tick()  # at 10 s, then the clock moves to 10.05 s
    [odom] = [frame for frame in rig.drain(admin) if frame.get("topic") == "/odom"]
    assert odom["msg"]["header"]["stamp"] == {"sec": 1_700_000_010, "nanosec": 0}
    rig.clock.advance(2.0)
    assert rig.call(admin, "/websim/status")["values"]["last_drive_age_s"] == 2.05
    now = rig.call(admin, "/rosapi/get_time")["values"]["time"]
    assert now["sec"] == 1_700_000_012 and abs(now["nanosec"] - 50_000_000) < 1_000


def test_the_clock_times_the_idle_pause() -> None:
    rig = robot_rig(idle_pause_s=1.0)
    host, clock = rig.host, rig.clock
    rig.tick_now()
    clock.advance(0.99)
    rig.tick_now()
    assert (host.stats.ticks, host.stats.paused) == (2, False)
    clock.advance(0.01)
    rig.tick_now()
    assert (host.stats.ticks, host.stats.paused) == (2, True)
