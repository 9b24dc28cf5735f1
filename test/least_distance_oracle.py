"""An exact least-distance QP solver in numpy (Goldfarb-Idnani): a reference for the tests.

``min 1/2 ||u - u0||^2 s.t. C u >= b``, solved by a primal-dual active-set method written
from its documentation, independently of the solvers the filter uses (OSQP, daqp): the
tests hold the filter's answers against it and against daqp's one-shot solve
(:mod:`qp_reference`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
import functools

import numpy as np
import scipy.linalg
import scipy.linalg.lapack


class LeastDistanceStatus(str, Enum):
    """Outcome of :func:`solve_least_distance`."""

    OPTIMAL = 'optimal'
    INFEASIBLE = 'infeasible'
    ITERATION_LIMIT = 'iteration_limit'


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


#: A row whose normal has a component below this fraction of its norm outside the span of
#: the working rows' normals is treated as linearly dependent on them.
DEPENDENCE_TOLERANCE = 1e-8


class _WorkingSet:
    """Working rows with ``C[rows].T = Q R`` (Q orthonormal (m, q), R upper triangular)."""

    def __init__(self, C: np.ndarray) -> None:
        self.C = C
        m = C.shape[1]
        self.rows: list[int] = []
        self._Q = np.zeros((m, m))
        self._R = np.zeros((m, m))

    @property
    def Q(self) -> np.ndarray:
        return self._Q[:, : len(self.rows)]

    @property
    def R(self) -> np.ndarray:
        q = len(self.rows)
        return self._R[:q, :q]

    def project(self, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Split ``normal`` against the working normals: ``(z, w)``.

        z is its part orthogonal to them, w its coordinates in Q (Gram-Schmidt twice:
        stable for nearly dependent rows).
        """
        Q = self.Q
        w = Q.T @ normal
        z = normal - Q @ w
        correction = Q.T @ z
        return z - Q @ correction, w + correction

    def add(self, row: int, z: np.ndarray, w: np.ndarray) -> None:
        q = len(self.rows)
        length = float(np.sqrt(z @ z))
        self._Q[:, q] = z / length
        self._R[:q, q] = w
        self._R[q, q] = length
        self.rows.append(row)

    def replace(self, rows: list[int], Q: np.ndarray, R: np.ndarray) -> None:
        """Replace the working rows by ``rows`` with ``C[rows].T = Q R``."""
        q = len(rows)
        self.rows = list(rows)
        self._Q[:, :q] = Q
        self._R[:q, :q] = R

    def drop(self, position: int) -> None:
        del self.rows[position]
        q = len(self.rows)
        if q:
            self._Q[:, :q], self._R[:q, :q] = np.linalg.qr(self.C[self.rows].T)

    def coefficients(self, normal_in_Q: np.ndarray) -> np.ndarray:
        """R with ``C[rows].T r = Q normal_in_Q``: solves ``R r = normal_in_Q``."""
        return _solve_triangular(self.R, normal_in_Q, lower=False)


def _solve_triangular(T: np.ndarray, v: np.ndarray, lower: bool) -> np.ndarray:
    """Solve ``T x = v`` for a triangular T (LAPACK ``dtrtrs``, called directly).

    The systems here are small (up to a few dozen unknowns), where scipy's and numpy's
    wrappers would cost more than the solve; ``T`` may be a strided view.
    """
    if not v.size:
        return np.zeros(0)
    x, _ = scipy.linalg.lapack.dtrtrs(T, v, lower=int(lower))
    return x


@functools.lru_cache(maxsize=64)
def _upper_triangle(rows: int, columns: int) -> np.ndarray:
    """Return the mask of the entries on and above the diagonal of a (rows, columns) matrix."""
    mask = np.triu(np.ones((rows, columns), dtype=bool))
    mask.setflags(write=False)
    return mask


def _pivoted_qr(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Economic column-pivoted QR ``M P = Q R`` (LAPACK ``dgeqp3`` and ``dorgqr`` directly).

    As ``scipy.linalg.qr(M, mode='economic', pivoting=True)``, without the wrapper's
    workspace queries and checks, which cost more than the factorisation at these sizes.

    Returns:
        Q (m, r), R (r, n) upper triangular and the pivots (n,), 0-based, r = min(m, n).
    """
    m, n = M.shape
    r = min(m, n)
    packed, pivots, tau, _, info = scipy.linalg.lapack.dgeqp3(M, lwork=max(64 * (n + 1), 1))
    if info != 0:
        raise np.linalg.LinAlgError(f'dgeqp3 failed with info = {info}')
    R = np.where(_upper_triangle(r, n), packed[:r], 0.0)  # np.triu, with the mask kept
    Q, _, info = scipy.linalg.lapack.dorgqr(packed[:, :r], tau[:r], lwork=max(64 * r, 1))
    if info != 0:
        raise np.linalg.LinAlgError(f'dorgqr failed with info = {info}')
    return Q, R, pivots - 1


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
        working_set: Rows guessed active at the optimum (order: most confident first).

    Returns:
        The solution; ``status`` says whether it is optimal.
    """
    C = np.asarray(C, dtype=float)
    b = np.asarray(b, dtype=float)
    u0 = np.asarray(u0, dtype=float)
    k, m = C.shape
    limit = max_iter if max_iter is not None else 10 * (k + m)
    norms = np.sqrt(np.einsum('ij,ij->i', C, C))
    null_rows = norms <= 1e-12 * max(1.0, float(norms.max(initial=0.0)))
    if np.any(b[null_rows] > 0.0):
        return LeastDistanceSolution(u0.copy(), LeastDistanceStatus.INFEASIBLE, (), np.zeros(0), 0)
    scale = np.where(null_rows, 1.0, norms)
    eligible = ~null_rows

    working = _WorkingSet(C)
    u, multipliers = _start(u0, C, b, scale, eligible, working, working_set, tolerance)
    iterations = 0
    while iterations < limit:
        distance = (C @ u - b) / scale
        distance[~eligible] = np.inf
        distance[working.rows] = np.inf
        p = int(np.argmin(distance)) if k else 0
        if k == 0 or distance[p] >= -tolerance:
            return LeastDistanceSolution(
                u, LeastDistanceStatus.OPTIMAL, tuple(working.rows), multipliers, iterations
            )
        new_multiplier = 0.0
        while iterations < limit:
            iterations += 1
            normal = C[p]
            z, w = working.project(normal)
            r = working.coefficients(w)
            # Dual step limit: the first working multiplier to reach zero.
            blocking = np.flatnonzero(r > 1e-14)
            if blocking.size:
                ratios = multipliers[blocking] / r[blocking]
                drop = int(blocking[np.argmin(ratios)])
                dual_step = float(ratios.min())
            else:
                drop, dual_step = -1, np.inf
            # z = 0 (to round-off): the new normal lies in the span of the working ones.
            if float(np.sqrt(z @ z)) > DEPENDENCE_TOLERANCE * scale[p]:
                primal_step = float(b[p] - normal @ u) / float(z @ normal)
            else:
                primal_step = np.inf
            step = min(dual_step, primal_step)
            if not np.isfinite(step):
                return LeastDistanceSolution(
                    u,
                    LeastDistanceStatus.INFEASIBLE,
                    tuple(working.rows),
                    multipliers,
                    iterations,
                )
            if np.isfinite(primal_step):
                u = u + step * z
            multipliers = multipliers - step * r
            new_multiplier += step
            if primal_step <= dual_step:
                working.add(p, z, w)
                multipliers = np.append(multipliers, new_multiplier)
                break
            working.drop(drop)
            multipliers = np.delete(multipliers, drop)
    return LeastDistanceSolution(
        u, LeastDistanceStatus.ITERATION_LIMIT, tuple(working.rows), multipliers, iterations
    )


def _start(
    u0: np.ndarray,
    C: np.ndarray,
    b: np.ndarray,
    scale: np.ndarray,
    eligible: np.ndarray,
    working: _WorkingSet,
    guess: Sequence[int],
    tolerance: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Find a dual-feasible start: u0, or the optimum with the guessed rows held as equalities.

    The guess is reduced to linearly independent rows, then rows with negative multipliers
    are dropped one at a time (most negative first) until all are nonnegative.
    """
    guessed = np.fromiter(guess, dtype=np.intp, count=len(guess))
    guessed = guessed[eligible[guessed]]
    # The distinct eligible rows, in the guess's order (most confident first).
    candidates = np.fromiter(dict.fromkeys(guessed.tolist()), dtype=np.intp)
    if candidates.size:
        # One rank-revealing (column-pivoted) QR picks independent rows from the guess:
        # C[candidates].T P = Q R, |R_ii| the part of pivoted row i outside the span of the
        # rows before it; the rank ends at the first pivot within tolerance of that span.
        Q, R, pivots = _pivoted_qr(C[candidates].T)
        pivoted = candidates[pivots[: min(candidates.size, C.shape[1])]]
        dependent = np.abs(np.diagonal(R)[: pivoted.size]) <= DEPENDENCE_TOLERANCE * scale[pivoted]
        rank = int(np.argmax(dependent)) if dependent.any() else pivoted.size
        working.replace(pivoted[:rank].tolist(), Q[:, :rank], R[:rank, :rank])
    while working.rows:
        # u = u0 + N^T lambda with N u = b_W, N^T = Q R:  R^T R lambda = b_W - N u0.
        rows = working.rows
        R = working.R
        rhs = b[rows] - C[rows] @ u0
        multipliers = _solve_triangular(R, _solve_triangular(R.T, rhs, lower=True), lower=False)
        worst = int(np.argmin(multipliers))
        # A multiplier times its row norm is the torque it contributes to u - u0.
        if multipliers[worst] * scale[rows[worst]] >= -tolerance:
            multipliers = np.maximum(multipliers, 0.0)
            return u0 + working.Q @ (R @ multipliers), multipliers
        working.drop(worst)
    return u0.copy(), np.zeros(0)
