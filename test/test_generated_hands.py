"""Generated hands and grasps (python -m grasp_tools.hands): what each one is, checked apart.

The hands are generated once for several seeds by the command itself; each is then read back
with Pinocchio's and MuJoCo's own URDF parsers, its URDF's collision spheres read with
ElementTree, and its object's surface computed here in numpy from the scenario's geometry,
so that the checks do not go through the generator's own arithmetic.
"""

from __future__ import annotations

import csv
import filecmp
from pathlib import Path
import subprocess
import sys
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation
import yaml

from grasp_safety_filter.campaign.spec import load_campaign
from grasp_safety_filter.campaign.store import read_table
from grasp_safety_filter.control.filter_config import SafetyFilterConfig
from grasp_safety_filter.io.parameters.spec import ParameterType
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import load_node_parameters, NODE_SCHEMAS, SAFETY_FILTER_NODE
from grasp_safety_filter.model.grasp_check import load_initial_grasp
from grasp_tools.hands.__main__ import main as generate
from grasp_tools.hands.grasp import generate_hand
from grasp_tools.hands.scenario import DEFAULTED, TEMPLATE
from hand_sim_node.mjcf import mjcf_from_model

#: seed -> hands generated.
SEEDS = {0: 4, 1: 3, 5: 3}
HANDS = [(seed, index) for seed, count in SEEDS.items() for index in range(count)]
CAMPAIGN = Path(sys.executable).parent / 'grasp-campaign'


@pytest.fixture(scope='module')
def out(tmp_path_factory) -> dict[int, Path]:
    """Each seed's output directory, written by the command."""
    directories = {}
    for seed, count in SEEDS.items():
        directory = tmp_path_factory.mktemp(f'seed{seed}')
        assert generate(['--count', str(count), '--seed', str(seed), '--out', str(directory)]) == 0
        directories[seed] = directory
    return directories


class Hand:
    """One generated hand read back from its files, with no help from the generator."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.urdf = (directory / 'hand.urdf').read_text()
        self.document = yaml.safe_load((directory / 'scenario.yaml').read_text())
        self.model_section = self.document['/**']['ros__parameters']['model']
        initial = self.document['hand_sim_node']['ros__parameters']['initial']
        self.q0 = np.array(initial['joint_positions'])
        self.p_object = np.array(initial['object_position'])
        self.R_object = Rotation.from_quat(initial['object_orientation']).as_matrix()
        self.joint_names = self.model_section['joint_names']
        self.pin_model = pin.buildModelFromXML(self.urdf)

    @property
    def shape(self) -> dict:
        return self.model_section['object']

    def object_size(self) -> np.ndarray:
        if self.shape['shape'] == 'sphere':
            return np.full(3, self.shape['size'])
        return np.array(self.shape['edge_lengths'])

    def q0_in_pinocchio_order(self) -> np.ndarray:
        q = np.zeros(self.pin_model.nq)
        for name, value in zip(self.joint_names, self.q0, strict=True):
            q[self.pin_model.joints[self.pin_model.getJointId(name)].idx_q] = value
        return q

    def tip_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """Sphere centres in the palm (n, 3) and radii (n,), from the URDF's collisions."""
        links = {}
        for link in ET.fromstring(self.urdf).iter('link'):
            sphere = link.find('collision/geometry/sphere')
            if sphere is not None:
                xyz = np.array(link.find('collision/origin').get('xyz').split(), float)
                links[link.get('name')] = (xyz, float(sphere.get('radius')))
        data = self.pin_model.createData()
        pin.framesForwardKinematics(self.pin_model, data, self.q0_in_pinocchio_order())
        centres, radii = [], []
        for tip in self.model_section['fingertip_frames']:
            # The tip frame hangs from its distal link by a fixed joint: its parent frame.
            frame = self.pin_model.frames[self.pin_model.getFrameId(tip)]
            link = self.pin_model.frames[frame.parentFrame]
            while link.name not in links:
                link = self.pin_model.frames[link.parentFrame]
            offset, radius = links[link.name]
            placement = data.oMf[self.pin_model.getFrameId(link.name)]
            centres.append(placement.rotation @ offset + placement.translation)
            radii.append(radius)
        return np.array(centres), np.array(radii)

    def surface_distance_and_normal(self, p_in_palm: np.ndarray) -> tuple[float, np.ndarray]:
        """Distance of a point outside the object from its surface, m, and the outward normal."""
        p = self.R_object.T @ (p_in_palm - self.p_object)
        if self.shape['shape'] == 'sphere':
            distance = np.linalg.norm(p)
            return distance - 0.5 * self.shape['size'], self.R_object @ (p / distance)
        half = 0.5 * np.array(self.shape['edge_lengths'])
        nearest = np.clip(p, -half, half)
        gap = p - nearest
        return float(np.linalg.norm(gap)), self.R_object @ (gap / np.linalg.norm(gap))


@pytest.fixture(scope='module')
def hands(out) -> dict[tuple[int, int], Hand]:
    return {(seed, i): Hand(out[seed] / f'hand_{i:03d}') for seed, i in HANDS}


@pytest.mark.parametrize('hand_id', HANDS)
def test_three_to_five_fingers_and_a_thumb_facing_the_others(hands, hand_id):
    hand = hands[hand_id]
    centres, _ = hand.tip_spheres()
    assert 3 <= len(centres) <= 5
    assert hand.model_section['contact_names'][0] == 'thumb'
    normals = np.array([hand.surface_distance_and_normal(c)[1] for c in centres])
    assert normals[0] @ normals[1:].mean(axis=0) <= -0.2
    if hand.shape['shape'] == 'box':  # some finger on the face opposite the thumb's
        assert np.min(normals[1:] @ normals[0]) < -0.999


@pytest.mark.parametrize('hand_id', HANDS)
def test_the_object_is_3_to_10_cm_above_the_palm(hands, hand_id):
    hand = hands[hand_id]
    size = hand.object_size()
    assert np.all((size >= 0.03) & (size <= 0.1))
    assert 0.05 <= hand.shape['mass'] <= 0.3
    assert 0.6 <= hand.model_section['friction_coefficient'] <= 1.0
    assert np.allclose(hand.R_object[:, 2], [0.0, 0.0, 1.0])  # turned about z at most
    assert hand.p_object[2] - 0.5 * size[2] > 0.0  # the lowest point above the palm


@pytest.mark.parametrize('hand_id', HANDS)
def test_the_urdf_builds_in_pinocchio_and_mujoco_with_the_same_joints(hands, hand_id):
    hand = hands[hand_id]
    mj_model = mujoco.MjModel.from_xml_string(hand.urdf)
    names = [mj_model.joint(j).name for j in range(mj_model.njnt)]
    assert hand.pin_model.nq == mj_model.njnt == len(hand.joint_names) == hand.q0.size
    assert sorted(names) == sorted(hand.joint_names)
    assert all(3 <= sum(n.startswith(f + '_') for n in names) <= 4 for f in
               hand.model_section['contact_names'])  # fmt: skip
    model, _ = load_initial_grasp(hand.directory / 'scenario.yaml')
    simulated = mujoco.MjModel.from_xml_string(mjcf_from_model(model))  # the MuJoCo plant's
    assert simulated.njnt == len(hand.joint_names) + 1  # and the object's free joint


@pytest.mark.parametrize('hand_id', HANDS)
def test_each_fingertip_sphere_touches_the_object(hands, hand_id):
    hand = hands[hand_id]
    centres, radii = hand.tip_spheres()
    assert np.all((radii >= 0.006) & (radii <= 0.015))
    distances = [hand.surface_distance_and_normal(c)[0] for c in centres]
    np.testing.assert_allclose(distances, radii, rtol=0.0, atol=1e-6)


@pytest.mark.parametrize('hand_id', HANDS)
def test_the_scenario_passes_the_start_up_check_and_every_node_schema(hands, hand_id):
    hand = hands[hand_id]
    path = hand.directory / 'scenario.yaml'
    load_initial_grasp(path)
    for node in NODE_SCHEMAS:
        load_node_parameters(path, node)
    text = path.read_text()
    assert text.startswith(f'# Generated by python -m grasp_tools.hands (seed {hand_id[0]}, '
                           f'hand {hand_id[1]}')  # fmt: skip
    # ROS 2 types parameters statically: a double must be written as one, not as an int.
    doubles = {
        spec.name
        for schema in NODE_SCHEMAS.values()
        for spec in schema
        if spec.type in (ParameterType.DOUBLE, ParameterType.DOUBLE_ARRAY)
    }
    checked = 0
    for section in hand.document.values():
        for name, value in flatten(section['ros__parameters']):
            if name in doubles:
                values = value if isinstance(value, list) else [value]
                assert all(isinstance(v, float) for v in values), (name, value)
                checked += 1
    assert checked > 50


@pytest.mark.parametrize('hand_id', HANDS[:1])
def test_the_filter_runs_its_defaults_where_the_template_pins_the_papers(hands, hand_id):
    """The class-K functions, margins, object workspace and metric are left to the defaults."""
    path = hands[hand_id].directory / 'scenario.yaml'
    written = dict(flatten(hands[hand_id].document['safety_filter_node']['ros__parameters']))
    config = SafetyFilterConfig.from_parameters(load_node_parameters(path, SAFETY_FILTER_NODE))
    template = SafetyFilterConfig.from_parameters(
        load_node_parameters(config_path(TEMPLATE), SAFETY_FILTER_NODE)
    )
    defaulted = {'.'.join(keys) for keys in DEFAULTED}
    for name, value in SafetyFilterConfig().to_parameters().items():
        left_out = any(name == key or name.startswith(f'{key}.') for key in defaulted)
        assert (name not in written) == left_out, name
        assert config.to_parameters()[name] == (
            value if left_out else template.to_parameters()[name]
        ), name
    assert config.to_parameters() != template.to_parameters()


def flatten(section: dict, prefix: str = '') -> list[tuple[str, object]]:
    items = []
    for key, value in section.items():
        if isinstance(value, dict):
            items += flatten(value, f'{prefix}{key}.')
        else:
            items.append((f'{prefix}{key}', value))
    return items


def joint_limits(hand: Hand) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's URDF limits, in the scenario's joint order, read by Pinocchio."""
    model = hand.pin_model
    k = [model.joints[model.getJointId(name)].idx_q for name in hand.joint_names]
    return model.lowerPositionLimit[k], model.upperPositionLimit[k]


@pytest.mark.parametrize('hand_id', HANDS)
def test_q0_lies_strictly_inside_its_limits(hands, hand_id):
    lower, upper = joint_limits(hands[hand_id])
    q0 = hands[hand_id].q0
    assert np.all((lower < q0) & (q0 < upper))
    assert np.all((upper - lower >= 1.0 - 1e-9) & (upper - lower <= 2.5 + 1e-9))


def test_some_joints_start_near_a_limit(hands):
    near = 0
    for hand in hands.values():
        lower, upper = joint_limits(hand)
        near += int(np.sum(np.minimum(hand.q0 - lower, upper - hand.q0) < 0.1))
    assert near >= 2


def test_the_same_seed_and_index_give_the_same_files_and_other_indices_other_hands(
    tmp_path, out
):
    generate_hand(1, 2, tmp_path / 'again')
    for name in ('hand.urdf', 'scenario.yaml'):
        assert filecmp.cmp(tmp_path / 'again' / name, out[1] / 'hand_002' / name, shallow=False)
    # Fewer hands of the same seed are the first of the more.
    assert generate(['--count', '2', '--seed', '1', '--out', str(tmp_path / 'two')]) == 0
    for name in ('hand.urdf', 'scenario.yaml'):
        assert filecmp.cmp(
            tmp_path / 'two' / 'hand_001' / name, out[1] / 'hand_001' / name, shallow=False
        )
    urdfs = {(out[seed] / f'hand_{i:03d}' / 'hand.urdf').read_text() for seed, i in HANDS}
    assert len(urdfs) == len(HANDS)


def test_the_index_and_the_campaign_list_every_hand(out, hands):
    count = SEEDS[0]
    with (out[0] / 'hands.csv').open(newline='') as file:
        rows = list(csv.DictReader(file))
    assert [int(row['hand']) for row in rows] == list(range(count))
    for row in rows:
        hand = hands[0, int(row['hand'])]
        assert int(row['fingers']) == len(hand.model_section['contact_names'])
        assert int(row['joints']) == hand.q0.size
        assert row['object'] == hand.shape['shape']
        lower, upper = joint_limits(hand)
        margin = np.minimum(hand.q0 - lower, upper - hand.q0).min()
        assert float(row['min_joint_margin']) == pytest.approx(margin, abs=1e-12)
        _, radii = hand.tip_spheres()
        assert float(row['tip_radius_min']) == pytest.approx(radii.min())
        assert 0.0 < float(row['min_workspace_margin']) < np.pi
        assert int(row['rejected']) >= 0
    campaign = load_campaign(out[0] / 'campaign.yaml')
    assert sorted(campaign.scenarios.values()) == sorted(
        (out[0] / f'hand_{i:03d}' / 'scenario.yaml').resolve() for i in range(count)
    )
    runs = campaign.runs()
    assert len(runs) == 2 * count and campaign.duration == 5.0
    for run in runs:
        amplitude = np.abs(run.overrides['reference.amplitude'])
        assert np.all(amplitude[:3] <= 0.01) and np.all(amplitude[3:5] == 0.0)
        assert amplitude[5] <= 0.2
        assert 0.5 <= run.overrides['reference.frequency'] <= 1.5


def test_a_two_hand_campaign_runs_through_grasp_campaign(tmp_path):
    directory = tmp_path / 'hands'
    assert generate(['--count', '2', '--seed', '3', '--out', str(directory), '--duration',
                     '0.05']) == 0  # fmt: skip
    result = subprocess.run(
        [str(CAMPAIGN), str(directory / 'campaign.yaml'), '--out', str(directory / 'results'),
         '--workers', '1', '--keep-worst', '0'],
        capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    rows = read_table(directory / 'results' / 'runs.csv')
    assert len(rows) == 4
    assert [row['mode'] for row in rows] == ['nominal', 'filtered'] * 2
    assert [row['scenario'] for row in rows] == [
        'hand_000/scenario.yaml', 'hand_000/scenario.yaml',
        'hand_001/scenario.yaml', 'hand_001/scenario.yaml',
    ]  # fmt: skip
    # Every run ends with a verdict (a nominal run may slip at once: that is an outcome).
    assert all(row['error'] == '' and row['held'] in ('True', 'False') for row in rows)
    assert all(0.0 <= float(row['t_end']) <= 0.05 + 1e-9 for row in rows)
    assert '2 scenarios' in (directory / 'results' / 'report.md').read_text()
