"""The optimum of a least-distance QP on a guessed working set, and its KKT check, compiled.

For a point y0 (m,), rows ``C y >= b`` (k rows) and a working set W of rows held with
equality, the optimum of ``min 1/2 ||y - y0||^2 s.t. C_W y = b_W`` solves, with
``d = y - y0`` and the multipliers lambda (``d = C_W^T lambda``), the KKT system (one LU
solve, LAPACK's ``dgesv``; no normal equations, so C_W's conditioning is not squared)::

    [ I    -C_W^T ] [ d      ]   [ 0            ]
    [ C_W   0     ] [ lambda ] = [ b_W - C_W y0 ]

It is the optimum of the whole problem (the stopping test of the exact active-set method,
:mod:`~grasp_safety_filter.control.least_distance`) when, with ``n_i = max(||C_i||, 1e-12)``
(a null row then holds only if its residual does) and a distance tolerance tol:

- every row holds: ``(C_i y - b_i) / n_i >= -tol``;
- the rows of W hold with equality: ``|C_i y - b_i| / n_i <= tol``;
- their multipliers are nonnegative: ``lambda_i n_i >= -tol``.

The OSQP backend tries the previous tick's active set this way before any solver call; it
settles almost every tick of a smooth run, so it is one compiled pass (a tick's share of it
was call overhead of some twenty numpy calls on 9 × 40 arrays).
"""

from __future__ import annotations

import math

import numpy as np

from grasp_safety_filter.control.row_checks import row_dot
from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.fortran_linalg import dgesv

#: :func:`working_set_scratch`'s arrays.
WorkingSetScratch = tuple[np.ndarray, np.ndarray]

#: Norm floor of a row in the check (a null row: all zero coefficients).
NULL_ROW_NORM = 1e-12


def working_set_scratch(m: int, rows: int) -> WorkingSetScratch:
    """Return the work arrays of :func:`optimum_on_working_set` for rows C of shape (k, m).

    Sized for any working set of the k rows, with ``s = m + k``: floats, the KKT matrix
    (``s^2``, column-major from 0), its right-hand side (s), the rows' norms (k) and
    distances (k); LAPACK's integers, the pivots (s) and ``info`` (last). Two arrays, not
    six: each array a compiled call takes from Python is unboxed on every call. One per
    caller, reused every call (the answers are new arrays).
    """
    size = m + rows
    return np.empty(size * size + size + 2 * rows), np.empty(size + 1, dtype=np.int32)


@kernel
def optimum_on_working_set(
    y0: np.ndarray,
    C: np.ndarray,
    b: np.ndarray,
    working_set: np.ndarray,
    tolerance: float,
    scratch: WorkingSetScratch,
) -> tuple[int, np.ndarray, np.ndarray]:
    """Solve on the working set and check optimality (module docstring).

    The KKT system is written column-major into ``scratch`` and solved there by ``dgesv``, as
    ``np.linalg.solve`` does on its own copies (a system with an entry not finite is refused
    as ``np.linalg.solve`` refuses it).

    Args:
        y0: Shape (m,).
        C: Shape (k, m), finite.
        b: Shape (k,), finite.
        working_set: Row indices W, distinct, shape (q,), q >= 1.
        tolerance: The distance tolerance tol (y's unit).
        scratch: :func:`working_set_scratch` of (m, k) (or of more rows).

    Returns:
        ``(outcome, y, lambda)``: outcome 1 when y is the optimum of the whole problem,
        0 when a row or a multiplier fails the check, -1 when the KKT system is singular
        (dependent rows) or its solution is not finite; lambda in W's order.

    Raises:
        ValueError: ``scratch`` is smaller than :func:`working_set_scratch` makes for C.
    """
    work, pivots = scratch
    k, m = C.shape
    q = working_set.shape[0]
    n = m + q
    # Offsets in work (working_set_scratch): the KKT matrix at 0, then the others.
    size = m + k
    rhs = size * size
    norms = rhs + size
    distances = norms + k
    if work.shape[0] < distances + k or pivots.shape[0] < size + 1:
        # No bounds checks in compiled code: a smaller scratch would be written past its end.
        raise ValueError('optimum_on_working_set: scratch too small for C; expected '
                         'working_set_scratch(m, k) of C (k, m)')
    for i in range(n * n):
        work[i] = 0.0
    finite = True
    for i in range(m):
        work[i * n + i] = 1.0
        work[rhs + i] = 0.0
    for a in range(q):
        r = working_set[a]
        residual = b[r]
        for c in range(m):
            work[(m + a) * n + c] = -C[r, c]
            work[c * n + m + a] = C[r, c]
            residual -= C[r, c] * y0[c]
            finite = finite and math.isfinite(C[r, c])
        work[rhs + m + a] = residual
        finite = finite and math.isfinite(residual)
    if finite:
        dgesv(n, 1, work, 0, n, pivots, 0, work, rhs, n, pivots, size)
    multipliers = np.empty(q)
    for a in range(q):
        multipliers[a] = work[rhs + m + a]
    if not finite or pivots[size] != 0:  # a singular system (dependent rows)
        return -1, y0, multipliers
    y = np.empty(m)
    for c in range(m):
        y[c] = y0[c] + work[rhs + c]
    for i in range(n):
        if not math.isfinite(work[rhs + i]):
            return -1, y, multipliers
    for i in range(k):
        squares = 0.0
        dot = 0.0
        for c in range(m):
            squares += C[i, c] * C[i, c]
            dot += C[i, c] * y[c]
        work[norms + i] = max(math.sqrt(squares), NULL_ROW_NORM)
        work[distances + i] = (dot - b[i]) / work[norms + i]
        if not work[distances + i] >= -tolerance:
            return 0, y, multipliers
    for a in range(q):
        r = working_set[a]
        norm, distance = work[norms + r], work[distances + r]
        if abs(distance) > tolerance or multipliers[a] * norm < -tolerance:
            return 0, y, multipliers
    return 1, y, multipliers


@kernel
def clipped_optimum_on_working_set(
    y0: np.ndarray,
    C: np.ndarray,
    b: np.ndarray,
    working_set: np.ndarray,
    tolerance: float,
    u_min: np.ndarray,
    u_max: np.ndarray,
    A: np.ndarray,
    lower: np.ndarray,
    feasibility_tolerance: float,
    scratch: WorkingSetScratch,
) -> tuple[int, np.ndarray, np.ndarray]:
    """:func:`optimum_on_working_set` for the identity metric (y = u), then the answer's checks.

    The optimum u is clipped to the box ``[u_min, u_max]`` and the barrier rows
    ``A u >= lower`` are checked to ``feasibility_tolerance`` in their own units, as the
    OSQP backend checks any answer
    (:meth:`~grasp_safety_filter.control.qp_solvers.problem.Solution.row_violation`).

    Returns:
        ``(outcome, u, lambda)``: outcome 1 when u (clipped) is the optimum and passes the
        row check, 0 when a check fails, -1 as :func:`optimum_on_working_set`, -2 when u
        is not finite.
    """
    outcome, y, multipliers = optimum_on_working_set(y0, C, b, working_set, tolerance, scratch)
    if outcome != 1:
        return outcome, y, multipliers
    m = y.shape[0]
    u = np.empty(m)
    for j in range(m):
        if not math.isfinite(y[j]):
            return -2, y, multipliers
        u[j] = min(max(y[j], u_min[j]), u_max[j])
    worst = 0.0
    for r in range(A.shape[0]):
        shortfall = lower[r] - row_dot(A, r, u)
        if not shortfall <= worst:  # NaN counts as violated
            worst = shortfall if shortfall == shortfall else math.inf
    return (1 if worst <= feasibility_tolerance else 0), u, multipliers
