"""The parameter files in config/ against the nodes' schemas, and the paper's scenario file."""

from __future__ import annotations

import math
from pathlib import Path
import re
import xml.etree.ElementTree as ElementTree

import pytest
import yaml

from grasp_safety_filter.io.parameters import (
    load_parameter_file,
    ROS_PARAMETERS_KEY,
    WILDCARD_NODE,
)
from grasp_safety_filter.io.schemas import load_node_parameters, MODEL_PARAMETERS, NODE_SCHEMAS

CONFIG = Path(__file__).resolve().parent.parent / 'config'
CONFIG_FILES = sorted(CONFIG.glob('*.yaml'))
PAPER_SCENARIO = CONFIG / 'paper_scenario.yaml'
MODEL_NAMES = {spec.name for spec in MODEL_PARAMETERS}
NODE_KEYS = {f'/{node}': node for node in NODE_SCHEMAS}


def test_config_directory_has_parameter_files():
    assert PAPER_SCENARIO in CONFIG_FILES


@pytest.fixture(params=CONFIG_FILES, ids=lambda path: path.name)
def sections(request):
    return request.param, load_parameter_file(request.param)


def test_sections_are_the_wildcard_then_known_nodes(sections):
    path, file_sections = sections
    unknown = set(file_sections) - {WILDCARD_NODE} - set(NODE_KEYS)
    assert not unknown, f'{path.name}: sections for nodes this package does not have: {unknown}'
    if WILDCARD_NODE in file_sections:
        # rclpy applies sections in file order: the wildcard first lets each node override it.
        assert next(iter(file_sections)) == WILDCARD_NODE


def test_wildcard_keys_are_declared_by_every_node(sections):
    path, file_sections = sections
    for node, schema in NODE_SCHEMAS.items():
        undeclared = set(file_sections.get(WILDCARD_NODE, {})) - set(schema.names)
        assert not undeclared, f'{path.name}: /** sets {sorted(undeclared)}, unknown to {node}'


def test_model_parameters_only_under_the_wildcard(sections):
    # One plant for all three nodes: a node-specific model value would let them disagree.
    path, file_sections = sections
    for key, values in file_sections.items():
        if key != WILDCARD_NODE:
            assert not MODEL_NAMES & set(values), f'{path.name}: {key} overrides model.*'


def test_node_keys_are_declared_by_that_node(sections):
    path, file_sections = sections
    for key, node in NODE_KEYS.items():
        undeclared = set(file_sections.get(key, {})) - set(NODE_SCHEMAS[node].names)
        assert not undeclared, f'{path.name}: {node} does not declare {sorted(undeclared)}'


#: Parameters a scenario file may leave out: a deprecated check, and the dimensions of the
#: object shapes the file does not use.
OPTIONAL_IN_FILES = {
    'model.fingertip_radius',
    'model.object.size',
    'model.object.edge_lengths',
    'model.contact_faces',
}


def test_every_declared_parameter_is_in_the_file(sections):
    path, file_sections = sections
    shared = set(file_sections.get(WILDCARD_NODE, {}))
    for key, node in NODE_KEYS.items():
        given = shared | set(file_sections.get(key, {}))
        missing = [
            name
            for name in NODE_SCHEMAS[node].names
            if name not in given and name not in OPTIONAL_IN_FILES
        ]
        assert not missing, f'{path.name}: {node} parameters missing from the file: {missing}'


@pytest.mark.parametrize('path', CONFIG_FILES, ids=lambda path: path.name)
@pytest.mark.parametrize('node', sorted(NODE_SCHEMAS))
def test_file_validates_for_every_node(path, node):
    values = load_node_parameters(path, node)
    assert set(values) == set(NODE_SCHEMAS[node].names)
    assert Path(values['model.urdf_file']).is_file()


@pytest.mark.parametrize('path', CONFIG_FILES, ids=lambda path: path.name)
def test_file_reads_the_same_with_plain_yaml(path):
    # Tools that read the file with PyYAML (YAML 1.1) must see the values ROS sees:
    # no "1e-8" (a string to PyYAML), no key relying on rcl-only parsing.
    def flatten(mapping, prefix=''):
        flat = {}
        for key, value in mapping.items():
            if isinstance(value, dict):
                flat.update(flatten(value, f'{prefix}{key}.'))
            else:
                flat[prefix + key] = value
        return flat

    document = yaml.safe_load(path.read_text(encoding='utf-8'))
    plain = {'/' + node.strip('/'): flatten(s[ROS_PARAMETERS_KEY]) for node, s in document.items()}
    assert plain == load_parameter_file(path)


# --------------------------------------------------------------------------------------------
# The paper's scenario (Section IV)
# --------------------------------------------------------------------------------------------

HALF_PI = math.pi / 2

#: Values the paper states, by node and parameter.
PAPER_VALUES = {
    'hand_sim_node': {
        'model.object.shape': 'cube',
        'model.object.mass': 0.11,
        'model.object.size': 0.2604,
        'model.friction_coefficient': 0.9,
        'model.fingertip_workspace.b_min': -math.pi,
        'model.fingertip_workspace.b_max': 0.0,
        'integrator': 'ode3',
        'duration': 15.0,
        'stop_on_workspace_exit': True,
    },
    'nominal_controller_node': {
        'gains.kp': 1.0,
        'gains.kd': 2.5,
        'gains.kf': 10.0,
        'reference.amplitude': [0.0, 0.0, 0.25, 0.0, 0.0, 2.0],
        'reference.frequency': 1.0,
    },
    'safety_filter_node': {
        'no_slip.enabled': True,
        'joint_limits.enabled': True,
        'fingertip_workspace.enabled': True,
        'barrier.alpha1.kind': 'cubic',
        'barrier.alpha1.gain': 1.0,
        'barrier.alpha2.kind': 'cubic',
        'barrier.alpha2.gain': 1.0,
    },
}


@pytest.fixture(scope='module')
def scenario():
    return {node: load_node_parameters(PAPER_SCENARIO, node) for node in NODE_SCHEMAS}


@pytest.mark.parametrize('node', sorted(PAPER_VALUES))
def test_scenario_has_the_papers_values(scenario, node):
    for name, value in PAPER_VALUES[node].items():
        assert scenario[node][name] == pytest.approx(value, abs=1e-15), name


def test_scenario_our_choices(scenario):
    model = scenario['hand_sim_node']
    margin = 0.15  # the sphere metric diag(R, R cos a) is singular at a = +-pi/2
    assert model['model.fingertip_workspace.a_min'] == pytest.approx(-HALF_PI + margin, abs=1e-15)
    assert model['model.fingertip_workspace.a_max'] == pytest.approx(HALF_PI - margin, abs=1e-15)
    assert model['model.gravity'] == [0.0, 0.0, -9.81]
    assert model['initial.joint_positions'] == pytest.approx(
        [3 * math.pi / 4, 0.75, HALF_PI - 0.75] * 3, abs=1e-15
    )
    assert model['initial.object_position'] == pytest.approx(
        [0.0, 0.0, 0.3 * math.cos(0.75)], abs=1e-15
    )
    assert model['initial.object_orientation'] == [0.0, 0.0, 0.0, 1.0]
    assert model['model.contact_faces'] == ['-x', '+x', '+y']


def test_all_nodes_see_the_same_model(scenario):
    models = [
        {name: value for name, value in values.items() if name in MODEL_NAMES}
        for values in scenario.values()
    ]
    assert models[0] == models[1] == models[2]


def test_scenario_matches_the_urdf(scenario):
    values = scenario['hand_sim_node']
    robot = ElementTree.parse(values['model.urdf_file']).getroot()
    joints = {joint.get('name'): joint for joint in robot.iter('joint')}
    links = {link.get('name') for link in robot.iter('link')}
    actuated = [name for name, joint in joints.items() if joint.get('type') == 'revolute']
    assert values['model.joint_names'] == actuated
    assert set(values['model.fingertip_frames']) <= links
    for name, q in zip(
        values['model.joint_names'], values['initial.joint_positions'], strict=True
    ):
        limit = joints[name].find('limit')
        lower, upper = float(limit.get('lower')), float(limit.get('upper'))
        # Inside the joint-limit barrier's safe set with margin.
        assert lower + 0.25 < q < upper - 0.25, name


def _leaves_with_comments(path: Path) -> dict[str, bool]:
    """Map each parameter of a file (``node/dotted.name``) to whether a comment explains it.

    A comment on a parameter's line(s) or on any enclosing key's line counts.
    """
    key_line = re.compile(r'^(?P<indent> *)(?P<key>[^\s#:,\[\]{}]+):(?:\s+(?P<rest>.*))?$')
    stack: list[tuple[int, str, bool]] = []  # (indent, key, commented)
    leaves: dict[str, bool] = {}
    last_leaf = None
    for line in path.read_text(encoding='utf-8').splitlines():
        if not line.strip() or line.lstrip().startswith('#'):
            continue
        match = key_line.match(line)
        if match is None:  # continuation of a flow sequence
            leaves[last_leaf] = leaves[last_leaf] or '#' in line
            continue
        indent = len(match['indent'])
        while stack and stack[-1][0] >= indent:
            stack.pop()
        rest = match['rest'] or ''
        commented = '#' in rest
        stack.append((indent, match['key'], commented))
        if rest and not rest.startswith('#'):
            node = stack[0][1]
            keys = [key for _, key, _ in stack[1:] if key != ROS_PARAMETERS_KEY]
            last_leaf = f'{node}/' + '.'.join(keys)
            leaves[last_leaf] = any(flag for _, _, flag in stack)
    return leaves


def test_every_value_the_paper_does_not_give_is_explained():
    leaves = _leaves_with_comments(PAPER_SCENARIO)
    sections = load_parameter_file(PAPER_SCENARIO)
    # The line parser sees exactly the file's parameters.
    assert sorted(leaves) == sorted(
        f'{node.lstrip("/") if node != WILDCARD_NODE else node}/{name}'
        for node, values in sections.items()
        for name in values
    )
    from_paper = {f'/**/{name}' for name in PAPER_VALUES['hand_sim_node'] if 'model.' in name}
    from_paper |= {
        f'{node}/{name}'
        for node, values in PAPER_VALUES.items()
        for name in values
        if not name.startswith('model.')
    }
    unexplained = sorted(name for name, commented in leaves.items() if not commented)
    assert set(unexplained) <= from_paper, set(unexplained) - from_paper
