"""The zeroing control barrier function (ZCBF) rows shared by the relative-degree-two families.

Joint limits, fingertip workspace and object workspace keep coordinates x inside bounds
with the construction of the paper's Section III, implemented once in :class:`BoxBarrier`:
for a coordinate x with ``h = sign (x - bound)``,

    B = h_dot + alpha_1(h)
    h_ddot(u) + alpha_1'(h) h_dot + alpha_2(B) >= 0

which keeps ``B >= 0`` and hence ``h >= 0`` forward invariant (paper, Theorem 1). The rows
are one compiled loop (:mod:`grasp_safety_filter.model.compiled`) instead of a dozen numpy
calls on arrays of 6 to 18 rows; for row r selecting coordinate ``j = index[r]`` with sign
``s = sign[r]`` and ``h_offset[r] = -s c_r`` (c_r the bound)::

    h = s x_j + h_offset,   h_dot = s x_dot_j,   B = h_dot + alpha_1(h)
    A[r] = s x_ddot.matrix[j],   lower[r] = -(s x_ddot.offset[j] + alpha_1'(h) h_dot + alpha_2(B))

with the extended class-K functions of :mod:`grasp_safety_filter.control.class_k`, each given
to the kernels as ``(cubic, gain)``: ``alpha(h) = k h^3`` and ``alpha'(h) = 3 k h^2`` when
cubic, else ``k h`` and ``k``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints.base import (
    BarrierValues,
    check_block,
    CheckedBlock,
    ConstraintRows,
    rows_of,
)
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.grasp_state import GraspState


def planar_box(lower: np.ndarray, upper: np.ndarray) -> dict[str, np.ndarray]:
    """:class:`BoxBarrier`'s ``index``, ``sign`` and ``bound`` for one 2-D box per contact.

    ``lower`` and ``upper`` have shape (n, 2): contact i's coordinates ``(x_i, y_i)`` (at
    ``2 i`` and ``2 i + 1`` of the flattened coordinates) stay in its box. Four rows per
    contact, contact-major: ``x_min, x_max, y_min, y_max``.
    """
    n = lower.shape[0]
    first = 2 * np.arange(n)
    return {
        'index': np.column_stack((first, first, first + 1, first + 1)).ravel(),
        'sign': np.tile([1.0, -1.0, 1.0, -1.0], n),
        'bound': np.column_stack((lower[:, 0], upper[:, 0], lower[:, 1], upper[:, 1])).ravel(),
    }


class BoxBarrier:
    """Relative-degree-two ZCBF rows keeping selected coordinates inside bounds.

    Row r selects coordinate ``x[index[r]]`` with sign ``s_r = +1`` (lower bound) or
    ``-1`` (upper bound) and bound ``c_r``; its barrier and constraint are::

        h_r = s_r (x[index[r]] - c_r)          h_dot_r = s_r x_dot[index[r]]
        B_r = h_dot_r + alpha_1(h_r)
        s_r x_ddot[index[r]](u) + alpha_1'(h_r) h_dot_r + alpha_2(B_r) >= 0

    Subclasses say which coordinates (:meth:`coordinates`) and name the rows.

    Attributes:
        family: Family name (first component of the row names).
        names: Row names.
        alpha1, alpha2: The extended class-K functions.
    """

    family: str = ''
    state_fields: tuple[str, ...] = ()
    #: The packed terms (:class:`~grasp_safety_filter.model.packed_terms.PackedLayout`
    #: names) of x, x_dot and ``[matrix | offset]`` of x_ddot, which :meth:`rows_into`
    #: reads straight from a packed state; None: it reads :meth:`coordinates`.
    packed_fields: tuple[str, str, str] | None = None

    def __init__(
        self,
        index: np.ndarray,
        sign: np.ndarray,
        bound: np.ndarray,
        names: tuple[str, ...],
        alpha1: ClassKFunction,
        alpha2: ClassKFunction,
    ) -> None:
        for parameter, alpha in (('alpha1', alpha1), ('alpha2', alpha2)):
            if not isinstance(alpha, ClassKFunction):
                raise ValueError(
                    f"'{parameter}': expected a ClassKFunction, got {type(alpha).__name__}"
                )
        self.alpha1 = alpha1
        self.alpha2 = alpha2
        self.names = names
        self._index = np.ascontiguousarray(index, dtype=np.intp)
        self._sign = np.ascontiguousarray(sign, dtype=float)
        self._h_offset = -self._sign * np.asarray(bound, dtype=float)
        self._alpha_parameters = (
            alpha1.kind == 'cubic',
            float(alpha1.gain),
            alpha2.kind == 'cubic',
            float(alpha2.gain),
        )
        self._last_h: tuple[GraspState | None, np.ndarray] = (None, self._h_offset)
        self._packed_starts: tuple[Any, tuple[int, int, int, int]] = (None, (0, 0, 0, 0))
        self._block = CheckedBlock()

    @property
    def compiled_packed_rows(self) -> bool:
        """Whether :meth:`rows_into` reads a packed state in compiled code only."""
        return self.packed_fields is not None

    def coordinates(self, state: GraspState) -> tuple[np.ndarray, np.ndarray, AffineMap]:
        """Return the constrained coordinates x, their rates x_dot and ``u ↦ x_ddot``."""
        raise NotImplementedError

    def barrier(self, state: GraspState) -> tuple[np.ndarray, np.ndarray]:
        """``(h, h_dot)`` per row, shape (k,) each."""
        x, x_dot, _ = self.coordinates(state)
        return self._sign * x[self._index] + self._h_offset, self._sign * x_dot[self._index]

    def rows(self, state: GraspState) -> ConstraintRows:
        """Rows ``s x_ddot(u) + alpha_1'(h) h_dot + alpha_2(h_dot + alpha_1(h)) >= 0``.

        In the common form: ``A = s * x_ddot.matrix[index]`` and
        ``lower = -(s * x_ddot.offset[index] + alpha_1'(h) h_dot + alpha_2(B))``
        (:meth:`rows_into`, on new arrays).
        """
        _, _, acceleration = self.coordinates(state)
        return rows_of(self, state, acceleration.matrix.shape[1])

    def rows_into(self, state: GraspState, A: np.ndarray, lower: np.ndarray, start: int) -> None:
        """Write :meth:`rows` into rows ``start:`` of the stacked ``A`` and ``lower``.

        From a packed state (``state.packed_terms``), the compiled rows read x, x_dot and
        x_ddot in its buffer (:attr:`packed_fields`), with no array made per field.
        """
        h = np.empty(self._index.shape[0])
        packed = getattr(state, 'packed_terms', None) if self.packed_fields else None
        if packed is not None:
            terms, layout = packed
            x_start, x_dot_start, x_ddot_start, d = self._packed_field_starts(state, layout)
            self._block.check(A, lower, start, h.shape[0], layout, self.family)
            box_barrier_rows_packed(
                self._index,
                self._sign,
                self._h_offset,
                terms,
                x_start,
                x_dot_start,
                x_ddot_start,
                d,
                self._alpha_parameters,
                A,
                lower,
                start,
                h,
            )
        else:
            x, x_dot, acceleration = self.coordinates(state)
            check_block(A, lower, start, h.shape[0], acceleration.matrix.shape[1], self.family)
            box_barrier_rows_into(
                self._index,
                self._sign,
                self._h_offset,
                x,
                x_dot,
                acceleration.matrix,
                acceleration.offset,
                self._alpha_parameters,
                A,
                lower,
                start,
                h,
            )
        self._last_h = (state, h)

    def _packed_field_starts(
        self, state: GraspState, layout: Any
    ) -> tuple[int, int, int, int]:
        """Where :attr:`packed_fields` start in a layout's buffer, and x's length d.

        The shapes are checked once per layout.
        """
        known, starts = self._packed_starts
        if layout is not known:
            # raises ValueError if the fields do not fit the family
            coordinates, _, _ = self.coordinates(state)
            x, x_dot, x_ddot = self.packed_fields
            starts = (
                layout.start(x),
                layout.start(x_dot),
                layout.start(x_ddot),
                coordinates.shape[0],
            )
            self._packed_starts = (layout, starts)
        return starts

    def values(self, state: GraspState, u: np.ndarray | None = None) -> BarrierValues:
        """Barrier values ``h`` per row (independent of u: relative degree two)."""
        last_state, h = self._last_h
        if state is not last_state:  # states are immutable: reuse h of the last rows() call
            x, _, _ = self.coordinates(state)
            h = self._sign * x[self._index] + self._h_offset
        return BarrierValues(h, self.names)


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
