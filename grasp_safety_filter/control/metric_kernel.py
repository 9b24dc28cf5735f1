"""The inverse-inertia metric's per-tick steps, compiled, equal to their numpy forms to the bit.

A tick with ``qp.metric: inverse_inertia`` (:mod:`~grasp_safety_filter.control.qp_metric`)
adds to the identity metric's tick the factor R of ``M_h / c`` and, on the OSQP backend's
guess (the last active set), the least-distance form in ``y = R^-1 u``. These kernels make
the same LAPACK and BLAS calls as the numpy code (:mod:`~grasp_safety_filter.control.
fortran_linalg`), so a compiled pass gives its answers:

- :func:`inertia_factor`: :func:`~grasp_safety_filter.control.qp_metric.write_inertia_factor`
  (numpy's trace, LAPACK's ``dpotrf`` on a column-major copy, as scipy's wrapper makes);
- :func:`metric_optimum_on_working_set`: the backend's step 1 with a metric (rows ``C R``,
  ``y_nom = R^-1 u_nom`` by ``dtrtrs``, the optimum on the working set, ``u = R y``
  clipped to the box and :meth:`~grasp_safety_filter.control.qp_solvers.problem.Solution.
  row_violation`'s check).
"""

from __future__ import annotations

import math

import numpy as np

from grasp_safety_filter.control.row_checks import clip_if_finite
from grasp_safety_filter.control.working_set import optimum_on_working_set, WorkingSetScratch
from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.fortran_linalg import (
    dpotrf,
    dtrtrs,
    matrix_matrix,
    matrix_vector,
)

#: The longest sum :func:`numpy_sum` adds as numpy does (numpy splits longer ones in two).
PAIRWISE_BLOCK = 128


@kernel
def numpy_sum(x: np.ndarray, start: int, step: int, n: int) -> float:
    """Return ``np.sum`` of n <= :data:`PAIRWISE_BLOCK` entries of x from ``start`` every ``step``.

    numpy's pairwise sum of a strided run: below 8 entries a plain loop from zero; else
    eight running sums, combined in pairs, then the tail one by one.
    """
    if n < 8:
        total = 0.0
        for i in range(n):
            total += x[start + i * step]
        return total
    r = np.empty(8)
    for j in range(8):
        r[j] = x[start + j * step]
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += x[start + (i + j) * step]
        i += 8
    total = (r[0] + r[1] + (r[2] + r[3])) + (r[4] + r[5] + (r[6] + r[7]))
    while i < n:
        total += x[start + i * step]
        i += 1
    return total


@kernel
def inertia_factor(
    terms: np.ndarray, start: int, R: np.ndarray, factor: np.ndarray
) -> bool:
    """Write R, ``R R^T = M_h / c``, from M_h at ``terms[start:]`` (C order), into R.

    Args:
        terms: Holds M_h, (m, m), kg m^2, from ``start``; m <= :data:`PAIRWISE_BLOCK`.
        start: M_h's first entry.
        R: Out: the lower-triangular factor, (m, m) (untouched when False is returned).
        factor: Out: R column-major, (m * m,) (for ``dtrtrs``).

    Returns:
        False where :func:`~grasp_safety_filter.control.qp_metric.write_inertia_factor`
        raises (M_h not finite, or not positive definite).
    """
    m = R.shape[0]
    scale = numpy_sum(terms, start, m + 1, m) / m
    for i in range(m * m):
        if not math.isfinite(terms[start + i]):
            return False
    if not scale > 0.0:
        return False
    for i in range(m):
        for j in range(m):
            factor[j * m + i] = terms[start + i * m + j] / scale
    info = np.zeros(1, dtype=np.int32)
    dpotrf(ord('L'), m, factor, 0, m, info, 0)
    if info[0] != 0:
        return False
    for j in range(m):
        for i in range(m):
            if i < j:
                factor[j * m + i] = 0.0
            R[i, j] = factor[j * m + i]
    return True


@kernel
def metric_optimum_on_working_set(
    C: np.ndarray,
    b: np.ndarray,
    working_set: np.ndarray,
    metric: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    u_nom: np.ndarray,
    box: tuple[np.ndarray, np.ndarray],
    rows: tuple[np.ndarray, np.ndarray],
    tolerances: tuple[float, float],
    scratch: WorkingSetScratch,
) -> tuple[int, np.ndarray, np.ndarray]:
    """Try the working set in ``y = R^-1 u`` as the OSQP backend's step 1 does with a metric.

    Args:
        C: The hard least-distance rows ``[A; B]`` in u, (k + 2m, m).
        b: Their lower bounds, (k + 2m,).
        working_set: Row indices, (q,), q >= 1.
        metric: ``(R, R column-major, C R, y_nom)``: R (m, m) and its copy in;
            ``C R`` (k + 2m, m) and ``y_nom = R^-1 u_nom`` (m,) out.
        u_nom: Nominal torque, (m,), N·m.
        box: ``(u_min, u_max)``, (m,) each, N·m.
        rows: ``C_data``, the hard QP's CSC values holding the barrier rows ``A`` (k, m)
            (column j's k entries from ``j (k + 1)``), and ``lower`` (k,).
        tolerances: The active-set and the feasibility tolerance.
        scratch: :func:`~grasp_safety_filter.control.working_set.working_set_scratch` of
            (m, k + 2m).

    Returns:
        ``(outcome, u, lambda)``: outcome 1 when u (``R y`` clipped) is the optimum and its
        rows hold, 0 when a check fails, -1 when the working set's system is singular,
        -2 when ``R^-1 u_nom`` cannot be formed.
    """
    R, factor, rows_y, y_nom = metric
    u_min, u_max = box
    C_data, lower = rows
    active_set_tolerance, feasibility_tolerance = tolerances
    m = R.shape[0]
    k = lower.shape[0]
    matrix_matrix(C, R, rows_y)
    y_nom[:] = u_nom
    info = np.zeros(1, dtype=np.int32)
    dtrtrs(ord('L'), ord('N'), ord('N'), m, 1, factor, 0, m, y_nom, 0, m, info, 0)
    if info[0] != 0:
        return -2, u_nom, np.empty(0)
    outcome, y, multipliers = optimum_on_working_set(
        y_nom, rows_y, b, working_set, active_set_tolerance, scratch
    )
    if outcome != 1:
        return outcome, y, multipliers
    unclipped = np.empty(m)
    matrix_vector(m, m, R.reshape(-1), 0, m, 1, y, unclipped)
    u = np.empty(m)
    if not clip_if_finite(unclipped, u_min, u_max, u):
        return 0, y, multipliers
    if k == 0:
        return 1, u, multipliers
    residual = np.empty(k)
    matrix_vector(k, m, C_data, 0, 1, k + 1, u, residual)
    for r in range(k):
        if not residual[r] - lower[r] >= -feasibility_tolerance:
            return 0, u, multipliers
    return 1, u, multipliers
