"""The safety filter's command messages: u* by joint name, and in ros2_control's form.

Every command (a computed u*, a held or fallback one) goes out as a ``sensor_msgs/JointState``
on ``/hand/effort_command``: efforts by joint name, stamped as the tick it answers (so a
bag and a lockstep simulator read it by stamp). With ``command.message:
float64_multi_array`` the same u* also goes out as the ``std_msgs/Float64MultiArray`` an
``effort_controllers/JointGroupEffortController`` takes on ``<controller>/commands``
(``/effort_controller/commands``, remap it): one torque per joint of the controller's
``joints`` (``command.joints``), in that order, unstamped.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io.messages import (
    effort_array_to_msg,
    effort_to_msg,
    joint_order,
    MessageError,
    MessageNamespace,
)
from grasp_safety_filter.io.parameters import flatten_parameters
from grasp_safety_filter.io.schemas import (
    FLOAT64_MULTI_ARRAY_COMMAND,
    JOINT_STATE_COMMAND,
    MODEL_JOINT_ORDER,
    model_joint_order,
)
from grasp_safety_filter.io.topics import EFFORT_COMMAND, EFFORT_CONTROLLER_COMMANDS
from grasp_safety_filter.nodes.outgoing import Outgoing


@dataclass(frozen=True)
class CommandConfig:
    """``command.message`` and ``command.joints``.

    Attributes:
        message: ``joint_state`` or ``float64_multi_array``.
        joints: The effort controller's joint order (``[MODEL_JOINT_ORDER]``: the model's).

    """

    message: str = JOINT_STATE_COMMAND
    joints: tuple[str, ...] = (MODEL_JOINT_ORDER,)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> CommandConfig:
        """Build from the filter node's ``command.*`` parameters."""
        flat = flatten_parameters(params)
        return cls(
            str(flat.get('command.message', JOINT_STATE_COMMAND)),
            tuple(flat.get('command.joints', (MODEL_JOINT_ORDER,))),
        )


class CommandOutput:
    """Builds the command messages of one u* (module docstring).

    Args:
        msgs: Message classes to build.
        joint_names: The model's joint names (u*'s order).
        config: The command form; default: JointState only.

    Raises:
        ConfigError: ``command.joints`` does not name every model joint exactly once.

    """

    def __init__(
        self,
        msgs: MessageNamespace,
        joint_names: Sequence[str],
        config: CommandConfig | None = None,
    ) -> None:
        config = config or CommandConfig()
        self.msgs = msgs
        self._joint_names = tuple(joint_names)
        self._order: np.ndarray | None = None
        if config.message == FLOAT64_MULTI_ARRAY_COMMAND:
            try:
                self._order = joint_order(
                    "parameter 'command.joints'",
                    model_joint_order(config.joints, self._joint_names),
                    self._joint_names,
                )
            except MessageError as error:
                raise ConfigError(str(error)) from None

    @property
    def topics(self) -> tuple[str, ...]:
        """The topics a command goes out on."""
        if self._order is None:
            return (EFFORT_COMMAND,)
        return (EFFORT_COMMAND, EFFORT_CONTROLLER_COMMANDS)

    def messages(self, stamp: int, u: np.ndarray) -> list[Outgoing]:
        """Return u* (model joint order, N·m) answering the tick of ``stamp`` (integer ns)."""
        command = Outgoing(
            EFFORT_COMMAND, stamp, effort_to_msg(self.msgs, stamp, self._joint_names, u)
        )
        if self._order is None:
            return [command]
        array = effort_array_to_msg(self.msgs, self._order, u)
        return [command, Outgoing(EFFORT_CONTROLLER_COMMANDS, stamp, array)]
