"""What the package's three rclpy nodes share: parameters and topic-table I/O.

An :class:`EndpointNode` computes its start-up parameters from its ROS arguments with the
precedence every ROS user expects (:mod:`grasp_safety_filter.io.ros_arguments`: later
parameter files beat earlier ones, every ``-p`` beats every file), refuses unknown names
and misspelt node sections, hands the values to rclpy as parameter overrides, declares its
node's parameter schema (descriptors, ranges, an on-set validation callback), runs the
cross-parameter checks and resolves a relative path against the directory of the file that
set it. It creates its publishers and subscriptions with the QoS of the topic table
(:mod:`grasp_safety_filter.io.topics`) and publishes the
:class:`~grasp_safety_filter.nodes.outgoing.Outgoing` lists its endpoint returns.
Parameters that are not read-only take effect when set: the post-set callback hands the
changed values to :meth:`EndpointNode.apply_parameters`.

A node process spins one (:mod:`~grasp_safety_filter.nodes.spin_node`). This module,
that one and the ``*_node.py`` modules are the only ones that import rclpy.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
import dataclasses
from pathlib import Path
import sys
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter

from grasp_safety_filter.io.diagnostic_keys import Key
from grasp_safety_filter.io.messages import (
    bounded_text,
    byte_value,
    DiagnosticLevel,
    DiagnosticReport,
    diagnostics_to_msg,
    MessageNamespace,
    rclpy_message_class,
)
from grasp_safety_filter.io.parameters import (
    declare_node_parameters,
    ParameterError,
    resolve_relative_paths,
    validate_parameters,
)
from grasp_safety_filter.io.paths import share_directory
from grasp_safety_filter.io.required_parameters import check_required_parameters
from grasp_safety_filter.io.ros_arguments import (
    given_parameters,
    GivenParameter,
    parse_ros_arguments,
    remapped_fully_qualified_name,
)
from grasp_safety_filter.io.schemas import check_node_parameters, NODE_SCHEMAS
from grasp_safety_filter.io.topics import DIAGNOSTICS, topic_spec
from grasp_safety_filter.nodes.outgoing import Outgoing

#: Shortest interval between two ERROR logs of failing subscription callbacks, s.
CALLBACK_ERROR_LOG_PERIOD = 1.0


class EndpointNode(Node):
    """An rclpy node around a message-level endpoint.

    Args:
        node_name: The node's default name, a key of :data:`NODE_SCHEMAS`.
        publishes: Topics it publishes (their types and QoS from the topic table).
        global_arguments: The arguments ``rclpy.init`` was given (default ``sys.argv``, as
            rclpy's); ignored with ``use_global_arguments=False``.
        **kwargs: Passed to ``rclpy.node.Node`` (``context``, ``cli_args``, ``namespace``...).
            ``parameter_overrides`` beat every argument.

    Attributes:
        parameters: Every parameter of the node's schema, validated, paths absolute.
        given_parameters: The names the arguments and overrides set, with their sources.
        msgs: The rclpy message classes, for the endpoint.

    Raises:
        ParameterError: A parameter file or ``-p`` rule gives an unknown or invalid
            parameter, a file has a misspelt node section, or the values are inconsistent.

    """

    def __init__(
        self,
        node_name: str,
        publishes: Iterable[str],
        *,
        global_arguments: Sequence[str] | None = None,
        **kwargs: Any,
    ) -> None:
        self.schema = NODE_SCHEMAS[node_name]
        caller_overrides: list[Parameter] = list(kwargs.pop('parameter_overrides', None) or [])
        expected_name, self.given_parameters = _start_up_parameters(
            node_name, global_arguments, caller_overrides, kwargs
        )
        given = {name: parameter.value for name, parameter in self.given_parameters.items()}
        source = f"node '{expected_name}'"
        check_node_parameters(node_name, validate_parameters(self.schema, given, source), source)
        check_required_parameters(node_name, given, source)
        # Converted by the schema (a double array as a list of floats); ROS's own as given.
        overrides = [
            Parameter(name, value=spec.validate(value) if spec is not None else value)
            for name, value in given.items()
            for spec in [self.schema.get(name)]
        ]
        super().__init__(node_name, parameter_overrides=overrides + caller_overrides, **kwargs)
        if self.get_fully_qualified_name() != expected_name:
            self.get_logger().warning(
                f"parameters were computed for '{expected_name}': ROS arguments this node "
                'does not understand renamed it'
            )
        values = declare_node_parameters(self, self.schema)
        self.parameters = resolve_relative_paths(
            self.schema,
            values,
            self.config_directory,
            {name: parameter.directory for name, parameter in self.given_parameters.items()},
        )
        self.msgs = MessageNamespace.from_rclpy()
        self._publishers_by_topic = {
            spec.name: self.create_publisher(
                rclpy_message_class(spec.msgtype), spec.name, spec.qos.to_rclpy()
            )
            for spec in map(topic_spec, publishes)
        }
        self.add_post_set_parameters_callback(self._on_parameters_set)

    @property
    def config_directory(self) -> Path:
        """The package's ``config/`` directory, base of relative paths left at their default."""
        return share_directory() / 'config'

    def subscribe(
        self,
        topic: str,
        callback: Callable[[Any], None],
        *,
        sensor: bool = False,
        newest_only: bool = False,
        raw: bool = False,
    ) -> Any:
        """Subscribe to a topic of the table with its type and QoS.

        ``sensor``: best effort instead of the table's reliability (same depth), as a
        subscription to a hand driver's or a tracker's stream should be: it matches reliable
        and best-effort publishers alike (many trackers publish best effort, as rclcpp's
        ``SensorDataQoS``), where a reliable one matches reliable publishers only.
        ``newest_only``: that, and a history of one: a node that falls behind a driver's
        stream takes its newest state next, not the states queued before it. ``raw``: the
        callback gets the serialised message (``bytes``): a node that reads one message in
        many (``rclpy.serialization.deserialize_message`` then) skips the others' conversion.

        The callback is wrapped by :func:`guarded_callback`: an exception it raises is
        logged (ERROR, throttled) and reported on ``/diagnostics`` (when this node
        publishes them) instead of ending ``rclpy.spin``.
        """
        spec = topic_spec(topic)
        qos = spec.qos
        if sensor or newest_only:
            qos = dataclasses.replace(qos, reliability='best_effort')
        if newest_only:
            qos = dataclasses.replace(qos, depth=1)
        guarded = guarded_callback(topic, callback, self._report_callback_error, self.context.ok)
        return self.create_subscription(
            rclpy_message_class(spec.msgtype), topic, guarded, qos.to_rclpy(), raw=raw
        )

    def subscribe_polled(self, topic: str) -> PolledSubscription:
        """Subscribe to a stream whose newest message is taken when wanted, not on arrival.

        Best effort with a history of one, as ``newest_only``. Spun by an executor that
        honours callback groups (:func:`~grasp_safety_filter.nodes.spin_node.
        wait_set_executor`), the node is never woken by it: reading a 1 kHz driver's stream
        30 times a second costs 30 takes, not 1 000 callbacks (DDS keeps the newest sample
        meanwhile). Under the events executor, which runs every callback, it still works.
        """
        spec = topic_spec(topic)
        qos = dataclasses.replace(spec.qos, reliability='best_effort', depth=1)
        polled = PolledSubscription()
        polled.subscription = self.create_subscription(
            rclpy_message_class(spec.msgtype), topic, polled.keep, qos.to_rclpy(),
            callback_group=_NeverExecuted(),
        )  # fmt: skip
        return polled

    def add_publisher(self, topic: str) -> None:
        """Publish ``topic`` too (its type and QoS from the table), once the node knows it must."""
        spec = topic_spec(topic)
        self._publishers_by_topic[topic] = self.create_publisher(
            rclpy_message_class(spec.msgtype), spec.name, spec.qos.to_rclpy()
        )

    def _report_callback_error(self, topic: str, error: Exception) -> None:
        """Log a subscription callback's exception (ERROR, throttled); report it, ERROR."""
        text = bounded_text(f'{topic}: message not handled: {type(error).__name__}: {error}')
        self.get_logger().error(text, throttle_duration_sec=CALLBACK_ERROR_LOG_PERIOD)
        publisher = self._publishers_by_topic.get(DIAGNOSTICS)
        if publisher is None:
            return
        report = DiagnosticReport.create(
            self.get_name(), DiagnosticLevel.ERROR, text, {'input.topic': topic}
        )
        publisher.publish(diagnostics_to_msg(self.msgs, max(self.now_seconds(), 0.0), report))

    def publisher(self, topic: str) -> Any:
        """Return the publisher of ``topic``."""
        return self._publishers_by_topic[topic]

    def publish(self, outgoing: Iterable[Outgoing]) -> None:
        """Publish each message on its topic, in order; log WARN and ERROR statuses."""
        for topic, _, msg in outgoing:
            self._publishers_by_topic[topic].publish(msg)
            if topic == DIAGNOSTICS:
                self._log_statuses(msg)

    def log_lines(self, lines: Iterable[tuple[DiagnosticLevel, str]]) -> None:
        """Log an endpoint's lines: ERROR as errors, WARN as warnings, others as information."""
        for level, text in lines:
            # One call site per severity: rclpy refuses to change it between calls.
            if level == DiagnosticLevel.ERROR:
                self.get_logger().error(text)
            elif level == DiagnosticLevel.WARN:
                self.get_logger().warning(text)
            else:
                self.get_logger().info(text)

    def now_seconds(self) -> float:
        """Return the node clock's time in s (simulation time under ``use_sim_time``)."""
        return self.get_clock().now().nanoseconds / 1e9

    def apply_parameters(self, changed: Mapping[str, Any]) -> None:
        """Apply live parameter changes (override); ``self.parameters`` is already updated."""

    def _on_parameters_set(self, parameters: list[Parameter]) -> None:
        changed = {
            p.name: self.schema[p.name].validate(p.value)
            for p in parameters
            if p.name in self.schema
        }
        if not changed:
            return
        self.parameters = {**self.parameters, **changed}
        try:
            self.apply_parameters(changed)
        except (ParameterError, ValueError) as error:
            self.get_logger().error(f'parameters {sorted(changed)} not applied: {error}')

    def _log_statuses(self, msg: Any) -> None:
        for status in msg.status:
            if any(item.key == Key.GRASP_VALID for item in status.values):
                continue  # the grasp check's: its changes are logged once (log_lines)
            level = byte_value(status.level)
            text = f'{status.name}: {status.message}'
            if level == DiagnosticLevel.ERROR:
                self.get_logger().error(text, throttle_duration_sec=1.0)
            elif level == DiagnosticLevel.WARN:
                self.get_logger().warning(text, throttle_duration_sec=1.0)


def guarded_callback(
    topic: str,
    callback: Callable[[Any], None],
    report: Callable[[str, Exception], None],
    context_ok: Callable[[], bool],
) -> Callable[[Any], None]:
    """Wrap a subscription callback so that no exception it raises ends the spin loop.

    Args:
        topic: The subscribed topic (named in the report).
        callback: The endpoint's handler.
        report: Called with the topic and the exception; its own failure is swallowed.
        context_ok: Whether the rclpy context still runs: once it is shut down, the
            exception propagates as before (a callback cut short by the node's shutdown).

    """

    def guarded(msg: Any) -> None:
        try:
            callback(msg)
        except Exception as error:
            if not context_ok():
                raise
            try:
                report(topic, error)
            except Exception:  # reporting must never end the spin either
                pass

    return guarded


def _start_up_parameters(
    node_name: str,
    global_arguments: Sequence[str] | None,
    caller_overrides: Sequence[Parameter],
    node_kwargs: Mapping[str, Any],
) -> tuple[str, dict[str, GivenParameter]]:
    """Collect what the process's and the node's ROS arguments and the overrides set.

    Returns:
        The node's fully qualified name after remapping, and ``{name: GivenParameter}``
        (:func:`~grasp_safety_filter.io.ros_arguments.given_parameters`, then the
        overrides, based in the current directory).

    Raises:
        ParameterError: As ``given_parameters``, or an override is unknown or invalid.
    """
    argument_lists = [node_kwargs.get('cli_args') or []]
    if node_kwargs.get('use_global_arguments', True):
        argument_lists.insert(0, sys.argv if global_arguments is None else global_arguments)
    argument_sets = [parse_ros_arguments(arguments) for arguments in argument_lists]
    name = remapped_fully_qualified_name(node_name, node_kwargs.get('namespace'), argument_sets)
    schema = NODE_SCHEMAS[node_name]
    others = [other for other_name, other in NODE_SCHEMAS.items() if other_name != node_name]
    given = given_parameters(
        schema, name, argument_sets, other_schemas=others, node_names=NODE_SCHEMAS
    )
    source = 'parameter_overrides'
    values = {parameter.name: parameter.value for parameter in caller_overrides}
    validate_parameters(schema, values, source, other_schemas=others)
    given.update({n: GivenParameter(v, source, Path.cwd()) for n, v in values.items()})
    return name, given


class _NeverExecuted(CallbackGroup):
    """A callback group the executor never waits on nor runs: its subscriptions are polled."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class PolledSubscription:
    """A subscription its owner takes from (:meth:`EndpointNode.subscribe_polled`)."""

    def __init__(self) -> None:
        self.subscription: Any = None
        self._kept: Any = None

    def keep(self, msg: Any) -> None:
        """Keep a message an executor took (the events executor ignores callback groups)."""
        self._kept = msg

    def take_newest(self) -> Any | None:
        """Return the newest message received since the last take (None: none)."""
        newest, self._kept = self._kept, None
        handle = self.subscription.handle
        with handle:
            # The take an executor does (rclpy's ``wait_for_message`` does it too).
            while (taken := handle.take_message(self.subscription.msg_type, False)) is not None:
                newest = taken[0]
        return newest
