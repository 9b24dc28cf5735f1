"""The ``acceleration`` QP metric: the factor it writes, and the corrections it prefers.

``W = c (S_h^T M_h S_h + S_o^T M_o S_o + eps M_h^-1)`` (``c = tr(M_h)/m``, S_h and S_o the
constrained dynamics' ``u -> ddq`` and ``u -> x_o_ddot``): a correction costs the
acceleration it gives the hand and the object. Checked on the paper's hand (m = 3n) and the
16-joint example hand (m > 3n), at their initial grasps and at random rolling ones, against a
reference W formed here with numpy's inverse; and in the filter, that a correction of a
squeeze that leaves the friction cones is an internal force, where the inverse-inertia
metric moves the object.
"""

from dataclasses import replace

from grasp_states import CONFIG_DIR, paper_model, random_configuration
import numpy as np
import pytest

from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.filter_result import FilterStatus
from grasp_safety_filter.control.qp import (
    ACCELERATION_REGULARISATION,
    QP_METRICS,
    write_acceleration_factor,
    write_inertia_factor,
)
from grasp_safety_filter.control.safety_filter import SafetyFilter, SafetyFilterConfig
from grasp_safety_filter.model.grasp_check import load_initial_grasp
from grasp_safety_filter.model.quaternion import rotation_matrix

EXAMPLE_HAND = CONFIG_DIR / 'four_finger_box.yaml'


def reference_metric(state):
    """Return W of the acceleration metric, formed with numpy's inverse."""
    M_h = state.M_h
    S_h = state.joint_acceleration.matrix
    S_o = state.object_acceleration.matrix
    K = S_h.T @ M_h @ S_h + S_o.T @ state.M_o @ S_o
    K = K + ACCELERATION_REGULARISATION * np.linalg.inv(M_h)
    return np.trace(M_h) / M_h.shape[0] * K


def initial_state(hand):
    """Return ``(model, state)`` at rest at the hand's scenario grasp (or the paper's)."""
    if hand == 'paper':
        model, params = load_initial_grasp(CONFIG_DIR / 'paper_scenario.yaml')
    else:
        model, params = load_initial_grasp(EXAMPLE_HAND)
    p_object = np.array(params['initial.object_position'])
    R_object = rotation_matrix(params['initial.object_orientation'])
    q = model.project_to_contact(params['initial.joint_positions'], p_object, R_object)
    state = model.state(0.0, q, np.zeros(model.n_joints), p_object, R_object, np.zeros(6))
    return model, state


def grasp_states():
    """Return the table's states: both hands at rest, and rolling grasps of the paper's."""
    states = {hand: initial_state(hand)[1] for hand in ('paper', 'example')}
    model = paper_model()
    rng = np.random.default_rng(7)
    for i in range(3):
        states[f'paper rolling {i}'] = random_configuration(model, rng, 0.2, 0.5).state(model)
    return states


STATES = grasp_states()


def test_metric_is_a_choice():
    assert 'acceleration' in QP_METRICS
    assert SafetyFilterConfig(metric='acceleration').metric == 'acceleration'


@pytest.mark.parametrize('name', sorted(STATES))
def test_factor_inverts_the_metric(name):
    state = STATES[name]
    m = state.M_h.shape[0]
    R = np.full((m, m), np.nan)
    write_acceleration_factor(
        state.M_h,
        state.joint_acceleration.matrix,
        state.object_acceleration.matrix,
        state.M_o,
        R,
    )
    assert np.all(np.triu(R, 1) == 0.0)
    product = R @ R.T @ reference_metric(state)
    assert np.abs(product - np.eye(m)).max() < 1e-6


@pytest.mark.parametrize('name', sorted(STATES))
def test_internal_forces_cost_only_the_regularisation(name):
    state = STATES[name]
    G, J_h = state.G, state.J_h
    _, _, vt = np.linalg.svd(G)
    internal = vt[np.linalg.matrix_rank(G):]  # G f = 0
    assert internal.shape[0] >= 3
    W = reference_metric(state)
    M_inverse = np.linalg.inv(state.M_h)
    c = np.trace(state.M_h) / state.M_h.shape[0]
    for f in internal:
        du = J_h.T @ f
        cost = du @ W @ du
        assert cost <= 1.01 * ACCELERATION_REGULARISATION * c * du @ M_inverse @ du


def test_free_hand_is_the_inverse_inertia_metric():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    M_h = A @ A.T + np.eye(6)
    R, R_inertia = np.zeros((6, 6)), np.zeros((6, 6))
    write_acceleration_factor(M_h, np.linalg.inv(M_h), np.zeros((6, 6)), np.eye(6), R)
    write_inertia_factor(M_h, R_inertia)
    scale = np.sqrt(1.0 + ACCELERATION_REGULARISATION)
    assert np.abs(R * scale - R_inertia).max() < 1e-12


@pytest.mark.parametrize(
    'terms, message',
    [
        ({'M_h': np.diag([2.0, -1.0, 1.0, 1.0])}, 'positive definite'),
        ({'M_h': -np.eye(4)}, 'M_h'),
        ({'M_h': np.full((4, 4), np.nan)}, 'finite'),
        ({'joint_acceleration': np.full((4, 4), np.inf)}, 'finite'),
    ],
)
def test_bad_terms_raise(terms, message):
    arguments = {
        'M_h': np.eye(4),
        'joint_acceleration': np.eye(4),
        'object_acceleration': np.zeros((6, 4)),
        'M_o': np.eye(6),
        'out': np.zeros((4, 4)),
        **terms,
    }
    with pytest.raises(ValueError, match=message):
        write_acceleration_factor(**arguments)


def filter_with(model, metric):
    """Return a filter with the suggested linear class-K functions and the given metric."""
    config = replace(
        PAPER_CONFIG,
        metric=metric,
        alpha1_kind='linear',
        alpha1_gain=10.0,
        alpha2_kind='linear',
        alpha2_gain=10.0,
    )
    return SafetyFilter.from_config(model, config)


@pytest.mark.parametrize('hand', ['paper', 'example'])
@pytest.mark.parametrize('pull', [0.5, 2.0])
def test_squeeze_corrected_by_internal_forces(hand, pull):
    """A torque that holds, plus an internal pull out of the cones: the fix is a squeeze.

    ``u_nom = u_hold - J_h^T f``, f the internal force (in null(G)) nearest to pressing
    every contact along its normal by ``pull`` N: ``u_hold`` satisfies every row, so an
    internal force alone restores them; the acceleration metric finds it (the grasp's
    accelerations change by ~0), the inverse-inertia metric accelerates joints and object.
    """
    model, state = initial_state(hand)
    u_hold = filter_with(model, 'acceleration').solve(state, state.gravity_torque).u
    n = state.G.shape[1] // 3
    press = np.tile([0.0, 0.0, pull], n)
    _, _, vt = np.linalg.svd(state.G)
    internal = vt[np.linalg.matrix_rank(state.G):]
    f = internal.T @ (internal @ press)
    u_nom = u_hold - state.J_h.T @ f
    change = {}
    for metric in ('inverse_inertia', 'acceleration'):
        result = filter_with(model, metric).solve(state, u_nom)
        assert result.status is FilterStatus.SOLVED, (metric, result.status)
        du = result.u - u_nom
        assert np.abs(du).max() > 1e-4  # the pull had to be corrected
        change[metric] = (
            np.linalg.norm(state.object_acceleration.matrix @ du),
            np.abs(state.joint_acceleration.matrix @ du).max(),
        )
    for before, after in zip(change['inverse_inertia'], change['acceleration'], strict=True):
        assert after <= 0.01 * before + 1e-9, change
