"""Issue 29, section 4: the fast paths of an incoming /cmd_vel read exactly what the slow ones do.

A frame is parsed by orjson where it reads as the standard library does (else by the
standard library), a message already in canonical form (every field, in order, each a float:
a Twist from any client) is taken as it is, and resolved names are kept. Each fast path gives
the same value, or the same refusal with the same reason, as the general path.
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from physics import ConfigError
from ros_nodes.robot_messages import twist_from_msg
from rosbridge.core.encoding import parse_json
from rosbridge.core.schema import ProtocolError, resolve_name
from rosbridge.msgs import definitions
from rosbridge.msgs.checks import MessageError

TEXTS = [
    '{"a": 1, "a": 2}',  # the last of duplicate keys
    '{"a": 123456789012345678901234567890}',  # beyond 64 bits: every digit kept
    '{"a": -9223372036854775809}',  # just beyond int64
    '{"a": 18446744073709551615}',  # uint64's largest
    '{"a": 0.1234567890123456789}',  # 19 digits in a fraction
    '{"a": NaN, "b": Infinity, "c": -Infinity}',
    '{"a": 1e400, "b": 1e-400}',  # beyond float range: inf and 0.0
    '{"a": -0.0, "b": -0, "c": 1E5}',
    '{"a": "\\ud83d\\ude00", "\u00e9": "\u00fc"}',
    ' [1, {"b": null}] ',
]


@pytest.mark.parametrize("text", TEXTS)
def test_a_frame_parses_to_what_the_standard_library_reads(text: str) -> None:
    for frame in (text, text.encode()):
        parsed, expected = parse_json(frame), json.loads(frame)
        assert repr(parsed) == repr(expected)  # nan and -0.0 compared too
        assert type(parsed["a"] if isinstance(parsed, dict) else parsed[0]) is \
            type(expected["a"] if isinstance(expected, dict) else expected[0])


@pytest.mark.parametrize("text", ['{"a":', '{"a": 1}\x00', "nul", '{"a": "\x01"}', "[1,]"])
def test_invalid_json_gets_the_standard_library_s_reason(text: str) -> None:
    with pytest.raises(ValueError) as expected:
        json.loads(text)
    with pytest.raises(ValueError) as refused:
        parse_json(text)
    assert str(refused.value) == str(expected.value)


TWIST = "geometry_msgs/msg/Twist"


def general(type_name: str, msg: Any) -> Any:
    """The general path of ``canonical`` (no fast path)."""
    return definitions._message(type_name, msg, type_name, 0)


def twist(**linear: Any) -> dict[str, Any]:
    return {"linear": {"x": 0.5, "y": 0.0, "z": 0.0, **linear},
            "angular": {"x": 0.0, "y": 0.0, "z": -0.25}}


@pytest.mark.parametrize("msg", [
    twist(), twist(x=float("nan")), twist(x=2),  # an int: the general path makes it a float
    {"angular": {"x": 0.0, "y": 0.0, "z": 1.0}, "linear": {"x": 1.0, "y": 0.0, "z": 0.0}},
    {"linear": {"x": 1.0}}, {}, {"linear": {"z": 0.0, "y": 0.0, "x": 1.0}},
])
def test_a_twist_comes_out_as_the_general_path_makes_it(msg: dict[str, Any]) -> None:
    made = definitions.canonical(TWIST, msg)
    assert repr(made) == repr(general(TWIST, msg))
    assert list(made) == ["linear", "angular"] and list(made["linear"]) == ["x", "y", "z"]
    assert made is not msg and made["linear"] is not msg.get("linear")  # a copy, always


@pytest.mark.parametrize(("msg", "reason"), [
    (twist(w=1.0), "geometry_msgs/msg/Vector3 has no field 'w'"),
    (twist(x="fast"), "linear.x: expected a number"),
    (twist(x=True), "linear.x: expected a number"),
    ({**twist(), "extra": 1.0}, "has no field 'extra'"),
    ({"linear": [1.0, 0.0, 0.0], "angular": {"x": 0.0, "y": 0.0, "z": 0.0}},
     "linear: expected an object"),
])
def test_a_twist_that_does_not_fit_is_refused_with_the_general_path_s_reason(
        msg: dict[str, Any], reason: str) -> None:
    with pytest.raises(MessageError, match=reason):
        definitions.canonical(TWIST, msg)


def test_a_pose_of_floats_takes_the_fast_path_and_a_header_never_does() -> None:
    pose = {"position": {"x": 1.0, "y": 2.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
    assert definitions._float_tree("geometry_msgs/msg/Pose") is not None
    assert definitions.canonical("geometry_msgs/msg/Pose", pose) == pose
    assert definitions._float_tree("geometry_msgs/msg/TwistStamped") is None  # a Header
    assert definitions._float_tree("std_msgs/msg/Empty") is None


def test_a_resolved_name_is_kept_and_a_refused_one_is_refused_every_time() -> None:
    assert resolve_name("cmd_vel") == resolve_name("/cmd_vel") == "/cmd_vel"
    assert resolve_name("x", "/ns") == "/ns/x"
    for _ in range(2):
        with pytest.raises(ProtocolError, match="is not a ROS name"):
            resolve_name("/bad name")


@pytest.mark.parametrize(("value", "reason"), [
    (float("inf"), "linear.y: expected a finite number"),
    ("1", "linear.y: expected a number"),
    (True, "linear.y: expected a number"),
    (10**400, "linear.y: expected a finite number, got an integer of 401 digits"),
])
def test_twist_from_msg_refuses_every_axis_with_its_reason(value: Any, reason: str) -> None:
    with pytest.raises(ConfigError, match=reason):
        twist_from_msg({"linear": {"x": 0.0, "y": value}})
    assert twist_from_msg({"linear": {"x": 1, "y": 2.0}, "angular": {"z": 0.5}}) == (1.0, 0.5)
