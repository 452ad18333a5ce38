"""The rosapi services, answered in-process as rosapi 2.x answers them on ROS 2.

Every service rosapi's node offers (``/rosapi/topics`` ... ``/rosapi/get_ros_version``; the
request and response fields are ``typedefs.SERVICE_DEFINITIONS``), over the graph a ROS 2
robot running rosbridge shows:

* nodes ``/virtual_robot`` (the robot's topics, parameter services and /reset_simulation),
  ``/rosbridge_websocket`` (what clients advertise, subscribe and offer), ``/rosapi`` and
  ``/rosapi_params`` (the helper node rosapi 2.0 starts), each publishing ``/rosout`` and
  ``/parameter_events`` as every ROS 2 node does; with ``--ros`` the graph's topics and
  nodes too (a graph node's parameters are its own ``NODE/get_parameters`` services, which
  clients can call; rosapi's ``get_param`` covers the robot's);
* type names in both spellings (``nav_msgs/Odometry``, ``nav_msgs/msg/Odometry``), answered
  ``pkg/msg/Type``; an unknown topic, service or type gives ``""`` or ``[]``, as rosapi does;
* parameters named ``NODE:PARAM`` (``/virtual_robot:mass_kg``; ``virtual_robot:mass_kg`` is
  made absolute, as ROS 2 does), values as JSON text. As rosapi 2.2 does, get_param,
  set_param and delete_param answer ``successful`` and the ``reason`` of a refusal in a
  response that reaches the caller's callback (roslibjs 1.4.1 calls ``callback``, newer
  roslibjs ``failedCallback``; a missing parameter's ``value`` is ``'""'``, which JSON-parses);
  rosapi 2.0's ``default_value`` is still answered for a missing parameter. Setting needs
  admin rights; the robot's parameters are declared ROS 2 parameters, so deleting one is
  refused with that reason.

A request with a field the service lacks or a field of the wrong type fails the call
(``result: false``), as rosbridge fails a request it cannot fill in.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

from physics import ConfigError
from ros_nodes.parameters import (
    RobotParameters,
    parameter_value_msg,
    shorten_value,
    value_from_parameter_value,
)
from ros_nodes.robot_interface import NODE_NAME, NODE_TOPICS, ROBOT_TOPICS
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Bridge
from rosbridge.core.capabilities.actions import normalize_action_type
from rosbridge.core.capabilities.services import ServiceHandler, ViaGraph
from rosbridge.core.encoding import parse_json
from rosbridge.core.errors import ServiceError, shorten
from rosbridge.core.session import Session
from rosbridge.graph.names import RELAY_NODE_NAME
from rosbridge.msgs import typedefs
from rosbridge.msgs.values import normalize_service_type, normalize_type, stamp

PREFIX = "/rosapi/"
"""Where rosapi's services live (its ``use_private_service_names`` default)."""

BRIDGE_NODE = f"/{RELAY_NODE_NAME}"
ROSAPI_NODE = "/rosapi"
ROSAPI_PARAMS_NODE = "/rosapi_params"
"""The nodes of a rosbridge deployment beside the robot (rosbridge_websocket_launch.xml)."""

ROS_VERSION = 2
ROS_DISTRO = "humble"
"""What ``get_ros_version`` answers: the distribution whose definitions the bridge uses
(``rosbridge.msgs.definitions``) and the Docker stack's default."""


Handler = Callable[[dict[str, str], Session], "Mapping[str, Any] | ViaGraph"]


def admin_hint(session: Session) -> str:
    """How ``session`` gets admin rights: its own URL with the token.

    ``/robots/NAME`` in a class (the robot's token or the instructor's), ``/`` for the single
    robot: a URL that works on this server.
    """
    return f"connect with the admin token: ws://HOST:PORT{session.url_path}?token=TOKEN"


def require_admin(session: Session, action: str) -> None:
    """Raise unless ``session`` presented the admin token; the one access check."""
    if not session.is_admin:
        raise ServiceError(f"{action} needs admin rights; {admin_hint(session)}")


@dataclass
class NodeInfo:
    """What one node of the graph publishes, subscribes to and offers (names, sorted)."""

    publishing: list[str] = field(default_factory=list)
    subscribing: list[str] = field(default_factory=list)
    services: list[str] = field(default_factory=list)


def graph_nodes(bridge: Bridge) -> dict[str, NodeInfo]:
    """The nodes a ROS 2 robot with rosbridge shows, and what each does, now."""
    node_topics = [spec.name for spec in NODE_TOPICS]
    client_services = {name for session in bridge.sessions for name in session.services}
    services = sorted(bridge.services.types())
    robot = NodeInfo(
        publishing=sorted(bridge.topics.owned() | set(node_topics)),
        subscribing=sorted(spec.name for spec in ROBOT_TOPICS if spec.direction == "in"),
        services=[name for name in services
                  if not name.startswith(PREFIX) and name not in client_services])
    relay = NodeInfo(
        publishing=sorted({topic for session in bridge.sessions
                           for topic in session.advertised} | set(node_topics)),
        subscribing=sorted({topic for session in bridge.sessions
                            for topic in session.subscriptions}),
        services=sorted(client_services))
    rosapi = NodeInfo(publishing=list(node_topics),
                      services=[name for name in services if name.startswith(PREFIX)])
    nodes = {ROSAPI_NODE: rosapi, ROSAPI_PARAMS_NODE: NodeInfo(publishing=list(node_topics)),
             BRIDGE_NODE: relay, NODE_NAME: robot}
    for name, (publishing, subscribing, offered) in bridge.graph.nodes().items():
        nodes.setdefault(name, NodeInfo(publishing, subscribing, offered))  # with --ros
    return nodes


def action_servers(topics: list[str]) -> list[str]:
    """Namespaces with both ``_action/feedback`` and ``_action/status`` (rosapi's test)."""
    parts: dict[str, set[str]] = {}
    for topic in topics:
        namespace, _, tail = topic.rpartition("/_action/")
        if namespace and tail in ("feedback", "status"):
            parts.setdefault(namespace, set()).add(tail)
    return sorted(name for name, found in parts.items() if found == {"feedback", "status"})


def _same_type(type_name: str, wanted: str, normalize: Callable[[str], str]) -> bool:
    try:
        return type_name == normalize(wanted)
    except ValueError:
        return False


def _param_name(name: str) -> tuple[str, str]:
    """``/virtual_robot:mass_kg`` -> (``/virtual_robot``, ``mass_kg``), as rosapi splits it."""
    parts = name.split(":")
    if len(parts) != 2 or not parts[0] or not parts[1]:
        raise ValueError(f"malformed parameter name {shorten_value(name)}; expected "
                         f"NODE:PARAM, e.g. '{NODE_NAME}:mass_kg'")
    node, param = parts
    return (node if node.startswith("/") else f"/{node}"), param


def add_rosapi(bridge: Bridge, robot: VirtualRobot) -> None:
    """Offer every rosapi service on ``bridge``, over ``robot``'s node and parameters."""
    params = robot.parameters
    handlers = _graph_handlers(bridge)
    handlers.update(_type_handlers(bridge))
    handlers.update(_param_handlers(params, lambda: bridge.graph.nodes().keys()))
    handlers["get_time"] = lambda args, session: {"time": stamp(robot.clock.stamp_s())}
    handlers["get_ros_version"] = lambda args, session: {"version": ROS_VERSION,
                                                         "distro": ROS_DISTRO}
    for name, type_name in ROSAPI_SERVICES.items():
        bridge.services.add(PREFIX + name, type_name, _checked(type_name, handlers[name]))


def _checked(type_name: str, handler: Handler) -> ServiceHandler:
    """``handler`` behind a check of the request against ``type_name``'s fields."""
    fields = dict(typedefs.request_fields(type_name))

    def call(args: Mapping[str, Any], session: Session) -> Mapping[str, Any] | ViaGraph:
        request = {name: "" for name in fields}
        for key, value in args.items():
            if key not in fields:
                raise ServiceError(f"{type_name} request has no field {shorten_value(key)} "
                                   f"(fields: {', '.join(fields) or 'none'})")
            if not isinstance(value, str):
                raise ServiceError(f"{key}: expected a string, got {type(value).__name__} "
                                   f"{shorten_value(value)}")
            request[key] = value
        return handler(request, session)

    return call


def _graph_handlers(bridge: Bridge) -> dict[str, Handler]:
    def topic_list() -> list[tuple[str, str]]:
        return sorted(bridge.topic_types().items())

    def node_details(args: dict[str, str], session: Session) -> Mapping[str, Any]:
        nodes = graph_nodes(bridge)
        info = nodes.get(args["node"])
        if info is None:
            raise ServiceError(f"no node {shorten_value(args['node'])}; nodes: "
                               f"{', '.join(nodes)}")
        return {"subscribing": info.subscribing, "publishing": info.publishing,
                "services": info.services}

    def channel(args: dict[str, str], which: str) -> list[str]:
        return [name for name, info in graph_nodes(bridge).items()
                if args["topic"] in getattr(info, which)]

    def service_node(args: dict[str, str], session: Session) -> Mapping[str, Any]:
        owners = [name for name, info in graph_nodes(bridge).items()
                  if args["service"] in info.services]
        return {"node": owners[0] if owners else ""}

    def service_providers(args: dict[str, str], session: Session) -> Mapping[str, Any]:
        # rosapi on ROS 2 matches a service type here, ROS 1 a service name: both work.
        wanted, types = args["service"], bridge.services.types()
        return {"providers": [
            name for name, info in graph_nodes(bridge).items()
            if any(service == wanted or _same_type(types.get(service, ""), wanted,
                                                   normalize_service_type)
                   for service in info.services)]}

    return {
        "topics": lambda args, session: {"topics": [name for name, _ in topic_list()],
                                         "types": [kind for _, kind in topic_list()]},
        "topics_for_type": lambda args, session: {"topics": [
            name for name, kind in topic_list() if _same_type(kind, args["type"],
                                                              normalize_type)]},
        "topics_and_raw_types": lambda args, session: {
            "topics": [name for name, _ in topic_list()],
            "types": [kind for _, kind in topic_list()],
            "typedefs_full_text": [typedefs.full_text(kind) for _, kind in topic_list()]},
        "topic_type": lambda args, session: {
            "type": bridge.topic_types().get(args["topic"], "")},
        "services": lambda args, session: {"services": sorted(bridge.services.types())},
        "services_for_type": lambda args, session: {"services": sorted(
            name for name, kind in bridge.services.types().items()
            if _same_type(kind, args["type"], normalize_service_type))},
        "service_type": lambda args, session: {
            "type": bridge.services.types().get(args["service"], "")},
        "service_node": service_node,
        "service_providers": service_providers,
        "nodes": lambda args, session: {"nodes": list(graph_nodes(bridge))},
        "node_details": node_details,
        "publishers": lambda args, session: {"publishers": channel(args, "publishing")},
        "subscribers": lambda args, session: {"subscribers": channel(args, "subscribing")},
        "action_servers": lambda args, session: {"action_servers": sorted(
            {*action_servers([name for name, _ in topic_list()]), *bridge.actions.types()})},
        "action_type": lambda args, session: {
            "type": bridge.actions.types().get(args["action"], "")},
    }


def _type_handlers(bridge: Bridge) -> dict[str, Handler]:
    def details(part: str) -> Handler:
        return lambda args, session: {"typedefs": typedefs.service_typedefs(args["type"],
                                                                            part)}

    def action_part(part: str) -> Handler:  # the in-process actions' (the TF republisher's)
        def typedefs_of(args: dict[str, str], session: Session) -> Mapping[str, Any]:
            try:
                action_type = normalize_action_type(args["type"])
            except ValueError:
                return {"typedefs": []}
            return {"typedefs": typedefs.message_typedefs(f"{action_type}_{part}")}
        return typedefs_of

    return {
        "interfaces": lambda args, session: {
            "interfaces": typedefs.message_types() + typedefs.service_types()},
        "message_details": lambda args, session: {
            "typedefs": typedefs.message_typedefs(args["type"])},
        "service_request_details": details("Request"),
        "service_response_details": details("Response"),
        "action_goal_details": action_part("Goal"),
        "action_result_details": action_part("Result"),
        "action_feedback_details": action_part("Feedback"),
    }


def _param_handlers(params: RobotParameters,
                    graph_nodes: Callable[[], Collection[str]]) -> dict[str, Handler]:
    """Rosapi's parameter services: the robot's here, a graph node's through its services."""
    def outcome(reason: str = "") -> dict[str, Any]:
        return {"successful": not reason, "reason": shorten(reason)}

    def graph_node(name: str) -> tuple[str, str] | None:
        """(node, param) when ``name`` is a parameter of another node on the graph."""
        try:
            node, param = _param_name(name)
        except ValueError:
            return None
        return (node, param) if node != NODE_NAME and node in graph_nodes() else None

    def get_graph_param(node: str, param: str) -> ViaGraph:
        def response(outcomes: list[tuple[bool, Any]]) -> Mapping[str, Any]:
            ok, values = outcomes[0]
            try:
                if not ok:
                    raise ConfigError(str(values))
                value = value_from_parameter_value((values.get("values") or [None])[0])
            except (ConfigError, AttributeError) as error:
                return {"value": json.dumps(""), **outcome(f"{node}: {error}")}
            if value is None:
                return {"value": json.dumps(""),
                        **outcome(f"parameter {param} not found on {node}")}
            return {"value": json.dumps(value), **outcome()}
        return ViaGraph(((f"{node}/get_parameters", {"names": [param]}),), response)

    def set_graph_param(node: str, param: str, value: Any) -> ViaGraph:
        def response(outcomes: list[tuple[bool, Any]]) -> Mapping[str, Any]:
            ok, values = outcomes[0]
            if not ok:
                return outcome(f"{node}: {values}")
            results = values.get("results") or [{}] if isinstance(values, Mapping) else [{}]
            result = results[0] if isinstance(results[0], Mapping) else {}
            return outcome("" if result.get("successful") else
                           f"{node}: {result.get('reason') or 'refused'}")
        request = {"parameters": [{"name": param, "value": parameter_value_msg(value)}]}
        return ViaGraph(((f"{node}/set_parameters", request),), response)

    def param_names(args: dict[str, str], session: Session) -> Mapping[str, Any] | ViaGraph:
        """The robot's, then (``--ros``) every graph node's, from its list_parameters."""
        robot_names = [f"{NODE_NAME}:{name}" for name in params.names()]
        others = sorted(node for node in graph_nodes() if node != NODE_NAME)
        if not others:
            return {"names": robot_names}

        def response(outcomes: list[tuple[bool, Any]]) -> Mapping[str, Any]:
            names = list(robot_names)
            for node, (ok, values) in zip(others, outcomes, strict=True):
                listed = values.get("result", {}).get("names", []) \
                    if ok and isinstance(values, Mapping) else []
                names.extend(f"{node}:{name}" for name in listed if isinstance(name, str))
            return {"names": names}

        return ViaGraph(tuple((f"{node}/list_parameters", {"prefixes": [], "depth": 0})
                              for node in others), response)

    def robot_param(name: str) -> str | None:
        """The robot parameter ``name`` names; None for another node's or a missing one."""
        node, param = _param_name(name)
        return param if node == NODE_NAME and param in params.names() else None

    def get_param(args: dict[str, str], session: Session) -> Mapping[str, Any] | ViaGraph:
        other = graph_node(args["name"])
        if other is not None:
            return get_graph_param(*other)
        try:
            param = robot_param(args["name"])
        except ValueError as error:
            return {"value": json.dumps(""), **outcome(str(error))}
        if param is not None:
            return {"value": json.dumps(params.get(param)), **outcome()}
        if args["default_value"]:  # rosapi 2.0 (Humble): a missing parameter's default
            try:
                default: Any = json.loads(args["default_value"])
            except ValueError:
                default = args["default_value"]
            return {"value": json.dumps(default), **outcome()}
        return {"value": json.dumps(""),
                **outcome(f"parameter {shorten_value(args['name'])} not found; "
                          f"{NODE_NAME} has {', '.join(params.names())}")}

    def set_param(args: dict[str, str], session: Session) -> Mapping[str, Any] | ViaGraph:
        try:
            other = graph_node(args["name"])
            if other is not None:  # its own set_parameters service: callable by anyone
                return set_graph_param(*other, parse_json(args["value"]))
            require_admin(session, "set_param")
            param = robot_param(args["name"])
            if param is None:
                raise ValueError(f"parameter {shorten_value(args['name'])} not found; "
                                 f"parameters are set on {NODE_NAME}")
            try:
                value = parse_json(args["value"])
            except ValueError as error:
                raise ValueError(f"value: expected JSON text, got "
                                 f"{shorten_value(args['value'])}: {error}") from None
            params.set(param, value)
        except (ServiceError, ValueError, ConfigError) as error:
            return outcome(str(error))
        return outcome()

    def has_param(args: dict[str, str], session: Session) -> Mapping[str, Any]:
        try:
            return {"exists": robot_param(args["name"]) is not None}
        except ValueError:
            return {"exists": False}  # rosapi logs a malformed name and answers false

    def delete_param(args: dict[str, str], session: Session) -> Mapping[str, Any]:
        try:
            param = robot_param(args["name"])
        except ValueError as error:
            return outcome(str(error))
        if param is None:
            return outcome()  # nothing to delete: rosapi does nothing and succeeds
        return outcome(f"{param} is declared by {NODE_NAME}; a declared ROS 2 parameter "
                       "cannot be deleted (undeclared), only set")

    return {
        "get_param_names": param_names,
        "get_param": get_param, "set_param": set_param, "has_param": has_param,
        "delete_param": delete_param,
    }


_ROSAPI_TYPES = {
    "topics": "Topics", "topics_for_type": "TopicsForType",
    "topics_and_raw_types": "TopicsAndRawTypes", "topic_type": "TopicType",
    "interfaces": "Interfaces", "services": "Services", "services_for_type": "ServicesForType",
    "service_type": "ServiceType", "service_node": "ServiceNode",
    "service_providers": "ServiceProviders", "nodes": "Nodes", "node_details": "NodeDetails",
    "publishers": "Publishers", "subscribers": "Subscribers",
    "action_servers": "GetActionServers", "action_type": "ActionType",
    "message_details": "MessageDetails", "service_request_details": "ServiceRequestDetails",
    "service_response_details": "ServiceResponseDetails",
    "action_goal_details": "ActionGoalDetails", "action_result_details": "ActionResultDetails",
    "action_feedback_details": "ActionFeedbackDetails", "get_param_names": "GetParamNames",
    "get_param": "GetParam", "set_param": "SetParam", "has_param": "HasParam",
    "delete_param": "DeleteParam", "get_time": "GetTime", "get_ros_version": "GetROSVersion",
}
ROSAPI_SERVICES = {name: f"rosapi_msgs/srv/{kind}" for name, kind in _ROSAPI_TYPES.items()}
"""rosapi's services (``/rosapi/NAME``) and their types, as rosapi 2.x registers them."""
