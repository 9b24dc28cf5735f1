"""Every QP backend on the same table of problems: random real grasps, hard and relaxed.

The problems are the filter's rows at random grasps of the paper's hand (rolling, near and
far from the limits), with u_nom drawn around the centre of the largest ball inside the
feasible set (an LP) so that a third of the hard problems are feasible with u_nom inside,
a third feasible with rows active and the rest infeasible. Each backend answers them in one
warm-started sequence and cold (a fresh backend per problem); the answers are compared with
two independent exact solvers (:mod:`qp_reference`) and their KKT residuals measured by the
:class:`Solution` itself.
"""

from collections import Counter

from grasp_states import moved, paper_model, random_configuration
import numpy as np
import pytest
from qp_reference import chebyshev_radius, hard_optimum, relaxed_optimum

from grasp_safety_filter.control.qp_solvers import (
    BACKENDS,
    Problem,
    SolutionStatus,
)
from grasp_safety_filter.control.safety_filter import SafetyFilter, SafetyFilterConfig
from grasp_safety_filter.io.parameters import ParameterError

N_PROBLEMS = 120
TOLERANCE = 1e-6  # N·m per N·m of |u_nom|: torque, KKT residuals


class Table:
    """The problems (A, lower, u_nom), the box, the weights and the reference answers."""

    def __init__(self, n, seed, smooth):
        model = paper_model()
        self.filter = SafetyFilter.from_config(model, SafetyFilterConfig())
        self.effort = np.asarray(model.effort_limits, dtype=float)
        self.weights = self.filter.relaxed_problem.slack_weights.copy()
        rng = np.random.default_rng(seed)
        self.cases = []
        c = random_configuration(model, rng, 0.25, 0.5)
        for i in range(n):
            if smooth:  # a rolling grasp, 1 ms apart: the warm start's case
                c = moved(c, 1e-3)
            else:
                c = random_configuration(model, rng, *((0.1, 0.1), (0.3, 1.0))[i % 2])
            rows = self.filter.constraint_rows(c.state(model))
            centre, radius = chebyshev_radius(rows.A, rows.lower, self.effort)
            direction = rng.normal(size=model.n_joints)
            reach = abs(radius) * 10.0 ** rng.uniform(-1.0, 1.5) + (i % 3) * 0.3
            u_nom = centre + reach * direction / np.linalg.norm(direction)
            feasible, u_hard = hard_optimum(rows.A, rows.lower, u_nom, -self.effort, self.effort)
            relaxed = None
            if not feasible:
                args = rows.A, rows.lower, self.weights, u_nom, -self.effort, self.effort
                relaxed = relaxed_optimum(*args)
            self.cases.append((rows.A, rows.lower, u_nom, feasible, u_hard, relaxed))


@pytest.fixture(scope='module')
def tables():
    return {'random': Table(N_PROBLEMS, 3, smooth=False), 'rolling': Table(60, 4, smooth=True)}


def check(backend, table):
    """Solve every problem of ``table`` with ``backend`` (a callable giving one per problem)."""
    m, k = table.cases[0][0].shape[1], table.cases[0][1].size
    A, lower, g = np.zeros((k, m)), np.zeros(k), np.zeros(m)
    problem = Problem(g, A, lower, -table.effort, table.effort)
    relaxed = problem.with_slack(table.weights)
    counts = Counter()
    for i, (A_i, lower_i, u_nom, feasible, u_hard, reference) in enumerate(table.cases):
        A[:], lower[:], g[:] = A_i, lower_i, -u_nom
        solver = backend(problem, table.weights)
        scale = TOLERANCE * (1.0 + np.abs(u_nom).max())
        hard = solver.solve(problem)
        assert np.isfinite(hard.u).all(), i
        assert np.all(hard.u >= -table.effort) and np.all(hard.u <= table.effort), i
        if feasible:
            counts['feasible'] += 1
            assert hard.status is SolutionStatus.OPTIMAL, (i, hard.status)
            assert np.abs(hard.u - u_hard).max() <= scale, (i, hard.u - u_hard)
            assert max(hard.residuals(problem)) <= scale, (i, hard.residuals(problem))
            assert hard.row_violation(problem) <= 1e-6, i
            counts['active'] += bool(hard.active)
            continue
        counts['infeasible'] += 1
        assert hard.status is SolutionStatus.INFEASIBLE, (i, hard.status)
        solution = solver.solve(relaxed)
        assert solution.status is SolutionStatus.OPTIMAL, (i, solution.status)
        u_ref, s_ref = reference
        assert np.isfinite(solution.u).all() and np.isfinite(solution.slack).all(), i
        assert np.abs(solution.u - u_ref).max() <= scale, (i, solution.u - u_ref)
        assert np.abs(solution.slack - s_ref).max() <= scale, i
        assert max(solution.residuals(relaxed)) <= scale, (i, solution.residuals(relaxed))
        assert solution.row_violation(relaxed) <= 1e-6, i
    return counts


@pytest.mark.parametrize('name', sorted(BACKENDS))
@pytest.mark.parametrize('table_name', ['random', 'rolling'])
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
    filter_ = SafetyFilter.from_config(model, SafetyFilterConfig(solver='daqp'))
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
