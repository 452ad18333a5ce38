"""The ``virtual_robot`` rclpy node: the simulated robot on a real ROS 2 graph.

A thin adapter around ``VirtualRobot``, which decides what is published, when and with which
stamp; the same class runs behind the embedded rosbridge server. The node turns its dicts into
rclpy messages (``rosbridge.msgs.rclpy_conversion``), publishes them with each topic's QoS
(``ros_nodes.robot_interface``), feeds ``/cmd_vel`` in, and keeps its ROS parameters and
``RobotParameters`` the same table, so ``ros2 param set /virtual_robot mass_kg 2.0`` and the
admin page do the same thing.

Run it with ``websim-robot [--ros-args -p world:=maze -p mode:=dynamic]`` or
``python -m ros_nodes.virtual_robot``. ``websim serve --ros`` runs it in-process instead, ticked
by the server (see ``rosbridge.graph.relay``).

Parameters (``ros2 param describe /virtual_robot NAME`` shows each): ``mode``, ``mass_kg``,
``inertia_kg_m2``, ``max_linear_mps``, ``max_angular_rps``, ``max_wheel_force_n`` and
``cmd_vel_timeout_s`` change at runtime; ``world``, ``params_file``, ``seed``, the noise
sigmas, ``localization`` and ``cmd_vel_stamped`` are read at start (read-only afterwards). The
node publishes ``/clock`` every tick, the stamp of the tick's messages: wall time, or with
``use_sim_time:=true`` sim time (``ros_nodes.sim_clock.SimClock``: from the wall time of the
start, exactly one tick per tick, counting on across resets), which the node's own rclpy
clock then follows too. Bad values are refused with the reason; nothing changes.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Sequence
from typing import Any, Protocol, TypeVar

try:
    import rclpy
    from rcl_interfaces.msg import (
        FloatingPointRange,
        IntegerRange,
        ParameterDescriptor,
        SetParametersResult,
    )

    # Humble has no rclpy.clock_type; later distributions re-export ClockType here.
    from rclpy.clock import Clock, ClockType  # type: ignore[attr-defined]
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_srvs.srv import Empty
except ImportError as error:  # pragma: no cover - depends on the installation
    raise ImportError(f"{error}: the virtual_robot node needs rclpy and the ROS message "
                      "packages (pip install '.[ros]')") from error

from physics import TICK_PERIOD_S, ConfigError, NoiseParams, Simulation, load_params, load_world
from physics.params import SHIPPED_PARAMS_FILE
from ros_nodes.node_parameters import add_parameter_callbacks
from ros_nodes.parameters import (
    PARAMETER_DOUBLE,
    PARAMETER_INTEGER,
    PARAMETERS,
    RUNTIME_PARAMETERS,
    WORLD_LOCALIZATION,
    ParameterSpec,
    parameter_spec,
)
from ros_nodes.robot_interface import (
    CLOCK,
    CMD_VEL,
    CMD_VEL_STAMPED_TYPE,
    NODE_BASENAME,
    PUBLISHED_TOPICS,
    RESET_SERVICE,
    SCAN,
    TopicSpec,
)
from ros_nodes.robot_messages import prefixed_frames
from ros_nodes.sim_clock import SimClock
from ros_nodes.tap import OUT
from ros_nodes.virtual_robot_core import Publication, VirtualRobot
from rosbridge.core.clock import WallClock
from rosbridge.msgs.rclpy_conversion import (
    MessageConversionError,
    PublisherFilter,
    message_class,
    to_dict,
    to_message,
)
from rosbridge.msgs.values import Message

TF_MISSING_WARNING = (
    "tf2_msgs is not installed, so /tf and /tf_static are not published: it is not on PyPI. "
    "Build it with 'bash scripts/build_tf2_msgs.sh' (needs cmake and a C compiler) or use a "
    "ROS 2 installation; 'websim serve --ros' still sends /tf to the browser.")

T = TypeVar("T")


class RobotAccess(Protocol):
    """How the node reaches a robot that another thread may own."""

    def call(self, fn: Callable[[], T]) -> T:
        """Run ``fn`` where the robot lives, wait, and return its result (or raise)."""

    def post(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` where the robot lives, without waiting."""


class DirectAccess:
    """The node owns the robot: its executor thread is the only one touching it."""

    def call(self, fn: Callable[[], T]) -> T:
        """Run ``fn`` now."""
        return fn()

    def post(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` now."""
        fn()


def relative(name: str) -> str:
    """A robot topic or service name relative to the node's namespace (``/odom`` -> ``odom``)."""
    return name.lstrip("/")


def qos_profile(spec: TopicSpec, reliability: str | None = None) -> QoSProfile:
    """The QoS a topic of the robot is published with (``TopicSpec.qos_profile``).

    ``sensor_data`` is rclpy's ``qos_profile_sensor_data`` (best effort, depth 5), as lidar
    drivers use; ``transient_local`` keeps the last message for late subscribers, as tf2's
    static broadcaster does; ``reliable`` is the ROS default (depth 10). ``reliability``
    (``best_effort`` or ``reliable``) overrides the table's (the ``scan_reliability``
    parameter).
    """
    offered = spec.qos_profile
    reliability = reliability or offered.reliability
    return QoSProfile(
        depth=offered.depth,
        reliability=ReliabilityPolicy.BEST_EFFORT if reliability == "best_effort"
        else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if offered.durability == "transient_local"
        else DurabilityPolicy.VOLATILE)


def descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    """The ROS descriptor of a parameter: its description, unit, range and read-only flag.

    rclpy itself then refuses values outside ``floating_point_range``/``integer_range``.
    """
    text = f"{spec.description} ({spec.unit})" if spec.unit else spec.description
    result = ParameterDescriptor(description=text, read_only=not spec.runtime)
    if spec.choices:
        result.additional_constraints = f"one of {spec.range_text()}"
    if spec.minimum is None or spec.maximum is None:
        return result
    if spec.type_code == PARAMETER_DOUBLE:
        result.floating_point_range = [FloatingPointRange(
            from_value=float(spec.minimum), to_value=float(spec.maximum), step=0.0)]
    elif spec.type_code == PARAMETER_INTEGER:
        result.integer_range = [IntegerRange(
            from_value=int(spec.minimum), to_value=int(spec.maximum), step=0)]
    return result


def _declare(node: Node, spec: ParameterSpec, value: Any = None) -> Any:
    """Declare ``spec`` on ``node`` (at ``value``, default its default); its value."""
    default = spec.default if value is None else value
    return node.declare_parameter(spec.name, default, descriptor(spec)).value


_RUNTIME_PARAMETERS = {spec.name for spec in RUNTIME_PARAMETERS}
_NOISE_PARAMETERS = [spec for spec in PARAMETERS if spec.name in
                     {item.name for item in dataclasses.fields(NoiseParams)}]
_DOUBLE_PARAMETERS = {spec.name for spec in PARAMETERS if spec.type_code == PARAMETER_DOUBLE}
_SPECS = {spec.name: spec for spec in PARAMETERS}


class VirtualRobotNode(Node):
    """The simulated robot as a ROS 2 node.

    Args:
        robot: the robot to wrap; None builds one from the parameters ``world``,
            ``params_file``, ``seed``, ``localization`` and the noise sigmas (each sigma's
            default: the world's ``noise``, else the parameter file's).
        access: how to reach ``robot`` (default: directly; ``websim serve --ros`` passes one
            that runs on the server's event loop).
        own_timer: tick the robot with a 20 Hz timer; with False, whoever owns the robot
            ticks it and the node publishes every tick's messages (``VirtualRobot.tap``).
        ignore_cmd_vel_from: a node whose /cmd_vel messages are ignored (the in-process
            rosbridge relay, whose commands the robot already got).
        frame_prefix: prefixed to every frame id the node publishes (``alice/`` gives
            ``alice/odom``, ``alice/base_link``: the multi-robot convention); the robot's
            topics and services are relative names, so ``namespace="/alice"`` in
            ``node_kwargs`` puts them under ``/alice``.
        publish_clock: publish the robot's ``/clock`` (always absolute: what ``use_sim_time``
            nodes read); False for a class's robots, whose one ``/clock`` the class publishes.
        clock_after: with ``own_timer=False``, how a tick's ``/clock`` is published after the
            tick's other messages (``websim serve --ros``: the event loop's ``call_soon``), so
            that a node on sim time has a tick's /odom and /scan before its timers see the
            tick's time; None publishes it in the robot's order (first).
        **node_kwargs: passed to ``rclpy.node.Node`` (e.g. ``context``).

    Raises:
        rclpy.exceptions.InvalidParameterValueException: a parameter override is invalid.
    """

    def __init__(self, robot: VirtualRobot | None = None, *, access: RobotAccess | None = None,
                 own_timer: bool = True, ignore_cmd_vel_from: str | None = None,
                 frame_prefix: str = "", publish_clock: bool = True,
                 clock_after: Callable[[Callable[[], None]], object] | None = None,
                 **node_kwargs: Any) -> None:
        super().__init__(NODE_BASENAME, **node_kwargs)
        self._frame_prefix = frame_prefix
        self._access: RobotAccess = access or DirectAccess()
        self._robot: VirtualRobot | None = None
        add_parameter_callbacks(self, _DOUBLE_PARAMETERS, self._validate_parameters,
                                self._apply_parameters)

        self._use_sim_time = bool(self.get_parameter("use_sim_time").value)
        self.robot = robot if robot is not None else self._build_robot()
        self._robot = self.robot
        self._declare_robot_parameters()
        self._cmd_vel_stamped = bool(_declare(self, parameter_spec("cmd_vel_stamped")))
        scan_reliability = str(_declare(self, parameter_spec("scan_reliability")))
        self._clock_after = clock_after
        self.publish_hook: Callable[[str, Callable[[], None]], None] | None = None
        """With ``own_timer=False``: given each tapped message's topic and a function that
        publishes it, publishes it when it chooses (``websim grade``'s lock step hands a
        tick's messages to the controller one at a time); None: at once."""

        self._robot_publishers: dict[str, Any] = {}
        self._classes: dict[str, Any] = {}
        for spec in PUBLISHED_TOPICS:
            if spec is CLOCK and not publish_clock:
                continue
            try:
                cls = message_class(spec.type)
            except MessageConversionError:
                if spec.type.startswith("tf2_msgs/"):
                    continue
                raise
            self._classes[spec.name] = cls
            self._robot_publishers[spec.name] = self.create_publisher(
                cls, spec.name if spec is CLOCK else relative(spec.name),
                qos_profile(spec, scan_reliability if spec is SCAN else None))
        if not any(name in self._robot_publishers for name in ("/tf", "/tf_static")):
            self.get_logger().warning(TF_MISSING_WARNING)

        cmd_vel_type = CMD_VEL_STAMPED_TYPE if self._cmd_vel_stamped else CMD_VEL.type
        callback: Callable[..., None] = self._on_cmd_vel
        if ignore_cmd_vel_from:
            relay = PublisherFilter(self, CMD_VEL.name, ignore_cmd_vel_from)

            def unless_relayed(msg: Any, info: Any) -> None:  # MessageInfo: Jazzy and later
                if not relay.is_from(info):
                    self._on_cmd_vel(msg)

            callback = unless_relayed
        self.create_subscription(message_class(cmd_vel_type), relative(CMD_VEL.name), callback,
                                 qos_profile(CMD_VEL))
        self.create_service(Empty, relative(RESET_SERVICE), self._on_reset)

        self.robot.parameters.listeners.append(self._on_robot_parameters_changed)
        self.robot.latched_listeners.append(self._publish_latched)
        if own_timer:
            # A steady clock: with use_sim_time the node's own clock follows /clock, which
            # this very timer publishes.
            self.create_timer(self.robot.sim.dt_s, self._tick,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        else:
            self.robot.tap.add(self._publish_tapped)
        self.publish(self._access.call(self.robot.latched))
        sim = self.robot.sim
        self.get_logger().info(
            f"world '{sim.world.name}', {sim.mode} mode; /cmd_vel as {cmd_vel_type}"
            f"{'; sim time' if self._use_sim_time else ''}")

    # ---- construction ---------------------------------------------------------------------

    def _build_robot(self) -> VirtualRobot:
        """The robot the start-up parameters describe (they are validated as declared)."""
        params_file = str(_declare(self, parameter_spec("params_file"),
                                   str(SHIPPED_PARAMS_FILE)))
        world = load_world(str(_declare(self, parameter_spec("world"))))
        seed = int(_declare(self, parameter_spec("seed")))
        localization = str(_declare(self, parameter_spec("localization")))
        platform = load_params(params_file)
        defaults = world.noise_over(platform.noise)
        noise = NoiseParams(**{
            spec.name: float(_declare(self, spec, float(getattr(defaults, spec.name))))
            for spec in _NOISE_PARAMETERS})
        sim = Simulation(world, platform.robot, seed=seed,
                         lidar=world.lidar_over(platform.lidar), noise=noise)
        clock = SimClock(TICK_PERIOD_S) if self._use_sim_time else WallClock()
        return VirtualRobot(sim, clock=clock,
                            localization=None if localization == WORLD_LOCALIZATION
                            else localization)

    def _declare_robot_parameters(self) -> None:
        """Declare the runtime parameters at their current values; overrides apply at once."""
        if not self.has_parameter("world"):  # a robot built elsewhere: describe it
            sim = self.robot.sim
            _declare(self, parameter_spec("world"), sim.world.source)
            _declare(self, parameter_spec("seed"), sim.seed or 0)
            _declare(self, parameter_spec("localization"), self.robot.localization)
            for spec in _NOISE_PARAMETERS:
                _declare(self, spec, float(getattr(sim.noise, spec.name)))
        parameters = self.robot.parameters
        current = self._access.call(lambda: {name: parameters.get(name)
                                             for name in _RUNTIME_PARAMETERS})
        for spec in RUNTIME_PARAMETERS:
            _declare(self, spec, current[spec.name])

    # ---- parameters -----------------------------------------------------------------------

    def _validate_parameters(self, parameters: list[Parameter[Any]]) -> SetParametersResult:
        """Refuse bad values with the reason (also for overrides given at start)."""
        robot_values = {p.name: p.value for p in parameters if p.name in _RUNTIME_PARAMETERS}
        try:
            for p in parameters:
                if p.name == "world":
                    load_world(str(p.value))
                elif p.name == "params_file":
                    load_params(str(p.value))
                elif p.name in _SPECS and p.name not in _RUNTIME_PARAMETERS:
                    _SPECS[p.name].validate(p.value)
            if robot_values and self._robot is not None:
                robot = self._robot
                self._access.call(lambda: robot.parameters.check(robot_values))
        except ConfigError as error:
            return SetParametersResult(successful=False, reason=str(error))
        except TimeoutError:
            return SetParametersResult(successful=False, reason="the simulation is not running")
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter[Any]]) -> None:
        """Make validated runtime changes in the simulation (unless it already has them)."""
        robot = self._robot
        values = {p.name: p.value for p in parameters if p.name in _RUNTIME_PARAMETERS}
        if robot is None or not values:
            return

        def apply() -> None:
            changed = {name: value for name, value in values.items()
                       if robot.parameters.get(name) != value}
            if changed:
                robot.parameters.set_many(changed)

        try:
            self._access.call(apply)
        except (ConfigError, TimeoutError) as error:
            self.get_logger().error(f"parameters {sorted(values)} not applied: {error}")

    def _on_robot_parameters_changed(self, names: list[str]) -> None:
        """A change made elsewhere (the admin page): mirror it into the node's parameters."""
        executor = self.executor
        if executor is not None:
            executor.create_task(self._sync_parameters, names)

    def _sync_parameters(self, names: list[str]) -> None:
        robot = self.robot
        current = self._access.call(lambda: {name: robot.parameters.get(name)
                                             for name in names if name in _RUNTIME_PARAMETERS})
        stale = [Parameter(name, value=value) for name, value in current.items()
                 if self.get_parameter(name).value != value]
        if stale:
            self.set_parameters(stale)

    # ---- topics and services --------------------------------------------------------------

    def _tick(self) -> None:
        self.publish(self.robot.step())  # a sim clock follows the world's ticks

    def publish(self, publications: Sequence[Publication]) -> None:
        """Publish the robot's messages (dicts) on the ROS graph; thread-safe."""
        for spec, msg in publications:
            self._publish_one(spec.name, msg)

    def subscription_count(self, topic: str) -> int:
        """Subscriptions of the graph the robot's publisher of ``topic`` has matched.

        They get what it publishes (``/odom``, ``/clock``...) from now on; 0 for a topic the
        node does not publish.
        """
        publisher = self._robot_publishers.get(topic)
        return 0 if publisher is None else int(publisher.get_subscription_count())

    def robot_publishers(self) -> dict[str, Any]:
        """The node's publisher of each topic of the robot it publishes, by topic name."""
        return dict(self._robot_publishers)

    def _publish_tapped(self, direction: str, topic: str, type_name: str, msg: Message,
                        sim_time_s: float) -> None:
        """The robot's tap: publish what it publishes (what it accepts came from a client)."""
        if direction != OUT:
            return
        if self.publish_hook is not None:
            self.publish_hook(topic, lambda: self._publish_one(topic, msg))
        elif topic == CLOCK.name and self._clock_after is not None:
            self._clock_after(lambda: self._publish_one(topic, msg))
        else:
            self._publish_one(topic, msg)

    def _publish_latched(self, publication: Publication) -> None:
        """A latched message changed (the URDF after a payload change): publish the new one."""
        spec, msg = publication
        self._publish_one(spec.name, msg)

    def _publish_one(self, topic: str, msg: Message) -> None:
        """Publish one robot message (a dict) on the ROS graph, if the node has its type."""
        publisher = self._robot_publishers.get(topic)
        if publisher is not None:
            if self._frame_prefix:
                msg = prefixed_frames(msg, self._frame_prefix)
            publisher.publish(to_message(self._classes[topic], msg, strict=False))

    def _on_cmd_vel(self, msg: Any) -> None:
        values, robot, stamped = to_dict(msg), self.robot, self._cmd_vel_stamped
        logger = self.get_logger()

        def apply() -> None:
            try:
                robot.on_cmd_vel(values, stamped=stamped)
            except ConfigError as error:
                logger.warning(f"/cmd_vel refused: {error}")

        self._access.post(apply)

    def _on_reset(self, request: Any, response: Any) -> Any:
        self._access.call(self.robot.reset)
        return response

    def destroy_node(self) -> None:
        """Stop listening to the robot, then destroy the node."""
        robot = self._robot  # None if the constructor failed
        if robot is not None and self._on_robot_parameters_changed in robot.parameters.listeners:
            robot.parameters.listeners.remove(self._on_robot_parameters_changed)
        if robot is not None:
            robot.tap.remove(self._publish_tapped)
            if self._publish_latched in robot.latched_listeners:
                robot.latched_listeners.remove(self._publish_latched)
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl+C or SIGTERM; ``args`` default to ``sys.argv``.

    Returns:
        0 after a clean shutdown, 2 when a parameter is invalid (the reason is printed).
    """
    rclpy.init(args=args)
    node = None
    try:
        node = VirtualRobotNode()
        rclpy.spin(node)
    except (InvalidParameterValueException, InvalidParameterTypeException,
            ConfigError) as error:
        print(f"websim-robot: error: {error}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        if rclpy.ok():
            raise
        # rclpy can fail taking a message that a signal's shutdown destroyed mid-take.
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
