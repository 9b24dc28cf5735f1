"""The OSQP backend's exact active-set steps, in the least-distance coordinates ``y = R^-1 u``.

The previous tick's (or OSQP's) active set tried as a guess (:meth:`ActiveSetSteps._on_guess`),
the exact active-set method's answer checked (:meth:`ActiveSetSteps._accept_exact`), the
relaxed problem solved by the active-set method (:meth:`ActiveSetSteps._relaxed_exactly`), and
the tick's metric factor R that maps between torques u (N·m) and y (``u = R y``; y = u for
the identity metric). :class:`~.osqp_backend.OSQPBackend` holds the state these steps read
and write.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.control.least_distance import (
    LeastDistanceSolution,
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
from grasp_safety_filter.control.row_checks import clip_if_finite
from grasp_safety_filter.control.working_set import (
    clipped_optimum_on_working_set,
    optimum_on_working_set,
    WorkingSetScratch,
)

#: Distance tolerance (N·m, in torque space) of the exact active-set method.
ACTIVE_SET_TOLERANCE = 1e-10


class ActiveSetSteps:
    """The exact active-set steps of :class:`~.osqp_backend.OSQPBackend` (a mixin)."""

    # Set by OSQPBackend: sizes m (torques) and k (barrier rows), the box (N·m), the
    # relaxed QP, the least-distance forms' rows and lower bounds, the tick's metric
    # factor and hard form in y, and the warm-start state these steps update.
    _m: int
    _k: int
    _u_min: np.ndarray
    _u_max: np.ndarray
    relaxed_qp: SafetyQP
    _box_rows: np.ndarray
    _hard_rows: np.ndarray
    _hard_lower: np.ndarray
    _relaxed_rows: np.ndarray
    _relaxed_lower: np.ndarray
    _relaxed_slack_diagonal: np.ndarray
    _sqrt_weights: np.ndarray
    _R: np.ndarray | None
    _rows_y: np.ndarray
    _y_nom: np.ndarray
    _last_active: tuple[int, ...] | None
    _pending: tuple[np.ndarray, tuple[int, ...], np.ndarray] | None
    _working_set: tuple[tuple[int, ...] | None, np.ndarray]
    _solve_scratch: WorkingSetScratch

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
        working_set = self._working_set_array(guess)
        if self._R is None:
            # y = u: the solve, the clip and the row check in one compiled pass.
            outcome, u, multipliers = clipped_optimum_on_working_set(
                self._y_nom,
                self._rows_y,
                self._hard_lower,
                working_set,
                ACTIVE_SET_TOLERANCE,
                self._u_min,
                self._u_max,
                problem.A,
                problem.lower,
                FEASIBILITY_TOLERANCE,
                self._solve_scratch,
            )
            if outcome != 1:
                return None
            return self._keep(
                Solution(u, SolutionStatus.OPTIMAL, guess, multipliers, None, iterations)
            )
        # y = R^-1 u with a metric
        outcome, y, multipliers = optimum_on_working_set(
            self._y_nom,
            self._rows_y,
            self._hard_lower,
            working_set,
            ACTIVE_SET_TOLERANCE,
            self._solve_scratch,
        )
        if outcome != 1:
            return None
        return self._keep_if_rows_hold(problem, y, guess, multipliers, iterations)

    def _working_set_array(self, guess: tuple[int, ...]) -> np.ndarray:
        """Return a guess as an index array (kept while the guess is the same tuple)."""
        known, working_set = self._working_set
        if guess is not known:
            working_set = np.fromiter(guess, dtype=np.intp, count=len(guess))
            self._working_set = (guess, working_set)
        return working_set

    def _accept_exact(
        self, problem: Problem, exact: LeastDistanceSolution, iterations: int
    ) -> Solution | None:
        """Return the active-set optimum, or None if a row fails the check."""
        return self._keep_if_rows_hold(
            problem, exact.u, exact.active, exact.multipliers, iterations, exact.iterations
        )

    def _keep_if_rows_hold(
        self,
        problem: Problem,
        y: np.ndarray,
        active: tuple[int, ...],
        multipliers: np.ndarray,
        iterations: int,
        refinement_steps: int = 0,
    ) -> Solution | None:
        """Keep the optimum ``u = R y`` clipped to the box if finite and its rows hold."""
        u = self._clip_finite(self._to_u(y))
        if u is None:
            return None
        solution = Solution(
            u, SolutionStatus.OPTIMAL, active, multipliers, None, iterations, refinement_steps
        )
        if not solution.row_violation(problem) <= FEASIBILITY_TOLERANCE:
            return None
        return self._keep(solution)

    def _keep(self, solution: Solution) -> Solution:
        """Remember an accepted optimum's active set (next tick's guess) and its answer."""
        self._last_active = solution.active
        self._pending = (solution.u, solution.active, solution.multipliers)
        return solution

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
        """Return x's torque part clipped to the box (a new array), None if not finite."""
        u = np.empty(self._m)
        # One compiled pass: the isfinite / maximum / minimum calls cost µs each.
        return u if clip_if_finite(x, self._u_min, self._u_max, u) else None
