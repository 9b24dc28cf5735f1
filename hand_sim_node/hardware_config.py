"""The hardware mode's configuration: the ``hardware.*`` and ``tracker.*`` parameters as values.

The parameters and their defaults are declared once, in
:data:`grasp_safety_filter.io.schemas.HAND_SIM_PARAMETERS`; :meth:`HardwareConfig.from_parameters`
reads them (and ``time_step``) from a node's parameters and checks them together
(:func:`~grasp_safety_filter.io.schemas.hardware_parameter_errors`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from grasp_safety_filter.io.messages import seconds_to_nanoseconds
from grasp_safety_filter.io.parameters import flatten_parameters, raise_parameter_errors
from grasp_safety_filter.io.schemas import (
    driver_substeps,
    FLOAT64_MULTI_ARRAY_COMMAND,
    hardware_parameter_errors,
    MODEL_JOINT_ORDER,
    model_joint_order,
    ODOMETRY_MESSAGE,
)
from grasp_safety_filter.io.topics import (
    EFFORT_COMMAND,
    EFFORT_CONTROLLER_COMMANDS,
    OBJECT_ODOM,
    OBJECT_POSE,
)
from hand_sim_node.config import (
    parameter_default,
    PARAMETER_SPECS,
    parameter_values,
    validate_fields,
)

#: Prefix of the names of an arm's joints published before the hand's.
EXTRA_JOINT_PREFIX = 'arm_joint_'

#: TrackerConfig field -> ROS parameter name.
_TRACKER_PARAMETERS = {
    name: f'tracker.{name}'
    for name in 'rate latency position_noise orientation_noise message seed'.split()
}

#: HardwareConfig field (all but ``tracker``) -> ROS parameter name.
_HARDWARE_PARAMETERS = {
    name: f'hardware.{name}'
    for name in (
        'rate command_timeout timeout_torque command_message command_joints extra_joints'
    ).split()
}


@dataclass(frozen=True)
class TrackerConfig:
    """The emulated object tracker (``tracker.*``).

    Attributes:
        rate: Samples per second, Hz.
        latency: Capture (the sample's stamp) to publication, s.
        position_noise: Standard deviation of the position noise per palm axis, m.
        orientation_noise: Standard deviation of the rotation noise per axis, rad
            (``R_measured = exp3(noise) R``).
        message: ``"odometry"`` (``/object/odom``) or ``"pose"`` (``/object/pose``).
        seed: Seed of the noise generator.
    """

    rate: float = parameter_default('tracker.rate')
    latency: float = parameter_default('tracker.latency')
    position_noise: float = parameter_default('tracker.position_noise')
    orientation_noise: float = parameter_default('tracker.orientation_noise')
    message: str = parameter_default('tracker.message')
    seed: int = parameter_default('tracker.seed')

    def __post_init__(self) -> None:
        validate_fields(self, _TRACKER_PARAMETERS)

    @property
    def latency_ns(self) -> int:
        """:attr:`latency` in integer ns."""
        return seconds_to_nanoseconds(self.latency)

    @property
    def topic(self) -> str:
        """The topic the samples go to."""
        return OBJECT_ODOM if self.message == ODOMETRY_MESSAGE else OBJECT_POSE


@dataclass(frozen=True)
class HardwareConfig:
    """The emulated hand driver (``hardware.*``) and object tracker.

    Attributes:
        rate: Driver rate, Hz: a state every ``1 / rate`` s of wall time.
        command_timeout: Wall-clock time without a valid command before the timeout torque, s.
        timeout_torque: ``"gravity_compensation"`` or ``"zero"``.
        command_message: ``"joint_state"`` or ``"float64_multi_array"``.
        command_joints: The Float64MultiArray's joint order (``["model.joint_names"]``: the
            model's).
        extra_joints: Joints of an arm published first in the joint states.
        tracker: The object tracker.

    Raises:
        ParameterError: A value out of its range.
    """

    rate: float = parameter_default('hardware.rate')
    command_timeout: float = parameter_default('hardware.command_timeout')
    timeout_torque: str = parameter_default('hardware.timeout_torque')
    command_message: str = parameter_default('hardware.command_message')
    command_joints: tuple[str, ...] = (MODEL_JOINT_ORDER,)
    extra_joints: int = parameter_default('hardware.extra_joints')
    tracker: TrackerConfig = field(default_factory=TrackerConfig)

    def __post_init__(self) -> None:
        validate_fields(self, _HARDWARE_PARAMETERS)
        object.__setattr__(self, 'command_joints', tuple(self.command_joints))

    @property
    def command_topic(self) -> str:
        """The topic the commands come on."""
        if self.command_message == FLOAT64_MULTI_ARRAY_COMMAND:
            return EFFORT_CONTROLLER_COMMANDS
        return EFFORT_COMMAND

    @property
    def command_timeout_ns(self) -> int:
        """:attr:`command_timeout` in integer ns."""
        return seconds_to_nanoseconds(self.command_timeout)

    def joint_order(self, model_joints: list[str]) -> list[str]:
        """Return the Float64MultiArray's joints (the sentinel resolved to ``model_joints``)."""
        return model_joint_order(self.command_joints, model_joints)

    def extra_joint_names(self) -> list[str]:
        """Return ``arm_joint_1`` ... ``arm_joint_<extra_joints>``."""
        return [f'{EXTRA_JOINT_PREFIX}{k}' for k in range(1, self.extra_joints + 1)]

    def substeps(self, time_step: float) -> int:
        """Integration steps of ``time_step`` s per driver period (ParameterError if not whole)."""
        return driver_substeps(self.rate, time_step)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> HardwareConfig:
        """Build from ``hand_sim_node``'s parameters and check them with ``time_step``.

        Missing parameters take their defaults; the values are checked as the hardware mode
        reads them, whatever ``lockstep`` says.

        Raises:
            ParameterError: A value out of range, or values that do not fit together
                (naming the parameters: e.g. a driver period that is not a whole number
                of ``time_step``).
        """
        flat = flatten_parameters(params)
        values = parameter_values(
            flat,
            (
                name
                for name in PARAMETER_SPECS
                if name.startswith(('hardware.', 'tracker.')) or name == 'time_step'
            ),
        )
        joints = list(values['hardware.command_joints'])
        # Without the model's joints (a caller's partial parameters), the order is checked
        # against itself (duplicates) and later against the model by the endpoint.
        values['model.joint_names'] = list(flat.get('model.joint_names') or joints)
        values['lockstep'] = False
        raise_parameter_errors(
            'hand_sim_node parameters', hardware_parameter_errors(values), 'inconsistent'
        )
        tracker = TrackerConfig(
            **{name: values[parameter] for name, parameter in _TRACKER_PARAMETERS.items()}
        )
        return cls(
            **{name: values[parameter] for name, parameter in _HARDWARE_PARAMETERS.items()},
            tracker=tracker,
        )
