"""The simulation_interfaces websim ships hash as upstream's: a ROS install's clients match ours.

ROS 2 (Iron and later) matches a topic's or a service's two ends by type name and type hash
(RIHS01, REP 2011), so definitions that differ in one field type or name would not talk to a
ROS install's ``simulation_interfaces``. websim ships its own copy
(``rosbridge/msgs/interfaces/simulation_interfaces/``; ``scripts/build_simulation_interfaces.sh``
builds it for the ROS graph). The hashes of every type of it (messages, services with their
requests, responses and events, the action with its goals, results and feedback) are held to
upstream's (``type_hashes/simulation_interfaces.json``: upstream's own files built with the
same rosidl; the hash strings only), computed here by rosidl's own Python, as the build
computes them (``rosidl_adapter``: .msg to .idl; ``rosidl_generator_type_description``: the
type descriptions and their hashes), from the shipped files, and read from the package where
one is built.
"""

from __future__ import annotations

import json
import os
import sysconfig
from pathlib import Path

import pytest

convert_to_idl = pytest.importorskip(
    "rosidl_adapter", reason="rosidl's generators not installed (bash "
    "scripts/build_simulation_interfaces.sh installs them)").convert_to_idl
generate_type_hash = pytest.importorskip(
    "rosidl_generator_type_description", reason="rosidl's generators not installed (bash "
    "scripts/build_simulation_interfaces.sh installs them)").generate_type_hash

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "simulation_interfaces"
SHIPPED = ROOT / "rosbridge" / "msgs" / "interfaces" / PACKAGE
UPSTREAM = json.loads((Path(__file__).with_name("type_hashes") / f"{PACKAGE}.json")
                      .read_text())["type_hashes"]
DEPENDENCIES = ("action_msgs", "builtin_interfaces", "geometry_msgs", "service_msgs",
                "std_msgs", "unique_identifier_msgs")
"""The packages whose types simulation_interfaces' name (service_msgs: every service's event;
action_msgs and unique_identifier_msgs: the action's goals)."""


def share(package: str) -> Path | None:
    """An installed package's share folder (a ROS install's, or the PyPI wheels'), or None."""
    prefixes = [*filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)),
                sysconfig.get_paths()["data"]]
    for prefix in prefixes:
        folder = Path(prefix) / "share" / package
        if (folder / "package.xml").is_file():
            return folder
    return None


def hashes_of(descriptions: list[Path]) -> dict[str, str]:
    """The package's own type hashes in generated type descriptions (``*.json``)."""
    found = {}
    for path in descriptions:
        for entry in json.loads(path.read_text())["type_hashes"]:
            if entry["type_name"].startswith(f"{PACKAGE}/"):
                found[entry["type_name"]] = entry["hash_string"]
    return found


def shipped_type_hashes(work: Path) -> dict[str, str]:
    """Every type hash of the shipped definitions, by rosidl as the build computes them."""
    includes = {package: share(package) for package in DEPENDENCIES}
    missing = sorted(package for package, folder in includes.items() if folder is None)
    if missing:
        pytest.skip(f"ROS 2's interface packages not installed ({', '.join(missing)}): "
                    "pip install '.[ros]'")
    idl_dir = work / "idl"
    idl_tuples = []
    for path in sorted(SHIPPED.glob("*/*")):
        if path.parent.name in ("msg", "srv", "action"):
            idl = convert_to_idl(SHIPPED, PACKAGE, path.relative_to(SHIPPED), idl_dir)
            idl_tuples.append(f"{idl_dir}:{idl.relative_to(idl_dir).as_posix()}")
    arguments = work / "arguments.json"
    arguments.write_text(json.dumps({
        "package_name": PACKAGE, "output_dir": str(work / "descriptions"),
        "idl_tuples": idl_tuples,
        "include_paths": [f"{package}:{folder}" for package, folder in includes.items()]}))
    return hashes_of([Path(path) for path in generate_type_hash(str(arguments))])


def test_every_shipped_type_hashes_as_upstreams(tmp_path: Path) -> None:
    ours = shipped_type_hashes(tmp_path)
    assert len(UPSTREAM) == 116  # 15 messages, 22 services x 4, the action's 13 types
    assert sorted(set(UPSTREAM) - set(ours)) == []
    assert sorted(set(ours) - set(UPSTREAM)) == []
    assert [name for name in UPSTREAM if ours[name] != UPSTREAM[name]] == []


def test_the_package_built_for_the_ros_graph_hashes_as_upstreams() -> None:
    folder = share(PACKAGE)
    if folder is None:
        pytest.skip("simulation_interfaces not built (bash scripts/build_simulation_interfaces.sh)")
    built = hashes_of(sorted(folder.glob("*/*.json")))
    assert built == UPSTREAM, f"{folder}: rebuild it from the shipped definitions"
