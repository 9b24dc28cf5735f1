"""The common form of every constraint family: named rows ``A u >= lower`` on the torque.

Each family turns one grasp constraint into rows that are affine in the joint torque u
(shape (m,), N·m) and reports its barrier values h (its margins, > 0 inside the safe set).
Here: the rows' and values' types, what the filter needs from a family
(:class:`ConstraintFamily`), and the checks every family makes of its arguments and of the
state fields and row blocks it reads and writes.
"""

from __future__ import annotations

from collections.abc import Sequence
import math
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np

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

    :meth:`rows_into` is the family's one computation of its rows: it writes them into rows
    ``start:`` of the filter's stacked ``A`` (K, m) and ``lower`` (K,), with no array of its
    own; :meth:`rows` returns the same rows as new arrays (:func:`rows_of`). A family whose
    ``rows_into`` runs compiled code only on a packed state (``state.packed_terms``), so
    that no numpy floating-point warning can come from it, says so with a true
    ``compiled_packed_rows``.

    Attributes:
        family: Family name, the first component of every row name (e.g. ``"no_slip"``).
        names: Row names, fixed at construction.
        state_fields: The :class:`GraspState` fields the rows read (for error reports).
        compiled_packed_rows: Whether ``rows_into`` on a packed state is compiled code only.
    """

    family: str
    names: tuple[str, ...]
    state_fields: tuple[str, ...]
    compiled_packed_rows: bool

    def rows(self, state: GraspState) -> ConstraintRows:
        """Return the family's rows ``A u >= lower`` at this state."""
        ...

    def rows_into(self, state: GraspState, A: np.ndarray, lower: np.ndarray, start: int) -> None:
        """Write the family's rows at this state into rows ``start:`` of ``A`` and ``lower``."""
        ...

    def values(self, state: GraspState, u: np.ndarray) -> BarrierValues:
        """Barrier values h at this state (and torque u where h depends on it)."""
        ...


def rows_of(family: ConstraintFamily, state: GraspState | None, n_joints: int) -> ConstraintRows:
    """Return a family's rows at ``state`` as new arrays, written by its ``rows_into``."""
    k = len(family.names)
    A = np.empty((k, n_joints))
    lower = np.empty(k)
    family.rows_into(state, A, lower, 0)
    return ConstraintRows(A, lower, family.names)


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


def check_rows(state_value: np.ndarray, rows: int, field: str) -> None:
    """Raise ValueError if a state array does not have ``rows`` leading entries."""
    if state_value.shape[0] != rows:
        raise ValueError(
            f"state.{field}: expected {rows} rows for this filter's joints/contacts, "
            f'got shape {state_value.shape}'
        )


def check_block(
    A: np.ndarray, lower: np.ndarray, start: int, count: int, n_joints: int, family: str
) -> None:
    """Raise ValueError unless rows ``start:start + count`` fit in ``A`` (K, m) and ``lower``.

    The compiled writers index without bounds checks: a block that does not fit would be
    written past the arrays or, read from a packed buffer, with the wrong row width.
    """
    if (
        A.ndim != 2
        or A.shape[1] != n_joints
        or lower.shape != (A.shape[0],)
        or start < 0
        or start + count > A.shape[0]
    ):
        raise ValueError(
            f'{family}: expected rows {start}:{start + count} of A (K, {n_joints}) and lower '
            f'(K,), got A {A.shape} and lower {lower.shape}'
        )


class CheckedBlock:
    """:func:`check_block` for a packed state's rows, done once for the same buffers.

    A filter writes into the same stacked ``A`` and ``lower`` from the same ``start`` on
    every tick; they (by identity) and the packed layout are checked the first time only.
    """

    __slots__ = ('_last',)

    def __init__(self) -> None:
        """Nothing checked yet."""
        self._last: tuple[Any, Any, Any, int] = (None, None, None, -1)

    def check(
        self, A: np.ndarray, lower: np.ndarray, start: int, count: int, layout: Any, family: str
    ) -> None:
        """:func:`check_block` with the layout's number of joints, unless just passed."""
        last = self._last
        if last[0] is A and last[1] is lower and last[2] is layout and last[3] == start:
            return
        check_block(A, lower, start, count, layout.n_joints, family)
        self._last = (A, lower, layout, start)
