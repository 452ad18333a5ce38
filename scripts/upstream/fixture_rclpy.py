"""With ``websim serve --ros``: the ROS 2 nodes of the upstream suites that can be real nodes.

- ``/add_two_ints_server``: roslibjs's ``test/examples/params.example.ts`` sets and gets
  ``/add_two_ints_server:use_sim_time`` (a parameter every ROS 2 node has) of the node its CI
  launches; this node serves no service (fixture_nodes.py offers ``/add_two_ints``).
- ``/fibonacci`` (``example_interfaces/action/Fibonacci``), the action roslibpy's
  ``tests/ros2/test_actions.py`` sends goals to, as ROS 2's action tutorial server computes it
  (feedback each step, cancel honoured), when example_interfaces imports
  (scripts/upstream/rosbridge_suite/build_example_interfaces.sh builds it for the PyPI wheels).
  So a goal goes bridge -> ROS graph -> rclpy, as on the robot.

Our own code. Usage: python3 scripts/upstream/fixture_rclpy.py [--step-s 0.5] (until killed)
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import rclpy
from rclpy.action.server import ActionServer, CancelResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor


def fibonacci_server(node: Any, step_s: float) -> Any:
    """An ActionServer on /fibonacci, or None without example_interfaces."""
    try:
        from example_interfaces.action import Fibonacci  # type: ignore[import-untyped]
    except ImportError:
        return None

    def execute(goal_handle: Any) -> Any:
        feedback = Fibonacci.Feedback()
        feedback.sequence = [0, 1]
        for i in range(1, goal_handle.request.order):
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return Fibonacci.Result(sequence=list(feedback.sequence))
            feedback.sequence.append(feedback.sequence[i] + feedback.sequence[i - 1])
            goal_handle.publish_feedback(feedback)
            time.sleep(step_s)
        goal_handle.succeed()
        return Fibonacci.Result(sequence=list(feedback.sequence))

    return ActionServer(node, Fibonacci, "fibonacci", execute,
                        cancel_callback=lambda _request: CancelResponse.ACCEPT,
                        callback_group=ReentrantCallbackGroup())


def main() -> None:
    """Start both nodes and spin until killed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--step-s", type=float, default=0.5)
    args = parser.parse_args()
    rclpy.init()
    params_node = rclpy.create_node("add_two_ints_server")
    action_node = rclpy.create_node("fibonacci_server")
    server = fibonacci_server(action_node, args.step_s)
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(params_node)
    executor.add_node(action_node)
    served = ["node /add_two_ints_server"] + (["action /fibonacci"] if server else [])
    print(f"fixture_rclpy: serving {', '.join(served)}", flush=True)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
