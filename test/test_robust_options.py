"""Filter options for a plant that is not the filter's model: torque rate, friction margin, cone.

The rows are checked against their inequalities written out here (membership tests that do
not use the rows), the filter with the torque-rate rows against the exact QP reference, and
the closed loop on our plant for the step bound per tick.
"""

import dataclasses
from dataclasses import replace
import json
from pathlib import Path

import numpy as np
import pytest
from qp_reference import hard_optimum
from scipy.optimize import nnls
from synthetic_state import synthetic_state, SyntheticHand
from test_safety_filter import independent_rows

from grasp_safety_filter.control.constraints import FrictionPyramid, TorqueRateBound
from grasp_safety_filter.control.constraints.friction_cone import DIAMOND, INSCRIBED
from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.filter_result import FilterStatus
from grasp_safety_filter.control.nominal import NominalController
from grasp_safety_filter.control.safety_filter import SafetyFilter
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.model.affine import AffineMap
from grasp_tools import mujoco_compare, mujoco_run
from grasp_tools.bench.command_line import bench_main, bench_parser
from grasp_tools.bench.recorded_run import Scenario
from grasp_tools.closed_loop import DURATION, run_closed_loop
from hand_sim_node.plant import RigidPlant

HAND = SyntheticHand()
M = HAND.n_joints
CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
CERTIFIED = {FilterStatus.NOMINAL, FilterStatus.SOLVED}


# -- torque rate ---------------------------------------------------------------------------


@pytest.mark.parametrize('max_step', [0.01, 0.2, 3.0])
def test_torque_rate_rows_hold_exactly_when_every_step_is_within_the_bound(max_step):
    family = TorqueRateBound(('j0', 'j1', 'j2'), max_step)
    rng = np.random.default_rng(int(100 * max_step))
    assert np.all(family.rows().residual(rng.normal(size=3) * 100) == 0.0)  # no previous u
    for _ in range(500):
        u_prev = rng.normal(size=3)
        family.remember(u_prev)
        u = u_prev + rng.uniform(-2.0, 2.0, size=3) * max_step
        rows = family.rows()
        assert rows.names[:2] == ('torque_rate/j0/decrease', 'torque_rate/j0/increase')
        inside = np.all(np.abs(u - u_prev) <= max_step)
        assert (rows.residual(u).min() >= 0.0) == inside
        np.testing.assert_allclose(
            rows.residual(u).reshape(3, 2),
            np.column_stack((max_step + (u - u_prev), max_step - (u - u_prev))),
            atol=1e-12,
        )
        np.testing.assert_array_equal(family.values(None, u).h, rows.residual(u))
    family.forget()
    assert np.all(family.rows().A == 0.0) and np.all(family.rows().lower == 0.0)


class TimedState:
    """The one field the torque-rate rows read with a rate bound: the state's time."""

    def __init__(self, t):
        self.t = t


@pytest.mark.parametrize(('max_step', 'max_rate'), [(0.2, 50.0), (0.01, 50.0), (3.0, 0.5)])
def test_torque_rate_per_second_bounds_the_step_by_the_elapsed_time(max_step, max_rate):
    """|u - u_prev| <= min(max_step, max_rate (t - t_prev)), written out; time back: none."""
    family = TorqueRateBound(('j0', 'j1'), max_step, max_rate)
    rng = np.random.default_rng(int(10 * max_rate))
    limited = {'rate': 0, 'step': 0}
    for _ in range(400):
        u_prev, t_prev = rng.normal(size=2), rng.uniform(0.0, 10.0)
        family.remember(u_prev, t_prev)
        elapsed = rng.choice([0.0, 1e-3, 2e-3, 0.05, 1.0]) * rng.uniform(0.5, 1.5)
        bound = min(max_step, max_rate * elapsed)
        limited['rate' if max_rate * elapsed < max_step else 'step'] += 1
        u = u_prev + rng.uniform(-2.0, 2.0, size=2) * max(bound, 1e-3)
        rows = family.rows(TimedState(t_prev + elapsed))
        inside = np.all(np.abs(u - u_prev) <= bound)
        assert (rows.residual(u).min() >= -1e-12) == inside
        np.testing.assert_allclose(
            rows.residual(u).reshape(2, 2),
            np.column_stack((bound + (u - u_prev), bound - (u - u_prev))),
            atol=1e-12,
        )
        assert np.all(family.rows(TimedState(t_prev - 1e-3)).A == 0.0)  # time went back
    assert min(limited.values()) > 0 or max_rate * 1.5 < max_step
    with pytest.raises(ValueError, match='max_rate'):
        family.rows(None)
    with pytest.raises(ValueError, match='t_previous'):
        family.remember(np.zeros(2))


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'max_step': 0.0}, 'max_step'),
        ({'max_step': -1.0}, 'max_step'),
        ({'max_step': float('nan')}, 'max_step'),
        ({'max_step': 0.2, 'max_rate': -1.0}, 'max_rate'),
        ({'max_step': 0.2, 'max_rate': float('inf')}, 'max_rate'),
    ],
)
def test_torque_rate_refuses_a_bad_bound(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TorqueRateBound(('j0',), **kwargs)


def test_torque_rate_weight_above_a_safety_weight_is_refused():
    with pytest.raises(ParameterError, match=r'relaxation\.torque_rate_weight.*fingertip'):
        replace(PAPER_CONFIG, torque_rate_enabled=True, torque_rate_weight=2e3)
    replace(PAPER_CONFIG, torque_rate_enabled=False, torque_rate_weight=2e3)  # unused: accepted


@pytest.mark.parametrize('max_step', [0.05, 0.3])
def test_filter_with_torque_rate_is_the_exact_optimum_with_the_previous_u(max_step):
    """A sequence of random states and nominal torques: each tick against the reference."""
    config = replace(PAPER_CONFIG, torque_rate_enabled=True, torque_rate_max_step=max_step)
    filter_ = SafetyFilter.from_config(HAND, config)
    rng = np.random.default_rng(int(1000 * max_step))
    u_prev = None
    lo, hi = HAND.joint_lower_limits, HAND.joint_upper_limits
    q0 = lo + 0.5 * (hi - lo)
    counts = {'bound_active': 0, 'feasible': 0, 'first': 0}
    for tick in range(200):
        if tick == 100:
            filter_.reset()
            u_prev = None
        # Slowly moving joints (the rows change little from tick to tick), jumping u_nom.
        q = q0 + 0.2 * (hi - lo) * np.sin(3e-3 * tick)
        state = synthetic_state(np.random.default_rng(7), HAND, speed=0.0, q=q, dq=0.0 * q)
        rows = independent_rows(config, state)
        u_nom = state.gravity_torque + rng.normal(scale=1.0, size=M)
        if u_prev is not None:  # |u - u_prev| <= max_step, written from the inequality
            A = np.vstack((np.eye(M), -np.eye(M)))
            lower = np.concatenate((u_prev - max_step, -u_prev - max_step))
            rows = rows._replace(
                A=np.vstack((rows.A, A)), lower=np.concatenate((rows.lower, lower))
            )
        else:
            counts['first'] += 1
        result = filter_.solve(state, u_nom)
        box = np.full(M, HAND.effort)
        feasible, u_reference = hard_optimum(rows.A, rows.lower, u_nom, -box, box)
        if feasible:
            counts['feasible'] += 1
            assert result.status in CERTIFIED, (tick, result.status)
            assert np.abs(result.u - u_reference).max() <= 1e-5, tick
            if u_prev is not None and np.abs(result.u - u_prev).max() >= max_step - 1e-6:
                counts['bound_active'] += 1
        else:
            assert result.status is FilterStatus.RELAXED
        u_prev = None if result.status.value.startswith('fallback') else result.u.copy()
    assert counts['first'] == 2 and counts['feasible'] >= 100 and counts['bound_active'] >= 20


@pytest.fixture(scope='module')
def scenario():
    return Scenario.load(CONFIG)


def largest_step_on_our_plant(scenario, overrides, duration=1.5):
    config = dataclasses.replace(scenario.filter_config, **overrides)
    plant = RigidPlant(scenario.model, scenario.sim_config)
    run = run_closed_loop(
        plant,
        NominalController(scenario.nominal_config),
        scenario.reference(plant.observe()),
        SafetyFilter.from_config(scenario.model, config),
        duration,
    )
    assert run.stop_reason == DURATION
    statuses = [tick.status for tick in run.ticks]
    return mujoco_run.max_torque_step(run.array('u')), statuses


@pytest.mark.parametrize(
    'bound',
    [
        {'torque_rate_max_step': 0.004},
        # 4 N·m/s over the 1 ms control period, max_step far looser.
        {'torque_rate_max_step': 1.0, 'torque_rate_max_rate': 4.0},
    ],
)
def test_closed_loop_torque_step_per_tick_is_bounded(scenario, bound):
    """The paper's run on our plant: without the bound u* jumps; with it, never more."""
    free, _ = largest_step_on_our_plant(scenario, {})
    assert scenario.sim_config.time_step == 1e-3
    bound_per_tick = 0.004
    assert free > 2 * bound_per_tick  # the check below could fail
    bounded, statuses = largest_step_on_our_plant(scenario, {'torque_rate_enabled': True, **bound})
    assert not any(status.value.startswith('fallback') for status in statuses)
    assert bounded <= bound_per_tick + 1e-6, bounded


# -- friction margin and cone shape --------------------------------------------------------


class ForceState:
    """The one field the no-slip rows read: contact forces f_c(u) = u (one contact)."""

    n_contacts = 1
    contact_force = AffineMap(np.eye(3), np.zeros(3))


def inside_rows(family, force):
    return family.rows(ForceState()).residual(force).min() >= 0.0


def in_mujoco_pyramid(force, mu):
    """Whether f is a non-negative combination of the edges (+-mu, 0, 1), (0, +-mu, 1)."""
    edges = np.array([[mu, 0, 1], [-mu, 0, 1], [0, mu, 1], [0, -mu, 1]], dtype=float).T
    _, residual = nnls(edges, force)
    return residual <= 1e-9


def random_forces(rng, count, mu):
    direction = rng.uniform(0.0, 2.0 * np.pi, count)
    ratio = rng.uniform(0.0, 1.6 * mu, count)  # tangential / normal
    f_n = rng.uniform(0.1, 5.0, count)
    return np.column_stack((ratio * f_n * np.cos(direction), ratio * f_n * np.sin(direction), f_n))


@pytest.mark.parametrize('margin', [0.0, 0.1, 0.3])
@pytest.mark.parametrize('mu', [0.4, 1.0])
def test_diamond_rows_are_the_pyramid_of_the_reduced_friction(mu, margin):
    family = FrictionPyramid(('c',), mu, 8, 0.0, margin, DIAMOND)
    assert len(family.names) == 4
    forces = random_forces(np.random.default_rng(int(10 * mu + 100 * margin)), 2000, mu)
    agree = [inside_rows(family, f) == in_mujoco_pyramid(f, mu * (1.0 - margin)) for f in forces]
    assert all(agree)
    inside = [inside_rows(family, f) for f in forces]
    assert 300 <= sum(inside) <= 1700
    assert all(in_mujoco_pyramid(f, mu) for f, ok in zip(forces, inside, strict=True) if ok)


@pytest.mark.parametrize('margin', [0.0, 0.1, 0.3])
@pytest.mark.parametrize('faces', [4, 8, 16])
def test_inscribed_rows_with_a_margin_keep_the_force_in_the_reduced_circular_cone(faces, margin):
    mu = 0.8
    family = FrictionPyramid(('c',), mu, faces, 0.0, margin, INSCRIBED)
    forces = random_forces(np.random.default_rng(faces), 3000, mu)
    inside = np.array([inside_rows(family, f) for f in forces])
    tangential = np.hypot(forces[:, 0], forces[:, 1])
    reduced = mu * (1.0 - margin)
    assert np.all(tangential[inside] <= reduced * forces[inside, 2] * (1 + 1e-12))
    # and it is the inscribed pyramid: inside the inner circle means inside the rows
    inner = tangential <= reduced * np.cos(np.pi / faces) * forces[:, 2] * (1 - 1e-12)
    assert np.all(inside[inner]) and inner.sum() > 300


def test_inscribed_pyramid_is_not_inside_a_pyramidal_contact_cone_the_diamond_is():
    """The claim behind ``no_slip.cone: diamond``: a vertex of the 8-face pyramid is outside."""
    mu = 1.0
    vertex = np.array([0.999 * np.cos(np.pi / 8), 0.999 * np.sin(np.pi / 8), 1.0])  # radius mu
    assert inside_rows(FrictionPyramid(('c',), mu, 8), vertex)
    assert not in_mujoco_pyramid(vertex, mu)
    assert not inside_rows(FrictionPyramid(('c',), mu, 8, 0.0, 0.0, DIAMOND), vertex)


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'friction_margin': -0.1}, 'friction_margin'),
        ({'friction_margin': 0.95}, 'friction_margin'),
        ({'cone': 'elliptic'}, "'cone'"),
    ],
)
def test_friction_options_refuse_bad_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        FrictionPyramid(('c',), 0.5, 8, 0.0, **kwargs)


def test_filter_options_reach_the_rows():
    config = replace(
        PAPER_CONFIG,
        cone='diamond',
        friction_margin=0.2,
        fingertip_workspace_enabled=False,
        joint_limits_enabled=False,
    )
    filter_ = SafetyFilter.from_config(HAND, config)
    assert len(filter_.row_names) == 4 * len(HAND.contact_names)
    state = synthetic_state(np.random.default_rng(3), HAND, speed=0.0)
    reference = FrictionPyramid(
        HAND.contact_names, HAND.friction_coefficient, 8, 0.01, 0.2, DIAMOND
    )
    rows = filter_.constraint_rows(state)
    np.testing.assert_allclose(rows.A, reference.rows(state).A)
    np.testing.assert_allclose(rows.lower, reference.rows(state).lower)


def test_measurement_command_takes_filter_overrides(tmp_path):
    out = tmp_path / 'figures.json'
    argv = [
        '--config',
        str(CONFIG),
        '--mode',
        'filtered',
        '--duration',
        '0.02',
        '--json',
        str(out),
        '--set',
        'torque_rate.enabled=true',
        '--set',
        'torque_rate.max_step=0.01',
    ]
    assert mujoco_run.main(argv) == 0
    figures = json.loads(out.read_text())
    overrides = {'torque_rate.enabled': True, 'torque_rate.max_step': 0.01}
    assert figures['filter_overrides'] == overrides
    assert figures['filtered']['max_torque_step_Nm'] <= 0.01 + 1e-6
    assert mujoco_run.main(['--config', str(CONFIG), '--set', 'no_such=1']) != 0


@pytest.mark.parametrize(
    ('main', 'parse', 'option', 'dest'),
    [
        (mujoco_run.main, mujoco_run.parse_args, '--set', 'set'),
        (mujoco_run.main, mujoco_run.parse_args, '--plant-set', 'plant_set'),
        (mujoco_compare.main, None, '--plant-set', None),
        (bench_main, lambda argv: bench_parser().parse_args(argv), '--set', 'overrides'),
    ],
)
def test_measurement_commands_read_overrides_as_a_parameter_file_does(
    main, parse, option, dest, capsys
):
    """The tools type ``NAME=VALUE`` as grasp-demo does: ``1e-5`` a double, ``[..]`` a list."""
    if dest is not None:
        parsed = parse([option, 'osqp.eps_abs=1e-5', option, 'x=[0.1, 2]'])
        assert getattr(parsed, dest) == [('osqp.eps_abs', 1e-5), ('x', [0.1, 2])]
    with pytest.raises(SystemExit) as exit_info:
        main([option, 'model.torsional_friction'])
    assert exit_info.value.code == 2
    assert "expected NAME=VALUE, got 'model.torsional_friction'" in capsys.readouterr().err


def test_measurement_command_runs_the_same_loop_on_our_plant(tmp_path):
    """``--plant rigid``: the filtered run's ticks equal the closed loop's on our plant."""
    out = tmp_path / 'figures.json'
    argv = [
        '--config',
        str(CONFIG),
        '--mode',
        'filtered',
        '--duration',
        '0.05',
        '--plant',
        'rigid',
        '--json',
        str(out),
    ]
    assert mujoco_run.main(argv) == 0
    run = json.loads(out.read_text())['filtered']
    assert run['stop_reason'] == DURATION and run['violation_steps'] == {}
    assert sum(run['filter_statuses'].values()) == 50
    scenario = Scenario.load(CONFIG)
    step, _ = largest_step_on_our_plant(scenario, {}, duration=0.05)
    assert run['max_torque_step_Nm'] == step
