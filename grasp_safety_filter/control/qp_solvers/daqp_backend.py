"""daqp backend: a dual active-set solver (Arnström, Bemporad, Axehill), warm-started.

daqp solves ``min 1/2 x^T H x + f^T x  s.t.  blower <= [I; A] x <= bupper`` exactly (an
active-set method: its answer satisfies the KKT conditions to its tolerances, no
refinement needed) and proves infeasibility. One ``daqp.Model`` per problem is set up once;
each tick updates ``f``, ``A`` and the bounds, and daqp starts from the previous tick's
working set (the rows move little in 1 ms). After a tick that did not end optimal (an
infeasible problem, a failure, or a tick with no answer) the next solve starts cold, from
an empty working set: a working set left by a failed solve is no valid start.

The hard problem: ``x = u``, ``H = I``, ``f = g``, the box as simple bounds, the barrier
rows ``lower <= A u``. The relaxed problem is the same :class:`~.problem.Problem` with its
slacks as variables: ``x = (u, s)``, ``H = diag(1, w)``, simple bounds ``s >= 0``, rows
``lower_r <= A_r u + d_r s_r`` (``d_r`` of :meth:`~.problem.Problem.slack_scale`). With
the inverse-inertia metric the torque block of H is the tick's ``W`` and ``f = -W u_nom``
(daqp's own Cholesky factorisation of H turns it into its least-distance problem); the box
stays simple bounds on u, held exactly. daqp's
soft constraints would add a slack of their own per row with its own weight convention;
explicit slacks keep the relaxed problem the one every backend solves.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import daqp
import numpy as np

from grasp_safety_filter.control.qp_solvers.problem import (
    FEASIBILITY_TOLERANCE,
    Problem,
    Solution,
    SolutionStatus,
)

#: daqp's bound for "no bound" (its DAQP_INF).
_INFINITY = 1e30

#: daqp exit flags.
_OPTIMAL = 1
_INFEASIBLE = -1

#: Tolerances tighter than daqp's defaults (primal 1e-6): the filter's own row check is
#: 1e-6 in the rows' units, which daqp's (normalised) tolerance must not exceed.
DEFAULT_SETTINGS: dict[str, Any] = {'primal_tol': 1e-9}


class _Model:
    """One daqp workspace with its bounds and constraint buffers."""

    def __init__(
        self,
        H: np.ndarray,
        A: np.ndarray,
        upper: np.ndarray,
        lower: np.ndarray,
        settings: Mapping[str, Any],
    ) -> None:
        self.H, self.A, self.upper, self.lower = H, A, upper, lower
        self.n_bounds = upper.shape[0] - A.shape[0]
        self.f = np.zeros(H.shape[0])
        self.cold = np.zeros(upper.shape[0], dtype=np.int32)
        self.model = daqp.Model()
        self.model.setup(H, self.f, A, upper, lower)
        self.model.settings = dict(settings)
        self.warm = False

    def solve(self, new_cost: bool) -> tuple[np.ndarray, int, int]:
        """Hand over this tick's data (H too if ``new_cost``): ``(x, flag, iterations)``."""
        H = self.H if new_cost else None
        if self.warm:
            self.model.update(H=H, f=self.f, A=self.A, blower=self.lower)
        else:
            self.model.update(H=H, f=self.f, A=self.A, blower=self.lower, sense=self.cold)
        x, _, flag, info = self.model.solve()
        self.warm = flag == _OPTIMAL
        return np.asarray(x, dtype=float), int(flag), int(info['iterations'])


class DAQPBackend:
    """The hard and relaxed problems of one filter, each in a warm-started ``daqp.Model``."""

    name = 'daqp'

    def __init__(
        self, problem: Problem, slack_weights: np.ndarray, settings: Mapping[str, Any]
    ) -> None:
        """Set both models up once.

        Args:
            problem: The hard problem (its arrays may be rewritten every tick).
            slack_weights: w of the relaxed problem, shape (k,).
            settings: daqp settings over :data:`DEFAULT_SETTINGS` (e.g. ``iter_limit``).
        """
        m, k = problem.n_torques, problem.n_rows
        self._m = m
        self._u_min, self._u_max = problem.u_min, problem.u_max
        options = {**DEFAULT_SETTINGS, **settings}
        no_upper = np.full(k, _INFINITY)
        self._hard = _Model(
            np.eye(m),
            np.zeros((k, m)),
            np.concatenate((problem.u_max, no_upper)),
            np.concatenate((problem.u_min, np.zeros(k))),
            options,
        )
        H = np.diag(np.concatenate((np.ones(m), slack_weights)))
        self._relaxed = _Model(
            H,
            np.zeros((k, m + k)),
            np.concatenate((problem.u_max, no_upper, no_upper)),
            np.concatenate((problem.u_min, np.zeros(k), np.zeros(k))),
            options,
        )
        # The slack column block's diagonal d, a view into the relaxed rows (entry (r, m + r)).
        self._slack_diagonal = self._relaxed.A.reshape(-1)[m : m + k * (m + k + 1) : m + k + 1]

    def reset(self) -> None:
        """Forget the working sets: the next solves start cold."""
        self._hard.warm = self._relaxed.warm = False

    def warm_start(self, solution: Solution | None) -> None:
        """Keep the working set after a tick settled without daqp; None: start cold."""
        if solution is None:
            self.reset()

    def solve(self, problem: Problem) -> Solution:
        """Solve the hard or the relaxed problem."""
        m = self._m
        model = self._relaxed if problem.relaxed else self._hard
        metric = problem.metric_factor is not None
        if metric:
            model.H[:m, :m] = problem.H
            np.matmul(model.H[:m, :m], problem.g, out=model.f[:m])
        else:
            np.copyto(model.f[:m], problem.g)
        model.A[:, :m] = problem.A
        model.lower[model.n_bounds :] = problem.lower
        if problem.relaxed:
            self._slack_diagonal[:] = problem.slack_scale()
        x, flag, iterations = model.solve(metric)
        if flag == _INFEASIBLE:
            u = self._clip(-problem.g)
            return Solution(u, SolutionStatus.INFEASIBLE, iterations=iterations)
        u = x[:m]
        if flag != _OPTIMAL or not np.isfinite(x).all():
            self.reset()
            return Solution(self._clip(-problem.g), SolutionStatus.FAILED, iterations=iterations)
        slack = x[m:].copy() if problem.relaxed else None
        solution = Solution(self._clip(u), SolutionStatus.OPTIMAL, slack, iterations)
        if not problem.relaxed and not solution.row_violation(problem) <= FEASIBILITY_TOLERANCE:
            self.reset()
            return Solution(solution.u, SolutionStatus.FAILED, iterations=iterations)
        return solution

    def _clip(self, u: np.ndarray) -> np.ndarray:
        return np.minimum(np.maximum(u, self._u_min), self._u_max)
