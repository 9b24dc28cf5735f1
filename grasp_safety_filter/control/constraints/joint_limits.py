"""Joint limits as relative-degree-two zeroing control barrier functions (paper eq. 15–18)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints.base import (
    check_limits_ordered,
    check_rows,
    finite_vector,
    validate_names,
)
from grasp_safety_filter.control.constraints.box_barrier import BoxBarrier
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.grasp_state import GraspState


class JointLimitBarrier(BoxBarrier):
    """Keep every joint angle inside ``[q_min,j, q_max,j]``.

    Two barriers per joint j (rows in this order, joint-major)::

        upper: h = q_max,j - q_j     h_dot = -dq_j     h_ddot(u) = -ddq_j(u)
        lower: h = q_j - q_min,j     h_dot =  dq_j     h_ddot(u) =  ddq_j(u)

    each with ``B = h_dot + alpha_1(h)`` and the constraint::

        h_ddot(u) + alpha_1'(h) h_dot + alpha_2(B) >= 0

    where ``ddq(u)`` is ``state.joint_acceleration`` (the constrained hand–object dynamics).
    With the default ``alpha_1 = alpha_2 = h^3`` this is
    ``h_ddot + 3 h^2 h_dot + (h_dot + h^3)^3 >= 0``. Units: h in rad, rows in rad/s².
    Row names: ``"joint_limits/<joint>/upper"`` and ``"joint_limits/<joint>/lower"``.
    """

    family = 'joint_limits'
    state_fields = ('q', 'dq', 'joint_acceleration')

    def __init__(
        self,
        joint_names: Sequence[str],
        q_min: Sequence[float] | np.ndarray,
        q_max: Sequence[float] | np.ndarray,
        alpha1: ClassKFunction | None = None,
        alpha2: ClassKFunction | None = None,
    ) -> None:
        """Build the barrier rows of every joint.

        Args:
            joint_names: The m joint names, in the model's joint order.
            q_min: Lower joint limits, shape (m,), rad.
            q_max: Upper joint limits, shape (m,), rad, each > q_min.
            alpha1: Extended class-K function of h (default cubic, gain 1).
            alpha2: Extended class-K function of B (default cubic, gain 1).

        Raises:
            ValueError: An argument is malformed; the message names it.
        """
        self.joint_names = validate_names(joint_names, 'joint_names')
        m = len(self.joint_names)
        self.q_min = finite_vector(q_min, m, 'q_min')
        self.q_max = finite_vector(q_max, m, 'q_max')
        check_limits_ordered(
            self.q_min, self.q_max, self.joint_names, 'q_min', 'q_max', strict=True
        )
        names = tuple(
            f'{self.family}/{joint}/{side}'
            for joint in self.joint_names
            for side in ('upper', 'lower')
        )
        super().__init__(
            index=np.repeat(np.arange(m), 2),
            sign=np.tile([-1.0, 1.0], m),
            bound=np.column_stack((self.q_max, self.q_min)).ravel(),
            names=names,
            alpha1=alpha1 if alpha1 is not None else ClassKFunction(),
            alpha2=alpha2 if alpha2 is not None else ClassKFunction(),
        )

    packed_fields = ('q', 'dq', 'joint_acceleration_augmented')

    def coordinates(self, state: GraspState) -> tuple[np.ndarray, np.ndarray, AffineMap]:
        """``(q, dq, u ↦ ddq)`` from the state."""
        m = len(self.joint_names)
        check_rows(state.q, m, 'q')
        check_rows(state.dq, m, 'dq')
        check_rows(state.joint_acceleration.offset, m, 'joint_acceleration')
        return state.q, state.dq, state.joint_acceleration
