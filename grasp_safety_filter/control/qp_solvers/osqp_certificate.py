"""OSQP's primal-dual answer read in the hard problem's terms.

Its KKT certificate (:func:`certified_torque`) and the translation between OSQP's dual
vector ``y`` and the problem's active rows and multipliers (:func:`working_set_guess`,
:func:`duals_of`, :func:`osqp_duals`).

OSQP's constraints: barrier rows (k), the box (m, two-sided), then, relaxed, the slack
bounds (k); OSQP's signs: ``y < 0`` at a lower bound. The problem's rows: barrier rows, box
rows ``k + 2 j`` (lower) and ``k + 2 j + 1`` (upper), slack bounds ``k + 2 m + r``, each
with a nonnegative multiplier.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.control.qp_solvers.problem import Problem
from grasp_safety_filter.model.compiled import kernel

#: Torque-space tolerance (N·m, per N·m of |u_nom|) of the KKT certificate of OSQP's answer.
CERTIFICATE_TOLERANCE = 1e-10


def certified_torque(
    x: np.ndarray,
    y: np.ndarray,
    u_nom: np.ndarray,
    problem: Problem,
    u_min: np.ndarray,
    u_max: np.ndarray,
    W: np.ndarray | None,
) -> np.ndarray | None:
    """Return OSQP's x clipped to the box if ``(x, y)`` is optimal, else None.

    Optimal: the hard problem's KKT conditions to :data:`CERTIFICATE_TOLERANCE` (scaled by
    ``1 + max |u_nom|``), in torque space, with OSQP's signs (y < 0 at a lower bound) and
    ``n_i = ||A_i||``: every row holds (``A_i u - lower_i >= -tol n_i``); barrier
    multipliers are <= 0; each row and box bound is held with equality or has no
    multiplier (``min(|y_i| n_i, |slack_i| / n_i) <= tol``); and
    ``W (u - u_nom) + A^T y_rows + y_box = 0`` to tol (W = I for the identity metric).

    Args:
        x: OSQP's primal answer; its first m entries are the torques u (N·m).
        y: OSQP's dual answer, shape (k + m,).
        u_nom: The nominal torque (N·m), shape (m,).
        problem: The hard problem (its rows A u >= lower).
        u_min: Lower torque bounds (N·m), shape (m,).
        u_max: Upper torque bounds (N·m), shape (m,).
        W: The metric ``(R R^T)^-1`` (dimensionless), or None for the identity.
    """
    A, lower = problem.A, problem.lower
    k = problem.n_rows
    u = x[: u_min.shape[0]]
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
        to_bound = np.where(y_box < 0.0, u - u_min, u_max - u)
        if np.minimum(np.abs(y_box), np.abs(to_bound)).max() > tolerance:
            return None
    gradient = u - u_nom if W is None else W @ (u - u_nom)
    if np.abs(gradient + A.T @ y_rows + y_box).max() > tolerance:
        return None
    return np.minimum(np.maximum(u, u_min), u_max)


def working_set_guess(y: np.ndarray, k: int, m: int) -> tuple[int, ...]:
    """Return the rows OSQP's y calls active, in the problem's numbering, largest |y| first.

    Multipliers below 1e-9 of the largest are noise.

    Args:
        y: OSQP's dual answer of the hard (k + m,) or relaxed (2 k + m,) problem.
        k: Number of barrier rows.
        m: Number of torques.
    """
    magnitude = np.abs(y)
    threshold = 1e-9 * max(1.0, float(magnitude.max(initial=0.0)))
    rows = np.empty(y.shape[0], dtype=np.intp)
    count = _rows_by_magnitude(y, magnitude, np.argsort(-magnitude), threshold, k, m, rows)
    return tuple(rows[:count].tolist())


@kernel
def _rows_by_magnitude(
    y: np.ndarray,
    magnitude: np.ndarray,
    order: np.ndarray,
    threshold: float,
    k: int,
    m: int,
    rows: np.ndarray,
) -> int:
    """Write :func:`working_set_guess`'s rows into ``rows`` (y's entries in ``order``); count.

    A loop over a few dozen entries, compiled: in Python it took tens of µs.
    """
    count = 0
    for i in order:
        if magnitude[i] <= threshold:
            break
        if k <= i < k + m:
            rows[count] = k + 2 * (i - k) + (1 if y[i] > 0.0 else 0)
            count += 1
        elif y[i] < 0.0:  # barrier rows and slack bounds are lower-bounded only
            rows[count] = i if i < k else i + m
            count += 1
    return count


def duals_of(rows: tuple[int, ...], y: np.ndarray, k: int) -> np.ndarray:
    """Return OSQP's y of the hard problem's ``rows`` (problem numbering; k barrier rows)."""
    return np.array([y[r] if r < k else y[k + (r - k) // 2] for r in rows])


def osqp_duals(
    active: tuple[int, ...], multipliers: np.ndarray, n_constraints: int, k: int
) -> np.ndarray:
    """Turn the hard problem's rows and multipliers into OSQP's y (< 0 at a lower bound).

    Args:
        active: The active rows, in the problem's numbering.
        multipliers: Their multipliers (nonnegative), shape (len(active),).
        n_constraints: Number of OSQP's constraints (k + m).
        k: Number of barrier rows.
    """
    y = np.zeros(n_constraints)
    for row, value in zip(active, multipliers, strict=True):
        if row < k:
            y[row] = -value
        else:
            joint, upper = divmod(row - k, 2)
            y[k + joint] += value if upper else -value
    return y
