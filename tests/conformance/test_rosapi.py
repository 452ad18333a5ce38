"""rosapi as rosbridge 2.x offers it on ROS 2, against a real ``websim serve``.

Driven by roslibpy (``Ros.get_topics``, ``get_nodes``, ``Param``...), by roslibjs 1.4.1 under
Node (``node/rosapi.js``) and, for the edge cases, by a raw ``websockets`` client. The graph
is the one a ROS 2 robot with rosbridge shows: the README's topics plus ``/rosout`` and
``/parameter_events``, the nodes ``/virtual_robot``, ``/rosbridge_websocket``, ``/rosapi`` and
``/rosapi_params``; parameters as ``/virtual_robot:NAME`` with JSON values and rosapi 2.2's
``successful``/``reason``.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import roslibpy
import websockets.sync.client as ws_client

from ros_nodes.robot_interface import NODE_TOPICS, ROBOT_TOPICS
from ros_nodes.rosapi import ROSAPI_SERVICES
from ros_nodes.rosout import LOG_BURST, WARN

from server_process import ServerProcess, wait_for

ANSWER_TIMEOUT_S = 10.0
NODE = shutil.which("node")
NODE_PROGRAM = Path(__file__).parent / "node" / "rosapi.js"

README_TOPICS = {spec.name: spec.type for spec in ROBOT_TOPICS}
ROBOT_NODES = {"/virtual_robot", "/rosbridge_websocket", "/rosapi", "/rosapi_params"}


def connected(url: str) -> roslibpy.Ros:
    client = roslibpy.Ros(host=url)
    client.run()
    return client


@pytest.fixture
def ros(server: ServerProcess) -> Iterator[roslibpy.Ros]:
    client = connected(server.ws_url)
    yield client
    client.close()


@pytest.fixture
def admin(server: ServerProcess) -> Iterator[roslibpy.Ros]:
    client = connected(server.admin_ws_url)
    yield client
    client.close()


def call(ros: roslibpy.Ros, service: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
    """A rosapi call through roslibpy; {"ok": values} or {"error": reason}."""
    answer: dict[str, Any] = {}
    roslibpy.Service(ros, f"/rosapi/{service}", ROSAPI_SERVICES[service]).call(
        roslibpy.ServiceRequest(args or {}), lambda values: answer.update(ok=dict(values)),
        lambda reason: answer.update(error=reason))
    wait_for(lambda: answer, ANSWER_TIMEOUT_S, f"the answer of /rosapi/{service}")
    return answer


def raw_call(server: ServerProcess, service: str, args: Any) -> dict[str, Any]:
    """A call_service sent as-is over a plain WebSocket; the service_response."""
    with ws_client.connect(server.ws_url, max_size=None) as socket:
        socket.send(json.dumps({"op": "call_service", "id": "raw", "service": service,
                                "args": args}))
        while True:
            reply = json.loads(socket.recv(timeout=ANSWER_TIMEOUT_S))
            if reply.get("op") == "service_response":
                return dict(reply)


def recorder(ros: roslibpy.Ros, topic: str, type_name: str) -> list[dict[str, Any]]:
    messages: list[dict[str, Any]] = []
    listener = roslibpy.Topic(ros, topic, type_name)
    listener.subscribe(messages.append)
    wait_for(lambda: "/rosbridge_websocket" in call(ros, "subscribers", {"topic": topic})
             .get("ok", {}).get("subscribers", []), ANSWER_TIMEOUT_S, f"{topic} subscribed")
    return messages


# ---- the graph ----------------------------------------------------------------------------

def test_get_topics_lists_the_readme_topics_and_every_nodes_rosout_and_parameter_events(
        ros: roslibpy.Ros) -> None:
    topics = ros.get_topics()
    table = dict(zip(topics, call(ros, "topics")["ok"]["types"], strict=True))
    assert {name: table.get(name) for name in README_TOPICS} == README_TOPICS
    assert table["/rosout"] == "rcl_interfaces/msg/Log"
    assert table["/parameter_events"] == "rcl_interfaces/msg/ParameterEvent"
    assert topics == sorted(topics)


def test_topic_type_answers_the_type_and_an_empty_string_for_an_unknown_topic(
        ros: roslibpy.Ros) -> None:
    assert ros.get_topic_type("/scan") == "sensor_msgs/msg/LaserScan"
    assert ros.get_topic_type("/no_such_topic") == ""


def test_topics_for_type_accepts_both_spellings_of_a_type(ros: roslibpy.Ros) -> None:
    assert ros.get_topics_for_type("nav_msgs/msg/Odometry") == ["/ground_truth", "/odom"]
    assert ros.get_topics_for_type("nav_msgs/Odometry") == ["/ground_truth", "/odom"]
    assert ros.get_topics_for_type("no_pkg/msg/Nothing") == []


def test_get_nodes_lists_the_robot_the_bridge_and_rosapis_nodes(ros: roslibpy.Ros) -> None:
    assert set(ros.get_nodes()) == ROBOT_NODES


def test_node_details_of_the_robot_are_its_topics_and_services(ros: roslibpy.Ros) -> None:
    details = ros.get_node_details("/virtual_robot")
    published = {spec.name for spec in ROBOT_TOPICS if spec.direction == "out"}
    assert set(details["publishing"]) == published | {spec.name for spec in NODE_TOPICS}
    assert details["subscribing"] == ["/cmd_vel"]
    assert "/virtual_robot/set_parameters" in details["services"]
    assert "/reset_simulation" in details["services"]
    assert not any(name.startswith("/rosapi/") for name in details["services"])


def test_node_details_of_an_unknown_node_fail_with_the_known_nodes(ros: roslibpy.Ros) -> None:
    answer = call(ros, "node_details", {"node": "virtual_robot"})
    assert "error" in answer and "/virtual_robot" in answer["error"]


def test_publishers_and_subscribers_follow_what_clients_do(
        ros: roslibpy.Ros, server: ServerProcess) -> None:
    assert call(ros, "publishers", {"topic": "/odom"})["ok"]["publishers"] == ["/virtual_robot"]
    assert call(ros, "subscribers", {"topic": "/cmd_vel"})["ok"]["subscribers"] == \
        ["/virtual_robot"]
    assert set(call(ros, "publishers", {"topic": "/rosout"})["ok"]["publishers"]) == ROBOT_NODES
    talker = connected(server.ws_url)
    try:
        chatter = roslibpy.Topic(talker, "/rosapi_test_chatter", "std_msgs/msg/String")
        chatter.advertise()
        wait_for(lambda: call(ros, "publishers", {"topic": "/rosapi_test_chatter"})["ok"]
                 ["publishers"] == ["/rosbridge_websocket"], ANSWER_TIMEOUT_S,
                 "the advertised topic's publisher")
        assert ros.get_topic_type("/rosapi_test_chatter") == "std_msgs/msg/String"
    finally:
        talker.close()
    wait_for(lambda: call(ros, "publishers", {"topic": "/rosapi_test_chatter"})["ok"]
             ["publishers"] == [], ANSWER_TIMEOUT_S, "the publisher gone with its client")


def test_services_list_every_rosapi_service_and_service_type_answers_each(
        ros: roslibpy.Ros) -> None:
    services = ros.get_services()
    assert {f"/rosapi/{name}" for name in ROSAPI_SERVICES} <= set(services)
    assert "/virtual_robot/get_parameters" in services and "/reset_simulation" in services
    assert ros.get_service_type("/rosapi/get_param") == "rosapi_msgs/srv/GetParam"
    assert ros.get_service_type("/reset_simulation") == "std_srvs/srv/Empty"
    assert ros.get_service_type("/no_such_service") == ""


def test_services_for_type_service_node_and_providers_name_the_robot(ros: roslibpy.Ros) -> None:
    assert ros.get_services_for_type("rcl_interfaces/SetParameters") == \
        ["/virtual_robot/set_parameters"]
    assert call(ros, "service_node", {"service": "/reset_simulation"})["ok"]["node"] == \
        "/virtual_robot"
    assert call(ros, "service_node", {"service": "/rosapi/nodes"})["ok"]["node"] == "/rosapi"
    assert call(ros, "service_node", {"service": "/nothing"})["ok"]["node"] == ""
    by_type = call(ros, "service_providers", {"service": "std_srvs/srv/Empty"})["ok"]
    by_name = call(ros, "service_providers", {"service": "/reset_simulation"})["ok"]
    assert by_type["providers"] == by_name["providers"] == ["/virtual_robot"]


def test_action_servers_are_the_tf_republishers_and_interfaces_list_the_known_types(
        ros: roslibpy.Ros) -> None:
    servers: list[Any] = []
    ros.get_action_servers(lambda values: servers.append(values["action_servers"]))
    wait_for(lambda: servers, ANSWER_TIMEOUT_S, "the action servers")
    # served in-process: rosbridge.tf's, and the simulation's (ros_nodes.simulation_services)
    assert servers == [["/simulate_steps", "/tf2_web_republisher"]]
    interfaces = call(ros, "interfaces")["ok"]["interfaces"]
    assert {"nav_msgs/msg/Odometry", "rcl_interfaces/msg/Log",
            "rosapi_msgs/srv/GetParam"} <= set(interfaces)
    assert call(ros, "action_type", {"action": "/fibonacci"})["ok"] == {"type": ""}


# ---- type definitions ---------------------------------------------------------------------

def test_message_details_are_the_typedefs_rosapi_builds_from_the_definition(
        ros: roslibpy.Ros) -> None:
    typedefs = ros.get_message_details("nav_msgs/msg/Odometry")["typedefs"]
    by_type = {typedef["type"]: typedef for typedef in typedefs}
    assert typedefs[0]["type"] == "nav_msgs/Odometry"
    assert typedefs[0]["fieldnames"] == ["header", "child_frame_id", "pose", "twist"]
    assert typedefs[0]["fieldtypes"] == ["std_msgs/Header", "string",
                                         "geometry_msgs/PoseWithCovariance",
                                         "geometry_msgs/TwistWithCovariance"]
    covariance = by_type["geometry_msgs/PoseWithCovariance"]
    assert covariance["fieldtypes"] == ["geometry_msgs/Pose", "double"]
    assert covariance["fieldarraylen"] == [-1, 36] and covariance["examples"] == ["{}", "[]"]
    assert by_type["builtin_interfaces/Time"]["fieldnames"] == ["sec", "nanosec"]
    assert len(by_type) == len(typedefs), "every nested type once"
    log = ros.get_message_details("rcl_interfaces/Log")["typedefs"][0]
    assert dict(zip(log["constnames"], log["constvalues"], strict=True))["WARN"] == str(WARN)
    assert ros.get_message_details("no_pkg/msg/Nothing")["typedefs"] == []


def test_service_request_and_response_details_describe_both_parts(ros: roslibpy.Ros) -> None:
    request = ros.get_service_request_details("rosapi_msgs/srv/GetParam")["typedefs"][0]
    assert request["type"] == "rosapi_msgs/GetParam_Request"
    assert "name" in request["fieldnames"]
    response = ros.get_service_response_details("rcl_interfaces/srv/GetParameters")
    assert response["typedefs"][0]["fieldtypes"] == ["rcl_interfaces/ParameterValue"]
    assert response["typedefs"][0]["fieldarraylen"] == [0]
    empty = ros.get_service_request_details("std_srvs/Empty")["typedefs"]
    assert empty[0]["fieldnames"] == ["structure_needs_at_least_one_member"]


def test_topics_and_raw_types_give_each_types_full_definition(ros: roslibpy.Ros) -> None:
    values = call(ros, "topics_and_raw_types")["ok"]
    texts = dict(zip(values["topics"], values["typedefs_full_text"], strict=True))
    assert "geometry_msgs/PoseWithCovariance pose" in texts["/odom"]
    assert "MSG: geometry_msgs/Vector3" in texts["/odom"]
    assert "float32[] ranges" in texts["/scan"]


# ---- time and version ---------------------------------------------------------------------

def test_get_time_is_the_clock_the_robots_stamps_come_from(ros: roslibpy.Ros) -> None:
    odom: list[dict[str, Any]] = []
    roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(odom.append)
    wait_for(lambda: odom, ANSWER_TIMEOUT_S, "an /odom message")
    answers: list[Any] = []
    ros.get_time(answers.append)  # blocking get_time reads ROS 1's secs/nsecs: not on ROS 2
    wait_for(lambda: answers, ANSWER_TIMEOUT_S, "the time")
    now = answers[0]["time"]
    assert set(now) == {"sec", "nanosec"}
    now_s = now["sec"] + now["nanosec"] * 1e-9
    stamp = odom[0]["header"]["stamp"]
    assert now_s >= stamp["sec"] + stamp["nanosec"] * 1e-9
    assert abs(now_s - time.time()) < 5.0, "wall-clock time, as the stamps"


def test_get_ros_version_is_ros_2_with_a_distribution(ros: roslibpy.Ros) -> None:
    version = call(ros, "get_ros_version")["ok"]
    assert version["version"] == 2 and version["distro"]


# ---- parameters ---------------------------------------------------------------------------

def test_get_params_names_the_robots_parameters_node_colon_name(ros: roslibpy.Ros) -> None:
    names = ros.get_params()
    assert "/virtual_robot:mass_kg" in names and "/virtual_robot:mode" in names
    assert all(name.startswith("/virtual_robot:") for name in names)


def test_param_get_of_a_robot_parameter_is_its_json_value(ros: roslibpy.Ros) -> None:
    assert roslibpy.Param(ros, "/virtual_robot:mode").get() in ("kinematic", "dynamic")
    assert isinstance(roslibpy.Param(ros, "virtual_robot:seed").get(), int), \
        "a relative node name is made absolute, as ROS 2 does"


def test_param_get_of_a_missing_parameter_parses_and_says_why(ros: roslibpy.Ros) -> None:
    assert roslibpy.Param(ros, "/virtual_robot:no_such_param").get() == ""
    answer = call(ros, "get_param", {"name": "/virtual_robot:no_such_param"})["ok"]
    assert answer["value"] == '""' and answer["successful"] is False
    assert "not found" in answer["reason"] and "mass_kg" in answer["reason"]
    malformed = call(ros, "get_param", {"name": "mass_kg"})["ok"]
    assert malformed["successful"] is False and "NODE:PARAM" in malformed["reason"]


def test_get_param_answers_rosapi_2_0s_default_value_for_a_missing_parameter(
        ros: roslibpy.Ros) -> None:
    number = call(ros, "get_param", {"name": "/other_node:gain", "default_value": "2.5"})["ok"]
    text = call(ros, "get_param", {"name": "/virtual_robot:nope", "default_value": "abc"})["ok"]
    assert (number["value"], number["successful"]) == ("2.5", True)
    assert json.loads(text["value"]) == "abc"


def test_param_set_without_admin_rights_reaches_the_callback_with_the_reason(
        ros: roslibpy.Ros) -> None:
    before = roslibpy.Param(ros, "/virtual_robot:max_linear_mps").get()
    answers: list[Any] = []
    roslibpy.Param(ros, "/virtual_robot:max_linear_mps").set(
        0.3, answers.append, lambda error: answers.append(("errback", error)))
    wait_for(lambda: answers, ANSWER_TIMEOUT_S, "set_param's answer")
    assert answers[0]["successful"] is False and "admin" in answers[0]["reason"]
    assert roslibpy.Param(ros, "/virtual_robot:max_linear_mps").get() == before


def test_param_set_with_admin_rights_changes_the_robot_and_announces_it(
        admin: roslibpy.Ros, ros: roslibpy.Ros) -> None:
    events = recorder(ros, "/parameter_events", "rcl_interfaces/msg/ParameterEvent")
    logs = recorder(ros, "/rosout", "rcl_interfaces/msg/Log")
    answers: list[Any] = []
    roslibpy.Param(admin, "/virtual_robot:inertia_kg_m2").set(0.01, answers.append)
    wait_for(lambda: answers, ANSWER_TIMEOUT_S, "set_param's answer")
    assert answers[0] == {"successful": True, "reason": ""}
    assert roslibpy.Param(ros, "/virtual_robot:inertia_kg_m2").get() == 0.01
    wait_for(lambda: events and logs, ANSWER_TIMEOUT_S, "the parameter event and its log")
    event = events[-1]
    assert event["node"] == "/virtual_robot"
    assert [(p["name"], p["value"]["double_value"]) for p in event["changed_parameters"]] == \
        [("inertia_kg_m2", 0.01)]
    assert logs[-1]["name"] == "virtual_robot" and "inertia_kg_m2" in logs[-1]["msg"]


def test_param_set_of_an_out_of_range_value_is_refused_with_the_range(
        admin: roslibpy.Ros) -> None:
    answer = call(admin, "set_param", {"name": "/virtual_robot:max_linear_mps",
                                       "value": "1e308"})["ok"]
    assert answer["successful"] is False and "max_linear_mps" in answer["reason"]
    answer = call(admin, "set_param", {"name": "/virtual_robot:mass_kg", "value": "{oops"})
    assert answer["ok"]["successful"] is False and "JSON" in answer["ok"]["reason"]


def test_has_param_and_delete_of_a_declared_parameter_is_refused_with_the_reason(
        admin: roslibpy.Ros) -> None:
    assert call(admin, "has_param", {"name": "/virtual_robot:mass_kg"})["ok"] == \
        {"exists": True}
    assert call(admin, "has_param", {"name": "/virtual_robot:nope"})["ok"] == {"exists": False}
    assert call(admin, "has_param", {"name": "no colon"})["ok"] == {"exists": False}
    answers: list[Any] = []
    roslibpy.Param(admin, "/virtual_robot:mass_kg").delete(answers.append)
    wait_for(lambda: answers, ANSWER_TIMEOUT_S, "delete_param's answer")
    assert answers[0]["successful"] is False and "cannot be deleted" in answers[0]["reason"]
    assert call(admin, "has_param", {"name": "/virtual_robot:mass_kg"})["ok"]["exists"]
    assert call(admin, "delete_param", {"name": "/virtual_robot:nope"})["ok"] == \
        {"successful": True, "reason": ""}


# ---- /rosout ------------------------------------------------------------------------------

def test_rosout_logs_a_refused_command_and_is_rate_bounded(
        ros: roslibpy.Ros, server: ServerProcess) -> None:
    logs = recorder(ros, "/rosout", "rcl_interfaces/msg/Log")
    sent = int(LOG_BURST) * 3
    with ws_client.connect(server.ws_url) as socket:
        for _ in range(sent):  # NaN is refused: each refusal would be a log line
            socket.send('{"op": "publish", "topic": "/cmd_vel", "msg": '
                        '{"linear": {"x": NaN}, "angular": {"z": 0.0}}}')
        socket.send(json.dumps({"op": "call_service", "id": "done",
                                "service": "/rosapi/get_time"}))
        while json.loads(socket.recv(timeout=ANSWER_TIMEOUT_S)).get("id") != "done":
            pass
    wait_for(lambda: any("/cmd_vel refused" in log["msg"] for log in logs), ANSWER_TIMEOUT_S,
             "the refusal on /rosout")
    refused = [log for log in logs if "/cmd_vel refused" in log["msg"]]
    assert all(log["level"] == WARN and log["name"] == "virtual_robot" for log in refused)
    assert len(refused) < sent, "the log rate is bounded"


def test_rosout_logs_a_reset(ros: roslibpy.Ros) -> None:
    logs = recorder(ros, "/rosout", "rcl_interfaces/msg/Log")
    done: list[Any] = []
    roslibpy.Service(ros, "/reset_simulation", "std_srvs/srv/Empty").call(
        roslibpy.ServiceRequest({}), done.append)
    wait_for(lambda: any("/reset_simulation" in log["msg"] for log in logs), ANSWER_TIMEOUT_S,
             "the reset on /rosout")
    stamp = logs[-1]["stamp"]
    assert math.isclose(stamp["sec"] + stamp["nanosec"] * 1e-9, time.time(), abs_tol=5.0)


# ---- malformed requests -------------------------------------------------------------------

def test_a_request_field_of_the_wrong_type_fails_the_call(server: ServerProcess) -> None:
    reply = raw_call(server, "/rosapi/get_param", {"name": 5})
    assert reply["result"] is False and "expected a string" in reply["values"]


def test_a_request_field_the_service_lacks_fails_the_call(server: ServerProcess) -> None:
    reply = raw_call(server, "/rosapi/topic_type", {"topic": "/odom", "extra": "x"})
    assert reply["result"] is False and "no field" in reply["values"]


def test_missing_request_fields_take_their_defaults(server: ServerProcess) -> None:
    assert raw_call(server, "/rosapi/topic_type", {})["values"] == {"type": ""}
    assert raw_call(server, "/rosapi/get_param", {})["values"]["successful"] is False


def test_a_ten_thousand_character_parameter_name_gets_a_short_reason(
        server: ServerProcess) -> None:
    name = "/virtual_robot:" + "x" * 10_000
    reply = raw_call(server, "/rosapi/get_param", {"name": name})
    assert reply["result"] is True and reply["values"]["successful"] is False
    assert len(reply["values"]["reason"]) < 1000
    assert raw_call(server, "/rosapi/has_param", {"name": name})["values"] == {"exists": False}


# ---- roslibjs -----------------------------------------------------------------------------

def run_roslibjs(url: str) -> dict[str, Any]:
    assert NODE is not None
    result = subprocess.run([NODE, str(NODE_PROGRAM), url], capture_output=True, text=True,
                            timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    return dict(json.loads(result.stdout))


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_roslibjs_rosapi_calls_answer_the_course_snippets(server: ServerProcess) -> None:
    result = run_roslibjs(server.ws_url)
    topics = result["topics"]["callback"][0]
    assert set(README_TOPICS) | {"/rosout", "/parameter_events"} <= set(topics["topics"])
    assert set(result["nodes"]["callback"][0]) == ROBOT_NODES
    subscribing, publishing, _ = result["nodeDetails"]["callback"]
    assert subscribing == ["/cmd_vel"] and "/odom" in publishing
    assert result["odomTopics"]["callback"][0] == ["/ground_truth", "/odom"]
    assert "/rosapi/get_param" in result["services"]["callback"][0]
    assert "/virtual_robot:mass_kg" in result["params"]["callback"][0]
    vector = {"x": "double", "y": "double", "z": "double"}  # decodeTypeDefs gives leaf types
    assert result["twistDecoded"] == {"linear": vector, "angular": vector}
    assert "structure_needs_at_least_one_member" in \
        result["resetRequest"]["callback"][0]["typedefs"][0]["fieldnames"]
    assert isinstance(result["getMass"]["callback"][0], float)
    assert result["getMissing"] == {"callback": [""]}, "JSON.parse of the value does not throw"
    refused = result["setMass"]["callback"][0]
    assert refused["successful"] is False and "admin" in refused["reason"], \
        "roslibjs 1.4.1 reads no 'successful': the refusal reaches its callback"
    assert result["getMassAfter"] == result["getMass"]
    assert result["deleteMass"]["callback"][0]["successful"] is False


@pytest.mark.skipif(NODE is None, reason="node not installed")
def test_roslibjs_param_set_with_admin_rights_changes_the_parameter(
        server: ServerProcess) -> None:
    result = run_roslibjs(server.admin_ws_url)
    assert result["setMass"]["callback"][0] == {"successful": True, "reason": ""}
    assert result["getMassAfter"] == {"callback": [2.5]}
