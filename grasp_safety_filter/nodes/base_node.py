"""What the package's three rclpy nodes share: parameters, topic-table I/O, spinning.

An :class:`EndpointNode` declares its node's parameter schema (descriptors, ranges, an
on-set validation callback), runs the cross-parameter checks, resolves relative paths
against the package's ``config/`` directory, creates its publishers and subscriptions with
the QoS of the topic table (:mod:`grasp_safety_filter.io.topics`) and publishes the
:class:`~grasp_safety_filter.nodes.outgoing.Outgoing` lists its endpoint returns.
Parameters that are not read-only take effect when set: the post-set callback hands the
changed values to :meth:`EndpointNode.apply_parameters`.

This module and the ``*_node.py`` modules are the only ones that import rclpy.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter

from grasp_safety_filter.io.messages import (
    byte_value,
    DiagnosticLevel,
    MessageNamespace,
    rclpy_message_class,
)
from grasp_safety_filter.io.parameters import (
    declare_node_parameters,
    ParameterError,
    resolve_relative_paths,
)
from grasp_safety_filter.io.paths import share_directory
from grasp_safety_filter.io.schemas import check_node_parameters, NODE_SCHEMAS
from grasp_safety_filter.io.topics import DIAGNOSTICS, topic_spec
from grasp_safety_filter.nodes.outgoing import Outgoing


class EndpointNode(Node):
    """An rclpy node around a message-level endpoint.

    Args:
        node_name: The node's default name, a key of :data:`NODE_SCHEMAS`.
        publishes: Topics it publishes (their types and QoS from the topic table).
        **kwargs: Passed to ``rclpy.node.Node`` (``cli_args``, ``parameter_overrides``...).

    Attributes:
        parameters: Every parameter of the node's schema, validated, paths absolute.
        msgs: The rclpy message classes, for the endpoint.

    """

    def __init__(self, node_name: str, publishes: Iterable[str], **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.schema = NODE_SCHEMAS[node_name]
        values = declare_node_parameters(self, self.schema)
        check_node_parameters(node_name, values, f"node '{self.get_fully_qualified_name()}'")
        # Relative paths (the URDF) resolve against the installed config/ directory.
        self.parameters = resolve_relative_paths(self.schema, values, self.config_directory)
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
        """The package's installed ``config/`` directory."""
        return share_directory() / 'config'

    def subscribe(self, topic: str, callback: Callable[[Any], None]) -> Any:
        """Subscribe to a topic of the table with its type and QoS."""
        spec = topic_spec(topic)
        return self.create_subscription(
            rclpy_message_class(spec.msgtype), topic, callback, spec.qos.to_rclpy()
        )

    def publisher(self, topic: str) -> Any:
        """Return the publisher of ``topic``."""
        return self._publishers_by_topic[topic]

    def publish(self, outgoing: Iterable[Outgoing]) -> None:
        """Publish each message on its topic, in order; log WARN and ERROR statuses."""
        for topic, _, msg in outgoing:
            self._publishers_by_topic[topic].publish(msg)
            if topic == DIAGNOSTICS:
                self._log_statuses(msg)

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
            level = byte_value(status.level)
            text = f'{status.name}: {status.message}'
            if level == DiagnosticLevel.ERROR:
                self.get_logger().error(text, throttle_duration_sec=1.0)
            elif level == DiagnosticLevel.WARN:
                self.get_logger().warning(text, throttle_duration_sec=1.0)


def spin_node(node_factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """Initialise rclpy, spin one node until shutdown or Ctrl-C, and clean up (Jazzy)."""
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
