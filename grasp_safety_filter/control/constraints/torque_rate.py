"""Torque rate: the filtered torque moves at most a bounded step per tick (or per second)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from grasp_safety_filter.control.constraints.base import (
    BarrierValues,
    box_lower,
    box_matrix,
    ConstraintRows,
    finite_scalar,
    finite_vector,
    rows_of,
    validate_names,
)
from grasp_safety_filter.model.grasp_state import GraspState


class TorqueRateBound:
    """Keep every joint torque within ``du_max`` (N·m) of the previous tick's u*.

    With ``u_prev`` the torque the filter returned on the previous tick, at the state time
    ``t_prev``, two rows per joint j (joint-major)::

        decrease: u_j - (u_prev,j - du_max) >= 0
        increase: (u_prev,j + du_max) - u_j >= 0

    i.e. ``|u_j - u_prev,j| <= du_max``, where ``du_max = max_step`` (N·m per tick), or with a
    rate bound ``max_rate`` (N·m/s) > 0 the tighter ``min(max_step, max_rate (t - t_prev))``
    (``t`` the state's time: the rate holds whatever the control period, and a late tick
    may move further). A soft contact is rung by a torque that jumps; this
    bounds the jump. With no previous torque (the first tick, after :meth:`forget`) the
    rows are vacuous, ``0 u >= 0``, so the row count never changes. The rows are not a
    safety constraint: the filter relaxes them with their own slack weight, never above the
    safety families'. Margins are the left-hand sides (N·m). Row names:
    ``"torque_rate/<joint>/decrease"`` and ``"torque_rate/<joint>/increase"``.
    """

    family = 'torque_rate'
    state_fields: tuple[str, ...] = ()
    compiled_packed_rows = False

    def __init__(
        self, joint_names: Sequence[str], max_step: float, max_rate: float = 0.0
    ) -> None:
        """Build the rows of every joint.

        Args:
            joint_names: The m joint names, in the model's joint order.
            max_step: The bound du_max > 0, N·m per tick.
            max_rate: The bound per second, N·m/s (>= 0; 0: none, ``max_step`` alone).

        Raises:
            ValueError: An argument is malformed; the message names it.
        """
        self.joint_names = validate_names(joint_names, 'joint_names')
        m = len(self.joint_names)
        self.max_step = finite_scalar(max_step, 'max_step', 0.0, inclusive=False)
        self.max_rate = finite_scalar(max_rate, 'max_rate', 0.0)
        self.names = tuple(
            f'{self.family}/{joint}/{side}'
            for joint in self.joint_names
            for side in ('decrease', 'increase')
        )
        self._A = box_matrix(m)
        self._A.setflags(write=False)
        self.previous: np.ndarray | None = None
        self.previous_time: float | None = None

    def remember(self, u: np.ndarray, t: float | None = None) -> None:
        """Take ``u`` (shape (m,), N·m), applied at state time ``t`` (s), as the previous tick's.

        Raises:
            ValueError: A malformed ``u``, or no finite ``t`` with a rate bound.
        """
        self.previous = finite_vector(u, len(self.joint_names), 'u_previous')
        if self.max_rate > 0.0:
            self.previous_time = finite_scalar(t, 't_previous')

    def forget(self) -> None:
        """Drop the previous torque: the rows are vacuous until :meth:`remember`."""
        self.previous = None
        self.previous_time = None

    def step_bound(self, t: float | None) -> float | None:
        """``du_max`` for a tick at state time ``t``, N·m; None: no bound (time went back).

        Raises:
            ValueError: A rate bound and no state time.
        """
        if self.max_rate == 0.0 or self.previous_time is None:
            return self.max_step
        if t is None:
            raise ValueError("'torque_rate.max_rate': the rows need the state's time t")
        elapsed = t - self.previous_time
        return None if elapsed < 0.0 else min(self.max_step, self.max_rate * elapsed)

    def rows(self, state: GraspState | None = None) -> ConstraintRows:
        """Rows ``u_j >= u_prev,j - du_max`` and ``-u_j >= -u_prev,j - du_max`` (new arrays)."""
        return rows_of(self, state, len(self.joint_names))

    def rows_into(
        self, state: GraspState | None, A: np.ndarray, lower: np.ndarray, start: int
    ) -> None:
        """Write :meth:`rows` into rows ``start:`` of the stacked ``A`` and ``lower``.

        Vacuous rows ``0 u >= 0`` without a previous torque or when time went back.
        """
        block = slice(start, start + len(self.names))
        step = None
        if self.previous is not None:
            step = self.step_bound(None if state is None else state.t)
        if step is None:
            A[block] = 0.0
            lower[block] = 0.0
        else:
            A[block] = self._A
            lower[block] = box_lower(self.previous - step, self.previous + step)

    def values(self, state: GraspState | None, u: np.ndarray) -> BarrierValues:
        """Margins ``du_max -+ (u_j - u_prev,j)`` per joint (N·m); 0 u >= 0 rows give 0."""
        rows = self.rows(state)
        return BarrierValues(rows.A @ u - rows.lower, self.names)
