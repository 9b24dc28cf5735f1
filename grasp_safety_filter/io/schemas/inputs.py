"""``STREAM_PARAMETERS``: how both controllers make their ticks from their input streams.

Declared by ``nominal_controller_node`` and ``safety_filter_node`` alike (give them the same
values in both nodes' sections, or as ``-p`` to both: the simulator does not declare them, so
they cannot go under ``/**``):

- ``input.sync: exact``: every input of a tick carries the tick's stamp, as the lockstep
  simulator stamps them (the paper's runs);
- ``input.sync: latest``: each joint state is a tick (a hand driver's stream, at its own
  rate); the object's state is the estimate at that stamp from the tracker's newest samples
  and the hand's joint velocities (:mod:`grasp_safety_filter.estimation.object_state`); the
  filter's u_nom is the one stamped as the state (the nominal controller's answer) or, from a
  controller of one's own with its own stamps, the newest no older than ``input.max_age``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from grasp_safety_filter.io.messages import joint_order, MessageError
from grasp_safety_filter.io.parameters import ParameterSpec, raise_parameter_errors
from grasp_safety_filter.io.schemas.common import DOUBLE, STRING, STRING_ARRAY

#: ``input.sync`` values.
EXACT_SYNC = 'exact'
LATEST_SYNC = 'latest'
SYNC_POLICIES = (EXACT_SYNC, LATEST_SYNC)

#: ``input.object_message`` values: nav_msgs/Odometry on /object/odom, or
#: geometry_msgs/PoseStamped on /object/pose.
ODOMETRY_MESSAGE = 'odometry'
POSE_MESSAGE = 'pose'
OBJECT_MESSAGES = (ODOMETRY_MESSAGE, POSE_MESSAGE)

# fmt: off
STREAM_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'input.sync', STRING, EXACT_SYNC,
        'How inputs make a tick: exact (joint state, object odometry and, for the filter, '
        'u_nom of one stamp: the lockstep simulator) or latest (every joint state is a '
        "tick, the object's state estimated at its stamp: a real hand's driver and tracker)",
        choices=SYNC_POLICIES, read_only=True,
    ),
    ParameterSpec(
        'input.object_message', STRING, ODOMETRY_MESSAGE,
        "The object's pose input: odometry (nav_msgs/Odometry on /object/odom, pose and "
        'twist) or pose (geometry_msgs/PoseStamped on /object/pose, input.sync latest only)',
        choices=OBJECT_MESSAGES, read_only=True,
    ),
    ParameterSpec(
        'object_state.correction_time', DOUBLE, 0.1,
        "With input.sync latest: time constant of the tracker's correction of the object state "
        "the hand's joint velocities carry between its samples; 0: each tracker pose taken "
        'as it is [s]',
        min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'object_state.max_age', DOUBLE, 0.5,
        'With input.sync latest: a tick whose newest object pose was captured longer ago than '
        'this is stale and rejected [s]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
)
# fmt: on
"""Both controllers' input streams (``nodes.stream_config.StreamConfig``)."""

#: ``command.message`` values.
JOINT_STATE_COMMAND = 'joint_state'
FLOAT64_MULTI_ARRAY_COMMAND = 'float64_multi_array'
COMMAND_MESSAGES = (JOINT_STATE_COMMAND, FLOAT64_MULTI_ARRAY_COMMAND)
#: ``command.joints`` default: the model's joint order.
MODEL_JOINT_ORDER = 'model.joint_names'

# fmt: off
COMMAND_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'command.message', STRING, JOINT_STATE_COMMAND,
        'Form of u* for the hand: joint_state (sensor_msgs/JointState by joint name on '
        "/hand/effort_command) or float64_multi_array (also ros2_control's "
        'effort_controllers/JointGroupEffortController form on /effort_controller/commands: '
        'std_msgs/Float64MultiArray in command.joints order)',
        choices=COMMAND_MESSAGES, read_only=True,
    ),
    ParameterSpec(
        'command.joints', STRING_ARRAY, [MODEL_JOINT_ORDER],
        "With float64_multi_array: the effort controller's joints parameter, every model joint "
        "once, in its order ('model.joint_names': in that order)",
        read_only=True,
    ),
)
# fmt: on
"""The safety filter's command output (``nodes.command_output.CommandOutput``)."""


def check_stream_parameters(values: Mapping[str, Any], source: str = 'parameters') -> None:
    """Refuse ``input.object_message: pose`` (no twist) unless ``input.sync: latest``.

    Raises:
        ParameterError: Naming both parameters.
    """
    if values['input.object_message'] == POSE_MESSAGE and values['input.sync'] != LATEST_SYNC:
        raise_parameter_errors(
            source,
            [
                "parameter 'input.object_message': 'pose' (no twist) needs 'input.sync' "
                f"'{LATEST_SYNC}', got '{values['input.sync']}'"
            ],
            'inconsistent',
        )


def model_joint_order(joints: Sequence[str], model_joints: Sequence[str]) -> list[str]:
    """Return an effort controller's joint order: ``joints``, or the model's for the sentinel.

    ``command.joints`` and ``hardware.command_joints`` default to
    ``[`` :data:`MODEL_JOINT_ORDER` ``]``: the model's own order.
    """
    return list(model_joints) if list(joints) == [MODEL_JOINT_ORDER] else list(joints)


def joint_order_errors(
    parameter: str, joints: Sequence[str], model_joints: Sequence[str]
) -> list[str]:
    """Return why ``parameter`` (a joint order) does not name every model joint once, if so.

    The sentinel :data:`MODEL_JOINT_ORDER` is always right.
    """
    try:
        order = model_joint_order(joints, model_joints)
        joint_order(f"parameter '{parameter}'", order, model_joints)
    except MessageError as error:
        return [str(error)]
    return []


def check_command_parameters(values: Mapping[str, Any], source: str = 'parameters') -> None:
    """Refuse a ``command.joints`` that does not name every model joint exactly once.

    Raises:
        ParameterError: Naming the joints that are not the model's and those missing.
    """
    errors = joint_order_errors(
        'command.joints', values['command.joints'], values['model.joint_names']
    )
    raise_parameter_errors(source, errors, 'inconsistent')
