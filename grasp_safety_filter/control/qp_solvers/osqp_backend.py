"""OSQP backend: warm-started ADMM, its answer certified or refined exactly.

A hard :class:`~.problem.Problem` goes through, in order, until one step gives the optimum:

1. The previous tick's active set: the optimum with those rows held as equalities is one
   small linear solve (:func:`~grasp_safety_filter.control.working_set.optimum_on_working_set`).
   It is accepted when it satisfies the KKT conditions the active-set method stops on
   (every row and bound holds, multipliers nonnegative, :data:`ACTIVE_SET_TOLERANCE`); OSQP
   is then not called (``iterations == 0``) and its next warm start is this primal-dual
   pair. The rows move little in one tick, so this settles almost every tick of a smooth
   run. (No guess after a relaxed or fallback tick.)
2. After an infeasible tick: the active-set method from the rows that proved it, no OSQP.
3. OSQP (set up once with a fixed sparsity pattern, :class:`~grasp_safety_filter.control.qp.
   SafetyQP`, warm-started), without polishing. Its ``(x, y)`` is accepted when it
   satisfies the KKT conditions to :data:`~.osqp_certificate.CERTIFICATE_TOLERANCE`
   (:mod:`~.osqp_certificate`); else the active set its multipliers name is tried as in
   step 1.
4. The exact active-set method (:mod:`~grasp_safety_filter.control.least_distance`) from
   OSQP's active set: optimal (``refinement_steps`` add/drop steps) or a proof of
   infeasibility, whatever OSQP said.

Why: the filter's QPs are degenerate where it matters (near a joint limit the barrier rows
of the same joint on the three fingers are nearly dependent), where ADMM needs thousands of
iterations to 1e-5 while its active-set guess is right after a few dozen; the dense step on
9 variables makes the answer exact at the cost of one small factorisation. OSQP's
tolerances (eps 1e-4, 50 iterations, termination checked every 5) only decide when ADMM
hands its active set over; polishing would repeat step 4.

The relaxed problem is first solved by the active-set method alone (in ``(u, s~)``, a
least-distance problem too), from the last tick's relaxed active set when the last tick was
relaxed (relaxed ticks come in runs) or else from the rows that proved the hard problem
infeasible; OSQP's relaxed solution gives the start only if that does not end optimal.

Every answer's rows are checked by the :class:`~.problem.Solution` (``row_violation`` at
most :data:`~.problem.FEASIBILITY_TOLERANCE`) before it is returned as optimal.

With the inverse-inertia metric (a problem with a ``metric_factor`` R) OSQP gets the tick's
cost ``P = W``, ``q = -W u_nom`` and keeps the box as bounds on u; every active-set step
works in ``y = R^-1 u``, where the cost is ``||y - y_nom||^2`` and the rows (the box
included) are ``[A; B] R`` (:meth:`~.problem.Problem.least_distance_form`), and maps its
answer back, ``u = R y``. The multipliers are the same in both variables.

This module sets OSQP up, warm-starts it and orders the steps; the active-set steps are
:mod:`~.osqp_active_set`'s, the reading of OSQP's answer :mod:`~.osqp_certificate`'s.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import osqp

from grasp_safety_filter.control.least_distance import (
    LeastDistanceSolution,
    LeastDistanceStatus,
    solve_least_distance,
)
from grasp_safety_filter.control.qp import SafetyQP
from grasp_safety_filter.control.qp_solvers.osqp_active_set import (
    ACTIVE_SET_TOLERANCE,
    ActiveSetSteps,
)
from grasp_safety_filter.control.qp_solvers.osqp_certificate import (
    certified_torque,
    duals_of,
    osqp_duals,
    working_set_guess,
)
from grasp_safety_filter.control.qp_solvers.problem import (
    Problem,
    Solution,
    SolutionStatus,
)
from grasp_safety_filter.control.working_set import working_set_scratch, WorkingSetScratch

_NO_MULTIPLIERS = np.zeros(0)
_NO_MULTIPLIERS.setflags(write=False)
_NO_ROWS = np.zeros(0, dtype=np.intp)

#: :meth:`OSQPBackend.last_active_guess`'s answer.
ActiveGuess = tuple[np.ndarray, np.ndarray, np.ndarray, WorkingSetScratch]

_CONVERGED = (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
_INFEASIBLE = (
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE,
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE,
)
_RELAXED_USABLE = (*_CONVERGED, osqp.SolverStatus.OSQP_MAX_ITER_REACHED)


class OSQPBackend(ActiveSetSteps):
    """The hard and relaxed problems of one filter, each with its own OSQP workspace."""

    name = 'osqp'

    def __init__(
        self, problem: Problem, slack_weights: np.ndarray, settings: Mapping[str, Any]
    ) -> None:
        """Set both problems up once (fixed sparsity).

        Args:
            problem: The hard problem (its arrays may be rewritten every tick).
            slack_weights: w of the relaxed problem, shape (k,).
            settings: Keyword settings of ``osqp.OSQP.setup`` (``warm_starting`` on).
        """
        m, k = problem.n_torques, problem.n_rows
        self._m, self._k = m, k
        self._u_min, self._u_max = problem.u_min, problem.u_max
        metric = problem.metric_factor is not None
        self.hard_qp = SafetyQP(m, k, problem.u_min, problem.u_max, metric=metric)
        self.relaxed_qp = SafetyQP(
            m, k, problem.u_min, problem.u_max, row_weights=slack_weights, metric=metric
        )
        self._hard = osqp.OSQP()
        self._relaxed = osqp.OSQP()
        for solver, qp in ((self._hard, self.hard_qp), (self._relaxed, self.relaxed_qp)):
            solver.setup(qp.P, qp.q, qp.C, qp.lower, qp.upper, **settings)
        # The least-distance forms' rows (Problem.least_distance_form), filled in place.
        B, c = problem.box
        self._box_rows = B
        self._hard_rows = np.concatenate((np.zeros((k, m)), B))
        self._hard_lower = np.concatenate((np.zeros(k), c))
        self._relaxed_rows = np.zeros((2 * k + 2 * m, m + k))
        self._relaxed_rows[k : k + 2 * m, :m] = B
        self._relaxed_rows[k + 2 * m :, m:] = np.eye(k)
        self._relaxed_lower = np.concatenate((np.zeros(k), c, np.zeros(k)))
        # The diagonal d / sqrt(w) of the barrier rows' slack block, a view (entry (r, m + r)).
        self._relaxed_slack_diagonal = self._relaxed_rows.reshape(-1)[
            m : m + k * (m + k + 1) : m + k + 1
        ]
        self._sqrt_weights = np.sqrt(self.relaxed_qp.row_weights)
        # This tick's metric factor (None: the identity) and the hard least-distance form
        # in y = R^-1 u: its rows and its start y_nom.
        self._R: np.ndarray | None = None
        self._rows_y = self._hard_rows
        self._y_nom = np.zeros(m)
        self._solve_scratch = working_set_scratch(m, k + 2 * m)
        self.reset()

    def reset(self) -> None:
        """Forget every warm start and guess."""
        # A tick settled without OSQP leaves its exact (u, active rows, multipliers) here,
        # turned into OSQP's y only if OSQP runs next.
        self._pending: tuple[np.ndarray, tuple[int, ...], np.ndarray] | None = None
        # The last hard optimum's active set, tried first; None after a relaxed tick.
        self._last_active: tuple[int, ...] | None = None
        # After an infeasible tick: the rows that proved it and the relaxed active set.
        self._infeasible_rows: tuple[int, ...] | None = None
        self._relaxed_active: tuple[int, ...] | None = None
        # This tick's: the hard attempt and the relaxed guess, read by the relaxed solve.
        self._attempt: LeastDistanceSolution | None = None
        self._relaxed_guess: tuple[int, ...] | None = None
        # The last guess tried on the hard problem and its rows as an index array.
        self._working_set: tuple[tuple[int, ...] | None, np.ndarray] = (None, _NO_ROWS)
        # Step 1 already failed this tick in a compiled pass (guess_rejected): not again.
        self._guess_rejected = False
        m, k = self._m, self._k
        self._hard.warm_start(x=np.zeros(m), y=np.zeros(k + m))
        self._relaxed.warm_start(x=np.zeros(m + k), y=np.zeros(2 * k + m))

    def warm_start(self, solution: Solution | None) -> None:
        """Start the next tick from a tick settled without this backend.

        Args:
            solution: The tick's optimum (e.g. u_nom with no active row), or None when the
                tick gave no answer: then nothing is guessed next tick.
        """
        self._infeasible_rows = self._relaxed_active = None
        if solution is None:
            self._last_active = None
            return
        self._last_active = solution.active
        self._pending = (solution.u, solution.active, solution.multipliers)

    def last_active_guess(self) -> ActiveGuess:
        """Return what a compiled pass needs to try step 1 itself.

        Returns:
            The previous tick's active set as an index array (empty when there is no guess),
            the hard least-distance form's rows ``C`` and ``b`` in u, whose first k rows
            the pass overwrites with the tick's ``A`` and ``lower``, and the solve's scratch.
        """
        guess = self._last_active
        working_set = self._working_set_array(guess) if guess else _NO_ROWS
        return working_set, self._hard_rows, self._hard_lower, self._solve_scratch

    def accept_guess(
        self,
        u_nom: np.ndarray,
        u: np.ndarray,
        multipliers: np.ndarray,
        in_y: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> Solution:
        """Take step 1's optimum found by a compiled pass, as :meth:`solve` would have.

        ``u`` (clipped to the box, rows checked) and ``multipliers`` are
        :func:`~grasp_safety_filter.control.working_set.clipped_optimum_on_working_set`'s
        answer on :meth:`last_active_guess`, with this tick's rows already in ``C`` and ``b``
        (with a metric, ``in_y``: the tick's R, ``C R`` and ``R^-1 u_nom`` the pass formed).
        """
        self._infeasible_rows = None
        self._relaxed_guess, self._relaxed_active = self._relaxed_active, None
        self._attempt = None
        if in_y is None:
            self._set_metric(None, u_nom)
        else:
            self._R, self._rows_y, self._y_nom = in_y
        guess = self._last_active
        return self._keep(Solution(u, SolutionStatus.OPTIMAL, guess, multipliers, None, 0))

    def guess_rejected(self) -> None:
        """Skip step 1 in the next hard solve: a compiled pass found the guess not optimal."""
        self._guess_rejected = True

    def load_kernels(self, problem: Problem) -> None:
        """Run every step once on ``problem`` now, answers discarded; then :meth:`reset`.

        numba loads a compiled step at its first call (:mod:`grasp_safety_filter.model.
        compiled`), some 5 to 20 ms each. The steps after a rejected guess (the reading of
        OSQP's multipliers, the exact active-set method) and the relaxed problem's run on a
        few ticks in a thousand, so the first such tick would load them all; a node calls
        this at start-up instead. Each is called as a tick calls it, so that its arrays
        have a tick's types.
        """
        m, k = self._m, self._k
        self._hard_rows[:k] = problem.A
        self._hard_lower[:k] = problem.lower
        self._set_metric(problem.metric_factor, -problem.g)
        y = self._hard.solve(raise_error=False).y  # OSQP's multipliers, as a tick has them
        guess = working_set_guess(y, k, m) or (0,)
        self._on_guess(problem, guess, 0)
        solve_least_distance(
            self._y_nom, self._rows_y, self._hard_lower, ACTIVE_SET_TOLERANCE, working_set=guess
        )
        self._solve_relaxed(problem.with_slack(self.relaxed_qp.row_weights))
        self.reset()

    def solve(self, problem: Problem) -> Solution:
        """Solve the hard or the relaxed problem (relaxed: right after its hard problem)."""
        return self._solve_relaxed(problem) if problem.relaxed else self._solve_hard(problem)

    def _solve_hard(self, problem: Problem) -> Solution:
        infeasible_rows, self._infeasible_rows = self._infeasible_rows, None
        self._relaxed_guess, self._relaxed_active = self._relaxed_active, None
        self._attempt = None
        k = self._k
        C, b = self._hard_rows, self._hard_lower
        C[:k] = problem.A
        b[:k] = problem.lower
        u_nom = -problem.g
        self._set_metric(problem.metric_factor, u_nom)
        C, y_nom = self._rows_y, self._y_nom
        rejected, self._guess_rejected = self._guess_rejected, False
        if self._last_active and not rejected:
            solution = self._on_guess(problem, self._last_active, 0)
            if solution is not None:
                return solution
        if infeasible_rows is not None:
            exact = solve_least_distance(
                y_nom, C, b, tolerance=ACTIVE_SET_TOLERANCE, working_set=infeasible_rows
            )
            if exact.status is LeastDistanceStatus.OPTIMAL:
                solution = self._accept_exact(problem, exact, 0)
                if solution is not None:
                    return solution
            elif exact.status is LeastDistanceStatus.INFEASIBLE:
                return self._not_solved(exact, 0)

        hard = self.hard_qp
        hard.update(problem.A, problem.lower, u_nom, self._R)
        if self._pending is not None:
            u_start, active, multipliers = self._pending
            self._hard.warm_start(
                x=u_start, y=osqp_duals(active, multipliers, hard.n_constraints, k)
            )
            self._pending = None
        if self._R is None:
            self._hard.update(q=hard.q, l=hard.lower, Ax=hard.C_data)
        else:
            self._hard.update(q=hard.q, l=hard.lower, Ax=hard.C_data, Px=hard.P_data)
        result = self._hard.solve(raise_error=False)
        iterations = int(result.info.iter)
        status = result.info.status_val
        if status in _CONVERGED:
            W = None if self._R is None else hard.W
            u = certified_torque(result.x, result.y, u_nom, problem, self._u_min, self._u_max, W)
            if u is not None:
                guess = working_set_guess(result.y, k, self._m)
                self._last_active = guess
                multipliers = np.abs(duals_of(guess, result.y, k))
                return Solution(u, SolutionStatus.OPTIMAL, guess, multipliers, None, iterations)
        guess: tuple[int, ...] = ()  # y is an infeasibility certificate, not multipliers
        if status not in _INFEASIBLE and np.isfinite(result.y).all():
            guess = working_set_guess(result.y, k, self._m)
            solution = self._on_guess(problem, guess, iterations)
            if solution is not None:
                return solution
        exact = solve_least_distance(
            y_nom, C, b, tolerance=ACTIVE_SET_TOLERANCE, working_set=guess
        )
        if exact.status is LeastDistanceStatus.OPTIMAL:
            solution = self._accept_exact(problem, exact, iterations)
            if solution is not None:
                return solution
        return self._not_solved(exact, iterations)

    def _not_solved(self, exact: LeastDistanceSolution, iterations: int) -> Solution:
        """Answer a hard problem with no optimum (proved infeasible, or none found)."""
        infeasible = exact.status is LeastDistanceStatus.INFEASIBLE
        self._attempt = exact
        self._last_active = None
        # The next tick starts its infeasibility proof from the rows of this one.
        self._infeasible_rows = exact.active if infeasible else None
        u = self._clip_finite(self._to_u(exact.u))
        return Solution(
            u if u is not None else np.zeros(self._m).clip(self._u_min, self._u_max),
            SolutionStatus.INFEASIBLE if infeasible else SolutionStatus.FAILED,
            exact.active,
            exact.multipliers,
            None,
            iterations,
            exact.iterations,
        )

    def _solve_relaxed(self, problem: Problem) -> Solution:
        attempt, self._attempt = self._attempt, None
        guess = self._relaxed_guess if attempt is not None else None
        if attempt is None or attempt.status is not LeastDistanceStatus.INFEASIBLE:
            guess = None
        elif not guess:
            # Hard rows and the relaxed problem's u-rows share their numbering.
            guess = attempt.active
        m = self._m
        u_nom = -problem.g
        self._hard_rows[: self._k] = problem.A
        self._set_metric(problem.metric_factor, u_nom)
        relaxed = self.relaxed_qp
        relaxed.update(problem.A, problem.lower, u_nom, self._R)
        exact = self._relaxed_exactly(u_nom, guess) if guess else None
        iterations = 0
        result = None
        if exact is None or exact.status is not LeastDistanceStatus.OPTIMAL:
            if self._R is None:
                self._relaxed.update(q=relaxed.q, l=relaxed.lower, Ax=relaxed.C_data)
            else:
                self._relaxed.update(
                    q=relaxed.q, l=relaxed.lower, Ax=relaxed.C_data, Px=relaxed.P_data
                )
            result = self._relaxed.solve(raise_error=False)
            iterations = int(result.info.iter)
            y = result.y
            exact = self._relaxed_exactly(
                u_nom, working_set_guess(y, self._k, m) if np.isfinite(y).all() else ()
            )
        steps = exact.iterations
        solution = None
        if exact.status is LeastDistanceStatus.OPTIMAL:
            u = self._clip_finite(self._to_u(exact.u[:m]))
            if u is not None:
                self._relaxed_active = exact.active
                solution = Solution(
                    u,
                    SolutionStatus.OPTIMAL,
                    exact.active,
                    exact.multipliers,
                    exact.u[m:] / self._sqrt_weights,
                    iterations,
                    steps,
                )
        elif result is not None and result.info.status_val in _RELAXED_USABLE:
            # OSQP's iterate, not certified: a relaxed torque all the same.
            u = self._clip_finite(result.x)
            if u is not None:
                solution = Solution(
                    u, SolutionStatus.INACCURATE, iterations=iterations, refinement_steps=steps
                )
        if solution is None:
            u = np.minimum(np.maximum(u_nom, self._u_min), self._u_max)
            solution = Solution(
                u, SolutionStatus.FAILED, iterations=iterations, refinement_steps=steps
            )
        # The hard iterate may have diverged on the infeasible problem: restart it from here.
        self._pending = (solution.u, (), _NO_MULTIPLIERS)
        return solution
