"""The hardware mode's state messages: joint states (an arm's joints first), truth, contacts.

Built for :class:`~hand_sim_node.hardware.HardwareEndpoint` from the plant's state, each
stamped with the driver period's stamp (integer ns):

- ``/hand/joint_states``: ``hardware.extra_joints`` joints ``arm_joint_1``... first, at
  fixed positions spread over :data:`EXTRA_JOINT_RANGE` with zero velocity and effort (as a
  ``joint_state_broadcaster`` of an arm with a hand publishes them), then the hand's q
  (rad), dq (rad/s) and the torque applied over the period (N·m);
- ``/object/true_odom``: the plant's exact object pose in the palm frame and twist in the
  object frame (:func:`~grasp_safety_filter.io.messages.odometry_to_msg`);
- ``/hand/contacts``: a step's contact data (:func:`~grasp_safety_filter.io.messages.
  contacts_to_msg`), stamped as the state.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from grasp_safety_filter.io.messages import (
    ContactData,
    contacts_to_msg,
    joint_state_to_msg,
    MessageNamespace,
    odometry_to_msg,
)
from grasp_safety_filter.io.topics import CONTACTS, JOINT_STATES, OBJECT_TRUE_ODOM
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.outgoing import Outgoing
from hand_sim_node.simulator import SimState, StepReport

#: Fixed positions of an arm's joints in the joint states span this range, rad.
EXTRA_JOINT_RANGE = (-0.3, 0.3)


class StateMessages:
    """Builds the hardware mode's state messages (module docstring).

    Args:
        model: The grasp model (joint and contact names, palm and object frames).
        msgs: Message classes to build (rclpy or rosbags).
        extra_joints: Names of an arm's joints, published first.

    Attributes:
        joint_names: The names in ``/hand/joint_states``, in order.
    """

    def __init__(self, model: GraspModel, msgs: MessageNamespace, extra_joints: list[str]) -> None:
        self.model = model
        self.msgs = msgs
        self.joint_names = [*extra_joints, *model.joint_names]
        self._extra_positions = np.linspace(*EXTRA_JOINT_RANGE, len(extra_joints))
        self._extra_zeros = np.zeros(len(extra_joints))

    def state(self, stamp_ns: int, state: SimState, applied_effort: np.ndarray) -> list[Outgoing]:
        """Return ``/hand/joint_states`` and ``/object/true_odom`` of ``state``.

        Args:
            stamp_ns: Their stamp, integer ns.
            state: The plant's state.
            applied_effort: The hand's torque over the period that ended at ``state``, N·m.
        """
        joint_state = joint_state_to_msg(
            self.msgs,
            stamp_ns,
            self.joint_names,
            np.r_[self._extra_positions, state.q],
            np.r_[self._extra_zeros, state.dq],
            np.r_[self._extra_zeros, applied_effort],
        )
        true_odometry = odometry_to_msg(
            self.msgs,
            stamp_ns,
            state.p_object_in_palm,
            state.R_object_to_palm,
            state.twist_object,
            frame_id=self.model.palm_frame,
            child_frame_id=self.model.object_frame,
        )
        return [
            Outgoing(JOINT_STATES, stamp_ns, joint_state),
            Outgoing(OBJECT_TRUE_ODOM, stamp_ns, true_odometry),
        ]

    def contacts(self, stamp_ns: int, report: StepReport) -> Outgoing:
        """Return ``/hand/contacts`` of a step's report, stamped ``stamp_ns`` (ns)."""
        data = ContactData.from_grasp_state(report.grasp_state, report.contact_force)
        data = dataclasses.replace(data, t=stamp_ns)
        msg = contacts_to_msg(self.msgs, data, self.model.contact_names)
        return Outgoing(CONTACTS, stamp_ns, msg)
