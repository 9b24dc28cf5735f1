"""Reading ROS 2 parameter files: YAML 1.2 numbers, node sections and wildcards, parsed once."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
import functools
from pathlib import Path
import re
from typing import Any

import yaml

from grasp_safety_filter.io.parameters.spec import ParameterError, ROS_PARAMETERS_KEY


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
