"""Bad scenario files fail at load with a message naming the parameter, expectation and value."""

from __future__ import annotations

from pathlib import Path
import re

import numpy as np
import pytest
import yaml

from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.quaternion import rotation_matrix

CONFIG = Path(__file__).resolve().parent.parent / 'config'


def load_with(tmp_path: Path, edit, urdf_edit=None) -> None:
    """Copy the paper scenario and URDF to tmp_path, edit them, load and check the grasp."""
    document = yaml.safe_load((CONFIG / 'paper_scenario.yaml').read_text())
    edit(document)
    urdf = (CONFIG / 'hand.urdf').read_text()
    if urdf_edit is not None:
        urdf = urdf_edit(urdf)
    (tmp_path / 'hand.urdf').write_text(urdf)
    path = tmp_path / 'scenario.yaml'
    path.write_text(yaml.safe_dump(document))
    model, params = GraspModel.from_parameter_file(path, 'hand_sim_node')
    model.check_grasp(
        params['initial.joint_positions'],
        np.asarray(params['initial.object_position']),
        rotation_matrix(params['initial.object_orientation']),
    )


def model_section(document):
    return document['/**']['ros__parameters']['model']


def sim_section(document):
    return document['hand_sim_node']['ros__parameters']


def set_in(section, key, value):
    def edit(document):
        section(document)[key] = value

    return edit


def rename_joint(document):
    model_section(document)['joint_names'][4] = 'finger2_joint_two'


def drop_joint(document):
    model_section(document)['joint_names'].pop()
    sim_section(document)['initial']['joint_positions'].pop()


def lift_object(document):
    sim_section(document)['initial']['object_position'] = [0.01, 0.0, 0.3]


def short_initial_q(document):
    sim_section(document)['initial']['joint_positions'] = [0.0] * 8


def swap_limits(urdf: str) -> str:
    return urdf.replace(
        '<limit lower="0" upper="4.7123889803846897',
        '<limit lower="4.8" upper="4.7123889803846897',
        1,
    )


CASES = [
    ('joint not in URDF', rename_joint, None, r'finger2_joint_two.*not a movable joint'),
    ('URDF joint not in scenario', drop_joint, None, r'finger3_joint3.*not listed'),
    ('q_min >= q_max', lambda d: None, swap_limits, r'finger1_joint1.*lower < upper'),
    ('fingertips apart', lift_object, None, r'separated from the object by 0\.01'),
    ('wrong vector length', short_initial_q, None, r'initial\.joint_positions.*\(9\), got 8'),
    (
        'mu <= 0',
        set_in(model_section, 'friction_coefficient', 0.0),
        None,
        r'friction_coefficient.*> 0',
    ),
    (
        'negative mass',
        set_in(model_section, 'object', {'shape': 'cube', 'mass': -0.1, 'size': 0.26}),
        None,
        r'object\.mass',
    ),
    (
        'negative radius',
        set_in(model_section, 'fingertip_radius', -0.06),
        None,
        r'fingertip_radius',
    ),
    (
        'radius not the URDF sphere',
        set_in(model_section, 'fingertip_radius', 0.05),
        None,
        r"fingertip_radius: contact 'finger1'.*link 'finger1_tip' \(0\.06 m\), got 0\.05 m",
    ),
    (
        'unknown key',
        set_in(model_section, 'frction_coefficient', 0.9),
        None,
        r'frction_coefficient.*friction_coefficient',
    ),
    (
        'wrong face label',
        set_in(model_section, 'contact_faces', ['-x', '+x', 'y']),
        None,
        r'contact_faces',
    ),
]


@pytest.mark.parametrize(
    ('edit', 'urdf_edit', 'message'), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_configuration_is_rejected_with_a_clear_message(tmp_path, edit, urdf_edit, message):
    with pytest.raises(ValueError, match=message):
        load_with(tmp_path, edit, urdf_edit)


def test_paper_scenario_loads_and_its_grasp_is_valid(tmp_path):
    load_with(tmp_path, lambda d: None)


def test_message_names_the_joint_in_an_unknown_joint_error(tmp_path):
    with pytest.raises(ValueError) as error:
        load_with(tmp_path, rename_joint)
    assert re.search(r'model\.joint_names', str(error.value))
