"""The Code panel's assignments, their starters, and the course's snippets as examples.

Each shipped scenario or suite is an assignment: what its controller is told, and a starter in
Python and in JavaScript.

Everything here is read from the scenario files (``examples/scenarios/``: their names,
descriptions, ``WEBSIM_<NAME>`` values by ``grading.controller_environment``, metrics) and the
robot's topic table (``ros_nodes.robot_interface``), never retyped: a new scenario file is a new
assignment in the panel, with its starter. The starters are programs that run as they are
(they connect, subscribe, answer each ``/odom`` with a zero ``/cmd_vel``) and say where the
student's controller goes; on a laptop they run unchanged with ``WEBSIM_URL`` set (``websim
grade`` sets it, and the page when it runs them).
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path
from typing import Any

from grading import Suite, controller_environment, load_suite
from physics import ConfigError
from physics.shipped import shipped
from ros_nodes.robot_interface import CMD_VEL, MAP, ODOM, SCAN, TopicSpec

SCENARIOS_DIR = shipped("physics", "examples/scenarios")
"""The shipped assignments (what ``websim grade NAME`` finds by name)."""

EXAMPLES_DIR = shipped("physics", "examples")
"""The course's snippets (``course_snippets.py``, ``course_snippets.js``)."""

EXAMPLES = (("course_snippets.py", "python", "Course snippets 2.5.5 (roslibpy)"),
            ("course_snippets.js", "javascript", "Course snippets 2.5.5 (roslib)"))
"""The examples the panel offers: file, language, title."""

CONTROLLER_TOPICS = (ODOM, SCAN, MAP, CMD_VEL)
"""The topics a course controller reads and writes, as the starters list them."""

DEFAULT_URL = "ws://localhost:9090"


def assignment_files(folder: Path = SCENARIOS_DIR) -> list[Path]:
    """The shipped scenario and suite files, by name."""
    return sorted(folder.glob("*.yaml"))


def assignments(folder: Path = SCENARIOS_DIR) -> list[dict[str, Any]]:
    """Every shipped assignment as the panel shows it (a bad file is left out, not fatal)."""
    found = []
    for path in assignment_files(folder):
        try:
            suite = load_suite(path)
        except ConfigError:
            continue
        found.append(assignment(path.stem, suite))
    return found


def assignment(name: str, suite: Suite) -> dict[str, Any]:
    """One assignment: its scenarios' environments and its starters.

    Args:
        name: what ``websim grade`` calls it (its file's name).
        suite: the file, read.
    """
    scenarios = [{"name": entry.scenario.name, "description": entry.scenario.description,
                  "env": controller_environment(entry.scenario),
                  "duration_s": entry.scenario.duration_s}
                 for entry in suite.entries]
    metrics = sorted({f"{metric.kind}" + ("" if metric.weight else " (reported)")
                      for entry in suite.entries for metric in entry.scenario.metrics})
    description = suite.description or suite.entries[0].scenario.description
    facts = {"name": name, "description": description, "scenarios": scenarios,
             "metrics": metrics}
    return {**facts, "starters": {"python": python_starter(facts),
                                  "javascript": javascript_starter(facts)}}


def _variables(scenarios: list[dict[str, Any]]) -> dict[str, list[str]]:
    """Each WEBSIM_* variable and its values over the scenarios, in order, once each."""
    values: dict[str, list[str]] = {}
    for scenario in scenarios:
        for variable, value in scenario["env"].items():
            seen = values.setdefault(variable, [])
            if value not in seen:
                seen.append(value)
    return values


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _topic_line(topic: TopicSpec) -> str:
    way = "publish" if topic.direction == "in" else "subscribe"
    rate = f", {topic.rate_hz:g} Hz" if topic.rate_hz else (", latched" if topic.latched else "")
    return f"{topic.name:<10} {topic.type:<28} {way}{rate}: {topic.description}"


WIDTH = 88
"""The starters' prose is wrapped to this many characters (a student's editor, a laptop's)."""


def _told(facts: dict[str, Any], comment: str) -> list[str]:
    """The header lines both starters share (without comment markers)."""
    scenarios = facts["scenarios"]
    lines = [f"{facts['name']}: {facts['description']}.", "",
             "What the controller is told (environment variables: websim grade sets them, and "
             "so does Run on the robot's page):",
             f"  WEBSIM_URL  the robot's rosbridge address ({DEFAULT_URL} if unset)"]
    for variable, values in _variables(scenarios).items():
        shown = " | ".join(values)
        lines.append(f"  {variable}  {shown}")
    if len(scenarios) > 1:
        lines.append(f"  (one value per scenario: {', '.join(s['name'] for s in scenarios)})")
    lines += ["", "Topics:"] + [f"  {_topic_line(topic)}" for topic in CONTROLLER_TOPICS]
    lines += ["", f"Graded by: {', '.join(facts['metrics'])}. Submit runs websim grade "
              f"{facts['name']} in deterministic mode: after each /odom the simulator waits "
              "for one /cmd_vel, so answer every /odom with one.", ""]
    wrapped = []
    for line in lines:
        indent = " " * (len(line) - len(line.lstrip()))
        wrapped += textwrap.wrap(line, WIDTH - len(comment), subsequent_indent=indent + "  "
                                 if indent else "", break_on_hyphens=False) or [""]
    return [f"{comment}{line}".rstrip() for line in wrapped]


def _constants(facts: dict[str, Any]) -> list[tuple[str, str, str, bool]]:
    """Each WEBSIM_* a starter reads.

    As (its name in the program, the variable, the first scenario's value, whether it is a
    number).
    """
    return [(variable.removeprefix("WEBSIM_"), variable, values[0],
             _is_number(values[0]) and not variable.endswith("_CHANGES"))
            for variable, values in _variables(facts["scenarios"]).items()]


def python_starter(facts: dict[str, Any]) -> str:
    """A roslibpy controller that runs as it is and says where the control goes."""
    constants = [f'{name} = float(os.environ.get("{variable}", "{value}"))' if number else
                 f'{name} = os.environ.get("{variable}", {json.dumps(value)})'
                 for name, variable, value, number in _constants(facts)]
    header = "\n".join(_told(facts, ""))
    return f'''"""{header}
Run on a laptop: pip install roslibpy, then WEBSIM_URL=ws://HOST:9090 python3 {facts['name']}.py
"""

import math
import os
import time

import roslibpy

{chr(10).join(constants)}


def yaw_of(odom):
    """The heading (rad) of an Odometry message: 2 atan2(z, w) of its planar quaternion."""
    q = odom["pose"]["pose"]["orientation"]
    return 2.0 * math.atan2(q["z"], q["w"])


def on_odom(odom):
    """One /odom in, one /cmd_vel out."""
    yaw = yaw_of(odom)
    linear_mps, angular_rps = 0.0, 0.0  # your controller here: from yaw, to a command
    cmd_vel.publish(roslibpy.Message({{"linear": {{"x": linear_mps, "y": 0.0, "z": 0.0}},
                                      "angular": {{"x": 0.0, "y": 0.0, "z": angular_rps}}}}))


ros = roslibpy.Ros(host=os.environ.get("WEBSIM_URL", "{DEFAULT_URL}"))
ros.run()
print("connected")
cmd_vel = roslibpy.Topic(ros, "{CMD_VEL.name}", "{CMD_VEL.type}")
cmd_vel.advertise()
roslibpy.Topic(ros, "{ODOM.name}", "{ODOM.type}").subscribe(on_odom)
while ros.is_connected:
    time.sleep(0.1)
'''


def javascript_starter(facts: dict[str, Any]) -> str:
    """A roslib 1.4.1 controller that runs as it is and says where the control goes."""
    constants = [f"const {name} = Number(process.env.{variable} || '{value}');" if number else
                 f"const {name} = process.env.{variable} || {json.dumps(value)};"
                 for name, variable, value, number in _constants(facts)]
    header = "\n".join(_told(facts, "// "))
    return f"""{header}
// Run on a laptop: npm install roslib@1.4.1, then WEBSIM_URL=ws://HOST:9090 node {facts['name']}.js
'use strict';

const ROSLIB = require('roslib');

{chr(10).join(constants)}

function yawOf(odom) {{
  // The heading (rad) of an Odometry message: 2 atan2(z, w) of its planar quaternion.
  const q = odom.pose.pose.orientation;
  return 2 * Math.atan2(q.z, q.w);
}}

const ros = new ROSLIB.Ros({{ url: process.env.WEBSIM_URL || '{DEFAULT_URL}' }});
const cmdVel = new ROSLIB.Topic({{ ros, name: '{CMD_VEL.name}', messageType: '{CMD_VEL.type}' }});
const odom = new ROSLIB.Topic({{ ros, name: '{ODOM.name}', messageType: '{ODOM.type}' }});

ros.on('connection', () => console.log('connected'));
ros.on('close', () => process.exit(0));
odom.subscribe((message) => {{ // one /odom in, one /cmd_vel out
  const yaw = yawOf(message);
  const linearMps = 0.0; // your controller here: from yaw, to a command
  const angularRps = 0.0;
  cmdVel.publish(new ROSLIB.Message({{
    linear: {{ x: linearMps, y: 0.0, z: 0.0 }},
    angular: {{ x: 0.0, y: 0.0, z: angularRps }},
  }}));
}});
"""


def examples(folder: Path = EXAMPLES_DIR) -> list[dict[str, str]]:
    """The course's snippets, as the panel loads them (those this installation has)."""
    found = []
    for file, language, title in EXAMPLES:
        path = folder / file
        if path.is_file():
            found.append({"name": file, "language": language, "title": title,
                          "text": path.read_text(encoding="utf-8")})
    return found
