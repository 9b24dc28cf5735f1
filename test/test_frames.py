"""The palm and object frames come from the configuration and are checked on every odometry.

``model.palm_frame`` (default: the URDF's root link) and ``model.object_frame`` (default
``object``) are what the simulator stamps on ``/object/odom`` and what the nominal
controller and the safety filter accept: a frame other than the configured one is
rejected, naming the field, the frame expected and the one received.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from test_endpoints import (
    CONFIG,
    DiagnosticLevel,
    make_filter,
    make_nominal,
    make_sim,
    statuses,
    through_cdr,
)

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspConfigError, GraspModel

NODES = ('hand_sim_node', 'nominal_controller_node', 'safety_filter_node')
FRAMES = {'model.palm_frame': 'hand_base', 'model.object_frame': 'grasped_cube'}


def scenario(**overrides: object) -> dict[str, dict]:
    """Each node's parameters of the paper's scenario, with ``overrides`` in every node."""
    return {node: {**load_node_parameters(CONFIG, node), **overrides} for node in NODES}


def first_messages(params: dict[str, dict]):
    sim = make_sim(params)
    state = {o.topic: through_cdr(o.msg) for o in sim.start()}
    return state[topics.JOINT_STATES], state[topics.OBJECT_ODOM]


def test_the_palm_frame_defaults_to_the_urdf_root_link(tmp_path):
    text = (Path(CONFIG).parent / 'hand.urdf').read_text()
    renamed = text.replace('name="palm"', 'name="base_link"').replace(
        'link="palm"', 'link="base_link"'
    )
    assert renamed != text
    (tmp_path / 'hand.urdf').write_text(renamed)
    params = load_node_parameters(CONFIG, 'safety_filter_node')
    model = GraspModel.from_parameters(
        {**params, 'model.urdf_file': str(tmp_path / 'hand.urdf'), 'model.palm_frame': ''}
    )
    assert (model.palm_frame, model.object_frame) == ('base_link', 'object')


def test_a_urdf_frame_that_is_not_the_root_is_refused_as_palm_frame():
    params = load_node_parameters(CONFIG, 'safety_filter_node')
    with pytest.raises(GraspConfigError, match=r"model\.palm_frame.*'finger1_tip'.*'palm'"):
        GraspModel.from_parameters({**params, 'model.palm_frame': 'finger1_tip'})


def test_configured_frames_reach_the_odometry_and_are_accepted_downstream():
    params = scenario(**FRAMES)
    joints, odometry = first_messages(params)
    assert odometry.header.frame_id == 'hand_base'
    assert odometry.child_frame_id == 'grasped_cube'
    nominal = make_nominal(params)
    assert nominal.on_joint_states(joints) == []
    effort_nominal, _reference_sample = nominal.on_odom(odometry)
    assert effort_nominal.topic == topics.EFFORT_NOMINAL
    safety_filter = make_filter(params)
    assert safety_filter.on_joint_states(joints) == []
    assert safety_filter.on_odom(odometry) == []
    outgoing = safety_filter.on_effort_nominal(through_cdr(effort_nominal.msg))
    assert topics.EFFORT_COMMAND in [o.topic for o in outgoing]


@pytest.mark.parametrize(
    ('field', 'configured'),
    [('header.frame_id', 'model.palm_frame'), ('child_frame_id', 'model.object_frame')],
)
def test_odometry_in_another_frame_is_rejected_naming_both_frames(field, configured):
    # The simulator stamps the paper's frames; the consumers expect the configured ones.
    _, odometry = first_messages(scenario())
    expected = FRAMES[configured]
    received = 'palm' if configured == 'model.palm_frame' else 'object'
    nominal = make_nominal(scenario(**{configured: expected}))
    (report,) = statuses(nominal.on_odom(odometry), 'nominal_controller')
    assert report.level is DiagnosticLevel.WARN
    for word in (field, expected, received):
        assert word in report.message, report.message
    safety_filter = make_filter(scenario(**{configured: expected}))
    reports = statuses(safety_filter.on_odom(odometry), 'safety_filter')
    assert reports, 'the filter accepted odometry in another frame'
    for word in (field, expected, received):
        assert word in reports[0].message, reports[0].message
