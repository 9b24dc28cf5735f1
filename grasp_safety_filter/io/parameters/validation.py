"""Validation of a node's parameters against its schema: every error named, all at once."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from grasp_safety_filter.io.parameters.spec import (
    NodeSchema,
    ParameterError,
    ParameterSpec,
    ParameterType,
    ROS_BUILTIN_PARAMETERS,
    ROS_QOS_OVERRIDES_PREFIX,
    suggestion,
)


def validate_parameters(
    schema: NodeSchema,
    values: Mapping[str, Any],
    source: str = 'parameters',
    *,
    strict_types: bool = True,
    other_schemas: Iterable[NodeSchema] = (),
) -> dict[str, Any]:
    """Check a node's parameter values against its schema and fill in the defaults.

    Args:
        schema: The node's schema.
        values: ``{dotted name: value}``, e.g. from :func:`parameters_for_node`.
        source: Where the values come from (a file and node), for the messages.
        strict_types: Reject an integer where a double is declared, as ROS does (its types
            are static: ``1`` in a parameter file is an integer, ``1.0`` a double).
        other_schemas: Schemas of other nodes, to tell where an unknown key belongs.

    Returns:
        Every parameter of the schema, converted to its Python type (arrays as lists).
        ROS's own parameters (``use_sim_time``, ``qos_overrides.*``) are checked and left out.

    Raises:
        ParameterError: Listing every problem; each names the parameter, the source, what was
            expected and what was received. Unknown names come with the closest declared one.
    """
    errors: list[str] = []
    result = schema.defaults()
    for name, value in values.items():
        spec = schema.get(name)
        if spec is None:
            builtin = ROS_BUILTIN_PARAMETERS.get(name)
            if builtin is not None:
                collect_checked(errors, builtin, value, strict_types)
            elif not name.startswith(ROS_QOS_OVERRIDES_PREFIX):
                errors.append(_unknown_message(schema, name, other_schemas))
            continue
        converted = collect_checked(errors, spec, value, strict_types)
        if converted is not None:
            result[name] = converted
    raise_parameter_errors(source, errors)
    return result


def collect_checked(errors: list[str], spec: ParameterSpec, value: Any, strict_types: bool) -> Any:
    """Return ``value`` checked against ``spec``, or None with its error appended to ``errors``."""
    try:
        if strict_types:
            _check_static_type(spec, value)
        return spec.validate(value)
    except ParameterError as error:
        errors.append(str(error))
        return None


def _check_static_type(spec: ParameterSpec, value: Any) -> None:
    """Reject integers where ROS declares a double (rclpy refuses them at declaration)."""

    def is_integer(item: Any) -> bool:
        return isinstance(item, int) and not isinstance(item, bool)

    if spec.type is ParameterType.DOUBLE and is_integer(value):
        raise ParameterError(
            f"parameter '{spec.name}': expected a double (ROS reads {value!r} as an integer; "
            f'write {float(value)!r}), got {value!r}'
        )
    if (
        (spec.type is ParameterType.DOUBLE_ARRAY or spec.per_contact)
        and isinstance(value, list | tuple)
        and any(is_integer(item) for item in value)
    ):
        raise ParameterError(
            f"parameter '{spec.name}': expected a double_array (ROS reads an element without "
            f'a decimal point as an integer; write {[float(v) for v in value]!r}), '
            f'got {list(value)!r}'
        )


def _unknown_message(schema: NodeSchema, name: str, other_schemas: Iterable[NodeSchema]) -> str:
    owners = [other.node_name for other in other_schemas if name in other]
    hint = (
        f' (it is a parameter of {", ".join(owners)})'
        if owners
        else suggestion(name, schema.names)
    )
    return f"unknown parameter '{name}': node '{schema.node_name}' does not declare it{hint}"


def raise_parameter_errors(source: str, errors: Sequence[str], kind: str = 'invalid') -> None:
    """Raise one ParameterError listing every problem found; return if there is none.

    Args:
        source: Where the values come from (a file and node), prefixed to the message.
        errors: One message per problem.
        kind: What the problems make the parameters, in the message of several
            (``"3 invalid parameters"``, ``"2 inconsistent parameters"``).

    Raises:
        ParameterError: ``errors`` is not empty.
    """
    if len(errors) == 1:
        raise ParameterError(f'{source}: {errors[0]}', errors)
    if errors:
        lines = '\n'.join(f'  - {error}' for error in errors)
        raise ParameterError(f'{source}: {len(errors)} {kind} parameters:\n{lines}', errors)


def resolve_relative_paths(
    schema: NodeSchema,
    values: Mapping[str, Any],
    base_directory: str | Path,
    base_directories: Mapping[str, str | Path] | None = None,
) -> dict[str, Any]:
    """Make every path parameter (``is_path``) absolute, relative ones against ``base_directory``.

    The runner passes the parameter file's directory. A node passes, per parameter in
    ``base_directories``, the directory of the file that set it (the current directory for
    a command-line value) and its package's config directory for the defaults.
    """
    resolved = dict(values)
    for spec in schema:
        value = resolved.get(spec.name)
        if spec.is_path and isinstance(value, str) and value:
            path = Path(value).expanduser()
            base = Path((base_directories or {}).get(spec.name, base_directory))
            resolved[spec.name] = str(path if path.is_absolute() else base / path)
    return resolved
