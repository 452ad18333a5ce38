"""simulation_interfaces and turtlesim's names on the ROS graph (``websim serve --ros``).

An rclpy client (what ``ros2 service call`` and ``ros2 action send_goal`` do) calls the
``websim_simulation`` node's services and sends a SimulateSteps goal. The packages are built
from websim's shipped definitions by ``scripts/build_simulation_interfaces.sh``
(``scripts/test.sh`` runs it); the tests are skipped without them.
"""

from __future__ import annotations

import math
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy not installed (pip install .[ros])")
pytest.importorskip("simulation_interfaces.srv", reason="simulation_interfaces not built "
                    "(bash scripts/build_simulation_interfaces.sh)")
pytest.importorskip("turtlesim.srv", reason="turtlesim not built "
                    "(bash scripts/build_simulation_interfaces.sh)")
pytest_plugins = ("ros_fixtures",)

from rclpy.action import ActionClient  # noqa: E402
from simulation_interfaces.action import SimulateSteps  # noqa: E402
from simulation_interfaces.msg import Result, SimulationState  # noqa: E402
from simulation_interfaces.srv import (  # noqa: E402
    GetEntityState,
    GetSimulatorFeatures,
    SetEntityState,
    SetSimulationState,
    SpawnEntity,
)
from turtlesim.srv import TeleportAbsolute  # noqa: E402

from ros_fixtures import Graph  # noqa: E402
from server_process import ServerProcess  # noqa: E402


def test_rclpy_calls_the_services_and_the_action(graph: Graph, ros_server: ServerProcess) -> None:
    features = graph.call(GetSimulatorFeatures, "/get_simulator_features",
                          GetSimulatorFeatures.Request()).features
    assert 11 in features.features and 33 in features.features
    request = SetEntityState.Request(entity="robot")
    request.state.pose.position.x, request.state.pose.position.y = 0.5, -0.25
    assert graph.call(SetEntityState, "/set_entity_state", request).result.result == \
        Result.RESULT_OK
    state = graph.call(GetEntityState, "/get_entity_state",
                       GetEntityState.Request(entity="robot")).state
    assert (state.pose.position.x, state.pose.position.y) == pytest.approx((0.5, -0.25))
    missing = graph.call(GetEntityState, "/get_entity_state",
                         GetEntityState.Request(entity="nobody"))
    assert missing.result.result == Result.RESULT_NOT_FOUND
    spawn = graph.call(SpawnEntity, "/spawn_entity", SpawnEntity.Request(name="second",
                                                                         uri="websim://robot"))
    assert spawn.result.result == Result.RESULT_FEATURE_UNSUPPORTED
    teleport = TeleportAbsolute.Request(x=-0.5, y=0.5, theta=1.0)
    graph.call(TeleportAbsolute, "/robot/teleport_absolute", teleport)
    state = graph.call(GetEntityState, "/get_entity_state",
                       GetEntityState.Request(entity="robot")).state
    yaw = 2 * math.atan2(state.pose.orientation.z, state.pose.orientation.w)
    assert (state.pose.position.x, state.pose.position.y, yaw) == pytest.approx(
        (-0.5, 0.5, 1.0), abs=1e-6)
    # Paused, a SimulateSteps goal reports each step and succeeds after the last.
    pause = SetSimulationState.Request()
    pause.state.state = SimulationState.STATE_PAUSED
    assert graph.call(SetSimulationState, "/set_simulation_state", pause).result.result == \
        Result.RESULT_OK
    client = ActionClient(graph.node, SimulateSteps, "/simulate_steps")
    graph.spin_until(client.server_is_ready, what="the /simulate_steps action server")
    feedback: list[Any] = []
    sent = client.send_goal_async(SimulateSteps.Goal(steps=3),
                                  feedback_callback=lambda message: feedback.append(
                                      message.feedback))
    graph.spin_until(sent.done, what="the goal accepted")
    result = sent.result().get_result_async()
    graph.spin_until(result.done, what="the goal's result")
    assert result.result().result.result.result == Result.RESULT_OK
    graph.spin_until(lambda: len(feedback) == 3, what="three feedback messages")
    assert [(f.completed_steps, f.remaining_steps) for f in feedback] == [(1, 2), (2, 1), (3, 0)]
