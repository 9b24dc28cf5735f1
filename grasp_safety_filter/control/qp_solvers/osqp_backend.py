"""OSQP backend: the paper's solver, set up once, warm-started, its answer checked.

The hard and the relaxed problem each have one OSQP workspace, set up once on the fixed
sparsity pattern of :class:`~grasp_safety_filter.control.qp.SafetyQP`; each tick updates
``q``, ``l`` and ``C``'s values (and P's with the inverse-inertia metric), and OSQP starts
from its own previous answer (``warm_starting``), polishing it on the rows it found active.

An answer is accepted only when it passes the KKT check of :func:`kkt_violation` (rows
hold, multipliers of the right sign, complementarity, stationarity) to
:data:`KKT_TOLERANCE`. The filter's QPs are degenerate where it matters: near a joint limit
the barrier rows of one joint on the three fingers are nearly dependent, and ADMM stops
with the wrong rows active on a few ticks in a hundred (or needs thousands of iterations).
Such a tick, and any tick OSQP does not solve (infeasible, iteration limit, non-finite), is
finished by daqp (:class:`~.daqp_backend.DAQPBackend`, a dual active-set solver: exact,
and a proof when the problem is infeasible). Every answer is then the optimum to the
solvers' tolerances, or a proved infeasibility; none is an ADMM iterate.

With the inverse-inertia metric (a problem with a ``metric_factor`` R) OSQP gets the tick's
cost ``P = W = (R R^T)^-1``, ``q = -W u_nom``, and keeps the box as bounds on u.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import osqp

from grasp_safety_filter.control.qp import SafetyQP
from grasp_safety_filter.control.qp_solvers.daqp_backend import DAQPBackend
from grasp_safety_filter.control.qp_solvers.problem import Problem, Solution, SolutionStatus

#: Settings the backend needs under the ``osqp.*`` parameters: quiet, warm-started.
DEFAULT_SETTINGS: dict[str, Any] = {'verbose': False, 'warm_starting': True}

#: Largest KKT violation of an accepted OSQP answer (:func:`kkt_violation`). A polished
#: answer on the right rows meets it by orders of magnitude; at 1e-6, answers polished on a
#: wrong active set passed, up to 2e-5 N·m from the optimum (the paper's run).
KKT_TOLERANCE = 1e-8

_SOLVED = osqp.SolverStatus.OSQP_SOLVED


def kkt_violation(qp: SafetyQP, x: np.ndarray, y: np.ndarray) -> float:
    """Largest violation of the KKT conditions of OSQP's ``(x, y)`` on ``qp``'s buffers.

    In OSQP's form ``min 1/2 x^T P x + q^T x, l <= C x <= u`` (y < 0 on an active lower
    bound, > 0 on an active upper one): the rows' violation, a multiplier of the wrong
    sign, ``|y_i|`` times its row's distance to the bound it holds, and ``|P x + q + C^T y|``;
    in the rows' own units (N, rad/s², N·m). inf when anything is not finite.
    """
    m, k = qp.n_torques, qp.n_rows
    u = x[:m]
    Cx = np.empty(qp.n_constraints)
    np.matmul(qp.A_rows, u, out=Cx[:k])
    Cx[k : k + m] = u
    H = qp.W if qp.metric_factor is not None else None
    gradient = H @ u if H is not None else u.copy()
    gradient += qp.q[:m] + qp.A_rows.T @ y[:k] + y[k : k + m]
    if qp.relaxed:
        s, y_rows, y_slack = x[m:], y[:k], y[k + m :]
        Cx[:k] += qp.slack_scale * s
        Cx[k + m :] = s
        gradient = np.concatenate(
            (gradient, qp.row_weights * s + qp.slack_scale * y_rows + y_slack)
        )
    with np.errstate(invalid='ignore'):
        below, above = qp.lower - Cx, Cx - qp.upper
        distance = np.where(y < 0.0, -below, np.where(y > 0.0, -above, 0.0))
        worst = max(
            below.max(initial=0.0),
            above.max(initial=0.0),
            # A row without an upper bound (barriers, slacks) holds no positive multiplier.
            np.where(np.isinf(qp.upper), y, 0.0).max(initial=0.0),
            np.abs(y * distance).max(initial=0.0),
            np.abs(gradient).max(initial=0.0),
        )
    return float(worst) if worst == worst else float('inf')


class _Workspace:
    """One OSQP workspace on one :class:`SafetyQP`'s buffers."""

    def __init__(self, qp: SafetyQP, settings: Mapping[str, Any]) -> None:
        self.qp = qp
        self.solver = osqp.OSQP()
        self.solver.setup(qp.P, qp.q, qp.C, qp.lower, qp.upper, **settings)
        self.cold()

    def cold(self) -> None:
        """Start the next solve from zero."""
        self.solver.warm_start(
            x=np.zeros(self.qp.n_variables), y=np.zeros(self.qp.n_constraints)
        )

    def solve(self, problem: Problem) -> tuple[np.ndarray | None, int]:
        """Write the problem into the buffers and solve: ``(x or None, iterations)``.

        x is OSQP's answer when it passes :func:`kkt_violation`, else None.
        """
        qp = self.qp
        qp.update(problem.A, problem.lower, -problem.g, problem.metric_factor)
        if qp.metric_factor is None:
            self.solver.update(q=qp.q, l=qp.lower, Ax=qp.C_data)
        else:
            self.solver.update(q=qp.q, l=qp.lower, Ax=qp.C_data, Px=qp.P_data)
        result = self.solver.solve(raise_error=False)
        iterations = int(result.info.iter)
        solved = result.info.status_val == _SOLVED
        if solved and kkt_violation(qp, result.x, result.y) <= KKT_TOLERANCE:
            return result.x, iterations
        self.cold()  # an unchecked iterate is no start for the next tick
        return None, iterations


class OSQPBackend:
    """The hard and relaxed problems of one filter in OSQP, finished by daqp when needed."""

    name = 'osqp'

    def __init__(
        self, problem: Problem, slack_weights: np.ndarray, settings: Mapping[str, Any]
    ) -> None:
        """Set both problems up once (fixed sparsity), and daqp to finish them.

        Args:
            problem: The hard problem (its arrays may be rewritten every tick).
            slack_weights: w of the relaxed problem, shape (k,).
            settings: Keyword settings of ``osqp.OSQP.setup`` over :data:`DEFAULT_SETTINGS`.
        """
        m, k = problem.n_torques, problem.n_rows
        self._m = m
        self._u_min, self._u_max = problem.u_min, problem.u_max
        metric = problem.metric_factor is not None
        options = {**DEFAULT_SETTINGS, **settings}
        box = (problem.u_min, problem.u_max)
        self._hard = _Workspace(SafetyQP(m, k, *box, metric=metric), options)
        self._relaxed = _Workspace(
            SafetyQP(m, k, *box, row_weights=slack_weights, metric=metric), options
        )
        self._exact = DAQPBackend(problem, slack_weights, {})

    def reset(self) -> None:
        """Forget the warm starts: the next solves start from zero."""
        self._hard.cold()
        self._relaxed.cold()
        self._exact.reset()

    def warm_start(self, solution: Solution | None) -> None:
        """Start the next hard solve from a tick settled without OSQP (None: from zero)."""
        if solution is None:
            self.reset()
        else:
            self._hard.solver.warm_start(x=solution.u, y=np.zeros(self._hard.qp.n_constraints))

    def solve(self, problem: Problem) -> Solution:
        """Solve the hard or the relaxed problem: OSQP's checked answer, or daqp's."""
        workspace = self._relaxed if problem.relaxed else self._hard
        x, iterations = workspace.solve(problem)
        if x is None:
            exact = self._exact.solve(problem)
            return Solution(exact.u, exact.status, exact.slack, iterations + exact.iterations)
        m = self._m
        u = np.minimum(np.maximum(x[:m], self._u_min), self._u_max)
        slack = np.maximum(x[m:], 0.0) if problem.relaxed else None
        return Solution(u, SolutionStatus.OPTIMAL, slack=slack, iterations=iterations)
