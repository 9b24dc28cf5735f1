"""What one safety-filter step returns: u*, how it was obtained, its margins and active rows.

:class:`ResultAssembler` turns u* and the tick's stacked rows ``A u >= lower`` into a
:class:`FilterResult`. The residuals ``A u* - lower`` (one compiled pass) are computed with
the result: they give the violated families and ``max_violation``. The barrier values h
(each family's ``values``) and the active rows are computed the first time the result's
``margins`` or ``active`` is read (:class:`RowValues`), from what the step had: the
residuals, u*, the (immutable) state and, for the torque-rate family, whose rows depend on
the previous torque, this tick's rows. The row checks are compiled: a few dozen rows of
m ≤ 16 torques, where numpy's calls would cost a microsecond or two of overhead each.
"""

from __future__ import annotations

from collections.abc import ItemsView, Iterator, Mapping, ValuesView
from dataclasses import dataclass, field
from enum import Enum
import math

import numpy as np

from grasp_safety_filter.control.constraints import ActuatorLimits, ConstraintRows
from grasp_safety_filter.control.filter_rows import FilterRows, row_dot
from grasp_safety_filter.control.qp_solvers import FEASIBILITY_TOLERANCE
from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.grasp_state import GraspState

#: A row counts as active when ``A u - lower <= ACTIVE_TOLERANCE`` (and the actuator bound
#: when u is within it of the bound).
ACTIVE_TOLERANCE = 1e-6


class FilterStatus(str, Enum):
    """How :meth:`SafetyFilter.solve` obtained u* (the value is the status string)."""

    NOMINAL = 'nominal'
    """u_nom satisfies every row and the box: ``u* = u_nom``, no QP solved."""
    SOLVED = 'solved'
    """The hard QP's optimum, as the backend found and checked it."""
    RELAXED = 'relaxed'
    """The hard QP is infeasible: the relaxed QP's solution."""
    FALLBACK_LAST_GOOD = 'fallback_last_good'
    """No QP answer: the last solved or nominal u*, clipped to the box."""
    FALLBACK_NOMINAL = 'fallback_nominal'
    """No QP answer and no earlier u*: u_nom clipped to the box."""


_NOT_CERTIFIED = frozenset(
    (FilterStatus.RELAXED, FilterStatus.FALLBACK_LAST_GOOD, FilterStatus.FALLBACK_NOMINAL)
)


class Margins(Mapping[str, float]):
    """Barrier value h per row name: a read-only mapping over a names tuple and a values array.

    Reads like the ``dict`` it stands for (``margins[name]``, iteration in row order,
    ``items()``, ``values()``, ``dict(margins)``, equality with a dict) without building
    one entry per row every tick. :attr:`names` and :attr:`array` give the rows in order.
    """

    __slots__ = ('_array', '_index', '_names')

    def __init__(
        self, names: tuple[str, ...], array: np.ndarray, index: Mapping[str, int] | None = None
    ) -> None:
        """Wrap ``array`` (one value per name, made read-only) under the distinct ``names``.

        ``index``: position of each name (shared between views of the same rows); built
        from ``names`` when None.

        Raises:
            ValueError: ``array`` does not have one value per name.
        """
        if array.shape != (len(names),):
            raise ValueError(
                f'margins: expected {len(names)} values, got an array of shape {array.shape}'
            )
        array.setflags(write=False)
        self._names = names
        self._array = array
        self._index = index if index is not None else {n: i for i, n in enumerate(names)}

    @property
    def names(self) -> tuple[str, ...]:
        """Row names, in row order."""
        return self._names

    @property
    def array(self) -> np.ndarray:
        """The values in row order, shape (len(names),) (read-only)."""
        return self._array

    def __getitem__(self, name: str) -> float:
        return float(self._array[self._index[name]])

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def items(self) -> ItemsView[str, float]:
        """Return the ``(name, h)`` pairs in row order."""
        return _MarginItems(self)

    def values(self) -> ValuesView[float]:
        """Return the values h in row order."""
        return _MarginValues(self)

    def __repr__(self) -> str:
        return f'{type(self).__name__}({dict(self.items())!r})'


class _MarginItems(ItemsView[str, float]):
    """``Margins.items()``, iterated without one lookup per row."""

    _mapping: Margins

    def __iter__(self) -> Iterator[tuple[str, float]]:
        return zip(self._mapping.names, self._mapping.array.tolist(), strict=True)


class _MarginValues(ValuesView[float]):
    """``Margins.values()``, iterated without one lookup per row."""

    _mapping: Margins

    def __iter__(self) -> Iterator[float]:
        return iter(self._mapping.array.tolist())


@dataclass(frozen=True)
class FilterResult:
    """The outcome of one filter step.

    Attributes:
        u: The filtered torque u*, shape (m,), N·m: finite, inside the actuator box.
        status: How it was obtained (:class:`FilterStatus`; compares equal to its string).
        relaxed: True when u* is not certified to satisfy every row (status ``relaxed`` or
            a fallback); False for ``nominal`` and ``solved``.
        relaxed_families: Families with a row violated at u* by more than
            ``FEASIBILITY_TOLERANCE`` (:mod:`~grasp_safety_filter.control.qp_solvers`), in
            stack order.
        margins: Barrier value h per row name (a read-only :class:`Margins` mapping): rad
            (joint limits, fingertip workspace), N (no slip, at the forces ``f_c(u*)``),
            N·m (actuator limits, at u*).
        active: Names of the rows with ``A u* - lower <= ACTIVE_TOLERANCE`` (violated rows
            included) and of the actuator bounds u* touches. ``margins`` and ``active``
            are properties, computed the first time they are read, then kept.
        solve_time: Wall time spent in the QP backend (the hard problem, the relaxed one
            when needed), s; 0 when no QP was solved.
        iterations: The backend's solver iterations (both QPs when relaxed); 0 when no
            QP was solved.
        max_violation: ``max(0, max_r (lower_r - A_r u*))``, in the rows' own units.
        row_values: What gives ``margins`` and ``active`` (on first read, then kept).
    """

    u: np.ndarray
    status: FilterStatus
    relaxed: bool
    relaxed_families: tuple[str, ...]
    solve_time: float
    iterations: int
    max_violation: float
    row_values: RowValues = field(repr=False, compare=False)

    @property
    def margins(self) -> Margins:
        """Barrier value h per row name at u* (see the class docstring)."""
        return self.row_values.margins

    @property
    def active(self) -> tuple[str, ...]:
        """Names of the active rows at u* (see the class docstring)."""
        return self.row_values.active


class ResultAssembler:
    """Builds :class:`FilterResult` from u* and the tick's rows, and margins at any torque.

    Attributes:
        families, row_names, slices: The enabled families, their rows' names and blocks.
        names, index: The barrier rows' names then the actuator box's; their positions.
    """

    def __init__(self, rows: FilterRows, actuator_limits: ActuatorLimits) -> None:
        """Lay out the rows: the families' stacked rows in order, then the actuator box's."""
        self.families = rows.families
        self.row_names = rows.names
        self.slices = rows.slices
        sizes = [len(family.names) for family in self.families]
        self._row_family = np.repeat(np.arange(len(sizes), dtype=np.intp), sizes)
        self._torque_rate = rows.torque_rate
        self._u_min = actuator_limits.lower
        self._u_max = actuator_limits.upper
        self.names = (*self.row_names, *actuator_limits.names)
        self.index = {name: i for i, name in enumerate(self.names)}

    def load_kernels(self, A: np.ndarray, lower: np.ndarray) -> None:
        """Call :meth:`result`'s row checks once, with its types (u* read-only): they load."""
        u = np.zeros(A.shape[1])
        u.setflags(write=False)
        slack = np.empty(len(self.names))
        residuals(A, lower, u, slack)
        violated = np.zeros(len(self.families), dtype=np.bool_)
        violations(slack[: len(self.row_names)], self._row_family, FEASIBILITY_TOLERANCE, violated)

    def margins(self, state: GraspState, u: np.ndarray) -> Margins:
        """Barrier values h per row name (families then actuator limits) at torque u."""
        u = np.asarray(u, dtype=float)
        if u.shape != self._u_min.shape:
            raise ValueError(f'u: expected shape {self._u_min.shape}, got {u.shape}')
        values = np.empty(len(self.names))
        self._write_margins(state, u, values, None)
        return Margins(self.names, values, self.index)

    def result(
        self,
        state: GraspState,
        u: np.ndarray,
        status: FilterStatus,
        rows: tuple[np.ndarray, np.ndarray],
        solve_time: float,
        iterations: int,
    ) -> FilterResult:
        """Return the result for u* (made read-only) on this tick's rows ``(A, lower)``."""
        u.setflags(write=False)
        k = len(self.row_names)
        # Residuals then (when read) box margins, side by side, for the active-row test.
        slack = np.empty(len(self.names))
        smallest = residuals(*rows, u, slack)  # slack[:k] = A u - lower
        relaxed_families: tuple[str, ...] = ()
        worst = 0.0
        # The minimum is NaN when a row is: NaN rows count as violated, as in the test below.
        if k and not smallest >= -FEASIBILITY_TOLERANCE:
            violated = np.zeros(len(self.families), dtype=np.bool_)
            worst = violations(slack[:k], self._row_family, FEASIBILITY_TOLERANCE, violated)
            relaxed_families = tuple(
                family.family
                for family, bad in zip(self.families, violated.tolist(), strict=True)
                if bad
            )
        # The torque-rate rows move with the next tick's u*: keep this tick's.
        rate_rows = self._torque_rate.rows(state) if self._torque_rate is not None else None
        return FilterResult(
            u=u,
            status=status,
            relaxed=status in _NOT_CERTIFIED,
            relaxed_families=relaxed_families,
            solve_time=solve_time,
            iterations=iterations,
            max_violation=worst if worst == worst else float('inf'),  # NaN rows: unknown
            row_values=RowValues(self, state, u, slack, rate_rows),
        )

    def _write_margins(
        self,
        state: GraspState,
        u: np.ndarray,
        values: np.ndarray,
        rate_rows: ConstraintRows | None,
    ) -> None:
        """Write every family's barrier values at u, then the box margins, into ``values``.

        ``rate_rows``: the torque-rate rows to evaluate instead of the family's current ones.
        """
        # Non-finite terms give non-finite margins, reported as such, not as warnings.
        with np.errstate(all='ignore'):
            for family, rows in zip(self.families, self.slices, strict=True):
                if rate_rows is not None and family is self._torque_rate:
                    values[rows] = rate_rows.A @ u - rate_rows.lower  # TorqueRateBound.values
                else:
                    values[rows] = family.values(state, u).h
            self._write_box(u, values[len(self.row_names) :])

    def _write_box(self, u: np.ndarray, out: np.ndarray) -> None:
        """Write the box rows, joint by joint: ``u_j - u_min,j`` then ``u_max,j - u_j`` (N·m)."""
        box_margins(u, self._u_min, self._u_max, out)


class RowValues:
    """One tick's margins and active rows at u*, computed on first read, then kept.

    Holds the row residuals ``A u* - lower`` (already computed by the step), followed by
    room for the box margins; nothing is evaluated until :attr:`margins` or :attr:`active`
    is read.
    """

    __slots__ = ('_active', '_assembler', '_margins', '_rate_rows', '_slack', '_state', '_u')

    def __init__(
        self,
        assembler: ResultAssembler,
        state: GraspState,
        u: np.ndarray,
        slack: np.ndarray,
        rate_rows: ConstraintRows | None,
    ) -> None:
        """Keep the step's state, u* (N·m), residuals and torque-rate rows (or None).

        ``slack`` has one entry per name of ``assembler``: the barrier rows' residuals, then
        room for the box margins, written when :attr:`active` is first read.
        """
        self._assembler = assembler
        self._state = state
        self._u = u
        self._slack = slack
        self._rate_rows = rate_rows
        self._margins: Margins | None = None
        self._active: tuple[str, ...] | None = None

    @property
    def margins(self) -> Margins:
        """Barrier value h per row name at u* (computed on the first read)."""
        if self._margins is None:
            assembler = self._assembler
            values = np.empty(len(assembler.names))
            assembler._write_margins(self._state, self._u, values, self._rate_rows)
            self._margins = Margins(assembler.names, values, assembler.index)
        return self._margins

    @property
    def active(self) -> tuple[str, ...]:
        """Names of the rows whose residual or box margin is at most ACTIVE_TOLERANCE."""
        if self._active is None:
            assembler, slack = self._assembler, self._slack
            assembler._write_box(self._u, slack[len(assembler.row_names) :])
            picked = np.flatnonzero(slack <= ACTIVE_TOLERANCE).tolist()
            self._active = tuple([assembler.names[i] for i in picked])
        return self._active


@kernel
def residuals(A: np.ndarray, lower: np.ndarray, u: np.ndarray, out: np.ndarray) -> float:
    """Write ``A u - lower`` of the rows A (k, m) into ``out[:k]``; return their minimum.

    The minimum is NaN if a residual is, inf if k = 0; u is the torque (m,), N·m.
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
    """Write ``u_j - u_min,j`` at ``out[2 j]``, ``u_max,j - u_j`` at ``out[2 j + 1]`` (N·m)."""
    for j in range(u.shape[0]):
        out[2 * j] = u[j] - u_min[j]
        out[2 * j + 1] = u_max[j] - u[j]


@kernel
def violations(
    residual: np.ndarray, group: np.ndarray, tolerance: float, violated: np.ndarray
) -> float:
    """Flag the groups with a row ``residual_r < -tolerance``; return ``max_r -residual_r``.

    ``residual``: ``A u - lower`` per row, (k,); ``group``: each row's family index, (k,);
    ``violated``: one flag per group, all False on entry. A NaN residual counts as violated,
    and makes the maximum NaN (as ``np.max``).
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
