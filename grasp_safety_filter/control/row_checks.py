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
