"""Actuator limits: the joint torque box (paper eq. 27), always enforced as hard bounds."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from grasp_safety_filter.control.constraints.base import (
    BarrierValues,
    box_rows,
    check_limits_ordered,
    ConstraintRows,
    finite_vector,
    rows_of,
    validate_names,
)
from grasp_safety_filter.model.grasp_state import GraspState


class ActuatorLimits:
    """Keep every joint torque inside ``[u_min,j, u_max,j]``.

    Two rows per joint j (rows in this order, joint-major)::

        lower: u_j - u_min,j >= 0
        upper: u_max,j - u_j >= 0

    Their margins are those left-hand sides (N·m). The safety filter passes this box to
    the QP as variable bounds, never relaxed. Row names: ``"actuator_limits/<joint>/lower"``
    and ``"actuator_limits/<joint>/upper"``.
    """

    family = 'actuator_limits'
    state_fields: tuple[str, ...] = ()
    compiled_packed_rows = False

    def __init__(
        self,
        joint_names: Sequence[str],
        u_min: float | Sequence[float] | np.ndarray,
        u_max: float | Sequence[float] | np.ndarray,
    ) -> None:
        """Build the torque box.

        Args:
            joint_names: The m joint names, in the model's joint order.
            u_min: Lower torque limits, N·m: one for all joints or one per joint.
            u_max: Upper torque limits, N·m, each >= u_min.

        Raises:
            ValueError: An argument is malformed; the message names it.
        """
        self.joint_names = validate_names(joint_names, 'joint_names')
        m = len(self.joint_names)
        self.lower = finite_vector(u_min, m, 'u_min')
        self.upper = finite_vector(u_max, m, 'u_max')
        check_limits_ordered(
            self.lower, self.upper, self.joint_names, 'u_min', 'u_max', strict=False
        )
        self.names = tuple(
            f'{self.family}/{joint}/{side}'
            for joint in self.joint_names
            for side in ('lower', 'upper')
        )
        self._A, self._lower_rows = box_rows(self.lower, self.upper)
        self._A.setflags(write=False)
        self._lower_rows.setflags(write=False)

    def rows(self, state: GraspState | None = None) -> ConstraintRows:
        """Rows ``u_j >= u_min,j`` and ``-u_j >= -u_max,j`` (independent of the state)."""
        return rows_of(self, state, len(self.joint_names))

    def rows_into(
        self, state: GraspState | None, A: np.ndarray, lower: np.ndarray, start: int
    ) -> None:
        """Write :meth:`rows` into rows ``start:`` of the stacked ``A`` and ``lower``."""
        block = slice(start, start + len(self.names))
        A[block] = self._A
        lower[block] = self._lower_rows

    def values(self, state: GraspState | None, u: np.ndarray) -> BarrierValues:
        """Margins ``(u_j - u_min,j, u_max,j - u_j)`` per joint, N·m."""
        return BarrierValues(self._A @ u - self._lower_rows, self.names)

    def clip(self, u: np.ndarray) -> np.ndarray:
        """``u`` clipped into the box."""
        return np.minimum(np.maximum(u, self.lower), self.upper)
