"""Parameter specs and node schemas: one typed, documented, range-checked entry per parameter."""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
import difflib
from enum import Enum
import math
from typing import Any

from grasp_safety_filter.errors import ConfigError

#: Key under each node name that holds its parameters (rcl_yaml_param_parser).
ROS_PARAMETERS_KEY = 'ros__parameters'

#: Name of the wildcard section every node reads.
WILDCARD_NODE = '/**'

#: What the description of a required parameter says.
REQUIRED_NOTE = '; required (the default is never used)'


class ParameterError(ConfigError):
    """A parameter is missing, unknown, of the wrong type or out of range.

    Attributes:
        errors: One message per problem found (the exception message joins them).
    """

    def __init__(self, message: str, errors: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.errors: tuple[str, ...] = tuple(errors) or (message,)


class ParameterType(Enum):
    """ROS 2 parameter types used by this package (rcl_interfaces/ParameterType)."""

    BOOL = 'bool'
    INTEGER = 'integer'
    DOUBLE = 'double'
    STRING = 'string'
    BOOL_ARRAY = 'bool_array'
    INTEGER_ARRAY = 'integer_array'
    DOUBLE_ARRAY = 'double_array'
    STRING_ARRAY = 'string_array'

    @property
    def is_array(self) -> bool:
        """Whether values of this type are sequences."""
        return self.value.endswith('_array')


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter: name, type, default, admissible range and description.

    Attributes:
        name: Dotted ROS parameter name, e.g. ``"no_slip.pyramid_faces"``.
        type: Its ROS parameter type (static: never changes at run time).
        default: Default value (of that type).
        description: One line, with the unit.
        min_value: Inclusive lower bound (numbers, or each element of a numeric array).
        max_value: Inclusive upper bound.
        choices: Admissible values of a string parameter (or of each element of an array).
        length: Required array length, if fixed.
        exclusive_min: Lower bound is strict (e.g. a mass must be > 0).
        read_only: Structural: read once at start-up, ``ros2 param set`` is refused.
        is_path: A file path; a relative one resolves against the parameter file's directory.
        per_contact: A double that may also be given as a list, one per contact (each element
            within the bounds); declared with dynamic typing, since ROS types are static.
        required: No meaningful default: a node refuses to start unless it is given
            (:mod:`grasp_safety_filter.io.required_parameters`); the description says so.
    """

    name: str
    type: ParameterType
    default: Any
    description: str
    min_value: float | None = None
    max_value: float | None = None
    choices: tuple[str, ...] | None = None
    length: int | None = None
    exclusive_min: bool = False
    read_only: bool = False
    is_path: bool = False
    per_contact: bool = False
    required: bool = False

    def __post_init__(self) -> None:
        if self.required and REQUIRED_NOTE not in self.description:
            # Before a trailing [unit], where the docs and ros2 param describe show it.
            text, bracket, unit = self.description.rpartition(' [')
            marked = (
                f'{text}{REQUIRED_NOTE} [{unit}'
                if bracket and self.description.endswith(']')
                else self.description + REQUIRED_NOTE
            )
            object.__setattr__(self, 'description', marked)

    def validate(self, value: Any) -> Any:
        """Return ``value`` converted to this parameter's Python type, or raise ParameterError.

        The message names the parameter, what was expected and what was received.
        """
        if self.per_contact and isinstance(value, Iterable) and not isinstance(value, str | bytes):
            items = [self._scalar(v, index) for index, v in enumerate(value)]
            if not items:
                raise ParameterError(
                    f"parameter '{self.name}': expected a {self.type.value} or a non-empty list "
                    'of them (one per contact), got []'
                )
            return items
        if self.type.is_array:
            if isinstance(value, str | bytes | Mapping) or not isinstance(value, Iterable):
                raise ParameterError(
                    f"parameter '{self.name}': expected a {self.type.value}, got "
                    f'{type(value).__name__} {value!r}'
                )
            value = list(value)
            items = [self._scalar(v, index) for index, v in enumerate(value)]
            if self.length is not None and len(items) != self.length:
                raise ParameterError(
                    f"parameter '{self.name}': expected {self.length} elements, got {len(items)}"
                )
            return items
        return self._scalar(value, None)

    def constraint_text(self) -> str:
        """Describe the admissible values in words, e.g. ``"> 0"`` or ``"3 elements"``."""
        parts: list[str] = []
        if self.per_contact:
            parts.append('one value or one per contact')
        if self.length is not None:
            parts.append(f'{self.length} elements')
        bounds = ''
        if self.choices is not None:
            bounds = 'one of ' + ', '.join(self.choices)
        elif self.min_value is not None and self.max_value is not None:
            opening = '(' if self.exclusive_min else '['
            bounds = f'in {opening}{_number(self.min_value)}, {_number(self.max_value)}]'
        elif self.min_value is not None:
            bounds = ('>' if self.exclusive_min else '>=') + f' {_number(self.min_value)}'
        elif self.max_value is not None:
            bounds = f'<= {_number(self.max_value)}'
        if bounds:
            each = self.type.is_array or self.per_contact
            parts.append(('each ' if each else '') + bounds)
        return ', '.join(parts)

    def _scalar(self, value: Any, index: int | None) -> Any:
        where = f"parameter '{self.name}'" + (f' element {index}' if index is not None else '')
        base = self.type.value.removesuffix('_array')
        if base == 'bool':
            if not isinstance(value, bool):
                raise ParameterError(f'{where}: expected a bool, got {value!r}')
            return value
        if base == 'string':
            if not isinstance(value, str):
                raise ParameterError(f'{where}: expected a string, got {value!r}')
            if self.choices is not None and value not in self.choices:
                raise ParameterError(
                    f'{where}: expected one of {list(self.choices)}, got {value!r}'
                )
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ParameterError(f'{where}: expected a {base}, got {value!r}')
        if base == 'integer':
            if isinstance(value, float):
                raise ParameterError(f'{where}: expected an integer, got {value!r}')
            number: float = value
        else:
            number = float(value)
            if not math.isfinite(number):
                raise ParameterError(f'{where}: expected a finite number, got {value!r}')
        if self.min_value is not None:
            below = number <= self.min_value if self.exclusive_min else number < self.min_value
            if below:
                relation = '>' if self.exclusive_min else '>='
                raise ParameterError(
                    f'{where}: expected {relation} {self.min_value}, got {value!r}'
                )
        if self.max_value is not None and number > self.max_value:
            raise ParameterError(f'{where}: expected <= {self.max_value}, got {value!r}')
        return number


def _number(value: float) -> str:
    """Shortest faithful text of a bound (``0``, ``-1.5707963267948966``)."""
    return str(int(value)) if float(value).is_integer() else repr(float(value))


@dataclass(frozen=True)
class NodeSchema:
    """Every parameter one node declares.

    Construction checks the schema itself: names are unique and each default passes its own
    spec (an array default must be non-empty, because rclpy infers the static type of a
    declared parameter from its default and cannot type an empty list).

    Attributes:
        node_name: The node's default name, e.g. ``"hand_sim_node"``.
        parameters: Its parameter specs, in declaration order.
    """

    node_name: str
    parameters: tuple[ParameterSpec, ...]
    _by_name: dict[str, ParameterSpec] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        by_name: dict[str, ParameterSpec] = {}
        for spec in self.parameters:
            if spec.name in by_name:
                raise ValueError(f"schema '{self.node_name}': parameter '{spec.name}' twice")
            if spec.type.is_array and not spec.default:
                raise ValueError(
                    f"schema '{self.node_name}': parameter '{spec.name}': expected a non-empty "
                    f'default for a {spec.type.value}, got {spec.default!r}'
                )
            spec.validate(spec.default)
            by_name[spec.name] = spec
        object.__setattr__(self, '_by_name', by_name)

    @classmethod
    def from_sections(cls, node_name: str, *sections: Iterable[ParameterSpec]) -> NodeSchema:
        """Concatenate sections of specs into one node's schema."""
        return cls(node_name, tuple(spec for section in sections for spec in section))

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in declaration order."""
        return tuple(spec.name for spec in self.parameters)

    def get(self, name: str) -> ParameterSpec | None:
        """Return the spec called ``name``, or None."""
        return self._by_name.get(name)

    def defaults(self) -> dict[str, Any]:
        """Return every parameter at its default value (converted to its Python type)."""
        return {spec.name: spec.validate(spec.default) for spec in self.parameters}

    def __getitem__(self, name: str) -> ParameterSpec:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(
                f"node '{self.node_name}' declares no parameter '{name}'"
                + suggestion(name, self.names)
            ) from None

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def __iter__(self) -> Iterator[ParameterSpec]:
        return iter(self.parameters)

    def __len__(self) -> int:
        return len(self.parameters)


def suggestion(name: str, candidates: Iterable[str]) -> str:
    """Return `` (did you mean '<closest>'?)`` for a misspelt name, or '' if none is close."""
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ''


#: Parameters rclpy declares on every node by itself; a file may set them for any node.
# fmt: off
ROS_BUILTIN_PARAMETERS: dict[str, ParameterSpec] = {
    'use_sim_time': ParameterSpec(
        'use_sim_time', ParameterType.BOOL, False, 'Use /clock instead of the system clock'
    ),
    'start_type_description_service': ParameterSpec(
        'start_type_description_service',
        ParameterType.BOOL,
        True,
        'Offer the ~/get_type_description service',
    ),
}
# fmt: on

#: Prefix of the QoS override parameters rclpy declares per publisher/subscription.
ROS_QOS_OVERRIDES_PREFIX = 'qos_overrides.'
