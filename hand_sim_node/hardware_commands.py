"""The hardware mode's torques: the commands as a hand's driver takes them, and its safe torque.

- ``hardware.command_message: joint_state``: a ``sensor_msgs/JointState`` on
  ``/hand/effort_command`` with one effort per model joint, by name, in any order. Its stamp
  is not read (a real driver does not check stamps), so any stamp is accepted; position and
  velocity may be empty or have one finite entry per name.
- ``float64_multi_array``: a ``std_msgs/Float64MultiArray`` on ``/effort_controller/commands``
  with one torque per joint of ``hardware.command_joints``, in that order (ros2_control's
  ``effort_controllers/JointGroupEffortController``).

Either is read into the model's joint order, N·m; a command with a non-finite value, the
wrong number of entries, or unknown, missing or duplicate joints raises
:class:`~grasp_safety_filter.io.messages.MessageError` naming the problem.

While the commands are timed out the driver applies :class:`SafeTorque` instead.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from grasp_safety_filter.io.messages import effort_array_from_msg, effort_values, joint_order
from grasp_safety_filter.io.schemas import FLOAT64_MULTI_ARRAY_COMMAND, ZERO_TORQUE
from grasp_safety_filter.model.grasp_model import GraspModel
from hand_sim_node.hardware_config import HardwareConfig


class CommandReader:
    """Reads the configured command message into model-order torques (module docstring).

    Args:
        config: The hardware mode's configuration (message type, topic, joint order).
        model_joints: The model's joint names.

    Raises:
        MessageError: ``hardware.command_joints`` does not name every model joint once.
    """

    def __init__(self, config: HardwareConfig, model_joints: Sequence[str]) -> None:
        self.topic = config.command_topic
        self.model_joints = list(model_joints)
        self.array = config.command_message == FLOAT64_MULTI_ARRAY_COMMAND
        self._order = (
            joint_order(
                'hardware.command_joints', config.joint_order(self.model_joints), self.model_joints
            )
            if self.array
            else None
        )

    def read(self, msg: Any) -> np.ndarray:
        """Return the command's torques in model joint order, shape (m,), N·m.

        Raises:
            MessageError: An invalid command (module docstring).
        """
        if self._order is not None:
            return effort_array_from_msg(msg, self._order, self.topic)
        return effort_values(msg, self.model_joints, self.topic)


class SafeTorque:
    """The torque a driver applies when the commands time out (``hardware.timeout_torque``).

    ``gravity_compensation``: g(q) of the model's hand, the torque holding it against
    gravity, from Pinocchio data of its own (the plant's buffers are untouched); ``zero``:
    none. Clipped to the URDF's effort limits.

    Args:
        model: The grasp model.
        kind: ``"gravity_compensation"`` or ``"zero"``.
    """

    def __init__(self, model: GraspModel, kind: str) -> None:
        hand = model.hand
        self.kind = kind
        self._limits = np.asarray(model.effort_limits, dtype=float)
        self._pin_model = hand.model
        self._data = hand.model.createData()
        self._index = np.asarray(hand.pinocchio_index)
        self._q = pin.neutral(hand.model)

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """Return g(q), shape (m,), N·m, at the joint angles ``q`` (rad, model order)."""
        self._q[self._index] = q
        gravity = pin.computeGeneralizedGravity(self._pin_model, self._data, self._q)
        return np.array(gravity[self._index])

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """Return the safe torque at ``q`` (rad), shape (m,), N·m, within the effort limits."""
        if self.kind == ZERO_TORQUE:
            return np.zeros(len(self._limits))
        return np.clip(self.gravity(q), -self._limits, self._limits)
