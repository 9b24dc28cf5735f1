"""The rows of :class:`~grasp_safety_filter.control.constraints.base.BoxBarrier`, compiled.

For row r selecting coordinate ``j = index[r]`` with sign ``s = sign[r]`` and
``h_offset[r] = -s c_r`` (c_r the bound)::

    h = s x_j + h_offset,   h_dot = s x_dot_j,   B = h_dot + alpha_1(h)
    A[r] = s x_ddot.matrix[j],   lower[r] = -(s x_ddot.offset[j] + alpha_1'(h) h_dot + alpha_2(B))

with the extended class-K functions of :mod:`grasp_safety_filter.control.class_k`, each given
as ``(cubic, gain)``: ``alpha(h) = k h^3`` and ``alpha'(h) = 3 k h^2`` when cubic, else
``k h`` and ``k``. One compiled loop over the rows (:mod:`grasp_safety_filter.model.compiled`)
instead of a dozen numpy calls on arrays of 6 to 18 rows.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def _alpha(cubic: bool, gain: float, h: float) -> float:
    """``k h^3`` (cubic) or ``k h``."""
    if cubic:
        return gain * h * h * h
    return gain * h


@kernel
def _alpha_slope(cubic: bool, gain: float, h: float) -> float:
    """``3 k h^2`` (cubic) or ``k``."""
    if cubic:
        return (3.0 * gain) * h * h
    return gain


@kernel
def box_barrier_rows_into(
    index: np.ndarray,
    sign: np.ndarray,
    h_offset: np.ndarray,
    x: np.ndarray,
    x_dot: np.ndarray,
    x_ddot_matrix: np.ndarray,
    x_ddot_offset: np.ndarray,
    alpha_parameters: tuple[bool, float, bool, float],
    A: np.ndarray,
    lower: np.ndarray,
    start: int,
    h: np.ndarray,
) -> None:
    """Write the rows ``A u >= lower`` at rows ``start:`` of A and lower, h into ``h``.

    Args:
        index: Selected coordinate per row, (k,).
        sign: +1 (lower bound) or -1 (upper bound) per row, (k,).
        h_offset: ``-sign * bound`` per row, (k,).
        x: The coordinates, (d,).
        x_dot: Their rates, (d,).
        x_ddot_matrix: ``u ↦ x_ddot`` sensitivity, (d, m).
        x_ddot_offset: ``x_ddot`` at u = 0, (d,).
        alpha_parameters: ``(alpha_1 cubic, alpha_1 gain, alpha_2 cubic, alpha_2 gain)``:
            whether each class-K function is cubic (else linear), and its gain.
        A: The stacked rows' matrix, (K, m), K ≥ start + k.
        lower: The stacked rows' lower bounds, (K,).
        start: The first row written.
        h: The barrier values, (k,).
    """
    alpha1_cubic, alpha1_gain, alpha2_cubic, alpha2_gain = alpha_parameters
    k = index.shape[0]
    m = x_ddot_matrix.shape[1]
    for r in range(k):
        j = index[r]
        s = sign[r]
        h_r = s * x[j] + h_offset[r]
        h_dot = s * x_dot[j]
        B = h_dot + _alpha(alpha1_cubic, alpha1_gain, h_r)
        lower[start + r] = -(
            s * x_ddot_offset[j]
            + _alpha_slope(alpha1_cubic, alpha1_gain, h_r) * h_dot
            + _alpha(alpha2_cubic, alpha2_gain, B)
        )
        h[r] = h_r
        for c in range(m):
            A[start + r, c] = s * x_ddot_matrix[j, c]


@kernel
def box_barrier_rows(
    index: np.ndarray,
    sign: np.ndarray,
    h_offset: np.ndarray,
    x: np.ndarray,
    x_dot: np.ndarray,
    x_ddot_matrix: np.ndarray,
    x_ddot_offset: np.ndarray,
    alpha_parameters: tuple[bool, float, bool, float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the rows ``A`` (k, m), ``lower`` (k,) and h (k,) (:func:`box_barrier_rows_into`)."""
    k = index.shape[0]
    A = np.empty((k, x_ddot_matrix.shape[1]))
    lower = np.empty(k)
    h = np.empty(k)
    box_barrier_rows_into(
        index, sign, h_offset, x, x_dot, x_ddot_matrix, x_ddot_offset, alpha_parameters,
        A, lower, 0, h,
    )
    return A, lower, h


@kernel
def box_barrier_rows_packed(
    index: np.ndarray,
    sign: np.ndarray,
    h_offset: np.ndarray,
    terms: np.ndarray,
    x_start: int,
    x_dot_start: int,
    x_ddot_start: int,
    n_coordinates: int,
    alpha_parameters: tuple[bool, float, bool, float],
    A: np.ndarray,
    lower: np.ndarray,
    start: int,
    h: np.ndarray,
) -> None:
    """:func:`box_barrier_rows_into` with x, x_dot and x_ddot read from a packed buffer.

    The fields are views of ``terms`` (no copy), so the rows are the same arithmetic.

    Args:
        index: Selected coordinate per row, (k,).
        sign: +1 (lower bound) or -1 (upper bound) per row, (k,).
        h_offset: ``-sign * bound`` per row, (k,).
        terms: The grasp state's packed terms
            (:class:`~grasp_safety_filter.model.packed_terms.PackedLayout`).
        x_start: Where the coordinates x (d,) start in ``terms``.
        x_dot_start: Where their rates (d,) start.
        x_ddot_start: Where ``[matrix | offset]`` of ``u ↦ x_ddot`` (d, m + 1) starts.
        n_coordinates: d.
        alpha_parameters: As :func:`box_barrier_rows_into`'s.
        A: The stacked rows' matrix, (K, m), K ≥ start + k.
        lower: The stacked rows' lower bounds, (K,).
        start: The first row written.
        h: The barrier values, (k,).
    """
    m = A.shape[1]
    d = n_coordinates
    x_ddot = terms[x_ddot_start:x_ddot_start + d * (m + 1)].reshape((d, m + 1))
    box_barrier_rows_into(
        index,
        sign,
        h_offset,
        terms[x_start:x_start + d],
        terms[x_dot_start:x_dot_start + d],
        x_ddot[:, :m],
        x_ddot[:, m],
        alpha_parameters,
        A,
        lower,
        start,
        h,
    )
