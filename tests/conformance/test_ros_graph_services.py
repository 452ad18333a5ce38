"""Services and rosapi across ``websim serve --ros``, as through rosbridge.

A service on the ROS graph (an rclpy server in this test) is callable from a roslibpy
client; a service a roslibpy client advertises is on the graph, and an rclpy client's call
reaches it and gets its answer; rosapi lists the graph's nodes with what they do.
"""

from __future__ import annotations

from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)

import roslibpy  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from ros_fixtures import Graph  # noqa: E402
from server_process import ServerProcess, wait_for  # noqa: E402

CALL_TIMEOUT_S = 15.0


def test_a_service_on_the_graph_is_callable_from_roslibpy(
        graph: Graph, ros_client: roslibpy.Ros) -> None:
    def set_bool(request: Any, response: Any) -> Any:
        response.success = request.data
        response.message = f"graph got {request.data}"
        return response

    graph.node.create_service(SetBool, "/graph_setbool", set_bool)
    service = roslibpy.Service(ros_client, "/graph_setbool", "std_srvs/srv/SetBool")

    def answered() -> dict[str, Any] | None:
        """Call until the server has discovered the service (rosbridge: "does not exist")."""
        answer: dict[str, Any] = {}
        service.call(roslibpy.ServiceRequest({"data": True}),
                     lambda values: answer.update(ok=dict(values)),
                     lambda reason: answer.update(error=reason))
        graph.spin_until(lambda: answer, CALL_TIMEOUT_S, "an answer")
        return answer if "ok" in answer else None

    answer = graph.spin_until(answered, CALL_TIMEOUT_S, "the graph service's answer")
    assert answer == {"ok": {"success": True, "message": "graph got True"}}


def test_a_service_roslibpy_advertises_is_callable_from_rclpy(
        graph: Graph, ros_client: roslibpy.Ros) -> None:
    def provide(request: dict[str, Any], response: dict[str, Any]) -> bool:
        response["success"] = not request["data"]
        response["message"] = "answered by a roslibpy client"
        return True

    provider = roslibpy.Service(ros_client, "/browser_setbool", "std_srvs/srv/SetBool")
    provider.advertise(provide)
    wait_for(lambda: "/browser_setbool" in dict(graph.node.get_service_names_and_types()),
             CALL_TIMEOUT_S, "the client's service on the graph")
    response = graph.call(SetBool, "/browser_setbool", SetBool.Request(data=False),
                          CALL_TIMEOUT_S)
    assert (response.success, response.message) == (True, "answered by a roslibpy client")
    provider.unadvertise()
    wait_for(lambda: "/browser_setbool" not in dict(graph.node.get_service_names_and_types()),
             CALL_TIMEOUT_S, "the service withdrawn from the graph")


def test_a_call_to_a_service_nobody_offers_fails_with_the_reason(
        graph: Graph, ros_client: roslibpy.Ros) -> None:
    answer: dict[str, Any] = {}
    roslibpy.Service(ros_client, "/nobody_offers", "std_srvs/srv/SetBool").call(
        roslibpy.ServiceRequest({"data": True}), lambda values: answer.update(ok=values),
        lambda reason: answer.update(error=reason))
    wait_for(lambda: answer, CALL_TIMEOUT_S, "the failure")
    assert "does not exist" in str(answer["error"])


def test_rosapi_lists_the_graphs_nodes_with_their_topics_and_services(
        graph: Graph, ros_client: roslibpy.Ros) -> None:
    graph.node.create_publisher(String, "/from_the_graph", 10)
    graph.node.create_service(SetBool, "/graph_node_service", lambda req, res: res)
    node_name = graph.node.get_fully_qualified_name()

    def details() -> dict[str, Any] | None:
        if node_name not in ros_client.get_nodes():
            return None
        found = ros_client.get_node_details(node_name)
        # Discovery announces a node's publishers and services separately:
        # wait for both, then check what else the entry holds.
        seen = "/from_the_graph" in found["publishing"] and \
            "/graph_node_service" in found["services"]
        return found if seen else None

    found = graph.spin_until(details, CALL_TIMEOUT_S,
                             f"{node_name} in rosapi's nodes with its topic and service")
    assert f"{node_name}/get_parameters" in found["services"], "its own parameter services too"
    assert "/virtual_robot" in ros_client.get_nodes(), "the robot's own entry stays"


def test_rosapi_gets_and_sets_a_graph_nodes_parameter_through_its_own_services(
        graph: Graph, ros_client: roslibpy.Ros) -> None:
    graph.node.declare_parameter("gain", 2.5)
    name = f"{graph.node.get_fully_qualified_name()}:gain"

    def got(client: roslibpy.Ros) -> Any:
        answer: list[Any] = []
        roslibpy.Param(client, name).get(answer.append)
        graph.spin_until(lambda: answer, CALL_TIMEOUT_S, f"the answer for {name}")
        return answer[0]

    graph.spin_until(lambda: got(ros_client) == 2.5, CALL_TIMEOUT_S,
                     "rosapi to reach the node's parameter (once discovered)")
    done: list[Any] = []  # no admin token: only the robot's own parameters need one
    roslibpy.Param(ros_client, name).set(4.0, done.append)
    graph.spin_until(lambda: done, CALL_TIMEOUT_S, "set_param's answer")
    assert graph.node.get_parameter("gain").value == 4.0
    assert got(ros_client) == 4.0
    names: list[Any] = []  # this node answers list_parameters only while it spins
    ros_client.get_params(lambda answer: names.extend(answer["names"]))
    graph.spin_until(lambda: names, CALL_TIMEOUT_S, "get_param_names' answer")
    assert name in names and "/virtual_robot:mass_kg" in names


def test_a_provider_leaving_mid_call_answers_the_ros_caller_and_a_new_provider_takes_over(
        graph: Graph, ros_server: ServerProcess) -> None:
    """rosbridge's advertise_service_duplicate: the next client's service serves the graph."""
    import json

    import websockets.sync.client as ws_client

    advertise = json.dumps({"op": "advertise_service", "type": "std_srvs/SetBool",
                            "service": "/handed_over"})
    client = graph.node.create_client(SetBool, "/handed_over")
    with ws_client.connect(ros_server.ws_url) as first:
        first.send(advertise)
        graph.spin_until(client.service_is_ready, CALL_TIMEOUT_S, "the first provider")
        pending = client.call_async(SetBool.Request(data=True))
        assert json.loads(first.recv(timeout=CALL_TIMEOUT_S))["op"] == "call_service"
    graph.spin_until(pending.done, CALL_TIMEOUT_S, "the ROS caller's answer after the "
                     "provider left (the default response; ROS 2 services cannot fail)")
    with ws_client.connect(ros_server.ws_url) as second:
        second.send(advertise)
        graph.spin_until(client.service_is_ready, CALL_TIMEOUT_S, "the second provider")

        def reached_second() -> Any:
            call = client.call_async(SetBool.Request(data=False))
            try:
                return json.loads(second.recv(timeout=1.0))
            except TimeoutError:
                client.remove_pending_request(call)
                return None

        request = graph.spin_until(reached_second, CALL_TIMEOUT_S, "a call at the second")
    assert request["op"] == "call_service" and request["args"] == {"data": False}
