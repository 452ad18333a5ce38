"""What each rosbridge of the deployment lets through (ros2-bridge/rosbridge_params.yaml):
students reach the robot's topics and may reset and read parameters; only the admin bridge, on
its own unpublished port, may change them; nginx and the health check use the bridges' ports.
"""

from __future__ import annotations

from deployment import (
    ADMIN_BRIDGE,
    BRIDGE,
    ROSAPI,
    STUDENT_BRIDGE,
    allowed,
    compose,
    load_healthcheck,
    nginx_upstreams,
    node_params,
    parse_glob,
    student_services,
)

from ros_nodes.parameters import RobotParameters
from ros_nodes.robot_interface import ROBOT_TOPICS


def test_globs_are_nonempty_lists() -> None:
    """An empty list means "everything" to the Humble release of rosbridge."""
    globs = [(node, key, value) for node, params in node_params().items()
             for key, value in params.items() if key.endswith("_glob")]
    assert {node for node, _, _ in globs} == {STUDENT_BRIDGE, ADMIN_BRIDGE, ROSAPI}, globs
    for node, key, value in globs:
        assert parse_glob(value), f"{node} {key} is empty"


def test_students_reach_the_robots_topics_and_nothing_else() -> None:
    robot_topics = {spec.name for spec in ROBOT_TOPICS}
    for node in (STUDENT_BRIDGE, ADMIN_BRIDGE, ROSAPI):
        globs = parse_glob(node_params()[node]["topics_glob"])
        assert {name for name in robot_topics if allowed(globs, name)} == robot_topics
        for other in ("/rosout", "/parameter_events", "/client_count", "/odom_fake"):
            assert not allowed(globs, other), (node, other)


def test_students_may_reset_and_read_parameters_but_not_change_them() -> None:
    globs = student_services()
    for name in ("/reset_simulation", "/virtual_robot/get_parameters",
                 "/virtual_robot/list_parameters", "/virtual_robot/describe_parameters",
                 "/virtual_robot/get_parameter_types", "/rosapi/topics"):
        assert allowed(globs, name), name
    for name in ("/virtual_robot/set_parameters", "/virtual_robot/set_parameters_atomically",
                 "/rosbridge_websocket/set_parameters", f"{ADMIN_BRIDGE}/set_parameters",
                 f"{ROSAPI}/set_parameters", "virtual_robot/set_parameters"):
        assert not allowed(globs, name), name


def test_rosapis_own_parameter_services_are_outside_the_always_open_rosapi_glob() -> None:
    assert not ROSAPI.startswith("/rosapi/")
    assert not allowed(student_services(), f"{ROSAPI}/set_parameters")


def test_admin_bridge_may_change_parameters_on_its_own_unpublished_port() -> None:
    params = node_params()
    admin = params[ADMIN_BRIDGE]
    assert allowed(parse_glob(admin["services_glob"]), "/virtual_robot/set_parameters")
    assert admin["port"] != params[STUDENT_BRIDGE]["port"]
    published = [int(port.split(":")[1]) for port in compose()["services"][BRIDGE]["ports"]]
    assert published == [params[STUDENT_BRIDGE]["port"]]


def test_rosapi_gives_nobody_any_parameter() -> None:
    globs = parse_glob(node_params()[ROSAPI]["params_glob"])
    for name in [*RobotParameters.names(), "use_sim_time", "port", "params_glob"]:
        assert not allowed(globs, name), name


def test_nginx_and_the_healthcheck_use_the_bridges_ports() -> None:
    params = node_params()
    student, admin = params[STUDENT_BRIDGE]["port"], params[ADMIN_BRIDGE]["port"]
    assert nginx_upstreams() == {"rosbridge": (BRIDGE, student),
                                 "rosbridge_admin": (BRIDGE, admin)}
    healthcheck = load_healthcheck()
    defaults = healthcheck.STUDENT_URL, healthcheck.ADMIN_URL
    assert defaults == (f"ws://127.0.0.1:{student}", f"ws://127.0.0.1:{admin}")
