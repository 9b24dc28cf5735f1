"""A filter step's result for u*: violated families now, margins and active rows when read."""

from __future__ import annotations

import itertools

import numpy as np

from grasp_safety_filter.control.constraints import (
    ActuatorLimits,
    ConstraintFamily,
    ConstraintRows,
    TorqueRateBound,
)
from grasp_safety_filter.control.filter_result import FilterResult, FilterStatus
from grasp_safety_filter.control.margins import Margins, RowValues
from grasp_safety_filter.control.qp_solvers import FEASIBILITY_TOLERANCE
from grasp_safety_filter.control.row_checks import box_margins, residuals, violations
from grasp_safety_filter.model.grasp_state import GraspState

#: A row counts as active when ``A u - lower <= ACTIVE_TOLERANCE`` (and the actuator bound
#: when u is within it of the bound).
ACTIVE_TOLERANCE = 1e-6

_NOT_CERTIFIED = frozenset(
    (FilterStatus.RELAXED, FilterStatus.FALLBACK_LAST_GOOD, FilterStatus.FALLBACK_NOMINAL)
)


class ResultAssembler:
    """Builds :class:`FilterResult` from u* and the tick's rows, and margins at any torque.

    The residuals ``A u* - lower`` (one matrix-vector product) are computed with the
    result: they give the violated families and ``max_violation``. The barrier values h
    (each family's :meth:`values`, the tick's state and u*) and the active rows are
    computed the first time the result's ``margins`` or ``active`` is read
    (:class:`~grasp_safety_filter.control.margins.RowValues`), from what the step had: the
    residuals, u*, the (immutable) state and, for the torque-rate family, whose rows depend
    on the previous torque, this tick's rows.
    """

    def __init__(
        self,
        families: tuple[ConstraintFamily, ...],
        actuator_limits: ActuatorLimits,
        torque_rate: TorqueRateBound | None,
    ) -> None:
        """Lay out the rows: the families' in order, then the actuator box's.

        Args:
            families: The enabled barrier families, in row order.
            actuator_limits: The torque box.
            torque_rate: The torque-rate family when enabled (one of ``families``).
        """
        self.families = families
        self.row_names: tuple[str, ...] = tuple(n for f in families for n in f.names)
        sizes = [len(family.names) for family in families]
        ends = list(itertools.accumulate(sizes))
        self.slices = [slice(end - size, end) for size, end in zip(sizes, ends, strict=True)]
        self._row_family = np.repeat(np.arange(len(sizes), dtype=np.intp), sizes)
        self._torque_rate = torque_rate
        self._u_min = actuator_limits.lower
        self._u_max = actuator_limits.upper
        self.names = (*self.row_names, *actuator_limits.names)
        self._index = {name: i for i, name in enumerate(self.names)}

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
        return Margins(self.names, values, self._index)

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

        def write_margins(values: np.ndarray) -> None:
            self._write_margins(state, u, values, rate_rows)

        return FilterResult(
            u=u,
            status=status,
            relaxed=status in _NOT_CERTIFIED,
            relaxed_families=relaxed_families,
            solve_time=solve_time,
            iterations=iterations,
            max_violation=worst if worst == worst else float('inf'),  # NaN rows: unknown
            row_values=RowValues(
                self.names,
                self._index,
                k,
                slack,
                write_margins,
                lambda out: self._write_box(u, out),
                ACTIVE_TOLERANCE,
            ),
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
