"""Simulator configuration: the validated ``hand_sim_node`` parameters as one value.

The parameters and their defaults are declared once, in
:data:`grasp_safety_filter.io.schemas.HAND_SIM_PARAMETERS` (the rclpy node declares them from
there); the ROS-free runner builds a :class:`SimConfig` from the same parameter file with
:meth:`SimConfig.from_parameters`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.io.parameters import flatten_parameters, ParameterError
from grasp_safety_filter.io.schemas import command_delay_steps as whole_steps
from grasp_safety_filter.io.schemas import HAND_SIM_PARAMETERS
from grasp_safety_filter.nodes.scenario import MAX_STEPS

#: ``hand_sim_node``'s parameter specifications, by name.
PARAMETER_SPECS = {spec.name: spec for spec in HAND_SIM_PARAMETERS}

_ARRAY_FIELDS: dict[str, str] = {
    'initial_joint_positions': 'initial.joint_positions',
    'initial_object_position': 'initial.object_position',
    'initial_object_orientation': 'initial.object_orientation',
}
_SCALAR_FIELDS: dict[str, str] = {
    'integrator': 'integrator',
    'time_step': 'time_step',
    'duration': 'duration',
    'stop_on_slip': 'stop_on_slip',
    'stop_on_workspace_exit': 'stop_on_workspace_exit',
    'position_gain': 'stabilization.position_gain',
    'velocity_gain': 'stabilization.velocity_gain',
    'lockstep': 'lockstep',
    'command_timeout': 'command_timeout',
    'command_delay': 'command_delay',
    'publish_clock': 'publish_clock',
}
"""SimConfig field -> ROS parameter name."""


def parameter_default(name: str) -> Any:
    """Return the default of the ``hand_sim_node`` parameter ``name``."""
    return PARAMETER_SPECS[name].default


def parameter_values(params: Mapping[str, Any], names: Iterable[str]) -> dict[str, Any]:
    """Return the parameters ``names`` of ``params`` (dotted or nested), each validated.

    A parameter missing from ``params`` takes its default.

    Raises:
        ParameterError: A parameter is of the wrong type or out of range.
    """
    flat = flatten_parameters(params)
    return {
        name: (
            PARAMETER_SPECS[name].validate(flat[name]) if name in flat else parameter_default(name)
        )
        for name in names
    }


def validate_fields(config: Any, parameters: Mapping[str, str]) -> None:
    """Replace each field of a frozen dataclass ``config`` by its parameter's validated value.

    Args:
        config: The dataclass instance (in its ``__post_init__``).
        parameters: Field name -> the ``hand_sim_node`` parameter it holds.

    Raises:
        ParameterError: Naming the parameter, what was expected and what was received.
    """
    for field_name, name in parameters.items():
        value = PARAMETER_SPECS[name].validate(getattr(config, field_name))
        object.__setattr__(config, field_name, value)


@dataclass(frozen=True, eq=False)
class SimConfig:
    """Validated simulator configuration (defaults: ``HAND_SIM_PARAMETERS``).

    Attributes:
        initial_joint_positions: Initial joint angles, shape (m,), rad (model joint order).
        initial_object_position: Initial object centre of mass in the palm frame, (3,), m.
        initial_object_orientation: Initial unit quaternion ``(x, y, z, w)`` of
            ``R_object_to_palm``, shape (4,).
        integrator: ``"ode3"`` or ``"rk4"``.
        time_step: Integration step, s; the torque is held constant over a step.
        duration: Simulated duration of a run, s.
        stop_on_slip: Whether slip (beta_i > mu) stops the run.
        stop_on_workspace_exit: Whether a contact leaving its fingertip workspace stops it.
        position_gain: Baumgarte gain ``K_p`` on the normal interpenetration, 1/s².
        velocity_gain: Baumgarte gain ``K_v`` on the contact velocity residual, 1/s.
        lockstep: Node only: wait for the command stamped t_k before integrating (the
            lockstep endpoint); False: the hardware mode (:mod:`hand_sim_node.hardware`,
            configured by :class:`~hand_sim_node.hardware_config.HardwareConfig`).
        command_timeout: Node only: lockstep wait before a diagnostic, s.
        command_delay: Lockstep: the plant applies the command stamped t_k from
            t_k + command_delay on, s; a whole number of ``time_step``
            (:attr:`command_delay_steps`), 0 with ``lockstep`` false.
        publish_clock: Node only, lockstep: publish /clock.

    Raises:
        ParameterError: Naming the parameter, what was expected and what was received.

    """

    initial_joint_positions: np.ndarray | tuple[float, ...]
    initial_object_position: np.ndarray | tuple[float, ...]
    initial_object_orientation: np.ndarray | tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)
    integrator: str = parameter_default('integrator')
    time_step: float = parameter_default('time_step')
    duration: float = parameter_default('duration')
    stop_on_slip: bool = parameter_default('stop_on_slip')
    stop_on_workspace_exit: bool = parameter_default('stop_on_workspace_exit')
    position_gain: float = parameter_default('stabilization.position_gain')
    velocity_gain: float = parameter_default('stabilization.velocity_gain')
    lockstep: bool = parameter_default('lockstep')
    command_timeout: float = parameter_default('command_timeout')
    command_delay: float = parameter_default('command_delay')
    publish_clock: bool = parameter_default('publish_clock')

    def __post_init__(self) -> None:
        validate_fields(self, _ARRAY_FIELDS)
        for field_name, name in _ARRAY_FIELDS.items():
            value = np.array(getattr(self, field_name), dtype=float)
            if value.size == 0:
                raise ParameterError(f"parameter '{name}': expected a non-empty list, got []")
            value.setflags(write=False)
            object.__setattr__(self, field_name, value)
        validate_fields(self, _SCALAR_FIELDS)
        quaternion = self.initial_object_orientation
        norm = float(np.linalg.norm(quaternion))
        if abs(norm - 1.0) > 1e-6:
            raise ParameterError(
                "parameter 'initial.object_orientation': expected a unit quaternion (x, y, z, "
                f'w), got {quaternion.tolist()} (norm {norm:.9g})'
            )
        unit = quaternion / norm
        unit.setflags(write=False)
        object.__setattr__(self, 'initial_object_orientation', unit)
        if self.time_step > self.duration:
            raise ParameterError(
                f"parameter 'time_step': expected <= duration ({self.duration} s), got "
                f'{self.time_step}'
            )
        whole_steps(self.command_delay, self.time_step)  # raises unless a whole number
        if self.command_delay > 0 and not self.lockstep:
            raise ParameterError(
                "parameters 'command_delay' and 'lockstep': the hardware mode (lockstep false) "
                'has no command delay; expected command_delay = 0 with lockstep false, got '
                f'{self.command_delay!r} s (the lockstep mode takes one)'
            )
        if self.duration / self.time_step > MAX_STEPS:
            raise ParameterError(
                f"parameter 'duration': expected at most {MAX_STEPS:g} steps of time_step "
                f'({self.time_step:g} s), got {self.duration:g} s'
            )

    @property
    def n_steps(self) -> int:
        """Number of steps of a full run, ``round(duration / time_step)``."""
        return max(1, round(self.duration / self.time_step))

    @property
    def command_delay_steps(self) -> int:
        """Steps of ``time_step`` from a command's tick to the plant applying it, ``>= 0``."""
        return whole_steps(self.command_delay, self.time_step)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> SimConfig:
        """Build from a node's parameters (dotted names or nested dictionaries).

        Parameters that are not the simulator's (the model's, for instance) are ignored;
        missing ones take their defaults from ``HAND_SIM_PARAMETERS``.

        Raises:
            ParameterError: A parameter is of the wrong type or out of range.

        """
        names = {**_ARRAY_FIELDS, **_SCALAR_FIELDS}
        values = parameter_values(params, names.values())
        return cls(**{field_name: values[name] for field_name, name in names.items()})
