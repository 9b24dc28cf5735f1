"""Both simulator endpoints' state messages: joint states, object odometry, contacts.

Built for :class:`~hand_sim_node.endpoint.HandSimEndpoint` (lockstep) and
:class:`~hand_sim_node.hardware.HardwareEndpoint` (hardware mode) from the plant's state,
each stamped with the stamp it is given (integer ns: the state's time in lockstep, the
driver period's in the hardware mode):

- ``/hand/joint_states``: an arm's joints ``arm_joint_1``... first, if any (the hardware
  mode's ``hardware.extra_joints``), at fixed positions spread over
  :data:`EXTRA_JOINT_RANGE` with zero velocity and effort (as a ``joint_state_broadcaster``
  of an arm with a hand publishes them), then the hand's q (rad), dq (rad/s) and the torque
  applied over the step or period that ended at the state (N·m);
- the object's odometry (``/object/odom`` in lockstep, ``/object/true_odom`` in the
  hardware mode): the plant's exact object pose in the palm frame and twist in the object
  frame (:func:`~grasp_safety_filter.io.messages.odometry_to_msg`);
- ``/hand/contacts``: a step's contact data at its start (:func:`~grasp_safety_filter.io.
  messages.contacts_to_msg`).
"""

from __future__ import annotations

from collections.abc import Sequence
import dataclasses

import numpy as np

from grasp_safety_filter.io.messages import (
    ContactData,
    contacts_to_msg,
    joint_state_to_msg,
    MessageNamespace,
    odometry_to_msg,
)
from grasp_safety_filter.io.topics import CONTACTS, JOINT_STATES
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.outgoing import Outgoing
from hand_sim_node.simulator import SimState, StepReport

#: Fixed positions of an arm's joints in the joint states span this range, rad.
EXTRA_JOINT_RANGE = (-0.3, 0.3)


class StateMessages:
    """Builds the simulator's state messages (module docstring).

    Args:
        model: The grasp model (joint and contact names, palm and object frames).
        msgs: Message classes to build (rclpy or rosbags).
        odometry_topic: The topic of the object's odometry.
        extra_joints: Names of an arm's joints, published first (none: the hand's only).

    Attributes:
        joint_names: The names in ``/hand/joint_states``, in order.
    """

    def __init__(
        self,
        model: GraspModel,
        msgs: MessageNamespace,
        odometry_topic: str,
        extra_joints: Sequence[str] = (),
    ) -> None:
        self.model = model
        self.msgs = msgs
        self.odometry_topic = odometry_topic
        self.joint_names = [*extra_joints, *model.joint_names]
        self._extra_positions = np.linspace(*EXTRA_JOINT_RANGE, len(extra_joints))
        self._extra_zeros = np.zeros(len(extra_joints))

    def state(self, stamp_ns: int, state: SimState, applied_effort: np.ndarray) -> list[Outgoing]:
        """Return ``/hand/joint_states`` and the object's odometry of ``state``.

        Args:
            stamp_ns: Their stamp, integer ns.
            state: The plant's state.
            applied_effort: The hand's torque over the step that ended at ``state``, N·m.
        """
        position, velocity, effort = state.q, state.dq, applied_effort
        if self._extra_zeros.size:
            position = np.r_[self._extra_positions, position]
            velocity = np.r_[self._extra_zeros, velocity]
            effort = np.r_[self._extra_zeros, effort]
        joint_state = joint_state_to_msg(
            self.msgs, stamp_ns, self.joint_names, position, velocity, effort
        )
        odometry = odometry_to_msg(
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
            Outgoing(self.odometry_topic, stamp_ns, odometry),
        ]

    def contacts(self, stamp_ns: int, report: StepReport) -> Outgoing:
        """Return ``/hand/contacts`` of a step's report, stamped ``stamp_ns`` (ns)."""
        data = ContactData.from_grasp_state(report.grasp_state, report.contact_force)
        data = dataclasses.replace(data, t=stamp_ns)
        msg = contacts_to_msg(self.msgs, data, self.model.contact_names)
        return Outgoing(CONTACTS, stamp_ns, msg)
