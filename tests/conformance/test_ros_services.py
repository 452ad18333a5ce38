"""Services across ``websim serve --ros``, as through rosbridge: both directions.

A service on the ROS graph (an rclpy server in this test) is callable from a roslibpy
client; a service a roslibpy client advertises is on the graph, and an rclpy client's call
reaches it and gets its answer.
"""

from __future__ import annotations

from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest_plugins = ("ros_fixtures",)

import roslibpy  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from ros_fixtures import Graph  # noqa: E402
from server_process import wait_for  # noqa: E402

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
