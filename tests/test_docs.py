"""What is written down twice is held equal to its one source.

The README's parameter table is ``parameters.markdown_table()``; its limits table states
``ClientLimits``' and the schema's numbers; ``web-interface/robot.json`` (what nginx serves in
the Docker stack) is ``websim robot-json`` for the shipped parameters. Every relative link in
the docs reaches a file and, where it names one, a heading.
"""

from __future__ import annotations

import io
import re
from contextlib import redirect_stdout
from pathlib import Path

import pytest

from grading.metrics import METRICS, parameters_table
from ros_nodes.parameters import markdown_table
from ros_nodes.robot_description import robot_json
from rosbridge.core import encoding, fragments, schema
from rosbridge.core.capabilities import services, topics
from rosbridge.core.limits import ClientLimits
from rosbridge.tf.republisher import RepublisherLimits
from rosbridge.transport import connection
from websim.cli import main

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_readme_parameter_table_is_made_from_the_parameter_specs() -> None:
    assert markdown_table() in README, "regenerate: python -c 'from ros_nodes.parameters " \
        "import markdown_table; print(markdown_table())'"


@pytest.mark.parametrize("kind", sorted(METRICS))
def test_grading_docs_parameter_tables_are_made_from_the_metrics(kind: str) -> None:
    grading_doc = (ROOT / "docs" / "grading.md").read_text(encoding="utf-8")
    assert parameters_table(kind) in grading_doc, "regenerate: python -c 'from grading." \
        f"metrics import parameters_table; print(parameters_table(\"{kind}\"))'"


def test_readme_limits_table_states_the_defaults_in_force() -> None:
    limits, tf = ClientLimits(), RepublisherLimits()
    rows = {
        "message size": f"{limits.max_frame_bytes >> 20} MiB",
        "message rate": f"{limits.max_rate:g} messages/s",
        "JSON nesting": f"{encoding.MAX_NESTING} levels",
        "JSON elements (values, objects, arrays)": f"{encoding.MAX_ELEMENTS:,} per message",
        "handling time": f"{limits.handling_share:.0%} of a core per client, sustained, "
                         f"{limits.handling_burst_s:g} s burst".replace("%", " %"),
        "bytes waiting to be sent to a client": f"{limits.max_queued_bytes >> 20} MiB",
        "replies waiting (service responses, statuses)": f"{limits.max_replies}",
        "a socket that accepts nothing while frames wait (watched once more than "
        f"{connection.WRITE_BUFFER_BYTES >> 10} KiB wait beyond its kernel buffer)":
            f"{limits.stall_timeout_s:g} s; the close handshake gets {limits.close_timeout_s:g} s",
        "`queue_length`": f"0 to {schema.MAX_QUEUE_LENGTH}",
        "`throttle_rate`": f"0 to {schema.MAX_THROTTLE_MS:,} ms",
        "`id`": f"a string of at most {schema.MAX_ID_CHARS} characters",
        "names, types": f"{schema.MAX_NAME_CHARS} characters",
        "subscribe ids per topic per client": f"{limits.max_ids_per_topic}",
        "subscriptions / advertised topics / offered services per client":
            f"{limits.max_subscriptions} / {limits.max_advertised} / {limits.max_services}",
        "offered actions per client": f"{limits.max_actions}",
        "action goals pending per client / per offered action":
            f"{limits.max_goals} / {limits.max_goals_per_action}",
        "fragments of one incoming message": f"{limits.max_fragments}",
        "fragmented messages incomplete at once per client":
            f"{limits.max_partial_messages}; one that gets no fragment for "
            f"{limits.fragment_timeout_s:g} s",
        "a message published with `latch: true`": f"{limits.max_latched_bytes >> 10} KiB",
        "bytes/s a client relays to others: publications, service calls and responses, "
        "goals, feedback, results": f"{limits.relay_bytes_per_s >> 10} KiB/s",
        "clients' latched messages per robot (a client's latched message goes when its "
        "publisher unadvertises or leaves)": f"{limits.robot_latched_bytes >> 20} MiB",
        "clients' latched messages of all the robots of a server together":
            f"{limits.server_latched_bytes >> 20} MiB",
        "handling time of all the clients of one robot together, from every address (a "
        "crowd on one robot)": f"{limits.robot_handling_share:g} of a core",
        "calls waiting for client-provided services":
            f"{services.MAX_PENDING_CALLS_PER_CLIENT} per caller, "
            f"{services.MAX_PENDING_CALLS_PER_SERVICE} per service",
        "`fragment_size` of a topic message": "rounded down to a power of two, at least "
                                              f"{fragments.MIN_TOPIC_FRAGMENT_SIZE} characters",
        "costly forms of one message kept (`png`, `cbor-raw`, fragmented)":
            f"{topics.MAX_VARIANTS}, together at most {topics.VARIANT_BYTES_FACTOR} × its JSON",
        "clients per robot": f"{limits.max_clients}",
        "WebSocket connections per server": f"{limits.max_connections}",
        "connections from one client address (IPv6: its /64; behind `--trusted-proxy`, the "
        "forwarded address); the instructor's root view does not count":
            f"{limits.address_max_connections}:",
        "connections from one address to one robot": f"{limits.address_max_robot_connections}",
        "messages/s of all connections of one address together (one per started 16 KiB, 1 s "
        "of burst)": f"{limits.address_max_rate:g}",
        "handling time / incoming bytes of all connections of one address":
            f"{limits.address_handling_share:g} of a core / "
            f"{limits.address_bytes_per_s >> 20} MiB/s",
        "new names one address enrols in an open class":
            f"{limits.address_enrolments}, then {limits.address_enrolments_per_s:g}/s",
        "TF republications (`/republish_tfs` topics and `/tf2_web_republisher` goals, "
        "[docs/viewers.md](docs/viewers.md))":
            f"{tf.per_client} per client, {tf.per_bridge} per robot, of which clients without "
            "the robot's token (or the instructor's) hold at most "
            f"{tf.per_bridge - tf.owner_reserve} together; {tf.frames} frames each, "
            f"a rate above 0 and at most {tf.max_rate_hz:g} Hz, a timeout of at most "
            f"{tf.max_timeout_s:g} s",
    }
    for limit, default in rows.items():
        assert f"| {limit} | {default}" in README, f"README limits table: {limit}"


def test_committed_robot_json_is_the_shipped_robot() -> None:
    committed = (ROOT / "web-interface" / "robot.json").read_text(encoding="utf-8")
    assert committed == robot_json(), "regenerate: websim robot-json > web-interface/robot.json"
    printed = io.StringIO()
    with redirect_stdout(printed):
        assert main(["robot-json"]) == 0
    assert printed.getvalue() == committed


MARKDOWN_LINK = re.compile(r"\]\(([^)\s]+)\)")
DOCS = ("README.md", "docs/course.md", "docs/assignments.md", "docs/viewers.md",
        "examples/README.md", "docs/grading.md")


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors_of(path: Path) -> set[str]:
    return {github_anchor(line.lstrip("#")) for line in path.read_text().splitlines()
            if line.startswith("#")}


@pytest.mark.parametrize("doc", DOCS)
def test_relative_links_in_the_docs_reach_a_file_and_heading(doc: str) -> None:
    source = ROOT / doc
    broken = []
    for target in MARKDOWN_LINK.findall(source.read_text()):
        if "://" in target or target.startswith("mailto:"):
            continue
        file_part, _, anchor = target.partition("#")
        linked = (source.parent / file_part).resolve() if file_part else source
        if not linked.exists():
            broken.append(f"{target}: no such file")
        elif anchor and linked.suffix == ".md" and anchor not in anchors_of(linked):
            broken.append(f"{target}: no heading with that anchor")
    assert not broken, f"{doc}: {broken}"
