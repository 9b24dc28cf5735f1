"""Exact least-distance QP by the dual active-set method of Goldfarb and Idnani (1983).

Solves, for a point u0 (m,) and rows ``C u >= b`` (k rows, dense)::

    min_u  1/2 ||u - u0||^2   s.t.   C u >= b

The metric is the identity (H = I) throughout. A general metric ``1/2 (u - u0)^T H (u - u0)``
(``qp.metric: inverse_inertia``) is brought to this form by its caller with ``u = R y``,
``R R^T = H^-1``: ``min 1/2 ||y - R^-1 u0||^2 s.t. (C R) y >= b``, the same multipliers
(:mod:`~grasp_safety_filter.control.qp_metric`). Tolerances are then distances in y.

The method keeps a working set W of linearly independent rows held with equality and their
multipliers ``lambda_W >= 0``: u is then the optimum of the problem restricted to W (dual
feasible). Each step adds the most violated row and moves along the direction that keeps
the rows of W satisfied with equality, dropping a row whose multiplier would turn negative.
Every step increases the objective, so the method terminates with the exact optimum (all
rows hold, KKT conditions satisfied by construction) or with a proof of infeasibility (a
violated row that no combination of the working rows can fix).

It can start from a guess of the optimal active set (e.g. from OSQP's multipliers): the
guess is reduced to independent rows with nonnegative multipliers, which is a valid starting
point. When the guess is the optimal active set, the method stops after this check, with no
step: it then certifies the guess exactly.

The OSQP backend (:mod:`~grasp_safety_filter.control.qp_solvers.osqp_backend`) uses it
after OSQP (a first-order method), whose iterates converge slowly on the filter's typical
degenerate problems (several nearly dependent barrier rows active at once). The problem is
small (m = 9 torques): dense linear algebra per step is cheap. Before OSQP, the backend
tries the previous tick's active set
(:func:`~grasp_safety_filter.control.working_set.optimum_on_working_set`: the start of this
method without its rank reduction, one LU solve) and checks the optimality conditions this
method stops on.

The method is one compiled kernel (:mod:`~grasp_safety_filter.control.least_distance_kernel`)
whose every product and factorisation is the BLAS or LAPACK call the numpy formulation
made, so its results are that formulation's, bit for bit, at a fraction of its cost.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np

from grasp_safety_filter.control.least_distance_kernel import (
    INFEASIBLE,
    ITERATION_LIMIT,
    least_distance,
    OPTIMAL,
)


class LeastDistanceStatus(str, Enum):
    """Outcome of :func:`solve_least_distance`."""

    OPTIMAL = 'optimal'
    INFEASIBLE = 'infeasible'
    ITERATION_LIMIT = 'iteration_limit'


_STATUSES = {
    OPTIMAL: LeastDistanceStatus.OPTIMAL,
    INFEASIBLE: LeastDistanceStatus.INFEASIBLE,
    ITERATION_LIMIT: LeastDistanceStatus.ITERATION_LIMIT,
}


@dataclass(frozen=True)
class LeastDistanceSolution:
    """Result of :func:`solve_least_distance`.

    Attributes:
        u: The last primal iterate, shape (m,) (the optimum when OPTIMAL).
        status: Optimal, infeasible or iteration limit.
        active: Indices of the working (active) rows at u.
        multipliers: Their Lagrange multipliers (>= 0), same order as ``active``.
        iterations: Number of add/drop steps after the start (0: the start was optimal).
    """

    u: np.ndarray
    status: LeastDistanceStatus
    active: tuple[int, ...]
    multipliers: np.ndarray
    iterations: int


def solve_least_distance(
    u0: np.ndarray,
    C: np.ndarray,
    b: np.ndarray,
    tolerance: float = 1e-9,
    max_iter: int | None = None,
    working_set: Sequence[int] = (),
) -> LeastDistanceSolution:
    """Minimise ``1/2 ||u - u0||^2`` subject to ``C u >= b``.

    Args:
        u0: Shape (m,).
        C: Shape (k, m), finite.
        b: Shape (k,), finite.
        tolerance: A row counts as satisfied when ``(C_i u - b_i) / ||C_i|| >= -tolerance``
            (a distance in u's unit); a guessed row's multiplier counts as negative when
            its contribution ``lambda_i ||C_i||`` to ``u - u0`` is below ``-tolerance``.
            Rows with ``||C_i|| = 0`` must have ``b_i <= 0``.
        max_iter: Add/drop step limit (default ``10 (k + m)``).
        working_set: Rows guessed active at the optimum, in ``[0, k)`` (order: most
            confident first).

    Returns:
        The solution; ``status`` says whether it is optimal.
    """
    C = np.ascontiguousarray(C, dtype=float)
    b = np.ascontiguousarray(b, dtype=float)
    u0 = np.ascontiguousarray(u0, dtype=float)
    k, m = C.shape
    limit = max_iter if max_iter is not None else 10 * (k + m)
    guess = np.asarray(working_set, dtype=np.intp).reshape(-1)
    u, status, active, multipliers, iterations = least_distance(
        u0, C, b, float(tolerance), limit, guess
    )
    return LeastDistanceSolution(
        u, _STATUSES[status], tuple(active.tolist()), multipliers, iterations
    )
