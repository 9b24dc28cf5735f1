"""The common form of every constraint family: named rows ``A u >= lower`` on the torque.

Each family turns one grasp constraint into rows that are affine in the joint torque u
(shape (m,), N·m) and reports its barrier values h (its margins, > 0 inside the safe set).
Two families of relative degree two (joint limits, fingertip workspace) share the zeroing
control barrier function (ZCBF) construction of the paper's Section III, implemented once in
:class:`BoxBarrier`: for a coordinate x with ``h = sign (x - bound)``,

    B = h_dot + alpha_1(h)
    h_ddot(u) + alpha_1'(h) h_dot + alpha_2(B) >= 0

which keeps ``B >= 0`` and hence ``h >= 0`` forward invariant (paper, Theorem 1).
"""

from __future__ import annotations

from collections.abc import Sequence
import math
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints.box_kernel import (
    box_barrier_rows,
    box_barrier_rows_into,
    box_barrier_rows_packed,
)
from grasp_safety_filter.control.constraints.shape_checks import check_block, CheckedBlock
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.grasp_state import GraspState


class ConstraintRows(NamedTuple):
    """Rows ``A u >= lower`` of one constraint family (or of a stack of them).

    Attributes:
        A: Shape (k, m): row sensitivities to the joint torque u.
        lower: Shape (k,): lower bounds (in each row's own unit).
        names: k row names, ``"<family>/<joint or contact>/<row>"``.
    """

    A: np.ndarray
    lower: np.ndarray
    names: tuple[str, ...]

    def residual(self, u: np.ndarray) -> np.ndarray:
        """Return ``A u - lower``, shape (k,): >= 0 where the row holds."""
        return self.A @ u - self.lower


class BarrierValues(NamedTuple):
    """Barrier values h (margins) of one family, one per row, > 0 inside the safe set.

    Attributes:
        h: Shape (k,), in the unit of the constrained quantity (rad, N, N·m).
        names: The k row names, the same as the family's constraint rows.
    """

    h: np.ndarray
    names: tuple[str, ...]


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


def box_rows(u_min: np.ndarray, u_max: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return a box as rows ``B u >= c``: ``u_j >= u_min,j``, ``-u_j >= -u_max,j`` per joint.

    Joint-major: joint j's lower row at 2 j, its upper row at 2 j + 1. ``B`` depends only on
    the number of joints (:func:`box_matrix`), ``c`` on the bounds (:func:`box_lower`).
    """
    return box_matrix(u_min.shape[0]), box_lower(u_min, u_max)


def box_matrix(m: int) -> np.ndarray:
    """Return ``B`` of :func:`box_rows` for m joints, shape (2 m, m): ``e_j`` and ``-e_j``."""
    B = np.zeros((2 * m, m))
    B[0::2] = np.eye(m)
    B[1::2] = -np.eye(m)
    return B


def box_lower(u_min: np.ndarray, u_max: np.ndarray) -> np.ndarray:
    """Return ``c`` of :func:`box_rows`, shape (2 m,): ``u_min,j`` and ``-u_max,j`` interleaved."""
    c = np.empty(2 * u_min.shape[0])
    c[0::2] = u_min
    c[1::2] = -u_max
    return c


@runtime_checkable
class ConstraintFamily(Protocol):
    """What the safety filter needs from a constraint family.

    A family may also have ``rows_into(state, A, lower, start)``, writing :meth:`rows`
    into rows ``start:`` of the filter's stacked ``A`` (K, m) and ``lower`` (K,) with no
    array of its own; the filter then calls it instead of :meth:`rows`. A family whose
    ``rows_into`` runs compiled code only on a packed state (``state.packed_terms``), so
    that no numpy floating-point warning can come from it, says so with a true
    ``compiled_packed_rows``.

    Attributes:
        family: Family name, the first component of every row name (e.g. ``"no_slip"``).
        names: Row names, fixed at construction.
        state_fields: The :class:`GraspState` fields the rows read (for error reports).
    """

    family: str
    names: tuple[str, ...]
    state_fields: tuple[str, ...]

    def rows(self, state: GraspState) -> ConstraintRows:
        """Return the family's rows ``A u >= lower`` at this state."""
        ...

    def values(self, state: GraspState, u: np.ndarray) -> BarrierValues:
        """Barrier values h at this state (and torque u where h depends on it)."""
        ...


def validate_names(names: Sequence[str], parameter: str) -> tuple[str, ...]:
    """Check that ``names`` is a non-empty sequence of distinct non-empty strings.

    Raises:
        ValueError: Naming ``parameter``, what was expected and what was received.
    """
    if isinstance(names, str) or not isinstance(names, Sequence):
        raise ValueError(f"'{parameter}': expected a sequence of names, got {names!r}")
    result = tuple(names)
    if not result:
        raise ValueError(f"'{parameter}': expected at least one name, got none")
    for name in result:
        if not isinstance(name, str) or not name or '/' in name:
            raise ValueError(
                f"'{parameter}': expected non-empty strings without '/', got {name!r}"
            )
    if len(set(result)) != len(result):
        raise ValueError(f"'{parameter}': expected distinct names, got {list(result)}")
    return result


def finite_vector(value: object, length: int, parameter: str) -> np.ndarray:
    """``value`` as a finite float vector of the given length (a scalar is broadcast).

    Raises:
        ValueError: Naming ``parameter``, the expected length and what was received.
    """
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"'{parameter}': expected numbers, got {value!r}") from None
    if array.ndim == 0:
        array = np.full(length, float(array))
    if array.shape != (length,):
        raise ValueError(
            f"'{parameter}': expected a scalar or {length} values, got shape {array.shape}"
        )
    if not np.all(np.isfinite(array)):
        raise ValueError(f"'{parameter}': expected finite values, got {array.tolist()}")
    array.setflags(write=False)
    return array


def finite_scalar(
    value: object, parameter: str, minimum: float | None = None, inclusive: bool = True
) -> float:
    """``value`` as a finite float, ``>= minimum`` (``> minimum`` unless ``inclusive``).

    Raises:
        ValueError: Naming ``parameter``, the bound and what was received.
    """
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise ValueError(f"'{parameter}': expected a number, got {value!r}")
    number = float(value)
    if minimum is None:
        if not math.isfinite(number):
            raise ValueError(f"'{parameter}': expected a finite number, got {value!r}")
        return number
    ok = number >= minimum if inclusive else number > minimum
    if not (math.isfinite(number) and ok):
        relation = '>=' if inclusive else '>'
        raise ValueError(
            f"'{parameter}': expected a finite number {relation} {minimum}, got {value!r}"
        )
    return number


def check_limits_ordered(
    lower: np.ndarray,
    upper: np.ndarray,
    joint_names: Sequence[str],
    lower_name: str,
    upper_name: str,
    strict: bool,
) -> None:
    """Check per joint that ``upper > lower`` (``strict``) or ``upper >= lower``.

    Raises:
        ValueError: Naming ``upper_name``, the expected order and, for the first joint out
            of order, its name and both limits.
    """
    bad = np.flatnonzero(upper <= lower if strict else upper < lower)
    if bad.size:
        j = int(bad[0])
        relation = '>' if strict else '>='
        raise ValueError(
            f"'{upper_name}': expected {upper_name} {relation} {lower_name} for every joint, "
            f'got {lower_name} = {lower[j]!r} and {upper_name} = {upper[j]!r} for joint '
            f'{joint_names[j]!r}'
        )


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
        ``lower = -(s * x_ddot.offset[index] + alpha_1'(h) h_dot + alpha_2(B))``, in one
        compiled pass (:func:`~grasp_safety_filter.control.constraints.box_kernel.
        box_barrier_rows`).
        """
        x, x_dot, acceleration = self.coordinates(state)
        A, lower, h = box_barrier_rows(
            self._index,
            self._sign,
            self._h_offset,
            x,
            x_dot,
            acceleration.matrix,
            acceleration.offset,
            self._alpha_parameters,
        )
        self._last_h = (state, h)
        return ConstraintRows(A, lower, self.names)

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

    def packed_rows_arguments(self, state: GraspState, layout: Any) -> tuple[Any, ...]:
        """``(index, sign, h_offset, (x_start, x_dot_start, x_ddot_start, d), alpha_parameters)``.

        :func:`box_barrier_rows_packed`'s arguments for a packed layout, its shapes checked
        once per layout (ValueError naming the field).
        """
        starts = self._packed_field_starts(state, layout)
        return self._index, self._sign, self._h_offset, starts, self._alpha_parameters

    def remember_barrier(self, state: GraspState, h: np.ndarray) -> None:
        """Keep the barrier values h written with the rows at ``state``, for :meth:`values`."""
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
