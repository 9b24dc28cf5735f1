"""The start-up advice: family allowances at rest, the QP at rest, the suggested gains.

Checked against what the advice does not compute itself: each allowance against the row the
filter's own family writes at rest (its ``lower`` is minus that acceleration), tau against the
linear functions' closed form ``1/k1 + 1/k2``, the rest margin against the hard QP of two
independent solvers (OSQP and daqp) at the ball's centre and against the filter's own tick
at rest, and the suggestion against the advice it gives once applied.
"""

from __future__ import annotations

import math
from pathlib import Path

import daqp
import numpy as np
import osqp
import pytest
from scipy import sparse

from grasp_safety_filter.control.safety_filter import SafetyFilter, SafetyFilterConfig
from grasp_safety_filter.control.startup_advice import (
    rest_state,
    startup_advice,
    STILL_ACCELERATION,
)
from grasp_safety_filter.io.messages import DiagnosticLevel
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import (
    HAND_SIM_NODE,
    load_node_parameters,
    node_overrides,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.quaternion import rotation_matrix
from grasp_safety_filter.model_report import main as model_report_main
from grasp_safety_filter.model_report import scenario_advice
from grasp_safety_filter.nodes.startup_log import PREFIX, StartupLog
from grasp_tools.hands.grasp import generate_hand

CONFIG = Path(config_path()).parent
LINEAR = {
    'barrier.alpha1.kind': 'linear',
    'barrier.alpha2.kind': 'linear',
    'barrier.alpha1.gain': 10.0,
    'barrier.alpha2.gain': 10.0,
}

# scenario, overrides, expected verdict, families expected frozen
CASES = [
    ('paper_scenario.yaml', {}, 'frozen', {'joint_limits'}),
    ('paper_scenario.yaml', LINEAR, 'ok', set()),
    ('four_finger_box.yaml', {}, 'frozen', {'joint_limits'}),
    ('four_finger_box.yaml', LINEAR, 'ok', set()),
    (
        'four_finger_sphere.yaml',
        {'object_workspace.enabled': True},
        'frozen',
        {'joint_limits', 'object_workspace'},
    ),
    ('four_finger_sphere.yaml', {**LINEAR, 'object_workspace.enabled': True}, 'ok', set()),
    ('four_finger_three_contacts.yaml', {}, 'frozen', {'joint_limits'}),
    # The filter's own mu far below the plant's: no squeeze holds the cube in its cones.
    (
        'paper_scenario.yaml',
        {'safety_filter_node/model.friction_coefficient': 0.01},
        'infeasible',
        None,
    ),
]


def _filter_and_state(scenario: str | Path, overrides: dict):
    """Return the filter node's filter and its model's state at rest at the initial grasp."""
    path = CONFIG / scenario
    sim = load_node_parameters(
        path, HAND_SIM_NODE, overrides=node_overrides(overrides, HAND_SIM_NODE)
    )
    params = _filter_parameters(scenario, overrides)
    model = GraspModel.from_parameters(params)
    p = np.asarray(sim['initial.object_position'], dtype=float)
    R = rotation_matrix(sim['initial.object_orientation'])
    q = model.project_to_contact(sim['initial.joint_positions'], p, R)
    state = model.state(0.0, q, np.zeros(model.n_joints), p, R, np.zeros(6))
    config = SafetyFilterConfig.from_parameters(params)
    return model, SafetyFilter.from_config(model, config), state


def _filter_parameters(scenario: str | Path, overrides: dict) -> dict:
    """Return the filter node's parameters of a scenario, with its overrides."""
    own = node_overrides(overrides, SAFETY_FILTER_NODE)
    return load_node_parameters(CONFIG / scenario, SAFETY_FILTER_NODE, overrides=own)


@pytest.mark.parametrize(('scenario', 'overrides', 'verdict', 'frozen'), CASES)
def test_advice_verdict_and_frozen_families(scenario, overrides, verdict, frozen):
    advice = scenario_advice(CONFIG / scenario, overrides)
    assert advice.verdict == verdict, advice.lines()
    if frozen is not None:
        assert set(advice.frozen) == frozen, advice.lines()
    assert bool(advice.suggestion) == bool(advice.frozen)
    assert advice.warns == (verdict != 'ok')


@pytest.mark.parametrize(('scenario', 'overrides'), [(c[0], c[1]) for c in CASES[:6]])
def test_allowance_is_the_rows_own_bound_at_rest(scenario, overrides):
    """At rest a row reads ``s x_ddot(u) >= -alpha_2(alpha_1(h))``.

    Its lower bound is ``-s x_ddot(0) - alpha_2(alpha_1(h))``: with alpha_2's gain doubled
    (the same state, so the same drift ``x_ddot(0)``) it drops by the allowance.
    """
    _, safety_filter, state = _filter_and_state(scenario, overrides)
    gain = SafetyFilterConfig.from_parameters(_filter_parameters(scenario, overrides)).alpha2_gain
    _, doubled, _ = _filter_and_state(scenario, {**overrides, 'barrier.alpha2.gain': 2.0 * gain})
    advice = startup_advice(safety_filter, state)
    assert advice.families
    one = {f.family: f for f in safety_filter.families}
    two = {f.family: f for f in doubled.families}
    for entry in advice.families:
        rows_one, rows_two = one[entry.family].rows(state), two[entry.family].rows(state)
        r = rows_one.names.index(entry.row)
        drop = rows_one.lower[r] - rows_two.lower[r]
        assert entry.acceleration == pytest.approx(drop, rel=1e-6, abs=1e-12)
        assert entry.margin == pytest.approx(one[entry.family].values(state).h[r], abs=1e-12)


@pytest.mark.parametrize(('k1', 'k2'), [(10.0, 10.0), (2.0, 10.0), (30.0, 40.0)])
def test_linear_tau_is_independent_of_the_margin(k1, k2):
    overrides = {**LINEAR, 'barrier.alpha1.gain': k1, 'barrier.alpha2.gain': k2}
    advice = scenario_advice(CONFIG / 'four_finger_box.yaml', overrides)
    for entry in advice.families:
        assert entry.tau == pytest.approx(1.0 / k1 + 1.0 / k2, rel=1e-9)
        assert entry.frozen == (1.0 / k1 + 1.0 / k2 > 1.0)


def test_suggestion_unfreezes_every_family():
    advice = scenario_advice(CONFIG / 'four_finger_box.yaml', {})
    assert advice.verdict == 'frozen'
    again = scenario_advice(CONFIG / 'four_finger_box.yaml', advice.suggestion)
    assert again.verdict == 'ok' and not again.suggestion, again.lines()


@pytest.mark.parametrize(
    ('overrides', 'metric'),
    [
        ({}, 'acceleration'),  # the example hand's inverse_inertia, frozen: suggested
        ({'qp.metric': 'identity'}, 'acceleration'),
        ({'qp.metric': 'acceleration'}, None),  # already chosen: not suggested again
    ],
)
def test_suggestion_names_the_acceleration_metric(overrides, metric):
    advice = scenario_advice(CONFIG / 'four_finger_box.yaml', overrides)
    assert advice.verdict == 'frozen'
    assert advice.suggestion.get('qp.metric') == metric


def _hard_qp_status(safety_filter: SafetyFilter, state, u_nom: np.ndarray) -> bool:
    """Return whether daqp finds the hard QP at ``state`` feasible (an independent solver)."""
    rows = safety_filter.constraint_rows(state)
    m = safety_filter.n_joints
    limits = safety_filter.actuator_limits
    A = np.vstack((rows.A, np.eye(m)))
    upper = np.concatenate((np.full(rows.A.shape[0], 1e30), limits.upper))
    lower = np.concatenate((rows.lower, limits.lower))
    sense = np.zeros(A.shape[0], dtype=np.int32)
    _, _, flag, _ = daqp.solve(np.eye(m), -u_nom, A, upper, lower, sense)
    return flag > 0


@pytest.mark.parametrize(('scenario', 'overrides', 'verdict'), [(c[0], c[1], c[2]) for c in CASES])
def test_rest_margin_agrees_with_an_independent_solver(scenario, overrides, verdict):
    """A positive margin: daqp solves the hard QP at rest; a negative one: it finds none."""
    _, safety_filter, state = _filter_and_state(scenario, overrides)
    advice = startup_advice(safety_filter, state)
    feasible = _hard_qp_status(safety_filter, state, np.zeros(safety_filter.n_joints))
    assert feasible == (advice.rest_margin > 0.0), advice.lines()
    assert (verdict == 'infeasible') == (not feasible)
    if not feasible:
        assert any(name.startswith('no_slip/') for name in advice.binding), advice.binding
        result = safety_filter.solve(state, np.zeros(safety_filter.n_joints))
        assert result.relaxed and np.all(np.isfinite(result.u))


def test_rest_margin_shrinks_with_the_gains():
    """The torque ball at rest grows with k1 k2 (the rows' allowance), here 1 -> 100."""
    margins = [
        scenario_advice(CONFIG / 'four_finger_box.yaml', {**LINEAR, 'barrier.alpha1.gain': k,
                                                          'barrier.alpha2.gain': k}).rest_margin
        for k in (1.0, 10.0)
    ]  # fmt: skip
    assert 0.0 < margins[0] < margins[1]


def test_rest_state_has_no_velocity():
    model, _, state = _filter_and_state('paper_scenario.yaml', {})
    moving = model.state(0.0, state.q, np.ones(model.n_joints), state.p_object_in_palm,
                         state.R_object_to_palm, np.ones(6))  # fmt: skip
    rest = rest_state(model, moving)
    assert not rest.dq.any() and not rest.twist_object.any()
    np.testing.assert_array_equal(rest.q, state.q)


def test_node_logs_the_advice_once_per_configuration():
    model, safety_filter, state = _filter_and_state('paper_scenario.yaml', {})
    log = StartupLog(model)
    assert log.take(safety_filter) == []
    log.first_state(state)
    log.first_state(state)
    lines = log.take(safety_filter)
    assert lines and all(line.text.startswith(PREFIX) for line in lines)
    assert {line.level for line in lines} == {DiagnosticLevel.WARN}
    assert any('joint_limits' in line.text and 'frozen' in line.text for line in lines)
    log.first_state(state)
    assert log.take(safety_filter) == []  # once
    log.again()
    log.first_state(state)
    assert len(log.take(safety_filter)) == len(lines)


def test_model_report_prints_the_advice(capsys):
    assert model_report_main(['--config', str(CONFIG / 'four_finger_box.yaml'),
                              '--set', 'barrier.alpha1.kind=linear']) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert 'start-up advice' in out and 'QP at rest: feasible' in out
    assert 'joint_limits: smallest margin' in out
    assert math.isfinite(float(out.split('margin of ')[1].split()[0]))


@pytest.mark.parametrize('index', [17, 71, 80])
def test_rest_margin_on_generated_hands_with_light_fingers(tmp_path, index):
    """Rows of norms 1 to ~5e5 (light fingers' joint accelerations): the margin is still found.

    Hands of seed 0 that HiGHS could not solve with the rows unscaled; daqp, an independent
    solver, agrees on feasibility at rest.
    """
    scenario = generate_hand(0, index, tmp_path / f'hand_{index:03d}').scenario
    _, safety_filter, state = _filter_and_state(scenario, {})
    advice = startup_advice(safety_filter, state)
    assert math.isfinite(advice.rest_margin), advice.lines()
    assert advice.binding and all('/' in name for name in advice.binding)
    feasible = _hard_qp_status(safety_filter, state, np.zeros(safety_filter.n_joints))
    assert feasible == (advice.rest_margin > 0.0), advice.lines()


def _grasp_acceleration_norm(state, u: np.ndarray) -> float:
    """``|a(u)|`` in the kinetic-energy norm of hand and object, ``sqrt(a^T M a)``."""
    a_h = state.joint_acceleration.matrix @ u + state.joint_acceleration.offset
    a_o = state.object_acceleration.matrix @ u + state.object_acceleration.offset
    return float(np.sqrt(a_h @ state.M_h @ a_h + a_o @ state.M_o @ a_o))


def _least_acceleration_by_osqp(safety_filter: SafetyFilter, state) -> np.ndarray:
    """u_still from the acceleration's own quadratic, by OSQP (an independent solver).

    ``c (|a_h|^2_M_h + |a_o|^2_M_o + 1e-4 |u|^2_M_h^-1)`` with ``a = S u + s``: the cost
    the advice writes as a metric around an unconstrained minimiser, here expanded.
    """
    S_h, s_h = state.joint_acceleration.matrix, state.joint_acceleration.offset
    S_o, s_o = state.object_acceleration.matrix, state.object_acceleration.offset
    M_h, M_o = state.M_h, state.M_o
    P = S_h.T @ M_h @ S_h + S_o.T @ M_o @ S_o + 1e-4 * np.linalg.inv(M_h)
    q = S_h.T @ M_h @ s_h + S_o.T @ M_o @ s_o
    rows = [f.rows(state) for f in safety_filter.families if f.family != 'torque_rate']
    A = np.vstack([r.A for r in rows])
    scale = np.linalg.norm(A, axis=1)[:, np.newaxis]  # rows of norm 1 to ~1e6: scaled
    m = safety_filter.n_joints
    limits = safety_filter.actuator_limits
    solver = osqp.OSQP()
    solver.setup(
        sparse.csc_matrix(np.triu(0.5 * (P + P.T))), q,
        sparse.csc_matrix(np.vstack((A / scale, np.eye(m)))),
        np.concatenate((np.concatenate([r.lower for r in rows]) / scale[:, 0], limits.lower)),
        np.concatenate((np.full(A.shape[0], np.inf), limits.upper)),
        eps_abs=1e-10, eps_rel=1e-10, max_iter=200000, polishing=True, verbose=False,
    )  # fmt: skip
    result = solver.solve(raise_error=False)
    assert result.info.status == 'solved', result.info.status
    return result.x


# scenario (a config file, or a generated hand of seed 0), overrides, held still
STILL_CASES = [
    ('four_finger_box.yaml', LINEAR, True),
    ('paper_scenario.yaml', LINEAR, True),
    (0, LINEAR, True),
    # finger2's friction cone at its apex and thumb_joint2 at its effort limit: no squeeze
    # holds this cube still.
    (426, LINEAR, False),
]


def _still_case(scenario, overrides, tmp_path):
    if isinstance(scenario, int):
        scenario = generate_hand(0, scenario, tmp_path / f'hand_{scenario:03d}').scenario
    return _filter_and_state(scenario, overrides)


@pytest.mark.parametrize(('scenario', 'overrides', 'still'), STILL_CASES)
def test_still_acceleration_agrees_with_an_independent_solver(
    scenario, overrides, still, tmp_path
):
    _, safety_filter, state = _still_case(scenario, overrides, tmp_path)
    advice = startup_advice(safety_filter, state)
    u = _least_acceleration_by_osqp(safety_filter, state)
    a_h = state.joint_acceleration.matrix @ u + state.joint_acceleration.offset
    assert advice.still_acceleration == pytest.approx(np.abs(a_h).max(), rel=1e-2, abs=1e-3)
    assert (advice.still_acceleration <= STILL_ACCELERATION) == still, advice.lines()
    assert (advice.verdict == 'moving') == (not still), advice.lines()
    answer = 'yes' if still else 'no'
    assert any(line.startswith(f'held still: {answer}') for line in advice.lines())


@pytest.mark.parametrize('scenario', [s[0] for s in STILL_CASES])
def test_no_filtered_torque_at_rest_accelerates_the_grasp_less(scenario, tmp_path):
    """Whatever u_nom, the filter's answer at rest moves the grasp at least as u_still does."""
    overrides = {**LINEAR, 'qp.metric': 'acceleration'}
    _, safety_filter, state = _still_case(scenario, overrides, tmp_path)
    least = _grasp_acceleration_norm(state, _least_acceleration_by_osqp(safety_filter, state))
    rng = np.random.default_rng(3)
    limits = safety_filter.actuator_limits
    for _ in range(10):
        u_nom = rng.uniform(limits.lower, limits.upper) * 0.3
        result = safety_filter.solve(state, u_nom)
        assert not result.relaxed
        assert _grasp_acceleration_norm(state, result.u) >= least * (1.0 - 1e-6)
