"""Every QP backend on the same table of problems: random real grasps, hard and relaxed.

The problems are the filter's rows at random grasps of the paper's hand (rolling, near and
far from the limits), with u_nom drawn around the centre of the largest ball inside the
feasible set (an LP) so that a third of the hard problems are feasible with u_nom inside,
a third feasible with rows active and the rest infeasible. Each backend answers them in one
warm-started sequence and cold (a fresh backend per problem); the answers are compared with
two independent exact solvers (:mod:`qp_reference`), and their rows measured by the
:class:`Solution` itself. Every table is solved with both cost metrics (``qp.metric``): the
identity, and the inverse inertia, whose reference cost ``W = (tr(M_h)/m) M_h^-1`` is
formed here from the state's M_h with numpy's inverse; and the tables include grasps of the
16-joint example hand (config/four_finger_box.yaml), where M_h couples the fingers' joints.
"""

from collections import Counter
from dataclasses import replace

from grasp_states import (
    CONFIG_DIR,
    Configuration,
    moved,
    paper_model,
    random_configuration,
)
import numpy as np
import pinocchio as pin
import pytest
from qp_reference import chebyshev_radius, hard_optimum, relaxed_optimum

from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.qp import write_inertia_factor
from grasp_safety_filter.control.qp_solvers import (
    BACKENDS,
    Problem,
    SolutionStatus,
)
from grasp_safety_filter.control.safety_filter import SafetyFilter, SafetyFilterConfig
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.model.grasp_check import load_initial_grasp
from grasp_safety_filter.model.quaternion import rotation_matrix

N_PROBLEMS = 120
TOLERANCE = 1e-6  # N·m per N·m of |u_nom|: torque, KKT residuals
METRICS = ('identity', 'inverse_inertia')
EXAMPLE_HAND = CONFIG_DIR / 'four_finger_box.yaml'


def inverse_inertia(M_h):
    """Return the reference metric ``W = (tr(M_h)/m) M_h^-1``, with numpy's inverse."""
    return np.trace(M_h) / M_h.shape[0] * np.linalg.inv(M_h)


class ExampleHand:
    """Random rolling grasps of the 16-joint example hand around its scenario's grasp."""

    def __init__(self):
        self.model, params = load_initial_grasp(EXAMPLE_HAND)
        self.q0 = np.array(params['initial.joint_positions'])
        self.p0 = np.array(params['initial.object_position'])
        self.R0 = rotation_matrix(params['initial.object_orientation'])

    def random_configuration(self, rng, spread, speed):
        model = self.model
        while True:
            p_object = self.p0 + rng.uniform(-0.003, 0.003, 3)
            R_object = pin.exp3(rng.uniform(-spread, spread, 3)) @ self.R0
            q_guess = self.q0 + rng.uniform(-spread, spread, self.q0.size)
            try:
                q = model.project_to_contact(q_guess, p_object, R_object)
            except ValueError:
                continue
            lower, upper = model.joint_lower_limits, model.joint_upper_limits
            if np.any(q <= lower) or np.any(q >= upper):
                continue
            twist = rng.normal(0.0, speed, 6) * np.array([0.03, 0.03, 0.03, 1.0, 1.0, 1.0])
            dq = model.rolling_joint_velocity(q, p_object, R_object, twist)
            return Configuration(q, dq, p_object, R_object, twist)


class Table:
    """The problems (A, lower, u_nom, W), the box, the weights and the reference answers."""

    def __init__(self, n, seed, smooth, metric, hand='paper'):
        configs = [replace(PAPER_CONFIG, metric=metric)]
        if hand == 'paper':
            model, offset = paper_model(), 0.3  # N·m

            def configuration(*args):
                return random_configuration(model, *args)
        else:
            example = ExampleHand()
            model, configuration = example.model, example.random_configuration
            # Its joints' margins are under 1 rad: with the paper's h^3 the hard problems
            # are mostly infeasible (or slabs ~1e-7 N·m thin); with gains 10 they are
            # feasible, ~5 mN·m wide. Every other problem has the gains 10.
            configs.insert(
                0, replace(PAPER_CONFIG, metric=metric, alpha1_gain=10.0, alpha2_gain=10.0)
            )
            offset = 0.002  # N·m
        self.metric = metric
        filters = [SafetyFilter.from_config(model, config) for config in configs]
        self.filter = filters[0]
        self.effort = np.asarray(model.effort_limits, dtype=float)
        self.weights = self.filter.relaxed_problem.slack_weights.copy()
        rng = np.random.default_rng(seed)
        self.cases = []
        c = configuration(rng, 0.25, 0.5)
        for i in range(n):
            if smooth:  # a rolling grasp, 1 ms apart: the warm start's case
                c = moved(c, 1e-3)
            else:
                c = configuration(rng, *((0.1, 0.1), (0.3, 1.0))[i % 2])
            state = c.state(model)
            rows = filters[i % len(filters)].constraint_rows(state)
            W = inverse_inertia(state.M_h) if metric == 'inverse_inertia' else None
            centre, radius = chebyshev_radius(rows.A, rows.lower, self.effort)
            direction = rng.normal(size=model.n_joints)
            reach = abs(radius) * 10.0 ** rng.uniform(-1.0, 1.5) + (i % 3) * offset
            u_nom = centre + reach * direction / np.linalg.norm(direction)
            box = -self.effort, self.effort
            feasible, u_hard = hard_optimum(rows.A, rows.lower, u_nom, *box, W)
            relaxed = None
            if not feasible:
                relaxed = relaxed_optimum(rows.A, rows.lower, self.weights, u_nom, *box, W)
            case = (rows.A, rows.lower, u_nom, feasible, u_hard, relaxed, state.M_h)
            self.cases.append(case)


@pytest.fixture(scope='module', params=METRICS)
def tables(request):
    metric = request.param
    return {
        'random': Table(N_PROBLEMS, 3, False, metric),
        'rolling': Table(60, 4, True, metric),
        'example_hand': Table(60, 5, False, metric, hand='example'),
    }


def check(backend, table):
    """Solve every problem of ``table`` with ``backend`` (a callable giving one per problem)."""
    m, k = table.cases[0][0].shape[1], table.cases[0][1].size
    A, lower, g = np.zeros((k, m)), np.zeros(k), np.zeros(m)
    R = np.eye(m) if table.metric == 'inverse_inertia' else None
    problem = Problem(g, A, lower, -table.effort, table.effort, metric_factor=R)
    relaxed = problem.with_slack(table.weights)
    counts = Counter()
    for i, (A_i, lower_i, u_nom, feasible, u_hard, reference, M_h) in enumerate(table.cases):
        A[:], lower[:], g[:] = A_i, lower_i, -u_nom
        if R is not None:
            write_inertia_factor(M_h, R)
        solver = backend(problem, table.weights)
        scale = TOLERANCE * (1.0 + np.abs(u_nom).max())
        hard = solver.solve(problem)
        assert np.isfinite(hard.u).all(), i
        assert np.all(hard.u >= -table.effort) and np.all(hard.u <= table.effort), i
        if feasible:
            counts['feasible'] += 1
            assert hard.status is SolutionStatus.OPTIMAL, (i, hard.status)
            assert np.abs(hard.u - u_hard).max() <= scale, (i, hard.u - u_hard)
            assert hard.row_violation(problem) <= 1e-6, i
            counts['active'] += bool((A_i @ u_hard - lower_i).min() <= 1e-6)
            continue
        counts['infeasible'] += 1
        assert hard.status is SolutionStatus.INFEASIBLE, (i, hard.status)
        solution = solver.solve(relaxed)
        assert solution.status is SolutionStatus.OPTIMAL, (i, solution.status)
        u_ref, s_ref = reference
        assert np.isfinite(solution.u).all() and np.isfinite(solution.slack).all(), i
        assert np.abs(solution.u - u_ref).max() <= scale, (i, solution.u - u_ref)
        assert np.abs(solution.slack - s_ref).max() <= scale, i
        assert solution.row_violation(relaxed) <= 1e-6, i
    return counts


@pytest.mark.parametrize('name', sorted(BACKENDS))
@pytest.mark.parametrize('table_name', ['random', 'rolling', 'example_hand'])
@pytest.mark.parametrize('warm', [True, False], ids=['warm', 'cold'])
def test_every_backend_solves_the_table_exactly(tables, name, table_name, warm):
    """Hard optimum or proof of infeasibility, then the relaxed optimum, as the references."""
    table = tables[table_name]
    settings = SafetyFilterConfig(solver=name).solver_settings()
    shared = []

    def backend(problem, weights):
        if warm and shared:
            return shared[0]
        shared[:] = [BACKENDS[name](problem, weights, settings)]
        return shared[0]

    counts = check(backend, table)
    if table_name == 'random':
        assert counts['feasible'] >= 30 and counts['infeasible'] >= 20, counts
        assert counts['active'] >= 20, counts
    elif table_name == 'example_hand':
        assert counts['feasible'] >= 15 and counts['infeasible'] >= 10, counts
        assert counts['active'] >= 10, counts
    else:
        assert counts['feasible'] + counts['infeasible'] == 60


@pytest.mark.parametrize('name', sorted(BACKENDS))
def test_a_backend_recovers_after_an_infeasible_problem(tables, name):
    """Infeasible, relaxed, then feasible problems on one backend: each answer exact."""
    table = tables['random']
    infeasible = [c for c in table.cases if not c[3]][:5]
    feasible = [c for c in table.cases if c[3]][:5]
    table.cases, saved = (
        [c for pair in zip(infeasible, feasible, strict=True) for c in pair],
        table.cases,
    )
    try:
        settings = SafetyFilterConfig(solver=name).solver_settings()
        solver = []

        def backend(problem, weights):
            if not solver:
                solver.append(BACKENDS[name](problem, weights, settings))
            return solver[0]

        counts = check(backend, table)
    finally:
        table.cases = saved
    assert counts['feasible'] == counts['infeasible'] == 5


def test_the_solver_parameter_names_the_backends():
    assert set(BACKENDS) == {'osqp', 'daqp'}
    assert SafetyFilterConfig.from_parameters({'qp.solver': 'daqp'}).solver == 'daqp'
    with pytest.raises(ParameterError, match=r"'qp\.solver'.*'osqp', 'daqp'.*'cvxopt'"):
        SafetyFilterConfig.from_parameters({'qp.solver': 'cvxopt'})


def test_a_backend_without_an_answer_gives_the_fallback_never_nan():
    """A daqp held to one iteration answers nothing: the filter falls back, finite, in the box."""
    model = paper_model()
    effort = np.asarray(model.effort_limits, dtype=float)
    filter_ = SafetyFilter.from_config(model, replace(PAPER_CONFIG, solver='daqp'))
    weights = filter_.relaxed_problem.slack_weights
    filter_.backend = BACKENDS['daqp'](filter_.problem, weights, {'iter_limit': 1})
    rng = np.random.default_rng(6)
    statuses = Counter()
    for _ in range(12):
        c = random_configuration(model, rng, 0.3, 1.0)
        result = filter_.solve(c.state(model), rng.normal(0.0, 3.0, model.n_joints))
        assert np.isfinite(result.u).all()
        assert np.all(np.abs(result.u) <= effort)
        statuses[result.status.value] += 1
    assert statuses['fallback_last_good'] + statuses['fallback_nominal'] >= 6, statuses


@pytest.mark.parametrize('name', sorted(BACKENDS))
@pytest.mark.parametrize('metric', METRICS)
def test_the_filter_on_the_example_hand_gives_the_reference_optimum(name, metric):
    """The filter's u* with either metric and backend against the references, rolling grasps.

    The filter forms W from each tick's state itself; the references get numpy's
    ``(tr(M_h)/m) M_h^-1`` (identity: None). Its hard QP's dense form carries the same W.
    """
    example = ExampleHand()
    model = example.model
    config = replace(PAPER_CONFIG, solver=name, metric=metric, alpha1_gain=10.0, alpha2_gain=10.0)
    filter_ = SafetyFilter.from_config(model, config)
    effort = np.asarray(model.effort_limits, dtype=float)
    weights = filter_.relaxed_problem.slack_weights
    rng = np.random.default_rng(11)
    c = example.random_configuration(rng, 0.1, 0.3)
    statuses = Counter()
    for i in range(40):
        c = moved(c, 1e-3)
        state = c.state(model)
        rows = filter_.constraint_rows(state)
        centre, radius = chebyshev_radius(rows.A, rows.lower, effort)
        direction = rng.normal(size=model.n_joints)
        u_nom = centre + (abs(radius) * 3.0 + 0.01 * (i % 2)) * direction / np.linalg.norm(
            direction
        )
        W = inverse_inertia(state.M_h) if metric == 'inverse_inertia' else None
        result = filter_.solve(state, u_nom)
        statuses[result.status.value] += 1
        feasible, u_ref = hard_optimum(rows.A, rows.lower, u_nom, -effort, effort, W)
        if not feasible:
            u_ref, _ = relaxed_optimum(rows.A, rows.lower, weights, u_nom, -effort, effort, W)
        assert np.abs(result.u - u_ref).max() <= TOLERANCE * (1.0 + np.abs(u_nom).max()), i
        P, q, *_ = filter_.hard_qp.dense()
        m = model.n_joints
        W_expected = np.eye(m) if W is None else W
        np.testing.assert_allclose(P[:m, :m], W_expected, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(q[:m], -W_expected @ u_nom, rtol=1e-9, atol=1e-12)
    assert statuses['solved'] >= 20, statuses


def test_the_metric_changes_the_optimum_where_rows_are_active():
    """On the example hand the two metrics give different u* (the metric is not ignored)."""
    example = ExampleHand()
    model = example.model
    rng = np.random.default_rng(12)
    gains = {'alpha1_gain': 10.0, 'alpha2_gain': 10.0}
    filters = {
        metric: SafetyFilter.from_config(model, replace(PAPER_CONFIG, metric=metric, **gains))
        for metric in METRICS
    }
    differences = []
    for _ in range(10):
        state = example.random_configuration(rng, 0.1, 0.3).state(model)
        u_nom = rng.normal(0.0, 0.05, model.n_joints)
        u = {metric: f.solve(state, u_nom).u for metric, f in filters.items()}
        differences.append(np.abs(u['identity'] - u['inverse_inertia']).max())
    assert max(differences) > 1e-3, differences


@pytest.mark.parametrize('name', sorted(BACKENDS))
def test_the_optimum_does_not_depend_on_the_metrics_scale(tables, name):
    """W and W / 6.25 (R and 2.5 R) give the same u*, hard and relaxed.

    The slacks are normalised by the rows' dual norms: both terms of the relaxed cost scale
    alike. (The identity tables: W = I against I / 6.25.)
    """
    table = tables['example_hand']
    m, k = table.cases[0][0].shape[1], table.cases[0][1].size
    settings = SafetyFilterConfig(solver=name).solver_settings()
    answers = []
    for scale in (1.0, 2.5):
        A, lower, g, R = np.zeros((k, m)), np.zeros(k), np.zeros(m), np.eye(m)
        problem = Problem(g, A, lower, -table.effort, table.effort, metric_factor=R)
        relaxed = problem.with_slack(table.weights)
        solver = BACKENDS[name](problem, table.weights, settings)
        us = []
        for A_i, lower_i, u_nom, feasible, _, _, M_h in table.cases[:30]:
            A[:], lower[:], g[:] = A_i, lower_i, -u_nom
            if table.metric == 'inverse_inertia':
                write_inertia_factor(M_h, R)
            R *= scale
            solution = solver.solve(problem)
            if not feasible:
                solution = solver.solve(relaxed)
            assert solution.status is SolutionStatus.OPTIMAL
            us.append(solution.u)
            R[:] = np.eye(m)
        answers.append(np.array(us))
    assert np.abs(answers[0] - answers[1]).max() <= TOLERANCE
