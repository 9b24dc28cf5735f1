"""The barriers' margins from the joint limits and the fingertip workspace bounds.

``joint_limits.margin`` and ``fingertip_workspace.margin`` move every bound inwards: the
filter's rows are then those of the inset bounds, built here directly by the families;
a margin that leaves no room is refused at start-up naming it. In closed loop, on a
generated hand whose linear barriers the 1 ms hold overshoots, the margins keep the real
limits (the simulator's event monitor, which knows nothing of them).
"""

from __future__ import annotations

import math
from pathlib import Path

from closed_loop_study import run
import numpy as np
import pytest

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints import FingertipWorkspaceBarrier, JointLimitBarrier
from grasp_safety_filter.control.safety_filter import SafetyFilter, SafetyFilterConfig
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import load_node_parameters, SAFETY_FILTER_NODE
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.quaternion import rotation_matrix
from grasp_tools.hands.grasp import generate_hand

SCENARIO = Path(config_path()).parent / 'four_finger_box.yaml'
LINEAR = {
    'barrier.alpha1.kind': 'linear',
    'barrier.alpha2.kind': 'linear',
    'barrier.alpha1.gain': 10.0,
    'barrier.alpha2.gain': 10.0,
}


def _filter(overrides: dict):
    params = load_node_parameters(SCENARIO, SAFETY_FILTER_NODE, overrides=overrides)
    model = GraspModel.from_parameters(params)
    return model, SafetyFilter.from_config(model, SafetyFilterConfig.from_parameters(params))


def _state(model: GraspModel, rng: np.random.Generator):
    q = 0.5 * (model.joint_lower_limits + model.joint_upper_limits)
    q = q + 0.1 * rng.standard_normal(model.n_joints)
    return model.state(0.0, q, 0.3 * rng.standard_normal(model.n_joints),
                       np.array([0.0, 0.0, 0.075]), rotation_matrix([0, 0, 0, 1]),
                       0.01 * rng.standard_normal(6))  # fmt: skip


@pytest.mark.parametrize('margin', [0.0, 0.02, 0.3])
def test_joint_limit_rows_are_those_of_the_inset_limits(margin):
    model, safety_filter = _filter({**LINEAR, 'joint_limits.margin': margin})
    family = next(f for f in safety_filter.families if f.family == 'joint_limits')
    inset = JointLimitBarrier(
        model.joint_names,
        model.joint_lower_limits + margin,
        model.joint_upper_limits - margin,
        ClassKFunction('linear', 10.0),
        ClassKFunction('linear', 10.0),
    )
    state = _state(model, np.random.default_rng(0))
    ours, theirs = family.rows(state), inset.rows(state)
    np.testing.assert_allclose(ours.A, theirs.A, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ours.lower, theirs.lower, rtol=1e-12, atol=1e-9)
    # h is the distance to the limit less the margin.
    h = family.values(state).h
    q = np.repeat(state.q, 2)
    limits = np.column_stack((model.joint_upper_limits, model.joint_lower_limits)).ravel()
    np.testing.assert_allclose(h, np.abs(limits - q) - margin, atol=1e-12)


@pytest.mark.parametrize('margin', [0.02, 0.5])
def test_fingertip_workspace_rows_are_those_of_the_inset_box(margin):
    model, safety_filter = _filter({'fingertip_workspace.margin': margin})
    family = next(f for f in safety_filter.families if f.family == 'fingertip_workspace')
    a_min, a_max, b_min, b_max = model.fingertip_workspace
    inset = FingertipWorkspaceBarrier(
        model.contact_names, a_min + margin, a_max - margin, b_min + margin, b_max - margin
    )
    state = _state(model, np.random.default_rng(1))
    np.testing.assert_allclose(family.values(state).h, inset.values(state).h, atol=1e-12)
    np.testing.assert_allclose(family.rows(state).lower, inset.rows(state).lower, atol=1e-12)


@pytest.mark.parametrize(
    ('name', 'value', 'message'),
    [
        ('joint_limits.margin', 0.5, "'joint_limits.margin': 0.5 leaves no room between"),
        ('fingertip_workspace.margin', 1.6, "'fingertip_workspace.margin': 1.6 leaves no room"),
        ('joint_limits.margin', -0.01, 'joint_limits.margin'),
    ],
)
def test_a_margin_without_room_is_refused_naming_it(name, value, message):
    with pytest.raises((ValueError, ParameterError), match=message.replace('.', r'\.')):
        _filter({name: value})


def test_margins_keep_a_generated_hand_inside_its_limits(tmp_path):
    """Generated hand 1 of seed 0: linear barriers overshoot its joint limits without them.

    With the margins (and its contacts kept on their object faces) it holds 2 s with every
    QP solved, as judged by the simulator's event monitor against the real limits. Both runs
    use the inverse-inertia metric, so that the margins alone make the difference.
    """
    scenario = generate_hand(0, 1, tmp_path / 'hand').scenario
    reference = {'reference.source': 'paper', 'reference.frequency': 1.1,
                 'reference.amplitude': [0.003, 0.0, -0.008, 0.0, 0.0, -0.18],
                 'qp.metric': 'inverse_inertia'}  # fmt: skip
    bare = run(scenario, 'filtered', 2.0, {
        **LINEAR, **reference, 'joint_limits.margin': 0.0,
        'fingertip_workspace.margin': 0.0, 'object_workspace.enabled': False,
    })  # fmt: skip
    assert not bare['held'] and bare['violations']['joint_limits'] > 0, bare
    kept = run(scenario, 'filtered', 2.0, {
        **LINEAR, **reference, 'joint_limits.margin': 0.02,
        'fingertip_workspace.margin': 0.02, 'object_workspace.enabled': True,
    })  # fmt: skip
    assert kept['held'] and kept['relaxed_ticks'] == 0, kept
    assert math.isclose(kept['t_end'], 2.0, abs_tol=1e-9)
