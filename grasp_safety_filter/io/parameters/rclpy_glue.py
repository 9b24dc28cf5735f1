"""rclpy glue (Jazzy): descriptors, the on-set callback, declaration; ROS imported when called."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from grasp_safety_filter.io.parameters.spec import NodeSchema, ParameterSpec, ParameterType
from grasp_safety_filter.io.parameters.validation import collect_checked


def make_parameter_descriptor(spec: ParameterSpec) -> Any:
    """Build the ``rcl_interfaces/msg/ParameterDescriptor`` of a spec.

    Type, description, read-only flag and, for a number bounded on both sides, an
    inclusive ``FloatingPointRange``/``IntegerRange`` (step 0: continuous) that
    ``ros2 param describe`` shows and rclpy enforces. Bounds it cannot express (strict,
    one-sided, per array element, choices) go to ``additional_constraints`` and are
    enforced by :func:`on_set_parameters_callback`.
    """
    from rcl_interfaces.msg import (
        FloatingPointRange,
        IntegerRange,
        ParameterDescriptor,
    )
    from rcl_interfaces.msg import ParameterType as ParameterTypeMsg

    descriptor = ParameterDescriptor(
        name=spec.name,
        type=getattr(ParameterTypeMsg, f'PARAMETER_{spec.type.name}'),
        description=spec.description,
        additional_constraints=spec.constraint_text(),
        read_only=spec.read_only,
    )
    if spec.per_contact:
        # A double or a double array: rclpy checks the type only when it is static, and
        # on_set_parameters_callback checks the value.
        descriptor.type = ParameterTypeMsg.PARAMETER_NOT_SET
        descriptor.dynamic_typing = True
    bounded = spec.min_value is not None and spec.max_value is not None
    if bounded and spec.type is ParameterType.DOUBLE:
        descriptor.floating_point_range = [
            FloatingPointRange(
                from_value=float(spec.min_value),
                to_value=float(spec.max_value),
                step=0.0,
            )
        ]
    elif bounded and spec.type is ParameterType.INTEGER:
        descriptor.integer_range = [
            IntegerRange(from_value=int(spec.min_value), to_value=int(spec.max_value), step=0)
        ]
    return descriptor


def on_set_parameters_callback(schema: NodeSchema) -> Callable[[list[Any]], Any]:
    """Make a callback for ``Node.add_on_set_parameters_callback`` that checks ``schema``.

    rclpy calls it with a list of ``rclpy.parameter.Parameter`` at declaration (each
    override from a parameter file) and on every ``set_parameters``; it returns
    ``SetParametersResult(successful, reason)``, the reason listing every rejected parameter.
    Names outside the schema (``use_sim_time``, QoS overrides) are left to their owners.
    """
    from rcl_interfaces.msg import SetParametersResult

    def callback(parameters: list[Any]) -> Any:
        errors: list[str] = []
        for parameter in parameters:
            spec = schema.get(parameter.name)
            if spec is not None:
                collect_checked(errors, spec, parameter.value, strict_types=True)
        return SetParametersResult(successful=not errors, reason='; '.join(errors))

    return callback


def declare_node_parameters(node: Any, schema: NodeSchema) -> dict[str, Any]:
    """Declare every parameter of ``schema`` on an rclpy node and return their values.

    Registers :func:`on_set_parameters_callback` first, so that overrides from a parameter
    file or the command line are validated as they are declared: a bad value stops the
    node at start-up with rclpy's ``InvalidParameterValueException`` carrying our message.

    Args:
        node: An ``rclpy.node.Node``.
        schema: The node's schema.

    Returns:
        ``{name: value}`` after overrides, converted like :func:`validate_parameters`
        (arrays as lists, not ``array.array``).
    """
    node.add_on_set_parameters_callback(on_set_parameters_callback(schema))
    declared = node.declare_parameters(
        namespace='',
        parameters=[
            # The default's Python type fixes the static ROS type: 1.0, never 1.
            (spec.name, spec.validate(spec.default), make_parameter_descriptor(spec))
            for spec in schema
        ],
    )
    return {
        parameter.name: schema[parameter.name].validate(parameter.value) for parameter in declared
    }
