"""ROS arguments read without ROS, and the start-up parameters a node computes from them."""

from __future__ import annotations

from pathlib import Path
import textwrap

import pytest

from grasp_safety_filter.io.parameters import (
    misspelt_node_sections,
    NodeSchema,
    ParameterError,
    ParameterSpec,
    ParameterType,
    parse_parameter_value,
    resolve_relative_paths,
)
from grasp_safety_filter.io.ros_arguments import (
    given_parameters,
    ParameterRule,
    parse_ros_arguments,
    remapped_fully_qualified_name,
    RemapRule,
    RosArguments,
)
from grasp_safety_filter.io.schemas import NODE_SCHEMAS, SAFETY_FILTER_NODE

T = ParameterType

SCHEMA = NodeSchema(
    'demo_node',
    (
        ParameterSpec('mass', T.DOUBLE, 1.0, 'Mass [kg]', min_value=0.0, exclusive_min=True),
        ParameterSpec('flag', T.BOOL, True, 'Flag'),
        ParameterSpec('gain.kp', T.DOUBLE, 1.0, 'Gain [-]'),
        ParameterSpec('urdf', T.STRING, 'hand.urdf', 'URDF', is_path=True),
    ),
)
OTHER = NodeSchema('other_node', (ParameterSpec('duration', T.DOUBLE, 1.0, 'Duration [s]'),))


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text), encoding='utf-8')
    return path


# --------------------------------------------------------------------------------------------
# Parsing


@pytest.mark.parametrize(
    ('arguments', 'expected'),
    [
        ([], RosArguments()),
        (['prog', '-p', 'x:=1', '--params-file', 'f.yaml'], RosArguments()),
        (
            ['prog', '--ros-args', '-p', 'x:=1', '--param', 'n:y:=[1.0, 2.0]'],
            RosArguments(
                parameter_rules=(
                    ParameterRule('x', 1, None, 'x:=1'),
                    ParameterRule('y', [1.0, 2.0], 'n', 'n:y:=[1.0, 2.0]'),
                )
            ),
        ),
        (
            ['--ros-args', '--params-file', 'a.yaml', '--', '--params-file', 'b.yaml'],
            RosArguments(params_files=('a.yaml',)),
        ),
        (
            '--ros-args --params-file a.yaml -- x --ros-args --params-file b.yaml'.split(),
            RosArguments(params_files=('a.yaml', 'b.yaml')),
        ),
        (
            # Flags of logging and security are skipped with their values, not read as rules.
            (
                '--ros-args --log-level debug -p a:=1 --log-level n:=info --enable-rosout-logs '
                '-e /enclave --log-file-name f -p b:=2'
            ).split(),
            RosArguments(
                parameter_rules=(
                    ParameterRule('a', 1, None, 'a:=1'),
                    ParameterRule('b', 2, None, 'b:=2'),
                )
            ),
        ),
        (
            (
                '--ros-args -r __node:=renamed --remap n:__ns:=/arm -r /a:=/b -r rostopic://c:=d'
            ).split(),
            RosArguments(
                remap_rules=(
                    RemapRule('__node', 'renamed'),
                    RemapRule('__ns', '/arm', 'n'),
                    RemapRule('/a', '/b'),
                    RemapRule('rostopic://c', 'd'),
                )
            ),
        ),
        # rcl's deprecated bare remap rule outside a --ros-args section.
        (['prog', '__node:=old'], RosArguments(remap_rules=(RemapRule('__node', 'old'),))),
        (
            ['--ros-args', '-p', 'ratio:=1:2', '-p', 'path:=a/b.urdf', '-p', 's:="3"'],
            RosArguments(
                parameter_rules=(
                    ParameterRule('ratio', '1:2', None, 'ratio:=1:2'),
                    ParameterRule('path', 'a/b.urdf', None, 'path:=a/b.urdf'),
                    ParameterRule('s', '3', None, 's:="3"'),
                )
            ),
        ),
    ],
)
def test_parse_ros_arguments(arguments, expected):
    assert parse_ros_arguments(arguments) == expected


@pytest.mark.parametrize(
    ('arguments', 'message'),
    [
        (['--ros-args', '-p'], "ROS argument '-p': expected a value after it"),
        (['--ros-args', '--params-file'], "ROS argument '--params-file': expected a value"),
        (['--ros-args', '-p', 'x'], "'-p x': expected name:=value or node_name:name:=value"),
        (['--ros-args', '-p', ':=1'], "'-p :=1': expected name:=value"),
        (['--ros-args', '-p', 'x:='], "'-p x:=': expected a value or a list of values"),
        (['--ros-args', '-p', 'x:={a: 1}'], "'-p x:={a: 1}': expected a value or a list"),
        (['--ros-args', '-p', 'x:=[1'], "'-p x:=[1': expected a YAML value"),
        (['--ros-args', '-p', 'n-1:x:=1'], "'-p n-1:x:=1': expected name:=value"),
    ],
)
def test_malformed_ros_arguments_are_refused(arguments, message):
    with pytest.raises(ParameterError) as caught:
        parse_ros_arguments(arguments)
    assert message in str(caught.value)


@pytest.mark.parametrize(
    ('text', 'value'),
    [
        ('true', True),
        ('false', False),
        ('3', 3),
        ('3.0', 3.0),
        ('1e-3', 1e-3),
        ('-2.5', -2.5),
        ('[0.1, 0.2]', [0.1, 0.2]),
        ('[a, b]', ['a', 'b']),
        ('"3"', '3'),
        ('hand.urdf', 'hand.urdf'),
        # rcl keeps these as the text written.
        ('null', 'null'),
        ('~', '~'),
        ('2024-01-01', '2024-01-01'),
    ],
)
def test_parameter_values_are_typed_as_yaml(text, value):
    parsed = parse_parameter_value(text)
    assert parsed == value
    assert type(parsed) is type(value)


# --------------------------------------------------------------------------------------------
# The node's name after remapping (checked against rcl itself in test_node_startup.py)


@pytest.mark.parametrize(
    ('process', 'own', 'namespace', 'expected'),
    [
        ([], [], None, '/demo_node'),
        ([], [], 'arm', '/arm/demo_node'),
        ([], ['--ros-args', '-r', '__node:=a', '-r', '__node:=b'], None, '/a'),
        ([], ['--ros-args', '-r', '__name:=a'], None, '/a'),
        (['--ros-args', '-r', '__node:=g'], ['--ros-args', '-r', '__node:=own'], None, '/own'),
        (['--ros-args', '-r', '__node:=g'], [], None, '/g'),
        ([], ['--ros-args', '-r', 'demo_node:__node:=x'], None, '/x'),
        ([], ['--ros-args', '-r', 'other_node:__node:=x'], None, '/demo_node'),
        ([], ['--ros-args', '-r', '__ns:=/left'], '/kw', '/left/demo_node'),
        ([], ['--ros-args', '-r', '__ns:=relative'], None, '/demo_node'),
        ([], ['--ros-args', '-r', '__ns:=/a/b', '-r', '__node:=c'], None, '/a/b/c'),
        ([], ['__node:=old'], None, '/old'),
    ],
)
def test_remapped_fully_qualified_name(process, own, namespace, expected):
    argument_sets = [parse_ros_arguments(process), parse_ros_arguments(own)]
    assert remapped_fully_qualified_name('demo_node', namespace, argument_sets) == expected


# --------------------------------------------------------------------------------------------
# Precedence


def given(tmp_path: Path, *argument_lists: list[str], name: str = '/demo_node') -> dict:
    sets = [parse_ros_arguments(arguments) for arguments in argument_lists]
    return given_parameters(
        SCHEMA,
        name,
        sets,
        other_schemas=[OTHER],
        node_names=['demo_node', 'other_node'],
        working_directory=tmp_path,
    )


@pytest.fixture
def base_file(tmp_path):
    # The node's own section says mass 2.0, as paper_scenario.yaml says enabled: true.
    return write(
        tmp_path / 'base.yaml',
        """
        /**:
          ros__parameters: {urdf: hand.urdf, gain: {kp: 3.0}}
        demo_node:
          ros__parameters: {mass: 2.0, flag: true}
        """,
    )


def files(*paths: Path) -> list[str]:
    return [argument for path in paths for argument in ('--params-file', str(path))]


def values(result: dict) -> dict:
    return {name: parameter.value for name, parameter in result.items()}


def test_file_values_with_the_node_section_after_the_wildcard(tmp_path, base_file):
    result = given(tmp_path, ['--ros-args', '--params-file', str(base_file)])
    assert values(result) == {'urdf': 'hand.urdf', 'gain.kp': 3.0, 'mass': 2.0, 'flag': True}
    assert {p.source for p in result.values()} == {f"parameter file '{base_file}'"}
    assert {p.directory for p in result.values()} == {base_file.parent}


def test_a_command_line_parameter_beats_the_files_node_section(tmp_path, base_file):
    result = given(tmp_path, ['--ros-args', '-p', 'mass:=4.0', '--params-file', str(base_file)])
    assert values(result)['mass'] == 4.0
    assert result['mass'].source == "ROS argument '-p mass:=4.0'"
    assert values(result)['flag'] is True


def test_a_later_file_beats_an_earlier_one_even_its_wildcard(tmp_path, base_file):
    # launch_ros writes a Node's dict parameters under /** to a file after the config file.
    launch_file = write(tmp_path / 'launch' / 'p.yaml', '/**:\n  ros__parameters: {mass: 5.0}\n')
    later = given(tmp_path, ['--ros-args', *files(base_file, launch_file)])
    assert values(later)['mass'] == 5.0
    assert later['mass'].directory == launch_file.parent
    assert values(later)['flag'] is True
    earlier = given(tmp_path, ['--ros-args', *files(launch_file, base_file)])
    assert values(earlier)['mass'] == 2.0


def test_within_a_file_sections_apply_in_file_order_as_in_rcl(tmp_path):
    path = write(
        tmp_path / 'p.yaml',
        """
        demo_node:
          ros__parameters: {mass: 2.0}
        /**:
          ros__parameters: {mass: 1.5}
        """,
    )
    assert values(given(tmp_path, ['--ros-args', '--params-file', str(path)])) == {'mass': 1.5}


def test_the_nodes_own_arguments_follow_the_process_arguments(tmp_path, base_file):
    other = write(tmp_path / 'other.yaml', 'demo_node:\n  ros__parameters: {mass: 7.0}\n')
    result = given(
        tmp_path,
        ['--ros-args', '-p', 'flag:=false', '--params-file', str(other)],
        ['--ros-args', '--params-file', str(base_file), '-p', 'gain.kp:=9.0'],
    )
    # Files: the process's first, then the node's; every -p after every file.
    assert values(result) == {'mass': 2.0, 'flag': False, 'urdf': 'hand.urdf', 'gain.kp': 9.0}


def test_node_targeted_rules_apply_to_their_node_only(tmp_path):
    arguments = ['--ros-args', '-p', 'demo_node:mass:=3.0', '-p', 'other_node:duration:=2.0']
    assert values(given(tmp_path, arguments)) == {'mass': 3.0}
    assert values(given(tmp_path, arguments, name='/renamed')) == {}


def test_a_section_for_a_renamed_node(tmp_path, base_file):
    path = write(tmp_path / 'p.yaml', 'left_hand:\n  ros__parameters: {mass: 6.0}\n')
    result = given(
        tmp_path,
        ['--ros-args', '--params-file', str(base_file), '--params-file', str(path)],
        name='/left_hand',
    )
    assert values(result) == {'urdf': 'hand.urdf', 'gain.kp': 3.0, 'mass': 6.0}


def test_relative_paths_resolve_against_their_own_source(tmp_path, base_file):
    config_directory = tmp_path / 'config'
    defaults_only = given(tmp_path)
    from_file = given(tmp_path, ['--ros-args', '--params-file', str(base_file)])
    from_rule = given(
        tmp_path, ['--ros-args', '--params-file', str(base_file), '-p', 'urdf:=cwd/h.urdf']
    )

    def resolved(result: dict) -> str:
        directories = {name: parameter.directory for name, parameter in result.items()}
        values_ = {**SCHEMA.defaults(), **values(result)}
        return resolve_relative_paths(SCHEMA, values_, config_directory, directories)['urdf']

    assert resolved(defaults_only) == str(config_directory / 'hand.urdf')
    assert resolved(from_file) == str(base_file.parent / 'hand.urdf')
    assert resolved(from_rule) == str(tmp_path / 'cwd' / 'h.urdf')


# --------------------------------------------------------------------------------------------
# Refusals


@pytest.mark.parametrize(
    ('text', 'message'),
    [
        (
            'demo_node:\n  ros__parameters: {mas: 2.0}\n',
            "parameter file '{path}' (node 'demo_node'): unknown parameter 'mas': node "
            "'demo_node' does not declare it (did you mean 'mass'?)",
        ),
        (
            '/**:\n  ros__parameters: {gain: {kq: 2.0}}\n',
            "(node 'demo_node'): unknown parameter 'gain.kq': node 'demo_node' does not declare "
            "it (did you mean 'gain.kp'?)",
        ),
        (
            # As the ROS-free loader: a name of another node under /** is refused.
            '/**:\n  ros__parameters: {duration: 2.0}\n',
            "unknown parameter 'duration': node 'demo_node' does not declare it (it is a "
            'parameter of other_node)',
        ),
        (
            'demo_nod:\n  ros__parameters: {mass: 2.0}\n',
            "parameter file '{path}': section '/demo_nod' addresses no node of this package "
            "(did you mean 'demo_node'?)",
        ),
        (
            '/arm/Other_Node:\n  ros__parameters: {duration: 2.0}\n',
            "section '/arm/Other_Node' addresses no node of this package (did you mean "
            "'other_node'?)",
        ),
        (
            'demo_node:\n  ros__parameters: {mass: 1}\n',
            "parameter 'mass': expected a double (ROS reads 1 as an integer; write 1.0)",
        ),
    ],
)
def test_files_with_unknown_names_or_misspelt_sections_are_refused(tmp_path, text, message):
    path = write(tmp_path / 'bad.yaml', text)
    with pytest.raises(ParameterError) as caught:
        given(tmp_path, ['--ros-args', '--params-file', str(path)])
    assert message.format(path=path) in str(caught.value)


@pytest.mark.parametrize(
    ('rule', 'message'),
    [
        ('mas:=2.0', "unknown parameter 'mas': node 'demo_node' does not declare it (did you"),
        ('duration:=2.0', '(it is a parameter of other_node)'),
        ('mass:=-1.0', "parameter 'mass': expected > 0.0, got -1.0"),
        ('demo_node:flag:=3', "parameter 'flag': expected a bool, got 3"),
    ],
)
def test_command_line_rules_with_unknown_names_or_bad_values_are_refused(tmp_path, rule, message):
    with pytest.raises(ParameterError) as caught:
        given(tmp_path, ['--ros-args', '-p', rule])
    assert f"ROS argument '-p {rule}' (node 'demo_node'): " in str(caught.value)
    assert message in str(caught.value)


def test_sections_of_other_systems_and_renamed_instances_are_allowed(tmp_path):
    sections = {
        key: {}
        for key in (
            '/**',
            '/*/demo_node',
            '/demo_node',
            '/arm/demo_node',
            '/demo_node_2',
            '/robot_state_publisher',
            '/arm_controller',
            '/camera_driver',
        )
    }
    assert misspelt_node_sections(sections, ['demo_node', 'other_node']) == []


def test_the_packages_files_have_no_misspelt_sections(tmp_path):
    config = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
    result = given_parameters(
        NODE_SCHEMAS[SAFETY_FILTER_NODE],
        '/safety_filter_node',
        [
            parse_ros_arguments(
                ['--ros-args', '--params-file', str(config), '-p', 'enabled:=false']
            )
        ],
        other_schemas=[s for n, s in NODE_SCHEMAS.items() if n != SAFETY_FILTER_NODE],
        node_names=NODE_SCHEMAS,
    )
    assert result['enabled'].value is False
    assert result['model.urdf_file'].directory == config.parent
