"""Torque rate: the filtered torque moves at most a bounded step per tick."""

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
    validate_names,
)
from grasp_safety_filter.model.grasp_state import GraspState


class TorqueRateBound:
    """Keep every joint torque within ``du_max`` (N·m) of the previous tick's u*.

    With ``u_prev`` the torque the filter returned on the previous tick, two rows per
    joint j (joint-major)::

        decrease: u_j - (u_prev,j - du_max) >= 0
        increase: (u_prev,j + du_max) - u_j >= 0

    i.e. ``|u_j - u_prev,j| <= du_max``. A soft contact is rung by a torque that jumps; this
    bounds the jump. With no previous torque (the first tick, after :meth:`forget`) the
    rows are vacuous, ``0 u >= 0``, so the row count never changes. The rows are not a
    safety constraint: the filter relaxes them with their own slack weight, never above the
    safety families'. Margins are the left-hand sides (N·m). Row names:
    ``"torque_rate/<joint>/decrease"`` and ``"torque_rate/<joint>/increase"``.
    """

    family = 'torque_rate'
    state_fields: tuple[str, ...] = ()

    def __init__(self, joint_names: Sequence[str], max_step: float) -> None:
        """Build the rows of every joint.

        Args:
            joint_names: The m joint names, in the model's joint order.
            max_step: The bound du_max > 0, N·m per tick.

        Raises:
            ValueError: An argument is malformed; the message names it.
        """
        self.joint_names = validate_names(joint_names, 'joint_names')
        m = len(self.joint_names)
        self.max_step = finite_scalar(max_step, 'max_step', 0.0, inclusive=False)
        self.names = tuple(
            f'{self.family}/{joint}/{side}'
            for joint in self.joint_names
            for side in ('decrease', 'increase')
        )
        self._A = box_matrix(m)
        self._A.setflags(write=False)
        self._vacuous = ConstraintRows(np.zeros((2 * m, m)), np.zeros(2 * m), self.names)
        self.previous: np.ndarray | None = None

    def remember(self, u: np.ndarray) -> None:
        """Take ``u`` (shape (m,), N·m) as the previous tick's torque."""
        self.previous = finite_vector(u, len(self.joint_names), 'u_previous')

    def forget(self) -> None:
        """Drop the previous torque: the rows are vacuous until :meth:`remember`."""
        self.previous = None

    def rows(self, state: GraspState | None = None) -> ConstraintRows:
        """Rows ``u_j >= u_prev,j - du_max`` and ``-u_j >= -u_prev,j - du_max``."""
        if self.previous is None:
            return self._vacuous
        lower = box_lower(self.previous - self.max_step, self.previous + self.max_step)
        return ConstraintRows(self._A, lower, self.names)

    def values(self, state: GraspState | None, u: np.ndarray) -> BarrierValues:
        """Margins ``du_max -+ (u_j - u_prev,j)`` per joint (N·m); 0 u >= 0 rows give 0."""
        rows = self.rows(state)
        return BarrierValues(rows.A @ u - rows.lower, self.names)
