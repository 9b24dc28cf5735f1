"""Parameter specs, parameter files and the rclpy glue (against stand-ins of the Jazzy API)."""

from __future__ import annotations

import array
import math
from pathlib import Path
import sys
import textwrap
import types
from typing import ClassVar

import pytest
import yaml

from grasp_safety_filter.io.parameters import (
    declare_node_parameters,
    load_parameter_file,
    make_parameter_descriptor,
    NodeSchema,
    on_set_parameters_callback,
    ParameterError,
    parameters_for_node,
    ParameterSpec,
    ParameterType,
    resolve_relative_paths,
    validate_parameters,
)
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.readme_tables import parameter_table_markdown
from grasp_safety_filter.io.schemas import (
    check_hand_sim_parameters,
    check_model_parameters,
    HAND_SIM_NODE,
    load_node_parameters,
    NODE_SCHEMAS,
    NOMINAL_CONTROLLER_NODE,
    REQUIRED_MODEL_PARAMETERS,
    SAFETY_FILTER_NODE,
)

T = ParameterType

MASS = ParameterSpec('mass', T.DOUBLE, 1.0, 'Mass [kg]', min_value=0.0, exclusive_min=True)
ANGLE = ParameterSpec('angle', T.DOUBLE, 0.0, 'Angle [rad]', min_value=-1.5, max_value=1.5)
FACES = ParameterSpec('faces', T.INTEGER, 8, 'Faces [-]', min_value=3)
KIND = ParameterSpec('kind', T.STRING, 'cubic', 'Kind', choices=('cubic', 'linear'))
FLAG = ParameterSpec('flag', T.BOOL, True, 'Flag')
GRAVITY = ParameterSpec('gravity', T.DOUBLE_ARRAY, [0.0, 0.0, -9.81], 'g [m/s^2]', length=3)
QUAT = ParameterSpec(
    'quat', T.DOUBLE_ARRAY, [0.0, 0.0, 0.0, 1.0], 'q', length=4, min_value=-1.0, max_value=1.0
)
NAMES = ParameterSpec('names', T.STRING_ARRAY, ['a'], 'Names', choices=('a', 'b'))
URDF = ParameterSpec('urdf', T.STRING, 'hand.urdf', 'URDF', is_path=True)

SCHEMA = NodeSchema('demo_node', (MASS, ANGLE, FACES, KIND, FLAG, GRAVITY, QUAT, NAMES, URDF))


# --------------------------------------------------------------------------------------------
# ParameterSpec
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ('spec', 'value', 'expected'),
    [
        (MASS, 2, 2.0),
        (MASS, 0.5, 0.5),
        (ANGLE, -1.5, -1.5),
        (FACES, 3, 3),
        (KIND, 'linear', 'linear'),
        (FLAG, False, False),
        (GRAVITY, (0, 0, -9.81), [0.0, 0.0, -9.81]),
        (GRAVITY, array.array('d', [1.0, 2.0, 3.0]), [1.0, 2.0, 3.0]),
        (NAMES, ['b', 'a'], ['b', 'a']),
    ],
)
def test_spec_accepts_and_converts(spec, value, expected):
    converted = spec.validate(value)
    assert converted == expected
    assert type(converted) is type(expected)


@pytest.mark.parametrize(
    ('spec', 'value', 'message'),
    [
        (MASS, 'heavy', "parameter 'mass': expected a double, got 'heavy'"),
        (MASS, True, "parameter 'mass': expected a double, got True"),
        (MASS, 0.0, "parameter 'mass': expected > 0.0, got 0.0"),
        (MASS, -1.0, "parameter 'mass': expected > 0.0, got -1.0"),
        (MASS, math.nan, "parameter 'mass': expected a finite number, got nan"),
        (MASS, math.inf, "parameter 'mass': expected a finite number, got inf"),
        (ANGLE, 1.6, "parameter 'angle': expected <= 1.5, got 1.6"),
        (ANGLE, -1.6, "parameter 'angle': expected >= -1.5, got -1.6"),
        (FACES, 8.0, "parameter 'faces': expected an integer, got 8.0"),
        (FACES, 2, "parameter 'faces': expected >= 3, got 2"),
        (
            KIND,
            'quadratic',
            "parameter 'kind': expected one of ['cubic', 'linear'], got 'quadratic'",
        ),
        (KIND, 3, "parameter 'kind': expected a string, got 3"),
        (FLAG, 1, "parameter 'flag': expected a bool, got 1"),
        (FLAG, 'true', "parameter 'flag': expected a bool, got 'true'"),
        (GRAVITY, [0.0, -9.81], "parameter 'gravity': expected 3 elements, got 2"),
        (GRAVITY, 9.81, "parameter 'gravity': expected a double_array, got float 9.81"),
        (GRAVITY, '0 0 -9.81', "parameter 'gravity': expected a double_array, got str"),
        (GRAVITY, [0.0, 'x', 1.0], "parameter 'gravity' element 1: expected a double, got 'x'"),
        (QUAT, [0.0, 0.0, 2.0, 1.0], "parameter 'quat' element 2: expected <= 1.0, got 2.0"),
        (NAMES, ['a', 'c'], "parameter 'names' element 1: expected one of ['a', 'b'], got 'c'"),
    ],
)
def test_spec_rejects_with_message(spec, value, message):
    with pytest.raises(ParameterError) as caught:
        spec.validate(value)
    assert message in str(caught.value)


@pytest.mark.parametrize(
    ('spec', 'text'),
    [
        (MASS, '> 0'),
        (ANGLE, 'in [-1.5, 1.5]'),
        (FACES, '>= 3'),
        (KIND, 'one of cubic, linear'),
        (FLAG, ''),
        (GRAVITY, '3 elements'),
        (QUAT, '4 elements, each in [-1, 1]'),
    ],
)
def test_constraint_text(spec, text):
    assert spec.constraint_text() == text


# --------------------------------------------------------------------------------------------
# NodeSchema
# --------------------------------------------------------------------------------------------


def test_schema_lookup_and_defaults():
    assert SCHEMA['faces'] is FACES
    assert 'faces' in SCHEMA and 'nope' not in SCHEMA
    assert SCHEMA.get('nope') is None
    assert SCHEMA.names[:2] == ('mass', 'angle')
    assert len(SCHEMA) == 9
    assert SCHEMA.defaults()['gravity'] == [0.0, 0.0, -9.81]
    with pytest.raises(
        KeyError, match="declares no parameter 'face' \\(did you mean 'faces'\\?\\)"
    ):
        SCHEMA['face']


@pytest.mark.parametrize(
    ('parameters', 'message'),
    [
        ((MASS, MASS), "parameter 'mass' twice"),
        (
            (ParameterSpec('m', T.DOUBLE, -1.0, 'm', min_value=0.0),),
            "parameter 'm': expected >= 0.0, got -1.0",
        ),
        (
            (ParameterSpec('v', T.DOUBLE_ARRAY, [], 'v'),),
            "parameter 'v': expected a non-empty default for a double_array, got []",
        ),
    ],
)
def test_schema_rejects_bad_specs(parameters, message):
    with pytest.raises(ValueError, match=message.replace('[', r'\[').replace(']', r'\]')):
        NodeSchema('bad_node', parameters)


# --------------------------------------------------------------------------------------------
# validate_parameters
# --------------------------------------------------------------------------------------------


def test_validate_fills_defaults_and_converts():
    values = validate_parameters(SCHEMA, {'mass': 2.5, 'gravity': [0.0, 0.0, -1.62]})
    assert values['mass'] == 2.5
    assert values['gravity'] == [0.0, 0.0, -1.62]
    assert values['faces'] == 8  # default
    assert set(values) == set(SCHEMA.names)


def test_validate_does_not_share_default_lists():
    first = validate_parameters(SCHEMA, {})
    first['gravity'][2] = 0.0
    assert validate_parameters(SCHEMA, {})['gravity'][2] == -9.81
    assert GRAVITY.default[2] == -9.81


def test_unknown_key_suggests_closest_name():
    with pytest.raises(ParameterError) as caught:
        validate_parameters(SCHEMA, {'gravitty': [0.0, 0.0, -9.81]}, source='scene.yaml')
    assert str(caught.value) == (
        "scene.yaml: unknown parameter 'gravitty': node 'demo_node' does not declare it "
        "(did you mean 'gravity'?)"
    )


def test_unknown_key_without_close_match_has_no_suggestion():
    with pytest.raises(ParameterError) as caught:
        validate_parameters(SCHEMA, {'zzz_qqq': 1.0}, source='scene.yaml')
    assert str(caught.value).endswith("node 'demo_node' does not declare it")


def test_unknown_key_names_the_node_that_declares_it():
    hand_sim = NODE_SCHEMAS[HAND_SIM_NODE]
    others = [NODE_SCHEMAS[NOMINAL_CONTROLLER_NODE], NODE_SCHEMAS[SAFETY_FILTER_NODE]]
    with pytest.raises(ParameterError, match='it is a parameter of nominal_controller_node'):
        validate_parameters(hand_sim, {'gains.kp': 1.0}, other_schemas=others)


@pytest.mark.parametrize(
    ('values', 'message'),
    [
        (
            {'mass': 1},
            "parameter 'mass': expected a double (ROS reads 1 as an integer; write 1.0)",
        ),
        (
            {'gravity': [0, 0, -9.81]},
            "parameter 'gravity': expected a double_array (ROS reads an element without a "
            'decimal point as an integer; write [0.0, 0.0, -9.81]), got [0, 0, -9.81]',
        ),
    ],
)
def test_integers_where_ros_declares_doubles(values, message):
    with pytest.raises(ParameterError) as caught:
        validate_parameters(SCHEMA, values)
    assert message in str(caught.value)
    # Non-strict mode (values from Python, not from a ROS parameter file) converts.
    assert validate_parameters(SCHEMA, values, strict_types=False)[next(iter(values))]


def test_all_errors_collected_in_one_message():
    with pytest.raises(ParameterError) as caught:
        validate_parameters(
            SCHEMA,
            {'mass': -1.0, 'gravity': [0.0], 'kind': 'cubicc', 'flagg': True},
            source="parameter file 'scene.yaml' (node 'demo_node')",
        )
    message = str(caught.value)
    assert message.startswith(
        "parameter file 'scene.yaml' (node 'demo_node'): 4 invalid parameters:"
    )
    assert len(caught.value.errors) == 4
    for fragment in (
        "parameter 'mass': expected > 0.0, got -1.0",
        "parameter 'gravity': expected 3 elements, got 1",
        "parameter 'kind': expected one of ['cubic', 'linear'], got 'cubicc'",
        "unknown parameter 'flagg'",
        "(did you mean 'flag'?)",
    ):
        assert fragment in message


def test_ros_builtin_parameters_are_checked_and_dropped():
    values = validate_parameters(
        SCHEMA, {'use_sim_time': True, 'qos_overrides./clock.publisher.depth': 10}
    )
    assert 'use_sim_time' not in values
    assert not any(name.startswith('qos_overrides') for name in values)
    with pytest.raises(ParameterError, match="parameter 'use_sim_time': expected a bool, got 1"):
        validate_parameters(SCHEMA, {'use_sim_time': 1})


def test_relative_paths_resolve_against_base(tmp_path):
    values = validate_parameters(SCHEMA, {})
    resolved = resolve_relative_paths(SCHEMA, values, tmp_path)
    assert resolved['urdf'] == str(tmp_path / 'hand.urdf')
    absolute = str(tmp_path / 'elsewhere' / 'hand.urdf')
    assert resolve_relative_paths(SCHEMA, {**values, 'urdf': absolute}, '/x')['urdf'] == absolute
    assert resolved['kind'] == values['kind']  # not a path: untouched


# --------------------------------------------------------------------------------------------
# Parameter files
# --------------------------------------------------------------------------------------------


def write(tmp_path: Path, text: str, name: str = 'params.yaml') -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text), encoding='utf-8')
    return path


def test_nested_mappings_flatten_to_dotted_names(tmp_path):
    path = write(
        tmp_path,
        """
        demo_node:
          ros__parameters:
            model:
              object:
                mass: 0.11
              fingertip_workspace: {a_min: -1.0, a_max: 1.0}
            barrier.alpha1.gain: 2.0
            flag: true
        """,
    )
    assert load_parameter_file(path) == {
        '/demo_node': {
            'model.object.mass': 0.11,
            'model.fingertip_workspace.a_min': -1.0,
            'model.fingertip_workspace.a_max': 1.0,
            'barrier.alpha1.gain': 2.0,
            'flag': True,
        }
    }


def test_numbers_read_as_rcl_reads_them(tmp_path):
    # YAML 1.1 (PyYAML) reads "1e-8" as a string; rcl_yaml_param_parser reads a double.
    path = write(
        tmp_path,
        """
        n:
          ros__parameters: {a: 1e-8, b: 1.0e6, c: -2E+3, d: 1, e: "1e-8", f: 0.5}
        """,
    )
    values = load_parameter_file(path)['/n']
    assert values == {'a': 1e-8, 'b': 1e6, 'c': -2e3, 'd': 1, 'e': '1e-8', 'f': 0.5}
    assert [type(values[k]) for k in 'abcdef'] == [float, float, float, int, str, float]


def test_yaml_1_1_numbers_stay_text_as_in_rcl(tmp_path):
    # YAML 1.2, as rcl: no digit separators nor base 60; an unsigned exponent is a double.
    path = write(
        tmp_path,
        """
        n:
          ros__parameters: {a: 1_000, b: 1:30, c: 1e5, d: 0x10, e: -.5, f: 2., g: 1.5_0}
        """,
    )
    values = load_parameter_file(path)['/n']
    assert values == {
        'a': '1_000', 'b': '1:30', 'c': 1e5, 'd': 16, 'e': -0.5, 'f': 2.0, 'g': '1.5_0'
    }
    assert [type(values[k]) for k in 'cdef'] == [float, int, float, float]


def test_slash_and_nested_namespace_node_names(tmp_path):
    path = write(
        tmp_path,
        """
        /**:
          ros__parameters: {a: 1.0}
        /plain_node:
          ros__parameters: {b: 2.0}
        other_node:
          ros__parameters: {c: 3.0}
        arm:
          hand_node:
            ros__parameters: {d: 4.0}
        /left/hand_node:
          ros__parameters: {e: 5.0}
        """,
    )
    assert list(load_parameter_file(path)) == [
        '/**',
        '/plain_node',
        '/other_node',
        '/arm/hand_node',
        '/left/hand_node',
    ]


@pytest.mark.parametrize(
    ('text', 'message'),
    [
        ('- a\n- b\n', "expected a mapping of node names to 'ros__parameters', got list"),
        ('', "expected a mapping of node names to 'ros__parameters', got NoneType"),
        ('n: {x: 1}\n', "node '/n/x': expected a mapping with 'ros__parameters', got 1"),
        ('n: 3\n', "node '/n': expected a mapping with 'ros__parameters', got 3"),
        ('ros__parameters: {a: 1}\n', "'ros__parameters' must sit under a node name"),
        (
            'n:\n  ros__parameters: [1, 2]\n',
            "node '/n': expected 'ros__parameters' to be a mapping",
        ),
        (
            'n:\n  ros__parameters:\n    a:\n',
            "node '/n': parameter 'a': expected a value, got nothing",
        ),
        (
            'n:\n  ros__parameters:\n    a: {}\n',
            "node '/n': parameter 'a': expected a value, got {}",
        ),
        (
            'n:\n  ros__parameters:\n    a.b: 1.0\n    a: {b: 2.0}\n',
            "node '/n': parameter 'a.b' is given twice",
        ),
        ('n:\n  ros__parameters:\n    a: 1.0\n    a: 2.0\n', "duplicate key 'a'"),
        ('n: [\n', 'invalid YAML'),
    ],
)
def test_malformed_files_name_file_and_problem(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ParameterError) as caught:
        load_parameter_file(path)
    assert f"parameter file '{path}'" in str(caught.value)
    assert message in str(caught.value)


def test_missing_file(tmp_path):
    path = tmp_path / 'nowhere.yaml'
    with pytest.raises(ParameterError) as caught:
        load_parameter_file(path)
    assert str(caught.value) == f"parameter file '{path}' does not exist"


def test_wildcard_then_node_section_node_wins(tmp_path):
    path = write(
        tmp_path,
        """
        /**:
          ros__parameters: {mass: 1.0, angle: 0.5}
        demo_node:
          ros__parameters: {mass: 2.0}
        other_node:
          ros__parameters: {mass: 3.0, faces: 4}
        """,
    )
    sections = load_parameter_file(path)
    assert parameters_for_node(sections, 'demo_node') == {'mass': 2.0, 'angle': 0.5}
    assert parameters_for_node(sections, '/demo_node') == {'mass': 2.0, 'angle': 0.5}
    assert parameters_for_node(sections, 'other_node') == {'mass': 3.0, 'angle': 0.5, 'faces': 4}
    assert parameters_for_node(sections, 'unlisted_node') == {'mass': 1.0, 'angle': 0.5}


def test_sections_apply_in_file_order_as_in_rclpy(tmp_path):
    # rclpy updates a node's overrides section by section in file order.
    path = write(
        tmp_path,
        """
        demo_node:
          ros__parameters: {mass: 2.0}
        /**:
          ros__parameters: {mass: 1.0}
        """,
    )
    assert parameters_for_node(load_parameter_file(path), 'demo_node') == {'mass': 1.0}


@pytest.mark.parametrize(
    ('key', 'node', 'namespace', 'applies'),
    [
        ('/**', 'demo_node', '/', True),
        ('/**', 'demo_node', '/arm', True),
        ('/*/demo_node', 'demo_node', '/arm', True),
        ('/*/demo_node', 'demo_node', '/', False),
        ('/**/demo_node', 'demo_node', '/', True),
        ('/**/demo_node', 'demo_node', '/a/b', True),
        ('/**/demo_node', 'other_node', '/a', False),
        ('/arm/demo_node', 'demo_node', '/arm', True),
        ('/arm/demo_node', 'demo_node', '/', False),
        ('demo_node', 'demo_node', '/arm', False),
        ('demo_node', '/demo_node', '/ignored', True),
    ],
)
def test_node_key_matching(key, node, namespace, applies):
    sections = {key: {'mass': 2.0}}
    expected = {'mass': 2.0} if applies else {}
    assert parameters_for_node(sections, node, namespace) == expected


# --------------------------------------------------------------------------------------------
# The package's schemas and their cross-parameter checks
# --------------------------------------------------------------------------------------------


def test_every_schema_parameter_is_documented_and_typed():
    for schema in NODE_SCHEMAS.values():
        for spec in schema:
            assert spec.description and spec.description[0].isupper(), spec.name
            if spec.type in (T.DOUBLE, T.INTEGER, T.DOUBLE_ARRAY):
                # A number's unit closes its description, "[-]" when dimensionless.
                assert spec.description.endswith(']'), spec.name
            if spec.type is T.DOUBLE:
                assert isinstance(spec.default, float), spec.name  # static type double, not int
            if spec.type is T.DOUBLE_ARRAY:
                assert all(isinstance(v, float) for v in spec.default), spec.name


def test_model_section_is_shared_and_read_only():
    model = [name for name in NODE_SCHEMAS[HAND_SIM_NODE].names if name.startswith('model.')]
    assert len(model) == 20
    for schema in NODE_SCHEMAS.values():
        assert [n for n in schema.names if n.startswith('model.')] == model
        assert all(schema[name].read_only for name in model)


def model_values(**changes):
    values = NODE_SCHEMAS[HAND_SIM_NODE].defaults()
    values.update(changes)
    return values


@pytest.mark.parametrize(
    ('changes', 'message'),
    [
        (
            {'model.fingertip_workspace.a_min': 0.5, 'model.fingertip_workspace.a_max': 0.5},
            "parameters 'model.fingertip_workspace.a_min' and 'model.fingertip_workspace.a_max': "
            'expected a_min < a_max, got 0.5 and 0.5',
        ),
        (
            {'model.fingertip_workspace.b_min': -0.5, 'model.fingertip_workspace.b_max': -1.0},
            "parameters 'model.fingertip_workspace.b_min' and 'model.fingertip_workspace.b_max': "
            'expected b_min < b_max, got -0.5 and -1.0',
        ),
        (
            {'model.joint_names': ['j1', 'j2', 'j1']},
            "parameter 'model.joint_names': expected unique names, got ['j1'] twice",
        ),
        (
            {'model.fingertip_frames': ['finger1_tip', 'finger2_tip']},
            "parameter 'model.fingertip_frames': expected one entry per contact in "
            "'model.contact_names' (3), got 2",
        ),
        (
            {'model.contact_faces': ['-x', '+x', '+y', '-y']},
            "parameter 'model.contact_faces': expected one entry per contact in "
            "'model.contact_names' (3), got 4",
        ),
    ],
)
def test_model_cross_checks(changes, message):
    with pytest.raises(ParameterError) as caught:
        check_model_parameters(model_values(**changes), source='scene.yaml')
    assert str(caught.value) == f'scene.yaml: {message}'


def test_model_check_accepts_defaults_and_sphere_without_faces():
    check_model_parameters(model_values())
    check_model_parameters(
        model_values(**{'model.object.shape': 'sphere', 'model.contact_faces': ['+z']})
    )


def test_model_check_collects_every_error():
    values = model_values(
        **{'model.fingertip_workspace.a_min': 1.5, 'model.contact_names': ['a', 'a', 'b']}
    )
    with pytest.raises(ParameterError) as caught:
        check_model_parameters(values)
    assert len(caught.value.errors) == 2
    assert '2 inconsistent parameters' in str(caught.value)


@pytest.mark.parametrize(
    ('changes', 'message'),
    [
        (
            {'initial.joint_positions': [0.0] * 8},
            "parameter 'initial.joint_positions': expected one angle per joint in "
            "'model.joint_names' (9), got 8",
        ),
        (
            {'initial.object_orientation': [0.0, 0.0, 0.7, 0.7]},
            "parameter 'initial.object_orientation': expected a unit quaternion",
        ),
    ],
)
def test_hand_sim_cross_checks(changes, message):
    with pytest.raises(ParameterError) as caught:
        check_hand_sim_parameters(model_values(**changes))
    assert message in str(caught.value)


def test_load_node_parameters_reports_file_node_and_parameter(tmp_path):
    path = write(
        tmp_path,
        """
        /**:
          ros__parameters:
            model: {object: {mass: -0.11}}
        hand_sim_node:
          ros__parameters:
            integrater: "rk4"
            time_step: 1
        """,
    )
    with pytest.raises(ParameterError) as caught:
        load_node_parameters(path, HAND_SIM_NODE)
    message = str(caught.value)
    assert message.startswith(f"parameter file '{path}' (node 'hand_sim_node'): 3 invalid")
    assert "parameter 'model.object.mass': expected > 0.0, got -0.11" in message
    assert (
        "unknown parameter 'integrater'" in message and "(did you mean 'integrator'?)" in message
    )
    assert "parameter 'time_step': expected a double (ROS reads 1 as an integer" in message


def test_load_node_parameters_runs_cross_checks_and_resolves_paths(tmp_path):
    path = write(
        tmp_path,
        """
        /**:
          ros__parameters:
            model: {fingertip_workspace: {b_min: -0.5, b_max: -1.0}}
        """,
    )
    with pytest.raises(ParameterError, match=r"\(node 'safety_filter_node'\): parameters"):
        load_node_parameters(path, SAFETY_FILTER_NODE)
    schema = NODE_SCHEMAS[NOMINAL_CONTROLLER_NODE]
    required = {name: schema[name].default for name in REQUIRED_MODEL_PARAMETERS}
    required['model.object.size'] = 0.2
    required['model.urdf_file'] = 'sub/h.urdf'
    nested: dict = {}
    for name, value in required.items():
        *sections, key = name.split('.')
        node = nested
        for section in sections:
            node = node.setdefault(section, {})
        node[key] = value
    good = write(tmp_path, yaml.safe_dump({'/**': {'ros__parameters': nested}}), 'ok.yaml')
    values = load_node_parameters(good, NOMINAL_CONTROLLER_NODE)
    assert values['model.urdf_file'] == str(tmp_path.resolve() / 'sub' / 'h.urdf')
    with pytest.raises(KeyError, match="unknown node 'planner_node'"):
        load_node_parameters(good, 'planner_node')


def test_parameter_table_lists_every_parameter():
    schema = NODE_SCHEMAS[SAFETY_FILTER_NODE]
    table = parameter_table_markdown(schema).splitlines()
    assert table[0].startswith('| Parameter | Type | Default |')
    assert len(table) == 2 + len(schema)
    for line, spec in zip(table[2:], schema, strict=True):
        assert line.startswith(f'| `{spec.name}`')
        assert line.count(' | ') == 4  # five cells: no unescaped pipe inside
    assert '| `no_slip.pyramid_faces` (ro) | integer | `8` | in [3, 64] |' in '\n'.join(table)


# --------------------------------------------------------------------------------------------
# rclpy glue, against stand-ins that follow the Jazzy API field by field
# (rcl_interfaces/msg/*.msg and rclpy/node.py: declare_parameters, _apply_descriptor)
# --------------------------------------------------------------------------------------------


class _Message:
    """A ROS message stand-in: keyword-only fields, each type-checked like rosidl Python does."""

    FIELDS: ClassVar[dict[str, tuple[type, object]]] = {}

    def __init__(self, **kwargs):
        for name, (_, default) in self.FIELDS.items():
            setattr(self, name, list(default) if isinstance(default, list) else default)
        for name, value in kwargs.items():
            assert name in self.FIELDS, f'Invalid arguments passed to constructor: {name}'
            setattr(self, name, value)

    def __setattr__(self, name, value):
        assert name in self.FIELDS, f'no field {name}'
        kind = self.FIELDS[name][0]
        assert isinstance(value, kind) and not (kind is int and isinstance(value, bool)), (
            f'field {name}: expected {kind.__name__}, got {value!r}'
        )
        object.__setattr__(self, name, value)


class FloatingPointRange(_Message):
    FIELDS: ClassVar[dict[str, tuple[type, object]]] = {
        'from_value': (float, 0.0),
        'to_value': (float, 0.0),
        'step': (float, 0.0),
    }


class IntegerRange(_Message):
    FIELDS: ClassVar[dict[str, tuple[type, object]]] = {
        'from_value': (int, 0),
        'to_value': (int, 0),
        'step': (int, 0),
    }


class ParameterDescriptor(_Message):
    FIELDS: ClassVar[dict[str, tuple[type, object]]] = {
        'name': (str, ''),
        'type': (int, 0),
        'description': (str, ''),
        'additional_constraints': (str, ''),
        'read_only': (bool, False),
        'dynamic_typing': (bool, False),
        'floating_point_range': (list, []),
        'integer_range': (list, []),
    }


class SetParametersResult(_Message):
    FIELDS: ClassVar[dict[str, tuple[type, object]]] = {
        'successful': (bool, False),
        'reason': (str, ''),
    }


class ParameterTypeMsg:
    PARAMETER_NOT_SET = 0
    PARAMETER_BOOL = 1
    PARAMETER_INTEGER = 2
    PARAMETER_DOUBLE = 3
    PARAMETER_STRING = 4
    PARAMETER_BYTE_ARRAY = 5
    PARAMETER_BOOL_ARRAY = 6
    PARAMETER_INTEGER_ARRAY = 7
    PARAMETER_DOUBLE_ARRAY = 8
    PARAMETER_STRING_ARRAY = 9


def ros_type_of(value) -> int:
    """Return rclpy's Parameter.Type.from_parameter_value, as type ids."""
    if isinstance(value, bool):
        return 1
    if isinstance(value, int):
        return 2
    if isinstance(value, float):
        return 3
    if isinstance(value, str):
        return 4
    if isinstance(value, list | tuple | array.array):
        for kind, type_id in ((bytes, 5), (bool, 6), (int, 7), (float, 8), (str, 9)):
            if all(isinstance(v, kind) for v in value):
                return type_id
    raise TypeError(value)


class Parameter:
    def __init__(self, name, value):
        self.name, self.value, self.type_ = name, value, ros_type_of(value)


class InvalidParameterValueError(Exception):
    pass


class FakeNode:
    """declare_parameters and on-set callbacks as rclpy Jazzy runs them."""

    def __init__(self, overrides=None):
        self.overrides = overrides or {}
        self.callbacks = []
        self.descriptors = {}
        self.values = {}

    def add_on_set_parameters_callback(self, callback):
        self.callbacks.insert(0, callback)

    def declare_parameters(self, namespace, parameters, ignore_override=False):
        declared = []
        for name, value, descriptor in parameters:
            assert isinstance(descriptor, ParameterDescriptor)
            name = f'{namespace}.{name}' if namespace else name
            descriptor.type = ros_type_of(value)  # static type inferred from the default
            value = self.overrides.get(name, value)
            parameter = Parameter(name, value)
            if parameter.type_ != descriptor.type:
                raise InvalidParameterValueError(f'{name}: wrong parameter type')
            for callback in self.callbacks:
                result = callback([parameter])
                assert isinstance(result, SetParametersResult)
                if not result.successful:
                    raise InvalidParameterValueError(result.reason)
            self.descriptors[name] = descriptor
            self.values[name] = value
            declared.append(parameter)
        return declared


@pytest.fixture
def fake_ros(monkeypatch):
    package = types.ModuleType('rcl_interfaces')
    msg = types.ModuleType('rcl_interfaces.msg')
    msg.FloatingPointRange = FloatingPointRange
    msg.IntegerRange = IntegerRange
    msg.ParameterDescriptor = ParameterDescriptor
    msg.ParameterType = ParameterTypeMsg
    msg.SetParametersResult = SetParametersResult
    package.msg = msg
    monkeypatch.setitem(sys.modules, 'rcl_interfaces', package)
    monkeypatch.setitem(sys.modules, 'rcl_interfaces.msg', msg)


def test_descriptor_of_bounded_double(fake_ros):
    descriptor = make_parameter_descriptor(ANGLE)
    assert descriptor.name == 'angle'
    assert descriptor.type == ParameterTypeMsg.PARAMETER_DOUBLE
    assert descriptor.description == 'Angle [rad]'
    assert descriptor.additional_constraints == 'in [-1.5, 1.5]'
    assert not descriptor.read_only
    (fp_range,) = descriptor.floating_point_range
    assert (fp_range.from_value, fp_range.to_value, fp_range.step) == (-1.5, 1.5, 0.0)
    assert descriptor.integer_range == []


def test_descriptor_of_bounded_integer(fake_ros):
    spec = ParameterSpec('n', T.INTEGER, 5, 'Count [-]', min_value=3, max_value=12)
    descriptor = make_parameter_descriptor(spec)
    (int_range,) = descriptor.integer_range
    assert (int_range.from_value, int_range.to_value, int_range.step) == (3, 12, 0)
    assert descriptor.floating_point_range == []


@pytest.mark.parametrize('spec', [MASS, FACES, KIND, GRAVITY, QUAT])
def test_descriptor_without_two_sided_scalar_bound_has_no_range(fake_ros, spec):
    descriptor = make_parameter_descriptor(spec)
    assert descriptor.floating_point_range == [] and descriptor.integer_range == []
    assert descriptor.additional_constraints == spec.constraint_text()


@pytest.mark.parametrize('node_name', sorted(NODE_SCHEMAS))
def test_declare_node_parameters_with_static_types(fake_ros, node_name):
    schema = NODE_SCHEMAS[node_name]
    node = FakeNode()
    values = declare_node_parameters(node, schema)
    assert values == schema.defaults()
    for spec in schema:
        descriptor = node.descriptors[spec.name]
        expected_type = getattr(ParameterTypeMsg, f'PARAMETER_{spec.type.name}')
        assert descriptor.type == expected_type, spec.name  # e.g. 1.0, not 1
        assert descriptor.read_only == spec.read_only
        assert descriptor.description == spec.description
    workspace = node.descriptors['model.fingertip_workspace.a_min'].floating_point_range[0]
    assert (workspace.from_value, workspace.to_value) == (-math.pi / 2, math.pi / 2)


def test_declare_applies_overrides_and_converts_arrays(fake_ros):
    overrides = {'model.gravity': array.array('d', [0.0, 0.0, -1.62]), 'time_step': 0.002}
    values = declare_node_parameters(FakeNode(overrides), NODE_SCHEMAS[HAND_SIM_NODE])
    assert values['model.gravity'] == [0.0, 0.0, -1.62]
    assert isinstance(values['model.gravity'], list)
    assert values['time_step'] == 0.002


def test_declare_rejects_bad_override_with_our_message(fake_ros):
    node = FakeNode({'model.object.mass': -0.11})
    with pytest.raises(InvalidParameterValueError) as caught:
        declare_node_parameters(node, NODE_SCHEMAS[SAFETY_FILTER_NODE])
    assert str(caught.value) == "parameter 'model.object.mass': expected > 0.0, got -0.11"


def test_on_set_callback(fake_ros):
    callback = on_set_parameters_callback(NODE_SCHEMAS[SAFETY_FILTER_NODE])
    good = callback([Parameter('osqp.max_iter', 100), Parameter('barrier.alpha1.kind', 'linear')])
    assert good.successful
    bad = callback(
        [
            Parameter('osqp.max_iter', 0),
            Parameter('input.fallback', 'brake'),
            Parameter('no_slip.enabled', False),
        ]
    )
    assert not bad.successful
    assert bad.reason == (
        "parameter 'osqp.max_iter': expected >= 1, got 0; parameter 'input.fallback': "
        "expected one of ['zero', 'gravity_compensation'], got 'brake'"
    )
    # Parameters the schema does not own (rclpy's, other parts of the node) are not judged.
    assert callback([Parameter('use_sim_time', True), Parameter('something_else', 1)]).successful


def test_declare_on_a_real_rclpy_node():
    import rclpy  # a test dependency: a missing rclpy fails here, it is not skipped
    from rclpy.exceptions import InvalidParameterValueException as RclpyInvalidValue
    from rclpy.parameter import Parameter as RclpyParameter

    rclpy.init()
    try:
        schema = NODE_SCHEMAS[NOMINAL_CONTROLLER_NODE]
        node = rclpy.create_node('nominal_controller_node')
        values = declare_node_parameters(node, schema)
        assert values == schema.defaults()
        assert node.describe_parameter('model.object.mass').read_only
        result = node.set_parameters([RclpyParameter('gains.kp', value=-1.0)])[0]
        assert not result.successful and "parameter 'gains.kp'" in result.reason
        node.destroy_node()
        bad = rclpy.create_node(
            'nominal_controller_node',
            parameter_overrides=[RclpyParameter('reference.frequency', value=-1.0)],
        )
        with pytest.raises(RclpyInvalidValue, match=r'reference\.frequency'):
            declare_node_parameters(bad, schema)
        bad.destroy_node()
    finally:
        rclpy.try_shutdown()


@pytest.mark.parametrize(
    'section', ['safety_filtr_node', 'Hand_Sim_Node', 'nominal_controler_node']
)
def test_the_ros_free_loader_refuses_a_misspelt_node_section(tmp_path, section):
    path = tmp_path / 'scenario.yaml'
    path.write_text(
        config_path().read_text(encoding='utf-8')
        + f'\n{section}:\n  ros__parameters:\n    enabled: false\n',
        encoding='utf-8',
    )
    expected = f"section '/{section}' addresses no node.*did you mean"
    with pytest.raises(ParameterError, match=expected):
        load_node_parameters(path, 'safety_filter_node')


def test_the_ros_free_loader_accepts_sections_for_other_nodes_of_a_system(tmp_path):
    path = tmp_path / 'scenario.yaml'
    path.write_text(
        config_path().read_text(encoding='utf-8')
        + '\nmy_hand_driver:\n  ros__parameters:\n    rate: 1000\n'
        + '\nhand_sim_node_2:\n  ros__parameters:\n    duration: 1.0\n',
        encoding='utf-8',
    )
    assert load_node_parameters(path, 'safety_filter_node')['enabled'] is True
