"""Property test of the protocol layer: whatever arrives, the bridge answers and the robot runs.

Hypothesis draws arbitrary JSON values, op-shaped dicts (every op of ``schema.OP_FIELDS`` with
its fields filled by well- and ill-typed values: huge integers, any JSON type in any field,
decoy name fields), raw text, bytes and CBOR-encoded binary frames, and feeds them from a
student and an admin client into ``Bridge.handle`` between ticks. Nothing may raise, no fault
may be recorded (an unexpected exception anywhere is a bug), the simulation must keep
stepping with a finite state, and every frame queued for a client must be strict JSON (no
NaN) or CBOR. ``benchmarks/fuzz_protocol.py`` runs the same strategies longer.
"""

from __future__ import annotations

import json
import math
from typing import Any

import cbor2
from bridge_rig import Rig
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rosbridge.core.schema import OP_FIELDS

NAMES = st.sampled_from(["/cmd_vel", "/odom", "/scan", "/tf", "/tf_static", "/world",
                         "/ground_truth", "/chat", "chat", "/rosout", "/reset_simulation",
                         "/rosapi/topics", "/rosapi/set_param", "/rosapi/get_param",
                         "/virtual_robot/set_parameters", "/virtual_robot/get_parameters",
                         "/virtual_robot/list_parameters", "/mine", ""]) | st.text(max_size=12)
"""Topic and service names: the real ones most of the time, anything now and then."""

TYPES = st.sampled_from(["geometry_msgs/msg/Twist", "geometry_msgs/Twist", "std_msgs/String",
                         "nav_msgs/msg/Odometry", "std_srvs/srv/Empty", "not a type",
                         "rcl_interfaces/srv/SetParameters"]) | st.text(max_size=12)

HUGE_INTEGERS = st.sampled_from([10**400, -(10**400), 2**63, 2**64, -(2**63) - 1, 2**53 + 1,
                                 10**308 * 10, 2**31])
"""Integers JSON can carry but no field may hold: beyond float, int64, JavaScript range."""

NUMBERS = (st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10**30, 10**30)
           | HUGE_INTEGERS)

JSON = st.recursive(
    st.none() | st.booleans() | NUMBERS | st.text(max_size=8),
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.text(max_size=6), children, max_size=4),
    max_leaves=20)
"""Arbitrary JSON values (NaN and infinity included, as Python's json writes them)."""

TWIST = st.fixed_dictionaries({}, optional={
    "linear": st.fixed_dictionaries({}, optional={"x": NUMBERS | JSON, "y": NUMBERS}),
    "angular": st.fixed_dictionaries({}, optional={"z": NUMBERS | JSON})})

PARAMETERS = st.fixed_dictionaries({"parameters": st.lists(st.fixed_dictionaries({
    "name": st.sampled_from(["mass_kg", "inertia_kg_m2", "mode", "max_linear_mps",
                             "cmd_vel_timeout_s", "nope"]),
    "value": st.fixed_dictionaries({"type": st.integers(0, 9)}, optional={
        "double_value": NUMBERS, "integer_value": st.integers(-10**20, 10**20),
        "string_value": st.sampled_from(["kinematic", "dynamic", "x"]),
        "bool_value": st.booleans()})}), max_size=3)})

FIELD_VALUES: dict[str, st.SearchStrategy[Any]] = {
    "topic": NAMES, "service": NAMES, "type": TYPES, "msg": TWIST | JSON,
    "args": PARAMETERS | JSON, "values": JSON, "level": st.sampled_from(
        ["info", "warning", "error", "none", "loud"]),
    "compression": st.sampled_from(["none", "cbor", "png", "zip"]),
    "throttle_rate": NUMBERS, "queue_length": st.integers(-5, 150) | HUGE_INTEGERS,
    "fragment_size": NUMBERS, "timeout": NUMBERS, "latch": st.booleans() | JSON,
    "result": st.booleans() | JSON,
}


@st.composite
def operation(draw: st.DrawFn) -> dict[str, Any]:
    """An op-shaped dict: a real op, most of its fields, values mostly of the right kind."""
    op = draw(st.sampled_from(sorted(OP_FIELDS)))
    message: dict[str, Any] = {"op": op}
    for name in OP_FIELDS[op]:
        if draw(st.integers(0, 4)) == 0:
            continue
        confused = draw(st.integers(0, 3)) == 0  # type confusion: any JSON in any field
        message[name] = draw(JSON if confused else FIELD_VALUES.get(name, JSON))
    if draw(st.booleans()):
        message["id"] = draw(st.text(max_size=6) | st.integers() | HUGE_INTEGERS | JSON)
    if draw(st.integers(0, 4)) == 0:  # a decoy name field the op does not use
        message[draw(st.sampled_from(["topic", "service"]))] = draw(NAMES)
    return message


FRAMES = (operation().map(json.dumps) | JSON.map(json.dumps)
          | st.text(max_size=40) | st.binary(max_size=40)
          | operation().map(cbor2.dumps) | JSON.map(cbor2.dumps))
"""One incoming WebSocket message: text (JSON or not) or binary (CBOR-encoded ops, CBOR
values, arbitrary bytes)."""

SESSIONS = st.lists(st.tuples(st.booleans(), FRAMES), min_size=1, max_size=12)
"""A sequence of (from the admin client?, frame)."""


def _strict(constant: str) -> Any:
    raise AssertionError(f"non-finite {constant} sent to a client")


def run_session(frames: list[tuple[bool, str | bytes]]) -> None:
    """Feed ``frames`` into a fresh rig with a tick after each; assert the invariants."""
    rig = Rig()
    student, admin, watcher = rig.client(), rig.client(admin=True), rig.client()
    rig.send(watcher, {"op": "subscribe", "topic": "/odom"})
    for from_admin, frame in frames:
        rig.send(admin if from_admin else student, frame)
        ticks = rig.robot.sim.time_s
        rig.tick()
        assert rig.robot.sim.time_s > ticks, "the simulation keeps stepping"
        assert all(math.isfinite(value) for value in rig.robot.sim.ground_truth())
        assert all(math.isfinite(value) for value in rig.robot.sim.odometry())
        for client in (student, admin, watcher):
            while (out := client.outbox.pop()) is not None:
                if isinstance(out, bytes):
                    cbor2.loads(out)
                else:
                    assert isinstance(json.loads(out, parse_constant=_strict), dict)
    rig.tick()
    assert rig.robot.sim.time_s > 0
    assert not rig.bridge.faults.degraded, rig.bridge.faults.report()


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(SESSIONS)
def test_any_input_leaves_the_bridge_answering_and_the_robot_finite(
        frames: list[tuple[bool, str | bytes]]) -> None:
    run_session(frames)
