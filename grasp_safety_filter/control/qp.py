"""The safety filter's quadratic program, assembled in place with a fixed sparsity pattern.

Variables ``x = (u, s)``: the joint torque u (m,) and, in the relaxed problem only, one
slack s_r >= 0 per barrier row r (k rows). With the barrier rows ``A u >= lower``::

    hard:     min_u    1/2 ||u - u_nom||^2
              s.t.     A u >= lower,   u_min <= u <= u_max

    relaxed:  min_u,s  1/2 ||u - u_nom||^2 + 1/2 sum_r w_r s_r^2
              s.t.     A u + d_r s_r >= lower_r   (every r),
                       u_min <= u <= u_max,   s >= 0

(the paper's objective ``||u - u_nom||^2``, halved). In the relaxed problem each slack is
normalised by its row's norm, ``d_r = ||A_r||`` (1 for a row with ``||A_r|| < 1e-9``), so
``s_r`` is the torque-space distance (N·m) by which row r is given up, whatever the row's
own unit (N, rad/s²): weights w_r are then comparable across families and against the
torque deviation. The actuator box stays hard in both problems.

In the solver's form ``min 1/2 x^T P x + q^T x  s.t.  lower <= C x <= upper``::

    hard:     C = [ A   ]        relaxed:  C = [ A    diag(d) ]
                  [ I_m ]                      [ I_m  0       ]
                                               [ 0    I_k     ]

``C`` is stored in compressed sparse column (CSC) form with every entry of ``A`` (and of
``d``) kept as a structural nonzero, even when its value is 0, so the pattern never changes
from one tick to the next: a solver set up once (OSQP) only receives new values of
``C.data``, ``q`` and ``lower`` (:attr:`C_data` etc., updated in place).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: Threshold below which a row is treated as independent of u when normalising its slack.
ROW_NORM_FLOOR = 1e-9


class SafetyQP:
    """Buffers of one QP (hard or relaxed) with a fixed CSC pattern.

    Attributes:
        n_torques: m, the number of joint torques.
        n_rows: k, the number of barrier rows.
        relaxed: True for the relaxed problem (slack variables present).
        P: Upper triangle of the (constant, diagonal) cost matrix, CSC.
        q: Linear cost, shape (n_variables,): ``(-u_nom, 0)``.
        lower, upper: Constraint bounds, shape (n_constraints,) (``upper`` is ``+inf`` on
            barrier rows and slack bounds).
        C_data: The values of ``C`` in CSC order, shape (nnz,), updated in place.
        A_rows: Writable (k, m) view of the barrier block ``A`` inside :attr:`C_data`.
        lower_rows: Writable (k,) view of the barrier rows' lower bounds in :attr:`lower`.
    """

    def __init__(
        self,
        n_torques: int,
        n_rows: int,
        u_min: np.ndarray,
        u_max: np.ndarray,
        row_weights: np.ndarray | None = None,
    ) -> None:
        """Allocate the buffers and the CSC pattern.

        Args:
            n_torques: m >= 1.
            n_rows: k >= 0 barrier rows.
            u_min: Lower actuator limits, shape (m,), N·m.
            u_max: Upper actuator limits, shape (m,), N·m.
            row_weights: Slack weights w_r > 0, shape (k,), for the relaxed problem;
                None for the hard problem.

        Raises:
            ValueError: Inconsistent sizes or non-positive weights.
        """
        m, k = int(n_torques), int(n_rows)
        if m < 1 or k < 0:
            raise ValueError(f'SafetyQP: expected n_torques >= 1 and n_rows >= 0, got {m}, {k}')
        u_min = np.asarray(u_min, dtype=float)
        u_max = np.asarray(u_max, dtype=float)
        if u_min.shape != (m,) or u_max.shape != (m,):
            raise ValueError(
                f'SafetyQP: expected u_min, u_max of shape ({m},), got {u_min.shape}, '
                f'{u_max.shape}'
            )
        self.n_torques, self.n_rows = m, k
        self.relaxed = row_weights is not None
        n_slack = k if self.relaxed else 0
        self.n_variables = m + n_slack
        self.n_constraints = k + m + n_slack

        cost = np.ones(self.n_variables)
        if self.relaxed:
            weights = np.asarray(row_weights, dtype=float)
            if weights.shape != (k,) or not np.all(np.isfinite(weights) & (weights > 0.0)):
                raise ValueError(f'SafetyQP: expected {k} finite row weights > 0, got {weights!r}')
            cost[m:] = weights
        self.row_weights = cost[m:].copy()
        diagonal = np.arange(self.n_variables, dtype=np.int32)
        self.P = sp.csc_matrix(
            (cost, diagonal, np.arange(self.n_variables + 1, dtype=np.int32)),
            shape=(self.n_variables, self.n_variables),
        )

        self.q = np.zeros(self.n_variables)
        self.lower = np.zeros(self.n_constraints)
        self.upper = np.full(self.n_constraints, np.inf)
        self.lower[k : k + m] = u_min
        self.upper[k : k + m] = u_max
        # Slack bounds s >= 0 are already in place (lower 0, upper inf).

        # Torque column j: rows 0..k-1 (A[:, j]), then row k + j (the box).
        # Slack column r: row r (d_r), then row k + m + r (s_r >= 0).
        torque_indices = np.concatenate(
            (np.tile(np.arange(k), (m, 1)), (k + np.arange(m))[:, np.newaxis]), axis=1
        )
        slack_indices = np.column_stack((np.arange(n_slack), k + m + np.arange(n_slack)))
        self._indices = np.concatenate((torque_indices.ravel(), slack_indices.ravel())).astype(
            np.int32
        )
        self._indptr = np.concatenate(
            (
                (k + 1) * np.arange(m + 1),
                (k + 1) * m + 2 * np.arange(1, n_slack + 1),
            )
        ).astype(np.int32)
        self.C_data = np.ones(self._indices.size)
        torque_block = self.C_data[: m * (k + 1)].reshape(m, k + 1)
        self._slack_scale = self.C_data[m * (k + 1) :].reshape(n_slack, 2)[:, 0]
        self.A_rows = torque_block[:, :k].T
        self.lower_rows = self.lower[:k]
        self.A_rows[:] = 0.0

    @property
    def slack_scale(self) -> np.ndarray:
        """The slack columns' entries d (relaxed problem), shape (k,) (empty when hard)."""
        return self._slack_scale

    @property
    def C(self) -> sp.csc_matrix:
        """The constraint matrix with its fixed pattern (a fresh CSC copy of the buffers)."""
        return sp.csc_matrix(
            (self.C_data.copy(), self._indices.copy(), self._indptr.copy()),
            shape=(self.n_constraints, self.n_variables),
        )

    def set_nominal(self, u_nom: np.ndarray) -> None:
        """Set the nominal torque: ``q = (-u_nom, 0)``."""
        np.negative(u_nom, out=self.q[: self.n_torques])

    def normalise_slacks(self) -> None:
        """Set the slack columns ``d_r = ||A_r||`` (relaxed problem; call after the rows)."""
        if self.relaxed:
            norms = np.sqrt(np.einsum('ij,ij->i', self.A_rows, self.A_rows))
            self._slack_scale[:] = np.where(norms < ROW_NORM_FLOOR, 1.0, norms)

    def update(self, A: np.ndarray, lower: np.ndarray, u_nom: np.ndarray) -> None:
        """Write a tick's barrier rows ``A u >= lower`` and nominal torque into the buffers."""
        self.A_rows[:] = A
        self.lower_rows[:] = lower
        self.set_nominal(u_nom)
        self.normalise_slacks()

    def dense(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(P, q, C, lower, upper)`` as dense copies (P full, infinities as ``inf``).

        For independent solvers and benchmarks; not for the control loop.
        """
        return (
            self.P.toarray(),
            self.q.copy(),
            self.C.toarray(),
            self.lower.copy(),
            self.upper.copy(),
        )
