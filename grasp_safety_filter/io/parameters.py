"""Parameter schemas: one typed, documented, range-checked entry per ROS parameter.

The same schema is declared by the rclpy node (with ParameterDescriptors and an on-set
validation callback) and used by the ROS-free runner to load ``config/*.yaml``.

A ROS 2 parameter file maps node names to ``ros__parameters``::

    /**:                          # every node
      ros__parameters:
        model:
          fingertip_radius: 0.06  # nested mappings flatten to "model.fingertip_radius"
    hand_sim_node:                # the node /hand_sim_node
      ros__parameters:
        time_step: 0.001

Node names may carry a leading slash and a namespace (``/arm/hand_sim_node``), or nest the
namespace as a mapping (``arm: {hand_sim_node: {ros__parameters: ...}}``); ``/*`` matches
one name token and ``/**`` any number. Sections apply in file order, later values replacing
earlier ones, as in rclpy: put ``/**`` first. Parameter types are static, as in ROS:
``1`` is an integer and is not accepted where a double is declared (write ``1.0``).

Only :func:`declare_node_parameters`, :func:`make_parameter_descriptor` and
:func:`on_set_parameters_callback` touch ROS, and they import it when called.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
import difflib
from enum import Enum
import functools
import math
from pathlib import Path
import re
from typing import Any

import yaml

from grasp_safety_filter.errors import ConfigError

#: Key under each node name that holds its parameters (rcl_yaml_param_parser).
ROS_PARAMETERS_KEY = 'ros__parameters'

#: Name of the wildcard section every node reads.
WILDCARD_NODE = '/**'


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

#: Prefix of the QoS override parameters rclpy declares per publisher/subscription.
ROS_QOS_OVERRIDES_PREFIX = 'qos_overrides.'


# --------------------------------------------------------------------------------------------
# Reading parameter files
# --------------------------------------------------------------------------------------------


class _RosYamlLoader(getattr(yaml, 'CSafeLoader', yaml.SafeLoader)):  # type: ignore[misc]
    """YAML as rcl_yaml_param_parser reads it: ``1e-8`` is a double; duplicate keys are errors.

    Numbers follow YAML 1.2 (:data:`_NUMBER_RESOLVERS`), as rcl does: PyYAML's YAML 1.1
    would read ``1e-8`` as a string and ``1_000`` or ``1:30`` as numbers. The parser is
    libyaml's where PyYAML has it (ten times faster than PyYAML's own on large files).
    """

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f'duplicate key {key!r}', key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


#: The plain scalars read as numbers, as in YAML 1.2: an exponent needs no dot nor sign
#: (``1e-5``); no digit separators (``1_000``) nor base 60 (``1:30``), which stay strings.
_NUMBER_RESOLVERS: dict[str, tuple[re.Pattern[str], str]] = {
    'tag:yaml.org,2002:float': (
        re.compile(
            r'^(?:[-+]?(?:[0-9]+\.[0-9]*|\.[0-9]+|[0-9]+(?=[eE]))(?:[eE][-+]?[0-9]+)?'
            r'|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$'
        ),
        '-+0123456789.',
    ),
    'tag:yaml.org,2002:int': (
        re.compile(r'^[-+]?(?:[0-9]+|0b[01]+|0o[0-7]+|0x[0-9a-fA-F]+)$'),
        '-+0123456789',
    ),
}

_RosYamlLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag not in _NUMBER_RESOLVERS]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
for _tag, (_regexp, _first) in _NUMBER_RESOLVERS.items():
    _RosYamlLoader.add_implicit_resolver(_tag, _regexp, list(_first))


def parse_parameter_value(text: str) -> Any:
    """Type a command-line value (``-p name:=value``) as rcl does: YAML, as in a file.

    ``true`` is a bool, ``3`` an integer, ``3.0`` and ``1e-3`` doubles, ``[0.1, 0.2]`` a
    double array, ``"3"`` a string. What rcl keeps as text (``null``, ``~``, dates, YAML
    1.1's ``1:30`` and ``1_000``) stays the text as written.

    Raises:
        ParameterError: The value is empty, a mapping or not YAML.
    """
    try:
        value = yaml.load(text, Loader=_RosYamlLoader)
        if isinstance(value, dict) or not text.strip():
            raise ParameterError(f'expected a value or a list of values, got {text!r}')
        if isinstance(value, list):
            return [v if isinstance(v, bool | int | float | str) else str(v) for v in value]
    except yaml.YAMLError as error:
        raise ParameterError(f'expected a YAML value, got {text!r}: {error}') from None
    except UnicodeError:
        raise ParameterError(f'expected UTF-8 text, got {text!r}') from None
    except RecursionError:
        raise ParameterError(
            f'expected a value or a list of values, got {text[:40]!r}... nested too deeply'
        ) from None
    return value if isinstance(value, bool | int | float | str) else text.strip()


def load_parameter_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """Read a ROS 2 parameter file without ROS.

    The file is parsed once while its modification time and size stay the same: the
    nodes of a run, each reading it, share that parse (array values are shared lists,
    not to be changed in place; the mappings returned are the caller's own).

    Args:
        path: The YAML file.

    Returns:
        ``{node: {dotted parameter name: value}}``. Node keys are fully qualified
        (``"/hand_sim_node"``, ``"/arm/hand_sim_node"``) or wildcard patterns (``"/**"``),
        in file order.

    Raises:
        ParameterError: The file is missing, is not YAML, or is not a ROS parameter file;
            the message names the file and the offending key.
    """
    path = Path(path)
    try:
        stat = path.stat()
    except FileNotFoundError:
        raise ParameterError(f"parameter file '{path}' does not exist") from None
    except OSError as error:
        raise ParameterError(
            f"parameter file '{path}': cannot read it: {error.strerror}"
        ) from None
    if not path.is_file():
        raise ParameterError(f"parameter file '{path}': expected a file, got a directory")
    parsed = _parsed_file(path, path.resolve(), stat.st_mtime_ns, stat.st_size)
    return {node: dict(section) for node, section in parsed.items()}


#: Parameter files kept parsed: the runner and a launch read one file for every node.
PARSED_FILES_KEPT = 4


@functools.lru_cache(maxsize=PARSED_FILES_KEPT)
def _parsed_file(
    path: Path, resolved: Path, mtime_ns: int, size: int
) -> dict[str, dict[str, Any]]:
    """Parse a parameter file once per (file, modification time, size); see the caller."""
    try:
        document = _read_document(path)
    except yaml.YAMLError as error:
        raise ParameterError(f"parameter file '{path}': invalid YAML: {error}") from None
    except UnicodeDecodeError as error:
        raise ParameterError(
            f"parameter file '{path}': expected UTF-8 text, got byte "
            f'0x{error.object[error.start]:02x} at offset {error.start}'
        ) from None
    except OSError as error:
        raise ParameterError(
            f"parameter file '{path}': cannot read it: {error.strerror}"
        ) from None
    except RecursionError:
        raise ParameterError(f"parameter file '{path}': invalid YAML: nested too deeply") from None
    if not isinstance(document, dict) or not document:
        raise ParameterError(
            f"parameter file '{path}': expected a mapping of node names to "
            f"'{ROS_PARAMETERS_KEY}', got {type(document).__name__}"
        )
    nodes: dict[str, dict[str, Any]] = {}
    _collect_nodes(document, '', path, nodes)
    return nodes


def _read_document(path: Path) -> Any:
    """Parse a YAML file as rcl does (:class:`_RosYamlLoader`)."""
    with path.open(encoding='utf-8') as stream:
        return yaml.load(stream, Loader=_RosYamlLoader)


def _collect_nodes(
    mapping: dict[Any, Any], prefix: str, path: Path, nodes: dict[str, dict[str, Any]]
) -> None:
    for key, section in mapping.items():
        if not isinstance(key, str):
            raise ParameterError(f"parameter file '{path}': expected a node name, got {key!r}")
        if key == ROS_PARAMETERS_KEY:
            raise ParameterError(
                f"parameter file '{path}': '{ROS_PARAMETERS_KEY}' must sit under a node name"
            )
        node = prefix + '/' + key.strip('/')
        if not isinstance(section, dict) or not section:
            raise ParameterError(
                f"parameter file '{path}': node '{node}': expected a mapping with "
                f"'{ROS_PARAMETERS_KEY}', got {section!r}"
            )
        for sub_key, sub_section in section.items():
            if sub_key == ROS_PARAMETERS_KEY:
                if not isinstance(sub_section, dict):
                    raise ParameterError(
                        f"parameter file '{path}': node '{node}': expected '{ROS_PARAMETERS_KEY}' "
                        f'to be a mapping of parameter names to values, got {sub_section!r}'
                    )
                flat = _flatten(sub_section, '', f"parameter file '{path}': node '{node}'")
                nodes.setdefault(node, {}).update(flat)
            else:
                # A nested namespace: "ns: {node: {ros__parameters: ...}}" is "/ns/node".
                _collect_nodes({sub_key: sub_section}, node, path, nodes)


def flatten_parameters(params: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Flatten nested parameter mappings to dotted ROS names (``{"a": {"b": 1}}``: ``a.b``).

    Lenient, for configs built in Python; files go through :func:`load_parameter_file`,
    which also rejects empty sections and repeated names.
    """
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            flat.update(flatten_parameters(value, prefix=f'{name}.'))
        else:
            flat[name] = value
    return flat


def _flatten(parameters: dict[Any, Any], prefix: str, where: str) -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in parameters.items():
        if not isinstance(key, str) or not key:
            raise ParameterError(f'{where}: expected a parameter name, got {key!r}')
        name = prefix + key
        if isinstance(value, dict):
            if not value:
                raise ParameterError(f"{where}: parameter '{name}': expected a value, got {{}}")
            nested = _flatten(value, name + '.', where)
        elif value is None:
            raise ParameterError(f"{where}: parameter '{name}': expected a value, got nothing")
        else:
            nested = {name: value}
        for nested_name, nested_value in nested.items():
            if nested_name in flat:
                raise ParameterError(f"{where}: parameter '{nested_name}' is given twice")
            flat[nested_name] = nested_value
    return flat


def _fully_qualified(node_name: str, namespace: str = '/') -> str:
    if node_name.startswith('/'):
        return node_name
    return namespace.rstrip('/') + '/' + node_name


def _node_pattern(key: str) -> re.Pattern[str]:
    """Compile a file's node key to a regex over fully qualified node names.

    As rclpy does: ``/*`` matches one name token (word characters), ``/**`` any number.
    """
    return re.compile(re.escape(key).replace(r'/\*\*', r'(/\w+)*').replace(r'/\*', r'(/\w+)'))


def parameters_for_node(
    file_parameters: Mapping[str, Mapping[str, Any]], node_name: str, namespace: str = '/'
) -> dict[str, Any]:
    """Return the parameters a node receives from a file.

    Every section whose node key matches the node (``/**``, other wildcards, its own name)
    applies in file order, later values replacing earlier ones: this is what rclpy does.
    With ``/**`` first, as in this package's files, the node's own section wins.

    Args:
        file_parameters: The result of :func:`load_parameter_file`.
        node_name: ``"hand_sim_node"`` or fully qualified ``"/arm/hand_sim_node"``.
        namespace: The node's namespace when ``node_name`` is relative.

    Returns:
        ``{dotted parameter name: value}``.
    """
    target = _fully_qualified(node_name, namespace)
    merged: dict[str, Any] = {}
    for key, section in file_parameters.items():
        if _node_pattern(_fully_qualified(key)).fullmatch(target):
            merged.update(section)
    return merged


#: Largest edit distance at which a node name counts as a misspelling of a known one.
MISSPELLING_EDITS = 2


def misspelt_node_sections(
    file_parameters: Mapping[str, Mapping[str, Any]], node_names: Iterable[str]
) -> list[str]:
    """Find the sections of a file addressed to a misspelt ``node_names`` entry.

    A section key's node name (its last token: ``/arm/safety_filtr_node`` gives
    ``safety_filtr_node``) is misspelt when it differs from a known name by at most two
    edits (letter case ignored) and does not merely extend it, as a renamed instance does
    (``hand_sim_node_2``). Wildcards and the sections of other nodes are left alone.

    Args:
        file_parameters: The result of :func:`load_parameter_file`.
        node_names: The names the file's sections should use, e.g. the package's nodes.

    Returns:
        One message per misspelt section, with the name it was probably meant to be.
    """
    known = list(node_names)
    errors: list[str] = []
    for key in file_parameters:
        name = key.rsplit('/', 1)[-1]
        if '*' in name or name in known:
            continue
        close = [
            candidate
            for candidate in known
            if not (len(name) > len(candidate) and name.lower().startswith(candidate.lower()))
            and _edit_distance(name.lower(), candidate.lower()) <= MISSPELLING_EDITS
        ]
        if close:
            closest = min(close, key=lambda known: _edit_distance(name.lower(), known.lower()))
            errors.append(
                f"section '{key}' addresses no node of this package (did you mean '{closest}'?)"
            )
    return errors


def _edit_distance(first: str, second: str) -> int:
    """Return the optimal-string-alignment distance (a swap of neighbours is one edit)."""
    rows = [list(range(len(second) + 1))]
    for i in range(1, len(first) + 1):
        row = [i] * (len(second) + 1)
        for j in range(1, len(second) + 1):
            row[j] = min(
                rows[i - 1][j] + 1,
                row[j - 1] + 1,
                rows[i - 1][j - 1] + (first[i - 1] != second[j - 1]),
            )
            swapped = first[i - 1] == second[j - 2] and first[i - 2] == second[j - 1]
            if i > 1 and j > 1 and swapped:
                row[j] = min(row[j], rows[i - 2][j - 2] + 1)
        rows.append(row)
    return rows[-1][-1]


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------


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
                _collect(errors, builtin, value, strict_types)
            elif not name.startswith(ROS_QOS_OVERRIDES_PREFIX):
                errors.append(_unknown_message(schema, name, other_schemas))
            continue
        converted = _collect(errors, spec, value, strict_types)
        if converted is not None:
            result[name] = converted
    raise_parameter_errors(source, errors)
    return result


def _collect(errors: list[str], spec: ParameterSpec, value: Any, strict_types: bool) -> Any:
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


# --------------------------------------------------------------------------------------------
# rclpy glue (Jazzy); ROS is imported only when these are called.
# --------------------------------------------------------------------------------------------


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
                _collect(errors, spec, parameter.value, strict_types=True)
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
