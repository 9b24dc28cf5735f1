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

With the inverse-inertia metric (``qp.metric``, below) the cost is
``1/2 (u - u_nom)^T W (u - u_nom)`` with ``W = (R R^T)^-1`` (R the metric factor, written
every tick), and the norm of the distances is W's: ``d_r = ||R^T A_r||`` (the row's
dual norm), so ``s_r`` is the distance in the metric ``||du||_W = sqrt(du^T W du)`` by which
row r is given up (N·m-equivalent: W is dimensionless and the identity for equal, uncoupled
joint inertias). Scaling W by any factor scales both terms of the relaxed cost alike: the
optimum does not depend on the metric's overall scale, and w_r reads as before, in W's
distance instead of the torque distance.

In the solver's form ``min 1/2 x^T P x + q^T x  s.t.  lower <= C x <= upper``::

    hard:     C = [ A   ]        relaxed:  C = [ A    diag(d) ]
                  [ I_m ]                      [ I_m  0       ]
                                               [ 0    I_k     ]

``C`` is stored in compressed sparse column (CSC) form with every entry of ``A`` (and of
``d``) kept as a structural nonzero, even when its value is 0, so the pattern never changes
from one tick to the next: a solver set up once (OSQP) only receives new values of
``C.data``, ``q`` and ``lower`` (:attr:`C_data` etc., updated in place).

The metric. ``qp.metric`` chooses the cost of the correction ``du = u - u_nom``:

- ``identity`` (the paper's, eq. 28): ``1/2 ||du||^2``.
- ``inverse_inertia``: ``1/2 du^T W du`` with ``W = c M_h^-1``, ``c = tr(M_h) / m``. For the
  free hand ``M_h ddq = u - h``, so ``du^T M_h^-1 du = ddq_c^T M_h ddq_c`` with ``ddq_c =
  M_h^-1 du`` the joint acceleration the correction causes: the correction is measured by
  the kinetic-energy norm of the motion it excites. A correction that pushes a light joint
  (a fingertip's) costs more than one of the same torque on a heavy joint, so the filter
  does not spend it on internal finger motion (null(J_h) of a redundant hand) that the
  2-norm finds cheap. The scalar c (the mean joint inertia, kg m^2) makes W dimensionless
  and equal to the identity for a hand of equal, uncoupled joint inertias; it does not move
  the optimum (hard or relaxed, see above).
- ``acceleration``: ``W = c (S_h^T M_h S_h + S_o^T M_o S_o + eps M_h^-1)`` with
  ``S_h = d ddq / du`` and ``S_o = d x_o_ddot / du`` of the grasped hand's constrained
  dynamics (``state.joint_acceleration``, ``state.object_acceleration``): a correction costs
  the kinetic-energy norm of the acceleration it gives the hand *and the object* (Gauss's
  least constraint), plus ``eps`` (:data:`ACCELERATION_REGULARISATION`) of the
  inverse-inertia cost. A change of internal force (``du = J_h^T f``, ``G f = 0``)
  accelerates nothing, so the filter corrects the squeeze with internal forces before it
  moves the object: the inverse-inertia metric, blind to the object, pays for a friction
  fix with accelerations of the object and of the light fingers (measured on a generated
  three-finger hand at t = 0: 4.4 m/s^2 and 34 rad/s^2 on the object, 115 rad/s^2 on a
  joint, against 0.004 m/s^2, 0.23 and 0.24 rad/s^2 with this metric, docs/any_hand.md).
  On the free hand (``S_h = M_h^-1``, no object) it is the inverse-inertia metric scaled by
  ``1 + eps``.

Every form of the QP reads the metric through one factor: the lower-triangular Cholesky
factor R of ``W^-1 = M_h / c = R R^T``. With ``x = R^-1 u``, ``du^T W du = ||x - x_nom||^2``:
the problem stays a least-distance problem in x with rows ``(A R) x >= lower``. The solvers
(OSQP, daqp) take a general cost: they get ``W = (R R^T)^-1`` and keep the box as bounds
on u; the relaxed problem's slacks are normalised by the rows' dual norms ``||R^T A_r||``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg.lapack
import scipy.sparse as sp

#: ``qp.metric`` values: the paper's 2-norm, the inverse-inertia metric and the
#: grasp-acceleration (least-constraint) metric.
IDENTITY = 'identity'
INVERSE_INERTIA = 'inverse_inertia'
ACCELERATION = 'acceleration'
QP_METRICS: tuple[str, ...] = (IDENTITY, INVERSE_INERTIA, ACCELERATION)

#: The acceleration metric's share of the inverse-inertia metric, eps: it only ranks the
#: corrections that excite no acceleration (internal forces), which the rest leaves free.
ACCELERATION_REGULARISATION = 1e-4

#: Threshold below which a row is treated as independent of u when normalising its slack.
ROW_NORM_FLOOR = 1e-9


class SafetyQP:
    """Buffers of one QP (hard or relaxed) with a fixed CSC pattern.

    Attributes:
        n_torques: m, the number of joint torques.
        n_rows: k, the number of barrier rows.
        relaxed: True for the relaxed problem (slack variables present).
        metric_factor: R of the metric ``W = (R R^T)^-1``, shape (m, m), lower triangular,
            written by the owner each tick; None for the identity metric.
        P: Upper triangle of the cost matrix, CSC (a fresh copy of :attr:`P_data`): diagonal
            for the identity metric, ``W`` dense in the torque block otherwise.
        P_data: The values of P in CSC order (:meth:`update_metric` rewrites them).
        q: Linear cost, shape (n_variables,): ``(-u_nom, 0)``, or ``(-W u_nom, 0)`` with a
            metric (W of the last :meth:`update_metric`).
        nominal: u_nom, shape (m,) (the last :meth:`set_nominal`).
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
        metric: bool = False,
    ) -> None:
        """Allocate the buffers and the CSC pattern.

        Args:
            n_torques: m >= 1.
            n_rows: k >= 0 barrier rows.
            u_min: Lower actuator limits, shape (m,), N·m.
            u_max: Upper actuator limits, shape (m,), N·m.
            row_weights: Slack weights w_r > 0, shape (k,), for the relaxed problem;
                None for the hard problem.
            metric: False: the identity metric (P constant and diagonal); True: a metric
                factor R is kept (:attr:`metric_factor`, the identity until written) and P's
                torque block is the dense upper triangle of ``W = (R R^T)^-1``.

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
        self.metric_factor = np.eye(m) if metric else None
        self.W = np.eye(m)
        self.nominal = np.zeros(m)
        self.q = np.zeros(self.n_variables)
        self._q_torques = self.q[:m]  # the torques' part of q, a view
        if metric:
            # Torque column j: rows 0..j (upper triangle); slack column r: its diagonal.
            self._P_indices = np.concatenate(
                [np.arange(j + 1) for j in range(m)] + [m + np.arange(n_slack)]
            ).astype(np.int32)
            n_upper = m * (m + 1) // 2
            columns = (np.arange(m + 1) * np.arange(1, m + 2)) // 2
            slack_columns = n_upper + np.arange(1, n_slack + 1)
            self._P_indptr = np.concatenate((columns, slack_columns)).astype(np.int32)
            self.P_data = np.empty(self._P_indices.size)
            self.P_data[n_upper:] = cost[m:]
            self.update_metric()
        else:
            self._P_indices = np.arange(self.n_variables, dtype=np.int32)
            self._P_indptr = np.arange(self.n_variables + 1, dtype=np.int32)
            self.P_data = cost

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
    def P(self) -> sp.csc_matrix:
        """The cost matrix's upper triangle with its fixed pattern (a fresh CSC copy)."""
        return sp.csc_matrix(
            (self.P_data.copy(), self._P_indices.copy(), self._P_indptr.copy()),
            shape=(self.n_variables, self.n_variables),
        )

    def update_metric(self) -> None:
        """Write ``W = (R R^T)^-1`` of :attr:`metric_factor` into P and q (identity: no-op)."""
        if self.metric_factor is not None:
            self.W = metric_matrix(self.metric_factor)
            m = self.n_torques
            # Column-major upper triangle: the transpose's row-major lower triangle.
            self.P_data[: m * (m + 1) // 2] = self.W.T[np.tril_indices(m)]
            self.set_nominal(self.nominal)

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
        """Set the nominal torque: ``q = (-u_nom, 0)``, or ``(-W u_nom, 0)`` with a metric."""
        self.nominal[:] = u_nom
        if self.metric_factor is None:
            np.negative(u_nom, out=self._q_torques)
        else:
            np.matmul(self.W, -self.nominal, out=self._q_torques)

    def normalise_slacks(self) -> None:
        """Set the slack columns ``d_r = ||A_r||``, or ``||R^T A_r||`` with a metric.

        Relaxed problem only; call after the rows and the metric factor are written.
        """
        if self.relaxed:
            norms = metric_row_norms(self.A_rows, self.metric_factor)
            self._slack_scale[:] = np.where(norms < ROW_NORM_FLOOR, 1.0, norms)

    def update(
        self,
        A: np.ndarray,
        lower: np.ndarray,
        u_nom: np.ndarray,
        metric_factor: np.ndarray | None = None,
    ) -> None:
        """Write a tick's rows ``A u >= lower``, nominal torque and metric into the buffers.

        ``metric_factor``: this tick's R (metric problems only; None keeps the last one).
        """
        self.A_rows[:] = A
        self.lower_rows[:] = lower
        if metric_factor is not None and self.metric_factor is not None:
            self.metric_factor[:] = metric_factor
            self.nominal[:] = u_nom
            self.update_metric()
        else:
            self.set_nominal(u_nom)
        self.normalise_slacks()

    def dense(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(P, q, C, lower, upper)`` as dense copies (P full, infinities as ``inf``).

        For independent solvers and benchmarks; not for the control loop.
        """
        self.update_metric()
        upper = self.P.toarray()
        return (
            upper + np.triu(upper, 1).T,
            self.q.copy(),
            self.C.toarray(),
            self.lower.copy(),
            self.upper.copy(),
        )


def write_acceleration_factor(
    M_h: np.ndarray,
    joint_acceleration: np.ndarray,
    object_acceleration: np.ndarray,
    M_o: np.ndarray,
    out: np.ndarray,
) -> None:
    """Write R, ``R R^T = W^-1`` of the ``acceleration`` metric (module docstring), into ``out``.

    ``W / c = S_h^T M_h S_h + S_o^T M_o S_o + eps M_h^-1`` with ``c = tr(M_h) / m`` and eps
    :data:`ACCELERATION_REGULARISATION`; R is lower triangular.

    Args:
        M_h: Hand joint-space inertia, shape (m, m), symmetric positive definite, kg m^2.
        joint_acceleration: ``S_h = d ddq / du``, shape (m, m).
        object_acceleration: ``S_o = d x_o_ddot / du``, shape (6, m).
        M_o: Object inertia (spatial), shape (6, 6).
        out: Shape (m, m), overwritten (zeros above the diagonal).

    Raises:
        ValueError: A term is not finite, or W is not positive definite.
    """
    # R_h R_h^T = M_h / c (M_h checked there), so c M_h^-1 = metric_matrix(R_h).
    write_inertia_factor(M_h, out)
    scale = float(np.trace(M_h)) / M_h.shape[0]
    if not all(np.isfinite(term).all() for term in (joint_acceleration, object_acceleration, M_o)):
        raise ValueError('acceleration metric: expected finite S_h, S_o and M_o')
    K = (
        joint_acceleration.T @ M_h @ joint_acceleration
        + object_acceleration.T @ M_o @ object_acceleration
    ) * scale + ACCELERATION_REGULARISATION * metric_matrix(out)
    # With P the order reversal and P W P = L L^T (lower), W^-1 = (P L^-T P) (P L^-T P)^T
    # and P L^-T P is lower triangular: R without forming W^-1.
    flipped = K[::-1, ::-1]
    factor, info = scipy.linalg.lapack.dpotrf(0.5 * (flipped + flipped.T), lower=1, clean=1)
    if info != 0:
        raise ValueError(f'acceleration metric: W not positive definite ({info})')
    inverse, info = scipy.linalg.lapack.dtrtri(factor, lower=1)
    if info != 0:
        raise ValueError(f'acceleration metric: W singular (dtrtri info {info})')
    out[:] = inverse.T[::-1, ::-1]


def write_inertia_factor(M_h: np.ndarray, out: np.ndarray) -> None:
    """Write R, ``R R^T = M_h / c`` with ``c = tr(M_h) / m``, lower triangular, into ``out``.

    Args:
        M_h: Hand joint-space inertia, shape (m, m), symmetric positive definite, kg m^2.
        out: Shape (m, m), overwritten (zeros above the diagonal).

    Raises:
        ValueError: M_h is not finite, or not positive definite.
    """
    m = M_h.shape[0]
    scale = float(np.trace(M_h)) / m
    if not (np.isfinite(M_h).all() and scale > 0.0):
        raise ValueError(f'M_h: expected a finite positive definite ({m}, {m}) matrix')
    factor, info = scipy.linalg.lapack.dpotrf(M_h / scale, lower=1, clean=1)
    if info != 0:
        raise ValueError(f'M_h: expected a positive definite matrix, Cholesky failed ({info})')
    out[:] = factor


def metric_matrix(R: np.ndarray) -> np.ndarray:
    """Return the cost matrix ``W = (R R^T)^-1 = R^-T R^-1``, shape (m, m), symmetric.

    By ``dtrtri`` and one product: LAPACK's ``dpotri`` and a triangular solve with a matrix
    right-hand side took up to 15 ms of CPU time now and then (measured, 16 joints,
    OpenBLAS), ``dtrtri`` under 0.1 ms.
    """
    inverse, info = scipy.linalg.lapack.dtrtri(R, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f'metric factor singular (dtrtri info {info})')
    W = inverse.T @ inverse
    return 0.5 * (W + W.T)


def metric_row_norms(A: np.ndarray, R: np.ndarray | None) -> np.ndarray:
    """Return ``||A_r||`` (identity) or ``||R^T A_r|| = sqrt(A_r W^-1 A_r^T)``, shape (k,).

    The dual norm of a row: its value divided by the norm is the distance, in the metric,
    from a torque to the row's boundary.
    """
    rows = A if R is None else A @ R
    return np.sqrt(np.einsum('ij,ij->i', rows, rows))
