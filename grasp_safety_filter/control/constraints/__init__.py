"""Grasp constraint families, each as named rows ``A u >= lower`` affine in the joint torque.

- :class:`FrictionPyramid` (``no_slip``): contact forces inside inscribed friction pyramids.
- :class:`JointLimitBarrier` (``joint_limits``): joint angles inside their limits (ZCBF).
- :class:`FingertipWorkspaceBarrier` (``fingertip_workspace``): rolling contact points on
  the fingertip surface (ZCBF).
- :class:`ObjectWorkspaceBarrier` (``object_workspace``): rolling contact points on their
  object surface, a margin inside a box face's edges (ZCBF).
- :class:`ActuatorLimits` (``actuator_limits``): the joint torque box.
- :class:`TorqueRateBound` (``torque_rate``): a bounded torque step per tick (not safety).

One module per family, named after it; ``base`` holds their common form and checks,
``box_barrier`` the ZCBF rows that joint limits and the two workspaces share.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from grasp_safety_filter.control.constraints.actuator_limits import ActuatorLimits
from grasp_safety_filter.control.constraints.base import (
    BarrierValues,
    ConstraintFamily,
    ConstraintRows,
)
from grasp_safety_filter.control.constraints.box_barrier import BoxBarrier
from grasp_safety_filter.control.constraints.fingertip_workspace import (
    FingertipWorkspaceBarrier,
)
from grasp_safety_filter.control.constraints.friction_cone import FrictionPyramid
from grasp_safety_filter.control.constraints.joint_limits import JointLimitBarrier
from grasp_safety_filter.control.constraints.object_workspace import ObjectWorkspaceBarrier
from grasp_safety_filter.control.constraints.torque_rate import TorqueRateBound
from grasp_safety_filter.model.grasp_state import GraspState

__all__ = [
    'ActuatorLimits',
    'BarrierValues',
    'BoxBarrier',
    'ConstraintFamily',
    'ConstraintRows',
    'FingertipWorkspaceBarrier',
    'FrictionPyramid',
    'JointLimitBarrier',
    'ObjectWorkspaceBarrier',
    'TorqueRateBound',
    'stack_constraints',
]


def stack_constraints(families: Sequence[ConstraintFamily], state: GraspState) -> ConstraintRows:
    """All families' rows ``A u >= lower`` stacked in the given order, with their names."""
    blocks = [family.rows(state) for family in families]
    m = state.n_joints
    A = np.vstack([block.A for block in blocks]) if blocks else np.zeros((0, m))
    lower = np.concatenate([block.lower for block in blocks]) if blocks else np.zeros(0)
    return ConstraintRows(A, lower, tuple(name for block in blocks for name in block.names))
