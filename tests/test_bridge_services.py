"""The bridge's services, driven in-process: the robot's, rosapi's and clients' own.

Calls, parameters, client-provided services, their timeouts and their providers leaving.
"""

from __future__ import annotations

from typing import Any

import pytest
from bridge_rig import Rig, topics_of

from ros_nodes.parameters import PARAMETER_DOUBLE, PARAMETER_STRING
from rosbridge.core.bridge import Session


@pytest.fixture
def rig() -> Rig:
    return Rig()


def test_unknown_service_fails_with_reason(rig: Rig) -> None:
    reply = rig.call(rig.client(), "/nope")
    assert reply["result"] is False and "does not exist" in reply["values"]


def test_reset_simulation(rig: Rig) -> None:
    rig.robot.sim.command(0.3, 0.2)
    rig.tick(20)
    reply = rig.call(rig.client(), "/reset_simulation", call_id="call_service:/reset:1")
    assert reply == {"op": "service_response", "service": "/reset_simulation", "values": {},
                     "result": True, "id": "call_service:/reset:1"}
    assert rig.robot.sim.ground_truth() == (0.0, 0.0, 0.0, 0.0, 0.0)


def set_mass(rig: Rig, session: Session, value: Any) -> Any:
    return rig.call(session, "/virtual_robot/set_parameters", {"parameters": [
        {"name": "mass_kg", "value": {"type": PARAMETER_DOUBLE, "double_value": value}}]})


def test_set_parameters_needs_the_admin_token(rig: Rig) -> None:
    reply = set_mass(rig, rig.client(admin=False), 2.4)
    assert reply["result"] is False
    assert "set_parameters needs admin rights" in reply["values"] and "token" in reply["values"]
    assert "ws://HOST:PORT/?token=TOKEN" in reply["values"]  # the single robot's URL
    assert rig.robot.sim.params.mass_kg == 1.2


def test_set_and_get_parameters_with_admin(rig: Rig) -> None:
    admin, student = rig.client(admin=True), rig.client()
    reply = set_mass(rig, admin, 2.4)
    assert reply["result"] is True
    assert reply["values"] == {"results": [{"successful": True, "reason": ""}]}
    got = rig.call(student, "/virtual_robot/get_parameters", {"names": ["mass_kg", "mode",
                                                                       "nope"]})
    values = got["values"]["values"]
    assert values[0]["type"] == PARAMETER_DOUBLE and values[0]["double_value"] == 2.4
    assert values[1]["type"] == PARAMETER_STRING and values[1]["string_value"] == "kinematic"
    assert values[2]["type"] == 0
    bad = set_mass(rig, admin, -1.0)["values"]["results"][0]
    assert bad["successful"] is False
    assert "mass_kg: must be between 0.01 and 1000, got -1.0" in bad["reason"]
    assert rig.robot.sim.params.mass_kg == 2.4


def test_mode_parameter_switches_the_model(rig: Rig) -> None:
    reply = rig.call(rig.client(admin=True), "/virtual_robot/set_parameters", {"parameters": [
        {"name": "mode", "value": {"type": PARAMETER_STRING, "string_value": "dynamic"}}]})
    assert reply["values"]["results"][0]["successful"] is True
    assert rig.robot.sim.mode == "dynamic"


def test_list_and_describe_parameters(rig: Rig) -> None:
    client = rig.client()
    names = rig.call(client, "/virtual_robot/list_parameters", {"prefixes": [], "depth": 0})
    listed = names["values"]["result"]["names"]
    assert {"mode", "mass_kg", "inertia_kg_m2", "max_linear_mps", "max_angular_rps"} <= \
        set(listed)
    described = rig.call(client, "/virtual_robot/describe_parameters", {"names": ["mass_kg"]})
    assert described["values"]["descriptors"][0]["type"] == PARAMETER_DOUBLE


def test_rosapi_topics_types_and_params(rig: Rig) -> None:
    client, admin = rig.client(), rig.client(admin=True)
    topics = rig.call(client, "/rosapi/topics")["values"]
    table = dict(zip(topics["topics"], topics["types"], strict=True))
    assert table["/odom"] == "nav_msgs/msg/Odometry"
    assert table["/tf"] == "tf2_msgs/msg/TFMessage"
    assert rig.call(client, "/rosapi/topic_type", {"topic": "/scan"})["values"] == {
        "type": "sensor_msgs/msg/LaserScan"}
    assert "/virtual_robot/set_parameters" in \
        rig.call(client, "/rosapi/services")["values"]["services"]
    names = rig.call(client, "/rosapi/get_param_names")["values"]["names"]
    assert "/virtual_robot:mass_kg" in names
    assert rig.call(client, "/rosapi/get_param", {"name": "/virtual_robot:mass_kg",
                                                  "default_value": ""})["values"] == {
        "value": "1.2", "successful": True, "reason": ""}
    refused = rig.call(client, "/rosapi/set_param", {"name": "/virtual_robot:mass_kg",
                                                     "value": "3.0"})["values"]
    assert refused["successful"] is False and "admin" in refused["reason"]
    assert rig.call(admin, "/rosapi/set_param", {"name": "/virtual_robot:mass_kg",
                                                 "value": "3.0"})["values"]["successful"]
    assert rig.robot.sim.params.mass_kg == 3.0


def test_client_provided_service_round_trip(rig: Rig) -> None:
    provider, caller = rig.client(), rig.client()
    rig.send(provider, {"op": "advertise_service", "service": "/add",
                        "type": "example_interfaces/AddTwoInts"})
    rig.send(caller, {"op": "call_service", "service": "/add", "id": "mine",
                      "args": {"a": 1, "b": 2}})
    [request] = rig.drain(provider)
    assert request["op"] == "call_service" and request["args"] == {"a": 1, "b": 2}
    rig.send(provider, {"op": "service_response", "service": "/add", "id": request["id"],
                        "values": {"sum": 3}, "result": True})
    assert rig.drain(caller) == [{"op": "service_response", "service": "/add",
                                  "values": {"sum": 3}, "result": True, "id": "mine"}]
    assert rig.bridge.services.types()["/add"] == "example_interfaces/srv/AddTwoInts"


def test_hanging_client_service_times_out(rig: Rig) -> None:
    provider, caller = rig.client(), rig.client()
    rig.send(provider, {"op": "advertise_service", "service": "/slow", "type": "std_srvs/Empty"})
    rig.send(caller, {"op": "call_service", "service": "/slow", "id": "c"})
    rig.send(caller, {"op": "subscribe", "topic": "/odom"})
    rig.tick()
    assert topics_of(rig.drain(caller)) == ["/odom"], "other traffic is not blocked"
    rig.clock.now_s += 4.9
    rig.bridge.services.expire()
    assert rig.drain(caller) == []
    rig.clock.now_s += 0.2
    rig.bridge.services.expire()
    [reply] = rig.drain(caller)
    assert reply["result"] is False and "did not answer within 5 s" in reply["values"]


def test_provider_disconnect_fails_its_pending_calls(rig: Rig) -> None:
    provider, caller = rig.client(), rig.client()
    rig.send(provider, {"op": "advertise_service", "service": "/s", "type": "std_srvs/Empty"})
    rig.send(caller, {"op": "call_service", "service": "/s", "id": "c"})
    rig.bridge.disconnect(provider)
    [reply] = rig.drain(caller)
    assert reply["result"] is False and "disconnected" in reply["values"]
    assert "/s" not in rig.bridge.services.types()


def test_access_denial_of_a_service_call_is_a_failed_response(rig: Rig) -> None:
    client = rig.client()
    reply = rig.call(client, "/bad name!")
    assert reply["result"] is False and "not a ROS name" in reply["values"]
