"""The metric of the safety filter's QP cost: which torque is "closest" to u_nom.

``qp.metric`` chooses the cost of the correction ``du = u - u_nom``:

- ``identity`` (the paper's, eq. 28): ``1/2 ||du||^2``.
- ``inverse_inertia``: ``1/2 du^T W du`` with ``W = c M_h^-1``, ``c = tr(M_h) / m``. For the
  free hand ``M_h ddq = u - h``, so ``du^T M_h^-1 du = ddq_c^T M_h ddq_c`` with ``ddq_c =
  M_h^-1 du`` the joint acceleration the correction causes: the correction is measured by
  the kinetic-energy norm of the motion it excites. A correction that pushes a light joint
  (a fingertip's) costs more than one of the same torque on a heavy joint, so the filter
  does not spend it on internal finger motion (null(J_h) of a redundant hand) that the
  2-norm finds cheap. The scalar c (the mean joint inertia, kg m^2) makes W dimensionless
  and equal to the identity for a hand of equal, uncoupled joint inertias; it does not move
  the optimum (hard or relaxed, see :mod:`~grasp_safety_filter.control.qp`).

Every form of the QP reads the metric through one factor: the lower-triangular Cholesky
factor R of ``W^-1 = M_h / c = R R^T``. With ``x = R^-1 u``, ``du^T W du = ||x - x_nom||^2``:
the problem stays a least-distance problem in x with rows ``(A R) x >= lower``. The solvers
(OSQP, daqp) take a general cost: they get ``W = (R R^T)^-1`` and keep the box as bounds
on u; the relaxed problem's slacks are normalised by the rows' dual norms ``||R^T A_r||``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg.lapack

#: ``qp.metric`` values: the paper's 2-norm, and the inverse-inertia metric.
IDENTITY = 'identity'
INVERSE_INERTIA = 'inverse_inertia'
QP_METRICS: tuple[str, ...] = (IDENTITY, INVERSE_INERTIA)


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


def to_metric_coordinates(R: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Return ``x = R^-1 u`` (shape (m,)): the variable in which the cost is ``||x - x0||^2``."""
    x, info = scipy.linalg.lapack.dtrtrs(R, u, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f'metric factor singular (dtrtrs info {info})')
    return x


def metric_row_norms(A: np.ndarray, R: np.ndarray | None) -> np.ndarray:
    """Return ``||A_r||`` (identity) or ``||R^T A_r|| = sqrt(A_r W^-1 A_r^T)``, shape (k,).

    The dual norm of a row: its value divided by the norm is the distance, in the metric,
    from a torque to the row's boundary.
    """
    rows = A if R is None else A @ R
    return np.sqrt(np.einsum('ij,ij->i', rows, rows))
