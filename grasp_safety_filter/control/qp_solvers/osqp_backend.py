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
   satisfies the KKT conditions to :data:`CERTIFICATE_TOLERANCE`; else the active set its
   multipliers name is tried as in step 1.
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
from grasp_safety_filter.control.qp_metric import to_metric_coordinates
from grasp_safety_filter.control.qp_solvers.problem import (
    FEASIBILITY_TOLERANCE,
    Problem,
    Solution,
    SolutionStatus,
)
from grasp_safety_filter.control.working_set import (
    clipped_optimum_on_working_set,
    optimum_on_working_set,
)

#: Torque-space tolerance (N·m, per N·m of |u_nom|) of the KKT certificate of OSQP's answer.
CERTIFICATE_TOLERANCE = 1e-10

#: Distance tolerance (N·m, in torque space) of the exact active-set method.
ACTIVE_SET_TOLERANCE = 1e-10

_NO_MULTIPLIERS = np.zeros(0)
_NO_MULTIPLIERS.setflags(write=False)

_CONVERGED = (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
_INFEASIBLE = (
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE,
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE,
)
_RELAXED_USABLE = (*_CONVERGED, osqp.SolverStatus.OSQP_MAX_ITER_REACHED)


class OSQPBackend:
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
        if self._last_active:
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
            self._hard.warm_start(x=u_start, y=self._osqp_duals(active, multipliers))
            self._pending = None
        if self._R is None:
            self._hard.update(q=hard.q, l=hard.lower, Ax=hard.C_data)
        else:
            self._hard.update(q=hard.q, l=hard.lower, Ax=hard.C_data, Px=hard.P_data)
        result = self._hard.solve(raise_error=False)
        iterations = int(result.info.iter)
        status = result.info.status_val
        if status in _CONVERGED:
            u = self._certified(result.x, result.y, u_nom, problem)
            if u is not None:
                guess = self._working_set_guess(result.y)
                self._last_active = guess
                multipliers = np.abs(self._duals_of(guess, result.y))
                return Solution(u, SolutionStatus.OPTIMAL, guess, multipliers, None, iterations)
        guess: tuple[int, ...] = ()  # y is an infeasibility certificate, not multipliers
        if status not in _INFEASIBLE and np.isfinite(result.y).all():
            guess = self._working_set_guess(result.y)
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
                u_nom, self._working_set_guess(y) if np.isfinite(y).all() else ()
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

    def _on_guess(
        self, problem: Problem, guess: tuple[int, ...], iterations: int
    ) -> Solution | None:
        """Return the optimum on a guessed active set W if it satisfies the KKT conditions.

        Every row and box bound holds, the rows of W with equality, and their multipliers
        are nonnegative, to :data:`ACTIVE_SET_TOLERANCE`; stationarity holds by
        construction (one compiled pass,
        :func:`~grasp_safety_filter.control.working_set.optimum_on_working_set`; with the
        identity metric, the box clip and the row check in the same pass:
        :func:`~grasp_safety_filter.control.working_set.clipped_optimum_on_working_set`).
        None otherwise.
        """
        if not guess:
            return None
        if self._R is None:
            # y = u: the solve, the clip and the row check in one compiled pass.
            outcome, u, multipliers = clipped_optimum_on_working_set(
                self._y_nom,
                self._rows_y,
                self._hard_lower,
                np.fromiter(guess, dtype=np.intp, count=len(guess)),
                ACTIVE_SET_TOLERANCE,
                self._u_min,
                self._u_max,
                problem.A,
                problem.lower,
                FEASIBILITY_TOLERANCE,
            )
            if outcome != 1:
                return None
            self._last_active = guess
            self._pending = (u, guess, multipliers)
            return Solution(u, SolutionStatus.OPTIMAL, guess, multipliers, None, iterations)
        outcome, u_guess, multipliers = optimum_on_working_set(
            self._y_nom,
            self._rows_y,
            self._hard_lower,
            np.fromiter(guess, dtype=np.intp, count=len(guess)),
            ACTIVE_SET_TOLERANCE,
        )
        if outcome != 1:  # y = R^-1 u with a metric
            return None
        u = self._clip_finite(self._to_u(u_guess))
        if u is None:
            return None
        solution = Solution(u, SolutionStatus.OPTIMAL, guess, multipliers, None, iterations)
        if not solution.row_violation(problem) <= FEASIBILITY_TOLERANCE:
            return None
        self._last_active = guess
        self._pending = (u, guess, multipliers)
        return solution

    def _accept_exact(
        self, problem: Problem, exact: LeastDistanceSolution, iterations: int
    ) -> Solution | None:
        """Return the active-set optimum, or None if a row fails the check."""
        u = self._clip_finite(self._to_u(exact.u))
        if u is None:
            return None
        solution = Solution(
            u,
            SolutionStatus.OPTIMAL,
            exact.active,
            exact.multipliers,
            None,
            iterations,
            exact.iterations,
        )
        if not solution.row_violation(problem) <= FEASIBILITY_TOLERANCE:
            return None
        self._last_active = exact.active
        self._pending = (u, exact.active, exact.multipliers)
        return solution

    def _certified(
        self, x: np.ndarray, y: np.ndarray, u_nom: np.ndarray, problem: Problem
    ) -> np.ndarray | None:
        """Return OSQP's x clipped to the box if ``(x, y)`` is optimal, else None.

        Optimal: the hard problem's KKT conditions to :data:`CERTIFICATE_TOLERANCE` (scaled by
        ``1 + max |u_nom|``), in torque space, with OSQP's signs (y < 0 at a lower bound) and
        ``n_i = ||A_i||``: every row holds (``A_i u - lower_i >= -tol n_i``); barrier
        multipliers are <= 0; each row and box bound is held with equality or has no
        multiplier (``min(|y_i| n_i, |slack_i| / n_i) <= tol``); and
        ``W (u - u_nom) + A^T y_rows + y_box = 0`` to tol (W = I for the identity metric).
        """
        A, lower = problem.A, problem.lower
        k = self._k
        u = x[: self._m]
        y_rows, y_box = y[:k], y[k:]
        if not (np.isfinite(u).all() and np.isfinite(y).all()):
            return None
        tolerance = CERTIFICATE_TOLERANCE * (1.0 + float(np.abs(u_nom).max()))
        if k:
            norms = np.sqrt(np.einsum('ij,ij->i', A, A)) + 1e-300
            slack = (A @ u - lower) / norms
            if (
                slack.min() < -tolerance
                or y_rows.max() * norms.max() > tolerance
                or np.minimum(np.abs(y_rows) * norms, np.abs(slack)).max() > tolerance
            ):
                return None
        if np.abs(y_box).max() > tolerance:  # some torque at its bound: check which
            to_bound = np.where(y_box < 0.0, u - self._u_min, self._u_max - u)
            if np.minimum(np.abs(y_box), np.abs(to_bound)).max() > tolerance:
                return None
        gradient = u - u_nom if self._R is None else self.hard_qp.W @ (u - u_nom)
        if np.abs(gradient + A.T @ y_rows + y_box).max() > tolerance:
            return None
        return np.minimum(np.maximum(u, self._u_min), self._u_max)

    def _working_set_guess(self, y: np.ndarray) -> tuple[int, ...]:
        """Return the rows OSQP's y calls active, in the problem's numbering, largest |y| first.

        OSQP's constraints: barrier rows (k), the box (m, two-sided), then, relaxed, the
        slack bounds (k); the problem's rows: barrier rows, box rows ``k + 2 j`` (lower) and
        ``k + 2 j + 1`` (upper), slack bounds ``k + 2 m + r``. Multipliers below 1e-9 of
        the largest are noise.
        """
        k, m = self._k, self._m
        magnitude = np.abs(y)
        threshold = 1e-9 * max(1.0, float(magnitude.max(initial=0.0)))
        rows = []
        for i in np.argsort(-magnitude):
            if magnitude[i] <= threshold:
                break
            if k <= i < k + m:
                rows.append(int(k + 2 * (i - k) + (1 if y[i] > 0.0 else 0)))
            elif y[i] < 0.0:  # barrier rows and slack bounds are lower-bounded only
                rows.append(int(i) if i < k else int(i + m))
        return tuple(rows)

    def _duals_of(self, rows: tuple[int, ...], y: np.ndarray) -> np.ndarray:
        """Return OSQP's y of the hard problem's ``rows`` (problem numbering)."""
        k = self._k
        return np.array([y[r] if r < k else y[k + (r - k) // 2] for r in rows])

    def _osqp_duals(self, active: tuple[int, ...], multipliers: np.ndarray) -> np.ndarray:
        """Turn the hard problem's rows and multipliers into OSQP's y (< 0 at a lower bound)."""
        y = np.zeros(self.hard_qp.n_constraints)
        k = self._k
        for row, value in zip(active, multipliers, strict=True):
            if row < k:
                y[row] = -value
            else:
                joint, upper = divmod(row - k, 2)
                y[k + joint] += value if upper else -value
        return y

    def _relaxed_exactly(self, u_nom: np.ndarray, guess: tuple[int, ...]) -> LeastDistanceSolution:
        """Solve the relaxed problem by the active-set method in ``(y, s~ = sqrt(w) s)``.

        ``y = R^-1 u`` (u for the identity metric); the caller maps y back.
        """
        relaxed = self.relaxed_qp
        k, m = self._k, self._m
        C, b = self._relaxed_rows, self._relaxed_lower
        if self._R is None:
            C[:k, :m] = relaxed.A_rows
        else:
            C[:k, :m] = relaxed.A_rows @ self._R
            C[k : k + 2 * m, :m] = self._box_rows @ self._R
        np.divide(relaxed.slack_scale, self._sqrt_weights, out=self._relaxed_slack_diagonal)
        b[:k] = relaxed.lower_rows
        y_nom = u_nom if self._R is None else to_metric_coordinates(self._R, u_nom)
        start = np.concatenate((y_nom, np.zeros(k)))
        return solve_least_distance(start, C, b, tolerance=ACTIVE_SET_TOLERANCE, working_set=guess)

    def _set_metric(self, R: np.ndarray | None, u_nom: np.ndarray) -> None:
        """Take this tick's metric factor: the hard rows and u_nom in ``y = R^-1 u``.

        Call after the hard rows (:attr:`_hard_rows`) hold this tick's A.
        """
        self._R = R
        if R is None:
            self._rows_y = self._hard_rows
            self._y_nom = u_nom
        else:
            self._rows_y = self._hard_rows @ R
            self._y_nom = to_metric_coordinates(R, u_nom)

    def _to_u(self, y: np.ndarray) -> np.ndarray:
        """Map the least-distance form's torque part back: ``u = R y`` (y for the identity)."""
        return y if self._R is None else self._R @ y

    def _clip_finite(self, x: np.ndarray) -> np.ndarray | None:
        u = np.asarray(x[: self._m], dtype=float)
        if not np.isfinite(u).all():
            return None
        return np.minimum(np.maximum(u, self._u_min), self._u_max)
