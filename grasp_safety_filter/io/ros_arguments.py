"""A node's ROS 2 command-line arguments, read without ROS, and the parameters they give.

rcl reads the ``--ros-args ... [--]`` sections of the process's arguments (those given to
``rclpy.init``) and of a node's own ``cli_args``: remap rules (``-r``), parameter files
(``--params-file``) and parameter rules (``-p``). It stores ``-p name:=value`` under
``/**``, so a node's own section in a file beats it: ``-p enabled:=false`` would not turn
off a filter whose file says ``enabled: true``. The package's nodes compute their start-up
parameters here instead, each later step beating the earlier ones:

1. the schema's defaults;
2. each parameter file in command-line order (the process's, then the node's own), a later
   file beating an earlier one; within one file the sections that address the node
   (``/**``, other wildcards, its own name) apply in file order, as in rcl and
   :func:`~grasp_safety_filter.io.parameters.parameters_for_node`;
3. each ``-p`` in command-line order, beating every file: ``-p name:=value`` for every
   node, ``-p node_name:name:=value`` for the node called ``node_name``.

launch_ros writes a Node's dict parameters to a temporary file placed after its other
files, so launch arguments beat the config file too.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
import re
from typing import Any

from grasp_safety_filter.io.parameters import (
    load_parameter_file,
    misspelt_node_sections,
    NodeSchema,
    ParameterError,
    parameters_for_node,
    parse_parameter_value,
    raise_parameter_errors,
    validate_parameters,
)

#: Open and close a section of ROS arguments.
ROS_ARGS_FLAG = '--ros-args'
ROS_ARGS_END = '--'

REMAP_FLAGS = ('-r', '--remap')
PARAMETER_FLAGS = ('-p', '--param')
PARAMS_FILE_FLAG = '--params-file'

#: rcl flags whose value concerns logging or security, not names or parameters.
OTHER_FLAGS_WITH_VALUE = ('--log-level', '--log-file-name', '--log-config-file', '-e', '--enclave')

#: Every flag followed by a value.
FLAGS_WITH_VALUE = (*REMAP_FLAGS, *PARAMETER_FLAGS, PARAMS_FILE_FLAG, *OTHER_FLAGS_WITH_VALUE)

#: Remap sources that rename the node and set its namespace (``__name`` is an alias).
NODE_NAME_SOURCES = ('__node', '__name')
NAMESPACE_SOURCE = '__ns'
_BARE_REMAP_SOURCES = (*NODE_NAME_SOURCES, NAMESPACE_SOURCE)

#: The node-name prefix of a rule (``node_name:rest``); not ``rostopic://``.
_NODE_PREFIX = re.compile(r'^(?P<node>[^:/]+):(?!//)(?P<rest>.*)$', re.DOTALL)

#: A valid node name token, the only node prefix rcl accepts in a ``-p`` rule.
_NODE_NAME = re.compile(r'^[A-Za-z_][A-Za-z0-9_]*$')


@dataclass(frozen=True)
class ParameterRule:
    """One ``-p [node_name:]name:=value`` rule (node None: every node; value YAML-typed)."""

    name: str
    value: Any
    node: str | None = None
    text: str = ''

    def applies_to(self, fully_qualified_name: str) -> bool:
        """Whether the rule sets the node's parameter (rcl: ``node_name`` in the root)."""
        return self.node is None or '/' + self.node == fully_qualified_name


@dataclass(frozen=True)
class RemapRule:
    """One ``-r [node_name:]source:=target`` rule."""

    source: str
    target: str
    node: str | None = None


@dataclass(frozen=True)
class RosArguments:
    """What one argument list holds for names and parameters, in command-line order.

    ``remap_rules`` also holds rcl's deprecated bare ``__node:=name`` outside the sections.
    """

    params_files: tuple[str, ...] = ()
    parameter_rules: tuple[ParameterRule, ...] = ()
    remap_rules: tuple[RemapRule, ...] = ()


@dataclass(frozen=True)
class GivenParameter:
    """A parameter value the arguments give a node (as given, YAML-typed), and its source.

    ``source``: ``"parameter file 'x.yaml'"``, ``"-p 'enabled:=false'"``...; ``directory``:
    where a relative path value resolves (the file's, or the current one for a ``-p``).
    """

    value: Any
    source: str
    directory: Path


def parse_ros_arguments(arguments: Sequence[str]) -> RosArguments:
    """Read the ROS sections of an argument list as rcl does.

    Tokens outside ``--ros-args ... [--]`` are the program's own, except rcl's deprecated
    bare remap rules of the node's name and namespace (``__node:=name``). Flags that concern
    neither names nor parameters (``--log-level LEVEL``, ``--enable-rosout-logs``...) are
    skipped with their value.

    Raises:
        ParameterError: A flag lacks its value, or a ``-p`` rule is not
            ``[node_name:]name:=value``.
    """
    params_files: list[str] = []
    parameter_rules: list[ParameterRule] = []
    remap_rules: list[RemapRule] = []
    tokens: Iterator[str] = iter(arguments)
    in_section = False
    for token in tokens:
        if not in_section:
            if token == ROS_ARGS_FLAG:
                in_section = True
            elif ':=' in token and _remap_rule(token).source in _BARE_REMAP_SOURCES:
                remap_rules.append(_remap_rule(token))  # rcl's deprecated bare rule
            continue
        if token == ROS_ARGS_END:
            in_section = False
            continue
        if token not in FLAGS_WITH_VALUE:
            continue  # --ros-args again, a flag without a value, or one rcl will refuse
        value = next(tokens, None)
        if value is None:
            raise ParameterError(f"ROS argument '{token}': expected a value after it, got none")
        if token in REMAP_FLAGS:
            remap_rules.append(_remap_rule(value))
        elif token in PARAMETER_FLAGS:
            parameter_rules.append(_parameter_rule(value))
        elif token == PARAMS_FILE_FLAG:
            params_files.append(value)
    return RosArguments(tuple(params_files), tuple(parameter_rules), tuple(remap_rules))


def _split_node_prefix(text: str) -> tuple[str | None, str]:
    match = _NODE_PREFIX.match(text)
    return (match['node'], match['rest']) if match else (None, text)


def _remap_rule(text: str) -> RemapRule:
    left, _, target = text.partition(':=')
    node, source = _split_node_prefix(left)
    return RemapRule(source, target, node)


def _parameter_rule(text: str) -> ParameterRule:
    left, separator, value_text = text.partition(':=')
    node, name = _split_node_prefix(left)
    if not separator or not name or (node is not None and not _NODE_NAME.match(node)):
        raise ParameterError(
            f"ROS argument '-p {text}': expected name:=value or node_name:name:=value"
        )
    try:
        value = parse_parameter_value(value_text)
    except ParameterError as error:
        raise ParameterError(f"ROS argument '-p {text}': {error}") from None
    return ParameterRule(name, value, node, text)


def remapped_fully_qualified_name(
    node_name: str, namespace: str | None, argument_sets: Sequence[RosArguments]
) -> str:
    """Return the node's fully qualified name after its ``__node`` and ``__ns`` rules.

    As rcl: the first matching rule of the node's own arguments wins, then the first of the
    process's; a rule with a node prefix addresses the name the node was created with; a
    relative ``__ns`` is ignored.

    ``namespace``: the node's namespace argument ('' or None: the root); ``argument_sets``:
    the process's arguments, then the node's own.
    """
    rules = [
        rule
        for arguments in reversed(argument_sets)
        for rule in arguments.remap_rules
        if rule.node is None or rule.node == node_name
    ]
    name = next((r.target for r in rules if r.source in NODE_NAME_SOURCES), node_name)
    namespace = next(
        (r.target for r in rules if r.source == NAMESPACE_SOURCE and r.target.startswith('/')),
        '/' + (namespace or '').lstrip('/'),
    )
    return namespace.rstrip('/') + '/' + name


def given_parameters(
    schema: NodeSchema,
    fully_qualified_name: str,
    argument_sets: Sequence[RosArguments],
    *,
    other_schemas: Iterable[NodeSchema] = (),
    node_names: Iterable[str] = (),
    working_directory: Path | None = None,
) -> dict[str, GivenParameter]:
    """Return the parameters the arguments give a node, with the precedence of the module.

    Each file's sections for the node and each ``-p`` rule are validated against the
    schema as they are read, so that a message names the file or rule at fault.

    ``fully_qualified_name`` is the node's after remapping; ``argument_sets`` the process's
    arguments, then the node's own; ``other_schemas`` tell where an unknown name belongs;
    a file section whose name is close to one of ``node_names`` is refused as misspelt.
    Returns every name the arguments set (schema parameters and ROS's own); the defaults
    are left to the schema.

    Raises:
        ParameterError: A file is unreadable, has a misspelt section, or gives the node an
            unknown or invalid parameter, or a ``-p`` rule does; the message names it.
    """
    others = list(other_schemas)
    known_names = [*node_names, fully_qualified_name.rsplit('/', 1)[-1]]
    label = fully_qualified_name.removeprefix('/')
    given: dict[str, GivenParameter] = {}
    for path in (path for arguments in argument_sets for path in arguments.params_files):
        file_parameters = load_parameter_file(path)
        source = f"parameter file '{path}'"
        raise_parameter_errors(source, misspelt_node_sections(file_parameters, known_names))
        values = parameters_for_node(file_parameters, fully_qualified_name)
        validate_parameters(schema, values, f"{source} (node '{label}')", other_schemas=others)
        directory = Path(path).resolve().parent
        given.update({name: GivenParameter(v, source, directory) for name, v in values.items()})
    directory = Path.cwd() if working_directory is None else working_directory
    for arguments in argument_sets:
        for rule in arguments.parameter_rules:
            if not rule.applies_to(fully_qualified_name):
                continue
            source = f"ROS argument '-p {rule.text}'"
            validate_parameters(
                schema, {rule.name: rule.value}, f"{source} (node '{label}')", other_schemas=others
            )
            given[rule.name] = GivenParameter(rule.value, source, directory)
    return given
