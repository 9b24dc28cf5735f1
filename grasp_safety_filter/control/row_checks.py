"""The filter step's checks on its stacked rows ``A u >= lower``, compiled.

Each is a loop over at most a few dozen rows of m ≤ 16 torques, where the numpy
expressions they replace (``np.isfinite(x).all()``, ``(A @ u >= lower).all()``,
``np.subtract(A @ u, lower)`` then ``min()``) cost a microsecond or two of call overhead
each (:mod:`grasp_safety_filter.model.compiled`).
"""

from __future__ import annotations

import math

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def row_dot(A: np.ndarray, r: int, u: np.ndarray) -> float:
    """``A[r] · u``, summed from the first column on (every check here sums the same way)."""
    total = 0.0
    for c in range(u.shape[0]):
        total += A[r, c] * u[c]
    return total


@kernel
def all_finite(first: np.ndarray, second: np.ndarray) -> bool:
    """Whether every entry of both 1-D arrays is finite (neither inf nor NaN)."""
    for value in first:
        if not math.isfinite(value):
            return False
    for value in second:
        if not math.isfinite(value):
            return False
    return True


@kernel
def inside(
    A: np.ndarray, lower: np.ndarray, u: np.ndarray, u_min: np.ndarray, u_max: np.ndarray
) -> bool:
    """Whether u satisfies every row ``A u >= lower`` and the box ``u_min <= u <= u_max``.

    A NaN anywhere counts as not satisfied.
    """
    for r in range(A.shape[0]):
        if not row_dot(A, r, u) >= lower[r]:
            return False
    for j in range(u.shape[0]):
        if not (u[j] >= u_min[j] and u[j] <= u_max[j]):
            return False
    return True


@kernel
def residuals(A: np.ndarray, lower: np.ndarray, u: np.ndarray, out: np.ndarray) -> float:
    """Write ``A u - lower`` into ``out[:k]``; return the minimum (NaN if one is, inf if k = 0).

    Args:
        A: The rows, (k, m).
        lower: Their lower bounds, (k,).
        u: The torque, (m,), N·m.
        out: At least k entries.
    """
    smallest = math.inf
    not_a_number = False
    for r in range(A.shape[0]):
        value = row_dot(A, r, u) - lower[r]
        out[r] = value
        if value != value:
            not_a_number = True
        elif value < smallest:
            smallest = value
    return math.nan if not_a_number else smallest


@kernel
def box_margins(u: np.ndarray, u_min: np.ndarray, u_max: np.ndarray, out: np.ndarray) -> None:
    """Write the box rows' margins joint by joint: ``u_j - u_min,j`` then ``u_max,j - u_j`` (N·m).

    Args:
        u: The torque, (m,), N·m.
        u_min: Lower bounds, (m,), N·m.
        u_max: Upper bounds, (m,), N·m.
        out: Shape (2 m,): joint j's lower margin at 2 j, its upper margin at 2 j + 1.
    """
    for j in range(u.shape[0]):
        out[2 * j] = u[j] - u_min[j]
        out[2 * j + 1] = u_max[j] - u[j]


@kernel
def violations(
    residual: np.ndarray, group: np.ndarray, tolerance: float, violated: np.ndarray
) -> float:
    """Flag the groups with a row ``residual_r < -tolerance``; return ``max_r -residual_r``.

    A NaN residual counts as violated, and makes the maximum NaN (as ``np.max``).

    Args:
        residual: ``A u - lower`` per row, (k,).
        group: Each row's group (its family's index), (k,).
        tolerance: The feasibility tolerance, >= 0, in the rows' units.
        violated: One flag per group, all False on entry; set True where a row violates.
    """
    worst = -math.inf
    not_a_number = False
    for r in range(residual.shape[0]):
        value = residual[r]
        if not value >= -tolerance:
            violated[group[r]] = True
        if value != value:
            not_a_number = True
        elif -value > worst:
            worst = -value
    return math.nan if not_a_number else worst
