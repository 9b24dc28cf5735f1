"""Exact reference optima of the filter's QPs, written out from their documentation.

Two independent exact solvers answer each problem: daqp's one-shot ``daqp.solve`` (cold,
dense, its own dual active-set code) and a Goldfarb-Idnani method in numpy
(:mod:`least_distance_oracle`, cold). They must agree with each other, so a backend built
on either one is still checked against the other.

A cost metric W (symmetric positive definite, ``1/2 (u - u_nom)^T W (u - u_nom)``; None: the
identity) goes to daqp as its H, and to the Goldfarb-Idnani method through the change of
variables ``u = L y``, ``L L^T = W^-1`` (numpy's Cholesky of numpy's inverse), which makes
the cost ``1/2 ||y - y_nom||^2``.
"""

import daqp
from least_distance_oracle import LeastDistanceStatus, solve_least_distance
import numpy as np
from scipy.optimize import linprog

#: How far the two references may differ (N·m) before the case counts as ill-posed.
REFERENCE_AGREEMENT = 1e-6

_INF = 1e30


def _box_rows(u_min, u_max):
    m = u_min.size
    return np.vstack((np.eye(m), -np.eye(m))), np.concatenate((u_min, -u_max))


def _factor(W, m):
    """``L`` with ``L L^T = W^-1`` (the identity for W = None)."""
    return np.eye(m) if W is None else np.linalg.cholesky(np.linalg.inv(W))


def hard_optimum(A, lower, u_nom, u_min, u_max, W=None):
    """``(feasible, u*)`` of ``min 1/2 du^T W du s.t. A u >= lower, u_min <= u <= u_max``.

    ``du = u - u_nom``; W None: the identity. Raises AssertionError when the two references
    disagree.
    """
    m = u_nom.size
    H = np.eye(m) if W is None else W
    upper = np.concatenate((u_max, np.full(lower.size, _INF)))
    low = np.concatenate((u_min, lower))
    x, _, flag, _ = daqp.solve(H, -H @ u_nom, np.ascontiguousarray(A), upper, low)
    assert flag in (1, -1), f'daqp exit flag {flag}'
    B, c = _box_rows(u_min, u_max)
    L = _factor(W, m)
    y_nom = np.linalg.solve(L, u_nom)
    exact = solve_least_distance(y_nom, np.vstack((A, B)) @ L, np.concatenate((lower, c)))
    assert exact.status is not LeastDistanceStatus.ITERATION_LIMIT
    feasible = flag == 1
    assert feasible == (exact.status is LeastDistanceStatus.OPTIMAL), 'references disagree'
    if feasible:
        gap = np.abs(np.asarray(x) - L @ exact.u).max()
        assert gap <= REFERENCE_AGREEMENT * (1.0 + np.abs(u_nom).max()), gap
    return feasible, np.asarray(x)


def relaxed_optimum(A, lower, weights, u_nom, u_min, u_max, W=None):
    """``u*`` of the relaxed QP (slack ``s_r >= 0`` per row, normalised by its dual norm).

    ``min 1/2 du^T W du + 1/2 sum_r w_r s_r^2`` s.t. ``A_r u + d_r s_r >= lower_r``
    (``d_r = sqrt(A_r W^-1 A_r^T)``, ``||A_r||`` for W = I; 1 below 1e-9),
    ``u_min <= u <= u_max``, ``s >= 0``. Returns ``(u*, s*)``.
    """
    m, k = u_nom.size, lower.size
    W_u = np.eye(m) if W is None else W
    norms = np.sqrt(np.einsum('ij,ij->i', A @ np.linalg.inv(W_u), A))
    d = np.where(norms < 1e-9, 1.0, norms)
    H = np.zeros((m + k, m + k))
    H[:m, :m] = W_u
    H[m:, m:] = np.diag(weights)
    f = np.concatenate((-W_u @ u_nom, np.zeros(k)))
    C = np.hstack((A, np.diag(d)))
    upper = np.concatenate((u_max, np.full(k, _INF), np.full(k, _INF)))
    low = np.concatenate((u_min, np.zeros(k), lower))
    x, _, flag, _ = daqp.solve(H, f, np.ascontiguousarray(C), upper, low)
    assert flag == 1, flag
    # The same problem in (L^-1 u, sqrt(w) s): a least-distance problem.
    B, c = _box_rows(u_min, u_max)
    L = _factor(W, m)
    rows = np.block(
        [
            [A @ L, np.diag(d / np.sqrt(weights))],
            [B @ L, np.zeros((2 * m, k))],
            [np.zeros((k, m)), np.eye(k)],
        ]
    )
    start = np.concatenate((np.linalg.solve(L, u_nom), np.zeros(k)))
    exact = solve_least_distance(start, rows, np.concatenate((lower, c, np.zeros(k))))
    assert exact.status is LeastDistanceStatus.OPTIMAL
    gap = np.abs(np.asarray(x[:m]) - L @ exact.u[:m]).max()
    assert gap <= REFERENCE_AGREEMENT * (1.0 + np.abs(u_nom).max()), gap
    return np.asarray(x[:m]), np.asarray(x[m:])


def chebyshev_radius(A, lower, effort):
    """Largest torque-space ball inside ``{A u >= lower, |u| <= effort}`` (LP), N·m.

    Negative when the set is empty: the most violated row's distance at the best u.
    """
    m = A.shape[1]
    norms = np.linalg.norm(A, axis=1)
    A_ub = np.vstack(
        (
            np.column_stack((-A, norms)),
            np.column_stack((np.eye(m), np.ones(m))),
            np.column_stack((-np.eye(m), np.ones(m))),
        )
    )
    b_ub = np.concatenate((-lower, effort, effort))
    bounds = [(None, None)] * m + [(None, float(effort.max()))]
    result = linprog(-np.eye(m + 1)[m], A_ub=A_ub, b_ub=b_ub, bounds=bounds)
    assert result.status == 0, result.message
    return result.x[:m], float(result.x[m])
