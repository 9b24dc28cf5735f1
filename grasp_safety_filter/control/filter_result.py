"""What one safety-filter step returns: u*, how it was obtained, margins and active rows."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from grasp_safety_filter.control.margins import Margins, RowValues


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
