"""The filter step's fused pass against the unfused step, field by field.

A filter whose :class:`~grasp_safety_filter.control.fused_tick.FusedTick` is removed runs
today's calls one by one; both filters see the same ticks (a rolling grasp 1 ms apart, with
jumps where the last active set is no longer optimal) and must give the same results to
the bit, and leave their backends in the same state.
"""

from __future__ import annotations

from grasp_states import CONFIG_DIR, Configuration, moved, paper_model, random_configuration
import numpy as np
import pinocchio as pin
import pytest
from random_hands import random_hand

from grasp_safety_filter.control import fused_tick
from grasp_safety_filter.control.filter_config import SafetyFilterConfig
from grasp_safety_filter.control.safety_filter import SafetyFilter
from grasp_safety_filter.model.grasp_check import load_initial_grasp
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.quaternion import rotation_matrix
from grasp_tools.bench.recorded_run import record_filtered_run, Scenario

TICKS = 60


def _paper(rng, **overrides):
    model = paper_model(**overrides)
    return model, lambda: random_configuration(model, rng)


def _paper_soft(rng):
    """Soft fingers: 4n wrench rows, two no-slip rows per face (torsion + and -)."""
    return _paper(rng, **{'model.torsional_friction': 0.005})


def _near(model, q0, p0, R0, rng, spread):
    """Return a rolling grasp near ``(q0, p0, R0)``, fingertips projected onto the object."""
    while True:
        p_object = p0 + rng.uniform(-0.003, 0.003, 3)
        R_object = pin.exp3(rng.uniform(-spread, spread, 3)) @ R0
        try:
            q = model.project_to_contact(
                q0 + rng.uniform(-spread, spread, q0.size), p_object, R_object
            )
        except ValueError:
            continue
        if np.any(q <= model.joint_lower_limits) or np.any(q >= model.joint_upper_limits):
            continue
        twist = rng.normal(0.0, 0.3, 6) * np.array([0.03, 0.03, 0.03, 1.0, 1.0, 1.0])
        dq = model.rolling_joint_velocity(q, p_object, R_object, twist)
        return Configuration(q, dq, p_object, R_object, twist)


def _four_finger(rng, config='four_finger_box.yaml'):
    model, params = load_initial_grasp(CONFIG_DIR / config)
    q0 = np.array(params['initial.joint_positions'])
    p0 = np.array(params['initial.object_position'])
    R0 = rotation_matrix(params['initial.object_orientation'])
    return model, lambda: _near(model, q0, p0, R0, rng, 0.05)


def _random_box_hand(rng, tmp_path):
    hand = random_hand(4)  # an even seed: a box
    path = hand.write(tmp_path)
    parameters = {**hand.model_parameters(path), **hand.initial_parameters()}
    model = GraspModel.from_parameters(parameters)
    return model, lambda: _near(model, hand.q0, hand.p_object, hand.R_object, rng, 0.03)


HANDS = {
    'paper': _paper,
    'paper soft': _paper_soft,
    'four_finger': _four_finger,
    'four_finger_sphere': lambda rng: _four_finger(rng, 'four_finger_sphere.yaml'),
    'random_box': _random_box_hand,
}
CONFIGS = {
    'default': {},
    'gains 10': {'alpha1_gain': 10.0, 'alpha2_gain': 10.0},
    'joint limits only': {'no_slip_enabled': False, 'fingertip_workspace_enabled': False},
    'object workspace': {'object_workspace_enabled': True},
}


def _assert_same(fused, unfused, tick):
    where = f'tick {tick}'
    assert fused.status == unfused.status, where
    np.testing.assert_array_equal(fused.u, unfused.u, err_msg=where)
    assert not fused.u.flags.writeable
    assert fused.relaxed == unfused.relaxed, where
    assert fused.relaxed_families == unfused.relaxed_families, where
    assert fused.iterations == unfused.iterations, where
    assert fused.active_set_steps == unfused.active_set_steps, where
    assert fused.max_violation == unfused.max_violation, where
    assert fused.active == unfused.active, where
    assert fused.margins.names == unfused.margins.names
    np.testing.assert_array_equal(
        np.array(list(fused.margins.values())), np.array(list(unfused.margins.values())),
        err_msg=where,
    )


def _assert_same_metric(fused, unfused):
    """Check what the metric's part of a tick writes: R, q, and the backend's form in y."""
    np.testing.assert_array_equal(fused.problem.metric_factor, unfused.problem.metric_factor)
    np.testing.assert_array_equal(fused.hard_qp.q, unfused.hard_qp.q)
    np.testing.assert_array_equal(fused.hard_qp.nominal, unfused.hard_qp.nominal)
    a, b = fused.backend, unfused.backend
    if a._R is not None or b._R is not None:
        np.testing.assert_array_equal(a._R, b._R)
        np.testing.assert_array_equal(a._rows_y, b._rows_y)
        np.testing.assert_array_equal(a._y_nom, b._y_nom)


METRIC_CASES = [
    (hand, config, 'identity') for hand in HANDS for config in CONFIGS
] + [
    (hand, config, 'inverse_inertia')
    for hand in ('four_finger', 'four_finger_sphere', 'random_box')
    for config in CONFIGS
]


def _fused_and_unfused(make_filter, monkeypatch):
    """Return two filters, the second never fused, and the fused pass's outcomes as it runs.

    Each outcome is ``(outcome, guessed)``: guessed when the pass tried a last active set.
    """
    fused, unfused = make_filter(), make_filter()
    assert fused._fused is not None
    unfused._fused = None
    outcomes = []

    def spy(original):
        def spied(*args):
            answer = original(*args)
            outcomes.append((answer[0], args[-2][0].shape[0] > 0))  # args[-2]: the guess
            return answer

        return spied

    for name in ('packed_tick', 'packed_tick_metric'):
        monkeypatch.setattr(fused_tick, name, spy(getattr(fused_tick, name)))
    return fused, unfused, outcomes


@pytest.mark.parametrize(('hand', 'config', 'metric'), METRIC_CASES)
def test_the_fused_pass_gives_the_unfused_results(hand, config, metric, tmp_path, monkeypatch):
    rng = np.random.default_rng(17)
    model, configuration = (
        HANDS[hand](rng, tmp_path) if hand == 'random_box' else HANDS[hand](rng)
    )
    settings = SafetyFilterConfig(metric=metric, **CONFIGS[config])
    fused, unfused, outcomes = _fused_and_unfused(
        lambda: SafetyFilter.from_config(model, settings), monkeypatch
    )
    m = fused.n_joints
    c = configuration()
    u_nom = rng.normal(0.0, 0.2, m)
    for tick in range(TICKS):
        if tick % 15 == 14:  # a jump: the last active set is no longer the optimum's
            c, u_nom = configuration(), rng.normal(0.0, 0.5, m)
        else:
            c = moved(c, 1e-3)
            u_nom = u_nom + rng.normal(0.0, 0.01, m)
        state = c.state(model, tick * 1e-3)
        assert state.packed_terms is not None
        if tick % 10 == 5:  # a W of the last R in the hard QP's q (as its dense form leaves)
            fused.hard_qp.dense()
            unfused.hard_qp.dense()
        _assert_same(fused.solve(state, u_nom), unfused.solve(state, u_nom), tick)
        _assert_same_metric(fused, unfused)
        np.testing.assert_array_equal(fused.problem.A, unfused.problem.A)
        np.testing.assert_array_equal(fused.problem.lower, unfused.problem.lower)
        np.testing.assert_array_equal(fused.problem.g, unfused.problem.g)
        assert fused.backend._last_active == unfused.backend._last_active
        np.testing.assert_array_equal(fused._last_good_u, unfused._last_good_u)
    assert len(outcomes) == TICKS
    # Else the guess is rarely optimal; the random paper grasps put contacts off their
    # faces' shrunk boxes, so with the object workspace every tick is relaxed.
    if config == 'gains 10' or (hand.startswith('paper') and config != 'object workspace'):
        assert any(outcome == fused_tick.SETTLED_ON_GUESS for outcome, _ in outcomes)
        assert any(not outcome and guessed for outcome, guessed in outcomes)  # rejected


@pytest.mark.parametrize(
    ('config', 'overrides'),
    [
        ('four_finger_sphere.yaml', {}),
        ('four_finger_box.yaml', {'object_workspace.enabled': True}),
    ],
)
def test_a_recorded_run_with_the_object_workspace_settles_in_the_pass(
    config, overrides, monkeypatch
):
    """Ticks of the closed loop, where the last active set is usually optimal."""
    scenario = Scenario.load(CONFIG_DIR / config, filter_overrides=overrides)
    assert scenario.filter_config.object_workspace_enabled
    ticks = record_filtered_run(scenario, 0.2)[0]
    fused, unfused, outcomes = _fused_and_unfused(scenario.safety_filter, monkeypatch)
    for k, tick in enumerate(ticks):
        sample = (tick.q, tick.dq, tick.p_object_in_palm, tick.R_object_to_palm)
        state = scenario.model.state(tick.t, *sample, tick.twist_object)
        _assert_same(fused.solve(state, tick.u_nom), unfused.solve(state, tick.u_nom), k)
        np.testing.assert_array_equal(fused.problem.A, unfused.problem.A)
    settled = [outcome for outcome, _ in outcomes if outcome == fused_tick.SETTLED_ON_GUESS]
    assert len(settled) > len(ticks) // 2


@pytest.mark.parametrize('metric', ['identity', 'inverse_inertia'])
def test_a_nominal_torque_inside_every_row_is_settled_by_the_pass(metric):
    model = paper_model()
    settings = SafetyFilterConfig(metric=metric, **CONFIGS['joint limits only'])
    fused, unfused, reference = (SafetyFilter.from_config(model, settings) for _ in range(3))
    unfused._fused = None
    rng = np.random.default_rng(3)
    nominal = 0
    for tick in range(10):
        state = random_configuration(model, rng, speed=0.05).state(model, tick * 1e-3)
        # Another filter's u*: often strictly inside every row (then it is u* here too).
        u_nom = reference.solve(state, rng.normal(0.0, 0.3, fused.n_joints)).u
        result = fused.solve(state, u_nom)
        _assert_same(result, unfused.solve(state, u_nom), tick)
        _assert_same_metric(fused, unfused)
        nominal += result.status == 'nominal'
    assert nominal >= 2


def test_bad_inputs_are_refused_by_name_before_any_compiled_pass():
    model = paper_model()
    f = SafetyFilter.from_config(model, SafetyFilterConfig(metric='identity'))
    state = random_configuration(model, np.random.default_rng(2)).state(model)
    with pytest.raises(ValueError, match='u_nom: expected shape'):
        f.solve(state, np.zeros(f.n_joints + 1))
    with pytest.raises(ValueError, match='u_nom: non-finite'):
        f.solve(state, np.full(f.n_joints, np.nan))
    other, _ = _four_finger(np.random.default_rng(0))
    c = _near(other, *_initial(other), np.random.default_rng(0), 0.01)
    with pytest.raises(ValueError, match='state: expected'):
        f.solve(c.state(other), np.zeros(f.n_joints))


def _initial(model):
    _, params = load_initial_grasp(CONFIG_DIR / 'four_finger_box.yaml')
    return (
        np.array(params['initial.joint_positions']),
        np.array(params['initial.object_position']),
        rotation_matrix(params['initial.object_orientation']),
    )


def test_no_fused_pass_with_another_backend():
    model = paper_model()
    assert SafetyFilter.from_config(model, SafetyFilterConfig(metric='identity'))._fused
    assert SafetyFilter.from_config(model, SafetyFilterConfig(metric='inverse_inertia'))._fused
    for settings in (
        SafetyFilterConfig(metric='identity', solver='daqp'),
        SafetyFilterConfig(metric='identity', torque_rate_enabled=True),
    ):
        assert SafetyFilter.from_config(model, settings)._fused is None
