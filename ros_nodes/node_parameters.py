"""Parameter callbacks shared by the rclpy nodes: validate, then apply, on every distribution.

Iron and later run three callbacks (pre-set, on-set, post-set); Humble has only on-set, so
there one callback validates and then applies. Either way integers given for double
parameters (``-p kp:=4``, ``ros2 param set ... mass_kg 2``) become doubles first.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

Parameters = list[Parameter[Any]]


def integers_as_doubles(parameters: Parameters, double_names: Collection[str]) -> Parameters:
    """The parameters with integer values of ``double_names`` turned into doubles."""
    return [Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
            if p.name in double_names and p.type_ == Parameter.Type.INTEGER else p
            for p in parameters]


def add_parameter_callbacks(node: Node, double_names: Collection[str],
                            validate: Callable[[Parameters], SetParametersResult],
                            apply: Callable[[Parameters], None]) -> None:
    """Make ``node`` coerce, ``validate`` (refusing with a reason) and ``apply`` changes."""

    def coerce(parameters: Parameters) -> Parameters:
        return integers_as_doubles(parameters, double_names)

    if hasattr(node, "add_post_set_parameters_callback"):  # Iron and later
        node.add_pre_set_parameters_callback(coerce)
        node.add_on_set_parameters_callback(validate)
        node.add_post_set_parameters_callback(apply)
        return

    def validate_and_apply(parameters: Parameters) -> SetParametersResult:
        coerced = coerce(parameters)
        result = validate(coerced)
        if result.successful:
            apply(coerced)
        return result

    node.add_on_set_parameters_callback(validate_and_apply)
