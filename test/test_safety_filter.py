"""The safety filter: optimality against an independent solver, relaxation, errors, config."""

import dataclasses
from dataclasses import replace
import math
import re

import daqp
import numpy as np
import pytest
from qp_reference import hard_optimum
import scipy.sparse as sp
from synthetic_state import synthetic_state, SyntheticHand, with_fields

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints import (
    FingertipWorkspaceBarrier,
    FrictionPyramid,
    JointLimitBarrier,
    stack_constraints,
)
from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.qp import SafetyQP
from grasp_safety_filter.control.qp_solvers import BACKENDS
from grasp_safety_filter.control.safety_filter import (
    FilterStatus,
    MEASURED_STATE_FIELDS,
    SafetyFilter,
    SafetyFilterConfig,
)
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import SAFETY_FILTER_QP_PARAMETERS
from grasp_safety_filter.model.affine import AffineMap

HAND = SyntheticHand()
M = HAND.n_joints
CERTIFIED = {FilterStatus.NOMINAL, FilterStatus.SOLVED}
SOLVERS = sorted(BACKENDS)

CONFIGS = {
    'paper': PAPER_CONFIG,
    'linear': replace(
        PAPER_CONFIG,
        alpha1_kind='linear', alpha1_gain=4.0, alpha2_kind='linear', alpha2_gain=10.0
    ),
    'coarse_pyramid': replace(PAPER_CONFIG, pyramid_faces=4, normal_force_margin=0.2),
}


def independent_rows(config, state, hand=HAND):
    """Build the barrier rows from the families directly (not from the filter's buffers)."""
    alpha1 = ClassKFunction(config.alpha1_kind, config.alpha1_gain)
    alpha2 = ClassKFunction(config.alpha2_kind, config.alpha2_gain)
    families = []
    if config.no_slip_enabled:
        families.append(
            FrictionPyramid(
                hand.contact_names,
                hand.friction_coefficient,
                config.pyramid_faces,
                config.normal_force_margin,
            )
        )
    if config.joint_limits_enabled:
        families.append(
            JointLimitBarrier(
                hand.joint_names, hand.joint_lower_limits, hand.joint_upper_limits, alpha1, alpha2
            )
        )
    if config.fingertip_workspace_enabled:
        families.append(
            FingertipWorkspaceBarrier(
                hand.contact_names, *hand.fingertip_workspace, alpha1, alpha2
            )
        )
    return stack_constraints(families, state)


def reference_optimum(rows, u_nom, effort):
    """(feasible, u*) of min 1/2 ||u - u_nom||^2 s.t. rows, |u| <= effort (daqp and G-I agree)."""
    box = np.full(u_nom.size, effort)
    return hard_optimum(rows.A, rows.lower, u_nom, -box, box)


def strictly_feasible_point(rows, effort, rng):
    """Find a torque satisfying every row with margin (daqp on tightened rows), or None."""
    norms = np.linalg.norm(rows.A, axis=1)
    tightened = rows._replace(lower=rows.lower + 1e-3 * norms)
    feasible, x = reference_optimum(tightened, rng.normal(size=M), 0.98 * effort)
    return x if feasible else None


def check_invariants(result, filter_):
    assert np.all(np.isfinite(result.u))
    assert np.all(result.u >= filter_.actuator_limits.lower)
    assert np.all(result.u <= filter_.actuator_limits.upper)
    assert result.relaxed == (result.status not in CERTIFIED)


# -- optimality on random states -----------------------------------------------------------


@pytest.mark.parametrize('solver', SOLVERS)
@pytest.mark.parametrize('name', list(CONFIGS))
def test_random_states_rows_hold_nominal_kept_optimum_matches_the_reference(name, solver):
    config = dataclasses.replace(CONFIGS[name], solver=solver)
    filter_ = SafetyFilter.from_config(HAND, config)
    rng = np.random.default_rng(sum(map(ord, name)))
    counts = {'feasible': 0, 'active': 0, 'nominal': 0, 'infeasible': 0}
    for trial in range(300):
        state = synthetic_state(rng, HAND, speed=(0.0, 0.02, 0.05)[trial % 3])
        rows = independent_rows(config, state)
        u_nom = rng.normal(scale=2.0, size=M)
        if trial % 3 == 1:
            interior = strictly_feasible_point(rows, HAND.effort, rng)
            if interior is not None:
                u_nom = interior
        result = filter_.solve(state, u_nom)
        check_invariants(result, filter_)
        feasible, u_reference = reference_optimum(rows, u_nom, HAND.effort)
        if not feasible:
            counts['infeasible'] += 1
            assert result.status is FilterStatus.RELAXED
            violated = rows.residual(result.u) < -1e-6
            assert set(result.relaxed_families) == {
                rows.names[i].split('/')[0] for i in np.flatnonzero(violated)
            }
            continue
        counts['feasible'] += 1
        assert result.status in CERTIFIED, (trial, result.status)
        assert rows.residual(result.u).min() >= -1e-6
        assert np.abs(result.u - u_reference).max() <= 1e-5
        nominal_feasible = rows.residual(u_nom).min() >= 0.0 and np.all(
            np.abs(u_nom) <= HAND.effort
        )
        if nominal_feasible:
            counts['nominal'] += 1
            assert result.status is FilterStatus.NOMINAL
            assert np.abs(result.u - u_nom).max() <= 1e-6
        else:
            counts['active'] += 1
            assert result.active
    assert counts['feasible'] >= 200
    assert counts['nominal'] >= 50 and counts['active'] >= 100, counts


@pytest.mark.parametrize('solver', SOLVERS)
def test_warm_started_sequence_matches_the_reference_at_every_tick(solver):
    """Slowly varying states (fixed model terms, moving joints and contacts) and u_nom."""
    config = dataclasses.replace(CONFIGS['paper'], solver=solver)
    filter_ = SafetyFilter.from_config(HAND, config)
    lo, hi = HAND.joint_lower_limits, HAND.joint_upper_limits
    q0 = lo + 0.5 * (hi - lo)
    statuses = set()
    for k in range(300):
        t = 1e-3 * k
        q = q0 + 0.2 * (hi - lo) * math.sin(3.0 * t)
        dq = 0.6 * (hi - lo) * math.cos(3.0 * t) * 0.05
        state = synthetic_state(np.random.default_rng(7), HAND, speed=0.0, q=q, dq=dq)
        reference_state = synthetic_state(np.random.default_rng(7), HAND, speed=0.0)
        u_nom = reference_state.gravity_torque + 1.5 * np.sin(5.0 * t + np.arange(M))
        result = filter_.solve(state, u_nom)
        rows = independent_rows(config, state)
        feasible, u_reference = reference_optimum(rows, u_nom, HAND.effort)
        assert feasible
        assert result.status in CERTIFIED
        assert np.abs(result.u - u_reference).max() <= 1e-5
        statuses.add(result.status)
    assert FilterStatus.SOLVED in statuses


# -- infeasible states: relaxation ---------------------------------------------------------


def only(*families, solver='osqp'):
    return dataclasses.replace(
        CONFIGS['paper'],
        solver=solver,
        no_slip_enabled='no_slip' in families,
        joint_limits_enabled='joint_limits' in families,
        fingertip_workspace_enabled='fingertip_workspace' in families,
    )


WEAK = SyntheticHand(effort=1e-3)


def beyond_joint_limit(state):
    q = state.q.copy()
    dq = np.zeros(M)
    q[0] = WEAK.joint_upper_limits[0] + 0.05
    dq[0] = 2.0  # still moving outwards
    return {
        'q': q,
        'dq': dq,
        'joint_acceleration': AffineMap(state.joint_acceleration.matrix, np.zeros(M)),
    }


def pulling_contact(state):
    offset = state.contact_force.offset.copy()
    offset[0:3] = (0.0, 0.0, -5.0)
    return {'contact_force': AffineMap(state.contact_force.matrix, offset)}


def rolling_off(state):
    xi, xi_dot = state.xi_cf.copy(), np.zeros((3, 2))
    xi[1, 0] = WEAK.fingertip_workspace[1] + 0.05
    xi_dot[1, 0] = 10.0
    return {
        'xi_cf': xi,
        'xi_cf_dot': xi_dot,
        'xi_cf_ddot': AffineMap(state.xi_cf_ddot.matrix, np.zeros(6)),
    }


INFEASIBLE_CASES = {
    'no_slip': (pulling_contact, 'no_slip/finger1/face0'),
    'joint_limits': (beyond_joint_limit, 'joint_limits/finger1_joint1/upper'),
    'fingertip_workspace': (rolling_off, 'fingertip_workspace/finger2/a_max'),
}


@pytest.mark.parametrize('solver', SOLVERS)
@pytest.mark.parametrize('family', list(INFEASIBLE_CASES))
def test_an_infeasible_family_is_relaxed_and_named(family, solver):
    rng = np.random.default_rng(5)
    make, row = INFEASIBLE_CASES[family]
    state = synthetic_state(rng, WEAK, speed=0.0)
    state = with_fields(state, **make(state))
    filter_ = SafetyFilter.from_config(WEAK, only(family, solver=solver))
    result = filter_.solve(state, rng.normal(size=M))
    check_invariants(result, filter_)
    assert result.status is FilterStatus.RELAXED and result.relaxed
    assert result.relaxed_families == (family,)
    assert row in result.active
    assert result.max_violation > 1e-3
    assert np.all(np.abs(result.u) <= 1e-3)


def test_several_infeasible_families_are_all_named():
    rng = np.random.default_rng(6)
    state = synthetic_state(rng, WEAK, speed=0.0)
    changes = {}
    for make, _ in INFEASIBLE_CASES.values():
        changes.update(make(state))
    state = with_fields(state, **changes)
    filter_ = SafetyFilter.from_config(WEAK, CONFIGS['paper'])
    result = filter_.solve(state, np.zeros(M))
    check_invariants(result, filter_)
    assert set(result.relaxed_families) == {'no_slip', 'joint_limits', 'fingertip_workspace'}
    assert result.relaxed_families == ('no_slip', 'joint_limits', 'fingertip_workspace')


def conflicting_state(rng):
    """Make joint 1's upper limit and contact 1's a_min rows conflict.

    Joint 1 must decelerate (it runs into q_max) while contact 1's a, driven by the same
    joint acceleration, must accelerate (it runs into a_min): no torque satisfies both.
    """
    state = synthetic_state(rng, HAND, speed=0.0)
    q, dq = state.q.copy(), np.zeros(M)
    q[0], dq[0] = HAND.joint_upper_limits[0] - 0.1, 1.0
    xi, xi_dot = np.array([[0.0, -1.5]] * 3), np.zeros((3, 2))
    xi[0, 0], xi_dot[0, 0] = HAND.fingertip_workspace[0] + 0.1, -1.0
    rolling = np.zeros((6, M))
    rolling[0, 0] = 1.0  # a_1_ddot = ddq_1
    return with_fields(
        state,
        q=q,
        dq=dq,
        xi_cf=xi,
        xi_cf_dot=xi_dot,
        joint_acceleration=AffineMap(np.eye(M), np.zeros(M)),
        xi_cf_ddot=AffineMap(rolling, np.zeros(6)),
    )


@pytest.mark.parametrize('solver', SOLVERS)
@pytest.mark.parametrize('joint_weight,workspace_weight', [(1e6, 1e3), (1e3, 1e6)])
def test_relaxation_gives_up_the_lower_weighted_family(joint_weight, workspace_weight, solver):
    config = dataclasses.replace(
        only('joint_limits', 'fingertip_workspace', solver=solver),
        joint_limits_weight=joint_weight,
        fingertip_workspace_weight=workspace_weight,
    )
    filter_ = SafetyFilter.from_config(HAND, config)
    state = conflicting_state(np.random.default_rng(8))
    result = filter_.solve(state, np.zeros(M))
    check_invariants(result, filter_)
    assert result.status is FilterStatus.RELAXED
    rows = independent_rows(config, state)
    joint_gap = -rows.residual(result.u)[rows.names.index('joint_limits/finger1_joint1/upper')]
    workspace_gap = -rows.residual(result.u)[rows.names.index('fingertip_workspace/finger1/a_min')]
    # Both rows have unit norm: the gaps are torque-space slacks, split as 1/w.
    assert joint_gap > 0.0 and workspace_gap > 0.0
    assert joint_gap / workspace_gap == pytest.approx(workspace_weight / joint_weight, rel=0.05)


# -- errors before the QP --------------------------------------------------------------------


class UntouchableSolver:
    """A backend that must not solve: the tick is settled before the QP."""

    def solve(self, problem):
        raise AssertionError('the QP backend solved a problem before the input was checked')

    def warm_start(self, solution):
        pass

    def reset(self):
        pass


def nan_at(array, index, value=np.nan):
    changed = np.array(array, dtype=float)
    changed[index] = value
    return changed


NON_FINITE_CASES = [
    ('q', lambda s: {'q': nan_at(s.q, 4)}),
    ('dq', lambda s: {'dq': nan_at(s.dq, 0, np.inf)}),
    ('xi_cf', lambda s: {'xi_cf': nan_at(s.xi_cf, (2, 1))}),
    ('xi_cf_dot', lambda s: {'xi_cf_dot': nan_at(s.xi_cf_dot, (0, 0), -np.inf)}),
    (
        'contact_force.matrix',
        lambda s: {
            'contact_force': AffineMap(
                nan_at(s.contact_force.matrix, (3, 2)), s.contact_force.offset
            )
        },
    ),
    (
        'contact_force.offset',
        lambda s: {
            'contact_force': AffineMap(
                s.contact_force.matrix, nan_at(s.contact_force.offset, 7, np.inf)
            )
        },
    ),
    (
        'joint_acceleration.matrix',
        lambda s: {
            'joint_acceleration': AffineMap(
                nan_at(s.joint_acceleration.matrix, (0, 0)), s.joint_acceleration.offset
            )
        },
    ),
    (
        'xi_cf_ddot.offset',
        lambda s: {'xi_cf_ddot': AffineMap(s.xi_cf_ddot.matrix, nan_at(s.xi_cf_ddot.offset, 5))},
    ),
]


MEASURED_CASES = [case for case in NON_FINITE_CASES if case[0] in MEASURED_STATE_FIELDS]
DERIVED_CASES = [case for case in NON_FINITE_CASES if case not in MEASURED_CASES]


@pytest.mark.parametrize('field,change', MEASURED_CASES)
def test_a_non_finite_measured_state_raises_naming_the_field_before_the_qp(field, change):
    rng = np.random.default_rng(9)
    filter_ = SafetyFilter.from_config(HAND, CONFIGS['paper'])
    filter_.backend = UntouchableSolver()
    state = synthetic_state(rng, HAND)
    with pytest.raises(ValueError, match=f'state\\.{field.replace(".", "[.]")}'):
        filter_.solve(with_fields(state, **change(state)), np.zeros(M))


@pytest.mark.parametrize('field,change', DERIVED_CASES)
def test_a_non_finite_model_term_falls_back_before_the_qp(field, change):
    # The measured state is finite: a model term that is not (an overflow) is no input error.
    rng = np.random.default_rng(9)
    filter_ = SafetyFilter.from_config(HAND, CONFIGS['paper'])
    state = synthetic_state(rng, HAND, speed=0.0)
    good = filter_.solve(state, np.zeros(M))
    assert good.status in CERTIFIED
    filter_.backend = UntouchableSolver()
    result = filter_.solve(with_fields(state, **change(state)), np.ones(M))
    check_invariants(result, filter_)
    assert result.status is FilterStatus.FALLBACK_LAST_GOOD
    assert np.array_equal(result.u, good.u)
    assert result.relaxed_families and result.max_violation == math.inf


def test_a_non_finite_field_that_no_enabled_family_reads_is_ignored():
    rng = np.random.default_rng(10)
    filter_ = SafetyFilter.from_config(HAND, only('no_slip', 'joint_limits'))
    state = synthetic_state(rng, HAND)
    state = with_fields(state, xi_cf=np.full((3, 2), np.nan))
    check_invariants(filter_.solve(state, np.zeros(M)), filter_)


@pytest.mark.parametrize(
    'u_nom,message',
    [
        (np.full(M, np.nan), 'u_nom: non-finite'),
        (
            np.concatenate((np.zeros(M - 1), [np.inf])),
            "u_nom: non-finite value inf for joint 'finger3_joint3'",
        ),
        (np.zeros(M + 1), 'u_nom: expected shape'),
        (np.zeros((M, 1)), 'u_nom: expected shape'),
        (['a'] * M, 'u_nom: expected'),
    ],
)
def test_a_bad_nominal_torque_raises_before_the_qp(u_nom, message):
    filter_ = SafetyFilter.from_config(HAND, CONFIGS['paper'])
    filter_.backend = UntouchableSolver()
    with pytest.raises(ValueError, match=message):
        filter_.solve(synthetic_state(np.random.default_rng(11), HAND), u_nom)


def test_a_state_of_another_hand_raises():
    filter_ = SafetyFilter.from_config(HAND, CONFIGS['paper'])
    other = synthetic_state(np.random.default_rng(12), SyntheticHand(n_fingers=2))
    with pytest.raises(ValueError, match='expected 9 joints and 3 contacts'):
        filter_.solve(other, np.zeros(M))


def scaled_field(value, factor):
    if isinstance(value, AffineMap):
        return AffineMap(value.matrix * factor, value.offset * factor)
    return np.asarray(value) * factor


@pytest.mark.parametrize('solver', SOLVERS)
@pytest.mark.parametrize('factor', [0.0, 1e-300, 1e150, 1e300])
def test_any_finite_state_gives_a_finite_torque_inside_the_box(factor, solver):
    rng = np.random.default_rng(13)
    filter_ = SafetyFilter.from_config(HAND, dataclasses.replace(CONFIGS['paper'], solver=solver))
    for _ in range(3):
        state = synthetic_state(rng, HAND, speed=0.5)
        fields = (
            'q',
            'dq',
            'xi_cf',
            'xi_cf_dot',
            'contact_force',
            'joint_acceleration',
            'xi_cf_ddot',
        )
        extreme = with_fields(
            state, **{f: scaled_field(getattr(state, f), factor) for f in fields}
        )
        for u_nom in (np.zeros(M), rng.normal(scale=100.0, size=M)):
            result = filter_.solve(extreme, u_nom)
            check_invariants(result, filter_)


# -- result contents ---------------------------------------------------------------------


def test_margins_active_rows_and_read_only_torque():
    rng = np.random.default_rng(14)
    config = CONFIGS['paper']
    filter_ = SafetyFilter.from_config(HAND, config)
    seen_active = False
    for _ in range(20):
        state = synthetic_state(rng, HAND, speed=0.0)
        result = filter_.solve(state, rng.normal(scale=2.0, size=M))
        names = (*filter_.row_names, *filter_.actuator_limits.names)
        assert tuple(result.margins) == names
        for family in filter_.families:
            h = family.values(state, result.u).h
            assert np.allclose([result.margins[n] for n in family.names], h)
        rows = independent_rows(config, state)
        residual = dict(zip(rows.names, rows.residual(result.u), strict=True))
        for i, name in enumerate(filter_.actuator_limits.names):
            residual[name] = filter_.actuator_limits.values(None, result.u).h[i]
        assert set(result.active) == {n for n, r in residual.items() if r <= 1e-6}
        seen_active |= bool(result.active)
        with pytest.raises(ValueError):
            result.u[0] = 1.0
    assert seen_active


def test_a_disabled_filter_only_clips_to_the_box():
    filter_ = SafetyFilter.from_config(HAND, only())
    assert filter_.row_names == ()
    state = synthetic_state(np.random.default_rng(15), HAND)
    u_nom = np.linspace(-8.0, 8.0, M)
    result = filter_.solve(state, u_nom)
    assert result.status in CERTIFIED
    assert np.allclose(result.u, np.clip(u_nom, -HAND.effort, HAND.effort))
    assert filter_.solve(state, np.zeros(M)).status is FilterStatus.NOMINAL


@pytest.mark.parametrize('solver', SOLVERS)
def test_reset_keeps_results_unchanged(solver):
    rng = np.random.default_rng(16)
    filter_ = SafetyFilter.from_config(HAND, dataclasses.replace(CONFIGS['paper'], solver=solver))
    state = synthetic_state(rng, HAND, speed=0.0)
    u_nom = rng.normal(scale=3.0, size=M)
    first = filter_.solve(state, u_nom)
    filter_.reset()
    again = filter_.solve(state, u_nom)
    assert np.allclose(first.u, again.u, atol=1e-9)


# -- construction and configuration ----------------------------------------------------------


def test_from_config_reads_the_grasp_model():
    filter_ = SafetyFilter.from_config(HAND, PAPER_CONFIG)
    assert filter_.config == PAPER_CONFIG
    assert filter_.joint_names == HAND.joint_names
    assert filter_.contact_names == HAND.contact_names
    assert np.array_equal(filter_.actuator_limits.lower, -HAND.effort_limits)
    assert np.array_equal(filter_.actuator_limits.upper, HAND.effort_limits)
    assert [f.family for f in filter_.families] == [
        'no_slip',
        'joint_limits',
        'fingertip_workspace',
    ]
    assert len(filter_.row_names) == 3 * 8 + 2 * M + 4 * 3


@pytest.mark.parametrize(
    'kwargs,message',
    [
        ({'workspace': (0.0, 1.0)}, 'workspace'),
        ({'mu': -0.5}, 'mu'),
        ({'q_max': np.zeros(M)}, 'q_max'),
        ({'u_min': 6.0}, 'u_max'),
        ({'config': {}}, 'config'),
    ],
)
def test_constructor_errors_name_the_argument(kwargs, message):
    arguments = {
        'config': PAPER_CONFIG,
        'joint_names': HAND.joint_names,
        'contact_names': HAND.contact_names,
        'q_min': HAND.joint_lower_limits,
        'q_max': HAND.joint_upper_limits,
        'u_min': -5.0,
        'u_max': 5.0,
        'mu': 0.9,
        'workspace': HAND.fingertip_workspace,
    }
    with pytest.raises(ValueError, match=message):
        SafetyFilter(**{**arguments, **kwargs})


def test_parameter_names_and_defaults():
    assert {spec.name for spec in SAFETY_FILTER_QP_PARAMETERS} == {
        'no_slip.enabled',
        'no_slip.pyramid_faces',
        'no_slip.normal_force_margin',
        'no_slip.friction_margin',
        'no_slip.cone',
        'torque_rate.enabled',
        'torque_rate.max_step',
        'torque_rate.max_rate',
        'joint_limits.enabled',
        'joint_limits.margin',
        'fingertip_workspace.enabled',
        'fingertip_workspace.margin',
        'object_workspace.enabled',
        'object_workspace.margin',
        'object_workspace.sphere_a_half_width',
        'object_workspace.sphere_b_half_width',
        'barrier.alpha1.kind',
        'barrier.alpha1.gain',
        'barrier.alpha2.kind',
        'barrier.alpha2.gain',
        'relaxation.no_slip_weight',
        'relaxation.joint_limits_weight',
        'relaxation.torque_rate_weight',
        'relaxation.fingertip_workspace_weight',
        'relaxation.object_workspace_weight',
        'osqp.eps_abs',
        'osqp.eps_rel',
        'osqp.max_iter',
        'osqp.polish',
        'qp.solver',
        'qp.metric',
    }
    defaults = {spec.name: spec.default for spec in SAFETY_FILTER_QP_PARAMETERS}
    assert SafetyFilterConfig().to_parameters() == defaults
    assert SafetyFilterConfig.from_parameters({}) == SafetyFilterConfig()


def test_from_parameters_reads_dotted_and_nested_names_and_ignores_others():
    config = SafetyFilterConfig.from_parameters(
        {
            'no_slip.pyramid_faces': 6,
            'barrier': {'alpha1': {'kind': 'linear', 'gain': 3}},
            'osqp': {'polish': True},
            'model.friction_coefficient': 0.5,
        }
    )
    assert config.pyramid_faces == 6 and config.alpha1_kind == 'linear'
    assert config.alpha1_gain == 3.0 and isinstance(config.alpha1_gain, float)
    assert config.polish is True
    assert SafetyFilterConfig.from_parameters(config.to_parameters()) == config


@pytest.mark.parametrize(
    'name,value',
    [
        ('no_slip.pyramid_faces', 2),
        ('no_slip.pyramid_faces', 8.0),
        ('no_slip.normal_force_margin', -0.1),
        ('no_slip.enabled', 'yes'),
        ('barrier.alpha1.gain', -1.0),
        ('barrier.alpha2.gain', 0.0),
        ('barrier.alpha1.kind', 'quadratic'),
        ('barrier.alpha2.kind', 'exponential'),
        ('relaxation.joint_limits_weight', 0.0),
        ('osqp.eps_abs', 0.0),
        ('osqp.max_iter', 0),
        ('osqp.polish', 1),
    ],
)
def test_bad_parameters_are_rejected_naming_them(name, value):
    with pytest.raises(ParameterError, match=re.escape(f"'{name}'")):
        SafetyFilterConfig.from_parameters({name: value})


def test_the_dataclass_validates_too():
    with pytest.raises(ParameterError, match=r"'barrier\.alpha2\.gain'"):
        SafetyFilterConfig(alpha2_gain=-2.0)
    with pytest.raises(ParameterError, match=r"'no_slip\.pyramid_faces'"):
        SafetyFilterConfig(pyramid_faces=1)


# -- the QP's fixed pattern ------------------------------------------------------------------


@pytest.mark.parametrize('relaxed', [False, True])
def test_qp_pattern_is_fixed_and_matches_the_documented_blocks(relaxed):
    rng = np.random.default_rng(17)
    m, k = 4, 6
    weights = rng.uniform(1.0, 10.0, size=k) if relaxed else None
    qp = SafetyQP(m, k, -np.ones(m), 2 * np.ones(m), row_weights=weights)
    pattern = qp.C
    for _ in range(3):
        A = rng.normal(size=(k, m))
        A[0] = 0.0  # zeros stay structural
        lower, u_nom = rng.normal(size=k), rng.normal(size=m)
        qp.update(A, lower, u_nom)
        C = qp.C
        assert C.nnz == pattern.nnz == m * (k + 1) + (2 * k if relaxed else 0)
        assert np.array_equal(C.indices, pattern.indices)
        assert np.array_equal(C.indptr, pattern.indptr)
        P, q, C_dense, lo, up = qp.dense()
        if relaxed:
            norms = np.where(np.linalg.norm(A, axis=1) < 1e-9, 1.0, np.linalg.norm(A, axis=1))
            expected = np.block(
                [
                    [A, np.diag(norms)],
                    [np.eye(m), np.zeros((m, k))],
                    [np.zeros((k, m)), np.eye(k)],
                ]
            )
            assert np.allclose(P, np.diag(np.concatenate((np.ones(m), weights))))
            assert np.allclose(lo, np.concatenate((lower, -np.ones(m), np.zeros(k))))
        else:
            expected = np.vstack((A, np.eye(m)))
            assert np.allclose(P, np.eye(m))
            assert np.allclose(lo, np.concatenate((lower, -np.ones(m))))
        assert np.allclose(C_dense, expected)
        assert np.allclose(q[:m], -u_nom) and np.all(q[m:] == 0.0)
        assert np.all(up[:k] == np.inf) and np.allclose(up[k : k + m], 2.0)
        assert isinstance(C, sp.csc_matrix)


def relaxed_objective(qp, u, u_nom):
    """Evaluate the relaxed QP's objective at u, each slack at its best value for u."""
    slack = np.maximum(0.0, (qp.lower_rows - qp.A_rows @ u) / qp.slack_scale)
    return 0.5 * np.sum((u - u_nom) ** 2) + 0.5 * np.sum(qp.row_weights * slack**2)


@pytest.mark.parametrize('solver', SOLVERS)
def test_relaxed_torque_is_the_relaxed_qps_optimum(solver):
    """Check against daqp on the relaxed QP's OSQP-form matrices (slacks as variables).

    The objective must agree to round-off; the torque to 1e-5 unless the violations are so
    large (> 1e6, objective ~1e15) that double precision no longer pins u down that well.
    """
    rng = np.random.default_rng(18)
    config = dataclasses.replace(CONFIGS['paper'], solver=solver)
    filter_ = SafetyFilter.from_config(HAND, config)
    k = len(filter_.row_names)
    relaxed_qp = SafetyQP(
        M,
        k,
        -HAND.effort * np.ones(M),
        HAND.effort * np.ones(M),
        row_weights=filter_.relaxed_problem.slack_weights,
    )
    checked = 0
    for _ in range(40):
        state = synthetic_state(rng, HAND, speed=0.1)
        u_nom = rng.normal(scale=3.0, size=M)
        result = filter_.solve(state, u_nom)
        if result.status is not FilterStatus.RELAXED:
            continue
        relaxed_qp.update(filter_.problem.A, filter_.problem.lower, u_nom)
        P, q, C, lower, upper = relaxed_qp.dense()
        x, _, flag, _ = daqp.solve(P, q, C, np.minimum(upper, 1e30), lower)
        assert flag == 1
        ours = relaxed_objective(relaxed_qp, result.u, u_nom)
        reference = relaxed_objective(relaxed_qp, x[:M], u_nom)
        assert ours <= reference * (1.0 + 1e-9)
        if result.max_violation < 1e6:
            assert np.abs(result.u - x[:M]).max() <= 1e-5
            checked += 1
    assert checked >= 10
