"""The replayed hard QPs through other solvers (cvxpy, Clarabel, daqp via qpsolvers)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
import importlib
import importlib.metadata
import time
from typing import Any, NamedTuple
import warnings

import numpy as np

from grasp_tools.bench.replay import DenseQP, statistics


class SolverInput(NamedTuple):
    """A QP in the general form ``min 1/2 x^T P x + q^T x  s.t.  G x <= h,  lb <= x <= ub``."""

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray
    h: np.ndarray
    lb: np.ndarray
    ub: np.ndarray


def general_form(qp: DenseQP) -> SolverInput:
    """Rewrite ``lower <= C x <= upper`` as ``G x <= h`` and bounds on x.

    Rows of C with a single nonzero entry equal to 1 are bounds on their variable; every
    other row gives ``-C_r x <= -lower_r`` and/or ``C_r x <= upper_r`` for its finite sides.
    """
    n = qp.q.size
    lb, ub = np.full(n, -np.inf), np.full(n, np.inf)
    general = []
    for r, row in enumerate(qp.C):
        (nonzero,) = np.nonzero(row)
        if nonzero.size == 1 and row[nonzero[0]] == 1.0:
            j = nonzero[0]
            lb[j] = max(lb[j], qp.lower[r])
            ub[j] = min(ub[j], qp.upper[r])
        else:
            general.append(r)
    rows = qp.C[general]
    lower, upper = qp.lower[general], qp.upper[general]
    has_lower, has_upper = np.isfinite(lower), np.isfinite(upper)
    G = np.concatenate((-rows[has_lower], rows[has_upper]))
    h = np.concatenate((-lower[has_lower], upper[has_upper]))
    return SolverInput(qp.P, qp.q, G, h, lb, ub)


class ExternalAnswer(NamedTuple):
    """One external solve: the solution (None if none was returned), status and solver."""

    x: np.ndarray | None
    status: str
    solver: str
    solver_time: float | None


@dataclass(frozen=True)
class ExternalSolver:
    """Another way to solve the same QP.

    Attributes:
        key: JSON key.
        label: Table label.
        solve: The solve, or None when the packages it needs are not installed.
        unavailable: Why it is skipped (None when available).
    """

    key: str
    label: str
    solve: Callable[[SolverInput], ExternalAnswer] | None
    unavailable: str | None = None


def _cvxpy_solve(solver: str | None, **options: float) -> Callable[[SolverInput], ExternalAnswer]:
    cp = importlib.import_module('cvxpy')
    if solver is not None and solver not in cp.installed_solvers():
        raise ImportError(f'cvxpy has no {solver} solver installed')

    def solve(qp: SolverInput) -> ExternalAnswer:
        # Built anew every tick, as a CBF-QP written with cvxpy usually is.
        x = cp.Variable(qp.q.size)
        problem = cp.Problem(
            cp.Minimize(0.5 * cp.quad_form(x, qp.P) + qp.q @ x),
            [qp.G @ x <= qp.h, x >= qp.lb, x <= qp.ub],
        )
        try:
            with warnings.catch_warnings():
                warnings.simplefilter('ignore')  # "solution may be inaccurate": counted below
                problem.solve() if solver is None else problem.solve(solver=solver, **options)
        except cp.error.SolverError:
            return ExternalAnswer(None, 'solver_error', solver or 'default', None)
        stats = problem.solver_stats
        value = x.value
        if value is not None and not np.isfinite(value).all():
            value = None
        return ExternalAnswer(
            None if value is None else np.array(value),
            str(problem.status),
            stats.solver_name if stats is not None else (solver or 'default'),
            stats.solve_time if stats is not None else None,
        )

    return solve


def _qpsolvers_solve(solver: str) -> Callable[[SolverInput], ExternalAnswer]:
    qpsolvers = importlib.import_module('qpsolvers')
    if solver not in qpsolvers.available_solvers:
        raise ImportError(f'qpsolvers has no {solver} backend installed')

    def solve(qp: SolverInput) -> ExternalAnswer:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            x = qpsolvers.solve_qp(qp.P, qp.q, qp.G, qp.h, lb=qp.lb, ub=qp.ub, solver=solver)
        if x is None or not np.isfinite(x).all():
            return ExternalAnswer(None, 'no_solution', solver, None)
        return ExternalAnswer(np.asarray(x, dtype=float), 'solved', solver, None)

    return solve


#: Clarabel's tolerances for the accurate cvxpy reference. An interior-point method stops
#: at a duality gap eps, and on a least-distance problem that leaves ``||u - u*|| ~ sqrt(2 eps)``:
#: its default gap 1e-8 allows about 1e-4 N·m, 1e-12 about 1e-6. (A feasibility tolerance
#: below 1e-10 makes it stall on this scenario's ill-conditioned QPs.)
CLARABEL_TIGHT = {'tol_gap_abs': 1e-12, 'tol_gap_rel': 1e-12, 'tol_feas': 1e-10}

#: The external solvers: key, label, factory of the solve function. The first two use
#: their defaults, as research code usually does; the last two are accurate references.
EXTERNAL_SOLVERS: tuple[
    tuple[str, str, Callable[[], Callable[[SolverInput], ExternalAnswer]]], ...
] = (
    ('cvxpy', 'cvxpy, default solver', lambda: _cvxpy_solve(None)),
    ('cvxpy_osqp', 'cvxpy + OSQP', lambda: _cvxpy_solve('OSQP')),
    (
        'cvxpy_clarabel',
        'cvxpy + Clarabel (tight)',
        lambda: _cvxpy_solve('CLARABEL', **CLARABEL_TIGHT),
    ),
    ('daqp', 'daqp (qpsolvers)', lambda: _qpsolvers_solve('daqp')),
)


def external_solvers() -> list[ExternalSolver]:
    """Every solver of :data:`EXTERNAL_SOLVERS`, with the reason when it is not installed."""
    solvers = []
    for key, label, factory in EXTERNAL_SOLVERS:
        try:
            solvers.append(ExternalSolver(key, label, factory()))
        except ImportError as error:
            reason = f'not installed ({error}); pip install grasp_safety_filter[bench]'
            solvers.append(ExternalSolver(key, label, None, reason))
    return solvers


def run_external(
    solver: ExternalSolver,
    qps: Sequence[DenseQP],
    ours: np.ndarray,
    certified: np.ndarray,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Solve every QP with ``solver``; compare with our u* where ours is certified.

    Args:
        solver: An available external solver.
        qps: The hard QPs.
        ours: Our u* per QP, shape (len(qps), m).
        certified: Per QP, True when our u* solves it (the hard QP is feasible), False when
            the filter found it infeasible.

    Returns:
        Wall time per QP (s), and the comparison: statuses, solver name, ``max_abs_du``
        (N·m, over ``compared`` QPs that both solved), ``missing`` (feasible QPs it returned
        no solution for), ``infeasible_agreed`` (of ``infeasible`` QPs, those it returned
        no solution for), solver-only time if the solver reports it.
    """
    inputs = [general_form(qp) for qp in qps]
    clock = time.perf_counter
    times = np.zeros(len(inputs))
    statuses: Counter[str] = Counter()
    names: set[str] = set()
    solver_times: list[float] = []
    deviations: list[float] = []
    missing = infeasible_agreed = 0
    for i, qp in enumerate(inputs):
        start = clock()
        answer = solver.solve(qp)
        times[i] = clock() - start
        statuses[answer.status] += 1
        names.add(answer.solver)
        if answer.solver_time is not None:
            solver_times.append(answer.solver_time)
        if certified[i]:
            if answer.x is None:
                missing += 1
            else:
                deviations.append(float(np.abs(answer.x - ours[i]).max()))
        elif answer.x is None:
            infeasible_agreed += 1
    comparison = {
        'solver': ', '.join(sorted(names)),
        'statuses': dict(statuses),
        'compared': len(deviations),
        'max_abs_du': max(deviations) if deviations else None,
        'median_abs_du': float(np.median(deviations)) if deviations else None,
        'missing': missing,
        'infeasible': int(np.count_nonzero(~certified)),
        'infeasible_agreed': infeasible_agreed,
        'solver_time_us': statistics(np.array(solver_times)) if solver_times else None,
    }
    return times, comparison
