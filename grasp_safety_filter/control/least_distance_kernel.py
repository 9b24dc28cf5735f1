"""The dual active-set least-distance method (:mod:`.least_distance`) as one compiled kernel.

Its steps are those of the numpy formulation it replaces, with the same BLAS and LAPACK
calls in the same order on the same layouts (:mod:`.fortran_linalg`): numpy's ``@`` as
``ddot`` or ``dgemv``, ``np.linalg.qr`` as ``dgeqrf`` and ``dorgqr``, the rank-revealing
QR as ``dgeqp3`` and ``dorgqr``, the triangular solves as ``dtrtrs``. The working rows'
factors ``C[rows].T = Q R`` are kept in two row-major (m, m) buffers, Q's first q columns
and R's leading (q, q) block in use, as the numpy formulation kept them.
"""

from __future__ import annotations

import math

import numpy as np

from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.fortran_linalg import (
    dgeqp3,
    dgeqrf,
    dorgqr,
    dot,
    dtrtrs,
    matrix_vector,
)

#: A row whose normal has a component below this fraction of its norm outside the span of
#: the working rows' normals is treated as linearly dependent on them.
DEPENDENCE_TOLERANCE = 1e-8

#: The kernel's status codes.
OPTIMAL, INFEASIBLE, ITERATION_LIMIT = 0, 1, 2


@kernel
def _row_norms(C: np.ndarray) -> np.ndarray:
    """``sqrt(einsum('ij,ij->i', C, C))`` summed as numpy's einsum sums (two lanes).

    numpy's contiguous sum of products keeps two partial sums (even and odd entries), adds
    the products of each group of eight entries last to first, and the two sums at the end.
    """
    k, m = C.shape
    norms = np.empty(k)
    for i in range(k):
        even = 0.0
        odd = 0.0
        j = 0
        while j + 8 <= m:
            for block in range(3, -1, -1):
                even = even + C[i, j + 2 * block] * C[i, j + 2 * block]
                odd = odd + C[i, j + 2 * block + 1] * C[i, j + 2 * block + 1]
            j += 8
        while j < m:
            even = even + C[i, j] * C[i, j]
            if j + 1 < m:
                odd = odd + C[i, j + 1] * C[i, j + 1]
            else:
                odd = odd + 0.0
            j += 2
        norms[i] = math.sqrt((even + odd) + 0.0)
    return norms


@kernel
def _workspace(size: float, least: int) -> np.ndarray:
    """Return a LAPACK workspace of the queried ``size``, at least ``least`` entries."""
    return np.empty(max(max(1, least), int(size)))


@kernel
def _factor(C: np.ndarray, rows: np.ndarray, q: int, Q: np.ndarray, R: np.ndarray) -> None:
    """``Q[:, :q], R[:q, :q] = np.linalg.qr(C[rows[:q]].T)`` (as numpy: with workspace queries)."""
    m = C.shape[1]
    packed = np.empty(q * m)  # C[rows].T, column-major
    for j in range(q):
        packed[j * m : (j + 1) * m] = C[rows[j]]
    tau = np.empty(q)
    query = np.empty(1)
    info = np.zeros(1, dtype=np.int32)
    dgeqrf(m, q, packed, 0, m, tau, 0, query, 0, -1, info, 0)
    work = _workspace(query[0], q)
    dgeqrf(m, q, packed, 0, m, tau, 0, work, 0, work.size, info, 0)
    orthonormal = packed.copy()
    dorgqr(m, q, q, orthonormal, 0, m, tau, 0, query, 0, -1, info, 0)
    work = _workspace(query[0], q)
    dorgqr(m, q, q, orthonormal, 0, m, tau, 0, work, 0, work.size, info, 0)
    for i in range(m):
        for j in range(q):
            Q[i * m + j] = orthonormal[j * m + i]
    for i in range(q):
        for j in range(q):
            R[i * m + j] = packed[j * m + i] if i <= j else 0.0


@kernel
def _independent_guess(
    C: np.ndarray,
    candidates: np.ndarray,
    scale: np.ndarray,
    rows: np.ndarray,
    Q: np.ndarray,
    R: np.ndarray,
) -> int:
    """Keep the guess's independent rows (pivoted QR ``C[candidates].T P = Q R``); their count.

    |R_ii| is the part of pivoted row i outside the span of the rows before it; the rank
    ends at the first pivot within tolerance of that span.
    """
    m = C.shape[1]
    n = candidates.size
    r = min(m, n)
    packed = np.empty(n * m)
    for j in range(n):
        packed[j * m : (j + 1) * m] = C[candidates[j]]
    pivots = np.zeros(n, dtype=np.int32)
    tau = np.empty(r)
    info = np.zeros(1, dtype=np.int32)
    work = np.empty(max(64 * (n + 1), 1))
    dgeqp3(m, n, packed, 0, m, pivots, 0, tau, 0, work, 0, work.size, info, 0)
    orthonormal = packed[: r * m].copy()
    work = np.empty(max(64 * r, 1))
    dorgqr(m, r, r, orthonormal, 0, m, tau, 0, work, 0, work.size, info, 0)
    rank = r
    for i in range(r):
        row = candidates[pivots[i] - 1]
        if abs(packed[i * m + i]) <= DEPENDENCE_TOLERANCE * scale[row]:
            rank = i
            break
        rows[i] = row
    for i in range(m):
        for j in range(rank):
            Q[i * m + j] = orthonormal[j * m + i]
    for i in range(rank):
        for j in range(rank):
            R[i * m + j] = packed[j * m + i] if i <= j else 0.0
    return rank


@kernel
def _triangular_solve(
    R: np.ndarray, m: int, q: int, v: np.ndarray, transposed: bool
) -> np.ndarray:
    """Solve ``R x = v`` (or ``R^T x = v``) for R's leading (q, q) block (``dtrtrs``)."""
    matrix = np.empty(q * q)  # column-major, as scipy's wrapper copies it
    for i in range(q):
        for j in range(q):
            matrix[j * q + i] = R[j * m + i] if transposed else R[i * m + j]
    x = v[:q].copy()
    info = np.zeros(1, dtype=np.int32)
    uplo = ord('L') if transposed else ord('U')
    dtrtrs(uplo, ord('N'), ord('N'), q, 1, matrix, 0, q, x, 0, q, info, 0)
    return x


@kernel
def _first_smallest(values: np.ndarray, n: int) -> int:
    """``np.argmin(values[:n])``: the first smallest entry, or the first NaN."""
    best = 0
    for i in range(n):
        if values[i] != values[i]:
            return i
        if values[i] < values[best]:
            best = i
    return best


@kernel
def _drop(
    C: np.ndarray, rows: np.ndarray, q: int, position: int, Q: np.ndarray, R: np.ndarray
) -> int:
    """Remove working row ``position`` of q and factor the rest anew; the new count."""
    rows[position : q - 1] = rows[position + 1 : q].copy()
    q -= 1
    if q:
        _factor(C, rows, q, Q, R)
    return q


@kernel
def _start(
    u0: np.ndarray,
    C: np.ndarray,
    b: np.ndarray,
    scale: np.ndarray,
    eligible: np.ndarray,
    guess: np.ndarray,
    tolerance: float,
    rows: np.ndarray,
    Q: np.ndarray,
    R: np.ndarray,
    multipliers: np.ndarray,
    u: np.ndarray,
) -> int:
    """Find a dual-feasible start: u0, or the optimum with the guessed rows held as equalities.

    The guess is reduced to linearly independent rows, then rows with negative multipliers
    are dropped one at a time (most negative first) until all are nonnegative. Writes u and
    the multipliers; returns the number of working rows.
    """
    k, m = C.shape
    candidates = np.empty(guess.size, dtype=np.intp)
    n = 0
    for g in guess:
        if g < 0 or g >= k:
            raise IndexError('a guessed row is out of range')
        if eligible[g] and not np.any(candidates[:n] == g):
            candidates[n] = g
            n += 1
    q = _independent_guess(C, candidates[:n], scale, rows, Q, R) if n else 0
    rhs = np.empty(m)
    while q:
        # u = u0 + N^T lambda with N u = b_W, N^T = Q R:  R^T R lambda = b_W - N u0.
        working = np.empty(q * m)
        for j in range(q):
            working[j * m : (j + 1) * m] = C[rows[j]]
        matrix_vector(q, m, working, 0, m, 1, u0, rhs)
        for j in range(q):
            rhs[j] = b[rows[j]] - rhs[j]
        lam = _triangular_solve(R, m, q, _triangular_solve(R, m, q, rhs, True), False)
        worst = _first_smallest(lam, q)
        # A multiplier times its row norm is the torque it contributes to u - u0.
        if lam[worst] * scale[rows[worst]] >= -tolerance:
            for j in range(q):
                multipliers[j] = lam[j] if (lam[j] > 0.0 or lam[j] != lam[j]) else 0.0
            matrix_vector(q, q, R, 0, m, 1, multipliers, rhs)
            matrix_vector(m, q, Q, 0, m, 1, rhs[:q].copy(), u)
            u += u0
            return q
        q = _drop(C, rows, q, worst, Q, R)
    u[:] = u0
    return 0


@kernel
def least_distance(
    u0: np.ndarray, C: np.ndarray, b: np.ndarray, tolerance: float, limit: int, guess: np.ndarray
) -> tuple[np.ndarray, int, np.ndarray, np.ndarray, int]:
    """Minimise ``1/2 ||u - u0||^2`` s.t. ``C u >= b`` from a guessed working set.

    Args:
        u0: (m,), contiguous.
        C: (k, m), C-contiguous.
        b: (k,).
        tolerance: Distance tolerance (:func:`.least_distance.solve_least_distance`).
        limit: Add/drop step limit.
        guess: Rows guessed active, (g,) integers.

    Returns:
        u (m,), the status code, the working rows (q,), their multipliers (q,) and the
        number of steps.
    """
    k, m = C.shape
    norms = _row_norms(C)
    largest = 0.0
    for i in range(k):
        largest = max(largest, norms[i])
    floor = 1e-12 * (largest if largest > 1.0 else 1.0)
    scale = np.empty(k)
    eligible = np.empty(k, dtype=np.bool_)
    for i in range(k):
        eligible[i] = not norms[i] <= floor
        scale[i] = norms[i] if eligible[i] else 1.0
        if not eligible[i] and b[i] > 0.0:
            return u0.copy(), INFEASIBLE, np.zeros(0, dtype=np.intp), np.zeros(0), 0
    rows = np.zeros(m, dtype=np.intp)
    Q = np.zeros(m * m)
    R = np.zeros(m * m)
    multipliers = np.zeros(m + 1)
    u = np.empty(m)
    q = _start(u0, C, b, scale, eligible, guess, tolerance, rows, Q, R, multipliers, u)
    flat = C.ravel()
    distance = np.empty(k)
    w, z, product, correction = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    iterations = 0
    while iterations < limit:
        matrix_vector(k, m, flat, 0, m, 1, u, distance)
        for i in range(k):
            distance[i] = (distance[i] - b[i]) / scale[i]
            if not eligible[i]:
                distance[i] = np.inf
        for j in range(q):
            distance[rows[j]] = np.inf
        p = _first_smallest(distance, k)
        if k == 0 or distance[p] >= -tolerance:
            return u, OPTIMAL, rows[:q].copy(), multipliers[:q].copy(), iterations
        new_multiplier = 0.0
        while iterations < limit:
            iterations += 1
            normal = C[p]
            # Split the normal against the working normals: z orthogonal to them, w its
            # coordinates in Q (Gram-Schmidt twice: stable for nearly dependent rows).
            matrix_vector(q, m, Q, 0, 1, m, normal, w)
            matrix_vector(m, q, Q, 0, m, 1, w, product)
            z[:] = normal - product
            matrix_vector(q, m, Q, 0, 1, m, z, correction)
            matrix_vector(m, q, Q, 0, m, 1, correction, product)
            z -= product
            w[:q] += correction[:q]
            r = _triangular_solve(R, m, q, w, False) if q else np.zeros(0)
            # Dual step limit: the first working multiplier to reach zero.
            drop, dual_step = -1, np.inf
            for j in range(q):
                if r[j] > 1e-14:
                    ratio = multipliers[j] / r[j]
                    if drop < 0 or ratio < dual_step:
                        drop, dual_step = j, ratio
            # z = 0 (to round-off): the new normal lies in the span of the working ones.
            if math.sqrt(dot(m, z, 0, 1, z, 0)) > DEPENDENCE_TOLERANCE * scale[p]:
                primal_step = (b[p] - dot(m, normal, 0, 1, u, 0)) / dot(m, z, 0, 1, normal, 0)
            else:
                primal_step = np.inf
            step = primal_step if primal_step < dual_step else dual_step
            if not np.isfinite(step):
                return u, INFEASIBLE, rows[:q].copy(), multipliers[:q].copy(), iterations
            if np.isfinite(primal_step):
                u += step * z
            for j in range(q):
                multipliers[j] = multipliers[j] - step * r[j]
            new_multiplier += step
            if primal_step <= dual_step:
                length = math.sqrt(dot(m, z, 0, 1, z, 0))
                for i in range(m):
                    Q[i * m + q] = z[i] / length
                for i in range(q):
                    R[i * m + q] = w[i]
                R[q * m + q] = length
                rows[q] = p
                multipliers[q] = new_multiplier
                q += 1
                break
            multipliers[drop : q - 1] = multipliers[drop + 1 : q].copy()
            q = _drop(C, rows, q, drop, Q, R)
    return u, ITERATION_LIMIT, rows[:q].copy(), multipliers[:q].copy(), iterations
