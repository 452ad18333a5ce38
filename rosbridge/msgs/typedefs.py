"""Type definitions as rosapi describes them: ``rosapi_msgs/msg/TypeDef`` lists and full text.

rosapi on ROS 2 builds a TypeDef from the type's generated Python class; here it is built from
the same definitions the bridge validates messages with (the rosbags typestore of ROS 2
Humble, see ``definitions``), plus the services the embedded bridge offers
(``SERVICE_DEFINITIONS``: rosbags holds no services). What it gives, as rosapi gives it:

* ``type`` and nested ``fieldtypes`` in the ``pkg/Type`` form (``geometry_msgs/Vector3``,
  ``rcl_interfaces/GetParameters_Request``), base types by their IDL names (``double``,
  ``float``, ``boolean``, ``octet``; ``char`` is ``uint8``);
* ``fieldarraylen`` -1 for a single value, 0 for a sequence, N for an array of N;
* ``examples`` the default as Python prints it (``0.0``, ``0``, ``False``, ``""``), ``[]`` for
  arrays, ``{}`` for nested messages;
* the type first, then every nested type once, depth first; an empty structure has the one
  ``uint8 structure_needs_at_least_one_member`` field ROS 2 generates for it;
* an unknown type: no typedefs (rosapi logs it and answers an empty list).

Where rosapi's introspection is plainly wrong it is not followed: constants are only the
type's constants (rosapi also lists ``SLOT_TYPES`` and every field), a bounded sequence's
element type is the type (``rcl_interfaces/FloatingPointRange``, not ``...Range, 1``).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from rosbridge.msgs.definitions import shipped_definitions
from rosbridge.msgs.values import normalize_service_type, normalize_type

MESSAGE_DEFINITIONS = {
    "rosapi_msgs/msg/TypeDef": "string type\nstring[] fieldnames\nstring[] fieldtypes\n"
                               "int32[] fieldarraylen\nstring[] examples\n"
                               "string[] constnames\nstring[] constvalues",
}
"""Messages the services below use that the typestore lacks."""

_TYPEDEFS = "---\nTypeDef[] typedefs"
SERVICE_DEFINITIONS = {
    "rcl_interfaces/srv/GetParameters": "string[] names\n---\nParameterValue[] values",
    "rcl_interfaces/srv/SetParameters": "Parameter[] parameters\n---\n"
                                        "SetParametersResult[] results",
    "rcl_interfaces/srv/ListParameters": "uint64 DEPTH_RECURSIVE=0\nstring[] prefixes\n"
                                         "uint64 depth\n---\nListParametersResult result",
    "rcl_interfaces/srv/DescribeParameters": "string[] names\n---\n"
                                             "ParameterDescriptor[] descriptors",
    "rcl_interfaces/srv/GetParameterTypes": "string[] names\n---\nuint8[] types",
    "std_srvs/srv/Empty": "---",
    "rosapi_msgs/srv/Topics": "---\nstring[] topics\nstring[] types",
    "rosapi_msgs/srv/TopicsForType": "string type\n---\nstring[] topics",
    "rosapi_msgs/srv/TopicsAndRawTypes": "---\nstring[] topics\nstring[] types\n"
                                         "string[] typedefs_full_text",
    "rosapi_msgs/srv/TopicType": "string topic\n---\nstring type",
    "rosapi_msgs/srv/Interfaces": "---\nstring[] interfaces",
    "rosapi_msgs/srv/Services": "---\nstring[] services",
    "rosapi_msgs/srv/ServicesForType": "string type\n---\nstring[] services",
    "rosapi_msgs/srv/ServiceType": "string service\n---\nstring type",
    "rosapi_msgs/srv/ServiceNode": "string service\n---\nstring node",
    "rosapi_msgs/srv/ServiceProviders": "string service\n---\nstring[] providers",
    "rosapi_msgs/srv/Nodes": "---\nstring[] nodes",
    "rosapi_msgs/srv/NodeDetails": "string node\n---\nstring[] subscribing\n"
                                   "string[] publishing\nstring[] services",
    "rosapi_msgs/srv/Publishers": "string topic\n---\nstring[] publishers",
    "rosapi_msgs/srv/Subscribers": "string topic\n---\nstring[] subscribers",
    "rosapi_msgs/srv/GetActionServers": "---\nstring[] action_servers",
    "rosapi_msgs/srv/ActionType": "string action\n---\nstring type",
    "rosapi_msgs/srv/MessageDetails": "string type\n" + _TYPEDEFS,
    "rosapi_msgs/srv/ServiceRequestDetails": "string type\n" + _TYPEDEFS,
    "rosapi_msgs/srv/ServiceResponseDetails": "string type\n" + _TYPEDEFS,
    "rosapi_msgs/srv/ActionGoalDetails": "string type\n" + _TYPEDEFS,
    "rosapi_msgs/srv/ActionResultDetails": "string type\n" + _TYPEDEFS,
    "rosapi_msgs/srv/ActionFeedbackDetails": "string type\n" + _TYPEDEFS,
    "rosapi_msgs/srv/GetParam": "string name\nstring default_value\n---\nstring value\n"
                                "bool successful\nstring reason",
    "rosapi_msgs/srv/SetParam": "string name\nstring value\n---\nbool successful\n"
                                "string reason",
    "rosapi_msgs/srv/HasParam": "string name\n---\nbool exists",
    "rosapi_msgs/srv/DeleteParam": "string name\n---\nbool successful\nstring reason",
    "rosapi_msgs/srv/GetParamNames": "---\nstring[] names",
    "rosapi_msgs/srv/GetTime": "---\nbuiltin_interfaces/Time time",
    "rosapi_msgs/srv/GetROSVersion": "---\nuint8 version\nstring distro",
}
"""The request and response of every service type the embedded bridge offers, in .srv form.

``GetParam`` keeps rosapi 2.0's ``default_value`` (Humble) beside 2.2's ``successful`` and
``reason`` (Jazzy and later), so requests of both generations are understood."""

IDL_NAMES = {"bool": "boolean", "byte": "octet", "char": "uint8", "float32": "float",
             "float64": "double"}
"""How ROS 2's generated classes name base types (``_fields_and_field_types``)."""

EMPTY_FIELD: tuple[str, Any] = ("structure_needs_at_least_one_member",
                                (Nodetype.BASE, ("uint8", 0)))
"""The member ROS 2 gives a structure without fields."""

SEPARATOR = "\n" + "=" * 80 + "\n"
"""Between the definitions of a full text (``gendeps --cat``'s form)."""

Definition = tuple[list[tuple[str, str, Any]], list[tuple[str, Any]]]
"""(constants, fields) of one type, as the rosbags typestore holds them."""


@functools.cache
def _definitions() -> Mapping[str, Definition]:
    """The typestore's messages, the shipped ones, ``MESSAGE_DEFINITIONS``, services' parts.

    The shipped ones (``definitions.shipped_definitions``: example_interfaces, the TF
    republisher's...) too, so a topic of theirs has its full text in rosapi's
    ``topics_and_raw_types`` (what Foxglove and Lichtblick decode it with).
    """
    defs: dict[str, Any] = dict(get_typestore(Stores.ROS2_HUMBLE).fielddefs)
    defs.update(shipped_definitions())
    for name, text in MESSAGE_DEFINITIONS.items():
        defs.update(get_types_from_msg(text, name))
    for name, text in SERVICE_DEFINITIONS.items():
        package, _, service = name.split("/")
        request, response = text.split("---")
        for part, part_text in (("Request", request), ("Response", response)):
            parsed = get_types_from_msg(part_text, f"{package}/msg/{service}_{part}")
            (consts, fields), = parsed.values()
            defs[f"{package}/srv/{service}_{part}"] = (consts, fields)
    return {name: (consts, fields or [EMPTY_FIELD]) for name, (consts, fields) in defs.items()}


def message_types() -> list[str]:
    """Every message type defined here (``pkg/msg/Type``), sorted."""
    return sorted(name for name in _definitions() if "/msg/" in name)


def service_types() -> list[str]:
    """Every service type defined here (``pkg/srv/Type``), sorted."""
    return sorted(SERVICE_DEFINITIONS)


def request_fields(service_type: str) -> list[tuple[str, str]]:
    """(name, base type) of each field of a service's request; KeyError if unknown.

    Only base-typed fields are listed (every rosapi request has only strings).
    """
    _, fields = _definitions()[f"{service_type}_Request"]
    return [(name, detail[0]) for name, (kind, detail) in fields
            if kind == Nodetype.BASE and name != EMPTY_FIELD[0]]


def message_typedefs(type_name: str) -> list[dict[str, Any]]:
    """The TypeDefs of a message type and of every type nested in it; [] if unknown."""
    try:
        key = normalize_type(type_name)
    except ValueError:
        return []
    return _typedefs(key) if key in _definitions() else []


def service_typedefs(service_type: str, part: str) -> list[dict[str, Any]]:
    """The TypeDefs of a service's ``"Request"`` or ``"Response"``; [] if unknown."""
    try:
        key = f"{normalize_service_type(service_type)}_{part}"
    except ValueError:
        return []
    return _typedefs(key) if key in _definitions() else []


def full_text(type_name: str) -> str:
    """The definition of a message type with its nested types', ``gendeps --cat``'s form."""
    defs = _definitions()
    try:
        root = normalize_type(type_name)
    except ValueError:
        root = type_name
    if root not in defs:
        return f"# failed to get full definition text for {type_name}: unknown type"
    text, pending, seen = "", [root], {root}
    while pending:
        key = pending.pop()
        if text:
            text += f"{SEPARATOR}MSG: {_short(key)}\n"
        consts, fields = defs[key]
        lines = [f"{kind} {name}={value}" for name, kind, value in consts]
        for name, (kind, detail) in fields:
            lines.append(f"{_msg_type(kind, detail)} {name}")
            nested = _nested(kind, detail)
            if nested is not None and nested not in seen:
                seen.add(nested)
                pending.append(nested)
        text += "\n".join(lines) + "\n"
    return text


def _typedefs(root: str) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    seen: set[str] = set()

    def visit(key: str) -> None:
        seen.add(key)
        typedef = _typedef(key)
        out.append(typedef)
        for _, (kind, detail) in _definitions()[key][1]:
            nested = _nested(kind, detail)
            if nested is not None and nested not in seen:
                visit(nested)

    visit(root)
    return out


def _typedef(key: str) -> dict[str, Any]:
    consts, fields = _definitions()[key]
    typedef: dict[str, Any] = {"type": _short(key), "fieldnames": [], "fieldtypes": [],
                               "fieldarraylen": [], "examples": [], "constnames": [],
                               "constvalues": []}
    for name, (kind, detail) in fields:
        length = -1
        if kind == Nodetype.ARRAY:
            (kind, detail), length = detail
        elif kind == Nodetype.SEQUENCE:
            (kind, detail), _ = detail
            length = 0
        if kind == Nodetype.BASE:
            field_type = IDL_NAMES.get(detail[0], detail[0])
            example = _example(field_type)
        else:
            field_type, example = _short(detail), "{}"
        typedef["fieldnames"].append(name)
        typedef["fieldtypes"].append(field_type)
        typedef["fieldarraylen"].append(length)
        typedef["examples"].append("[]" if length >= 0 else example)
    for name, _, value in sorted(consts):
        typedef["constnames"].append(name)
        typedef["constvalues"].append(str(value))
    return typedef


def _example(base_type: str) -> str:
    """The default of a base type as Python prints it (what rosapi's examples are)."""
    if base_type in ("double", "float"):
        return "0.0"
    if base_type == "boolean":
        return "False"
    if base_type in ("string", "wstring"):
        return ""
    if base_type == "octet":
        return "b'\\x00'"
    return "0"


def _nested(kind: Nodetype, detail: Any) -> str | None:
    """The message type a field holds (itself or as elements); None for base types."""
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        kind, detail = detail[0]
    return str(detail) if kind == Nodetype.NAME else None


def _msg_type(kind: Nodetype, detail: Any) -> str:
    """A field's type as a .msg file writes it (``float64[36]``, ``geometry_msgs/Vector3``)."""
    if kind == Nodetype.BASE:
        base, bound = detail
        return f"{base}<={bound}" if bound else str(base)
    if kind == Nodetype.NAME:
        return _short(detail)
    element, length = detail
    inner = _msg_type(*element)
    if kind == Nodetype.ARRAY:
        return f"{inner}[{length}]"
    return f"{inner}[<={length}]" if length else f"{inner}[]"


def _short(key: str) -> str:
    """``geometry_msgs/msg/Twist`` -> ``geometry_msgs/Twist``, as rosapi names types."""
    package, _, name = key.split("/")
    return f"{package}/{name}"
