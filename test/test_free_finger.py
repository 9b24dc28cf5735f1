"""A free finger: the example hand's fourth finger touches nothing (four_finger_three_contacts).

Its joints are commanded (in ``model.joint_names``) but on no listed fingertip's chain.
They move no contact: their columns of J_h are zero, the no-slip and workspace rows of the
filter do not involve them, the joint-limit rows of the free joints involve only them, the
nominal controller holds them at their posture without touching the grasp, and a run through
the runner keeps the free finger inside its limits while the three contacts hold the box.
"""

from __future__ import annotations

from pathlib import Path

from grasp_states import CONFIG_DIR
import numpy as np
import pytest

from grasp_safety_filter import runner
from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import ReferenceSample
from grasp_safety_filter.control.safety_filter import SafetyFilter
from grasp_safety_filter.model.grasp_check import grasp_findings
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_parameters import free_joint_names
from grasp_safety_filter.model.quaternion import rotation_matrix
from hand_sim_node.constraint_margins import FAMILIES

CONFIG = CONFIG_DIR / 'four_finger_three_contacts.yaml'
FREE = [f'finger4_joint{k}' for k in range(1, 5)]


@pytest.fixture(scope='module')
def scenario():
    model, params = GraspModel.from_parameter_file(CONFIG)
    R_o = rotation_matrix(params['initial.object_orientation'])
    p_o = np.asarray(params['initial.object_position'], dtype=float)
    q0 = model.project_to_contact(np.asarray(params['initial.joint_positions']), p_o, R_o)
    return model, q0, p_o, R_o


def free_mask(model: GraspModel) -> np.ndarray:
    return np.array([name in FREE for name in model.joint_names])


def states(model, q0, p_o, R_o, count=4):
    """Yield the initial grasp moving: random rates of the free finger, rolling elsewhere."""
    rng = np.random.default_rng(3)
    free = free_mask(model)
    for _ in range(count):
        q = q0.copy()
        q[free] += rng.uniform(-0.2, 0.2, free.sum())
        twist = rng.normal(0.0, 0.05, 6)
        dq = model.rolling_joint_velocity(q, p_o, R_o, twist)
        dq[free] = rng.normal(0.0, 0.5, free.sum())
        yield model.state(0.0, q, dq, p_o, R_o, twist)


def test_joints_on_no_fingertip_chain_are_the_free_ones(scenario):
    model, *_ = scenario
    assert free_joint_names(model.hand) == FREE
    assert model.n_contacts == 3 and model.n_joints == 16


def test_the_free_columns_of_J_h_are_zero_and_the_grasp_is_valid(scenario):
    model, q0, p_o, R_o = scenario
    assert grasp_findings(model, q0, p_o, R_o) == []
    free = free_mask(model)
    for state in states(model, q0, p_o, R_o):
        assert np.all(state.J_h[:, free] == 0.0)
        assert np.linalg.matrix_rank(state.J_h) == 9
        assert np.linalg.matrix_rank(state.J_h[:, ~free]) == 9


def test_the_filter_rows_of_the_grasp_ignore_the_free_joints(scenario):
    model, q0, p_o, R_o = scenario
    free = free_mask(model)
    safety_filter = SafetyFilter.from_config(model, PAPER_CONFIG)
    for state in states(model, q0, p_o, R_o):
        rows = safety_filter.constraint_rows(state)
        scale = np.abs(rows.A).max()
        families = np.array([name.split('/')[0] for name in rows.names])
        joint_rows = np.array([name.split('/')[1] in FREE for name in rows.names])
        grasp_rows = families != 'joint_limits'
        assert grasp_rows.sum() == 3 * (8 + 4)
        np.testing.assert_allclose(rows.A[np.ix_(grasp_rows, free)], 0.0, atol=1e-12 * scale)
        # Free joints' limits involve only the free joints' torques, and the others none.
        own = (families == 'joint_limits') & joint_rows
        others = (families == 'joint_limits') & ~joint_rows
        assert own.sum() == 2 * len(FREE)
        np.testing.assert_allclose(rows.A[np.ix_(own, ~free)], 0.0, atol=1e-12 * scale)
        np.testing.assert_allclose(rows.A[np.ix_(others, free)], 0.0, atol=1e-12 * scale)
        assert np.all(np.abs(rows.A[np.ix_(own, free)]).max(axis=1) > 1e-3 * scale)
        # A torque on the free joints changes no contact force.
        u = np.zeros(model.n_joints)
        u[free] = 0.1
        forces = state.contact_force(u) - state.contact_force(np.zeros(model.n_joints))
        np.testing.assert_allclose(forces, 0.0, atol=1e-12)


def test_the_nominal_controller_holds_the_free_finger_at_its_posture(scenario):
    model, q0, p_o, R_o = scenario
    free = free_mask(model)
    config = NominalConfig()
    controller = NominalController(config, posture=q0)
    pose = np.concatenate((p_o, np.zeros(3)))
    reference = ReferenceSample(pose)
    still = model.state(0.0, q0, np.zeros(16), p_o, R_o, np.zeros(6))
    held = controller.compute(still, reference)
    # At its posture and at rest: gravity compensation only.
    np.testing.assert_allclose(held.u[free], still.gravity_torque[free], atol=1e-12)
    for state in states(model, q0, p_o, R_o):
        out = controller.compute(state, reference)
        offset, rate = (state.q - q0)[free], state.dq[free]
        # A posture spring and damper per unit inertia on the free finger (its block of M_h).
        M_free = state.M_h[np.ix_(free, free)]
        expected = state.gravity_torque[free] + M_free @ (
            -config.null_space_kp * offset - config.null_space_kd * rate
        )
        np.testing.assert_allclose(out.u[free], expected, rtol=1e-9, atol=1e-12)
        # The free finger leaves the grasp's torques alone: same as with it at rest at q0.
        q_held, dq_held = state.q.copy(), state.dq.copy()
        q_held[free], dq_held[free] = q0[free], 0.0
        twin = model.state(0.0, q_held, dq_held, p_o, R_o, state.twist_object)
        np.testing.assert_allclose(
            out.u[~free], controller.compute(twin, reference).u[~free], rtol=1e-9, atol=1e-12
        )


def test_a_run_holds_the_grasp_and_keeps_the_free_finger_in_its_limits(scenario, tmp_path):
    model, q0, *_ = scenario
    free = free_mask(model)
    result = runner.run(runner.RunOptions(Path(CONFIG), duration=0.4), tmp_path / 'out')
    summary = result.summary
    assert summary['completed'] and len(load_run(result.bag).t) == 400
    assert {family: v['count'] for family, v in summary['violations'].items()} == dict.fromkeys(
        FAMILIES, 0
    )
    assert summary['mu'] == [0.8, 0.8, 0.6]
    run = load_run(result.bag)
    q_free = run.q[:, free]
    assert np.all(q_free > model.joint_lower_limits[free])
    assert np.all(q_free < model.joint_upper_limits[free])
    assert np.abs(q_free - q0[free]).max() < 1e-6
    # The object follows the reference: the three contacts hold it.
    assert np.all(run.required_friction < run.mu_per_contact)
